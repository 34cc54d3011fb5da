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

use anyhow::{Result, anyhow};
use clap::Args;
use hils_brake_unit::{BrakeDemand, Valve};
use hils_plant::{Surface, WHEELSETS};
use hils_sil::ClosedLoop;
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

fn print_table(verdicts: &[&Verdict]) {
    crate::say!("{}", report::table(verdicts));
}

pub fn main(args: WspTestArgs) -> Result<()> {
    let out = args.out.check()?;
    let file = params_or_default(args.params.as_deref())?;
    let programme = Programme::load(&args.programme)?;
    let runs = programme.runs(&file)?;
    let criteria = programme.criteria.for_file(&file);
    if let Some(log) = &args.log {
        let map = crate::measured::load_map(args.map.as_deref())?;
        let log =
            crate::measured::read_run_log_with(log, map.as_ref()).map_err(|e| anyhow!("{e}"))?;
        let named = log.metadata.get("run").map(str::to_string);
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
        let verdict = judge_run_log(&log, &run, &criteria)?.verdict;
        print_table(&[&verdict]);
        return out.write_json(&[&verdict]);
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
    crate::say!(
        "{passed}/{} runs passed; programme time {elapsed:.1} s on {} threads",
        verdicts.len(),
        rayon::current_num_threads()
    );
    out.write_json(&verdicts)?;
    out.write_report(|dir| {
        let dir = dir.path();
        report::write(dir, &outcomes, &criteria)?;
        Ok(vec![dir.join("report.md")])
    })
}
