//! Brake-input channels: ADC oversampling, calibration, scaling and plausibility.
//!
//! Each of the four channels is a caliper **load cell** (pad normal force per friction face,
//! N: the plant's `BrakeInput::ClampForce`) or a cylinder **pressure transducer** (Pa: the
//! plant's `BrakeInput::CylinderPressure`, turned into clamp force by paper Eq (1) inside
//! the plant). Both are "live zero" sensors whose conditioning amplifier gives 10 % of the
//! ADC range at zero load and 90 % at full scale (defaults: 40 kN, 1 MPa); the input has
//! a pull-down, so an open wire reads 0 V.
//!
//! **Oversampling.** The ADC converts the sequence ch1 ch2 ch3 ch4 four times per step
//! (16 ranks, one hardware trigger, DMA); the four conversions of a channel are summed
//! (14-bit sum) and averaged.
//!
//! **Calibration.** value = (mean counts - offset) x gain; offset in counts, gain in N or Pa
//! per count. `Tare` takes the present mean as the offset.
//!
//! **Plausibility** (checked every step, in this order):
//! * any raw sample above 4095: [`SensorFault::AdcInvalid`] (DMA or configuration fault);
//! * mean below 2 % of the range: [`SensorFault::Open`] (open wire or short to ground);
//! * mean above 98 % of the range: [`SensorFault::Short`] (short to the supply);
//! * value outside the plausible range (default -5 % .. 110 % of full scale):
//!   [`SensorFault::OutOfRange`];
//! * the oversampled sum identical for `stuck_steps` steps (default 5000 = 0.5 s):
//!   [`SensorFault::Stuck`]. A live sensor always shows some counts of noise in a 4-sample
//!   sum; a noise-free source (a lab calibrator) may need `stuck_steps = 0` (check off).
//!
//! **Debounce** (up/down counter): a step with a condition adds [`DEBOUNCE_UP`] to the
//! channel's score, a clean step takes 1 off; the condition latches when the score reaches
//! `debounce_steps` x [`DEBOUNCE_UP`]. A steady condition so latches after `debounce_steps`
//! steps (default 10 = 1 ms), as before, and an intermittent one present on a fraction
//! d > 1/10 of the steps latches within `debounce_steps` x 9 / (10 d - 1) steps (9 of 10:
//! 12 steps; 1 of 2: 23; 1 of 5: 90), where a counter that restarts on any clean step never
//! latched it. Single spikes (one step in more than ten) never latch. On a step with a
//! condition the channel holds its last plausible value. A latched fault stays until it is
//! cleared by command while its cause is gone: no condition this step and the score back
//! to 0 (at most `debounce_steps` x 9 clean steps after the last condition, 9 ms by
//! default), so an intermittent cause is never cleared. What a latched fault does to the run
//! (the safe state) is decided in [`crate::rig`].

use num_enum::{IntoPrimitive, TryFromPrimitive};

/// Largest 12-bit ADC reading.
pub const ADC_MAX_COUNTS: u16 = 4095;
/// Conversions of each channel per step.
pub const OVERSAMPLING: usize = 4;
/// Length of the ADC regular sequence: ch1..ch4 repeated `OVERSAMPLING` times.
pub const ADC_SEQUENCE_LEN: usize = crate::CHANNELS * OVERSAMPLING;

/// Debounce score a step with a condition adds (a clean step takes 1 off): a condition
/// present on more than one step in [`DEBOUNCE_UP`] + 1 latches.
pub const DEBOUNCE_UP: u32 = 9;

/// What a channel measures.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum SensorKind {
    /// Caliper load cell: pad normal force per friction face, N.
    #[default]
    LoadCell = 0,
    /// Brake cylinder pressure transducer, Pa.
    PressureTransducer = 1,
}

impl SensorKind {
    /// Full-scale value (90 % of the ADC range): 40 kN or 1 MPa.
    pub fn full_scale(self) -> f32 {
        match self {
            SensorKind::LoadCell => 40_000.0,
            SensorKind::PressureTransducer => 1.0e6,
        }
    }

