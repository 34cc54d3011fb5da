//! The value parser of every numeric flag of `hils`, with its range ([`FLAGS`]). A value
//! outside its range, 0 where 0 means nothing, a negative, NaN, inf or a huge number is an
//! error that names the flag, before any file is read or written.

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

/// The numeric flags, each declared once: its range (a `pub const`), its value parser
/// (`parser -> type`: the value as `type`; a count is whole, so the cast is exact) and its
/// place in [`FLAGS`].
macro_rules! flags {
    ($($(#[$doc:meta])* $name:ident = $kind:ident($command:literal, $flag:literal, $min:expr, $max:expr), $parser:ident -> $ty:ty;)*) => {
        $(
            $(#[$doc])*
            pub const $name: FlagRange = $kind($command, $flag, $min, $max);
            #[doc = concat!("Value parser of `", $command, " ", $flag, "` ([`", stringify!($name), "`]).")]
            pub fn $parser(s: &str) -> Result<$ty, String> {
                $name.parse(s).map(|x| x as $ty)
            }
        )*
        /// Every numeric flag of `hils` (the property test feeds each its bad values). A
        /// `flag` without `--` is a positional value (named as in `--help`); `command` is the
        /// command line up to it.
        pub const FLAGS: &[FlagRange] = &[$($name),*];
    };
}

flags! {
    /// `simulate --speed-kmh`: the paper's vehicle up to 400 km/h.
    SPEED_KMH = range("simulate", "--speed-kmh", 1.0, 400.0), speed_kmh -> f64;
    /// `simulate --sample-rate-hz`: 1 Hz up to the plant rate (10 kHz).
    SAMPLE_RATE_HZ = range("simulate", "--sample-rate-hz", 1.0, 10_000.0), sample_rate_hz -> f64;
    /// `diagnose --step-s`: the replay step, 10 us to 10 ms.
    STEP_S = range("diagnose", "--step-s", 1e-5, 1e-2), step_s -> f64;
    /// `bench --steps`.
    STEPS = count("bench", "--steps", 1.0, 1e9), steps -> usize;
    /// `bench --repeat`.
    REPEAT = count("bench", "--repeat", 1.0, 1000.0), repeat -> usize;
    /// `target-cost --timeout-s`.
    TIMEOUT_S = count("target-cost", "--timeout-s", 1.0, 86_400.0), timeout_s -> u64;
    /// `decode --run` (1 = the first run).
    RUN = count("decode", "--run", 1.0, 1e6), run_index -> usize;
    /// `bench --write-log-mb`.
    LOG_MB = range("bench", "--write-log-mb", 0.001, 10_000.0), log_mb -> f64;
    /// `bench --write-friction-points`: a synthetic friction test of 6 (five parameters and
    /// a residual) to a billion points.
    FRICTION_POINTS = count("bench", "--write-friction-points", 6.0, 1e9), friction_points -> u64;
    /// `hils rig --lost-after-s`: two status periods (10 ms each) up to a minute.
    RIG_LOST_AFTER_S = range("rig status", "--lost-after-s", 0.02, 60.0), rig_lost_after_s -> f64;
    /// `hils rig start --speed-kmh`: 1 km/h up to the top of the wheel-speed frames
    /// (655.34 km/h, 0.01 km/h per bit; `hils_rig_core::can::WHEEL_SPEED_MAX_KMH`).
    RIG_SPEED_KMH = range("rig start", "--speed-kmh", 1.0, 655.34), rig_speed_kmh -> f32;
    /// `hils rig brake service DECEL_MPS2`: 0.01 m/s^2 up to 5 m/s^2 (half of g: more than
    /// any wheel-rail adhesion gives).
    RIG_SERVICE_DECEL_MPS2 = range("rig brake service", "DECEL_MPS2", 0.01, 5.0), rig_service_decel_mps2 -> f32;
    /// `hils rig calibrate CH gain GAIN`: N or Pa per ADC count, 0.01 (a 33 N load cell over
    /// the live-zero span of 3276 counts) up to 10,000 (a 33 MPa transducer).
    RIG_GAIN = range("rig calibrate 1 gain", "GAIN", 0.01, 10_000.0), rig_gain -> f32;
    /// `hils rig calibrate CH offset COUNTS`: the zero-load reading, between the board's open
    /// (2 % of 4095) and short (98 %) thresholds: a zero outside them reads as a wiring fault.
    RIG_OFFSET_COUNTS = range("rig calibrate 1 offset", "COUNTS", 0.02 * 4095.0, 0.98 * 4095.0), rig_offset_counts -> f32;
    /// `hils rig configure divider STEPS`: telemetry every 1-10,000 plant steps (the board's
    /// range, `hils.dbc`).
    RIG_DIVIDER = count("rig configure divider", "STEPS", 1.0, 10_000.0), rig_divider -> u16;
    /// `hils rig configure teeth TEETH`: teeth of the simulated speed-sensor wheel, 1-1000
    /// (the board's range, `hils.dbc`).
    RIG_TEETH = count("rig configure teeth", "TEETH", 1.0, 1000.0), rig_teeth -> u16;
    /// `hils rig watch|record|wait --for-s`: 1 ms up to a day.
    RIG_FOR_S = range("rig wait", "--for-s", 0.001, 86_400.0), rig_for_s -> f64;
    /// `hils rig watch --every-s`: one view per 10 ms (the status period) up to an hour.
    RIG_EVERY_S = range("rig watch", "--every-s", 0.01, 3600.0), rig_every_s -> f64;
    /// `hils rig run --max-run-s`: 1 s up to an hour of board time per run.
    RIG_MAX_RUN_S = range("rig run", "--max-run-s", 1.0, 3600.0), rig_max_run_s -> f64;
    /// `hils rig run --settle-s`: 0.1 s up to 10 min for the cylinders to vent between runs.
    RIG_SETTLE_S = range("rig run", "--settle-s", 0.1, 600.0), rig_settle_s -> f64;
    /// `hils rig --sim-fault KIND=SECONDS`: board time of the fault, 1 ms up to a day.
    RIG_SIM_FAULT_S = range("rig status", "--sim-fault", 0.001, 86_400.0), rig_sim_fault_s -> f64;
}

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
    Ok((kind, rig_sim_fault_s(t)?))
}
/// [`rig_sim_fault`] as a clap value parser (the text is kept, checked).
pub fn rig_sim_fault_text(spec: &str) -> Result<String, String> {
    rig_sim_fault(spec).map(|_| spec.to_string())
}
