//! Channel plausibility beyond the brake inputs (issue 24 items 1 and 2, found on data the
//! method was not tuned on): a channel that is stuck, or logged in another unit, must not
//! be read as physics.
//!
//! - **Stuck**: a speed or an observed channel that holds one value at every sample (a
//!   dead sensor whose logger writes 0, or its last value) measures nothing. It is treated
//!   as not measured: a stuck v_ref is refused like an empty one, a stuck wheel speed
//!   leaves that wheelset's speed uncompared (it is no locked wheel: a wheel cannot lock
//!   before the brake applies), a stuck brake force, axle load, disc temperature or a_x
//!   is left out of the comparison. Brake inputs are judged in [`super::inputs`].
//! - **Speed units**: v_ref and the wheel speeds r omega measure the same speed (creep is
//!   a few percent, a slide lasts a fraction of the run). A column that reads more than
//!   [`SPEED_RATIO_MAX`] times, or less than its inverse, the median of the others over
//!   80 % of the moving samples is a unit or channel error (km/h under `v_ref_mps`, rev/s
//!   under `omega*_radps`): refused, naming the column and the factor.
//! - **Observation units**: a brake force `f_brake` is mu x (friction faces) x clamp force;
//!   one that implies a friction coefficient outside [[`MU_MIN`], [`super::spikes::MU_MAX`]]
//!   while its brake applies is in another unit (kN) or on another channel. An axle load
//!   `q` outside [[`LOAD_SHARE_MIN`], 1/[`LOAD_SHARE_MIN`]] of a quarter of the car's weight
//!   likewise. Such a column is left out of the comparison, saying so.

use hils_plant::brake::Caliper;
use hils_plant::{Params, WHEELSETS};
use hils_sil::record::run_log::{A_X, F_BRAKE, OMEGA, Q, T_DISC, V_REF};

use super::spikes::MU_MAX;
use crate::figures::round_sig;
use crate::measured::RunLog;

/// Fewest finite samples before a column that holds one value is called stuck.
const STUCK_MIN_SAMPLES: usize = 10;
/// Largest ratio of a speed column to the median of the others over 80 % of the moving
/// samples (a wheel radius a few percent off, creep and a radar's slow error stay far
/// inside it; km/h for m/s is 3.6, rev/s for rad/s 0.16).
pub const SPEED_RATIO_MAX: f64 = 1.3;
/// Speed below which the speed ratio is not judged, m/s.
const MOVING_MPS: f64 = 2.0;
/// Least friction coefficient a brake force may imply while its brake applies (wet,
/// glazed pads stay above 0.15).
pub const MU_MIN: f64 = 0.05;
/// Least share of a quarter of the car's weight an axle load may show (and its inverse
/// the most: a full payload is about 1.5).
pub const LOAD_SHARE_MIN: f64 = 0.3;

/// The one value of a column that holds one value at every finite sample (stuck), if so.
fn stuck_value(x: &[f64]) -> Option<f64> {
    let mut it = x.iter().copied().filter(|v| v.is_finite());
    let first = it.next()?;
    let mut n = 1;
    for v in it {
        if v != first {
            return None;
        }
        n += 1;
    }
    (n >= STUCK_MIN_SAMPLES).then_some(first)
}

/// Stuck columns of a log, set to not measured (speeds) or removed (observed channels):
/// (column, the one value it reads), for the notes and the errors.
pub fn remove_stuck(log: &mut RunLog) -> Vec<(String, f64)> {
    let mut out = Vec::new();
    let mut speeds: Vec<(String, &mut Vec<f64>)> =
        vec![(V_REF.name(0).to_string(), &mut log.v_ref_mps)];
    for (j, w) in log.omega_radps.iter_mut().enumerate() {
        speeds.push((OMEGA.name(j).to_string(), w));
    }
    for (name, x) in speeds {
        if let Some(v) = stuck_value(x) {
            x.iter_mut().for_each(|s| *s = f64::NAN);
            out.push((name, v));
        }
    }
    for (c, cols) in [
        (F_BRAKE, &mut log.f_brake_n),
        (Q, &mut log.q_n),
        (T_DISC, &mut log.t_disc_c),
    ] {
        for (j, col) in cols.iter_mut().enumerate() {
            if let Some(v) = col.as_deref().and_then(stuck_value) {
                *col = None;
                out.push((c.name(j).to_string(), v));
            }
        }
    }
    if let Some(v) = log.a_x_mps2.as_deref().and_then(stuck_value) {
        log.a_x_mps2 = None;
        out.push((A_X.name(0).to_string(), v));
    }
    out
}

/// What a stuck column's value says, for the notes: "reads 0 at every sample (a dead
/// sensor)".
pub fn stuck_text(value: f64) -> String {
    format!(
        "reads {} at every sample (a dead sensor: no live sensor holds one value)",
        round_sig(value, 4)
    )
}

/// A likely unit behind a factor between a speed column and the others.
fn speed_unit_hint(factor: f64) -> &'static str {
    let near = |k: f64| (factor / k).ln().abs() < 0.1;
    if near(3.6) {
        " (km/h logged as m/s?)"
    } else if near(1.0 / 3.6) {
        " (the others in km/h?)"
    } else if near(60.0 / std::f64::consts::TAU) {
        " (rev/min logged as rad/s?)"
    } else if near(1.0 / std::f64::consts::TAU) {
        " (rev/s logged as rad/s?)"
    } else {
        ""
    }
}

