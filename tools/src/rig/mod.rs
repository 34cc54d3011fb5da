//! `hils rig`: operate the rig board from the host over CAN with the frames of `hils.dbc`
//! (`firmware/rig-core/hils.dbc`, codec `hils_rig_core::can`).
//!
//! One concern per module: [`transport`] (the send/receive trait), [`sim`] (the in-process
//! board, `--interface sim`), [`socketcan`] (SocketCAN, Linux), [`monitor`] (decoding and
//! supervision of the received frames), [`commands`] (commands and their results),
//! [`watch`] (the live view), [`record`] (the run log), [`programme`] (`hils rig run`).
//!
//! # Sessions
//!
//! Every invocation is a session: the interface is opened, the line runs, the session ends.
//! On a CAN interface the board persists between invocations, so `hils rig start ...`,
//! `hils rig watch`, `hils rig stop` in turn (or in two terminals) work as expected. With
//! `--interface sim` the board lives in the process, so a single command meets a fresh
//! (idle) board; `hils rig session FILE` runs a script of lines in one process (and works
//! the same on a CAN interface). A script line is a `hils rig` command line without
//! `hils rig` (`start --speed-kmh 100 --rail wet --friction variable`, `brake eb`,
//! `wait --until-end`, `record --out run.csv`, `watch --for-s 2`); `#` starts a comment.
//! A rejected command, a lost board, a bus-off or a stuck alive counter ends the session
//! (exit code 1) and what was recorded is written.

pub mod agreement;
pub mod commands;
pub mod io_config;
pub mod monitor;
pub mod programme;
pub mod record;
pub mod sim;
pub mod socketcan;
pub mod track;
pub mod transport;
pub mod watch;

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, anyhow, bail};
use clap::{Args, Parser, Subcommand, ValueEnum};
use hils_plant::{FrictionModel, Rail};
use hils_rig_core::can::{
    BrakeCommand, Calibration, ClassicFrame, Command, ConfigItem, InjectedFault, RigMode, RigState,
    StartCommand, VehicleKey,
};
use hils_rig_core::sensor::SensorKind;

use commands::{Flow, Outcome, Session};
use monitor::{Alarm, Seen, state_name};
use record::Recorder;
use sim::{SimBoard, SimFaults};
use transport::{ProbeEvent, Received, Transport, TransportError};
use watch::Watcher;

/// Arguments of `hils rig`.
#[derive(Args, Debug, Clone)]
pub struct RigArgs {
    /// `sim` (the board's logic in this process, the simulated brake unit as the controller
    /// under test) or a SocketCAN interface (`can0`).
    #[arg(long, global = true, default_value = "can0")]
    pub interface: String,
    /// No frame from the board for this long (s) = board lost; 0.02-60 s.
    #[arg(long, global = true, default_value_t = 0.5, value_parser = crate::flags::rig_lost_after_s)]
    pub lost_after_s: f64,
    /// Sim: pace the board to the wall clock (else it runs as fast as the host steps it).
    #[arg(long, global = true)]
    pub realtime: bool,
    /// Sim: a fault at a board time, `board-lost=S`, `bus-off=S` or `alive-frozen=S`
    /// (repeatable); S is 0.001-86400 s.
    #[arg(long = "sim-fault", global = true, value_parser = crate::flags::rig_sim_fault_text)]
    pub sim_faults: Vec<String>,
    #[command(subcommand)]
    pub command: RigCommand,
}

/// `hils rig` subcommands.
#[derive(Subcommand, Debug, Clone)]
pub enum RigCommand {
    #[command(flatten)]
    Line(Line),
    /// Run a script of `hils rig` lines in one session (one board for `--interface sim`).
    Session {
        /// The script: one command line per line, `#` comments.
        file: PathBuf,
    },
    /// Run a programme of runs on the rig, recording each (see `hils rig run --help`).
    ///
    /// `--report DIR` (required): report.md, the plots and each run's log (NAME.csv).
    /// `--json FILE`: the per-run results (the `hils wsp-test --json` keys, with `on_rig`
    /// and `end`).
    Run(programme::RunArgs),
}

