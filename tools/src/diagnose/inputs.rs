//! The brake inputs the replay may use (issue 24 items 1 and 2): per wheelset the clamp
//! force (the input where logged, as the spec says) or else the cylinder pressure through
//! Eq (1), each only where it is measured and plausible.
//!
//! A brake-input column is not usable when
//! - it has no value at all: a dead transducer, which is not a released brake;
//! - it rises and falls with the braking, far above its noise, while the vehicle
//!   decelerates, but never reaches a level any brake could brake with: a unit or channel
//!   error (a pressure in kPa, bar, psi or MPa under `p_cyl*_pa` stays below Eq (1)'s
//!   release threshold K_r / A_c; a clamp force in kN under `f_clamp*_n` would brake the
//!   vehicle at a thousandth of what it does, even at a friction coefficient of
//!   [`MU_MAX`]);
//! - it has a gap longer than [`MAX_INPUT_GAP_S`] across which the input changes (the
//!   replay would invent the brake application there).
//!
//! A wheelset whose clamp force is not usable is driven by its pressure (and the other way
//! round), saying so; a pressure beside the clamp force that is not usable is left out of
//! the pad-force check, saying so; a wheelset with no usable input cannot be judged.

use hils_plant::brake::Caliper;
use hils_plant::{Params, WHEELSETS};
use hils_sil::record::Channel;
use hils_sil::record::run_log::{F_BRAKE, F_CLAMP, P_CYL, T_DISC, WSP};

use super::plausible::quantile;
use super::replay::VALIDATION_BLOCK_S;
use super::spikes::MU_MAX;
use crate::figures::{round_dp, round_sig};
use crate::measured::{RunLog, noise_sigma};

/// Longest gap of a brake input that the replay bridges by linear interpolation when the
/// input differs across it, s (a validation block: about the time a WSP valve takes to
/// vent a cylinder).
pub const MAX_INPUT_GAP_S: f64 = VALIDATION_BLOCK_S;
/// Largest deceleration a car shows without its brakes, m/s^2: the steepest main-line
/// gradient the fit allows (40 permille, 0.39 m/s^2) plus the aerodynamic and rolling drag
/// of a car at 160 km/h (about 0.25 m/s^2), rounded up.
pub const NO_BRAKE_DECEL_MPS2: f64 = 0.7;
/// Least deceleration that shows the vehicle braking while an input is applied, m/s^2
/// (well above the noise of a speed differentiated over 1 s).
pub const MIN_BRAKING_MPS2: f64 = 0.1;
/// A column carries a signal when its range exceeds this many times its noise.
const SIGNAL_SIGMAS: f64 = 20.0;
/// Speed windows for the deceleration, s.
const WINDOW_S: f64 = 0.5;

/// What the diagnosis does with a column (for the notes on its empty cells and spikes).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Role {
    /// A brake input driving the replay.
    Input,
    /// A cylinder pressure beside the clamp force (the pad-force check).
    PressureObservation,
    /// A disc temperature.
    DiscTemp,
    /// A WSP flag.
    Flag,
    /// Any other channel the replay is compared with.
    Compared,
    /// A column the diagnosis does not use.
    Unused,
}

impl Role {
    /// What the diagnosis does with the column's empty cells and spikes.
    pub fn treatment(self) -> &'static str {
        match self {
            Role::Input => "the brake input is bridged across them by linear interpolation",
            Role::PressureObservation => {
                "bridged by linear interpolation for the pressure-to-pad-force check"
            }
            Role::DiscTemp => {
                "left out of the comparison; where Eq (2) takes the measured disc temperature, \
                 it is interpolated between readings"
            }
            Role::Flag => "no venting is read there (the slides count the cells with a value)",
            Role::Compared | Role::Unused => "left out of the comparison (nothing is invented)",
        }
    }
}

/// The vehicle's speed in windows of 0.5 s (median of v_ref and the wheel speeds r omega:
/// one bad sensor or a sliding wheel does not move it) and its deceleration over 1 s.
pub struct SpeedTrace {
    /// Window starts, s from the log's start.
    t0: f64,
    v: Vec<f64>,
    decel: Vec<f64>,
}

