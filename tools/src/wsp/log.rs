//! A captured run log judged as a run of the programme: the ONE judging path of
//! `hils wsp-test --log` and `hils rig run` (issue 24 item 5), so the same recording gets
//! the same verdict from both.
//!
//! [`judge_log`] reads the log, refuses it when it is not the run it is judged as
//! ([`check_log_is_run`]: speed, track, demand, each named), takes its trace from the brake
//! command ([`trace_of_log`]), says what the log measured, and judges it with the SIL
//! run's metrics and criteria ([`judge_trace`], `super::metrics`).
//!
//! # What the log must say
//!
//! * **Speed**: the speed at the brake command (and `initial_speed_kmh`, when given) within
//!   [`SPEED_TOLERANCE_KMH`] or [`SPEED_TOLERANCE_SHARE`] of the run's.
//! * **Track**: `# track: LAYOUT` ([`super::programme::track_layout`]: `low`, or
//!   `low; dry from 120 to 220 m`) equal to the run's track, or `# rail: wet|dry` for a run
//!   on a uniform track of that rail. A log that says neither is refused (add the line).
//! * **Demand**: `# demand: emergency|service:<m/s^2>|step:<n>` equal to the run's, or the
//!   `cmd` column at the brake command (`EB`: emergency, `SB`: service), or `eb_command_s`
//!   alone (emergency). A log that says none of these is refused.
//!
//! # Brake command and standstill
//!
//! The brake command is `brake_command_s`, else `eb_command_s`, else the first sample whose
//! `cmd` is not a release, else the first sample. Standstill is the stop speed plus the
//! logged speed's resolution, `# speed_resolution_kmh` (the rig's frames: 0.01 km/h).
//!
//! # What the log measured
//!
//! Speeds and distance always. Air consumption needs the cylinder pressures and the vent
//! states: `wsp1..4` (the spec's vent flags), else vent flags estimated from the pressure
//! falls ([`estimate_vents`]: under a programme run's constant demand only a dump valve
//! lowers a cylinder pressure). WSP timer actions need the vent and the hold states as
//! logged: the spec's run log has no hold states, so they are not measured (a valve-state
//! column reader fills [`Trace::holding`] here). What is not measured is `null`, listed in
//! `not_measured`, its criterion not judged and not passed (`super::metrics`).

use std::path::Path;

use anyhow::{Result, anyhow, bail};
use hils_brake_unit::BrakeDemand;
use hils_plant::{Surface, WHEELSETS};
use hils_sil::{Cmd, KMH_PER_MPS, ParamFile};

use super::metrics::{AvailableAdhesion, Trace, judge, wheelset_offsets};
use super::programme::{Criteria, Run, demand_text, parse_demand, track_layout};
use super::{Outcome, allowed_stop};
use crate::measured::{RunLog, read_run_log};

/// A log's speed at the brake command may differ from its run's by this much, km/h ...
pub const SPEED_TOLERANCE_KMH: f64 = 2.0;
/// ... or by this share of the run's speed, whichever is larger.
pub const SPEED_TOLERANCE_SHARE: f64 = 0.03;

/// Longest run of empty or non-finite cells of a log column that is interpolated, s (a
/// radar dropout; the spec allows empty `v_ref` cells); a longer gap rejects the log.
pub const MAX_GAP_S: f64 = 0.1;

/// Falls of a cylinder pressure faster than this count as venting when the log has no
/// valve states, Pa/s (2 bar/s: above the transducer noise of +-2 ADC counts over a 10 ms
/// telemetry interval, below a dump valve's fall).
pub const VENT_FALL_PA_PER_S: f64 = 2.0e5;

/// Reads the log at `path` and judges it as `run` (module doc): refused when it is not
/// that run.
pub fn judge_log(path: &Path, run: &Run, criteria: &Criteria) -> Result<Outcome> {
    judge_run_log(
        &read_run_log(path).map_err(|e| anyhow!("{e}"))?,
        run,
        criteria,
    )
}

/// Judges a run log read as `run` ([`judge_log`]).
pub fn judge_run_log(log: &RunLog, run: &Run, criteria: &Criteria) -> Result<Outcome> {
    let path = &log.path;
    let t_brake = brake_command_s(log)?;
    let mut trace = trace_of_log(log, &run.file, t_brake)?;
    check_log_is_run(log, run, trace.v_mps[0])
        .map_err(|e| anyhow!("{}: not run `{}`: {e}", path.display(), run.name))?;
    trace.speed_resolution_mps = match log.metadata.number("speed_resolution_kmh", path) {
        Ok(r) => r.unwrap_or(0.0).max(0.0) / KMH_PER_MPS,
        Err(e) => bail!("{e}"),
    };
    if !(0..WHEELSETS).all(|j| trace.venting[j].len() == trace.t_s.len()) {
        estimate_vents(&mut trace);
    }
    Ok(judge_trace(run.clone(), trace, criteria))
}

