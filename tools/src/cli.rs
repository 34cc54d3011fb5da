//! The command line in one place: the `hils` commands ([`Cli`]) and the value parser of
//! every numeric flag, with its range ([`FLAGS`]). A value outside its range, 0 where 0
//! means nothing, a negative, NaN, inf or a huge number is an error that names the flag,
//! before any file is read or written.

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
    /// Fit Eq (2) to brake-dynamometer friction tests.
    FitFriction(crate::fit_friction::FitFrictionArgs),
    /// Diagnose measured runs against a baseline parameter file.
    Diagnose(crate::diagnose::DiagnoseArgs),
    /// Instructions per plant step on the emulated Cortex-M4F.
    TargetCost(crate::target_cost::TargetCostArgs),
    /// Turn a captured defmt telemetry log into a run-log CSV.
    Decode(crate::decode::DecodeArgs),
    /// WSP test bench: a programme of low-adhesion runs in SIL (or a captured rig log),
    /// judged against the stopping distance the adhesion allows.
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

/// The accepted range of a numeric flag (both ends included).
#[derive(Clone, Copy, Debug)]
pub struct FlagRange {
    /// The subcommand and the flag (`simulate --sample-rate-hz`).
    pub command: &'static str,
    pub flag: &'static str,
    pub min: f64,
    pub max: f64,
    /// Whole numbers only.
    pub integer: bool,
}

const fn range(command: &'static str, flag: &'static str, min: f64, max: f64) -> FlagRange {
    FlagRange {
        command,
        flag,
        min,
        max,
        integer: false,
    }
}

const fn count(command: &'static str, flag: &'static str, min: f64, max: f64) -> FlagRange {
    FlagRange {
        integer: true,
        ..range(command, flag, min, max)
    }
}

/// `simulate --speed-kmh`: the paper's vehicle up to 400 km/h.
pub const SPEED_KMH: FlagRange = range("simulate", "--speed-kmh", 1.0, 400.0);
/// `simulate --sample-rate-hz`: 1 Hz up to the plant rate (10 kHz).
pub const SAMPLE_RATE_HZ: FlagRange = range("simulate", "--sample-rate-hz", 1.0, 10_000.0);
/// `diagnose --step-s`: the replay step, 10 us to 10 ms.
pub const STEP_S: FlagRange = range("diagnose", "--step-s", 1e-5, 1e-2);
/// `bench --steps`.
pub const STEPS: FlagRange = count("bench", "--steps", 1.0, 1e9);
/// `bench --repeat`.
pub const REPEAT: FlagRange = count("bench", "--repeat", 1.0, 1000.0);
/// `target-cost --timeout-s`.
pub const TIMEOUT_S: FlagRange = count("target-cost", "--timeout-s", 1.0, 86_400.0);
/// `decode --run` (1 = the first run).
pub const RUN: FlagRange = count("decode", "--run", 1.0, 1e6);

/// `bench --write-log-mb`.
pub const LOG_MB: FlagRange = range("bench", "--write-log-mb", 0.001, 10_000.0);

/// Every numeric flag of `hils` (the property test feeds each its bad values).
pub const FLAGS: [FlagRange; 8] = [
    LOG_MB,
    SPEED_KMH,
    SAMPLE_RATE_HZ,
    STEP_S,
    STEPS,
    REPEAT,
    TIMEOUT_S,
    RUN,
];

impl FlagRange {
    /// Parses a value of this flag: a finite number within the range (whole if a count).
    pub fn parse(&self, text: &str) -> Result<f64, String> {
        let x: f64 = text
            .trim()
            .parse()
            .map_err(|_| format!("`{text}` is not a number"))?;
        let kind = if self.integer {
            "a whole number"
        } else {
            "a number"
        };
        if !(x >= self.min && x <= self.max) || (self.integer && x.fract() != 0.0) {
            return Err(format!(
                "`{text}` is outside the accepted range: {kind} in [{}, {}]",
                self.min, self.max
            ));
        }
        Ok(x)
    }
}

/// Value parser of `simulate --speed-kmh`.
pub fn speed_kmh(s: &str) -> Result<f64, String> {
    SPEED_KMH.parse(s)
}
/// Value parser of `simulate --sample-rate-hz`.
pub fn sample_rate_hz(s: &str) -> Result<f64, String> {
    SAMPLE_RATE_HZ.parse(s)
}
/// Value parser of `diagnose --step-s`.
pub fn step_s(s: &str) -> Result<f64, String> {
    STEP_S.parse(s)
}
/// Value parser of `bench --steps`.
pub fn steps(s: &str) -> Result<usize, String> {
    STEPS.parse(s).map(|x| x as usize)
}
/// Value parser of `bench --repeat`.
pub fn repeat(s: &str) -> Result<usize, String> {
    REPEAT.parse(s).map(|x| x as usize)
}
/// Value parser of `target-cost --timeout-s`.
pub fn timeout_s(s: &str) -> Result<u64, String> {
    TIMEOUT_S.parse(s).map(|x| x as u64)
}
/// Value parser of `decode --run`.
pub fn run_index(s: &str) -> Result<usize, String> {
    RUN.parse(s).map(|x| x as usize)
}
/// Value parser of `bench --write-log-mb`.
pub fn log_mb(s: &str) -> Result<f64, String> {
    LOG_MB.parse(s)
}