    /// Nominal calibration: zero at 10 %, full scale at 90 % of 4095 counts.
    pub fn default_calibration(self) -> SensorCalibration {
        let zero = 0.1 * ADC_MAX_COUNTS as f32;
        let span = 0.8 * ADC_MAX_COUNTS as f32;
        SensorCalibration {
            offset_counts: zero,
            gain: self.full_scale() / span,
        }
    }

    /// Default plausibility limits.
    pub fn default_limits(self) -> SensorLimits {
        let fs = self.full_scale();
        SensorLimits {
            open_below_counts: 0.02 * ADC_MAX_COUNTS as f32,
            short_above_counts: 0.98 * ADC_MAX_COUNTS as f32,
            min_value: -0.05 * fs,
            max_value: 1.10 * fs,
            stuck_steps: 5000,
            debounce_steps: 10,
        }
    }
}

/// Linear calibration: value = (counts - offset_counts) x gain.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SensorCalibration {
    /// ADC reading of a zero value, counts.
    pub offset_counts: f32,
    /// N or Pa per count.
    pub gain: f32,
}

/// Plausibility limits of a channel.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SensorLimits {
    /// Below this the wire is open, ADC counts.
    pub open_below_counts: f32,
    /// Above this the wire is shorted to the supply, ADC counts.
    pub short_above_counts: f32,
    /// Plausible physical range (N or Pa).
    pub min_value: f32,
    /// Highest plausible value (N or Pa).
    pub max_value: f32,
    /// Steps with an identical oversampled sum that mean "stuck" (0 = check off).
    pub stuck_steps: u32,
    /// Steps a steady condition needs to latch (intermittent ones: see the module's debounce).
    pub debounce_steps: u16,
}

/// A sensor fault (3-bit code in `RIG_DIAG`: 1-5 in declaration order, 0 = no fault:
/// [`crate::Code::code`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, IntoPrimitive, TryFromPrimitive)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum SensorFault {
    /// Below 2 % of the ADC range: open wire or short to ground.
    Open = 1,
    /// Above 98 % of the ADC range: short to the supply.
    Short,
    /// Outside the plausible physical range.
    OutOfRange,
    /// Reading frozen.
    Stuck,
    /// A raw sample above 4095 (ADC/DMA fault).
    AdcInvalid,
}

/// A sensor fault to inject (tests the plausibility chain and the safe state on the rig;
/// the `InjectedFault` code of `RIG_COMMAND`: 1-4 in declaration order, 0 = remove the
/// injection).
#[derive(Clone, Copy, Debug, PartialEq, Eq, IntoPrimitive, TryFromPrimitive)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum InjectedFault {
    /// The channel reads 0 counts (open wire with the input pull-down).
    Open = 1,
    /// The channel reads full scale (short to the supply).
    Short,
    /// The channel's oversampled reading freezes at its present value.
    Stuck,
    /// The channel reads 10 % of the span above its plausible range.
    OutOfRange,
}

/// Why a calibration command was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum CalibrationError {
    /// Tare needs an unloaded, plausible sensor: the reading must be within 10 % of the
    /// range of the nominal zero (10 %), and no fault pending or latched.
    NotAtZero,
    /// Gain not finite or zero; offset outside 0..4095.
    BadValue,
}

/// One step's reading of a channel.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Reading {
    /// Physical value (N or Pa); while a fault is pending or latched, the last plausible one.
    pub value: f32,
    /// Mean ADC counts of this step (after fault injection).
    pub mean_counts: f32,
    /// Latched fault.
    pub fault: Option<SensorFault>,
    /// A condition is present but not yet latched.
    pub pending: bool,
}

/// One brake-input channel.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SensorChannel {
    /// What the channel measures (load cell or pressure transducer).
    pub kind: SensorKind,
    /// Counts to N or Pa.
    pub calibration: SensorCalibration,
    /// Plausibility limits.
    pub limits: SensorLimits,
    inject: Option<InjectedFault>,
    frozen_sum: u32,
    last_sum: Option<u32>,
    same_sum_steps: u32,
    /// The condition of the last step.
    pending: Option<SensorFault>,
    /// Up/down debounce score (module doc).
    score: u32,
    latched: Option<SensorFault>,
    value: f32,
    mean_counts: f32,
}

