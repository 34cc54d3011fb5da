//! A counting model of one pulse timer channel as RM0440 describes the parts the rig uses
//! (TIMx upcounting, PWM mode 1 on channel 1), for host tests and the simulated rig
//! (`hils rig --interface sim`): what a controller's speed sensor input sees of the pulse
//! train the step writes through [`crate::pulse::PulseChannel`].
//!
//! * PSC, ARR and CCR1 are preloaded: they reach the shadow registers the counter runs
//!   with at an update event (the counter passing ARR, or UG), none while CR1.UDIS is set
//!   (UG then only restarts the counter).
//! * An update event sets SR.UIF (CR1.URS = 0, the reset value the board keeps).
//! * CCMR1.OC1M (PWM mode 1 or force inactive) takes effect at once.
//!
//! The counter is kept in counts of the undivided clock; a period of PSC and ARR lasts
//! (PSC + 1)(ARR + 1) of them.

use crate::pulse::{PulseRegisters, PulseTimerRegs};

/// One timer channel, counting.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CountingTimer {
    preload: PulseRegisters,
    shadow: PulseRegisters,
    update_disabled: bool,
    pwm: bool,
    update_flag: bool,
    /// Undivided clock counts into the running period.
    phase: u64,
    /// Length of the last period that ended, undivided clock counts (None: none ended
    /// since the output was last silent).
    last_period: Option<u64>,
}

impl CountingTimer {
    /// A timer running `r` (as after the board's start with the silent registers).
    pub fn new(r: PulseRegisters) -> Self {
        Self {
            preload: r,
            shadow: r,
            update_disabled: false,
            pwm: true,
            update_flag: false,
            phase: 0,
            last_period: None,
        }
    }

    /// Length of the running period, undivided clock counts (at least 1).
    fn period(&self) -> u64 {
        (self.shadow.psc as u64 + 1) * (self.shadow.arr as u64 + 1)
    }

    /// Whether the pin can go high: PWM mode and a compare value above 0.
    pub fn is_pulsing(&self) -> bool {
        self.pwm && self.shadow.ccr > 0
    }

    /// The registers the counter runs with now.
    pub fn shadow(&self) -> PulseRegisters {
        self.shadow
    }

    fn update_event(&mut self) {
        if !self.update_disabled {
            self.shadow = self.preload;
            self.update_flag = true;
        }
    }

    /// Runs for `clock_counts` counts of the undivided clock: each period that ends is an
    /// update event. Returns how many pulse periods ended.
    pub fn run(&mut self, clock_counts: u64) -> u32 {
        self.phase += clock_counts;
        let mut ended = 0;
        while self.phase >= self.period() {
            self.phase -= self.period();
            if self.is_pulsing() {
                self.last_period = Some(self.period());
                ended += 1;
            }
            self.update_event();
        }
        if !self.is_pulsing() {
            self.last_period = None;
        }
        ended
    }

    /// The length of the last whole pulse period, undivided clock counts: what an input
    /// that measures the period between rising edges read last (None while silent and
    /// until the first period after silence ends).
    pub fn last_period_counts(&self) -> Option<u64> {
        self.last_period.filter(|_| self.is_pulsing())
    }
}

