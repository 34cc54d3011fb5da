//! The four axle-speed pulse trains: channel 1 of TIM1 (PA8), TIM15 (PB14), TIM8 (PC6) and
//! TIM20 (PB2), PWM mode 1 with ARR and CCR preload; PSC/ARR/CCR come from
//! `hils_rig_core::pulse` and are written by the step through `pulse::PulseChannel` (UDIS
//! around the writes, silence at once, the period dithered at each update event, SR.UIF). The output enable (PC8) of the interface stage is on only
//! while the rig says the controller-facing outputs are live.
//!
//! All four are break-capable timers (RM0440: TIM1/8/20 advanced, TIM15 with one
//! complementary channel; TIM4, used before for wheelset 2, has no break input): the break
//! input takes only the system break sources (the BKIN pin input is disconnected, AF1.BKINE
//! = 0; the Cortex-M4 lockup through SYSCFG_CFGR2.CLL, the clock security system always),
//! and a break clears MOE, which with OSSI = 1 and OIS1 = 0 drives the output low in
//! hardware, without the core (BDTR: BKE, BKP active high, OSSI, OSSR, AOE = 0).

use embassy_stm32::pac;
use embassy_stm32::pac::timer::TimAdv;
use embassy_stm32::pac::timer::vals::{Bkp, Ocm, Ossi, Ossr};
use embassy_stm32::timer::low_level::Timer;
use embassy_stm32::timer::simple_pwm::PwmPin;
use embassy_stm32::timer::{Ch1, GeneralInstance4Channel};
use hils_rig_core::pulse::{PulseChannel, PulseRegisters, PulseTimerRegs};

/// A pin: GPIO port (0 = A, 1 = B, 2 = C) and number.
pub type PinId = (usize, usize);

/// The pulse pins of wheelsets 1..4: PA8, PB14, PC6, PB2.
pub const PULSE_PIN_IDS: [PinId; 4] = [(0, 8), (1, 14), (2, 6), (1, 2)];
/// The output enable of the interface stage (PC8, active high, pull-down on the board side:
/// off in reset): on, the sensor loops are closed; off, they are open ("sensor lost").
pub const OUTPUT_ENABLE_PIN_ID: PinId = (2, 8);
/// FDCAN1_TX (PA12): driven high (recessive) in every safe state.
pub const CAN_TX_PIN_ID: PinId = (0, 12);

/// The GPIO port of a [`PinId`].
pub const fn port(p: PinId) -> pac::gpio::Gpio {
    match p.0 {
        0 => pac::GPIOA,
        1 => pac::GPIOB,
        _ => pac::GPIOC,
    }
}

/// The pulse pins (port, pin) of wheelsets 1..4, for the safe state.
pub const PULSE_PINS: [(pac::gpio::Gpio, usize); 4] = [
    (port(PULSE_PIN_IDS[0]), PULSE_PIN_IDS[0].1),
    (port(PULSE_PIN_IDS[1]), PULSE_PIN_IDS[1].1),
    (port(PULSE_PIN_IDS[2]), PULSE_PIN_IDS[2].1),
    (port(PULSE_PIN_IDS[3]), PULSE_PIN_IDS[3].1),
];
/// The output enable (port, pin).
pub const OUTPUT_ENABLE_PIN: (pac::gpio::Gpio, usize) =
    (port(OUTPUT_ENABLE_PIN_ID), OUTPUT_ENABLE_PIN_ID.1);

/// What the reset handler writes to each port (A, B, C) before anything else
/// (`ccm.rs` `__pre_init`): the MODER bits of the safe pins (mask, value: general-purpose
/// output) and the BSRR word (pulse pins, output enable, EB loop PB5 and demand PWM PA7 low,
/// PA12 high).
pub const SAFE_PIN_WRITES: [(u32, u32, u32); 3] = [safe_writes(0), safe_writes(1), safe_writes(2)];

