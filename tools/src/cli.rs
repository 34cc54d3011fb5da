//! The command line in one place: the `hils` commands ([`Cli`]); the value parsers of
//! their numeric flags are in [`crate::flags`].

use clap::{Parser, Subcommand};

/// `hils`: the host tools.
#[derive(Parser, Debug)]
#[command(name = "hils", version, about = "Railway brake HILS host tools")]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Subcommand, Debug)]
pub enum Command {
    /// Run a scenario with the plant and the simulated brake unit (software in the loop):
    /// writes run.csv, summary.json and the paper's figures.
    Simulate(crate::simulate::SimulateArgs),
    /// Host speed of the plant (steps per second, f32 and f64; real-time factor at 10 kHz);
    /// `--reader FILE`: time and peak memory of reading a measured file.
    Bench(crate::bench::BenchArgs),
    /// Fit Eq (2) to brake-dynamometer friction tests (`--json`: the fitted parameters;
    /// `--report`: plots like the paper's Fig 2).
    FitFriction(crate::fit_friction::FitFrictionArgs),
    /// Diagnose measured runs against a baseline parameter file (`--json`: the diagnosis JSON
    /// of spec/diagnosis.md; `--report`: report.md with plots).
    Diagnose(crate::diagnose::DiagnoseArgs),
    /// Instructions per plant step on the emulated Cortex-M4F.
    TargetCost(crate::target_cost::TargetCostArgs),
    /// Turn a captured defmt telemetry log into a run-log CSV.
    Decode(crate::decode::DecodeArgs),
    /// WSP test bench: a programme of low-adhesion runs in SIL (or a captured rig log),
    /// judged against the stopping distance the adhesion allows (`--json`: the per-run
    /// results; `--report`: summary table and per-run plots).
    WspTest(crate::wsp::WspTestArgs),
    /// Operate the rig board over CAN (or `--interface sim`): start, stop, brake, inject,
    /// calibrate, status, watch, record, session scripts, programmes.
    Rig(crate::rig::RigArgs),
}

/// Runs a parsed command line.
pub fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Simulate(a) => crate::simulate::main(a),
        Command::Bench(a) => crate::bench::main(a),
        Command::FitFriction(a) => crate::fit_friction::main(a),
        Command::Diagnose(a) => crate::diagnose::main(a),
        Command::TargetCost(a) => crate::target_cost::main(a),
        Command::Decode(a) => crate::decode::main(a),
        Command::WspTest(a) => crate::wsp::main(a),
        Command::Rig(a) => crate::rig::main(a),
    }
}