impl SpeedTrace {
    pub fn new(baseline: &Params, log: &RunLog) -> Self {
        let r = baseline.vehicle.wheel_radius;
        let t0 = log.t_s[0];
        let n = ((log.t_s.last().unwrap_or(&t0) - t0) / WINDOW_S) as usize + 1;
        let mut samples: Vec<Vec<f64>> = vec![Vec::new(); n];
        for i in 0..log.len() {
            let mut s: Vec<f64> = std::iter::once(log.v_ref_mps[i])
                .chain(log.omega_radps.iter().map(|w| w[i] * r))
                .filter(|x| x.is_finite())
                .collect();
            if !s.is_empty() {
                samples[((log.t_s[i] - t0) / WINDOW_S) as usize].push(median(&mut s));
            }
        }
        let v: Vec<f64> = samples.iter_mut().map(|s| median(s)).collect();
        let decel = (0..n)
            .map(|k| {
                let (a, b) = (k.saturating_sub(1), (k + 1).min(n - 1));
                (v[a] - v[b]) / ((b - a).max(1) as f64 * WINDOW_S)
            })
            .collect();
        SpeedTrace { t0, v, decel }
    }

    /// Speed lost from the first window to the slowest, m/s.
    pub fn speed_lost_mps(&self) -> f64 {
        let first = self
            .v
            .iter()
            .copied()
            .find(|x| x.is_finite())
            .unwrap_or(0.0);
        let slowest = self
            .v
            .iter()
            .copied()
            .filter(|x| x.is_finite())
            .fold(f64::INFINITY, f64::min);
        (first - slowest).max(0.0)
    }

    /// The deceleration the vehicle shows while a column (`t`, `x`) is above `level`,
    /// beyond what it shows while it is below (or beyond [`NO_BRAKE_DECEL_MPS2`] when the
    /// log has less than 1 s below), m/s^2, and the mean deceleration while above. Windows
    /// where the vehicle is nearly at rest are left out. None: never above.
    fn braking_while(&self, t: &[f64], x: &[f64], level: f64) -> Option<(f64, f64)> {
        let mut col: Vec<Vec<f64>> = vec![Vec::new(); self.v.len()];
        for (ti, xi) in t.iter().zip(x) {
            let k = ((ti - self.t0) / WINDOW_S) as usize;
            if let Some(c) = col.get_mut(k) {
                c.push(*xi);
            }
        }
        let (mut up, mut down) = (Vec::new(), Vec::new());
        for (k, c) in col.iter_mut().enumerate() {
            if c.is_empty() || !(self.v[k] > 1.0 && self.decel[k].is_finite()) {
                continue;
            }
            if median(c) > level {
                up.push(self.decel[k]);
            } else {
                down.push(self.decel[k]);
            }
        }
        let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
        if up.is_empty() {
            return None;
        }
        let without = if down.len() >= 2 {
            mean(&down)
        } else {
            NO_BRAKE_DECEL_MPS2
        };
        Some((mean(&up) - without, mean(&up)))
    }
}

fn median(x: &mut [f64]) -> f64 {
    if x.is_empty() {
        return f64::NAN;
    }
    let k = x.len() / 2;
    *x.select_nth_unstable_by(k, f64::total_cmp).1
}

/// The inputs chosen for a run: every used column's role and the notes on what was left
/// out or switched.
pub struct Chosen {
    pub roles: Vec<(String, Role)>,
    pub notes: Vec<String>,
}

/// A brake-input column of a log: its kind, wheelset and values.
struct Column<'a> {
    channel: Channel,
    j: usize,
    t: &'a [f64],
    x: &'a [f64],
}

impl Column<'_> {
    fn name(&self) -> String {
        self.channel.name(self.j).to_string()
    }
}

