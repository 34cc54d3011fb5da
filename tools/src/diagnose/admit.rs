//! The admission stage of `hils diagnose` (issue 24 items 1, 2, 3, 7, 18): what the method
//! can judge, before anything is replayed. A file it cannot judge is refused with a
//! [`CannotJudge`] error naming the file, the column, the duration or the rate; there is no
//! diagnosis JSON then, because every value of its `discrepancy` would be a confident answer
//! (see docs/diagnosis.md, "What the method cannot judge").
//!
//! The limits come from the method itself:
//! - **rate**: comparison bins are 20 ms or two sample intervals, and fit and validation
//!   data alternate in blocks of [`VALIDATION_BLOCK_S`]: a bin must fit in a block, so a
//!   sample at least every [`MAX_SAMPLE_INTERVAL_S`];
//! - **duration**: every decision is made on validation data (every third block), which
//!   must hold at least [`WINDOW_MIN_COUNT`] bins (a window with fewer is not judged);
//! - **braking**: the smallest effect the method names changes the deceleration by about
//!   [`SMALLEST_DECEL_CHANGE`]; it shows at the speed resolution only when the vehicle loses
//!   at least [`MIN_SPEED_LOST_MPS`];
//! - **brake inputs** ([`super::inputs`]): every wheelset needs a measured brake input
//!   (dead transducers, unit errors, gaps the replay cannot bridge).
//!
//! Outliers ([`super::spikes`]) are removed here (kept out of the judgement) and counted,
//! and the notes say once, per column, what the diagnosis does with its empty cells and
//! spikes.

use std::fmt;

use hils_plant::Params;
use hils_sil::record::run_log::{A_X, F_BRAKE, OMEGA, Q, T_DISC, V_REF};

use super::inputs::{self, Role};
use super::plausible;
use super::replay::{self, SPEED_FLOOR_MPS, VALIDATION_BLOCK_S, WINDOW_MIN_COUNT};
use super::spikes;
use crate::measured::RunLog;

/// Why the method cannot judge a file (an error of `hils diagnose`).
#[derive(Clone, Debug, PartialEq)]
pub struct CannotJudge {
    /// The file's name.
    pub file: String,
    /// What is wrong, naming the column, the duration or the rate.
    pub reason: String,
}

impl fmt::Display for CannotJudge {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "cannot judge {}: {}", self.file, self.reason)
    }
}

impl std::error::Error for CannotJudge {}

/// Largest median sample interval, s: two samples must fit in a validation block.
pub const MAX_SAMPLE_INTERVAL_S: f64 = VALIDATION_BLOCK_S / 2.0;
/// Smallest relative change of the deceleration the method names (a friction level 1 %
/// off; `search::MIN_EFFECT` of its scale).
pub const SMALLEST_DECEL_CHANGE: f64 = 0.01;
/// Least speed the vehicle must lose over a log, m/s: a deceleration error of
/// [`SMALLEST_DECEL_CHANGE`] shows at the speed resolution only over this much.
pub const MIN_SPEED_LOST_MPS: f64 = SPEED_FLOOR_MPS / SMALLEST_DECEL_CHANGE;

/// Runs admitted to the diagnosis: copies of the logs with their outliers removed and the
/// brake inputs chosen, and the notes on what was done.
pub struct Admitted {
    pub logs: Vec<RunLog>,
    pub notes: Vec<String>,
}

/// Admits the runs, or says which one the method cannot judge and why.
pub fn admit(baseline: &Params, logs: &[RunLog]) -> Result<Admitted, CannotJudge> {
    let mut out = Admitted {
        logs: Vec::with_capacity(logs.len()),
        notes: Vec::new(),
    };
    for log in logs {
        let refuse = |reason: String| CannotJudge {
            file: log.name(),
            reason,
        };
        let mut clean = log.clone();
        let stuck = plausible::remove_stuck(&mut clean);
        let speed_notes = check_speeds(&clean, &stuck).map_err(refuse)?;
        plausible::check_speed_units(baseline, &clean).map_err(refuse)?;
        check_rate(log).map_err(refuse)?;
        check_duration(&clean).map_err(refuse)?;
        let spiked = remove_spikes(baseline, &mut clean);
        let trace = inputs::SpeedTrace::new(baseline, &clean);
        let chosen = inputs::choose(baseline, &mut clean, &trace).map_err(refuse)?;
        check_speed_lost(&trace).map_err(refuse)?;
        let mut notes = speed_notes;
        notes.extend(stuck_notes(&stuck));
        notes.extend(column_notes(log, &spiked, &chosen.roles));
        notes.extend(chosen.notes);
        notes.extend(plausible::remove_implausible_observations(
            baseline, &mut clean,
        ));
        // The reader's notes on empty cells are restated above with what the diagnosis does
        // with them (one note per column).
        clean
            .notes
            .retain(|n| !log.missing.keys().any(|c| n.starts_with(&format!("{c}:"))));
        notes.splice(0..0, clean.notes.drain(..));
        out.notes
            .extend(notes.into_iter().map(|n| format!("{}: {n}", log.name())));
        out.logs.push(clean);
    }
    Ok(out)
}