/// A command that runs alone or as a line of a session.
#[derive(Subcommand, Debug, Clone)]
pub enum Line {
    /// Start a run (rig mode: the controller on the rig closes the loop).
    Start(StartArgs),
    /// Stop the run (outputs to the safe state).
    Stop,
    /// Brake command: `eb`, `service DECEL_MPS2` or `release`.
    Brake {
        demand: BrakeKind,
        /// Service deceleration, m/s^2 (for `service`): 0.01-5.
        #[arg(value_parser = crate::flags::rig_service_decel_mps2)]
        decel_mps2: Option<f32>,
    },
    /// Inject a sensor fault on channel 1-4 (`none` removes it).
    Inject { channel: u8, fault: FaultKind },
    /// Calibrate channel 1-4: `tare`, `gain GAIN`, `offset COUNTS`, `kind load-cell|pressure`.
    Calibrate {
        channel: u8,
        #[command(subcommand)]
        action: CalAction,
    },
    /// Clear latched faults whose cause is gone.
    ClearFaults,
    /// Arm the board for the controller on the rig: the pulse trains and wheel-speed frames
    /// (and every controller output) go live in the following rig-mode runs. The board
    /// disarms at every stop, fault and reset.
    Arm,
    /// Disarm: the outputs the controller reads go to their safe values at once.
    Disarm,
    /// Set the telemetry divider, the sensor-wheel teeth or the controller I/O (no run
    /// active).
    #[command(subcommand)]
    Configure(ConfigKind),
    /// Print the board's status.
    Status,
    /// Live view of the board (at the status rate on a terminal).
    Watch {
        /// Stop after this long (s, 0.001-86400); default: until the board is lost.
        #[arg(long, value_parser = crate::flags::rig_for_s)]
        for_s: Option<f64>,
        /// When the output is not a terminal: one view per this much board time, s
        /// (0.01-3600).
        #[arg(long, default_value_t = 1.0, value_parser = crate::flags::rig_every_s)]
        every_s: f64,
    },
    /// Record the wheel-speed and status frames as a run log. Alone: until a run ends (or
    /// `--for-s`); in a session: from here to the end of the session or the next `record`
    /// (which ends and writes this one first). The file's folder is checked before the
    /// session sends anything.
    Record {
        /// Run-log file: CSV, or MDF4 when its name ends in `.mf4`.
        #[arg(long)]
        out: PathBuf,
        /// Record at most this long, s (0.001-86400).
        #[arg(long, value_parser = crate::flags::rig_for_s)]
        for_s: Option<f64>,
    },
    /// Wait: `--for-s S`, or `--until-end` (a run was running and no longer is; an error
    /// when it has not ended after `--for-s` or 600 s of board time).
    Wait {
        /// Wait this long, s (0.001-86400).
        #[arg(long, value_parser = crate::flags::rig_for_s)]
        for_s: Option<f64>,
        #[arg(long)]
        until_end: bool,
    },
}

#[derive(Args, Debug, Clone)]
pub struct StartArgs {
    /// Initial speed, km/h: 1-655.34 (the top of the wheel-speed frames).
    #[arg(long, value_parser = crate::flags::rig_speed_kmh)]
    pub speed_kmh: f32,
    #[arg(long, value_enum, default_value_t = RailArg::Wet)]
    pub rail: RailArg,
    #[arg(long, value_enum, default_value_t = FrictionArg::Variable)]
    pub friction: FrictionArg,
    /// Track file (a programme's `[tracks.NAME]` table at the top level: `base`, `[[zone]]`):
    /// its zones are sent (`TrackZone`, `Track` commit) and the run starts on it
    /// (`--rail` unused).
    #[arg(long)]
    pub track: Option<PathBuf>,
    /// `rig` (the controller on the rig) or `self-test` (the board's own simulated brake unit).
    #[arg(long, value_enum, default_value_t = ModeArg::Rig)]
    pub mode: ModeArg,
    /// Self-test: emergency brake at t = 0.
    #[arg(long)]
    pub eb: bool,
    /// Rig mode: arm the board for the controller right before the start (`hils rig arm`):
    /// the board refuses a rig-mode start while not armed.
    #[arg(long)]
    pub arm: bool,
}

