//! What the bench judges in a run, from its time series (a SIL run or a captured rig log:
//! the same code).
//!
//! * **Stopping distance**: carbody distance from the brake command (t = 0) to standstill.
//! * **Allowed distance** (in the spirit of CEN/TR 17315, which judges WSP by the stopping
//!   distance against the one the available adhesion permits): a point-mass stop from the
//!   same speed in which the brake acts after the unit's response time t_r (dead time + fill
//!   time constant: the delay of a first-order build-up) and then decelerates at each
//!   position at min(a_demand, g mu_avail(x) M / M_eff), mu_avail(x) the available
//!   adhesion (peak of F/Q over creepage, at the current speed) of the surface under each
//!   wheelset, averaged over the four. Running resistance is left out (the allowed distance
//!   is that of a perfect WSP on the same rail).
//! * **Distance ratio** = stopping / allowed distance; pass if <= `max_distance_ratio`.
//! * **Adhesion utilisation** = the deceleration achieved over the deceleration the
//!   available adhesion allows, time-averaged while v > `min_speed_mps` and the brake acts:
//!   integral(a) / integral(g mu_avail M / M_eff).
//! * **Air consumption**: free air vented by the WSP dump valves, litres at atmospheric
//!   pressure (isothermal): sum over vent samples of V_cyl (p[k-1] - p[k]) / p_atm.
//! * **Locks**: a wheelset is locked while its speed is below `lock_speed_ratio` of the
//!   vehicle speed (v > `min_speed_mps`); longest lock per wheelset, number of locks.
//! * **WSP timer actions**: continuous vents of `wsp_timer_s` or longer.
//! * **Slide onsets**: first time a wheelset's deficit exceeds max(0.8 m/s, 6 % v).

use hils_plant::contact::Polach;
use hils_plant::track::ContactSets;
use hils_plant::{Params, Surface, Track};
use serde::Serialize;

use super::programme::Criteria;

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
    /// Resolution of the logged vehicle speed, m/s (0 for a simulated trace): a speed within
    /// it of the stop speed cannot be told from standstill.
    pub speed_resolution_mps: f64,
}

/// Available adhesion of each surface as a function of speed (1 m/s grid).
pub struct AvailableAdhesion {
    table: [Vec<f64>; 4],
}

impl AvailableAdhesion {
    pub fn new(params: &Params, sets: &ContactSets) -> Self {
        let q = params.total_mass() * params.vehicle.g / 4.0;
        let table = Surface::ALL.map(|s| {
            let polach = Polach::<f64>::with_set(&params.contact, &sets.set(&params.contact, s));
            (0..=120)
                .map(|v| {
                    let v = (v as f64).max(0.5);
                    (1..400)
                        .map(|i| polach.adhesion_coefficient(i as f64 * 5e-4, v, q))
                        .fold(0.0, f64::max)
                })
                .collect()
        });
        Self { table }
    }

    /// Peak adhesion coefficient of `surface` at speed `v` (m/s).
    pub fn at(&self, surface: Surface, v: f64) -> f64 {
        let t = &self.table[surface as usize];
        let x = v.clamp(0.0, (t.len() - 1) as f64);
        let i = (x.floor() as usize).min(t.len() - 2);
        let f = x - i as f64;
        t[i] * (1.0 - f) + t[i + 1] * f
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

/// The stop a perfect WSP would make (module doc).
pub struct AllowedStop<'a> {
    pub adhesion: &'a AvailableAdhesion,
    pub track: &'a Track,
    pub offsets: [f64; 4],
    /// M / M_eff (rotating inertia).
    pub mass_ratio: f64,
    pub g: f64,
    pub demand_mps2: f64,
    pub response_s: f64,
}

impl AllowedStop<'_> {
    /// Deceleration the adhesion allows at `x`, `v`.
    pub fn adhesion_decel(&self, x: f64, v: f64) -> f64 {
        self.g * self.mass_ratio * self.adhesion.under_vehicle(self.track, &self.offsets, x, v)
    }

    /// Distance from `v0` (m/s), integrated at 1 ms.
    pub fn distance(&self, v0: f64) -> f64 {
        let dt = 1e-3;
        let mut x = v0 * self.response_s;
        let mut v = v0;
        while v > 0.0 {
            let a = self.demand_mps2.min(self.adhesion_decel(x, v));
            let v_new = (v - a * dt).max(0.0);
            x += 0.5 * (v + v_new) * dt;
            v = v_new;
            if x > 1e6 {
                break;
            }
        }
        x
    }
}

