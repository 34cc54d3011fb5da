//! The controller I/O of issue 21 on the board (docs/rig.md "Controller I/O"): the valve
//! coil inputs (PC2-PC5 dump, PC9-PC12 hold: one GPIOC_IDR load a step), the EB loop relay
//! (PB5), the service demand PWM (PA7 = TIM17_CH1, AF1) and the air-spring DACs (PA4 =
//! DAC1_OUT1, PA6 = DAC2_OUT1). Set up once at init by register writes; the step writes
//! only BSRR, TIM17's registers (through `pulse::update`: PSC/ARR only when the frequency
//! changes) and the two DHR12R1.
//!
//! Safe state (reset, every fault, `DrivenOutputs::safe`): PB5 low (relay dropped: loop
//! open), PA7 low (no valid demand), DAC codes 0. PB5 and PA7 are in the reset handler's
//! safe pin table (`pulse::SAFE_PIN_WRITES`).

use embassy_stm32::pac;
use embassy_stm32::pac::dac::vals::Mode as DacMode;
use embassy_stm32::pac::gpio::vals::{Moder, Pupdr};
use embassy_stm32::pac::timer::TimAdv;
use hils_rig_core::controller_io::DrivenOutputs;
use hils_rig_core::pulse::PulseRegisters;
use hils_rig_core::valves::{DUMP_BITS, HOLD_BITS, ValveLevels};

use crate::pulse::{Channel1Out, PinId, port};

/// The EB loop relay driver (PB5, push-pull, high = relay energised = loop closed).
pub const EB_LOOP_PIN_ID: PinId = (1, 5);
/// The service demand PWM (PA7, TIM17_CH1 in AF1).
pub const DEMAND_PWM_PIN_ID: PinId = (0, 7);
/// TIM17_CH1's alternate function on PA7 (STM32G474 datasheet, AF table).
const DEMAND_PWM_AF: u8 = 1;
/// The air-spring DAC pins, bogie 1 (PA4 = DAC1_OUT1) and 2 (PA6 = DAC2_OUT1).
pub const DAC_PIN_IDS: [PinId; 2] = [(0, 4), (0, 6)];
/// Largest 12-bit DAC code.
const DAC_MAX: u16 = 4095;
/// DAC_MCR.HFSEL for an AHB clock above 160 MHz (RM0440 DAC_MCR: 0b10).
const DAC_HFSEL_ABOVE_160_MHZ: u8 = 0b10;

/// The DACs of bogies 1 and 2 (channel 1 of each).
const DACS: [pac::dac::Dac; 2] = [pac::DAC1, pac::DAC2];

/// TIM17 in TIM1's register layout (CR1, CR2, CCMR1, CCER, PSC, ARR, CCR1, BDTR, AF1 at
/// TIM1's offsets, RM0440 TIM16/TIM17 register map).
// SAFETY: TIM17's register block; only the registers it shares with TIM1 are used.
pub const DEMAND_TIMER: TimAdv = unsafe { TimAdv::from_ptr(pac::TIM17.as_ptr()) };

/// The controller-facing lines beyond the wheel speeds.
pub struct ControllerIo {
    pwm: Channel1Out,
}