#[derive(ValueEnum, Debug, Clone, Copy, PartialEq, Eq)]
pub enum RailArg {
    Wet,
    Dry,
}
#[derive(ValueEnum, Debug, Clone, Copy, PartialEq, Eq)]
pub enum FrictionArg {
    Variable,
    Constant,
}
#[derive(ValueEnum, Debug, Clone, Copy, PartialEq, Eq)]
pub enum ModeArg {
    Rig,
    SelfTest,
}
#[derive(ValueEnum, Debug, Clone, Copy, PartialEq, Eq)]
pub enum BrakeKind {
    Eb,
    Service,
    Release,
}
#[derive(ValueEnum, Debug, Clone, Copy, PartialEq, Eq)]
pub enum FaultKind {
    Open,
    Short,
    Stuck,
    OutOfRange,
    None,
}
/// `calibrate CH ...`: what to set.
#[derive(Subcommand, Debug, Clone, Copy, PartialEq)]
pub enum CalAction {
    /// The present reading becomes the zero (offset).
    Tare,
    /// Gain, N or Pa per ADC count: 0.01-10000.
    Gain {
        #[arg(value_parser = crate::flags::rig_gain)]
        gain: f32,
    },
    /// Offset, ADC counts of the zero load: 81.9-4013.1 (inside the open/short thresholds).
    Offset {
        #[arg(value_parser = crate::flags::rig_offset_counts)]
        counts: f32,
    },
    /// The measured quantity (resets the calibration to the kind's default).
    Kind { kind: SensorKindArg },
}
/// `calibrate CH kind ...`.
#[derive(ValueEnum, Debug, Clone, Copy, PartialEq, Eq)]
pub enum SensorKindArg {
    /// Caliper load cell, N.
    LoadCell,
    /// Cylinder pressure transducer, Pa.
    Pressure,
}
/// `configure ...`: an item and its value.
#[derive(Subcommand, Debug, Clone, PartialEq, Eq)]
pub enum ConfigKind {
    /// Telemetry every STEPS plant steps: 1-10000.
    Divider {
        #[arg(value_parser = crate::flags::rig_divider)]
        steps: u16,
    },
    /// Teeth of the simulated speed-sensor wheel: 1-1000.
    Teeth {
        #[arg(value_parser = crate::flags::rig_teeth)]
        teeth: u16,
    },
    /// The controller I/O from a file (valve inputs wired, demand PWM, air-spring signals;
    /// format: docs/rig.md, "Controller I/O"): every value checked, then one frame each.
    Io { file: PathBuf },
}

impl RailArg {
    pub fn rail(self) -> Rail {
        match self {
            RailArg::Wet => Rail::Wet,
            RailArg::Dry => Rail::Dry,
        }
    }
}

impl FrictionArg {
    pub fn model(self) -> FrictionModel {
        match self {
            FrictionArg::Variable => FrictionModel::Variable,
            FrictionArg::Constant => FrictionModel::Constant,
        }
    }
}

/// A channel argument 1-4 as the frame's 0-3.
fn channel(c: u8) -> Result<u8> {
    if (1..=4).contains(&c) {
        Ok(c - 1)
    } else {
        bail!("channel {c}: the board has channels 1-4")
    }
}