/// The speeds the method needs: v_ref (the vehicle's speed, against which slides and creep
/// are judged); a wheel speed without any value, or stuck at one (`stuck`, from
/// [`plausible::remove_stuck`]), leaves that wheelset's speed uncompared.
fn check_speeds(log: &RunLog, stuck: &[(String, f64)]) -> Result<Vec<String>, String> {
    let dead = |x: &[f64]| !x.iter().any(|v| v.is_finite());
    let what = |name: &str| match stuck.iter().find(|(c, _)| c == name) {
        Some((_, v)) => plausible::stuck_text(*v),
        None => "has no value at all".to_string(),
    };
    if dead(&log.v_ref_mps) {
        let name = V_REF.name(0).to_string();
        return Err(format!(
            "{name} {}: the vehicle speed, against which the wheels' slides and creep are \
             judged, is not measured",
            what(&name)
        ));
    }
    Ok((0..log.omega_radps.len())
        .filter(|&j| dead(&log.omega_radps[j]))
        .map(|j| {
            let name = OMEGA.name(j).to_string();
            format!(
                "{name} {}: wheelset {}'s speed is not compared (its wheel-rail link is not \
                 checked, its slides not judged)",
                what(&name),
                j + 1
            )
        })
        .collect())
}

/// The notes on stuck observed channels (the speeds have theirs in [`check_speeds`]).
fn stuck_notes(stuck: &[(String, f64)]) -> Vec<String> {
    stuck
        .iter()
        .filter(|(c, _)| !c.starts_with(OMEGA.stem) && !c.starts_with(V_REF.stem))
        .map(|(c, v)| format!("{c} {}: not compared", plausible::stuck_text(*v)))
        .collect()
}

/// The sample rate the method needs (see the module doc).
fn check_rate(log: &RunLog) -> Result<(), String> {
    let dt = log.median_interval_s();
    // (time stamps written with a few decimals: 10 Hz may read 0.1000000001 s)
    if dt <= MAX_SAMPLE_INTERVAL_S * (1.0 + 1e-6) {
        return Ok(());
    }
    Err(format!(
        "sampled every {} s ({} Hz, column t_s); the method compares bins of two samples in \
         fit and validation blocks of {VALIDATION_BLOCK_S} s and needs a sample at least every \
         {MAX_SAMPLE_INTERVAL_S} s ({} Hz)",
        crate::figures::round_sig(dt, 3),
        crate::figures::round_sig(1.0 / dt, 3),
        1.0 / MAX_SAMPLE_INTERVAL_S
    ))
}

/// Number of validation bins with a v_ref sample in a log of `duration` s with bins of
/// `bin_s` (the bins of [`replay::Prepared`]).
fn validation_bins(t: &[f64], bin_s: f64, duration: f64) -> usize {
    let n_bins = (duration / bin_s).floor() as usize + 1;
    let mut seen = vec![false; n_bins];
    for &ti in t.iter().filter(|&&ti| ti <= duration) {
        let b = ((ti / bin_s) as usize).min(n_bins - 1);
        seen[b] = true;
    }
    (0..n_bins)
        .filter(|&b| seen[b] && replay::is_validation_bin(b, bin_s))
        .count()
}

/// The duration the method needs: enough validation bins to judge a window.
fn check_duration(log: &RunLog) -> Result<(), String> {
    let t0 = log.t_s[0];
    let t: Vec<f64> = log
        .t_s
        .iter()
        .zip(&log.v_ref_mps)
        .filter(|(_, v)| v.is_finite())
        .map(|(t, _)| t - t0)
        .collect();
    let duration = log.t_s.last().map_or(0.0, |t| t - t0);
    let bin_s = replay::bin_width(log.median_interval_s());
    let have = validation_bins(&t, bin_s, duration);
    if have >= WINDOW_MIN_COUNT {
        return Ok(());
    }
    // The shortest log at this bin width that would hold enough (every bin sampled).
    let (mut count, mut b) = (0, 0);
    while count < WINDOW_MIN_COUNT {
        count += usize::from(replay::is_validation_bin(b, bin_s));
        b += 1;
    }
    let need = b as f64 * bin_s;
    Err(format!(
        "the log spans {} s (column t_s) with {have} validation bin(s) of {} ms; every decision \
         is made on validation data (every third {VALIDATION_BLOCK_S} s block), which needs at \
         least {WINDOW_MIN_COUNT} bins: at least {} s of log at this rate",
        crate::figures::round_sig(duration, 3),
        crate::figures::round_sig(bin_s * 1e3, 3),
        crate::figures::round_sig(need, 3)
    ))
}

