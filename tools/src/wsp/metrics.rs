//! What the bench judges in a run, from its time series (a SIL run or a captured rig log:
//! the same code).
//!
//! * **Stopping distance**: carbody distance from the brake command (t = 0) to standstill.
//! * **Allowed distance** (in the spirit of CEN/TR 17315, which judges WSP by the stopping
//!   distance against the one the available adhesion permits): a point-mass stop from the
//!   same speed of a perfect WSP ([`AllowedStop`]): each wheelset brakes as the demand
//!   makes it brake on a rolling wheel ([`BrakeModel`]: the demand's cylinder pressure,
//!   building up behind the dead time as p_d (1 - exp(-(t - t_d)/tau)), through Eq (1)
//!   with the pads' friction of Eq (2) at the rolling friction speed and the logged disc
//!   temperature, over r M_eff), capped at a quarter of g mu_avail, mu_avail the available
//!   adhesion (peak of F/Q over creepage at the current speed) of the surface under it,
//!   times its logged friction factor when the rail recovers. Rail forces decelerate the
//!   moving mass M, so the cap is g mu (not g mu M/M_eff). The plant's Davis resistance
//!   and gradient are added. (Before issue 25 the brake gave the demand's nominal
//!   deceleration; with Eq (2)'s pad friction above mu_d0 an EB on a dry rail stopped 6 %
//!   short of its reference.)
//! * **Distance ratio** = stopping / allowed distance; pass if <= `max_distance_ratio`.
//! * **Adhesion utilisation**: from the equivalent response time t_d + tau to the stop, the
//!   speed lost over the integral of min(a_demand, g mu_avail) + resistance.
//! * **Air consumption**: free air vented by the WSP dump valves, litres at atmospheric
//!   pressure (isothermal): sum over the vent episodes (samples at which the dump valve
//!   vents as it acts, else as commanded) of V_channel (p before - p after) / p_atm. Needs the cylinder pressures and the vent states
//!   (or vent flags estimated from the pressure falls, then listed in
//!   `estimated_from_cylinder_pressure`).
//! * **Locks**: a wheelset is locked while its speed is below `lock_speed_ratio` of the
//!   vehicle speed (v > `min_speed_mps`); longest lock per wheelset, number of locks.
//! * **WSP timer actions**: continuous WSP action (vent or hold) of the unit's timer or
//!   longer, one open at the end of the trace included. Needs the vent and the hold states
//!   as the valves had them (a hold shows in no pressure).
//!
//! A metric the trace cannot give is **not measured**: `null` in the JSON, listed in
//! `not_measured`, and its criterion is not judged (`... (not measured: not judged)`, not
//! passed): nothing passes that was not measured.
//! * **Slide onsets**: first time a wheelset's creepage exceeds the creepage at which the
//!   adhesion under it peaks (beyond the peak of the curve the wheel slides).

use hils_plant::brake::Caliper;
use hils_plant::contact::Polach;
use hils_plant::friction::DiscPadFriction;
use hils_plant::track::ContactSets;
use hils_plant::{Params, Surface, Track};
use serde::Serialize;

use super::programme::Criteria;
use crate::figures::round_dp;

/// Standard atmosphere, Pa.
const P_ATM_PA: f64 = 101_325.0;

/// A run's time series (uniform or not).
#[derive(Clone, Debug, Default)]
pub struct Trace {
    pub t_s: Vec<f64>,
    /// Vehicle speed, m/s.
    pub v_mps: Vec<f64>,
    /// Distance since the brake command, m.
    pub x_m: Vec<f64>,
    /// Wheel circumferential speeds r omega, m/s.
    pub wheel_mps: [Vec<f64>; 4],
    /// Cylinder pressures, Pa (empty when not measured).
    pub p_cyl_pa: [Vec<f64>; 4],
    /// WSP vent command per wheelset.
    pub venting: [Vec<bool>; 4],
    /// Whether each wheelset's dump valve vents the cylinder, as it acts (the command of one
    /// dead time ago; empty when not logged: the command is used).
    pub acting_vent: [Vec<bool>; 4],
    /// WSP hold command per wheelset (empty when not logged).
    pub holding: [Vec<bool>; 4],
    /// Friction factor of each wheelset's contact (degraded adhesion that recovers; empty
    /// when not logged, i.e. 1).
    pub mu_factor: [Vec<f64>; 4],
    /// Disc temperature rise of each wheelset, degC (empty when not logged).
    pub disc_temp_c: [Vec<f64>; 4],
    /// Resolution of the logged vehicle speed, m/s (0 for a simulated trace): a speed within
    /// it of the stop speed cannot be told from standstill.
    pub speed_resolution_mps: f64,
    /// Samples of a log whose empty or non-finite cells were interpolated.
    pub filled_samples: usize,
    /// Whether `venting` was estimated from the cylinder pressure falls (a log without the
    /// valve states), not logged.
    pub vents_estimated: bool,
}

