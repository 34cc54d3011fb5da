//! Step accounting from the DWT cycle counter.
//!
//! The step interrupt reads `DWT.CYCCNT` on entry and again after the outputs are written,
//! and tells whether the step timer's update flag was already set again on exit (the next
//! tick came while this step ran). [`StepTiming::record`] turns that into:
//!
//! * the step duration (exit - entry, wrapping: CYCCNT wraps every 25 s at 170 MHz, far
//!   longer than a step);
//! * an **overrun** when the duration reaches the step period or the next tick is already
//!   pending: counted, and flagged to the run (never silently absorbed);
//! * **missed ticks** from the interval between two entries: an interval of k periods
//!   (rounded) means k - 1 ticks were lost, so the simulated time lags the wall clock by
//!   that many steps; counted separately.
//!
//! Maximum and mean are kept per telemetry window ([`StepTiming::take_window`]) and for
//! the whole run.

/// Statistics of a window of steps, CPU cycles.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct WindowStats {
    /// Longest step of the window, CPU cycles.
    pub max_cycles: u32,
    /// Mean step of the window (rounded), CPU cycles.
    pub mean_cycles: u32,
    /// Steps in the window.
    pub steps: u32,
}

/// What one step's timing says.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct StepVerdict {
    /// How long the step took, CPU cycles.
    pub duration_cycles: u32,
    /// The step took longer than its period.
    pub overrun: bool,
    /// Ticks lost before this step.
    pub missed_ticks: u32,
}

/// Step timing of a run.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepTiming {
    /// CPU cycles per step period (17 000 at 170 MHz and 10 kHz).
    pub period_cycles: u32,
    win_max: u32,
    win_sum: u64,
    win_steps: u32,
    /// Longest step of the run, cycles.
    pub run_max_cycles: u32,
    run_sum: u64,
    /// Steps timed in the run.
    pub run_steps: u64,
    /// Overruns in the run.
    pub overruns: u32,
    /// Ticks lost in the run.
    pub missed_ticks: u32,
    last_entry: Option<u32>,
}

impl StepTiming {
    /// Timing for a CPU clock and a step rate (both Hz).
    pub fn new(cpu_hz: u32, step_hz: u32) -> Self {
        Self {
            period_cycles: (cpu_hz / step_hz.max(1)).max(1),
            win_max: 0,
            win_sum: 0,
            win_steps: 0,
            run_max_cycles: 0,
            run_sum: 0,
            run_steps: 0,
            overruns: 0,
            missed_ticks: 0,
            last_entry: None,
        }
    }

    /// Clears the run and window statistics (a new run starts).
    pub fn reset(&mut self) {
        *self = Self::new_with_period(self.period_cycles);
    }

    fn new_with_period(period_cycles: u32) -> Self {
        let mut t = Self::new(1, 1);
        t.period_cycles = period_cycles;
        t
    }

    /// Records a step: CYCCNT at entry and exit, and whether the next tick was pending at exit.
    pub fn record(&mut self, entry: u32, exit: u32, tick_pending_at_exit: bool) -> StepVerdict {
        let duration = exit.wrapping_sub(entry);
        let mut missed = 0;
        if let Some(last) = self.last_entry {
            let interval = entry.wrapping_sub(last);
            let p = self.period_cycles;
            // Rounded number of periods since the last entry (jitter of up to half a
            // period is not a lost tick): (interval + p / 2) / p in 32 bits, where the
            // sum could overflow (interval % p + p / 2 < 2 p adds at most one period).
            let periods = interval / p + u32::from(interval % p >= p - p / 2);
            if periods >= 2 {
                missed = periods - 1;
            }
        }
        self.last_entry = Some(entry);
        let overrun = duration >= self.period_cycles || tick_pending_at_exit;
        self.win_max = self.win_max.max(duration);
        self.win_sum += duration as u64;
        self.win_steps = self.win_steps.saturating_add(1);
        self.run_max_cycles = self.run_max_cycles.max(duration);
        self.run_sum += duration as u64;
        self.run_steps += 1;
        if overrun {
            self.overruns = self.overruns.saturating_add(1);
        }
        self.missed_ticks = self.missed_ticks.saturating_add(missed);
        StepVerdict {
            duration_cycles: duration,
            overrun,
            missed_ticks: missed,
        }
    }

    /// Max and mean since the last call, and starts a new window.
    pub fn take_window(&mut self) -> WindowStats {
        let s = WindowStats {
            max_cycles: self.win_max,
            mean_cycles: if self.win_steps > 0 {
                crate::pulse::div_u64(self.win_sum, self.win_steps as u64) as u32
            } else {
                0
            },
            steps: self.win_steps,
        };
        self.win_max = 0;
        self.win_sum = 0;
        self.win_steps = 0;
        s
    }

