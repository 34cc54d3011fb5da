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
//! states: `wsp1..4` (the spec's vent flags: the dump valve's coil, as the rig's valve
//! inputs read it), else vent flags estimated from the pressure falls ([`estimate_vents`]:
//! under a programme run's constant demand only a dump valve lowers a cylinder pressure).
//! WSP timer actions need the vent and the hold states as logged: `wsp1..4` and `hold1..4`
//! (the hold valve's coil, an extra column of rig logs and `hils decode`), else they are
//! not measured. The valve states are taken as SIL takes the simulated unit's
//! ([`set_valves`]): venting while the dump coil is energised, holding while the hold coil
//! is without it, the dump valve acting on the cylinder one pneumatic dead time
//! (`[brake_unit] dead_time`) after its coil. A column with an empty cell (an input not
//! wired) gives no states for its wheelset. What is not measured is `null`, listed in
//! `not_measured`, its criterion not judged and not passed (`super::metrics`).

use std::path::Path;

use anyhow::{Result, anyhow, bail};
use hils_brake_unit::BrakeDemand;
use hils_plant::{Surface, WHEELSETS};
use hils_sil::{Cmd, KMH_PER_MPS, ParamFile};

use super::metrics::{
    AvailableAdhesion, BrakeModel, CaliperBrake, DiscTemps, Trace, judge, wheelset_offsets,
};
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
/// valve states, Pa/s (2 bar/s: above the transducer noise over [`VENT_WINDOW_S`], below a
/// dump valve's fall).
pub const VENT_FALL_PA_PER_S: f64 = 2.0e5;

/// The pressure fall of [`VENT_FALL_PA_PER_S`] is taken over at least this time, s (10 ms,
/// the rig's telemetry interval). Sample to sample at 1 kHz the transducer's noise alone
/// falls faster than 2 bar/s (a rig run's log: 267 Pa in 1 ms), and counting those falls
/// made 234 l of a run that vented 56 l; over 10 ms the same noise is 27 kPa/s.
pub const VENT_WINDOW_S: f64 = 0.01;

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
    let not_judged = |e: String| anyhow!("{}: not judged: {e}", path.display());
    crate::diagnose::plausible::check_speed_units(&run.file.plant, log).map_err(not_judged)?;
    let t_brake = brake_command_s(log)?;
    let mut trace = trace_of_log(log, &run.file, t_brake)?;
    check_pressure_units(&trace, &run.file).map_err(|e| not_judged(e.to_string()))?;
    check_log_is_run(log, run, trace.v_mps[0])
        .map_err(|e| anyhow!("{}: not run `{}`: {e}", path.display(), run.name))?;
    trace.speed_resolution_mps = match log.metadata.number("speed_resolution_kmh", path) {
        Ok(r) => r.unwrap_or(0.0).max(0.0) / KMH_PER_MPS,
        Err(e) => bail!("{e}"),
    };
    check_vents_lower_pressure(&trace).map_err(|e| not_judged(e.to_string()))?;
    if !(0..WHEELSETS).all(|j| trace.venting[j].len() == trace.t_s.len()) {
        estimate_vents(&mut trace);
    }
    Ok(judge_trace(run.clone(), trace, criteria))
}

/// Every run of a programme brakes: a logged cylinder pressure that never reaches Eq (1)'s
/// release threshold K_r / A_c (below it the pads apply no force) from the brake command
/// on measures no brake at all. It is in another unit (kPa or bar under `p_cyl*_pa`) or
/// from a dead transducer, and its falls would give the air consumption a thousandth of
/// what it was: refused, naming the column.
fn check_pressure_units(trace: &Trace, file: &ParamFile) -> Result<()> {
    let b = &file.plant.brake;
    let release_pa = b.retaining_spring_force / b.piston_area;
    for (j, p) in trace.p_cyl_pa.iter().enumerate() {
        let peak = p.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        if !p.is_empty() && peak < release_pa {
            bail!(
                "`p_cyl{}_pa` peaks at {} Pa in a braked run, below Eq (1)'s release threshold of {} Pa (no pad force at all): a unit error (kPa or bar logged as Pa?) or a dead transducer",
                j + 1,
                crate::figures::round_sig(peak, 3),
                crate::figures::round_sig(release_pa, 3)
            );
        }
    }
    Ok(())
}