/// The `RIG_COMMAND`s of a line, in order (none for lines that send nothing): `start`
/// sends the default vehicle (`Vehicle` default: no variant is asked for) and, with
/// `--track FILE`, the track (clear, zones, commit) before the start, whose `StartDigest`
/// is the digest of that setup ([`track::with_setup_digest`]).
pub fn commands_of(line: &Line) -> Result<Vec<Command>> {
    let mut out = Vec::new();
    if let Line::Configure(ConfigKind::Io { file }) = line {
        return Ok(io_config::commands(&io_config::load(file)?));
    }
    if let Line::Start(a) = line {
        out.push(Command::Vehicle {
            key: VehicleKey::Default,
            value: 0.0,
        });
        if let Some(t) = &a.track {
            let (track, sets) = track::load_track_file(t)?;
            out.extend(
                track::track_commands(&track, &sets)
                    .with_context(|| format!("--track {}", t.display()))?,
            );
        }
    }
    match command_of(line)? {
        Some(start @ Command::Start { .. }) => {
            let start = track::with_setup_digest(&out, start)?;
            if matches!(line, Line::Start(a) if a.arm) {
                out.push(Command::Arm);
            }
            out.push(start);
        }
        c => out.extend(c),
    }
    Ok(out)
}

/// The `RIG_COMMAND` of a line (None for lines that send nothing).
fn command_of(line: &Line) -> Result<Option<Command>> {
    Ok(Some(match line {
        Line::Start(a) => Command::Start(StartCommand {
            track: a.track.is_some(),
            mode: match a.mode {
                ModeArg::Rig => RigMode::Rig,
                ModeArg::SelfTest => RigMode::SelfTest,
            },
            rail: a.rail.rail(),
            friction: a.friction.model(),
            emergency: a.eb,
            initial_speed_kmh: a.speed_kmh,
            // Stamped by `commands_of` from the setup sent before it.
            setup_digest: 0,
        }),
        Line::Stop => Command::Stop,
        Line::Brake { demand, decel_mps2 } => Command::Brake(match (demand, decel_mps2) {
            (BrakeKind::Eb, None) => BrakeCommand::Emergency,
            (BrakeKind::Release, None) => BrakeCommand::Release,
            (BrakeKind::Service, Some(d))
                if crate::flags::RIG_SERVICE_DECEL_MPS2.contains(*d as f64) =>
            {
                BrakeCommand::Service {
                    deceleration_mps2: *d,
                }
            }
            (BrakeKind::Service, _) => {
                bail!("brake service needs a deceleration 0.01-5 m/s^2 (`brake service 1.0`)")
            }
            (_, Some(_)) => bail!("only `brake service` takes a deceleration"),
        }),
        Line::Inject { channel: c, fault } => Command::InjectFault {
            channel: channel(*c)?,
            fault: match fault {
                FaultKind::Open => Some(InjectedFault::Open),
                FaultKind::Short => Some(InjectedFault::Short),
                FaultKind::Stuck => Some(InjectedFault::Stuck),
                FaultKind::OutOfRange => Some(InjectedFault::OutOfRange),
                FaultKind::None => None,
            },
        },
        Line::Calibrate { channel: c, action } => Command::Calibrate {
            channel: channel(*c)?,
            action: match *action {
                CalAction::Tare => Calibration::Tare,
                CalAction::Gain { gain } => Calibration::SetGain(gain),
                CalAction::Offset { counts } => Calibration::SetOffset(counts),
                CalAction::Kind { kind } => Calibration::SetKind(match kind {
                    SensorKindArg::LoadCell => SensorKind::LoadCell,
                    SensorKindArg::Pressure => SensorKind::PressureTransducer,
                }),
            },
        },
        Line::ClearFaults => Command::ClearFaults,
        Line::Arm => Command::Arm,
        Line::Disarm => Command::Disarm,
        Line::Configure(item) => Command::Configure(match item {
            ConfigKind::Divider { steps } => ConfigItem::TelemetryDivider(*steps),
            ConfigKind::Teeth { teeth } => ConfigItem::Teeth(*teeth),
            // Sent by `commands_of` (several frames).
            ConfigKind::Io { .. } => return Ok(None),
        }),
        Line::Status | Line::Watch { .. } | Line::Record { .. } | Line::Wait { .. } => {
            return Ok(None);
        }
    }))
}