impl Trace {
    /// The logged friction factors, when every wheelset has one per sample.
    pub fn mu_factors(&self) -> Option<MuFactors<'_>> {
        let n = self.x_m.len();
        self.mu_factor
            .iter()
            .all(|f| f.len() == n && n > 0)
            .then_some(MuFactors {
                x_m: &self.x_m,
                factor: &self.mu_factor,
            })
    }

    /// Whether every wheelset's `field` has one value per sample.
    fn logged<T>(&self, field: &[Vec<T>; 4]) -> bool {
        field.iter().all(|f| f.len() == self.t_s.len())
    }

    /// Whether the air consumption can be judged: pressures and vent states (logged or
    /// estimated) of every wheelset.
    pub fn air_measured(&self) -> bool {
        self.logged(&self.p_cyl_pa) && self.logged(&self.venting)
    }

    /// Whether the WSP timer actions can be judged: the vent and hold states as logged.
    pub fn timer_measured(&self) -> bool {
        self.logged(&self.venting) && self.logged(&self.holding) && !self.vents_estimated
    }

    /// Whether wheelset `j`'s WSP acts (vent or hold) at sample `k`.
    fn released(&self, j: usize, k: usize) -> bool {
        self.venting[j].get(k).copied().unwrap_or(false)
            || self.holding[j].get(k).copied().unwrap_or(false)
    }
}

/// Available adhesion of each surface as a function of speed (1 m/s grid): the peak of
/// F/Q over creepage and the creepage where it peaks.
pub struct AvailableAdhesion {
    table: [Vec<f64>; 4],
    peak_creep: [Vec<f64>; 4],
}

impl AvailableAdhesion {
    pub fn new(params: &Params, sets: &ContactSets) -> Self {
        let q = params.total_mass() * params.vehicle.g / 4.0;
        let peaks = Surface::ALL.map(|s| {
            let polach = Polach::<f64>::with_set(&params.contact, &sets.set(&params.contact, s));
            (0..=120)
                .map(|v| {
                    let v = (v as f64).max(0.5);
                    (1..400)
                        .map(|i| {
                            let creep = i as f64 * 5e-4;
                            (polach.adhesion_coefficient(creep, v, q), creep)
                        })
                        .fold((0.0, 0.0), |m, c| if c.0 > m.0 { c } else { m })
                })
                .collect::<Vec<(f64, f64)>>()
        });
        Self {
            table: peaks.clone().map(|p| p.iter().map(|c| c.0).collect()),
            peak_creep: peaks.map(|p| p.iter().map(|c| c.1).collect()),
        }
    }

    /// Linear interpolation of a 1 m/s table at `v`.
    fn interpolate(t: &[f64], v: f64) -> f64 {
        let x = v.clamp(0.0, (t.len() - 1) as f64);
        let i = (x.floor() as usize).min(t.len() - 2);
        let f = x - i as f64;
        t[i] * (1.0 - f) + t[i + 1] * f
    }

    /// Peak adhesion coefficient of `surface` at speed `v` (m/s).
    pub fn at(&self, surface: Surface, v: f64) -> f64 {
        Self::interpolate(&self.table[surface as usize], v)
    }

    /// Creepage at which the adhesion of `surface` peaks at speed `v` (m/s): beyond it a
    /// wheel slides (less force for more creep).
    pub fn peak_creep(&self, surface: Surface, v: f64) -> f64 {
        Self::interpolate(&self.peak_creep[surface as usize], v)
    }

    /// Mean available adhesion of the four wheelsets with the leading one at `x` (m).
    pub fn under_vehicle(&self, track: &Track, offsets: &[f64; 4], x: f64, v: f64) -> f64 {
        offsets
            .iter()
            .map(|o| self.at(track.surface_at(x + o), v))
            .sum::<f64>()
            / 4.0
    }
}

/// Track positions of the wheelsets relative to the leading one, m.
pub fn wheelset_offsets(p: &Params) -> [f64; 4] {
    let (b, w) = (p.vehicle.bogie_base, p.vehicle.wheel_base);
    [0.0, -w, -b, -b - w]
}

