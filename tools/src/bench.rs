//! `hils bench`: host steps per second of the full plant (17 DOF, four contacts, Eq 2
//! friction, disc heat) in f32 and f64, and the real-time factor at 10 kHz.
//!
//! The plant runs the paper's EB (150 km/h, wet): the brake inputs are the cylinder
//! pressures of a closed-loop run recorded beforehand, so the timed loop is the plant
//! alone (slides and WSP included); a second figure times plant + simulated brake unit.

use std::hint::black_box;
use std::time::Instant;

use anyhow::{Result, anyhow};
use clap::Args;
use hils_brake_unit::BrakeDemand;
use hils_plant::{BrakeInput, Plant, Real};
use hils_sil::{ClosedLoop, KMH_PER_MPS, ParamFile};

/// Initial speed of the benchmark run: the paper's 150 km/h, m/s.
const PAPER_SPEED_MPS: f64 = 150.0 / KMH_PER_MPS;
use serde::Serialize;

#[derive(Args, Debug, Clone)]
pub struct BenchArgs {
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
    /// Plant steps per timed repetition.
    #[arg(long, default_value_t = 300_000, value_parser = crate::cli::steps)]
    pub steps: usize,
    /// Repetitions (the best is reported).
    #[arg(long, default_value_t = 5, value_parser = crate::cli::repeat)]
    pub repeat: usize,
}

/// Figures printed by `hils bench --json`.
#[derive(Debug, Serialize, Clone, PartialEq)]
pub struct BenchFigures {
    pub steps_per_s_f32: f64,
    pub steps_per_s_f64: f64,
    pub realtime_factor_f32: f64,
    pub realtime_factor_f64: f64,
    pub closed_loop_steps_per_s_f32: f64,
    pub ns_per_step_f32: f64,
    pub plant_rate_hz: f64,
    pub steps: usize,
    pub repeat: usize,
    pub math: &'static str,
    pub threads: usize,
}

/// Cylinder pressures of the paper's EB, one per step (closed loop, f32).
fn recorded_inputs(params: &ParamFile, steps: usize) -> Result<Vec<[f32; 4]>> {
    let rail = params.scenario.paper_eb.rail;
    let mut sim = ClosedLoop::<f32>::from_file(params, rail, PAPER_SPEED_MPS as f32)
        .map_err(|e| anyhow!("{e}"))?;
    sim.set_demand(BrakeDemand::Emergency);
    Ok((0..steps)
        .map(|_| {
            sim.step();
            sim.unit_outputs().cylinder_pressure
        })
        .collect())
}

fn time_plant<F: Real>(params: &ParamFile, inputs: &[[f32; 4]], repeat: usize) -> Result<f64> {
    let inputs: Vec<[BrakeInput<F>; 4]> = inputs
        .iter()
        .map(|p| p.map(|x| BrakeInput::CylinderPressure(F::of(x as f64))))
        .collect();
    let mut best = f64::INFINITY;
    for _ in 0..repeat {
        let sc = &params.scenario.paper_eb;
        let mut plant =
            Plant::<F>::with_step(&params.plant, sc.rail, F::of(PAPER_SPEED_MPS), sc.step_s)
                .map_err(|e| anyhow!("{e}"))?;
        let start = Instant::now();
        for input in &inputs {
            black_box(plant.step(black_box(input)));
        }
        best = best.min(start.elapsed().as_secs_f64());
        black_box(plant.outputs());
    }
    Ok(inputs.len() as f64 / best)
}

fn time_closed_loop(params: &ParamFile, steps: usize, repeat: usize) -> Result<f64> {
    let mut best = f64::INFINITY;
    for _ in 0..repeat {
        let rail = params.scenario.paper_eb.rail;
        let mut sim = ClosedLoop::<f32>::from_file(params, rail, PAPER_SPEED_MPS as f32)
            .map_err(|e| anyhow!("{e}"))?;
        sim.set_demand(BrakeDemand::Emergency);
        let start = Instant::now();
        for _ in 0..steps {
            black_box(sim.step());
        }
        best = best.min(start.elapsed().as_secs_f64());
    }
    Ok(steps as f64 / best)
}

/// Measures the figures (single thread).
pub fn measure(params: &ParamFile, steps: usize, repeat: usize) -> Result<BenchFigures> {
    let inputs = recorded_inputs(params, steps)?;
    let rate = 1.0 / params.scenario.paper_eb.step_s;
    let f32_rate = time_plant::<f32>(params, &inputs, repeat)?;
    let f64_rate = time_plant::<f64>(params, &inputs, repeat)?;
    let closed = time_closed_loop(params, steps, repeat)?;
    Ok(BenchFigures {
        steps_per_s_f32: f32_rate,
        steps_per_s_f64: f64_rate,
        realtime_factor_f32: f32_rate / rate,
        realtime_factor_f64: f64_rate / rate,
        closed_loop_steps_per_s_f32: closed,
        ns_per_step_f32: 1e9 / f32_rate,
        plant_rate_hz: rate,
        steps,
        repeat,
        math: hils_plant::math::IMPLEMENTATION,
        threads: 1,
    })
}

pub fn main(args: BenchArgs) -> Result<()> {
    let params = ParamFile::default();
    let f = measure(&params, args.steps.max(1), args.repeat.max(1))?;
    if args.json {
        println!("{}", serde_json::to_string(&f)?);
    } else {
        println!(
            "plant (17 DOF, 4 contacts, Eq 2, heat), paper EB inputs, one core, best of {}:",
            f.repeat
        );
        println!(
            "  f32: {:>10.0} steps/s  ({:.0} ns/step)  real-time factor at {:.0} Hz: {:.0}x",
            f.steps_per_s_f32, f.ns_per_step_f32, f.plant_rate_hz, f.realtime_factor_f32
        );
        println!(
            "  f64: {:>10.0} steps/s  real-time factor: {:.0}x",
            f.steps_per_s_f64, f.realtime_factor_f64
        );
        println!(
            "  plant + simulated brake unit (f32): {:.0} steps/s; math: {}",
            f.closed_loop_steps_per_s_f32, f.math
        );
        println!("  target: >= 300x real time (3 M steps/s) for f32");
    }
    Ok(())
}
