//! `hils`: host tools of the railway brake HILS. See README.md.

use anyhow::Result;
use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(name = "hils", version, about = "Railway brake HILS host tools")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run a scenario with the plant and the simulated brake unit (software in the loop):
    /// writes run.csv, summary.json and the paper's figures.
    Simulate(hils::simulate::SimulateArgs),
    /// Host speed of the plant (steps per second, f32 and f64; real-time factor at 10 kHz).
    Bench(hils::bench::BenchArgs),
    /// Fit Eq (2) to brake-dynamometer friction tests.
    FitFriction(hils::fit_friction::FitFrictionArgs),
    /// Diagnose measured runs against a baseline parameter file.
    Diagnose(hils::diagnose::DiagnoseArgs),
    /// Instructions per plant step on the emulated Cortex-M4F.
    TargetCost(hils::target_cost::TargetCostArgs),
    /// Turn a captured defmt telemetry log into a run-log CSV.
    Decode(hils::decode::DecodeArgs),
    /// WSP test bench: a programme of low-adhesion runs in SIL (or a captured rig log),
    /// judged against the stopping distance the adhesion allows.
    WspTest(hils::wsp::WspTestArgs),
    /// Operate the rig board over CAN (or `--interface sim`): start, stop, brake, inject,
    /// calibrate, status, watch, record, session scripts, programmes.
    Rig(hils::rig::RigArgs),
}

fn main() -> Result<()> {
    match Cli::parse().command {
        Command::Simulate(a) => hils::simulate::main(a),
        Command::Bench(a) => hils::bench::main(a),
        Command::FitFriction(a) => hils::fit_friction::main(a),
        Command::Diagnose(a) => hils::diagnose::main(a),
        Command::TargetCost(a) => hils::target_cost::main(a),
        Command::Decode(a) => hils::decode::main(a),
        Command::WspTest(a) => hils::wsp::main(a),
        Command::Rig(a) => hils::rig::main(a),
    }
}
