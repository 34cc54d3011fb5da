//! `hils target-cost`: the plant on the emulated Cortex-M4F, as a chain of stages that
//! each return a value:
//!
//! 1. [`build`]: build the emulator binary (or take `--elf`) -> its path;
//! 2. [`emulator`]: run it in QEMU -> what it printed;
//! 3. [`parse`]: parse that -> [`EmulatorOutput`];
//! 4. [`compare`]: the host's f32 run against the target's, bit for bit -> [`Comparison`];
//! 5. [`fidelity`]: the f32 run against the f64 reference -> [`Fidelity`];
//! 6. [`evaluate`]: the figures -> [`TargetCost`];
//! 7. [`cycles`]: the executed instruction mix weighted with a stated CPI model ->
//!    [`CycleEstimate`] (cycles per step from CCM SRAM and from flash);
//! 8. [`report`]: the text report (or JSON).
//!
//! Builds the emulator binary (`firmware/qemu`, `cargo qemu`) unless `--elf` names one,
//! runs it in QEMU (`-machine mps2-an386 -cpu cortex-m4 -icount shift=0`, semihosting),
//! and reads what it prints (see `firmware/qemu/src/main.rs`): the SysTick calibration,
//! instructions per plant step (mean, maximum, percentiles; per part) and the trajectory of
//! the paper's EB for both disc-pad friction models, every f32 as its bit pattern. The same
//! scenario then runs on the host in f32 ([`host_trace`]) and every recorded value is
//! compared bit for bit ([`compare`]); the host run is also checked against what
//! `hils simulate` records ([`check_against_simulate`]). Finally the f32 run is compared
//! with the f64 reference ([`fidelity`]): the math comparison of docs/target.md.
//!
//! The math implementation is the one `hils_plant::math` was compiled with; the emulator is
//! built with the same one, so `cargo run -p hils --features hils-plant/math-libm --
//! target-cost` measures the libm variant, and so on.

pub mod build;
pub mod compare;
pub mod cycles;
pub mod emulator;
pub mod fidelity;
pub mod latency;
pub mod parse;
pub mod report;

use std::path::PathBuf;
use std::time::{Duration, Instant};

use anyhow::{Result, anyhow, bail};
use clap::Args;
use hils_plant::FrictionModel;
use serde::Serialize;

pub use build::{board_opt_level, build_elf, emulator_features, workspace_root};
pub use compare::{
    Comparison, Mismatch, check_against_simulate, column_names, compare, host_trace,
};
pub use cycles::CycleEstimate;
pub use emulator::run_emulator;
use fidelity::friction_name;
pub use fidelity::{Fidelity, RunFigures, fidelity};
pub use parse::{
    CalibrationPoint, EmulatorOutput, FunctionCost, PartCost, RigStepCost, TargetRun, parse_output,
};
pub use report::report;

/// Targets of the issue (14): instructions per full plant step, variable friction.
pub const TARGET_MEAN: f64 = 1200.0;
pub const TARGET_MAX: u32 = 1400;
/// Target of issue 14 for the step with the degraded-adhesion model on: at most this much
/// above the mean of the paper EB's step (variable friction), percent.
pub const TARGET_DEGRADED_INCREASE_PERCENT: f64 = 15.0;
/// Budget of issue 11: instructions of the rig's step (`Rig::step` with its command), max.
pub const RIG_STEP_BUDGET_MAX: u32 = 6000;

/// Arguments of `hils target-cost`.
#[derive(Args, Debug, Clone)]
pub struct TargetCostArgs {
    /// Print one JSON object instead of the report.
    #[arg(long)]
    pub json: bool,
    /// Emulator binary to run (default: build it with cargo, `cargo qemu`).
    #[arg(long)]
    pub elf: Option<PathBuf>,
    /// QEMU system emulator for Arm.
    #[arg(long, default_value = "qemu-system-arm")]
    pub qemu: String,
    /// Give up on the emulator after this many seconds.
    #[arg(long, default_value_t = 900, value_parser = crate::flags::timeout_s)]
    pub timeout_s: u64,
    /// Also save the emulator's raw output (trajectory lines included) to this file.
    #[arg(long)]
    pub save_output: Option<PathBuf>,
    /// Report the rig's own step instead (`Rig::step` with a mock board through the
    /// scripted sequence: start, 2 s running, stop, restart in the other mode, fault
    /// injection, clear, calibrate).
    #[arg(long)]
    pub rig: bool,
}