impl SensorChannel {
    /// A channel of `kind` with its default calibration and limits, no fault.
    pub fn new(kind: SensorKind) -> Self {
        Self {
            kind,
            calibration: kind.default_calibration(),
            limits: kind.default_limits(),
            inject: None,
            frozen_sum: 0,
            last_sum: None,
            same_sum_steps: 0,
            pending: None,
            score: 0,
            latched: None,
            value: 0.0,
            mean_counts: 0.0,
        }
    }

    /// Takes this step's `OVERSAMPLING` raw conversions of the channel.
    pub fn update(&mut self, samples: [u16; OVERSAMPLING]) -> Reading {
        let adc_invalid = samples.iter().any(|&s| s > ADC_MAX_COUNTS);
        let mut sum: u32 = samples.iter().map(|&s| s.min(ADC_MAX_COUNTS) as u32).sum();
        match self.inject {
            Some(InjectedFault::Open) => sum = 0,
            Some(InjectedFault::Short) => sum = ADC_MAX_COUNTS as u32 * OVERSAMPLING as u32,
            Some(InjectedFault::Stuck) => sum = self.frozen_sum,
            _ => {}
        }
        let mean = sum as f32 / OVERSAMPLING as f32;
        self.mean_counts = mean;
        let mut value = (mean - self.calibration.offset_counts) * self.calibration.gain;
        if self.inject == Some(InjectedFault::OutOfRange) {
            value = self.limits.max_value + 0.1 * (self.limits.max_value - self.limits.min_value);
        }

        if self.last_sum == Some(sum) {
            self.same_sum_steps = self.same_sum_steps.saturating_add(1);
        } else {
            self.same_sum_steps = 0;
        }
        self.last_sum = Some(sum);

        let l = &self.limits;
        let condition = if adc_invalid {
            Some(SensorFault::AdcInvalid)
        } else if mean < l.open_below_counts {
            Some(SensorFault::Open)
        } else if mean > l.short_above_counts {
            Some(SensorFault::Short)
        } else if !(value >= l.min_value && value <= l.max_value) {
            Some(SensorFault::OutOfRange)
        } else if l.stuck_steps > 0 && self.same_sum_steps >= l.stuck_steps {
            Some(SensorFault::Stuck)
        } else {
            None
        };

        self.pending = condition;
        let threshold = self.latch_score();
        match condition {
            Some(c) => {
                self.score = (self.score + DEBOUNCE_UP).min(threshold);
                if self.latched.is_none() && self.score >= threshold {
                    self.latched = Some(c);
                }
            }
            None => {
                self.score = self.score.saturating_sub(1);
                self.value = value;
            }
        }
        Reading {
            value: self.value,
            mean_counts: mean,
            fault: self.latched,
            pending: self.cause_present(),
        }
    }

    /// Debounce score at which a condition latches.
    fn latch_score(&self) -> u32 {
        self.limits.debounce_steps.max(1) as u32 * DEBOUNCE_UP
    }

    /// A condition this step, or one recent enough that the debounce score is not back to 0.
    pub fn cause_present(&self) -> bool {
        self.pending.is_some() || self.score > 0
    }

    /// Latched fault, if any.
    pub fn fault(&self) -> Option<SensorFault> {
        self.latched
    }

    /// Last plausible value (N or Pa).
    pub fn value(&self) -> f32 {
        self.value
    }

    /// Clears the latched fault if its cause is gone ([`Self::cause_present`] false);
    /// returns whether the channel is now free of faults.
    pub fn clear_fault(&mut self) -> bool {
        if !self.cause_present() {
            self.latched = None;
        }
        self.latched.is_none()
    }

