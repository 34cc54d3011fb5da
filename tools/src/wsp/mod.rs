//! `hils wsp-test`: the WSP test bench (issue 13). A programme (TOML, [`programme`]) of runs
//! on tracks of adhesion zones is simulated in SIL (plant + simulated brake unit, f32 as
//! on the target) in parallel over the cores, or a captured rig run is read (`--log`);
//! each run is judged by the same criteria ([`metrics`]); JSON and a report
//! ([`report`]) follow.

pub mod metrics;
pub mod programme;
pub mod report;

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Result, anyhow, bail};
use clap::Args;
use hils_brake_unit::{BrakeDemand, Valve};
use hils_plant::{Surface, WHEELSETS};
use hils_sil::{ClosedLoop, ParamFile};
use indicatif::{ProgressBar, ProgressStyle};
use rayon::prelude::*;

use crate::params_file::params_or_default;
use metrics::{
    AllowedStop, AvailableAdhesion, Resistance, Trace, Verdict, judge, wheelset_offsets,
};
use programme::{Criteria, Programme, Run};

/// Arguments of `hils wsp-test`.
#[derive(Args, Debug, Clone)]
pub struct WspTestArgs {
    /// The test programme (TOML).
    #[arg(long, default_value = "programmes/wsp-low-adhesion.toml")]
    pub programme: PathBuf,
    /// Parameter file (default: built-in values, equal to the reference file).
    #[arg(long)]
    pub params: Option<PathBuf>,
    /// `--json`: the per-run results; `--report`: the summary table and per-run plots.
    #[command(flatten)]
    pub out: crate::outputs::Outputs,
    /// Judge a captured rig run log instead of simulating (its `# run: NAME` metadata or
    /// `--run` names the programme's run whose track and criteria apply).
    #[arg(long)]
    pub log: Option<PathBuf>,
    /// The programme's run a `--log` is judged as.
    #[arg(long)]
    pub run: Option<String>,
    /// Channel map (TOML): which of the files' channels or columns is which spec column,
    /// their units, and metadata (docs/mdf4.md). Without it the spec's names are expected.
    #[arg(long, value_name = "FILE")]
    pub map: Option<PathBuf>,
}

/// A judged run with its trace (for the report).
pub struct Outcome {
    pub run: Run,
    pub trace: Trace,
    /// Surface under each wheelset per sample.
    pub surfaces: Vec<[Surface; 4]>,
    pub verdict: Verdict,
}

/// Record every this many plant steps (1 ms at 10 kHz).
const RECORD_EVERY: u32 = 10;
/// A run gives up after this long, s.
const MAX_TIME_S: f64 = 300.0;

/// Simulates one run (f32, as on the target).
pub fn simulate(run: &Run) -> Result<(Trace, Vec<[Surface; 4]>)> {
    let file = &run.file;
    let mut sim = ClosedLoop::<f32>::from_file(file, hils_plant::Rail::Wet, run.speed_mps as f32)
        .map_err(|e| anyhow!("run `{}`: {e}", run.name))?;
    sim.set_track(file, run.track, &run.sets)
        .map_err(|e| anyhow!("run `{}`: {e}", run.name))?;
    sim.set_demand(run.demand);
    let r = file.plant.vehicle.wheel_radius;
    let dt = file.scenario.paper_eb.step_s;
    let mut rule = hils_sil::StopRule::new(dt, 0.2, MAX_TIME_S);
    let mut trace = Trace::default();
    let mut surfaces = Vec::new();
    loop {
        sim.step();
        let out = sim.outputs();
        let steps = out.steps;
        let done = rule.observe(steps, out.vehicle_speed);
        if steps % RECORD_EVERY == 0 || done {
            let u = sim.unit_outputs();
            let acting = sim.unit.acting_valves();
            trace.t_s.push(steps as f64 * dt);
            trace.v_mps.push(out.vehicle_speed as f64);
            trace.x_m.push(out.distance as f64);
            for j in 0..WHEELSETS {
                trace.wheel_mps[j].push(out.wheelsets[j].omega as f64 * r);
                trace.p_cyl_pa[j].push(u.cylinder_pressure_pa[j] as f64);
                trace.venting[j].push(u.valves[j] == Valve::Vent);
                trace.holding[j].push(u.valves[j] == Valve::Hold);
                trace.acting_vent[j].push(acting[j] == Valve::Vent);
                trace.mu_factor[j].push(sim.plant.track().contact(j).1 as f64);
            }
            surfaces.push(sim.plant.track().surfaces());
        }
        if done {
            break;
        }
    }
    Ok((trace, surfaces))
}

/// Deceleration a run demands of the brake, m/s^2.
pub fn demand_decel(run: &Run) -> f64 {
    let u = &run.file.brake_unit;
    match run.demand {
        BrakeDemand::Emergency => u.eb_deceleration_mps2,
        BrakeDemand::Service { deceleration_mps2 } => {
            (deceleration_mps2 as f64).min(u.eb_deceleration_mps2)
        }
        BrakeDemand::ServiceStep { step } => {
            let steps = u.service_steps.max(1);
            (u.full_service_deceleration_mps2 * step.min(steps) as f64 / steps as f64)
                .min(u.eb_deceleration_mps2)
        }
        BrakeDemand::Release => 0.0,
    }
}