/// The time of the brake command, s (module doc).
fn brake_command_s(log: &RunLog) -> Result<f64> {
    for key in ["brake_command_s", "eb_command_s"] {
        if let Some(t) = log
            .metadata
            .number(key, &log.path)
            .map_err(|e| anyhow!("{e}"))?
        {
            return Ok(t);
        }
    }
    let first_brake = log.cmd.as_ref().and_then(|c| {
        c.iter()
            .position(|x| cmd_of(x).is_some_and(|c| c != Cmd::Release))
            .map(|k| log.t_s[k])
    });
    Ok(first_brake.unwrap_or(log.t_s[0]))
}

/// The brake command of a `cmd` cell: `EB`, `SB`, `REL` (any case) or its code.
fn cmd_of(cell: &str) -> Option<Cmd> {
    let cell = cell.trim();
    [Cmd::Release, Cmd::Emergency, Cmd::Service]
        .into_iter()
        .find(|c| c.text().eq_ignore_ascii_case(cell))
        .or_else(|| cell.parse::<u8>().ok().and_then(|k| Cmd::try_from(k).ok()))
}

/// Whether two speeds (km/h) are the same run's start (module doc).
fn same_speed(log_kmh: f64, run_kmh: f64) -> bool {
    (log_kmh - run_kmh).abs() <= SPEED_TOLERANCE_KMH.max(SPEED_TOLERANCE_SHARE * run_kmh)
}

/// Checks that the log is a recording of `run` (module doc): its speed at the brake
/// command `v_brake_mps`, its track and its demand. The error names everything that
/// differs.
pub fn check_log_is_run(log: &RunLog, run: &Run, v_brake_mps: f64) -> Result<()> {
    let reasons: Vec<String> = [
        check_speed(log, run, v_brake_mps),
        check_track(log, run),
        check_demand(log, run),
    ]
    .into_iter()
    .filter_map(|r| r.err().map(|e| format!("{e:#}")))
    .collect();
    if reasons.is_empty() {
        Ok(())
    } else {
        bail!("{}", reasons.join("; "))
    }
}

/// The log's `initial_speed_kmh` and its speed at the brake command against the run's.
fn check_speed(log: &RunLog, run: &Run, v_brake_mps: f64) -> Result<()> {
    let run_kmh = run.speed_mps * KMH_PER_MPS;
    let tolerance = format!(
        "more than {SPEED_TOLERANCE_KMH} km/h or {:.0} % apart",
        SPEED_TOLERANCE_SHARE * 100.0
    );
    if let Some(v0) = log
        .metadata
        .number("initial_speed_kmh", &log.path)
        .map_err(|e| anyhow!("{e}"))?
    {
        if !same_speed(v0, run_kmh) {
            bail!(
                "speed: `initial_speed_kmh: {v0}`, the run starts at {run_kmh:.1} km/h ({tolerance})"
            );
        }
    }
    let v_kmh = v_brake_mps * KMH_PER_MPS;
    if !same_speed(v_kmh, run_kmh) {
        bail!(
            "speed: {v_kmh:.1} km/h at the brake command, the run starts at {run_kmh:.1} km/h ({tolerance})"
        );
    }
    Ok(())
}

/// The log's `track` (layout) or `rail` against the run's track.
fn check_track(log: &RunLog, run: &Run) -> Result<()> {
    let want = track_layout(&run.track);
    if let Some(layout) = log.metadata.get("track") {
        if layout.trim() != want {
            bail!(
                "track: the log's is `{}`, the run's is `{want}`",
                layout.trim()
            );
        }
        return Ok(());
    }
    if let Some(rail) = log.rail {
        let surface = match rail {
            hils_plant::Rail::Wet => Surface::Wet,
            hils_plant::Rail::Dry => Surface::Dry,
        };
        if run.track.zones().is_empty() && run.track.base() == surface {
            return Ok(());
        }
        bail!(
            "track: the log is on a {} rail (`rail` metadata), the run's track is `{want}`",
            surface.name()
        );
    }
    bail!(
        "track: the log names neither its track (`# track: {want}`) nor its rail \
         (`# rail: wet|dry`): it cannot be checked against the run's; add the line if it is so"
    )
}