const fn safe_writes(port: usize) -> (u32, u32, u32) {
    let low = [
        PULSE_PIN_IDS[0],
        PULSE_PIN_IDS[1],
        PULSE_PIN_IDS[2],
        PULSE_PIN_IDS[3],
        OUTPUT_ENABLE_PIN_ID,
        crate::controller_io::EB_LOOP_PIN_ID,
        crate::controller_io::DEMAND_PWM_PIN_ID,
    ];
    let (mut mask, mut value, mut bsrr) = (0u32, 0u32, 0u32);
    let mut k = 0;
    while k < low.len() + 1 {
        let (p, pin) = if k < low.len() { low[k] } else { CAN_TX_PIN_ID };
        if p == port {
            mask |= 3 << (2 * pin);
            value |= 1 << (2 * pin);
            bsrr |= if k < low.len() {
                1 << (16 + pin)
            } else {
                1 << pin
            };
        }
        k += 1;
    }
    (mask, value, bsrr)
}

/// The pulse timers of wheelsets 1..4, as their common register layout (TIM15's CR1,
/// CCMR1, CCER, PSC, ARR, CCR1, BDTR, AF1 sit where TIM1's do).
pub const PULSE_TIMERS: [TimAdv; 4] = [
    pac::TIM1,
    // SAFETY: TIM15's register block; only the registers it shares with TIM1 are used.
    unsafe { TimAdv::from_ptr(pac::TIM15.as_ptr()) },
    pac::TIM8,
    pac::TIM20,
];

/// Switches a pin to a GPIO output driven low: BSRR first, then MODER, so that it goes from
/// whatever drove it (the timer's low, a weak pull) straight to the GPIO's low.
pub fn drive_low(port: pac::gpio::Gpio, pin: usize) {
    port.bsrr().write(|w| w.set_br(pin, true));
    port.moder()
        .modify(|w| w.set_moder(pin, pac::gpio::vals::Moder::OUTPUT));
}

/// Sets the output enable (the step, each tick: live or not).
#[inline(always)]
pub fn set_output_enable(on: bool) {
    let (port, pin) = OUTPUT_ENABLE_PIN;
    port.bsrr().write(|w| {
        if on {
            w.set_bs(pin, true)
        } else {
            w.set_br(pin, true)
        }
    });
}

/// Channel 1 of a break-capable timer (TIM1 register layout: TIM1/8/20, and TIM15/16/17
/// whose registers used here sit where TIM1's do) driven as a [`PulseRegisters`] output.
pub struct Channel1Out {
    regs: TimAdv,
    /// The registers last written and the period dither (`pulse::PulseChannel`).
    channel: PulseChannel,
}

impl Channel1Out {
    /// Configures the timer (stopped): PWM mode 1 with preload, break on lockup and clock
    /// failure, channel enabled with MOE = 0, OSSI = 1, OIS1 = 0 (the timer drives the
    /// output low). The pin may go to the timer's alternate function after this, then
    /// [`Channel1Out::start`].
    pub fn configure(regs: TimAdv, silent: &PulseRegisters) -> Self {
        regs.cr1().modify(|w| {
            w.set_cen(false);
            w.set_arpe(true);
            w.set_udis(false);
        });
        regs.bdtr().modify(|w| w.set_moe(false));
        regs.cr2().modify(|w| w.set_ois(0, false));
        regs.ccmr_output(0).modify(|w| {
            w.set_ocm(0, Ocm::PWM_MODE1);
            w.set_ocpe(0, true);
        });
        regs.af1().modify(|w| w.set_bkine(false));
        regs.bdtr().modify(|w| {
            w.set_ossi(Ossi::IDLE_LEVEL);
            w.set_ossr(Ossr::IDLE_LEVEL);
            w.set_bkp(0, Bkp::ACTIVE_HIGH);
            w.set_bke(0, true);
            w.set_aoe(false);
        });
        // OSSI is set: enabling the channel now drives OC1 at its idle level (OIS1 = 0).
        regs.ccer().modify(|w| {
            w.set_ccp(0, false);
            w.set_cce(0, true);
        });
        Self {
            regs,
            channel: PulseChannel::new(*silent),
        }
    }

    /// Loads the silent registers and starts the timer (MOE, CEN).
    pub fn start(&mut self, silent: &PulseRegisters) {
        self.write_prescaler(silent.psc);
        self.write_period(silent.arr);
        self.write_compare(silent.ccr);
        self.generate_update();
        self.channel = PulseChannel::new(*silent);
        self.regs.bdtr().modify(|w| w.set_moe(true));
        self.regs.cr1().modify(|w| w.set_cen(true));
    }