/// Largest rise of a cylinder pressure while its logged dump valve acts, Pa (0.5 bar: far
/// above the transducer noise of a few hundred Pa; a valve open to the atmosphere only
/// lowers the pressure).
pub const VENT_RISE_MAX_PA: f64 = 5.0e4;

/// A dump valve venting (its coil logged energised, acting one dead time later) while the
/// cylinder pressure rises by more than [`VENT_RISE_MAX_PA`] is no vent: the valve input is
/// stuck or miswired (a `wsp` column stuck at 1 gave 0.0 l of air and a timer action per
/// wheelset, judged as the unit's). Refused, naming the column and the time.
fn check_vents_lower_pressure(trace: &Trace) -> Result<()> {
    for j in 0..WHEELSETS {
        let (vent, p) = (&trace.acting_vent[j], &trace.p_cyl_pa[j]);
        if vent.len() != trace.t_s.len() || p.len() != vent.len() {
            continue;
        }
        let mut start: Option<usize> = None;
        for k in 0..vent.len() {
            match (vent[k], start) {
                (true, None) => start = Some(k),
                (false, Some(_)) => start = None,
                (true, Some(k0)) if p[k] - p[k0] > VENT_RISE_MAX_PA => bail!(
                    "`wsp{}` has the dump valve venting from {:.3} s (from the brake command) while `p_cyl{}_pa` rises by {} kPa by {:.3} s: a venting valve only lowers it; a stuck or miswired valve input",
                    j + 1,
                    trace.t_s[k0],
                    j + 1,
                    crate::figures::round_sig((p[k] - p[k0]) / 1e3, 3),
                    trace.t_s[k]
                ),
                _ => {}
            }
        }
    }
    Ok(())
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
        if let Some(t) = &log.t_disc_c[j] {
            trace.disc_temp_c[j] = column(&format!("t_disc{}", j + 1), t)?;
        }
    }
    trace.filled_samples = filled.iter().filter(|&&f| f).count();
    let from_brake = |c: &Option<Vec<f64>>| c.as_ref().map(|c| c[k0..].to_vec());
    set_valves(
        &mut trace,
        &t_s,
        log.wsp.each_ref().map(from_brake),
        log.hold.each_ref().map(from_brake),
        file.brake_unit.dead_time_s,
    );
    trace.t_s = t_s;
    let mut x = 0.0;
    trace.x_m.push(0.0);
    for k in 1..trace.t_s.len() {
        x += 0.5 * (trace.v_mps[k] + trace.v_mps[k - 1]) * (trace.t_s[k] - trace.t_s[k - 1]);
        trace.x_m.push(x);
    }
    Ok(trace)
}

/// The valve states of a log as the judge takes them, the same as SIL's (`super::simulate`:
/// the unit's valves; module doc): venting while the dump coil is energised (`dump`),
/// holding while the hold coil is without it (`hold`), and `acting_vent` the vent delayed by
/// the pneumatic dead time `dead_time_s`, as the unit's acting valves are. A wheelset whose
/// column is absent or has an empty cell (an input not wired) gets no states.
fn set_valves(
    trace: &mut Trace,
    t_s: &[f64],
    dump: [Option<Vec<f64>>; WHEELSETS],
    hold: [Option<Vec<f64>>; WHEELSETS],
    dead_time_s: f64,
) {
    let on = |c: &Option<Vec<f64>>| -> Option<Vec<bool>> {
        let c = c.as_ref()?;
        c.iter()
            .all(|x| x.is_finite())
            .then(|| c.iter().map(|&x| x > 0.5).collect())
    };
    for j in 0..WHEELSETS {
        let Some(vent) = on(&dump[j]) else { continue };
        trace.acting_vent[j] = (0..t_s.len())
            .map(|k| {
                let t = t_s[k] - dead_time_s + 1e-9;
                let i = t_s.partition_point(|&ti| ti <= t);
                i.checked_sub(1).is_some_and(|i| vent[i])
            })
            .collect();
        if let Some(h) = on(&hold[j]) {
            trace.holding[j] = h.iter().zip(&vent).map(|(&h, &v)| h && !v).collect();
        }
        trace.venting[j] = vent;
    }
}