/// The log's `demand` metadata, `cmd` column or `eb_command_s` against the run's demand.
fn check_demand(log: &RunLog, run: &Run) -> Result<()> {
    let want = demand_text(run.demand);
    let mut said = false;
    if let Some(text) = log.metadata.get("demand") {
        let demand = parse_demand(text).map_err(|e| anyhow!("`demand` metadata: {e}"))?;
        if demand_text(demand) != want {
            bail!(
                "demand: the log's is `{}`, the run's is `{want}`",
                text.trim()
            );
        }
        said = true;
    }
    if let Some(cmd) = &log.cmd {
        let t_brake = brake_command_s(log)?;
        let k = log.t_s.partition_point(|&t| t < t_brake).min(log.len() - 1);
        let cell = &cmd[k];
        let run_cmd = Cmd::of(run.demand);
        match cmd_of(cell) {
            Some(c) if c == run_cmd => {}
            Some(c) => bail!(
                "demand: the log's `cmd` at the brake command is `{}`, the run's demand `{want}` is `{}`",
                c.text(),
                run_cmd.text()
            ),
            None if said => {}
            None => bail!(
                "demand: the log's `cmd` at the brake command, `{cell}`, is not EB, SB or REL"
            ),
        }
        said = true;
    }
    if !said && log.metadata.get("eb_command_s").is_some() {
        if run.demand != BrakeDemand::Emergency {
            bail!(
                "demand: the log has an emergency brake (`eb_command_s`), the run's demand is `{want}`"
            );
        }
        said = true;
    }
    if !said {
        bail!(
            "demand: the log says none (no `# demand: {want}`, no `cmd` column, no `eb_command_s`)"
        );
    }
    Ok(())
}

/// A run log as a trace from the brake command `t_brake` s (distance integrated from the
/// vehicle speed; gaps up to [`MAX_GAP_S`] interpolated and counted, longer ones refused).
pub fn trace_of_log(log: &RunLog, file: &ParamFile, t_brake: f64) -> Result<Trace> {
    let path = log.path.display();
    let k0 = log
        .t_s
        .iter()
        .position(|&t| t >= t_brake)
        .unwrap_or(log.len());
    if log.len() < k0 + 2 {
        bail!("{path}: fewer than two samples from the brake command");
    }
    let r = file.plant.vehicle.wheel_radius;
    let t0 = log.t_s[k0];
    let t_s: Vec<f64> = log.t_s[k0..].iter().map(|t| t - t0).collect();
    let mut filled = vec![false; t_s.len()];
    let mut column = |name: &str, y: &[f64]| -> Result<Vec<f64>> {
        let mut y = y[k0..].to_vec();
        fill_gaps(&t_s, &mut y, MAX_GAP_S, &mut filled)
            .map_err(|t| anyhow!("{path}: `{name}` has a gap of over {MAX_GAP_S} s at {t:.3} s (from the brake command): not judged"))?;
        Ok(y)
    };
    let mut trace = Trace {
        v_mps: column("v_ref", &log.v_ref_mps)?,
        ..Trace::default()
    };
    for j in 0..WHEELSETS {
        let omega = column(&format!("omega{}", j + 1), &log.omega_radps[j])?;
        trace.wheel_mps[j] = omega.iter().map(|w| w * r).collect();
        if let Some(p) = &log.p_cyl_pa[j] {
            trace.p_cyl_pa[j] = column(&format!("p_cyl{}", j + 1), p)?;
        }
        if let Some(w) = &log.wsp[j] {
            trace.venting[j] = w[k0..].iter().map(|&b| b > 0.5).collect();
        }
    }
    trace.filled_samples = filled.iter().filter(|&&f| f).count();
    trace.t_s = t_s;
    let mut x = 0.0;
    trace.x_m.push(0.0);
    for k in 1..trace.t_s.len() {
        x += 0.5 * (trace.v_mps[k] + trace.v_mps[k - 1]) * (trace.t_s[k] - trace.t_s[k - 1]);
        trace.x_m.push(x);
    }
    Ok(trace)
}