/// Deceleration of the plant's running resistance and gradient (`[resistance]`,
/// `[track]`): a(v) = (a + b v + c v^2) / M + g sin(atan(grade)), m/s^2 (the plant puts the
/// Davis force on the carbody and the gradient on every body; M the moving mass).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Resistance {
    /// Davis a / M, b / M, c / M (m/s^2, 1/s, 1/m).
    pub davis_per_kg: [f64; 3],
    /// g sin(atan(gradient)), m/s^2 (uphill positive).
    pub g_along_mps2: f64,
}

impl Resistance {
    /// The plant's resistance and gradient.
    pub fn of(p: &Params) -> Self {
        let m = p.total_mass();
        let r = &p.resistance;
        let grade = p.track.gradient_permille / 1000.0;
        Self {
            davis_per_kg: [
                r.davis_a_n / m,
                r.davis_b_n_per_mps / m,
                r.davis_c_n_per_mps2 / m,
            ],
            g_along_mps2: p.vehicle.g * grade / (1.0 + grade * grade).sqrt(),
        }
    }

    /// Deceleration at speed `v` (m/s > 0), m/s^2.
    pub fn decel(&self, v: f64) -> f64 {
        let [a, b, c] = self.davis_per_kg;
        a + b * v + c * v * v + self.g_along_mps2
    }
}

/// The friction factor 1 + (R - 1) lambda each wheelset had along the run (degraded
/// adhesion that recovers), against the carbody distance.
#[derive(Clone, Copy, Debug)]
pub struct MuFactors<'a> {
    pub x_m: &'a [f64],
    pub factor: &'a [Vec<f64>; 4],
}

impl MuFactors<'_> {
    /// Wheelset `j`'s factor when the vehicle was at `x` (the last sample before it).
    pub fn at(&self, j: usize, x: f64) -> f64 {
        let k = self.x_m.partition_point(|&xk| xk <= x).saturating_sub(1);
        self.factor[j].get(k).copied().unwrap_or(1.0)
    }
}

/// Disc temperature rise of each wheelset against the vehicle speed, from a trace: the
/// temperature when the speed first fell to each value (the discs have then absorbed the
/// kinetic energy down to that speed, whichever stop makes it).
#[derive(Clone, Debug, Default)]
pub struct DiscTemps {
    /// Falling speeds, m/s (the running minimum of the trace's speed).
    speed_mps: Vec<f64>,
    temp_c: Vec<[f64; 4]>,
}

impl DiscTemps {
    /// The disc temperatures of `trace` against its speed (empty when not logged).
    pub fn of(trace: &Trace) -> Self {
        let n = trace.v_mps.len();
        let mut d = Self::default();
        if trace.disc_temp_c.iter().any(|t| t.len() != n) {
            return d;
        }
        let mut lowest = f64::INFINITY;
        for k in 0..n {
            if trace.v_mps[k] < lowest {
                lowest = trace.v_mps[k];
                d.speed_mps.push(lowest);
                d.temp_c
                    .push(std::array::from_fn(|j| trace.disc_temp_c[j][k]));
            }
        }
        d
    }

    /// Wheelset `j`'s disc temperature when the speed fell to `v`, degC (0, the cold disc
    /// and the highest friction Eq (2) gives, when not logged).
    pub fn at(&self, j: usize, v: f64) -> f64 {
        let k = self.speed_mps.partition_point(|&s| s > v);
        self.temp_c
            .get(k.min(self.temp_c.len().saturating_sub(1)))
            .map_or(0.0, |t| t[j])
    }
}

/// A brake on rolling wheels: Eq (1) at the demand's cylinder pressure with the pads'
/// friction of Eq (2) (paper), the torque decelerating the effective mass.
#[derive(Clone, Debug)]
pub struct CaliperBrake {
    /// Cylinder pressure of the demand, Pa (the brake unit's mapping,
    /// `hils_brake_unit::demand_pressure`).
    pub demand_pressure_pa: f64,
    caliper: Caliper<f64>,
    friction: DiscPadFriction<f64>,
    /// Friction speed per vehicle speed on a rolling wheel, l_p / r.
    friction_speed_per_mps: f64,
    /// Deceleration per N m of brake torque, 1 / (r M_eff), m/s^2/(N m).
    decel_per_torque: f64,
    disc: DiscTemps,
}