    /// The step's new registers: nothing when unchanged, preloaded under UDIS, or silent at
    /// once, with the period dithered at each update event (`hils_rig_core::pulse::
    /// PulseChannel::write`; the channel state is copied out so that `self` is its timer).
    #[inline(always)]
    pub fn write(&mut self, r: &PulseRegisters) {
        let mut channel = self.channel;
        channel.write(r, self);
        self.channel = channel;
    }

    /// The timer's registers (bring-up: break check).
    #[cfg(feature = "bringup")]
    pub fn regs(&self) -> TimAdv {
        self.regs
    }
}

/// One pulse output: a timer driving channel 1 (its pin in the timer's alternate function).
pub struct PulseOut<T: GeneralInstance4Channel> {
    /// Keeps the timer's clock on.
    _timer: Timer<'static, T>,
    _pin: PwmPin<'static, T, Ch1>,
    out: Channel1Out,
}

impl<T: GeneralInstance4Channel> PulseOut<T> {
    /// Configures the timer ([`Channel1Out::configure`]), only then switches the pin to the
    /// timer's alternate function (`pin`, embassy's `PwmPin::new`), and starts the timer with
    /// the silent registers. The pin goes from the safe GPIO low of the start (`__pre_init`)
    /// straight to the timer's driven low: it never floats. (With MOE = 0 and OSSI = 0, the
    /// reset state, the timer leaves the output undriven, RM0440 "Output control bits for
    /// complementary OCx and OCxN channels with break feature": a pin switched to AF before
    /// OSSI is set floats until it is.)
    pub fn new(
        timer: Timer<'static, T>,
        pin: impl FnOnce() -> PwmPin<'static, T, Ch1>,
        silent: &PulseRegisters,
    ) -> Self {
        // SAFETY: the timer's own register block; only TIM1-layout registers it has are used.
        let regs = unsafe { TimAdv::from_ptr(timer.regs_core().as_ptr()) };
        let out = Channel1Out::configure(regs, silent);
        let mut out = Self {
            _timer: timer,
            _pin: pin(),
            out,
        };
        out.out.start(silent);
        out
    }

    /// The step's new registers ([`Channel1Out::write`]).
    #[inline(always)]
    pub fn write(&mut self, r: &PulseRegisters) {
        self.out.write(r);
    }

    /// The timer's registers (bring-up: break check).
    #[cfg(feature = "bringup")]
    pub fn regs(&self) -> TimAdv {
        self.out.regs()
    }
}

impl PulseTimerRegs for Channel1Out {
    #[inline(always)]
    fn set_update_disable(&mut self, disable: bool) {
        self.regs.cr1().modify(|w| w.set_udis(disable));
    }
    #[inline(always)]
    fn write_prescaler(&mut self, psc: u16) {
        self.regs.psc().write_value(psc);
    }
    #[inline(always)]
    fn write_period(&mut self, arr: u32) {
        self.regs.arr().write(|w| w.set_arr(arr as u16));
    }
    #[inline(always)]
    fn write_compare(&mut self, ccr: u32) {
        self.regs.ccr(0).write(|w| w.set_ccr(ccr as u16));
    }
    #[inline(always)]
    fn set_pwm(&mut self, pwm: bool) {
        let mode = if pwm {
            Ocm::PWM_MODE1
        } else {
            Ocm::FORCE_INACTIVE
        };
        self.regs.ccmr_output(0).modify(|w| w.set_ocm(0, mode));
    }
    #[inline(always)]
    fn generate_update(&mut self) {
        self.regs.egr().write(|w| w.set_ug(true));
    }
    /// SR.UIF read, and cleared by writing 0 to it alone (rc_w0: the other flags are
    /// written 1, which leaves them; RM0440 TIMx_SR). An update event between the read and
    /// the write is lost: the dither then skips one advance, which moves one period by a
    /// count at most.
    #[inline(always)]
    fn take_update_flag(&mut self) -> bool {
        let set = self.regs.sr().read().uif();
        if set {
            self.regs.sr().write_value(pac::timer::regs::SrAdv(!1));
        }
        set
    }
}