/// Why a session ended early.
#[derive(Debug)]
pub enum Stop {
    Rejected(Outcome),
    Alarm(Alarm),
    Error(anyhow::Error),
}

impl std::fmt::Display for Stop {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Stop::Rejected(o) => write!(f, "{o}"),
            Stop::Alarm(a) => write!(f, "{a}"),
            Stop::Error(e) => write!(f, "{e:#}"),
        }
    }
}

impl From<Alarm> for Stop {
    fn from(a: Alarm) -> Self {
        Stop::Alarm(a)
    }
}
/// A session's error: a rejection or an alarm as its text, an error with its causes.
impl From<Stop> for anyhow::Error {
    fn from(s: Stop) -> Self {
        match s {
            Stop::Error(e) => e,
            other => anyhow!("{other}"),
        }
    }
}
impl From<anyhow::Error> for Stop {
    fn from(e: anyhow::Error) -> Self {
        Stop::Error(e)
    }
}

/// Whether a run was seen running and no longer is.
#[derive(Default)]
struct RunEnd {
    seen_running: bool,
}

impl RunEnd {
    fn ended(&mut self, seen: &Seen) -> bool {
        if let Seen::Status(s) = seen {
            if s.state == RigState::Running {
                self.seen_running = true;
            } else if self.seen_running {
                return true;
            }
        }
        false
    }
}

/// Longest `wait --until-end` without `--for-s`, s.
pub const WAIT_MAX_S: f64 = 600.0;

/// The open recording of a session.
pub struct Recording {
    pub out: PathBuf,
    /// The programme run recorded (`# run:` metadata).
    pub run: Option<String>,
}

/// Runs one line in a session; prints what it does.
pub fn run_line<T: Transport>(
    s: &mut Session<T>,
    line: &Line,
    recording: &mut Option<Recording>,
    alone: bool,
) -> Result<(), Stop> {
    let commands = commands_of(line)?;
    if let Line::Start(a) = line {
        s.last_track_layout = match &a.track {
            Some(t) => Some(crate::wsp::programme::track_layout(
                &track::load_track_file(t)?.0,
            )),
            None => None,
        };
    }
    if !commands.is_empty() {
        for c in commands {
            let o = s.command(c)?;
            println!("{o}");
            if !o.accepted {
                return Err(Stop::Rejected(o));
            }
        }
        return Ok(());
    }
    match line {
        Line::Status => {
            let st = s.next_status(1)?;
            println!(
                "{}",
                watch::render(&s.board, &s.link.describe(), s.link.now_s())
            );
            let _ = st;
        }
        Line::Watch { for_s, every_s } => {
            let mut w = Watcher::stdout(&s.link.describe(), *every_s);
            s.run_for(for_s.unwrap_or(f64::INFINITY), |b, seen| {
                w.frame(b, seen);
                Flow::Continue
            })?;
        }
        Line::Record { out, for_s } => {
            if let Some(first) = recording.take() {
                let end = format!(
                    "a new recording (record --out {}) began at t = {:.3} s",
                    out.display(),
                    s.link.now_s()
                );
                finish(s, Some(first), &end)?;
            }
            s.recorder = Some(Recorder::default());
            *recording = Some(Recording {
                out: out.clone(),
                run: None,
            });
            println!("recording to {}", out.display());
            if alone {
                let mut end = RunEnd::default();
                s.run_for(for_s.unwrap_or(f64::INFINITY), |_, seen| {
                    if end.ended(seen) {
                        Flow::Done
                    } else {
                        Flow::Continue
                    }
                })?;
            }
        }
        Line::Wait { for_s, until_end } => {
            let mut end = RunEnd::default();
            if let Some(st) = s.board.status() {
                end.seen_running = st.state == RigState::Running;
            }
            let limit = for_s.unwrap_or(if *until_end { WAIT_MAX_S } else { 0.0 });
            let mut ended = false;
            s.run_for(limit, |_, seen| {
                if *until_end && end.ended(seen) {
                    ended = true;
                    Flow::Done
                } else {
                    Flow::Continue
                }
            })?;
            let state = s.board.status().map(|st| {
                format!(
                    "board {} at t = {:.3} s, {:.2} km/h",
                    state_name(st.state),
                    s.link.now_s(),
                    st.vehicle_speed_kmh
                )
            });
            let state = state.unwrap_or_else(|| "no status frame".into());
            if *until_end && !ended {
                return Err(Stop::Error(anyhow!(
                    "wait --until-end: the run did not end within {limit} s of board time ({state})"
                )));
            }
            println!("wait: {state}");
        }
        _ => {}
    }
    Ok(())
}