    /// Injects (or removes) a fault at the raw-reading level.
    pub fn inject(&mut self, fault: Option<InjectedFault>) {
        if fault == Some(InjectedFault::Stuck) {
            self.frozen_sum = self.last_sum.unwrap_or(0);
        }
        self.inject = fault;
    }

    /// The fault injected into this channel, if any.
    pub fn injected(&self) -> Option<InjectedFault> {
        self.inject
    }

    /// Zero: the present mean becomes the offset.
    pub fn tare(&mut self) -> Result<(), CalibrationError> {
        let nominal = self.kind.default_calibration().offset_counts;
        let tolerance = 0.1 * ADC_MAX_COUNTS as f32;
        if self.cause_present()
            || self.latched.is_some()
            || self.last_sum.is_none()
            || !((self.mean_counts - nominal).abs() <= tolerance)
        {
            return Err(CalibrationError::NotAtZero);
        }
        self.calibration.offset_counts = self.mean_counts;
        Ok(())
    }

    /// Sets the gain, N or Pa per count; refuses zero, NaN and inf.
    pub fn set_gain(&mut self, gain: f32) -> Result<(), CalibrationError> {
        if !(gain.is_finite() && gain != 0.0) {
            return Err(CalibrationError::BadValue);
        }
        self.calibration.gain = gain;
        Ok(())
    }

    /// Sets the zero reading, counts; refuses values outside the ADC's range.
    pub fn set_offset(&mut self, offset_counts: f32) -> Result<(), CalibrationError> {
        if !(offset_counts >= 0.0 && offset_counts <= ADC_MAX_COUNTS as f32) {
            return Err(CalibrationError::BadValue);
        }
        self.calibration.offset_counts = offset_counts;
        Ok(())
    }

    /// Changes the measured quantity; calibration and limits go back to the kind's defaults.
    /// The fault state (latched fault, debounce, stuck tracking, injection) is the wiring's
    /// and stays: a new kind clears no fault (only [`Self::clear_fault`] does, with the cause
    /// gone).
    pub fn set_kind(&mut self, kind: SensorKind) {
        let old = *self;
        *self = Self {
            inject: old.inject,
            frozen_sum: old.frozen_sum,
            last_sum: old.last_sum,
            same_sum_steps: old.same_sum_steps,
            pending: old.pending,
            score: old.score,
            latched: old.latched,
            ..Self::new(kind)
        };
    }
}