/// Chooses each wheelset's brake input (and the pressure observations) in `log`, removing
/// the columns that are not usable; an error when a wheelset has no usable input.
pub fn choose(baseline: &Params, log: &mut RunLog, trace: &SpeedTrace) -> Result<Chosen, String> {
    let mut chosen = Chosen {
        roles: Vec::new(),
        notes: Vec::new(),
    };
    let mut refused = Vec::new();
    let checks: Vec<(Check, Check)> = (0..WHEELSETS)
        .map(|j| {
            let check = |channel: Channel, x: &Option<Vec<f64>>| {
                x.as_ref().map(|x| {
                    let c = Column {
                        channel,
                        j,
                        t: &log.t_s,
                        x,
                    };
                    (c.name(), usable(baseline, &c, trace))
                })
            };
            (
                check(F_CLAMP, &log.f_clamp_n[j]),
                check(P_CYL, &log.p_cyl_pa[j]),
            )
        })
        .collect();
    let others_brake = checks.iter().any(|(f, p)| signal(f) || signal(p));
    for (j, (force, pressure)) in checks.into_iter().enumerate() {
        let isolated_checked = log.f_brake_n[j].is_some();
        let unbraked = !signal(&force) && !signal(&pressure);
        let [force, pressure] = quiet_inputs([force, pressure], others_brake, isolated_checked, j)
            .map(|c| c.map(|(name, r)| (name, r.map(|_| ()))));
        let usable_any = [&force, &pressure]
            .into_iter()
            .any(|c| c.as_ref().is_some_and(|c| c.1.is_ok()));
        if isolated_checked && unbraked && others_brake && usable_any {
            chosen.notes.push(format!(
                "wheelset {}'s brake input stays at its released level while the others brake: \
                 replayed as an isolated brake ({} shows whether it is)",
                j + 1,
                F_BRAKE.name(j)
            ));
        }
        let ok = |c: &Option<(String, Result<(), String>)>| c.as_ref().is_some_and(|c| c.1.is_ok());
        let (force_ok, pressure_ok) = (ok(&force), ok(&pressure));
        if !force_ok && !pressure_ok {
            let why: Vec<String> = [force, pressure]
                .into_iter()
                .flatten()
                .filter_map(|(name, r)| r.err().map(|e| format!("{name}: {e}")))
                .collect();
            refused.push(format!(
                "wheelset {} has no usable brake input: {}",
                j + 1,
                why.join("; ")
            ));
            continue;
        }
        for (name, r) in [&force, &pressure].into_iter().flatten() {
            let role = match (r, name.starts_with(F_CLAMP.stem), force_ok) {
                (Err(e), _, _) => {
                    chosen.notes.push(format!("{name} not used: {e}"));
                    Role::Unused
                }
                (Ok(()), true, _) | (Ok(()), false, false) => Role::Input,
                (Ok(()), false, true) => Role::PressureObservation,
            };
            chosen.roles.push((name.clone(), role));
        }
        if !force_ok {
            if force.is_some() {
                chosen.notes.push(format!(
                    "wheelset {} is driven by its cylinder pressure {} through Eq (1)",
                    j + 1,
                    P_CYL.name(j)
                ));
            }
            log.f_clamp_n[j] = None;
        }
        if !pressure_ok {
            log.p_cyl_pa[j] = None;
        }
    }
    if !refused.is_empty() {
        return Err(refused.join("; "));
    }
    for j in 0..WHEELSETS {
        chosen
            .roles
            .push((T_DISC.name(j).to_string(), Role::DiscTemp));
        chosen.roles.push((WSP.name(j).to_string(), Role::Flag));
    }
    Ok(chosen)
}

/// A brake-input column's name and whether it is usable (`Ok(true)`: with a signal).
type Check = Option<(String, Result<bool, String>)>;

fn signal(c: &Check) -> bool {
    matches!(c, Some((_, Ok(true))))
}

fn quiet(c: &Check) -> bool {
    matches!(c, Some((_, Ok(false))))
}

/// Brake inputs that carry no signal (stay at one level within their noise), judged
/// against the wheelset's other input and the other wheelsets (issue 24 item 2): quiet
/// beside the wheelset's other input that applies, it is a dead transducer; quiet while
/// other wheelsets brake and nothing of this one does, it is a dead transducer or an
/// isolated brake, which the speeds cannot tell apart, unless the wheelset's brake force
/// `f_brake` is logged (then it is replayed as isolated and that channel checks it).
fn quiet_inputs(
    [force, pressure]: [Check; 2],
    others_brake: bool,
    isolated_checked: bool,
    j: usize,
) -> [Check; 2] {
    let dead = |c: Check, why: String| c.map(|(name, _)| (name, Err(why)));
    let applies = |c: &Check| c.as_ref().map_or(String::new(), |(n, _)| n.clone());
    let beside = |other: &Check| {
        format!(
            "carries no signal (it stays within its noise) while {} applies the brake: a dead \
             transducer",
            applies(other)
        )
    };
    if signal(&force) && quiet(&pressure) {
        let why = beside(&force);
        return [force, dead(pressure, why)];
    }
    if signal(&pressure) && quiet(&force) {
        let why = beside(&pressure);
        return [dead(force, why), pressure];
    }
    if others_brake && !signal(&force) && !signal(&pressure) && !isolated_checked {
        let why = format!(
            "carries no signal (it stays within its noise) while the other wheelsets brake: a \
             dead transducer or an isolated brake, which the speeds cannot tell apart (with \
             {} logged an isolated brake is judged)",
            F_BRAKE.name(j)
        );
        let f = if quiet(&force) {
            dead(force, why.clone())
        } else {
            force
        };
        let p = if quiet(&pressure) {
            dead(pressure, why)
        } else {
            pressure
        };
        return [f, p];
    }
    [force, pressure]
}