/// Ends a session: writes the recording (if any) with why it ended.
pub fn finish<T: Transport>(
    s: &mut Session<T>,
    recording: Option<Recording>,
    end: &str,
) -> Result<()> {
    if let (Some(rec), Some(r)) = (s.recorder.take(), recording) {
        let mut rec = rec;
        rec.push_probe(s.link.take_probe());
        let meta = record::RunMeta {
            source: format!("hils rig record over {}", s.link.describe()),
            run: r.run,
            start: s.last_start,
            end: end.to_string(),
            wheel_radius_m: None,
            track: s.last_track_layout.clone(),
            demand: None,
        };
        let w = rec.write(&r.out, &meta)?;
        println!(
            "wrote {} ({} rows, {} probe records; end: {end})",
            r.out.display(),
            w.rows,
            w.probe_records
        );
    }
    Ok(())
}

/// Parses the sim fault options; a kind given twice is refused (one time per kind: the
/// second would silently replace the first).
pub fn sim_faults(specs: &[String]) -> Result<SimFaults> {
    let mut f = SimFaults::default();
    for spec in specs {
        let (kind, t) =
            crate::flags::rig_sim_fault(spec).map_err(|e| anyhow!("--sim-fault {e}"))?;
        let slot = match kind {
            "board-lost" => &mut f.board_lost_at_s,
            "bus-off" => &mut f.bus_off_at_s,
            _ => &mut f.status_alive_frozen_at_s,
        };
        if let Some(first) = slot.replace(t) {
            bail!("--sim-fault {spec}: {kind} is already given (at {first} s); one time per kind");
        }
    }
    Ok(f)
}

impl Transport for Box<dyn Transport> {
    fn send(&mut self, frame: &ClassicFrame) -> Result<(), TransportError> {
        (**self).send(frame)
    }
    fn receive(&mut self, timeout_s: f64) -> Result<Option<Received>, TransportError> {
        (**self).receive(timeout_s)
    }
    fn now_s(&self) -> f64 {
        (**self).now_s()
    }
    fn take_probe(&mut self) -> Vec<ProbeEvent> {
        (**self).take_probe()
    }
    fn describe(&self) -> String {
        (**self).describe()
    }
}

/// Opens the interface of the arguments.
pub fn open(args: &RigArgs) -> Result<Box<dyn Transport>> {
    let faults = sim_faults(&args.sim_faults)?;
    if args.interface == "sim" {
        return Ok(Box::new(SimBoard::new(faults, args.realtime)));
    }
    if faults != SimFaults::default() || args.realtime {
        bail!("--sim-fault and --realtime are for `--interface sim`");
    }
    socketcan::open(&args.interface)
}