/// The speed the vehicle must lose (see the module doc).
fn check_speed_lost(trace: &inputs::SpeedTrace) -> Result<(), String> {
    let lost = trace.speed_lost_mps();
    if lost >= MIN_SPEED_LOST_MPS {
        return Ok(());
    }
    Err(format!(
        "the vehicle loses {} m/s over the log (v_ref_mps and the wheel speeds); a {} % change \
         of the deceleration, the smallest effect the method names, shows at its speed \
         resolution ({SPEED_FLOOR_MPS} m/s) only over at least {MIN_SPEED_LOST_MPS} m/s: too \
         little braking to judge",
        crate::figures::round_dp(lost, 2),
        SMALLEST_DECEL_CHANGE * 100.0
    ))
}

/// Spikes found per column: (column name, times of the spikes from the log's start, s).
type Spiked = Vec<(String, Vec<f64>)>;

/// Removes the spikes of every numeric channel (set to "not measured").
fn remove_spikes(baseline: &Params, log: &mut RunLog) -> Spiked {
    let t0 = log.t_s[0];
    let t = log.t_s.clone();
    let wheel_rate = spikes::wheel_rim_accel_max_mps2(baseline) / baseline.vehicle.wheel_radius;
    let mut out = Vec::new();
    for (name, x) in numeric_columns(log) {
        let rate = if name.starts_with(OMEGA.stem) {
            wheel_rate
        } else {
            0.0
        };
        let idx = spikes::spike_indices(&t, x, rate);
        if !idx.is_empty() {
            out.push((name, idx.iter().map(|&i| t[i] - t0).collect()));
            idx.iter().for_each(|&i| x[i] = f64::NAN);
        }
    }
    out
}

/// Every numeric channel of a run log but the time and the WSP flags, by column name.
fn numeric_columns(log: &mut RunLog) -> Vec<(String, &mut Vec<f64>)> {
    let mut out: Vec<(String, &mut Vec<f64>)> =
        vec![(V_REF.name(0).to_string(), &mut log.v_ref_mps)];
    for (j, w) in log.omega_radps.iter_mut().enumerate() {
        out.push((OMEGA.name(j).to_string(), w));
    }
    let per_wheelset = [
        (hils_sil::record::run_log::P_CYL, &mut log.p_cyl_pa),
        (hils_sil::record::run_log::F_CLAMP, &mut log.f_clamp_n),
        (F_BRAKE, &mut log.f_brake_n),
        (T_DISC, &mut log.t_disc_c),
        (Q, &mut log.q_n),
    ];
    for (c, cols) in per_wheelset {
        for (j, col) in cols.iter_mut().enumerate() {
            if let Some(x) = col {
                out.push((c.name(j).to_string(), x));
            }
        }
    }
    if let Some(a) = &mut log.a_x_mps2 {
        out.push((A_X.name(0).to_string(), a));
    }
    out
}

/// Up to three times of a list, s.
fn some_times(t: &[f64]) -> String {
    let shown: Vec<String> = t
        .iter()
        .take(3)
        .map(|x| format!("{}", crate::figures::round_dp(*x, 3)))
        .collect();
    let more = if t.len() > 3 { ", ..." } else { "" };
    format!("t = {}{more} s", shown.join(", "))
}

/// One note per column with empty cells or spikes: how many, and what the diagnosis does
/// with them (issue 24 item 18: one true statement per column).
fn column_notes(log: &RunLog, spiked: &Spiked, roles: &[(String, Role)]) -> Vec<String> {
    let mut names: Vec<&String> = log.missing.keys().collect();
    for (c, _) in spiked {
        if !names.contains(&c) {
            names.push(c);
        }
    }
    let role_of = |c: &str| {
        roles
            .iter()
            .find(|(n, _)| n == c)
            .map_or(Role::Compared, |(_, r)| *r)
    };
    names
        .into_iter()
        // Unused columns and dead wheel speeds have their own note.
        .filter(|c| role_of(c) != Role::Unused)
        .filter(|c| !(c.starts_with(OMEGA.stem) && log.missing.get(*c) == Some(&log.len())))
        .map(|c| {
            let empty = log.missing.get(c).copied().unwrap_or(0);
            let spikes = spiked
                .iter()
                .find(|(n, _)| n == c)
                .map(|(_, t)| t.as_slice());
            let mut what = Vec::new();
            if empty > 0 {
                what.push(format!("{empty} empty cell(s) (not measured)"));
            }
            if let Some(t) = spikes {
                what.push(format!(
                    "{} single-sample spike(s) ({}; an outlier, e.g. interference, not a slide)",
                    t.len(),
                    some_times(t)
                ));
            }
            format!("{c}: {}: {}", what.join(" and "), role_of(c).treatment())
        })
        .collect()
}