/// Whether a brake-input column is usable (see the module doc), or why not; Ok(true) when
/// it carries a signal (rises above its noise), Ok(false) when it stays at one level.
fn usable(baseline: &Params, c: &Column, trace: &SpeedTrace) -> Result<bool, String> {
    let idx: Vec<usize> = (0..c.x.len()).filter(|&i| c.x[i].is_finite()).collect();
    if idx.is_empty() {
        return Err(
            "no value at all (a dead transducer?): a brake input that is not measured \
                    is not a released brake"
                .into(),
        );
    }
    let t: Vec<f64> = idx.iter().map(|&i| c.t[i]).collect();
    let x: Vec<f64> = idx.iter().map(|&i| c.x[i]).collect();
    let (rest, peak) = (quantile(&x, 0.001), quantile(&x, 0.99));
    if peak - rest <= SIGNAL_SIGMAS * noise_sigma(&t, &x) {
        return Ok(false);
    }
    plausible_units(baseline, c, &t, &x, (rest, peak), trace)?;
    bridgeable(c, &t, &x).map(|()| true)
}

/// The unit or channel check (see the module doc).
fn plausible_units(
    baseline: &Params,
    c: &Column,
    t: &[f64],
    x: &[f64],
    (rest, peak): (f64, f64),
    trace: &SpeedTrace,
) -> Result<(), String> {
    // At rest: the released brake (an emergency brake from the first sample is released
    // for its dead time only); applied: the held level (spikes are already removed).
    let caliper = Caliper::<f64>::new(&baseline.brake);
    let pressure = c.channel == P_CYL;
    let clamp = if pressure {
        caliper.clamp_force(peak)
    } else {
        peak
    };
    let b = &baseline.brake;
    let v = &baseline.vehicle;
    let implied = MU_MAX * clamp * b.friction_faces as f64 * b.friction_radius
        / v.wheel_radius
        / baseline.effective_mass();
    let Some((braking, decel)) = trace.braking_while(t, x, rest + 0.5 * (peak - rest)) else {
        return Ok(());
    };
    if braking < MIN_BRAKING_MPS2 || implied * WHEELSETS as f64 >= 0.1 * braking {
        return Ok(());
    }
    let why = if pressure && clamp <= 0.0 {
        format!(
            "by Eq (1) a cylinder pressure below {} Pa applies no pad force at all: a unit or \
             channel error (kPa, bar, psi or MPa logged as Pa?)",
            round_sig(b.retaining_spring_force / b.piston_area, 3)
        )
    } else {
        format!(
            "even a friction coefficient of {MU_MAX} would brake the vehicle at only {} m/s^2 \
             with it: a unit or channel error ({} logged as {}?)",
            round_sig(implied * WHEELSETS as f64, 2),
            if pressure { "kPa" } else { "kN" },
            if pressure { "Pa" } else { "N" }
        )
    };
    Err(format!(
        "rises to only {} while the vehicle brakes at {} m/s^2; {why}",
        round_sig(peak, 3),
        round_dp(decel, 2)
    ))
}

/// The gap check (see the module doc); `t`, `x` are the finite samples.
fn bridgeable(c: &Column, t: &[f64], x: &[f64]) -> Result<(), String> {
    let (start, end) = (c.t[0], *c.t.last().unwrap_or(&c.t[0]));
    let mut sorted = x.to_vec();
    sorted.sort_by(f64::total_cmp);
    let range = sorted[sorted.len() - 1] - sorted[0];
    let mut gaps: Vec<(f64, f64, bool)> = vec![(start, t[0], false), (t[t.len() - 1], end, false)];
    for k in 1..t.len() {
        let steady = (x[k] - x[k - 1]).abs() <= 0.02 * range;
        gaps.push((t[k - 1], t[k], steady));
    }
    match gaps
        .into_iter()
        .find(|(a, b, steady)| b - a > MAX_INPUT_GAP_S && !steady)
    {
        None => Ok(()),
        Some((a, b, _)) => Err(format!(
            "no reading from t = {} s to {} s ({} s) while the input changes: the replay would \
             invent the brake input there (it bridges at most {MAX_INPUT_GAP_S} s)",
            round_dp(a - start, 3),
            round_dp(b - start, 3),
            round_dp(b - a, 3)
        )),
    }
}