    /// Mean step of the run, cycles.
    pub fn run_mean_cycles(&self) -> u32 {
        if self.run_steps > 0 {
            (self.run_sum / self.run_steps) as u32
        } else {
            0
        }
    }
}

/// Cycles to microseconds.
pub fn cycles_to_us(cycles: u32, cpu_hz: u32) -> f32 {
    cycles as f32 * 1.0e6 / cpu_hz.max(1) as f32
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn max_mean_and_window_reset() {
        let mut t = StepTiming::new(170_000_000, 10_000);
        assert_eq!(t.period_cycles, 17_000);
        let mut entry = 1000u32;
        for d in [5000u32, 7000, 6000] {
            let v = t.record(entry, entry + d, false);
            assert!(!v.overrun);
            assert_eq!(v.missed_ticks, 0);
            entry += 17_000;
        }
        assert_eq!(
            t.take_window(),
            WindowStats {
                max_cycles: 7000,
                mean_cycles: 6000,
                steps: 3
            }
        );
        assert_eq!(t.take_window(), WindowStats::default());
        assert_eq!(t.run_max_cycles, 7000);
        assert_eq!(t.run_mean_cycles(), 6000);
    }

    #[test]
    fn overrun_by_duration_or_pending_tick_is_counted() {
        let mut t = StepTiming::new(170_000_000, 10_000);
        assert!(t.record(0, 17_000, false).overrun);
        assert!(!t.record(17_000, 17_000 + 16_999, false).overrun);
        assert!(t.record(34_000, 34_100, true).overrun);
        assert_eq!(t.overruns, 2);
    }

    #[test]
    fn missed_ticks_from_entry_intervals_with_jitter_tolerance() {
        let mut t = StepTiming::new(170_000_000, 10_000);
        t.record(0, 100, false);
        // Jitter of +-40 % of a period: no lost tick.
        assert_eq!(
            t.record(17_000 + 6_800, 17_000 + 6_900, false).missed_ticks,
            0
        );
        assert_eq!(t.record(34_000 - 6_000, 34_000, false).missed_ticks, 0);
        // 3 periods later: 2 ticks lost.
        assert_eq!(
            t.record(28_000 + 51_000, 28_000 + 51_100, false)
                .missed_ticks,
            2
        );
        assert_eq!(t.missed_ticks, 2);
    }

    /// Missed ticks after `interval` cycles as the 64-bit formula counts them: rounded
    /// periods (interval + p / 2) / p, less the one expected.
    fn missed_ticks_64(interval: u32, period: u32) -> u64 {
        let periods = (interval as u64 + period as u64 / 2) / period as u64;
        periods.saturating_sub(1)
    }

    proptest::proptest! {
        /// The missed ticks counted in 32 bits equal the 64-bit formula's, at any interval
        /// (up to 2^32 cycles, where the 32-bit sum would overflow) and on either side of
        /// each rounding boundary (half a period past a whole number of periods).
        #[test]
        fn missed_ticks_equal_the_64_bit_rounding(
            period in proptest::prop_oneof![1u32..40_000, 1u32..=u32::MAX],
            any_interval in proptest::prop_oneof![0u32..200_000, (u32::MAX - 200_000)..=u32::MAX, 0u32..=u32::MAX],
            whole_periods in 0u64..5_000,
            offset in -1i64..=1,
        ) {
            let boundary = whole_periods * period as u64 + (period - period / 2) as u64;
            let near_boundary = u32::try_from(boundary as i64 + offset).unwrap_or(u32::MAX);
            for interval in [any_interval, near_boundary] {
                let mut t = StepTiming::new_with_period(period);
                t.record(0, 0, false);
                let missed = t.record(interval, interval, false).missed_ticks;
                proptest::prop_assert_eq!(missed as u64, missed_ticks_64(interval, period));
            }
        }
    }

    #[test]
    fn cycle_counter_wrap_is_handled() {
        let mut t = StepTiming::new(170_000_000, 10_000);
        let entry = u32::MAX - 500;
        let v = t.record(entry, entry.wrapping_add(4000), false);
        assert_eq!(v.duration_cycles, 4000);
        let v = t.record(
            entry.wrapping_add(17_000),
            entry.wrapping_add(21_000),
            false,
        );
        assert_eq!(
            (v.duration_cycles, v.missed_ticks, v.overrun),
            (4000, 0, false)
        );
    }

    #[test]
    fn reset_keeps_the_period() {
        let mut t = StepTiming::new(170_000_000, 10_000);
        t.record(0, 20_000, false);
        t.reset();
        assert_eq!((t.period_cycles, t.overruns, t.run_steps), (17_000, 0, 0));
        assert_eq!(cycles_to_us(17_000, 170_000_000), 100.0);
    }
}