impl CaliperBrake {
    /// The brake of the plant `p` at the demand pressure `demand_pressure_pa`, with the
    /// disc temperatures `disc` (from the trace judged).
    pub fn new(p: &Params, demand_pressure_pa: f64, disc: DiscTemps) -> Self {
        Self {
            demand_pressure_pa,
            caliper: Caliper::new(&p.brake),
            friction: DiscPadFriction::new(&p.friction),
            friction_speed_per_mps: p.brake.friction_radius / p.vehicle.wheel_radius,
            decel_per_torque: 1.0 / (p.vehicle.wheel_radius * p.effective_mass()),
            disc,
        }
    }

    /// Wheelset `j`'s brake deceleration of the vehicle at cylinder pressure `p_pa` and
    /// speed `v` (m/s), m/s^2: T_b / (r M_eff), T_b of Eq (1).
    pub fn wheelset_decel(&self, j: usize, p_pa: f64, v: f64) -> f64 {
        let clamp = self.caliper.clamp_force(p_pa);
        let mu_d = self
            .friction
            .mu_d(v * self.friction_speed_per_mps, self.disc.at(j, v), clamp);
        self.caliper.torque(mu_d, clamp) * self.decel_per_torque
    }
}

/// What the brake does on rolling wheels without WSP: the reference's brake.
#[derive(Clone, Debug)]
pub enum BrakeModel {
    /// A fixed deceleration of the vehicle, m/s^2 (shared equally by the wheelsets).
    Deceleration(f64),
    /// Eq (1) and Eq (2) at the demand's cylinder pressure.
    Caliper(CaliperBrake),
}

impl BrakeModel {
    /// Wheelset `j`'s share of the vehicle's brake deceleration at `share` of the full
    /// demand (of its pressure for a caliper) and speed `v`, m/s^2.
    pub fn wheelset_decel(&self, j: usize, share: f64, v: f64) -> f64 {
        match self {
            BrakeModel::Deceleration(a) => a * share / 4.0,
            BrakeModel::Caliper(c) => c.wheelset_decel(j, c.demand_pressure_pa * share, v),
        }
    }
}

/// The stop a perfect WSP would make (module doc).
pub struct AllowedStop<'a> {
    pub adhesion: &'a AvailableAdhesion,
    pub track: &'a Track,
    pub offsets: [f64; 4],
    pub g: f64,
    /// Running resistance and gradient of the plant.
    pub resistance: Resistance,
    /// The brake the demand makes on rolling wheels.
    pub brake: BrakeModel,
    /// Brake response: the demand builds up as a_d (1 - exp(-(t - t_d) / tau)) after the
    /// dead time t_d, s.
    pub dead_time_s: f64,
    /// Build-up time constant tau, s.
    pub build_up_s: f64,
    /// The adhesion actually available under each wheelset when the rail recovers
    /// (degraded adhesion on): the curves' peaks times these factors. None: the rail does
    /// not recover (factor 1).
    pub mu_factor: Option<MuFactors<'a>>,
    /// Whether the rail recovers (`[degraded_adhesion]` on): then the run can be judged
    /// only with `mu_factor` (the reference would otherwise be the uncleaned adhesion).
    pub recovers: bool,
}

impl AllowedStop<'_> {
    /// Wheelset `j`'s share of the deceleration the adhesion allows at `x`, `v`: g mu_j / 4
    /// (rail force decelerates the moving mass M: a = sum mu_j Q_j / M with Q_j = M g / 4).
    fn wheelset_adhesion_decel(&self, j: usize, x: f64, v: f64) -> f64 {
        let f = self.mu_factor.map_or(1.0, |m| m.at(j, x));
        let mu = self
            .adhesion
            .at(self.track.surface_at(x + self.offsets[j]), v)
            * f;
        self.g * mu / 4.0
    }

    /// Deceleration the adhesion allows at `x`, `v`: g times the mean over the wheelsets of
    /// their available adhesion.
    pub fn adhesion_decel(&self, x: f64, v: f64) -> f64 {
        (0..4).map(|j| self.wheelset_adhesion_decel(j, x, v)).sum()
    }

    /// The brake's share of the demand at `t` s after the command (0 before the dead time).
    pub fn build_up(&self, t: f64) -> f64 {
        if t <= self.dead_time_s {
            0.0
        } else if self.build_up_s <= 0.0 {
            1.0
        } else {
            1.0 - (-(t - self.dead_time_s) / self.build_up_s).exp()
        }
    }

    /// Brake deceleration a perfect WSP reaches at `t`, `x`, `v`: each wheelset's brake as
    /// the demand builds up, capped by the adhesion under it.
    pub fn brake_decel(&self, t: f64, x: f64, v: f64) -> f64 {
        let share = self.build_up(t);
        (0..4)
            .map(|j| {
                self.brake
                    .wheelset_decel(j, share, v)
                    .min(self.wheelset_adhesion_decel(j, x, v))
            })
            .sum()
    }

    /// Equivalent response time t_d + tau (a step of the full demand at it stops in the
    /// same distance on a demand-limited rail, up to a tau^2 term).
    pub fn response_s(&self) -> f64 {
        self.dead_time_s + self.build_up_s
    }

    /// Distance from `v0` (m/s), integrated at 1 ms (running resistance and gradient
    /// included).
    pub fn distance(&self, v0: f64) -> f64 {
        let dt = 1e-3;
        let (mut x, mut v, mut t) = (0.0, v0, 0.0);
        while v > 0.0 {
            let a = self.brake_decel(t, x, v) + self.resistance.decel(v);
            let v_new = (v - a * dt).clamp(0.0, v0.max(v));
            x += 0.5 * (v + v_new) * dt;
            v = v_new;
            t += dt;
            if x > 1e6 || t > 3600.0 {
                break;
            }
        }
        x
    }
}