/// The perfect-WSP stop of a run on the adhesion `trace` had available (its logged friction
/// factors when the rail recovers), with the brake response of the parameter file (dead
/// time, fill time constant).
pub fn allowed_stop<'a>(
    run: &'a Run,
    adhesion: &'a AvailableAdhesion,
    trace: &'a Trace,
) -> AllowedStop<'a> {
    let p = &run.file.plant;
    let u = &run.file.brake_unit;
    AllowedStop {
        adhesion,
        track: &run.track,
        offsets: wheelset_offsets(p),
        g: p.vehicle.g,
        resistance: Resistance::of(p),
        demand_mps2: demand_decel(run),
        dead_time_s: u.dead_time_s,
        build_up_s: u.fill_time_constant_s,
        mu_factor: trace.mu_factors(),
        recovers: run.file.degraded_adhesion.enabled,
    }
}

/// Simulates and judges one run.
pub fn run_one(run: Run, criteria: &Criteria) -> Result<Outcome> {
    let (trace, surfaces) = simulate(&run)?;
    let adhesion = AvailableAdhesion::new(&run.file.plant, &run.sets);
    let verdict = judge(
        &run.name,
        &trace,
        &allowed_stop(&run, &adhesion, &trace),
        criteria,
    );
    Ok(Outcome {
        run,
        trace,
        surfaces,
        verdict,
    })
}

/// A captured rig run log as a trace from the brake command (its `brake_command_s`
/// metadata, else the first sample; distance integrated from the vehicle speed), and the
/// run its `# run:` metadata names.
pub fn trace_of_log(path: &std::path::Path, file: &ParamFile) -> Result<(Trace, Option<String>)> {
    trace_of_log_with(path, file, None)
}

/// [`trace_of_log`] of a log (CSV or MDF4) read through a channel map.
pub fn trace_of_log_with(
    path: &std::path::Path,
    file: &ParamFile,
    map: Option<&crate::measured::ChannelMap>,
) -> Result<(Trace, Option<String>)> {
    let log = crate::measured::read_run_log_with(path, map).map_err(|e| anyhow!("{e}"))?;
    let t_brake = match log.metadata.get("brake_command_s") {
        Some(t) => t
            .parse::<f64>()
            .ok()
            .filter(|t| t.is_finite())
            .ok_or_else(|| anyhow!("{}: brake_command_s `{t}` is not a time", path.display()))?,
        None => log.t_s.first().copied().unwrap_or(0.0),
    };
    let k0 = log
        .t_s
        .iter()
        .position(|&t| t >= t_brake)
        .unwrap_or(log.len());
    if log.len() < k0 + 2 {
        bail!(
            "{}: fewer than two samples from the brake command",
            path.display()
        );
    }
    let r = file.plant.vehicle.wheel_radius;
    let t0 = log.t_s[k0];
    let t_s: Vec<f64> = log.t_s[k0..].iter().map(|t| t - t0).collect();
    let mut filled = vec![false; t_s.len()];
    let mut column = |name: &str, y: &[f64]| -> Result<Vec<f64>> {
        let mut y = y[k0..].to_vec();
        fill_gaps(&t_s, &mut y, MAX_GAP_S, &mut filled)
            .map_err(|t| anyhow!("{}: `{name}` has a gap of over {MAX_GAP_S} s at {t:.3} s (from the brake command): not judged", path.display()))?;
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
    let run = log.metadata.get("run").map(|s| s.to_string());
    Ok((trace, run))
}

/// Longest run of empty or non-finite cells of a log column that is interpolated, s (a
/// radar dropout; the spec allows empty `v_ref` cells); a longer gap rejects the log.
pub const MAX_GAP_S: f64 = 0.1;

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

/// Judges a captured run log as `run` of the programme (`hils wsp-test --log` and
/// `hils rig run`): the same metrics and criteria as a SIL run; the surfaces under the
/// wheelsets are those of the run's track at the logged distance.
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

fn print_table(verdicts: &[&Verdict]) {
    println!("{}", report::table(verdicts));
}

pub fn main(args: WspTestArgs) -> Result<()> {
    let file = params_or_default(args.params.as_deref())?;
    let programme = Programme::load(&args.programme)?;
    let runs = programme.runs(&file)?;
    let criteria = programme.criteria.for_file(&file);
    if let Some(log) = &args.log {
        let map = crate::measured::load_map(args.map.as_deref())?;
        let (trace, named) = trace_of_log_with(log, &file, map.as_ref())?;
        let name = args.run.clone().or(named).ok_or_else(|| {
            anyhow!(
                "{}: no `# run:` metadata; name the run with --run",
                log.display()
            )
        })?;
        let run = runs
            .into_iter()
            .find(|r| r.name == name)
            .ok_or_else(|| anyhow!("the programme has no run `{name}`"))?;
        let verdict = judge_trace(run, trace, &criteria).verdict;
        print_table(&[&verdict]);
        return args.out.write_json(&[&verdict]);
    }
    let started = Instant::now();
    let bar = ProgressBar::new(runs.len() as u64).with_style(
        ProgressStyle::with_template("{bar:40} {pos}/{len} runs {elapsed_precise}")
            .map_err(|e| anyhow!("{e}"))?,
    );
    let outcomes: Vec<Outcome> = runs
        .into_par_iter()
        .map(|run| {
            let outcome = run_one(run, &criteria);
            bar.inc(1);
            outcome
        })
        .collect::<Result<_>>()?;
    bar.finish();
    let elapsed = started.elapsed().as_secs_f64();
    let verdicts: Vec<&Verdict> = outcomes.iter().map(|o| &o.verdict).collect();
    print_table(&verdicts);
    let passed = verdicts.iter().filter(|v| v.passed).count();
    println!(
        "{passed}/{} runs passed; programme time {elapsed:.1} s on {} threads",
        verdicts.len(),
        rayon::current_num_threads()
    );
    args.out.write_json(&verdicts)?;
    args.out.write_report(|dir| {
        report::write(dir, &outcomes, &criteria)?;
        Ok(vec![dir.join("report.md")])
    })
}
