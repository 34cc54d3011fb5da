//! Pulse trains like axle speed sensors: f = teeth x omega / 2 pi.
//!
//! Each wheelset drives one timer channel in PWM mode 1 at 50 % duty: the output frequency
//! is f = f_timer / ((PSC + 1)(ARR + 1)). [`PulseTimer::registers`] picks the smallest
//! prescaler that lets ARR + 1 fit the counter and splits the period into whole counts
//! (ARR + 1) and a fraction of a count in 1/256 (`arr_frac`). One period is within a count
//! of the exact one: a relative error below 1 / (ARR + 1), and ARR + 1 >= 32768 whenever
//! the prescaler is above 1, so below 0.0031 % from 0.04 Hz up to 2.6 kHz and below 0.2 %
//! up to f_timer / 500 (340 kHz at 170 MHz). [`PulseChannel`] dithers ARR between periods
//! so that the mean period carries the fraction too: the mean frequency is exact to 1/256
//! count (below 1.2e-7 of the speed up to 2.6 kHz), and a held speed shows no staircase.
//! Above f_timer / 500 the frequency is held there (a wheel of 1000 teeth at 300 rad/s
//! gives 48 kHz).
//!
//! **Standstill.** Below [`MIN_FREQUENCY_HZ`] (0.5 Hz: one edge per second or less is no
//! speed signal) and for NaN the output is silent: CCR = 0 holds the pin low, with a short
//! 0.1 ms period so that the next setting takes effect at once.
//!
//! **Update** ([`update`], [`apply`]; RM0440 TIMx_CR1.UDIS, TIMx_EGR.UG, TIMx_CCMRx.OCxM).
//! A new frequency is written with preload (ARR and CCR preloaded, PSC always is) under
//! CR1.UDIS, so an update event that falls between the three writes cannot load a mixed
//! PSC/ARR pair (a wrong frequency for one period; possible whenever the prescaler changes,
//! e.g. at 1297 Hz, ~140 km/h with 90 teeth): the new frequency starts at the end of the
//! running period, without a runt pulse, as a real sensor's change shows within a period.
//! Going silent (safe state) does not wait for the running period (up to 2 s at 0.5 Hz):
//! the output is forced inactive at once (OCxM = force inactive) and the silent registers
//! are loaded (UG, with UDIS clear: UG does not load them while UDIS is set). Leaving
//! silence loads the new registers at once (UG) and restores PWM mode 1. Unchanged
//! registers are not written; a new duty at the same PSC and ARR (the service demand PWM) writes
//! CCR alone.

use core::f32::consts::TAU;

/// Below this the output is silent, Hz.
pub const MIN_FREQUENCY_HZ: f32 = 0.5;

/// Register values of one pulse channel (written as they are).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PulseRegisters {
    /// TIMx_PSC: prescaler - 1.
    pub psc: u16,
    /// TIMx_ARR: period - 1, counts.
    pub arr: u32,
    /// TIMx_CCRy: high time, counts (0 = silent).
    pub ccr: u32,
    /// The period's fraction of a count above ARR + 1, in 1/256: the channel dithers ARR
    /// between ARR and ARR + 1 from one timer period to the next ([`PulseChannel`]), so that
    /// the mean period is ARR + 1 + `arr_frac` / 256 counts (0: every period ARR + 1).
    pub arr_frac: u8,
}

impl PulseRegisters {
    /// Whether the output is silent (no pulses: CCR 0).
    pub fn is_silent(&self) -> bool {
        self.ccr == 0
    }
}

/// A timer that makes a pulse train.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PulseTimer {
    /// Counter clock before the prescaler, Hz (170 MHz on the G474 at full speed).
    pub clock_hz: u32,
    /// Largest ARR + 1 (65536 for a 16-bit counter).
    pub max_period: u32,
}

/// Axle-speed-sensor frequency of a wheelset, Hz: teeth |omega| / 2 pi (a speed sensor
/// has no direction). NaN stays NaN (silent).
#[inline]
pub fn wheel_frequency_hz(omega_radps: f32, teeth: u16) -> f32 {
    teeth as f32 * omega_radps.abs() / TAU
}