impl ControllerIo {
    /// Sets everything up, outputs safe: clocks, the eight valve inputs (input, pull-up), PB5
    /// output low, TIM17 (as the pulse timers, break on lockup) silent before PA7 goes to
    /// AF1, the DACs at code 0 (0 V) with their output buffer off (the interface stage's
    /// op-amp buffers them). `dac2`: the bring-up image leaves
    /// DAC2 off (PA6 high impedance: its pulse-check jumper to PA8 sits there).
    pub fn new(silent: &PulseRegisters, dac2: bool) -> Self {
        pac::RCC.ahb2enr().modify(|w| {
            w.set_gpioaen(true);
            w.set_gpioben(true);
            w.set_gpiocen(true);
            w.set_dac1en(true);
            w.set_dac2en(true);
        });
        pac::RCC.apb2enr().modify(|w| w.set_tim17en(true));
        // Two AHB/APB cycles before the enabled peripherals take writes (RM0440 RCC).
        let _ = pac::RCC.apb2enr().read();
        cortex_m::asm::dsb();

        for bit in DUMP_BITS.into_iter().chain(HOLD_BITS) {
            let pin = bit as usize;
            pac::GPIOC
                .pupdr()
                .modify(|w| w.set_pupdr(pin, Pupdr::PULL_UP));
            pac::GPIOC
                .moder()
                .modify(|w| w.set_moder(pin, Moder::INPUT));
        }
        let (eb, eb_pin) = (port(EB_LOOP_PIN_ID), EB_LOOP_PIN_ID.1);
        crate::pulse::drive_low(eb, eb_pin);

        let mut pwm = Channel1Out::configure(DEMAND_TIMER, silent);
        // The timer drives OC1 low (OSSI, OIS1 = 0) from here: PA7 goes from the safe GPIO
        // low straight to it.
        let (pa, pwm_pin) = (port(DEMAND_PWM_PIN_ID), DEMAND_PWM_PIN_ID.1);
        pa.afr(pwm_pin / 8)
            .modify(|w| w.set_afr(pwm_pin % 8, DEMAND_PWM_AF));
        pa.moder()
            .modify(|w| w.set_moder(pwm_pin, Moder::ALTERNATE));
        pwm.start(silent);

        for (k, dac) in DACS.into_iter().enumerate() {
            let (p, pin) = (port(DAC_PIN_IDS[k]), DAC_PIN_IDS[k].1);
            p.pupdr().modify(|w| w.set_pupdr(pin, Pupdr::FLOATING));
            p.moder().modify(|w| w.set_moder(pin, Moder::ANALOG));
            dac.cr().modify(|w| w.set_en(0, false));
            dac.mcr().modify(|w| {
                w.set_hfsel(DAC_HFSEL_ABOVE_160_MHZ);
                // Buffer off (MODE1 = 010): 0 V .. VREF+, code 0 = 0 V, below the
                // transducer's live zero; the x2 op-amp stage buffers it (docs/rig.md).
                w.set_mode(0, DacMode::NORMAL_EXT_BUFDIS);
            });
            dac.dhr12r(0).write(|w| w.set_dhr(0));
            // No trigger (TEN1 = 0): DHR goes to DOR one APB clock after each write.
            dac.cr().modify(|w| w.set_en(0, k == 0 || dac2));
        }
        Self { pwm }
    }

    /// The valve inputs' port as it reads now: one load of GPIOC_IDR.
    #[inline(always)]
    pub fn valve_levels(&self) -> ValveLevels {
        ValveLevels(pac::GPIOC.idr().read().0 as u16)
    }

    /// Drives the loop (BSRR), the PWM (TIM17 through `pulse::update`) and the DACs
    /// (DHR12R1): a few register writes, no waiting.
    #[inline(always)]
    pub fn drive(&mut self, o: &DrivenOutputs) {
        let (eb, pin) = (port(EB_LOOP_PIN_ID), EB_LOOP_PIN_ID.1);
        eb.bsrr().write(|w| {
            if o.eb_loop_closed {
                w.set_bs(pin, true)
            } else {
                w.set_br(pin, true)
            }
        });
        self.pwm.write(&o.pwm);
        DACS[0]
            .dhr12r(0)
            .write(|w| w.set_dhr(o.dac[0].min(DAC_MAX)));
        DACS[1]
            .dhr12r(0)
            .write(|w| w.set_dhr(o.dac[1].min(DAC_MAX)));
    }
}

/// The safe outputs from any state (fault handlers, start): PB5 and PA7 as GPIO low, TIM17
/// stopped with its output forced inactive, DAC codes 0. Register writes only (writes to an
/// unclocked peripheral are ignored).
pub fn enter_safe_state() {
    let t = DEMAND_TIMER;
    t.cr1().modify(|w| w.set_cen(false));
    t.ccmr_output(0)
        .modify(|w| w.set_ocm(0, pac::timer::vals::Ocm::FORCE_INACTIVE));
    t.bdtr().modify(|w| w.set_moe(false));
    for id in [EB_LOOP_PIN_ID, DEMAND_PWM_PIN_ID] {
        crate::pulse::drive_low(port(id), id.1);
    }
    for dac in DACS {
        dac.dhr12r(0).write(|w| w.set_dhr(0));
    }
}