/// Vent flags from the cylinder pressures, for a log without valve states (module doc):
/// sample k vents while (p[k-1] - p[k]) / dt > [`VENT_FALL_PA_PER_S`]. Nothing when a
/// pressure is not logged (the air is then not measured).
pub fn estimate_vents(trace: &mut Trace) {
    let n = trace.t_s.len();
    if trace.p_cyl_pa.iter().any(|p| p.len() != n) {
        return;
    }
    for j in 0..WHEELSETS {
        let p = &trace.p_cyl_pa[j];
        let mut vent = vec![false; n];
        for k in 1..n {
            let dt = trace.t_s[k] - trace.t_s[k - 1];
            vent[k] = dt > 0.0 && (p[k - 1] - p[k]) / dt > VENT_FALL_PA_PER_S;
        }
        trace.venting[j] = vent;
    }
    trace.vents_estimated = true;
}

/// Fills the non-finite samples of `y` (times `t_s`) linearly between their finite
/// neighbours (the nearest one at either end) and marks them in `filled`; a run longer than
/// `max_gap_s` (or a column with no finite sample) is refused with the time it starts.
pub fn fill_gaps(
    t_s: &[f64],
    y: &mut [f64],
    max_gap_s: f64,
    filled: &mut [bool],
) -> Result<(), f64> {
    let n = y.len();
    let mut k = 0;
    while k < n {
        if y[k].is_finite() {
            k += 1;
            continue;
        }
        let start = k;
        while k < n && !y[k].is_finite() {
            k += 1;
        }
        let before = start.checked_sub(1);
        let after = (k < n).then_some(k);
        let span_start = t_s[before.unwrap_or(start)];
        let span_end = t_s[after.unwrap_or(k - 1)];
        if span_end - span_start > max_gap_s || (before.is_none() && after.is_none()) {
            return Err(t_s[start]);
        }
        for i in start..k {
            y[i] = match (before, after) {
                (Some(a), Some(b)) => {
                    let f = (t_s[i] - t_s[a]) / (t_s[b] - t_s[a]);
                    y[a] + (y[b] - y[a]) * f
                }
                (Some(a), None) => y[a],
                (None, Some(b)) => y[b],
                (None, None) => unreachable!("refused above"),
            };
            filled[i] = true;
        }
    }
    Ok(())
}

/// The brake response of a log from its cylinder pressures (in the spirit of EN 14531's
/// equivalent response time): p_final the highest logged pressure; the fastest wheelset's
/// times to 10 % and 63.2 % of it fit a first-order build-up after a dead time,
/// tau = (t63 - t10) / (1 - ln(1/0.9)), t_d = t10 - ln(1/0.9) tau. None when the pressures
/// are not logged or never reach 63.2 %.
pub fn response_of_log(trace: &Trace) -> Option<(f64, f64)> {
    let n = trace.t_s.len();
    let logged: Vec<&Vec<f64>> = trace.p_cyl_pa.iter().filter(|p| p.len() == n).collect();
    let p_final = logged
        .iter()
        .flat_map(|p| p.iter())
        .fold(0.0f64, |m, &p| m.max(p));
    if logged.is_empty() || p_final <= 0.0 {
        return None;
    }
    let first = |share: f64| {
        logged
            .iter()
            .filter_map(|p| p.iter().position(|&x| x >= share * p_final))
            .map(|k| trace.t_s[k])
            .fold(f64::INFINITY, f64::min)
    };
    let (t10, t63) = (first(0.1), first(1.0 - (-1.0f64).exp()));
    if !(t10.is_finite() && t63.is_finite()) {
        return None;
    }
    let l10 = (1.0f64 / 0.9).ln();
    let tau = ((t63 - t10) / (1.0 - l10)).max(0.0);
    Some(((t10 - l10 * tau).max(0.0), tau))
}

/// Judges a log's trace as `run` of the programme: the same metrics and criteria as a SIL
/// run, the brake response from the logged pressures when they show it; the surfaces under
/// the wheelsets are those of the run's track at the logged distance.
pub fn judge_trace(run: Run, trace: Trace, criteria: &Criteria) -> Outcome {
    let adhesion = AvailableAdhesion::new(&run.file.plant, &run.sets);
    let mut allowed = allowed_stop(&run, &adhesion, &trace);
    if let Some((dead_time_s, build_up_s)) = response_of_log(&trace) {
        (allowed.dead_time_s, allowed.build_up_s) = (dead_time_s, build_up_s);
    }
    let verdict = judge(&run.name, &trace, &allowed, criteria);
    let offsets = wheelset_offsets(&run.file.plant);
    let surfaces = trace
        .x_m
        .iter()
        .map(|&x| offsets.map(|o| run.track.surface_at(x + o)))
        .collect();
    Outcome {
        run,
        trace,
        surfaces,
        verdict,
    }
}