/// Per-run metrics and verdicts (JSON keys fixed by issue 13), rounded to their resolution
/// (issue 25): distances to the mm, times to the ms, ratios to 1e-4, air to 0.1 l.
#[derive(Clone, Debug, Serialize)]
pub struct Verdict {
    pub name: String,
    pub passed: bool,
    pub stopping_distance_m: Option<f64>,
    pub allowed_distance_m: f64,
    pub distance_ratio: Option<f64>,
    pub adhesion_utilisation: f64,
    /// Free air vented, l (None: not measured).
    pub air_consumption_l: Option<f64>,
    pub max_lock_s: [f64; 4],
    pub lock_count: [u32; 4],
    /// WSP timer actions (None: not measured).
    pub wsp_timer_actions: Option<u32>,
    pub slide_onset_s: [Option<f64>; 4],
    /// Samples of a log whose empty or non-finite cells were interpolated.
    pub filled_samples: usize,
    pub stop_time_s: Option<f64>,
    /// Each criterion and whether it passed.
    pub criteria: Vec<Criterion>,
    /// Metrics the trace cannot give (JSON keys; their values are null, their criteria not
    /// judged).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub not_measured: Vec<String>,
    /// Metrics estimated from the cylinder pressure falls (no valve states logged).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub estimated_from_cylinder_pressure: Vec<String>,
}

/// The criterion on a metric that may not be measured: judged when it is, else listed as
/// `... (not measured: not judged)` and not passed.
fn criterion_on<T>(text: String, value: Option<T>, pass: impl Fn(T) -> bool) -> (String, bool) {
    match value {
        Some(v) => (text, pass(v)),
        None => (format!("{text} (not measured: not judged)"), false),
    }
}

/// One pass criterion of a run.
#[derive(Clone, Debug, Serialize)]
pub struct Criterion {
    pub criterion: String,
    pub passed: bool,
}

/// Longest lock, lock count and slide onset of wheelset `j` (a lock still on at the end
/// counts to the last sample). The slide onset is the first time the wheelset's creepage
/// (v - w) / v exceeds the creepage at which the adhesion under it peaks (independent of
/// the unit's own slide thresholds).
fn locks_of(
    trace: &Trace,
    j: usize,
    allowed: &AllowedStop,
    c: &Criteria,
) -> (f64, u32, Option<f64>) {
    let (mut longest, mut count, mut onset) = (0.0f64, 0u32, None);
    let mut start: Option<f64> = None;
    for k in 1..trace.t_s.len() {
        let (t, v, w) = (trace.t_s[k], trace.v_mps[k], trace.wheel_mps[j][k]);
        let active = v > c.min_speed_mps;
        let locked = active && w < c.lock_speed_ratio * v;
        match (locked, start) {
            (true, None) => {
                start = Some(t);
                count += 1;
            }
            (false, Some(s)) => {
                longest = longest.max(t - s);
                start = None;
            }
            (true, Some(s)) => longest = longest.max(t - s),
            _ => {}
        }
        if onset.is_none() && active {
            let surface = allowed.track.surface_at(trace.x_m[k] + allowed.offsets[j]);
            if (v - w) / v > allowed.adhesion.peak_creep(surface, v) {
                onset = Some(t);
            }
        }
    }
    (longest, count, onset)
}