/// Per-run metrics and verdicts (JSON keys fixed by issue 13).
#[derive(Clone, Debug, Serialize)]
pub struct Verdict {
    pub name: String,
    pub passed: bool,
    pub stopping_distance_m: Option<f64>,
    pub allowed_distance_m: f64,
    pub distance_ratio: Option<f64>,
    pub adhesion_utilisation: f64,
    pub air_consumption_l: f64,
    pub max_lock_s: [f64; 4],
    pub lock_count: [u32; 4],
    pub wsp_timer_actions: u32,
    pub slide_onset_s: [Option<f64>; 4],
    pub stop_time_s: Option<f64>,
    /// Each criterion and whether it passed.
    pub criteria: Vec<Criterion>,
}

/// One pass criterion of a run.
#[derive(Clone, Debug, Serialize)]
pub struct Criterion {
    pub criterion: String,
    pub passed: bool,
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
    let mut timer = 0u32;
    let mut air_l = 0.0;
    let (mut used, mut available) = (0.0, 0.0);
    for j in 0..4 {
        let mut lock_start: Option<f64> = None;
        let mut vent_start: Option<f64> = None;
        for k in 1..n {
            let (t, v, w) = (trace.t_s[k], trace.v_mps[k], trace.wheel_mps[j][k]);
            let active = v > c.min_speed_mps;
            let locked = active && w < c.lock_speed_ratio * v;
            match (locked, lock_start) {
                (true, None) => {
                    lock_start = Some(t);
                    locks[j] += 1;
                }
                (false, Some(s)) => {
                    max_lock[j] = max_lock[j].max(t - s);
                    lock_start = None;
                }
                (true, Some(s)) => max_lock[j] = max_lock[j].max(t - s),
                _ => {}
            }
            if onsets[j].is_none() && active && v - w > (0.06 * v).max(0.8) {
                onsets[j] = Some(t);
            }
            let venting = trace.venting[j].get(k).copied().unwrap_or(false);
            match (venting, vent_start) {
                (true, None) => vent_start = Some(t),
                (false, Some(s)) => {
                    if t - s >= c.wsp_timer_s - 1e-6 {
                        timer += 1;
                    }
                    vent_start = None;
                }
                _ => {}
            }
            let p = &trace.p_cyl_pa[j];
            if venting && p.len() == n && p[k] < p[k - 1] {
                air_l += c.cylinder_volume_l * (p[k - 1] - p[k]) / P_ATM_PA;
            }
        }
    }
    for k in 1..n {
        let v = trace.v_mps[k];
        if v > c.min_speed_mps && stop.is_none_or(|s| k <= s) {
            let dt = trace.t_s[k] - trace.t_s[k - 1];
            used += (trace.v_mps[k - 1] - v).max(0.0);
            available += allowed.adhesion_decel(trace.x_m[k], v) * dt;
        }
    }
    let utilisation = if available > 0.0 {
        used / available
    } else {
        0.0
    };
    let ratio = stopping.map(|s| s / allowed_m);
    let criteria: Vec<Criterion> = [
        ("stops".to_string(), stop.is_some()),
        (
            format!("distance_ratio <= {}", c.max_distance_ratio),
            ratio.is_some_and(|r| r <= c.max_distance_ratio),
        ),
        (
            format!("max_lock_s <= {}", c.max_lock_s),
            max_lock.iter().all(|&l| l <= c.max_lock_s),
        ),
        (
            format!("wsp_timer_actions <= {}", c.max_wsp_timer_actions),
            timer <= c.max_wsp_timer_actions,
        ),
        (
            format!("air_consumption_l <= {}", c.max_air_consumption_l),
            air_l <= c.max_air_consumption_l,
        ),
    ]
    .into_iter()
    .map(|(criterion, passed)| Criterion { criterion, passed })
    .collect();
    Verdict {
        name: name.to_string(),
        passed: criteria.iter().all(|c| c.passed),
        stopping_distance_m: stopping,
        allowed_distance_m: allowed_m,
        distance_ratio: ratio,
        adhesion_utilisation: utilisation,
        air_consumption_l: air_l,
        max_lock_s: max_lock,
        lock_count: locks,
        wsp_timer_actions: timer,
        slide_onset_s: onsets,
        stop_time_s: stop.map(|k| trace.t_s[k]),
        criteria,
    }
}