/// `a / b` (b > 0), with the Cortex-M4's 32-bit hardware division when both fit in 32
/// bits (a timer's counts always do below 2.1 GHz) instead of the software 64-bit one
/// (~100 instructions each; the step computes four channels' registers every tick).
/// The same quotient either way.
#[inline]
pub(crate) fn div_u64(a: u64, b: u64) -> u64 {
    match (u32::try_from(a), u32::try_from(b)) {
        (Ok(a), Ok(b)) => (a / b) as u64,
        _ => div_u64_wide(a, b),
    }
}

/// The software 64-bit division of [`div_u64`], out of line and cold: the board keeps it
/// in flash (firmware/board/ccm.x), so the step's CCM SRAM code holds no 64-bit division.
#[cold]
#[inline(never)]
fn div_u64_wide(a: u64, b: u64) -> u64 {
    a / b
}

/// `x as u64` for a finite `x >= 0`, with the FPU's conversion to 32 bits when `x` fits
/// (instead of the software one to 64 bits). The same value either way: both truncate.
#[inline]
fn u64_of(x: f32) -> u64 {
    if x < 4_294_967_296.0 {
        x as u32 as u64
    } else {
        u64_of_wide(x)
    }
}

/// The software conversion of [`u64_of`], out of line and cold (in flash on the board,
/// as [`div_u64_wide`]).
#[cold]
#[inline(never)]
fn u64_of_wide(x: f32) -> u64 {
    x as u64
}

impl PulseTimer {
    /// A 16-bit timer at `clock_hz`.
    pub const fn timer16(clock_hz: u32) -> Self {
        Self {
            clock_hz,
            max_period: 1 << 16,
        }
    }

    /// Highest frequency set exactly to 0.1 %, Hz.
    pub fn max_frequency_hz(&self) -> f32 {
        self.clock_hz as f32 / 500.0
    }

    /// Largest usable ARR + 1: a PWM period needs at least 2 counts, whatever the
    /// configuration says (a `max_period` below 2 is a configuration error, not a panic).
    fn usable_max_period(&self) -> u32 {
        self.max_period.max(2)
    }

    /// The silent setting: output low, 0.1 ms period.
    pub fn silent(&self) -> PulseRegisters {
        let period = (self.clock_hz / 10_000).clamp(2, self.usable_max_period());
        PulseRegisters {
            psc: 0,
            arr: period - 1,
            ccr: 0,
            arr_frac: 0,
        }
    }

    /// Registers for a frequency (Hz); silent below [`MIN_FREQUENCY_HZ`] or for NaN.
    pub fn registers(&self, frequency_hz: f32) -> PulseRegisters {
        if !(frequency_hz >= MIN_FREQUENCY_HZ) || self.clock_hz == 0 {
            return self.silent();
        }
        let f = frequency_hz.min(self.max_frequency_hz());
        // Counts of one period at the undivided clock (f >= 0.5 Hz: at most 2 f_clk, which
        // fits a u64 and, for f_clk <= 2.1 GHz, a u32).
        let counts = u64_of(self.clock_hz as f32 / f + 0.5);
        let max_period = self.usable_max_period() as u64;
        let prescale = div_u64(counts + max_period - 1, max_period).clamp(1, 1 << 16);
        // The period in prescaled counts with its fraction (f32 holds 8 bits of fraction up
        // to 65536 counts): ARR + 1 is its whole part, `arr_frac` the rest, dithered.
        let exact = self.clock_hz as f32 / (f * prescale as f32);
        let whole = u64_of(exact);
        let (period, frac) = if whole < 2 {
            (2, 0)
        } else if whole >= max_period {
            (max_period, 0)
        } else {
            (whole, ((exact - whole as f32) * 256.0) as u32)
        };
        PulseRegisters {
            psc: (prescale - 1) as u16,
            arr: (period - 1) as u32,
            ccr: (period / 2) as u32,
            arr_frac: frac.min(255) as u8,
        }
    }

