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

use anyhow::{Context, Result, anyhow, bail};
use clap::Args;
use hils_brake_unit::{BrakeDemand, Valve};
use hils_plant::{Surface, WHEELSETS};
use hils_sil::{ClosedLoop, ParamFile};
use indicatif::{ProgressBar, ProgressStyle};
use rayon::prelude::*;

use crate::params_file::params_or_default;
use metrics::{AllowedStop, AvailableAdhesion, Trace, Verdict, judge, wheelset_offsets};
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
    /// Write the per-run results as JSON here.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Write the report (summary table, per-run plots) into this directory.
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Judge a captured rig run log instead of simulating (its `# run: NAME` metadata or
    /// `--run` names the programme's run whose track and criteria apply).
    #[arg(long)]
    pub log: Option<PathBuf>,
    /// The programme's run a `--log` is judged as.
    #[arg(long)]
    pub run: Option<String>,
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
            trace.t_s.push(steps as f64 * dt);
            trace.v_mps.push(out.vehicle_speed as f64);
            trace.x_m.push(out.distance as f64);
            for j in 0..WHEELSETS {
                trace.wheel_mps[j].push(out.wheelsets[j].omega as f64 * r);
                trace.p_cyl_pa[j].push(u.cylinder_pressure[j] as f64);
                trace.venting[j].push(u.valves[j] == Valve::Vent);
            }
            surfaces.push(sim.plant.track().surfaces());
        }
        if done {
            break;
        }
    }
    Ok((trace, surfaces))
}

/// The perfect-WSP stop of a run.
pub fn allowed_stop<'a>(run: &'a Run, adhesion: &'a AvailableAdhesion) -> AllowedStop<'a> {
    let p = &run.file.plant;
    let u = &run.file.brake_unit;
    let demand = match run.demand {
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
    };
    AllowedStop {
        adhesion,
        track: &run.track,
        offsets: wheelset_offsets(p),
        mass_ratio: p.total_mass() / p.effective_mass(),
        g: p.vehicle.g,
        demand_mps2: demand,
        response_s: u.dead_time_s + u.fill_time_constant_s,
    }
}

/// Simulates and judges one run.
pub fn run_one(run: Run, criteria: &Criteria) -> Result<Outcome> {
    let (trace, surfaces) = simulate(&run)?;
    let adhesion = AvailableAdhesion::new(&run.file.plant, &run.sets);
    let verdict = judge(&run.name, &trace, &allowed_stop(&run, &adhesion), criteria);
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
    let log = crate::measured::read_run_log(path).map_err(|e| anyhow!("{e}"))?;
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
    let mut trace = Trace {
        t_s: log.t_s[k0..].iter().map(|t| t - t0).collect(),
        v_mps: log.v_ref_mps[k0..].to_vec(),
        ..Trace::default()
    };
    let mut x = 0.0;
    trace.x_m.push(0.0);
    for k in 1..trace.t_s.len() {
        x += 0.5 * (trace.v_mps[k] + trace.v_mps[k - 1]) * (trace.t_s[k] - trace.t_s[k - 1]);
        trace.x_m.push(x);
    }
    for j in 0..WHEELSETS {
        trace.wheel_mps[j] = log.omega_radps[j][k0..].iter().map(|w| w * r).collect();
        if let Some(p) = &log.p_cyl_pa[j] {
            trace.p_cyl_pa[j] = p[k0..].to_vec();
        }
        if let Some(w) = &log.wsp[j] {
            trace.venting[j] = w[k0..].iter().map(|&b| b > 0.5).collect();
        }
    }
    let run = log.metadata.get("run").map(|s| s.to_string());
    Ok((trace, run))
}

/// Judges a captured run log as `run` of the programme (`hils wsp-test --log` and
/// `hils rig run`): the same metrics and criteria as a SIL run; the surfaces under the
/// wheelsets are those of the run's track at the logged distance.
pub fn judge_trace(run: Run, trace: Trace, criteria: &Criteria) -> Outcome {
    let adhesion = AvailableAdhesion::new(&run.file.plant, &run.sets);
    let verdict = judge(&run.name, &trace, &allowed_stop(&run, &adhesion), criteria);
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
    let criteria = programme.criteria;
    if let Some(log) = &args.log {
        let (trace, named) = trace_of_log(log, &file)?;
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
        if let Some(out) = &args.json {
            write_json(out, &[&verdict])?;
        }
        return Ok(());
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
    if let Some(out) = &args.json {
        write_json(out, &verdicts)?;
    }
    if let Some(dir) = &args.report {
        report::write(dir, &outcomes, &criteria)?;
        println!("report: {}", dir.join("report.md").display());
    }
    Ok(())
}

fn write_json(path: &std::path::Path, verdicts: &[&Verdict]) -> Result<()> {
    let text = serde_json::to_string_pretty(verdicts)?;
    std::fs::write(path, text).with_context(|| format!("cannot write {}", path.display()))
}