/// WSP timer actions of wheelset `j`: continuous WSP action (vent or hold: the brake is
/// not applied) of `wsp_timer_s` or longer, an action still on at the end included.
fn timer_actions_of(trace: &Trace, j: usize, timer_s: f64) -> u32 {
    let n = trace.t_s.len();
    let mut actions = 0;
    let mut start: Option<f64> = None;
    for k in 0..n {
        let t = trace.t_s[k];
        match (trace.released(j, k), start) {
            (true, None) => start = Some(t),
            (false, Some(s)) => {
                actions += u32::from(t - s >= timer_s - 1e-6);
                start = None;
            }
            _ => {}
        }
    }
    if let (Some(s), Some(&end)) = (start, trace.t_s.last()) {
        actions += u32::from(end - s >= timer_s - 1e-6);
    }
    actions
}

/// Free air vented from wheelset `j`'s channel, litres at atmospheric pressure: per vent
/// episode (a run of samples at which the dump valve vents as it acts, else as commanded),
/// the pressure at the sample before it less the pressure at its last sample, plus the fall
/// to the sample after it while the pressure still falls there (a rise is the refill that
/// follows). Only for a trace whose pressures and vents are logged ([`Trace::air_measured`]).
///
/// The valve opens and closes between two samples, at any time (a rig's controller runs
/// its control cycle on its own clock): summing the falls between samples that vent lost
/// the fall from the closing to the first sample without vent, up to one sample period of
/// the fastest fall per episode (-1.7 .. -2.0 % of a rig run's air, by the phase of the
/// unit's cycle to the log's samples), and counted only falls, so the transducer's noise
/// added air where a vent falls slowly. The sample after an episode takes the rest of the
/// fall, and a difference of two noisy samples has the noise's mean, zero; only the last
/// interval's positive part keeps a small bias with noise (+-175 Pa rms: about 60 Pa an
/// episode of tens of kPa), so the figure is within 0.3 % at any phase and noise
/// (`tests::air_of_a_sampled_noisy_log_is_unbiased`), and a refill right after the vent
/// (`host-tests` `wsp_bench::metrics_of_a_hand_made_trace`) takes back nothing.
fn air_of(trace: &Trace, j: usize, channel_volume_l: f64) -> f64 {
    let p = &trace.p_cyl_pa[j];
    let vents = if trace.acting_vent[j].len() == p.len() {
        &trace.acting_vent[j]
    } else {
        &trace.venting[j]
    };
    let venting = |k: usize| vents.get(k).copied().unwrap_or(false);
    // An episode from the sample before it (k0) to the first sample after it (k1). A
    // missing pressure at either end (a gap in the log) falls back to the finite falls
    // within, so that one empty cell neither voids the run's air nor becomes NaN.
    // The fall from the valve's closing to the sample after it counts while the pressure
    // still falls; a rise there is the refill that follows (a coarse log, or a unit that
    // fills at once), which must not take back the vented air.
    let episode = |k0: usize, k1: usize| -> f64 {
        let k_last = k1.saturating_sub(1).max(k0);
        if p[k0].is_finite() && p[k1].is_finite() && p[k_last].is_finite() {
            (p[k0] - p[k_last]) + (p[k_last] - p[k1]).max(0.0)
        } else {
            (k0 + 1..=k1)
                .map(|k| p[k - 1] - p[k])
                .filter(|d| d.is_finite() && *d > 0.0)
                .sum()
        }
    };
    let last = p.len().saturating_sub(1);
    let mut fall_pa = 0.0;
    let mut start = None;
    for k in 0..p.len() {
        match (venting(k), start) {
            (true, None) => start = Some(k.saturating_sub(1)),
            (false, Some(k0)) => {
                fall_pa += episode(k0, k);
                start = None;
            }
            _ => {}
        }
    }
    if let Some(k0) = start {
        fall_pa += episode(k0, last);
    }
    channel_volume_l * fall_pa.max(0.0) / P_ATM_PA
}

/// Adhesion utilisation while the brake acts: from the equivalent response time to the
/// stop (or `min_speed_mps`), the speed lost over what a perfect WSP loses in that time,
/// v(k0) - v(k1) over the integral of the perfect WSP's brake deceleration
/// ([`AllowedStop::brake_decel`] at the trace's time, place and speed) + resistance.
fn utilisation_of(trace: &Trace, allowed: &AllowedStop, stop: Option<usize>, c: &Criteria) -> f64 {
    let n = trace.t_s.len();
    let end = stop.unwrap_or(n.saturating_sub(1));
    let Some(k0) = (0..=end.min(n.saturating_sub(1)))
        .find(|&k| trace.t_s[k] >= allowed.response_s() && trace.v_mps[k] > c.min_speed_mps)
    else {
        return 0.0;
    };
    let k1 = (k0..=end)
        .take_while(|&k| trace.v_mps[k] > c.min_speed_mps)
        .last()
        .unwrap_or(k0);
    let available: f64 = (k0 + 1..=k1)
        .map(|k| {
            let (t, x, v) = (trace.t_s[k], trace.x_m[k], trace.v_mps[k]);
            let a = allowed.brake_decel(t, x, v);
            (a + allowed.resistance.decel(v)) * (t - trace.t_s[k - 1])
        })
        .sum();
    if available > 0.0 {
        (trace.v_mps[k0] - trace.v_mps[k1]) / available
    } else {
        0.0
    }
}