    /// The mean frequency a register setting produces, Hz (0 when silent): over the
    /// dithered periods of a [`PulseChannel`], ARR + 1 + `arr_frac` / 256 counts each.
    pub fn frequency_of(&self, r: &PulseRegisters) -> f64 {
        if r.is_silent() {
            return 0.0;
        }
        let period = r.arr as f64 + 1.0 + r.arr_frac as f64 / 256.0;
        self.clock_hz as f64 / ((r.psc as f64 + 1.0) * period)
    }
}

/// How the board writes a channel's registers for a new setting ([`update`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PulseUpdate {
    /// The same setting: nothing to write.
    Keep,
    /// A new frequency: PSC, ARR, CCR written under UDIS, loaded at the running period's end.
    Preload(PulseRegisters),
    /// The same frequency, a new duty (the service demand PWM): CCR only, loaded at the
    /// running period's end (one register write).
    Duty(u32),
    /// Silent at once: output forced inactive, the silent registers loaded (UG).
    SilenceNow(PulseRegisters),
    /// From silent to a frequency: registers loaded at once (UG), PWM mode 1 again.
    Resume(PulseRegisters),
}

/// The update from the registers last written to `next` (module doc). `arr_frac` is not a
/// register: only PSC, ARR and CCR count.
pub fn update(last: &PulseRegisters, next: &PulseRegisters) -> PulseUpdate {
    if (last.psc, last.arr, last.ccr) == (next.psc, next.arr, next.ccr) {
        PulseUpdate::Keep
    } else if next.is_silent() {
        PulseUpdate::SilenceNow(*next)
    } else if last.is_silent() {
        PulseUpdate::Resume(*next)
    } else if (last.psc, last.arr) == (next.psc, next.arr) {
        PulseUpdate::Duty(next.ccr)
    } else {
        PulseUpdate::Preload(*next)
    }
}

/// The registers of one pulse timer channel as [`apply`] drives them (the board implements
/// it over TIM1/TIM8/TIM20/TIM15 channel 1).
pub trait PulseTimerRegs {
    /// TIMx_CR1.UDIS: no update event (the shadow registers keep their values).
    fn set_update_disable(&mut self, disable: bool);
    /// TIMx_PSC (preloaded).
    fn write_prescaler(&mut self, psc: u16);
    /// TIMx_ARR (preloaded, ARPE).
    fn write_period(&mut self, arr: u32);
    /// TIMx_CCR1 (preloaded, OC1PE).
    fn write_compare(&mut self, ccr: u32);
    /// TIMx_CCMR1.OC1M: PWM mode 1 (`true`) or force inactive (`false`), at once.
    fn set_pwm(&mut self, pwm: bool);
    /// TIMx_EGR.UG: counter to 0 and the preloaded registers into the shadows at once.
    fn generate_update(&mut self);
    /// TIMx_SR.UIF, read and cleared: whether an update event (a new period, or UG) happened
    /// since the last call.
    fn take_update_flag(&mut self) -> bool;
}

/// PSC, ARR and CCR under UDIS (no update event between them).
#[inline]
fn write<T: PulseTimerRegs>(t: &mut T, r: &PulseRegisters) {
    t.set_update_disable(true);
    t.write_prescaler(r.psc);
    t.write_period(r.arr);
    t.write_compare(r.ccr);
    t.set_update_disable(false);
}

/// Writes an update in the order that keeps every period whole (module doc).
#[inline]
pub fn apply(u: PulseUpdate, t: &mut impl PulseTimerRegs) {
    match u {
        PulseUpdate::Keep => {}
        PulseUpdate::Preload(r) => write(t, &r),
        PulseUpdate::Duty(ccr) => t.write_compare(ccr),
        PulseUpdate::SilenceNow(r) => {
            t.set_pwm(false);
            write(t, &r);
            t.generate_update();
        }
        PulseUpdate::Resume(r) => {
            write(t, &r);
            t.generate_update();
            t.set_pwm(true);
        }
    }
}