/// Vent flags from the cylinder pressures, for a log without valve states (module doc):
/// every sample of a window of at least [`VENT_WINDOW_S`] (the samples after its first)
/// over which the pressure fell faster than [`VENT_FALL_PA_PER_S`] vents. Nothing when a
/// pressure is not logged (the air is then not measured).
pub fn estimate_vents(trace: &mut Trace) {
    let n = trace.t_s.len();
    if trace.p_cyl_pa.iter().any(|p| p.len() != n) {
        return;
    }
    for j in 0..WHEELSETS {
        trace.venting[j] = falls_faster_than_venting(&trace.t_s, &trace.p_cyl_pa[j]);
    }
    // Every wheelset on the estimate (the logged ones of a partly wired rig too).
    trace.acting_vent = Default::default();
    trace.vents_estimated = true;
}

/// [`estimate_vents`] for one pressure `p` at times `t_s` (increasing).
fn falls_faster_than_venting(t_s: &[f64], p: &[f64]) -> Vec<bool> {
    let n = t_s.len();
    let mut vent = vec![false; n];
    // `start`: the latest sample at least VENT_WINDOW_S before k; `marked`: samples up to
    // it are flagged already (each sample is flagged once: linear in the log's length).
    let (mut start, mut marked) = (0usize, 0usize);
    for k in 1..n {
        while start + 1 < k && t_s[k] - t_s[start + 1] >= VENT_WINDOW_S {
            start += 1;
        }
        let dt = t_s[k] - t_s[start];
        if dt > 0.0 && (p[start] - p[k]) / dt > VENT_FALL_PA_PER_S {
            for flag in &mut vent[(start + 1).max(marked + 1)..=k] {
                *flag = true;
            }
            marked = k;
        }
    }
    vent
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
/// equivalent response time) towards the demand's pressure `demand_pressure_pa`: the
/// fastest wheelset's times to 10 % and 63.2 % of it fit a first-order build-up after a dead
/// time, tau = (t63 - t10) / (1 - ln(1/0.9)), t_d = t10 - ln(1/0.9) tau. Each wheelset only
/// up to its first WSP action (vent or hold) and the stop: a build-up that WSP or the stop
/// cut short is not the brake's response (on a very low adhesion rail the pressure reaches
/// the demand only at the end, which gave tau ~ 100 s). None when the pressures are not
/// logged or no wheelset reaches 63.2 % before its WSP acts (the parameter file's response
/// is then used).
pub fn response_of_log(trace: &Trace, demand_pressure_pa: f64) -> Option<(f64, f64)> {
    if !(demand_pressure_pa > 0.0) {
        return None;
    }
    let n = trace.t_s.len();
    // Up to the stop: at standstill the cylinders go on to the full demand (a controller
    // holds the brake), which the build-up under way never reached.
    let stop_mps = hils_sil::scenario::STOP_SPEED_MPS + trace.speed_resolution_mps.max(0.0);
    let stop = trace.v_mps.iter().position(|&v| v <= stop_mps).unwrap_or(n);
    let acts = |states: &Vec<bool>| states.iter().position(|&a| a).unwrap_or(n);
    let l10 = (1.0f64 / 0.9).ln();
    (0..4)
        .filter(|&j| trace.p_cyl_pa[j].len() == n)
        .filter_map(|j| {
            let end = stop
                .min(acts(&trace.venting[j]))
                .min(acts(&trace.holding[j]));
            let p = &trace.p_cyl_pa[j][..end];
            let first = |share: f64| {
                p.iter()
                    .position(|&x| x >= share * demand_pressure_pa)
                    .map(|k| trace.t_s[k])
            };
            let (t10, t63) = (first(0.1)?, first(1.0 - (-1.0f64).exp())?);
            let tau = ((t63 - t10) / (1.0 - l10)).max(0.0);
            Some(((t10 - l10 * tau).max(0.0), tau))
        })
        .min_by(|a, b| (a.0 + a.1).total_cmp(&(b.0 + b.1)))
}

/// The disc temperatures of the perfect-WSP brake (Eq (2)'s pad friction depends on them)
/// for a log that does not hold them (a rig's log): those of the SIL run of the same
/// programme run, the plant's disc heat balance (Eqs 3-6) under the reference unit. A cold
/// disc instead (0 rise, Eq (2)'s highest friction) made the reference of a low -> dry ->
/// low EB 3.3 % shorter on the rig than in SIL. None when the log holds them, or when the
/// SIL run fails (then the cold disc of [`DiscTemps::at`]).
fn sil_disc_temps(run: &Run, trace: &Trace) -> Option<DiscTemps> {
    let n = trace.t_s.len();
    if trace.disc_temp_c.iter().all(|t| t.len() == n) {
        return None;
    }
    super::simulate(run)
        .ok()
        .map(|(sil, _)| DiscTemps::of(&sil))
}

/// Judges a log's trace as `run` of the programme: the same metrics and criteria as a SIL
/// run, the brake response from the logged pressures when they show it; the surfaces under
/// the wheelsets are those of the run's track at the logged distance.
pub fn judge_trace(run: Run, trace: Trace, criteria: &Criteria) -> Outcome {
    let adhesion = AvailableAdhesion::new(&run.file.plant, &run.sets);
    let mut allowed = allowed_stop(&run, &adhesion, &trace);
    let demand_pressure_pa =
        hils_brake_unit::demand_pressure(&run.file.plant, &run.file.brake_unit, run.demand);
    if let Some(disc) = sil_disc_temps(&run, &trace) {
        allowed.brake =
            BrakeModel::Caliper(CaliperBrake::new(&run.file.plant, demand_pressure_pa, disc));
    }
    if let Some((dead_time_s, build_up_s)) = response_of_log(&trace, demand_pressure_pa) {
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

#[cfg(test)]
mod tests {
    use super::*;

    /// Transducer noise alone (+-7 counts of 38.15 Pa at 1 kHz, up to 534 Pa in 1 ms) is no
    /// vent; a dump (260 -> 200 kPa with the reference vent lag, 0.15 s) is one, from its
    /// first milliseconds (flags at most one window early), and the falls it flags add up to the dump's 60 kPa.
    #[test]
    fn noise_is_no_vent_and_a_dump_is_one() {
        let dt = 1e-3;
        let t: Vec<f64> = (0..2000).map(|k| k as f64 * dt).collect();
        // Deterministic noise in [-7, 7] counts.
        let noise = |k: usize| ((k * 7919 + 13) % 15) as f64 - 7.0;
        let flat: Vec<f64> = (0..t.len()).map(|k| 2.6e5 + 38.15 * noise(k)).collect();
        assert!(!falls_faster_than_venting(&t, &flat).contains(&true));
        let tau = 0.15;
        let (k0, k1) = (
            500,
            500 + (tau * (260.0f64 / 200.0).ln() / dt).round() as usize,
        );
        let dump: Vec<f64> = (0..t.len())
            .map(|k| {
                let p = match k {
                    k if k < k0 => 2.6e5,
                    k if k < k1 => 2.6e5 * (-((k - k0) as f64 * dt) / tau).exp(),
                    _ => 2.6e5 * (-((k1 - k0) as f64 * dt) / tau).exp(),
                };
                p + 38.15 * noise(k)
            })
            .collect();
        let vent = falls_faster_than_venting(&t, &dump);
        // The window that shows the fall begins at most 10 ms before it.
        assert!(!vent[..k0 - 10].contains(&true), "before the dump");
        assert!(vent[k0 + 2..k1].iter().all(|&v| v), "during the dump");
        assert!(!vent[k1 + 20..].contains(&true), "after the dump");
        let fallen: f64 = (1..t.len())
            .filter(|&k| vent[k] && dump[k] < dump[k - 1])
            .map(|k| dump[k - 1] - dump[k])
            .sum();
        let true_fall = dump[k0 - 1] - dump[k1];
        assert!(
            (fallen - true_fall).abs() < 0.05 * true_fall,
            "{fallen} vs {true_fall}"
        );
    }
}