/// The speed-unit check (see the module doc): an error naming every column that does not
/// measure the speed the others do.
pub fn check_speed_units(baseline: &Params, log: &RunLog) -> Result<(), String> {
    let r = baseline.vehicle.wheel_radius;
    let speed = |k: usize, i: usize| {
        if k == 0 {
            log.v_ref_mps[i]
        } else {
            log.omega_radps[k - 1][i] * r
        }
    };
    let mut ratios: Vec<Vec<f64>> = vec![Vec::new(); WHEELSETS + 1];
    for i in 0..log.len() {
        let s: Vec<f64> = (0..=WHEELSETS).map(|k| speed(k, i)).collect();
        for k in 0..=WHEELSETS {
            let mut others: Vec<f64> = (0..=WHEELSETS)
                .filter(|&m| m != k && s[m].is_finite())
                .map(|m| s[m])
                .collect();
            if others.len() < 2 || !s[k].is_finite() {
                continue;
            }
            others.sort_by(f64::total_cmp);
            let mid = others[others.len() / 2];
            if mid > MOVING_MPS {
                ratios[k].push(s[k] / mid);
            }
        }
    }
    let mut wrong = Vec::new();
    for (k, x) in ratios.iter_mut().enumerate() {
        if x.len() < STUCK_MIN_SAMPLES {
            continue;
        }
        x.sort_by(f64::total_cmp);
        let q = |p: f64| x[((x.len() - 1) as f64 * p).round() as usize];
        let (low, mid, high) = (q(0.1), q(0.5), q(0.9));
        if low > SPEED_RATIO_MAX || high < 1.0 / SPEED_RATIO_MAX {
            let name = if k == 0 {
                V_REF.name(0).to_string()
            } else {
                format!("{} (times the wheel radius {r} m)", OMEGA.name(k - 1))
            };
            wrong.push(format!(
                "{name} reads {} times the other speed columns (median over the moving \
                 samples){}",
                round_sig(mid, 3),
                speed_unit_hint(mid)
            ));
        }
    }
    if wrong.is_empty() {
        return Ok(());
    }
    Err(format!(
        "{}; v_ref and the wheel speeds measure the same speed within creep and slides: a \
         unit or channel error",
        wrong.join("; ")
    ))
}

/// The observation-unit check (see the module doc); removes the columns that fail and
/// returns a note for each. Run after the brake inputs are chosen.
pub fn remove_implausible_observations(baseline: &Params, log: &mut RunLog) -> Vec<String> {
    let mut notes = Vec::new();
    let caliper = Caliper::<f64>::new(&baseline.brake);
    let faces = baseline.brake.friction_faces as f64;
    for j in 0..WHEELSETS {
        let clamp: Option<Vec<f64>> = match (&log.f_clamp_n[j], &log.p_cyl_pa[j]) {
            (Some(f), _) => Some(f.clone()),
            (None, Some(p)) => Some(p.iter().map(|&p| caliper.clamp_force(p)).collect()),
            _ => None,
        };
        let (Some(clamp), Some(fb)) = (clamp, &log.f_brake_n[j]) else {
            continue;
        };
        let peak = quantile(&clamp, 0.99);
        let mu: Vec<f64> = clamp
            .iter()
            .zip(fb)
            .filter(|(c, f)| c.is_finite() && f.is_finite() && **c > 0.5 * peak)
            .map(|(c, f)| f / (faces * c))
            .collect();
        if mu.len() < STUCK_MIN_SAMPLES || !(peak > 0.0) {
            continue;
        }
        let m = quantile(&mu, 0.5);
        if !(MU_MIN..=MU_MAX).contains(&m) {
            notes.push(format!(
                "{} not compared: while the brake applies it is {} times the friction faces \
                 ({faces}) x the clamp force, a friction coefficient no pad has (a unit or \
                 channel error{})",
                F_BRAKE.name(j),
                round_sig(m, 2),
                if m < 0.01 { ", kN logged as N?" } else { "" }
            ));
            log.f_brake_n[j] = None;
        }
    }
    let quarter = baseline.total_mass() * baseline.vehicle.g / WHEELSETS as f64;
    for j in 0..WHEELSETS {
        let Some(q) = &log.q_n[j] else { continue };
        let share = quantile(q, 0.5) / quarter;
        if !(LOAD_SHARE_MIN..=1.0 / LOAD_SHARE_MIN).contains(&share) {
            notes.push(format!(
                "{} not compared: its median is {} times a quarter of the car's weight ({} \
                 kN), no axle load of this car (a unit or channel error{})",
                Q.name(j),
                round_sig(share, 2),
                round_sig(quarter * 1e-3, 3),
                if share < 0.01 {
                    ", kN logged as N?"
                } else {
                    ""
                }
            ));
            log.q_n[j] = None;
        }
    }
    notes
}

/// A quantile of the finite values (NaN when none).
pub fn quantile(x: &[f64], p: f64) -> f64 {
    let mut v: Vec<f64> = x.iter().copied().filter(|v| v.is_finite()).collect();
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * p).round() as usize]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stuck_needs_one_value_at_every_sample() {
        assert_eq!(stuck_value(&[0.0; 20]), Some(0.0));
        let mut x = vec![3.5; 20];
        x[3] = f64::NAN;
        assert_eq!(stuck_value(&x), Some(3.5));
        x[7] = 3.5000001;
        assert_eq!(stuck_value(&x), None);
        assert_eq!(stuck_value(&[1.0; 5]), None);
        assert_eq!(stuck_value(&[f64::NAN; 20]), None);
    }

    #[test]
    fn unit_hints() {
        assert!(speed_unit_hint(3.58).contains("km/h"));
        assert!(speed_unit_hint(0.16).contains("rev/s"));
        assert_eq!(speed_unit_hint(2.0), "");
    }
}