/// Splits the 16-rank DMA sequence (ch1 ch2 ch3 ch4, four times) into the conversions of
/// each channel.
pub fn split_sequence(raw: &[u16; ADC_SEQUENCE_LEN]) -> [[u16; OVERSAMPLING]; crate::CHANNELS] {
    let mut out = [[0u16; OVERSAMPLING]; crate::CHANNELS];
    for (rank, &s) in raw.iter().enumerate() {
        out[rank % crate::CHANNELS][rank / crate::CHANNELS] = s;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// Counts for a physical value with the default calibration (independent f64 formula:
    /// 10 % + 80 % x value / full scale of 4095).
    fn counts_for(kind: SensorKind, value: f64) -> f64 {
        4095.0 * (0.1 + 0.8 * value / kind.full_scale() as f64)
    }

    /// Four samples around a mean with a little noise (a live sensor).
    fn noisy(mean: f64, step: u32) -> [u16; 4] {
        let n = [0i32, 1, -1, 0, 2, -2, 1, 0];
        core::array::from_fn(|i| {
            (mean.round() as i32 + n[(step as usize + i * 3) % n.len()]).clamp(0, 4095) as u16
        })
    }

    #[test]
    fn scaling_matches_independent_formula_both_kinds() {
        for kind in [SensorKind::LoadCell, SensorKind::PressureTransducer] {
            let fs = kind.full_scale() as f64;
            for frac in [0.0, 0.1, 0.25, 0.5, 0.75, 1.0] {
                let mut ch = SensorChannel::new(kind);
                let c = counts_for(kind, frac * fs).round() as u16;
                let r = ch.update([c; 4]);
                // One count of quantisation: FS / 3276 counts.
                let expected = (c as f64 - 409.5) * fs / (0.8 * 4095.0);
                assert!(
                    (r.value as f64 - expected).abs() <= 1e-4 * fs,
                    "{kind:?} {frac}"
                );
                assert!(
                    (r.value as f64 - frac * fs).abs() <= fs / 3276.0,
                    "{kind:?} {frac}"
                );
                assert_eq!(r.fault, None);
            }
        }
    }

    #[test]
    fn oversampling_averages_the_four_conversions() {
        let mut ch = SensorChannel::new(SensorKind::LoadCell);
        let r = ch.update([1000, 1001, 1003, 1004]);
        assert_eq!(r.mean_counts, 1002.0);
        let seq: [u16; 16] = core::array::from_fn(|i| (i % 4) as u16 * 100 + (i / 4) as u16);
        let split = split_sequence(&seq);
        assert_eq!(split[2], [200, 201, 202, 203]);
        assert_eq!(split[0], [0, 1, 2, 3]);
    }

    #[test]
    fn calibration_tare_gain_offset() {
        let mut ch = SensorChannel::new(SensorKind::LoadCell);
        // Tare at 450 counts (zero drifted by 40 counts).
        ch.update([450; 4]);
        ch.tare().unwrap();
        assert_eq!(ch.calibration.offset_counts, 450.0);
        assert_eq!(ch.update([450, 451, 449, 450]).value, 0.0);
        ch.set_gain(10.0).unwrap();
        assert_eq!(ch.update([550, 551, 549, 550]).value, 1000.0);
        ch.set_offset(500.0).unwrap();
        assert_eq!(ch.update([600, 601, 599, 600]).value, 1000.0);
        assert_eq!(ch.set_gain(f32::NAN), Err(CalibrationError::BadValue));
        assert_eq!(ch.set_gain(0.0), Err(CalibrationError::BadValue));
        assert_eq!(ch.set_offset(-1.0), Err(CalibrationError::BadValue));
        assert_eq!(
            ch.set_offset(f32::INFINITY),
            Err(CalibrationError::BadValue)
        );
        // Tare under load (50 % FS) is refused.
        ch.update([2048, 2049, 2047, 2048]);
        assert_eq!(ch.tare(), Err(CalibrationError::NotAtZero));
    }

    fn run_until_latched(
        ch: &mut SensorChannel,
        samples: [u16; 4],
        max: u32,
    ) -> Option<(u32, SensorFault)> {
        for k in 1..=max {
            if let Some(f) = ch.update(samples).fault {
                return Some((k, f));
            }
        }
        None
    }

    #[test]
    fn open_short_and_range_latch_after_debounce_and_hold_last_value() {
        for (samples, want) in [
            ([0u16; 4], SensorFault::Open),
            ([60; 4], SensorFault::Open),
            ([4095; 4], SensorFault::Short),
            ([4050; 4], SensorFault::Short),
            // 150 counts: electrically alive but -3.2 kN (< -2 kN).
            ([150; 4], SensorFault::OutOfRange),
            // 3950 counts: 43.2 kN... inside; 4000 counts = 43.8 kN inside; use gain change below.
        ] {
            let mut ch = SensorChannel::new(SensorKind::LoadCell);
            for k in 0..100 {
                ch.update(noisy(counts_for(SensorKind::LoadCell, 10_000.0), k));
            }
            let before = ch.value();
            assert!((before - 10_000.0).abs() < 30.0);
            // Nine steps pending: value held, no latch.
            for _ in 0..9 {
                let r = ch.update(samples);
                assert!(r.pending);
                assert_eq!(r.fault, None);
                assert_eq!(r.value, before);
            }
            let r = ch.update(samples);
            assert_eq!(r.fault, Some(want), "{samples:?}");
            assert_eq!(r.value, before);
            // Latched until cleared, and clearing fails while the cause persists.
            assert!(!ch.clear_fault());
            // The cause goes: the debounce score needs 10 x 9 clean steps to reach 0; until
            // then the cause counts as present and no clear succeeds.
            for k in 0..89 {
                ch.update(noisy(counts_for(SensorKind::LoadCell, 5_000.0), k));
                assert!(!ch.clear_fault(), "clean step {k}");
            }
            ch.update(noisy(counts_for(SensorKind::LoadCell, 5_000.0), 1));
            assert_eq!(ch.fault(), Some(want));
            assert!(ch.clear_fault());
            assert_eq!(
                ch.update(noisy(counts_for(SensorKind::LoadCell, 5_000.0), 2))
                    .fault,
                None
            );
        }
        // Out of range high: a gain that puts 3000 counts at 2 x full scale.
        let mut ch = SensorChannel::new(SensorKind::LoadCell);
        ch.set_gain(2.0 * 40_000.0 / (3000.0 - 409.5)).unwrap();
        assert_eq!(
            run_until_latched(&mut ch, [3000; 4], 100),
            Some((10, SensorFault::OutOfRange))
        );
    }

    /// Steps until an open wire present on `on` steps of every `period` latches (None
    /// within 20 000 steps).
    fn intermittent_open_latches_after(on: u32, period: u32) -> Option<u32> {
        let mut ch = SensorChannel::new(SensorKind::LoadCell);
        for k in 0..20_000u32 {
            let s = if k % period < on {
                [0; 4]
            } else {
                noisy(2000.0, k)
            };
            if ch.update(s).fault.is_some() {
                return Some(k + 1);
            }
        }
        None
    }

    #[test]
    fn intermittent_open_latches_within_the_bound() {
        // Independent bound: score +9 per faulty step, -1 per clean one, latch at 90; a
        // duty d gains (10 d - 1) per step on average, so it latches within
        // 90 / (10 d - 1) steps plus one period of phase.
        for (on, period) in [(9u32, 10u32), (1, 2), (1, 5), (3, 10), (2, 9)] {
            let d = on as f64 / period as f64;
            let bound = (90.0 / (10.0 * d - 1.0)).ceil() as u32 + period;
            let got = intermittent_open_latches_after(on, period);
            assert!(
                got.is_some_and(|n| n <= bound),
                "{on} of {period}: latched after {got:?}, bound {bound}"
            );
        }
        // A restart-on-clean debounce never latches 9 of 10; this one does, after 12 steps.
        assert_eq!(intermittent_open_latches_after(9, 10), Some(12));
        // One step in ten or fewer: spikes, never latched.
        assert_eq!(intermittent_open_latches_after(1, 10), None);
        assert_eq!(intermittent_open_latches_after(1, 50), None);
    }

    #[test]
    fn an_intermittent_cause_is_never_cleared() {
        let mut ch = SensorChannel::new(SensorKind::LoadCell);
        let mut clears = 0;
        for k in 0..5_000u32 {
            let s = if k % 10 < 5 { [0; 4] } else { noisy(2000.0, k) };
            ch.update(s);
            if ch.fault().is_some() && ch.clear_fault() {
                clears += 1;
            }
        }
        assert_eq!(clears, 0);
        assert_eq!(ch.fault(), Some(SensorFault::Open));
    }

    #[test]
    fn a_single_spike_does_not_latch() {
        let mut ch = SensorChannel::new(SensorKind::PressureTransducer);
        for k in 0..1000 {
            let s = if k % 50 == 7 {
                [4095; 4]
            } else {
                noisy(2000.0, k)
            };
            assert_eq!(ch.update(s).fault, None);
        }
    }

    #[test]
    fn stuck_reading_latches_after_window_but_noise_never_does() {
        let mut ch = SensorChannel::new(SensorKind::LoadCell);
        for k in 0..20_000 {
            assert_eq!(ch.update(noisy(1500.0, k)).fault, None, "step {k}");
        }
        let mut ch = SensorChannel::new(SensorKind::LoadCell);
        // Identical sums: stuck after 5000 same steps + 10 debounce.
        let got = run_until_latched(&mut ch, [1500, 1501, 1500, 1501], 10_000);
        assert_eq!(got, Some((5010, SensorFault::Stuck)));
        // Check off: never stuck.
        let mut ch = SensorChannel::new(SensorKind::LoadCell);
        ch.limits.stuck_steps = 0;
        assert_eq!(run_until_latched(&mut ch, [1500; 4], 20_000), None);
    }

    #[test]
    fn injected_faults_reach_the_same_verdicts() {
        for (inj, want) in [
            (InjectedFault::Open, SensorFault::Open),
            (InjectedFault::Short, SensorFault::Short),
            (InjectedFault::OutOfRange, SensorFault::OutOfRange),
        ] {
            let mut ch = SensorChannel::new(SensorKind::LoadCell);
            ch.update(noisy(2000.0, 0));
            ch.inject(Some(inj));
            let got = (0..10).map(|k| ch.update(noisy(2000.0, k))).last().unwrap();
            assert_eq!(got.fault, Some(want));
            ch.inject(None);
            // Ten steps at +9 saturate the score at 90: 90 clean steps to decay.
            for k in 0..90 {
                ch.update(noisy(2000.0, k));
            }
            assert!(ch.clear_fault());
        }
        let mut ch = SensorChannel::new(SensorKind::LoadCell);
        ch.update(noisy(2000.0, 0));
        ch.inject(Some(InjectedFault::Stuck));
        let mut latched_at = None;
        for k in 0..6000 {
            if ch.update(noisy(2000.0, k)).fault == Some(SensorFault::Stuck) {
                latched_at = Some(k + 1);
                break;
            }
        }
        // The frozen sum repeats from the first injected step: 5000 same + 10 debounce,
        // counted from the step before injection (whose sum it repeats).
        assert_eq!(latched_at, Some(5009));
    }

    #[test]
    fn adc_samples_above_12_bits_are_a_fault() {
        let mut ch = SensorChannel::new(SensorKind::LoadCell);
        assert_eq!(
            run_until_latched(&mut ch, [1000, 1000, 5000, 1000], 20),
            Some((10, SensorFault::AdcInvalid))
        );
    }

    #[test]
    fn set_kind_keeps_a_latched_fault_and_its_cause() {
        let mut ch = SensorChannel::new(SensorKind::LoadCell);
        assert_eq!(
            run_until_latched(&mut ch, [0; 4], 20),
            Some((10, SensorFault::Open))
        );
        ch.set_kind(SensorKind::PressureTransducer);
        assert_eq!(ch.fault(), Some(SensorFault::Open));
        assert!(!ch.clear_fault(), "the wire is still open");
        ch.update([0; 4]);
        assert!(!ch.clear_fault());
        assert_eq!(ch.fault(), Some(SensorFault::Open));
    }

    #[test]
    fn set_kind_resets_calibration_but_keeps_injection() {
        let mut ch = SensorChannel::new(SensorKind::LoadCell);
        ch.set_gain(3.0).unwrap();
        ch.inject(Some(InjectedFault::Open));
        ch.set_kind(SensorKind::PressureTransducer);
        assert_eq!(
            ch.calibration,
            SensorKind::PressureTransducer.default_calibration()
        );
        assert_eq!(ch.injected(), Some(InjectedFault::Open));
    }

    proptest! {
        /// Any raw input (including > 12-bit garbage) gives a finite value and never panics;
        /// a plausible value is within the plausible range.
        #[test]
        fn any_raw_input_is_handled(samples in proptest::array::uniform4(proptest::num::u16::ANY), kind_p in proptest::bool::ANY) {
            let kind = if kind_p { SensorKind::LoadCell } else { SensorKind::PressureTransducer };
            let mut ch = SensorChannel::new(kind);
            for _ in 0..12 {
                let r = ch.update(samples);
                prop_assert!(r.value.is_finite());
                if r.fault.is_none() && !r.pending {
                    prop_assert!(r.value >= ch.limits.min_value && r.value <= ch.limits.max_value);
                }
            }
        }
    }
}