/// Judges `trace` against the criteria; `allowed` is the perfect-WSP stop of the run.
pub fn judge(name: &str, trace: &Trace, allowed: &AllowedStop, c: &Criteria) -> Verdict {
    let n = trace.t_s.len();
    let stop_mps = hils_sil::scenario::STOP_SPEED_MPS + trace.speed_resolution_mps.max(0.0);
    let stop = (0..n).find(|&k| trace.v_mps[k] <= stop_mps);
    let stopping = stop.map(|k| trace.x_m[k]);
    let v0 = trace.v_mps.first().copied().unwrap_or(0.0);
    let allowed_m = allowed.distance(v0);
    let mut max_lock = [0.0f64; 4];
    let mut locks = [0u32; 4];
    let mut onsets = [None; 4];
    for j in 0..4 {
        (max_lock[j], locks[j], onsets[j]) = locks_of(trace, j, allowed, c);
    }
    let timer = trace.timer_measured().then(|| {
        (0..4)
            .map(|j| timer_actions_of(trace, j, c.wsp_timer_s))
            .sum()
    });
    let air_l = trace
        .air_measured()
        .then(|| (0..4).map(|j| air_of(trace, j, c.channel_volume_l)).sum());
    let mut not_measured = Vec::new();
    if air_l.is_none() {
        not_measured.push("air_consumption_l".to_string());
    }
    if timer.is_none() {
        not_measured.push("wsp_timer_actions".to_string());
    }
    let estimated = if trace.vents_estimated && air_l.is_some() {
        vec!["air_consumption_l".to_string()]
    } else {
        Vec::new()
    };
    let utilisation = utilisation_of(trace, allowed, stop, c);
    let ratio = stopping.map(|s| s / allowed_m);
    // A criterion that does not apply is not listed (it would read as passed): the
    // adhesion reference needs the logged friction factors only when the rail recovers.
    let reference_known = allowed.recovers.then(|| {
        (
            "adhesion reference known (degraded adhesion: friction factors logged)".to_string(),
            allowed.mu_factor.is_some(),
        )
    });
    let criteria: Vec<Criterion> = reference_known
        .into_iter()
        .chain([
            ("stops".to_string(), stop.is_some()),
            (
                format!("distance_ratio <= {}", c.max_distance_ratio),
                ratio.is_some_and(|r| r <= c.max_distance_ratio),
            ),
            (
                format!("max_lock_s <= {}", c.max_lock_s),
                max_lock.iter().all(|&l| l <= c.max_lock_s),
            ),
            criterion_on(
                format!("wsp_timer_actions <= {}", c.max_wsp_timer_actions),
                timer,
                |t| t <= c.max_wsp_timer_actions,
            ),
            criterion_on(
                format!("air_consumption_l <= {}", c.max_air_consumption_l),
                air_l,
                |a| a <= c.max_air_consumption_l,
            ),
        ])
        .map(|(criterion, passed)| Criterion { criterion, passed })
        .collect();
    let (mm, ms, ratio_dp, litre) = (3, 3, 4, 1);
    Verdict {
        name: name.to_string(),
        passed: criteria.iter().all(|c| c.passed),
        stopping_distance_m: stopping.map(|x| round_dp(x, mm)),
        allowed_distance_m: round_dp(allowed_m, mm),
        distance_ratio: ratio.map(|r| round_dp(r, ratio_dp)),
        adhesion_utilisation: round_dp(utilisation, ratio_dp),
        air_consumption_l: air_l.map(|a| round_dp(a, litre)),
        max_lock_s: max_lock.map(|t| round_dp(t, ms)),
        lock_count: locks,
        wsp_timer_actions: timer,
        filled_samples: trace.filled_samples,
        slide_onset_s: onsets.map(|o| o.map(|t| round_dp(t, ms))),
        stop_time_s: stop.map(|k| round_dp(trace.t_s[k], ms)),
        criteria,
        not_measured,
        estimated_from_cylinder_pressure: estimated,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A WSP cycle of a cylinder on a fine time grid (10 us): from the EB pressure, a short
    /// dump (fast falls) then hold, fill; every third cycle a long dump to near 0 (slow
    /// falls, below the transducer's noise per sample). Returns the pressures, the vent
    /// states and the air the vents let out, Pa of fall.
    fn fine_cylinder(phase_steps: usize) -> (Vec<f64>, Vec<bool>, f64) {
        let (dt, p_eb) = (1e-5f64, 3.5e5);
        let (vent_tau, fill_tau) = (0.15, 0.1);
        // In fine steps: a cycle of 0.9 s from 50 ms on (the first step of a sample period
        // at phase 0, as a SIL trace), dumps of 60 or 600 ms, 0.1 s hold.
        let (start, cycle, hold) = (5_001 + phase_steps, 90_000, 10_000);
        let n = 600_000;
        let (mut p, mut vented) = (p_eb, 0.0);
        let (mut ps, mut vents) = (Vec::with_capacity(n), Vec::with_capacity(n));
        for i in 0..n {
            let running = i >= start;
            let (number, in_cycle) = (
                (i.max(start) - start) / cycle,
                (i.max(start) - start) % cycle,
            );
            let dump = if number % 3 == 2 { 60_000 } else { 6_000 };
            let vent = running && in_cycle < dump;
            let fill = running && in_cycle >= dump + hold;
            let before = p;
            if vent {
                p -= p * (1.0 - (-dt / vent_tau).exp());
                vented += before - p;
            } else if fill {
                p += (p_eb - p) * (1.0 - (-dt / fill_tau).exp());
            }
            ps.push(p);
            vents.push(vent);
        }
        (ps, vents, vented)
    }

    /// The fine cylinder sampled every 1 ms (each sample's vent flag: the valve acting just
    /// before it, as a SIL trace's), with a transducer's noise of `noise_pa` (uniform).
    fn sampled(phase_steps: usize, noise_pa: f64, seed: u32) -> (Trace, f64) {
        let (p, vents, vented) = fine_cylinder(phase_steps);
        let mut trace = Trace::default();
        let mut state = seed;
        for k in (100..p.len()).step_by(100) {
            state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            let u = (state >> 8) as f64 / (1u32 << 24) as f64;
            trace.t_s.push(k as f64 * 1e-5);
            trace.p_cyl_pa[0].push(p[k] + noise_pa * (2.0 * u - 1.0));
            trace.acting_vent[0].push(vents[k]);
        }
        (trace, vented)
    }

    /// Before (falls between vent samples summed): -0.58 % at a 0.9 ms phase of the valve
    /// to the samples (each closing's last fall lost), +7.3 .. +7.9 % with noise of +-600 Pa
    /// (the noise's falls counted in the slow vents). The air per vent episode is exact on an aligned trace (SIL's) and within
    /// 0.3 % at any phase, with or without noise.
    #[test]
    fn air_of_a_sampled_noisy_log_is_unbiased() {
        for tenth_ms in 0..10 {
            let phase_s = tenth_ms as f64 * 1e-4;
            for (noise_pa, seed) in [(0.0, 1), (600.0, 7), (600.0, 99)] {
                let (trace, vented_pa) = sampled(10 * tenth_ms, noise_pa, seed);
                let air = air_of(&trace, 0, P_ATM_PA);
                let err = (air - vented_pa) / vented_pa;
                let limit = if tenth_ms == 0 && noise_pa == 0.0 {
                    1e-9
                } else {
                    3e-3
                };
                assert!(
                    err.abs() <= limit,
                    "phase {phase_s} s, noise {noise_pa} Pa: {air} against {vented_pa} Pa ({err})"
                );
            }
        }
    }

    /// A gap (NaN) at the edge of a vent episode neither voids nor poisons the run's air:
    /// that episode falls back to its finite falls, the others keep their exact figure.
    #[test]
    fn a_gap_in_the_pressure_log_keeps_the_air() {
        let (mut trace, vented_pa) = sampled(0, 0.0, 1);
        let k0 = (1..trace.p_cyl_pa[0].len())
            .find(|&k| trace.acting_vent[0][k])
            .unwrap();
        trace.p_cyl_pa[0][k0 - 1] = f64::NAN;
        let air = air_of(&trace, 0, P_ATM_PA);
        assert!(air.is_finite() && air > 0.0, "air {air}");
        assert!(
            (air - vented_pa).abs() / vented_pa < 0.05,
            "{air} against {vented_pa} Pa"
        );
    }
}
