//! The paper's emergency brake in closed loop and the stop rule every run ends by (the
//! host's `hils simulate`, the emulated target, the board's run state and the diagnosis
//! generator use this one copy).

use hils_brake_unit::BrakeDemand;
use hils_plant::{FrictionModel, Real};

use crate::closed_loop::{ClosedLoop, LoopError};
use crate::params::ParamFile;

/// The vehicle has stopped when the carbody speed falls to this, m/s.
pub const STOP_SPEED_MPS: f64 = 0.01;
/// A run goes on this long after the stop, s.
pub const AFTER_STOP_S: f64 = 1.0;
/// A run gives up this long after its start if the vehicle has not stopped, s.
pub const MAX_TIME_S: f64 = 120.0;

/// Whether a carbody speed (m/s) counts as standstill: the stop of every run. Compared
/// in the plant's own precision (no f64 in the board's step; no f32 value lies between
/// 0.01 and its f32 rounding, so the f32 and f64 comparisons agree).
#[inline]
pub fn at_standstill<F: Real>(vehicle_speed_mps: F) -> bool {
    vehicle_speed_mps <= F::of(STOP_SPEED_MPS)
}

/// When a run ends: [`AFTER_STOP_S`] (or another time) after the first step at
/// standstill, or at a time limit.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct StopRule {
    after_steps: u32,
    max_steps: u32,
    stop_step: Option<u32>,
}

impl StopRule {
    /// The rule at plant step `step_s`: end `after_stop_s` after the stop, or at
    /// `max_time_s`.
    pub fn new(step_s: f64, after_stop_s: f64, max_time_s: f64) -> Self {
        Self {
            after_steps: libm::ceil(after_stop_s / step_s) as u32,
            max_steps: libm::ceil(max_time_s / step_s) as u32,
            stop_step: None,
        }
    }

    /// The paper scenario's rule ([`AFTER_STOP_S`], [`MAX_TIME_S`]) at `step_s`.
    pub fn paper(step_s: f64) -> Self {
        Self::new(step_s, AFTER_STOP_S, MAX_TIME_S)
    }

    /// Notes the state after step `steps` (steps since the start); returns whether the run
    /// is over.
    pub fn observe<F: Real>(&mut self, steps: u32, vehicle_speed_mps: F) -> bool {
        if self.stop_step.is_none() && at_standstill(vehicle_speed_mps) {
            self.stop_step = Some(steps);
        }
        let after_stop =
            matches!(self.stop_step, Some(s) if steps >= s.saturating_add(self.after_steps));
        after_stop || steps >= self.max_steps
    }

    /// The step at which the carbody speed first fell to [`STOP_SPEED_MPS`].
    pub fn stop_step(&self) -> Option<u32> {
        self.stop_step
    }

    /// The step limit.
    pub fn max_steps(&self) -> u32 {
        self.max_steps
    }
}

/// The paper's emergency brake in closed loop: EB command at t = 0 from the scenario's
/// initial speed on its rail (150 km/h, wet, in the reference parameters), stepped until
/// the [`StopRule`] ends it. The caller does the steps (so the target can time them)
/// through [`EbScenario::advance`].
#[derive(Clone, Debug)]
pub struct EbScenario<F: Real> {
    /// The loop being run (plant + simulated brake unit).
    pub sim: ClosedLoop<F>,
    rule: StopRule,
    record_every: u32,
}

/// What [`EbScenario::advance`] says about the step just taken.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Advance {
    /// Record this step (every `record_every` steps).
    pub record: bool,
    /// The run is over (this step was the last).
    pub done: bool,
}

impl<F: Real> EbScenario<F> {
    /// The scenario with the reference parameters and one friction model, recorded every
    /// `record_every` steps.
    pub fn paper(friction: FrictionModel, record_every: u32) -> Result<Self, LoopError> {
        let mut file = ParamFile::default();
        file.plant.friction.model = friction;
        Self::new(&file, record_every)
    }

    /// The scenario of a parameter file (rail, initial speed and step from
    /// `[scenario.paper_eb]`, the unit from `[brake_unit]`).
    pub fn new(file: &ParamFile, record_every: u32) -> Result<Self, LoopError> {
        let sc = &file.scenario.paper_eb;
        let v0 = F::of(sc.initial_speed_kmh / crate::KMH_PER_MPS);
        let sim = ClosedLoop::from_file(file, sc.rail, v0)?;
        Ok(Self::from_loop(
            sim,
            StopRule::paper(sc.step_s),
            record_every,
        ))
    }

    /// The scenario on a loop built by the caller; the EB demand is set before the first
    /// step.
    pub fn from_loop(mut sim: ClosedLoop<F>, rule: StopRule, record_every: u32) -> Self {
        sim.set_demand(BrakeDemand::Emergency);
        Self {
            sim,
            rule,
            record_every: record_every.max(1),
        }
    }

    /// Plant steps taken so far.
    pub fn steps(&self) -> u32 {
        self.sim.plant.steps()
    }

    /// The step at which the carbody speed first fell to [`STOP_SPEED_MPS`].
    pub fn stop_step(&self) -> Option<u32> {
        self.rule.stop_step()
    }

    /// The stop rule (its step limit).
    pub fn rule(&self) -> &StopRule {
        &self.rule
    }

    /// Takes one step: `step` must advance `sim` by exactly one step (`sim.step()`, timed
    /// or not). Returns whether to record it and whether the run is over. A `step` that
    /// does not advance the plant ends the run (the plant's step counter is the clock).
    pub fn advance(&mut self, step: impl FnOnce(&mut ClosedLoop<F>)) -> Advance {
        let before = self.steps();
        step(&mut self.sim);
        let steps = self.steps();
        if steps != before.wrapping_add(1) {
            return Advance {
                record: false,
                done: true,
            };
        }
        let done = self.rule.observe(steps, self.sim.plant.vehicle_speed());
        Advance {
            record: steps % self.record_every == 0,
            done,
        }
    }
}