/// The optimisation levels of the emulator image measured and of the board image.
#[derive(Clone, Debug, Serialize)]
pub struct OptLevels {
    /// The emulator image's (its `H` line; `None` from an image too old to say).
    pub emulator: Option<String>,
    /// The board image's (Cargo.toml, [`board_opt_level`]).
    pub board: String,
}

impl OptLevels {
    /// Reads both; an image this program built at another level than the board's is an
    /// error (the figures would not be the board's: Cargo.toml sets both alike).
    fn check(text: &str, built_here: bool) -> Result<Self> {
        let levels = Self {
            emulator: parse_output(text)?.opt_level,
            board: board_opt_level()?,
        };
        if built_here && levels.emulator.as_deref() != Some(levels.board.as_str()) {
            bail!(
                "the emulator image was built at opt-level {} but the board image is built at \
                 {}: give [profile.firmware.package.hils-qemu] in Cargo.toml the board's opt-level",
                levels.emulator.as_deref().unwrap_or("(not said)"),
                levels.board
            );
        }
        Ok(levels)
    }

    /// One line for the report.
    pub fn text(&self) -> String {
        match self.emulator.as_deref() {
            Some(e) if e == self.board => {
                format!("emulator image built at opt-level {e}, as the board image (Cargo.toml)")
            }
            Some(e) => format!(
                "emulator image built at opt-level {e}; the board image is built at {}: \
                 these figures are not the board's",
                self.board
            ),
            None => format!(
                "emulator image of unknown opt-level (it does not say); the board image is \
                 built at {}",
                self.board
            ),
        }
    }
}

/// The figures of `hils target-cost --rig --json`.
#[derive(Clone, Debug, Serialize)]
pub struct RigCost {
    pub rig_step_instructions_max: u32,
    pub rig_step_instructions_mean: f64,
    pub rig_step_budget_max: u32,
    pub within_budget: bool,
    pub ticks: u32,
    /// Tick (0-based) of the maximum.
    pub max_tick: u32,
    pub rejected_commands: u32,
    pub machine: &'static str,
    pub opt_level: OptLevels,
    /// Input-to-output latencies ([`latency`]).
    pub latency: Vec<latency::Path>,
}

/// The rig's figures from the emulator's output.
pub fn rig_cost(text: &str, opt_level: OptLevels) -> Result<RigCost> {
    let out = parse_output(text)?;
    let r = out
        .rig
        .ok_or_else(|| anyhow!("the emulator output has no rig step line (`G`)"))?;
    if r.rejected_commands != 0 {
        bail!(
            "the rig refused {} commands of its cost sequence",
            r.rejected_commands
        );
    }
    Ok(RigCost {
        rig_step_instructions_max: r.max,
        rig_step_instructions_mean: r.mean,
        rig_step_budget_max: RIG_STEP_BUDGET_MAX,
        within_budget: r.max <= RIG_STEP_BUDGET_MAX,
        ticks: r.ticks,
        max_tick: r.max_tick,
        rejected_commands: r.rejected_commands,
        machine: "QEMU mps2-an386 (Cortex-M4F), -icount shift=0",
        opt_level,
        latency: latency::measure(r.max),
    })
}