/// The lines of a session script, each checked as [`commands_of`] makes its frames (its
/// values and the files it names read and checked); an error names the script's line.
pub fn parse_script(path: &Path, text: &str) -> Result<Vec<Line>> {
    #[derive(Parser)]
    #[command(name = "line", no_binary_name = true)]
    struct One {
        #[command(subcommand)]
        line: Line,
    }
    let mut lines = Vec::new();
    for (i, raw) in text.lines().enumerate() {
        let body = raw.split('#').next().unwrap_or("").trim();
        if body.is_empty() {
            continue;
        }
        let one = One::try_parse_from(body.split_whitespace()).map_err(|e| {
            anyhow!(
                "{}:{}: `{body}`: {}",
                path.display(),
                i + 1,
                e.render().to_string().lines().next().unwrap_or("bad line")
            )
        })?;
        // Every value and file of the line (channel, service deceleration, `--track`,
        // `configure io`) checked now, before the session sends anything: a bad line 9
        // does not end a session after lines 1-8 have started a run.
        commands_of(&one.line)
            .map_err(|e| anyhow!("{}:{}: `{body}`: {e:#}", path.display(), i + 1))?;
        lines.push(one.line);
    }
    Ok(lines)
}

/// Checks the output of every `record` line before the session sends anything: its folder
/// exists and takes the file, and no two lines record into the same file.
pub fn check_recordings(lines: &[Line]) -> Result<()> {
    let mut seen = std::collections::BTreeSet::new();
    for line in lines {
        if let Line::Record { out, .. } = line {
            crate::outputs::OutFile::check_file(
                out,
                "record --out",
                "a run log goes to a file (the session prints its lines on standard output)",
            )?;
            if !seen.insert(out.clone()) {
                bail!(
                    "record --out {} appears twice: the second recording would replace the first",
                    out.display()
                );
            }
        }
    }
    Ok(())
}

/// Runs lines in one session (the recordings' files checked first); each recording is
/// written however the session ends.
pub fn run_session<T: Transport>(s: &mut Session<T>, lines: &[Line], alone: bool) -> Result<()> {
    check_recordings(lines)?;
    let mut recording = None;
    let mut result = Ok(());
    for line in lines {
        if let Err(e) = run_line(s, line, &mut recording, alone) {
            result = Err(e);
            break;
        }
    }
    let end = match &result {
        Ok(()) => "end of session".to_string(),
        Err(e) => format!("session ended early: {e}"),
    };
    finish(s, recording, &end)?;
    Ok(result?)
}

/// `hils rig`.
pub fn main(args: RigArgs) -> Result<()> {
    match &args.command {
        RigCommand::Run(a) => programme::main(&args, a),
        RigCommand::Session { file } => {
            let text = std::fs::read_to_string(file)
                .map_err(|e| anyhow!("cannot read {}: {e}", file.display()))?;
            let lines = parse_script(file, &text)?;
            if lines.is_empty() {
                bail!(
                    "{}: no command line (only blanks and `#` comments): nothing to run",
                    file.display()
                );
            }
            let mut s = Session::new(open(&args)?, args.lost_after_s);
            run_session(&mut s, &lines, false)
        }
        RigCommand::Line(line) => {
            let mut s = Session::new(open(&args)?, args.lost_after_s);
            run_session(&mut s, std::slice::from_ref(line), true)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_sim_fault_kind_given_twice_is_refused_not_replaced() {
        let specs = |s: &[&str]| s.iter().map(|x| x.to_string()).collect::<Vec<_>>();
        let f = sim_faults(&specs(&["bus-off=5", "board-lost=2"])).unwrap();
        assert_eq!((f.bus_off_at_s, f.board_lost_at_s), (Some(5.0), Some(2.0)));
        let e = format!(
            "{:#}",
            sim_faults(&specs(&["bus-off=5", "bus-off=1"])).unwrap_err()
        );
        assert!(e.contains("bus-off=1") && e.contains("already"), "{e}");
    }
}