/// One pulse channel as the step drives it: [`update`] and [`apply`] from the registers
/// last written, with the period dithered so that its mean is exact.
///
/// **Dither** (a first-order sigma-delta over the timer's periods). A 16-bit period's
/// resolution is one count in ARR + 1 (1.5e-5 to 3e-5 of the speed between 0.04 Hz and
/// 2.6 kHz): held for many periods, that staircase is a speed error a WSP unit's
/// deceleration filter sees. The channel keeps a residue, the sum of the fractions of the
/// periods so far modulo 256. Each step writes ARR + 1 when the residue plus the setting's
/// `arr_frac` carries over 256, ARR otherwise (preloaded: it is the next period's). At each
/// update event (a new period started, TIMx_SR.UIF, read once per step) the residue takes
/// the fraction of the setting that period was loaded from. So the periods' lengths sum to
/// the settings' exact periods within one count, whatever the settings do between update
/// events. Should more than one period end within a step (above 10 kHz), the residue takes
/// one fraction for them: the mean stays within one count over the step.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PulseChannel {
    /// The registers as last written (ARR with the dither's count; `arr_frac` the
    /// setting's).
    written: PulseRegisters,
    /// Sum of the fractions of the periods so far, modulo 256.
    residue: u8,
}

impl PulseChannel {
    /// A channel whose timer holds `silent` ([`PulseTimer::silent`]).
    pub const fn new(silent: PulseRegisters) -> Self {
        Self {
            written: silent,
            residue: 0,
        }
    }

    /// The registers as last written (with the dither's count in ARR).
    pub fn written(&self) -> PulseRegisters {
        self.written
    }