impl PulseTimerRegs for CountingTimer {
    fn set_update_disable(&mut self, disable: bool) {
        self.update_disabled = disable;
    }
    fn write_prescaler(&mut self, psc: u16) {
        self.preload.psc = psc;
    }
    fn write_period(&mut self, arr: u32) {
        self.preload.arr = arr;
    }
    fn write_compare(&mut self, ccr: u32) {
        self.preload.ccr = ccr;
    }
    fn set_pwm(&mut self, pwm: bool) {
        self.pwm = pwm;
        if !pwm {
            self.last_period = None;
        }
    }
    fn generate_update(&mut self) {
        self.phase = 0;
        self.update_event();
    }
    fn take_update_flag(&mut self) -> bool {
        core::mem::take(&mut self.update_flag)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pulse::{PulseChannel, PulseTimer};
    use proptest::prelude::*;

    const TIMER: PulseTimer = PulseTimer::timer16(170_000_000);
    /// Undivided clock counts per 0.1 ms step.
    const STEP_COUNTS: u64 = 17_000;

    /// A channel stepped at 10 kHz with the setting `f(step)`: the lengths of the periods
    /// that ended, undivided clock counts (the first, started from silence, left out).
    fn run(steps: usize, f: impl Fn(usize) -> f32) -> std::vec::Vec<u64> {
        let mut t = CountingTimer::new(TIMER.silent());
        let mut ch = PulseChannel::new(TIMER.silent());
        let mut periods = std::vec::Vec::new();
        for k in 0..steps {
            for _ in 0..t.run(STEP_COUNTS) {
                periods.extend(t.last_period_counts());
            }
            ch.write(&TIMER.registers(f(k)), &mut t);
        }
        periods.split_off(1)
    }

    fn mean(periods: &[u64]) -> f64 {
        periods.iter().sum::<u64>() as f64 / periods.len() as f64
    }

    #[test]
    fn a_constant_frequency_is_exact_on_average_and_each_period_within_a_count() {
        // 1388.3 Hz (150 km/h, 90 teeth, 0.43 m): 122 451.5 counts, prescaler 2.
        let f = 1388.3f32;
        let r = TIMER.registers(f);
        assert_eq!(r.psc, 1);
        assert!(r.arr_frac > 0);
        let periods = run(200_000, |_| f);
        // Every period ARR + 1 or ARR + 2 prescaled counts.
        let short = 2 * (r.arr as u64 + 1);
        assert!(periods.iter().all(|&p| p == short || p == short + 2));
        // The mean against 170e6 / f in f64 (independent): within the f32 fraction's
        // 1/256 count (2 undivided counts per prescaled one) and the run's edge.
        let want = 170e6 / f as f64;
        let got = mean(&periods);
        let edge = 2.0 * 256.0 / periods.len() as f64;
        assert!(
            (got - want).abs() < 2.0 * 2.0 / 256.0 + edge,
            "{got} vs {want}"
        );
        // Without the dither every period would be ARR + 1: off by the fraction.
        assert!((short as f64 - want).abs() > 0.1);
    }

    #[test]
    fn the_dither_choice_survives_new_settings_between_update_events() {
        // The setting alternates every step between two periods one count apart with half
        // a count of fraction each (61 000.5 and 61 001.5 prescaled counts at PSC 1): a
        // new ARR is written between nearly every two update events. Their periods must
        // average 61 001.0; losing the long period's count at each write would give about
        // 61 000.5.
        let fs = [170e6 / (2.0 * 61_000.5), 170e6 / (2.0 * 61_001.5)].map(|f: f64| f as f32);
        for f in fs {
            let r = TIMER.registers(f);
            assert_eq!(r.psc, 1);
            assert!((r.arr_frac as i32 - 128).abs() <= 2, "{}", r.arr_frac);
        }
        let periods = run(100_000, |k| fs[k % 2]);
        let got = mean(&periods) / 2.0;
        assert!((got - 61_001.0).abs() < 0.05, "{got}");
    }

    #[test]
    fn a_braking_wheel_s_periods_sum_to_the_settings_they_were_loaded_from() {
        // 1 m/s^2 from 150 km/h at 90 teeth: the period grows by about 1.5 counts per
        // period, so ARR and the fraction change between any two update events. Each
        // period against the exact mean of the setting it was loaded from (the last one
        // written before its start): the sum of the differences stays within a count
        // (sigma-delta); deciding with the fraction of an older setting would not.
        let f0 = 1388.3f64;
        let mut t = CountingTimer::new(TIMER.silent());
        let mut ch = PulseChannel::new(TIMER.silent());
        let (mut loading, mut running) = (None::<f64>, None::<f64>);
        let (mut sum_error, mut n, mut sum_abs) = (0.0f64, 0, 0.0f64);
        for k in 0..50_000 {
            let ended = t.run(STEP_COUNTS);
            if ended == 1 {
                if let (Some(p), Some(want)) = (t.last_period_counts(), running) {
                    sum_error += p as f64 - want;
                    sum_abs += (p as f64 - want).abs();
                    n += 1;
                }
            }
            if ended > 0 {
                running = loading;
            }
            let r = TIMER.registers((f0 * (1.0 - 2.4e-6 * k as f64)) as f32);
            ch.write(&r, &mut t);
            loading = Some(170e6 / TIMER.frequency_of(&r));
        }
        assert!(n > 3000, "{n} periods");
        // Undivided counts: 2 per prescaled count at PSC 1.
        assert!(sum_error.abs() <= 2.0 * 1.1, "{sum_error} over {n} periods");
        // And each period within one count of its setting.
        assert!(sum_abs / n as f64 <= 2.0, "{}", sum_abs / n as f64);
    }

    proptest! {
        /// Any frequency in range: the dithered periods average to the setting's mean
        /// frequency (`frequency_of`) within 1/256 count, and that within 2/256 count of
        /// the f64 period.
        #[test]
        fn dithered_mean_equals_the_setting(f in 0.6f32..20_000.0) {
            let r = TIMER.registers(f);
            let prescaled = r.psc as f64 + 1.0;
            let mean_counts = 170e6 / TIMER.frequency_of(&r) / prescaled;
            let exact = 170e6 / f as f64 / prescaled;
            prop_assert!((mean_counts - exact).abs() <= 2.0 / 256.0, "{} vs {}", mean_counts, exact);
            let mut ch = PulseChannel::new(TIMER.silent());
            let mut t = CountingTimer::new(TIMER.silent());
            ch.write(&r, &mut t);
            let mut periods = std::vec::Vec::new();
            for _ in 0..1024 {
                // A step right after each update event: the channel sees each period start.
                t.run(t.period() - t.phase);
                periods.extend(t.last_period_counts());
                ch.write(&r, &mut t);
            }
            let n = periods.len() as f64;
            let mean = mean(&periods) / prescaled;
            prop_assert!((mean - mean_counts).abs() <= 2.0 / 256.0 + 2.0 / n,
                "{} vs {}", mean, mean_counts);
        }
    }
}