/// The figures of `hils target-cost --json`.
#[derive(Clone, Debug, Serialize)]
pub struct TargetCost {
    /// Mean instructions per full plant step (`Plant::step`): the larger of the two
    /// friction models' means over the scenario.
    pub instructions_mean: f64,
    /// Largest instructions of one plant step over both runs.
    pub instructions_max: u32,
    /// Host f32 and emulated target trajectories equal bit for bit, both frictions.
    pub bit_identical: bool,
    pub target_mean: f64,
    pub target_max: u32,
    pub within_targets: bool,
    pub math: String,
    pub machine: &'static str,
    pub instructions_per_systick_tick: u32,
    /// Largest |measured - known| over the calibration loops, instructions.
    pub calibration_max_error: u32,
    pub frictions: Vec<FrictionCost>,
    pub functions: Vec<FunctionCost>,
    pub fidelity: Vec<Fidelity>,
    pub emulator_wall_s: f64,
    /// Cycles per step estimated from the executed instruction mix ([`cycles`]); `None`
    /// with `cycles_error` when the profile could not be taken (no llvm-objdump, ...).
    pub cycles: Option<CycleEstimate>,
    pub cycles_error: Option<String>,
    /// The optimisation levels (`None` from [`evaluate`] alone: no image to check).
    pub opt_level: Option<OptLevels>,
    /// The step with degraded adhesion on, on a non-uniform track (`None` if the emulator
    /// did not measure it).
    pub degraded: Option<DegradedCost>,
}

/// The plant step with the degraded-adhesion model on (variable friction), on a track with
/// zones, against the paper EB's step (uniform wet track, model off).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct DegradedCost {
    /// The track (`programmes/wsp-low-adhesion.toml`'s name).
    pub track: String,
    pub steps: u64,
    pub instructions_mean: f64,
    pub instructions_max: u32,
    pub instructions_p99: u32,
    /// Mean over the paper EB's variable-friction mean, minus 1, percent.
    pub increase_percent: f64,
    pub target_increase_percent: f64,
    pub within_target: bool,
}

/// The degraded-adhesion figures, against the variable friction run's mean step.
fn degraded_cost(out: &EmulatorOutput) -> Option<DegradedCost> {
    let (track, cost) = out.degraded.as_ref()?;
    let base = out
        .run(friction_name(FrictionModel::Variable))?
        .part("step")?
        .mean;
    let increase_percent = 100.0 * (cost.mean / base - 1.0);
    Some(DegradedCost {
        track: track.clone(),
        steps: cost.n,
        instructions_mean: cost.mean,
        instructions_max: cost.max,
        instructions_p99: cost.p99,
        increase_percent,
        target_increase_percent: TARGET_DEGRADED_INCREASE_PERCENT,
        within_target: increase_percent <= TARGET_DEGRADED_INCREASE_PERCENT,
    })
}

/// One friction model's figures.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct FrictionCost {
    pub friction: String,
    pub steps: u32,
    pub stop_step: Option<u32>,
    /// Per part (`hils_sil::trace::PARTS`).
    pub parts: std::collections::BTreeMap<String, PartCost>,
    pub comparison: Comparison,
    /// Values checked against `hils simulate`'s samples of the same run.
    pub simulate_values_checked: usize,
}

/// Runs the stages: build (or take) the ELF, emulate, then [`evaluate`].
pub fn measure(args: &TargetCostArgs) -> Result<TargetCost> {
    let (text, wall, elf, opt_level) = emulate(args)?;
    let mut cost = evaluate(&text, wall)?;
    cost.opt_level = Some(opt_level);
    match cycles::estimate(&args.qemu, &elf, cost.instructions_mean) {
        Ok(c) => cost.cycles = Some(c),
        Err(e) => cost.cycles_error = Some(format!("{e:#}")),
    }
    Ok(cost)
}

/// Builds (or takes) the ELF and runs it: the emulator's output, its wall time (s), the ELF
/// and the optimisation levels ([`OptLevels::check`]).
fn emulate(args: &TargetCostArgs) -> Result<(String, f64, PathBuf, OptLevels)> {
    let elf = match &args.elf {
        Some(p) => p.clone(),
        None => build_elf()?,
    };
    let started = Instant::now();
    let text = run_emulator(&args.qemu, &elf, Duration::from_secs(args.timeout_s))?;
    let wall = started.elapsed().as_secs_f64();
    if let Some(path) = &args.save_output {
        crate::outputs::write_file(path, &text)?;
    }
    let opt_level = OptLevels::check(&text, args.elf.is_none())?;
    Ok((text, wall, elf, opt_level))
}

