//! `hils wsp-test`: the WSP test bench (issue 13). A programme (TOML, [`programme`]) of runs
//! on tracks of adhesion zones is simulated in SIL (plant + simulated brake unit, f32 as
//! on the target) in parallel over the cores, or a captured rig run is read (`--log`);
//! each run is judged by the same criteria ([`metrics`]); JSON and a report
//! ([`report`]) follow.

pub mod log;
pub mod metrics;
pub mod programme;
pub mod report;

pub use log::{
    MAX_GAP_S, fill_gaps, judge_log, judge_run_log, judge_trace, response_of_log, trace_of_log,
};

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Result, anyhow, bail};
use clap::Args;
use hils_brake_unit::Valve;
use hils_plant::{Surface, WHEELSETS};
use hils_sil::ClosedLoop;
use indicatif::{ProgressBar, ProgressStyle};
use rayon::prelude::*;

use crate::outputs::OutDir;
use crate::params_file::params_or_default;
use metrics::{
    AllowedStop, AvailableAdhesion, BrakeModel, CaliperBrake, DiscTemps, Resistance, Trace,
    Verdict, judge, wheelset_offsets,
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
                trace.disc_temp_c[j].push(out.wheelsets[j].disc_temp as f64);
            }
            surfaces.push(sim.plant.track().surfaces());
        }
        if done {
            break;
        }
    }
    Ok((trace, surfaces))
}

/// The brake a run's demand makes on rolling wheels: the brake unit's cylinder pressure of
/// the demand (`hils_brake_unit::demand_pressure`, the same mapping as the unit's) through
/// Eq (1) and Eq (2) with the disc temperatures of `trace`.
pub fn demand_brake(run: &Run, trace: &Trace) -> BrakeModel {
    let p = &run.file.plant;
    let pressure = hils_brake_unit::demand_pressure(p, &run.file.brake_unit, run.demand);
    BrakeModel::Caliper(CaliperBrake::new(p, pressure, DiscTemps::of(trace)))
}

/// The perfect-WSP stop of a run on the adhesion `trace` had available (its logged friction
/// factors when the rail recovers, its disc temperatures), with the brake response of the
/// parameter file (dead time, fill time constant).
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
        brake: demand_brake(run, trace),
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

fn print_table(verdicts: &[&Verdict]) {
    crate::say!("{}", report::table(verdicts));
}

/// Simulates and judges every run in parallel, writing each run's plots into the report
/// folder as it is judged (file stem `NAME`, or `NAME-TAG` with `report = (dir, TAG)`)
/// and keeping only its verdict: memory does not grow with the number of runs beyond their
/// verdicts (issue 24 item 8). A progress bar on standard error.
pub fn judge_runs(
    runs: Vec<Run>,
    criteria: &Criteria,
    report: Option<(&OutDir, &str)>,
) -> Result<Vec<Verdict>> {
    let bar = ProgressBar::new(runs.len() as u64).with_style(
        ProgressStyle::with_template(
            "{bar:40} {pos}/{len} runs, {elapsed_precise} elapsed, about {eta} to go",
        )
        .map_err(|e| anyhow!("{e}"))?,
    );
    if let Some((dir, _)) = report {
        dir.create()?;
    }
    let verdicts = runs
        .into_par_iter()
        .map(|run| {
            let outcome = run_one(run, criteria)?;
            if let Some((dir, tag)) = report {
                let stem = match tag {
                    "" => outcome.run.name.clone(),
                    tag => format!("{}-{tag}", outcome.run.name),
                };
                report::write_run_plots(dir, &stem, &outcome)?;
            }
            bar.inc(1);
            Ok(outcome.verdict)
        })
        .collect::<Result<Vec<Verdict>>>()?;
    bar.finish_and_clear();
    Ok(verdicts)
}

/// The process's peak resident memory, MB (Linux; 0 where unknown).
pub fn peak_memory_mb() -> f64 {
    crate::bench::peak_rss_bytes() as f64 / 1e6
}

pub fn main(args: WspTestArgs) -> Result<()> {
    let mut inputs = vec![("--programme", args.programme.as_path())];
    inputs.extend(args.log.as_deref().map(|l| ("--log", l)));
    inputs.extend(args.params.as_deref().map(|p| ("--params", p)));
    inputs.extend(args.map.as_deref().map(|p| ("--map", p)));
    let out = args.out.check()?.not_over(&inputs)?;
    let file = params_or_default(args.params.as_deref())?;
    let programme = Programme::load(&args.programme)?;
    let runs = programme.runs(&file)?;
    let criteria = programme.criteria.for_file(&file);
    if let Some(log) = &args.log {
        return judge_one_log(&args, log, runs, &criteria, &out);
    }
    let started = Instant::now();
    let verdicts = judge_runs(runs, &criteria, out.report.as_ref().map(|d| (d, "")))?;
    let elapsed = started.elapsed().as_secs_f64();
    let refs: Vec<&Verdict> = verdicts.iter().collect();
    print_table(&refs);
    let passed = verdicts.iter().filter(|v| v.passed).count();
    crate::say!(
        "{passed}/{} runs passed; programme time {elapsed:.1} s on {} threads; peak memory {:.0} MB",
        verdicts.len(),
        rayon::current_num_threads(),
        peak_memory_mb()
    );
    out.write_json(&verdicts)?;
    out.write_report(|dir| Ok(vec![report::write(dir, &verdicts, &criteria)?]))
}

/// `--log FILE`: judges the log as the run its `# run:` metadata (or `--run`) names.
fn judge_one_log(
    args: &WspTestArgs,
    log: &std::path::Path,
    runs: Vec<Run>,
    criteria: &Criteria,
    out: &crate::outputs::Checked,
) -> Result<()> {
    let map = crate::measured::load_map(args.map.as_deref())?;
    let log = crate::measured::read_run_log_with(log, map.as_ref()).map_err(|e| anyhow!("{e}"))?;
    let named = log.metadata.get("run").map(|n| n.trim().to_string());
    // `--run` names the run of another programme's log; the log of one of this programme's
    // runs is not judged as another of its runs (the checks of speed, track and demand do
    // not see a vehicle variant).
    if let (Some(run), Some(logged)) = (&args.run, &named) {
        if run != logged && runs.iter().any(|r| &r.name == logged) {
            bail!(
                "{}: `# run: {logged}` is a run of {} and --run names `{run}`: a log is judged as the run it recorded",
                log.path.display(),
                args.programme.display()
            );
        }
    }
    let name = args.run.clone().or(named).ok_or_else(|| {
        anyhow!(
            "{}: no `# run:` metadata; name the run with --run",
            log.path.display()
        )
    })?;
    let run = runs
        .into_iter()
        .find(|r| r.name == name)
        .ok_or_else(|| anyhow!("the programme has no run `{name}`"))?;
    let outcome = judge_run_log(&log, &run, criteria)?;
    print_table(&[&outcome.verdict]);
    out.write_json(&[&outcome.verdict])?;
    out.write_report(|dir| {
        report::write_run_plots(dir, &outcome.run.name, &outcome)?;
        Ok(vec![report::write(
            dir,
            std::slice::from_ref(&outcome.verdict),
            criteria,
        )?])
    })
}
