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

/// `hils rig --lost-after-s`: two status periods (10 ms each) up to a minute.
pub const RIG_LOST_AFTER_S: FlagRange = range("rig status", "--lost-after-s", 0.02, 60.0);
/// `hils rig start --speed-kmh`: the board's start-speed signal, 1 km/h up to its top
/// (163.82 km/h, 0.01 km/h per bit).
pub const RIG_SPEED_KMH: FlagRange = range("rig start", "--speed-kmh", 1.0, 163.82);
/// `hils rig brake service DECEL_MPS2`: 0.01 m/s^2 up to 5 m/s^2 (half of g: more than
/// any wheel-rail adhesion gives).
pub const RIG_SERVICE_DECEL_MPS2: FlagRange = range("rig brake service", "DECEL_MPS2", 0.01, 5.0);
/// `hils rig calibrate CH gain GAIN`: N or Pa per ADC count, 0.01 (a 33 N load cell over
/// the live-zero span of 3276 counts) up to 10,000 (a 33 MPa transducer).
pub const RIG_GAIN: FlagRange = range("rig calibrate 1 gain", "GAIN", 0.01, 10_000.0);
/// `hils rig calibrate CH offset COUNTS`: the zero-load reading, between the board's open
/// (2 % of 4095) and short (98 %) thresholds: a zero outside them reads as a wiring fault.
pub const RIG_OFFSET_COUNTS: FlagRange = range(
    "rig calibrate 1 offset",
    "COUNTS",
    0.02 * 4095.0,
    0.98 * 4095.0,
);
/// `hils rig configure divider STEPS`: telemetry every 1-10,000 plant steps (the board's
/// range, `hils.dbc`).
pub const RIG_DIVIDER: FlagRange = count("rig configure divider", "STEPS", 1.0, 10_000.0);
/// `hils rig configure teeth TEETH`: teeth of the simulated speed-sensor wheel, 1-1000
/// (the board's range, `hils.dbc`).
pub const RIG_TEETH: FlagRange = count("rig configure teeth", "TEETH", 1.0, 1000.0);
/// `hils rig watch|record|wait --for-s`: 1 ms up to a day.
pub const RIG_FOR_S: FlagRange = range("rig wait", "--for-s", 0.001, 86_400.0);
/// `hils rig watch --every-s`: one view per 10 ms (the status period) up to an hour.
pub const RIG_EVERY_S: FlagRange = range("rig watch", "--every-s", 0.01, 3600.0);
/// `hils rig run --max-run-s`: 1 s up to an hour of board time per run.
pub const RIG_MAX_RUN_S: FlagRange = range("rig run", "--max-run-s", 1.0, 3600.0);
/// `hils rig run --settle-s`: 0.1 s up to 10 min for the cylinders to vent between runs.
pub const RIG_SETTLE_S: FlagRange = range("rig run", "--settle-s", 0.1, 600.0);
/// `hils rig --sim-fault KIND=SECONDS`: board time of the fault, 1 ms up to a day.
pub const RIG_SIM_FAULT_S: FlagRange = range("rig status", "--sim-fault", 0.001, 86_400.0);

/// Every numeric flag of `hils` (the property test feeds each its bad values). A `flag`
/// without `--` is a positional value (named as in `--help`); `command` is the command
/// line up to it.
pub const FLAGS: [FlagRange; 20] = [
    LOG_MB,
    SPEED_KMH,
    SAMPLE_RATE_HZ,
    STEP_S,
    STEPS,
    REPEAT,
    TIMEOUT_S,
    RUN,
    RIG_LOST_AFTER_S,
    RIG_SPEED_KMH,
    RIG_SERVICE_DECEL_MPS2,
    RIG_GAIN,
    RIG_OFFSET_COUNTS,
    RIG_DIVIDER,
    RIG_TEETH,
    RIG_FOR_S,
    RIG_EVERY_S,
    RIG_MAX_RUN_S,
    RIG_SETTLE_S,
    RIG_SIM_FAULT_S,
];

impl FlagRange {
    /// Whether `x` is a value of this flag (finite, within the range, whole if a count).
    pub fn contains(&self, x: f64) -> bool {
        x >= self.min && x <= self.max && !(self.integer && x.fract() != 0.0)
    }

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
        if !self.contains(x) {
            return Err(format!(
                "`{text}` is outside the accepted range: {kind} in [{}, {}]",
                self.min, self.max
            ));
        }
        Ok(x)
    }
}

/// Value parsers: `name: RANGE -> type` is `pub fn name(&str) -> Result<type, String>`, the
/// value of `RANGE` as `type` (a count is whole, so the cast is exact).
macro_rules! value_parsers {
    ($($flag:literal $name:ident: $range:ident -> $ty:ty;)*) => {$(
        #[doc = concat!("Value parser of `", $flag, "`.")]
        pub fn $name(s: &str) -> Result<$ty, String> {
            $range.parse(s).map(|x| x as $ty)
        }
    )*};
}

value_parsers! {
    "simulate --speed-kmh" speed_kmh: SPEED_KMH -> f64;
    "simulate --sample-rate-hz" sample_rate_hz: SAMPLE_RATE_HZ -> f64;
    "diagnose --step-s" step_s: STEP_S -> f64;
    "bench --steps" steps: STEPS -> usize;
    "bench --repeat" repeat: REPEAT -> usize;
    "target-cost --timeout-s" timeout_s: TIMEOUT_S -> u64;
    "decode --run" run_index: RUN -> usize;
    "bench --write-log-mb" log_mb: LOG_MB -> f64;
    "rig --lost-after-s" rig_lost_after_s: RIG_LOST_AFTER_S -> f64;
    "rig start --speed-kmh" rig_speed_kmh: RIG_SPEED_KMH -> f32;
    "rig brake service DECEL_MPS2" rig_service_decel_mps2: RIG_SERVICE_DECEL_MPS2 -> f32;
    "rig calibrate CH gain GAIN" rig_gain: RIG_GAIN -> f32;
    "rig calibrate CH offset COUNTS" rig_offset_counts: RIG_OFFSET_COUNTS -> f32;
    "rig configure divider STEPS" rig_divider: RIG_DIVIDER -> u16;
    "rig configure teeth TEETH" rig_teeth: RIG_TEETH -> u16;
    "rig watch|record|wait --for-s" rig_for_s: RIG_FOR_S -> f64;
    "rig watch --every-s" rig_every_s: RIG_EVERY_S -> f64;
    "rig run --max-run-s" rig_max_run_s: RIG_MAX_RUN_S -> f64;
    "rig run --settle-s" rig_settle_s: RIG_SETTLE_S -> f64;
}

/// Value parser of `rig --sim-fault KIND=SECONDS`: the kind (`board-lost`, `bus-off`,
/// `alive-frozen`) and the board time, s.
pub fn rig_sim_fault(spec: &str) -> Result<(&str, f64), String> {
    const KINDS: [&str; 3] = ["board-lost", "bus-off", "alive-frozen"];
    let (kind, t) = spec
        .split_once('=')
        .ok_or_else(|| format!("`{spec}`: expected KIND=SECONDS"))?;
    if !KINDS.contains(&kind) {
        return Err(format!("`{spec}`: kinds are {}", KINDS.join(", ")));
    }
    Ok((kind, RIG_SIM_FAULT_S.parse(t)?))
}
/// [`rig_sim_fault`] as a clap value parser (the text is kept, checked).
pub fn rig_sim_fault_text(spec: &str) -> Result<String, String> {
    rig_sim_fault(spec).map(|_| spec.to_string())
}
