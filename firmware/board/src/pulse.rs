//! The four axle-speed pulse trains: channel 1 of TIM1 (PA8), TIM4 (PB6), TIM8 (PC6) and
//! TIM20 (PB2), PWM mode 1 with ARR and CCR preload; PSC/ARR/CCR come from
//! `hils_rig_core::pulse` and are written by the step.

use embassy_stm32::pac;
use embassy_stm32::timer::low_level::{OutputCompareMode, Timer};
use embassy_stm32::timer::simple_pwm::PwmPin;
use embassy_stm32::timer::{Ch1, Channel as TimChannel, GeneralInstance4Channel};
use hils_rig_core::pulse::PulseRegisters;

/// The pulse pins (port, pin) of wheelsets 1..4, for the fault handlers' safe state.
pub const PULSE_PINS: [(pac::gpio::Gpio, usize); 4] = [
    (pac::GPIOA, 8),
    (pac::GPIOB, 6),
    (pac::GPIOC, 6),
    (pac::GPIOB, 2),
];

/// One pulse output: a timer driving channel 1.
pub struct PulseOut<T: GeneralInstance4Channel> {
    timer: Timer<'static, T>,
    _pin: PwmPin<'static, T, Ch1>,
}

impl<T: GeneralInstance4Channel> PulseOut<T> {
    /// Configures the timer, writes the silent registers and starts it.
    pub fn new(
        timer: Timer<'static, T>,
        pin: PwmPin<'static, T, Ch1>,
        silent: &PulseRegisters,
    ) -> Self {
        timer.set_output_compare_mode(TimChannel::Ch1, OutputCompareMode::PwmMode1);
        timer.set_output_compare_preload(TimChannel::Ch1, true);
        timer.set_autoreload_preload(true);
        let out = Self { timer, _pin: pin };
        out.write(silent);
        out.timer.generate_update_event();
        out.timer.enable_channel(TimChannel::Ch1, true);
        out.timer.enable_outputs();
        out.timer.start();
        out
    }

    /// Writes PSC, ARR and CCR1; all preloaded: they take effect at the next update event.
    #[inline(always)]
    pub fn write(&self, r: &PulseRegisters) {
        let regs = self.timer.regs_core();
        regs.psc().write_value(r.psc);
        regs.arr().write(|w| w.set_arr(r.arr as u16));
        self.timer
            .regs_gp16()
            .ccr(0)
            .write(|w| w.set_ccr(r.ccr as u16));
    }
}