/// The figures from the emulator's output: parse, compare each friction model's run with
/// the host, fidelity, totals.
pub fn evaluate(text: &str, emulator_wall_s: f64) -> Result<TargetCost> {
    let out = parse_output(text)?;
    if out.math != hils_plant::math::IMPLEMENTATION {
        bail!(
            "the emulator computes with `{}` but this program with `{}`: build both alike",
            out.math,
            hils_plant::math::IMPLEMENTATION
        );
    }
    let mut frictions = Vec::new();
    let mut fid = Vec::new();
    for friction in [FrictionModel::Variable, FrictionModel::Constant] {
        frictions.push(friction_cost(&out, friction)?);
        fid.push(fidelity(friction)?);
    }
    let step_costs: Vec<PartCost> = out
        .runs
        .iter()
        .map(|r| {
            r.part("step")
                .copied()
                .ok_or_else(|| anyhow!("no `step` cost line"))
        })
        .collect::<Result<_>>()?;
    let instructions_mean = step_costs.iter().map(|c| c.mean).fold(0.0, f64::max);
    let instructions_max = step_costs.iter().map(|c| c.max).max().unwrap_or(0);
    let calibration_max_error = out
        .calibration
        .iter()
        .map(|c| c.measured.abs_diff(c.expected))
        .max()
        .unwrap_or(0);
    Ok(TargetCost {
        instructions_mean,
        instructions_max,
        bit_identical: frictions.iter().all(|f| f.comparison.identical),
        target_mean: TARGET_MEAN,
        target_max: TARGET_MAX,
        within_targets: instructions_mean <= TARGET_MEAN && instructions_max <= TARGET_MAX,
        math: out.math.clone(),
        machine: "QEMU mps2-an386 (Cortex-M4F), -icount shift=0",
        instructions_per_systick_tick: out.instructions_per_tick,
        calibration_max_error,
        frictions,
        functions: out.functions.clone(),
        fidelity: fid,
        emulator_wall_s,
        cycles: None,
        cycles_error: None,
        opt_level: None,
        degraded: degraded_cost(&out),
    })
}

/// One friction model's costs and comparisons.
fn friction_cost(out: &EmulatorOutput, friction: FrictionModel) -> Result<FrictionCost> {
    let name = friction_name(friction);
    let run = out
        .run(name)
        .ok_or_else(|| anyhow!("the emulator output has no {name} friction run"))?;
    let (host_rows, _, _) = host_trace(friction)?;
    Ok(FrictionCost {
        friction: name.to_string(),
        steps: run.steps,
        stop_step: run.stop_step,
        parts: run.parts.iter().cloned().collect(),
        comparison: compare(name, &run.rows, &host_rows),
        simulate_values_checked: check_against_simulate(friction, &host_rows)?,
    })
}

/// `hils target-cost`.
pub fn main(args: TargetCostArgs) -> Result<()> {
    if let Some(path) = &args.save_output {
        crate::outputs::OutFile::check_file(
            path,
            "--save-output",
            "the emulator's output is saved to a file (the figures go to standard output)",
        )?;
    }
    if args.rig {
        let (text, _, _, opt_level) = emulate(&args)?;
        let c = rig_cost(&text, opt_level)?;
        if args.json {
            println!("{}", serde_json::to_string(&c)?);
        } else {
            println!(
                "rig step (Rig::step + command, mock board, {} ticks of the cost sequence) on {}:\n  \
                 {}\n  rig_step_instructions_max  {} (tick {}; budget {}: {})\n  rig_step_instructions_mean {:.0}",
                c.ticks,
                c.machine,
                c.opt_level.text(),
                c.rig_step_instructions_max,
                c.max_tick,
                c.rig_step_budget_max,
                if c.within_budget { "within" } else { "OVER" },
                c.rig_step_instructions_mean
            );
            print!("{}", latency::text(&c.latency, c.rig_step_instructions_max));
        }
        return Ok(());
    }
    let c = measure(&args)?;
    if args.json {
        println!("{}", serde_json::to_string(&c)?);
    } else {
        print!("{}", report(&c));
    }
    Ok(())
}