    /// The step's new setting `r`: the residue advanced if a period started since the last
    /// step, then the update from the registers last written to `r` with the dither's
    /// count (type doc).
    #[inline]
    pub fn write(&mut self, r: &PulseRegisters, t: &mut impl PulseTimerRegs) {
        if t.take_update_flag() {
            self.residue = self.residue.wrapping_add(self.written.arr_frac);
        }
        let mut next = *r;
        // A fraction above 0 leaves ARR + 2 within the counter (`PulseTimer::registers`).
        if !r.is_silent() && r.arr_frac > 0 {
            next.arr += self.residue.checked_add(r.arr_frac).is_none() as u32;
        } else {
            next.arr_frac = 0;
        }
        apply(update(&self.written, &next), t);
        self.written = next;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const TIMER: PulseTimer = PulseTimer::timer16(170_000_000);

    /// Independent f64 reference: f = teeth omega / 2 pi.
    fn exact(omega: f64, teeth: u16) -> f64 {
        teeth as f64 * omega / (2.0 * std::f64::consts::PI)
    }

    #[test]
    fn silent_at_standstill_and_for_nan() {
        for omega in [0.0f32, -0.0, 1e-6, f32::NAN] {
            let r = TIMER.registers(wheel_frequency_hz(omega, 90));
            assert!(r.is_silent(), "{omega}");
            assert_eq!(TIMER.frequency_of(&r), 0.0);
        }
        // 0.5 Hz at 90 teeth: omega = 0.0349 rad/s; just above it runs.
        assert!(!TIMER.registers(wheel_frequency_hz(0.036, 90)).is_silent());
    }

    #[test]
    fn paper_speeds_within_a_thousandth() {
        // 150 km/h on a 0.43 m wheel, 90 teeth: 1388.0 Hz, 122 479 clock counts: prescaler 2.
        let omega = 150.0 / 3.6 / 0.43;
        let r = TIMER.registers(wheel_frequency_hz(omega as f32, 90));
        let err = (TIMER.frequency_of(&r) / exact(omega, 90) - 1.0).abs();
        assert!(err < 1e-5, "{err}");
        assert_eq!(r.psc, 1);
        let half_period = 170e6 / exact(omega, 90) / 2.0;
        assert!(
            (r.arr as f64 + 1.0 - half_period).abs() <= 1.0,
            "{} vs {half_period}",
            r.arr
        );
    }

    #[test]
    fn error_sweep_5hz_to_max() {
        // Log sweep of frequencies over teeth 1..1000: worst relative error.
        let mut worst = 0.0f64;
        for teeth in [1u16, 7, 48, 90, 120, 1000] {
            let mut omega = 5.0 * 2.0 * std::f64::consts::PI / teeth as f64;
            while exact(omega, teeth) < TIMER.max_frequency_hz() as f64 {
                let r = TIMER.registers(wheel_frequency_hz(omega as f32, teeth));
                let e = (TIMER.frequency_of(&r) / exact(omega, teeth) - 1.0).abs();
                worst = worst.max(e);
                omega *= 1.0137;
            }
        }
        assert!(worst <= 1e-3, "worst relative error {worst}");
    }

    #[test]
    fn duty_is_half_and_registers_fit_16_bits() {
        for f in [
            0.5f32,
            0.51,
            3.0,
            17.0,
            999.0,
            2593.0,
            40_000.0,
            1e6,
            f32::INFINITY,
        ] {
            let r = TIMER.registers(f);
            assert!(r.arr <= 0xFFFF && r.arr >= 1, "{f}");
            assert_eq!(r.ccr, (r.arr + 1) / 2);
        }
        // Above the exact range the frequency is held at f_clk / 500.
        let r = TIMER.registers(1e9);
        assert!((TIMER.frequency_of(&r) - 340_000.0).abs() < 1.0);
    }

    /// A 16-bit timer as RM0440 describes the parts used: PSC, ARR, CCR1 preloaded into
    /// shadows at an update event (overflow or UG), none while UDIS is set (UG then only
    /// resets the counter); OC1M takes effect at once.
    #[derive(Clone, Default)]
    struct Timer {
        pre: PulseRegisters,
        shadow: PulseRegisters,
        udis: bool,
        pwm: bool,
        /// An overflow happens right after this many register writes (None: never).
        overflow_after: Option<usize>,
        writes: usize,
        /// Every shadow set the timer ran a period with.
        periods: std::vec::Vec<PulseRegisters>,
    }

    impl Timer {
        fn running(r: PulseRegisters) -> Self {
            Self {
                pre: r,
                shadow: r,
                pwm: true,
                ..Default::default()
            }
        }
        fn update_event(&mut self) {
            if !self.udis {
                self.shadow = self.pre;
            }
            self.periods.push(self.shadow);
        }
        fn wrote(&mut self) {
            self.writes += 1;
            if self.overflow_after == Some(self.writes) {
                self.update_event();
            }
        }
        /// The pin now: low when forced inactive or CCR 0.
        fn output_can_be_high(&self) -> bool {
            self.pwm && self.shadow.ccr > 0
        }
    }

    impl PulseTimerRegs for Timer {
        fn set_update_disable(&mut self, d: bool) {
            self.udis = d;
            self.wrote();
        }
        fn write_prescaler(&mut self, psc: u16) {
            self.pre.psc = psc;
            self.wrote();
        }
        fn write_period(&mut self, arr: u32) {
            self.pre.arr = arr;
            self.wrote();
        }
        fn write_compare(&mut self, ccr: u32) {
            self.pre.ccr = ccr;
            self.wrote();
        }
        fn set_pwm(&mut self, pwm: bool) {
            self.pwm = pwm;
            self.wrote();
        }
        fn generate_update(&mut self) {
            if !self.udis {
                self.shadow = self.pre;
            }
            self.wrote();
        }
        fn take_update_flag(&mut self) -> bool {
            false
        }
    }

    /// The registers of `f` as a timer holds them (no fraction: that is not a register).
    fn regs(f: f32) -> PulseRegisters {
        PulseRegisters {
            arr_frac: 0,
            ..TIMER.registers(f)
        }
    }

    #[test]
    fn an_update_event_between_the_writes_never_loads_a_mixed_setting() {
        // 1297 Hz: the prescaler changes between these two (PSC 1 -> 2).
        let (a, b) = (regs(1300.0), regs(1290.0));
        assert_ne!(a.psc, b.psc);
        for at in 0..8 {
            let mut t = Timer::running(a);
            t.overflow_after = Some(at);
            apply(update(&a, &b), &mut t);
            t.update_event();
            assert!(
                t.periods.iter().all(|p| *p == a || *p == b),
                "overflow after write {at}: {:?}",
                t.periods
            );
            assert_eq!(t.shadow, b);
        }
        // Negative control: the same writes without UDIS load a mixed pair for some timing.
        let mixed = (0..4).any(|at| {
            let mut t = Timer::running(a);
            t.overflow_after = Some(at);
            t.write_prescaler(b.psc);
            t.write_period(b.arr);
            t.write_compare(b.ccr);
            t.periods.iter().any(|p| *p != a && *p != b)
        });
        assert!(mixed);
    }

    #[test]
    fn going_silent_is_at_once_and_coming_back_too() {
        let slow = regs(0.6); // a 1.7 s period
        let silent = TIMER.silent();
        let mut t = Timer::running(slow);
        let u = update(&slow, &silent);
        assert_eq!(u, PulseUpdate::SilenceNow(silent));
        apply(u, &mut t);
        // Low now, without waiting for the running period; the silent setting loaded.
        assert!(!t.output_can_be_high());
        assert_eq!((t.shadow, t.udis), (silent, false));
        let fast = regs(1388.0);
        let u = update(&silent, &fast);
        assert_eq!(u, PulseUpdate::Resume(fast));
        apply(u, &mut t);
        assert!(t.output_can_be_high());
        assert_eq!(t.shadow, fast);
        assert_eq!(update(&fast, &fast), PulseUpdate::Keep);
        assert_eq!(update(&fast, &slow), PulseUpdate::Preload(slow));
    }

    #[test]
    fn a_new_duty_at_the_same_frequency_is_one_write_loaded_at_the_period_end() {
        let a = regs(500.0);
        let b = PulseRegisters {
            ccr: a.ccr / 5,
            ..a
        };
        let u = update(&a, &b);
        assert_eq!(u, PulseUpdate::Duty(b.ccr));
        let mut t = Timer::running(a);
        apply(u, &mut t);
        assert_eq!((t.writes, t.shadow), (1, a));
        t.update_event();
        assert_eq!(t.shadow, b);
        // A new period is never a duty-only update.
        assert!(matches!(update(&a, &regs(400.0)), PulseUpdate::Preload(_)));
    }

    proptest! {
        /// Any timer configuration (a `max_period` below 2 or a stopped clock included) and
        /// any frequency: no panic, the registers fit the counter, a clock of 0 is silent.
        #[test]
        fn any_configuration_any_frequency(
            clock_hz in proptest::num::u32::ANY,
            max_period in prop_oneof![0u32..4, proptest::num::u32::ANY],
            f in proptest::num::f32::ANY,
        ) {
            let timer = PulseTimer { clock_hz, max_period };
            let r = timer.registers(f);
            prop_assert!(r.arr >= 1 && r.arr < max_period.max(2));
            // The dither's long period fits too.
            prop_assert!(r.arr_frac == 0 || r.arr + 1 < max_period.max(2));
            prop_assert!(r.ccr <= r.arr);
            if clock_hz == 0 || !(f >= MIN_FREQUENCY_HZ) {
                prop_assert!(r.is_silent());
            }
        }

        #[test]
        fn any_speed_any_teeth(omega in proptest::num::f32::ANY, teeth in 1u16..=1000) {
            let f = wheel_frequency_hz(omega, teeth);
            let r = TIMER.registers(f);
            prop_assert!(r.arr <= 0xFFFF);
            let got = TIMER.frequency_of(&r);
            let want = exact(omega.abs() as f64, teeth);
            if want.is_finite() && want >= 5.0 && want <= TIMER.max_frequency_hz() as f64 {
                prop_assert!((got / want - 1.0).abs() <= 1e-3, "{} vs {}", got, want);
            }
            if !(f >= MIN_FREQUENCY_HZ) {
                prop_assert!(r.is_silent());
            }
        }
    }
}
