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

pub mod commands;
pub mod monitor;
pub mod programme;
pub mod record;
pub mod sim;
pub mod socketcan;
pub mod transport;
pub mod watch;

use std::path::{Path, PathBuf};

use anyhow::{Result, anyhow, bail};
use clap::{Args, Parser, Subcommand, ValueEnum};
use hils_plant::{FrictionModel, Rail};
use hils_rig_core::can::{
    BrakeCommand, Calibration, ClassicFrame, Command, ConfigItem, InjectedFault, RigMode, RigState,
};
use hils_rig_core::sensor::SensorKind;

use commands::{Flow, Outcome, Session, state_name};
use monitor::{Alarm, Seen};
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
    /// No frame from the board for this long (s) = board lost.
    #[arg(long, global = true, default_value_t = 0.5)]
    pub lost_after_s: f64,
    /// Sim: pace the board to the wall clock (else it runs as fast as the host steps it).
    #[arg(long, global = true)]
    pub realtime: bool,
    /// Sim: a fault at a board time, `board-lost=S`, `bus-off=S` or `alive-frozen=S`
    /// (repeatable).
    #[arg(long = "sim-fault", global = true)]
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
        /// Service deceleration, m/s^2 (for `service`).
        decel_mps2: Option<f32>,
    },
    /// Inject a sensor fault on channel 1-4 (`none` removes it).
    Inject { channel: u8, fault: FaultKind },
    /// Calibrate channel 1-4: `tare`, `gain X`, `offset X`, `kind load-cell|pressure`.
    Calibrate {
        channel: u8,
        action: CalAction,
        /// The gain (unit per count), offset (counts) or kind (`load-cell`, `pressure`).
        value: Option<String>,
    },
    /// Clear latched faults whose cause is gone.
    ClearFaults,
    /// Set the telemetry divider or the sensor-wheel teeth (no run active).
    Configure { item: ConfigKind, value: u16 },
    /// Print the board's status.
    Status,
    /// Live view of the board (at the status rate on a terminal).
    Watch {
        /// Stop after this long (s); default: until the board is lost.
        #[arg(long)]
        for_s: Option<f64>,
        /// When the output is not a terminal: one view per this much board time, s.
        #[arg(long, default_value_t = 1.0)]
        every_s: f64,
    },
    /// Record the wheel-speed and status frames as a run log. Alone: until a run ends (or
    /// `--for-s`); in a session: from here to the end of the session.
    Record {
        #[arg(long)]
        out: PathBuf,
        #[arg(long)]
        for_s: Option<f64>,
    },
    /// Wait: `--for-s S`, or `--until-end` (a run was running and no longer is).
    Wait {
        #[arg(long)]
        for_s: Option<f64>,
        #[arg(long)]
        until_end: bool,
    },
}

#[derive(Args, Debug, Clone)]
pub struct StartArgs {
    /// Initial speed, km/h (the board takes 0-163.82).
    #[arg(long)]
    pub speed_kmh: f32,
    #[arg(long, value_enum, default_value_t = RailArg::Wet)]
    pub rail: RailArg,
    #[arg(long, value_enum, default_value_t = FrictionArg::Variable)]
    pub friction: FrictionArg,
    /// Track profile: not carried by `hils.dbc` (refused with an error).
    #[arg(long)]
    pub track: Option<PathBuf>,
    /// `rig` (the controller on the rig) or `self-test` (the board's own simulated brake unit).
    #[arg(long, value_enum, default_value_t = ModeArg::Rig)]
    pub mode: ModeArg,
    /// Self-test: emergency brake at t = 0.
    #[arg(long)]
    pub eb: bool,
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
#[derive(ValueEnum, Debug, Clone, Copy, PartialEq, Eq)]
pub enum CalAction {
    Tare,
    Gain,
    Offset,
    Kind,
}
#[derive(ValueEnum, Debug, Clone, Copy, PartialEq, Eq)]
pub enum ConfigKind {
    Divider,
    Teeth,
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

/// The `RIG_COMMAND` of a line (None for lines that send nothing).
pub fn command_of(line: &Line) -> Result<Option<Command>> {
    Ok(Some(match line {
        Line::Start(a) => {
            if let Some(t) = &a.track {
                bail!(
                    "--track {}: the board takes no track profile over CAN (hils.dbc has no track signal); not supported yet",
                    t.display()
                );
            }
            Command::Start {
                mode: match a.mode {
                    ModeArg::Rig => RigMode::Rig,
                    ModeArg::SelfTest => RigMode::SelfTest,
                },
                rail: a.rail.rail(),
                friction: a.friction.model(),
                emergency: a.eb,
                initial_speed_kmh: a.speed_kmh,
            }
        }
        Line::Stop => Command::Stop,
        Line::Brake { demand, decel_mps2 } => Command::Brake(match (demand, decel_mps2) {
            (BrakeKind::Eb, None) => BrakeCommand::Emergency,
            (BrakeKind::Release, None) => BrakeCommand::Release,
            (BrakeKind::Service, Some(d)) if d.is_finite() && (0.0..=10.0).contains(d) => {
                BrakeCommand::Service {
                    deceleration_mps2: *d,
                }
            }
            (BrakeKind::Service, _) => {
                bail!("brake service needs a deceleration 0-10 m/s^2 (`brake service 1.0`)")
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
        Line::Calibrate {
            channel: c,
            action,
            value,
        } => {
            let number = || -> Result<f32> {
                let v = value
                    .as_deref()
                    .ok_or_else(|| anyhow!("calibrate {action:?} needs a value"))?;
                v.parse::<f32>()
                    .map_err(|_| anyhow!("calibration value `{v}` is not a number"))
            };
            Command::Calibrate {
                channel: channel(*c)?,
                action: match action {
                    CalAction::Tare => Calibration::Tare,
                    CalAction::Gain => Calibration::SetGain(number()?),
                    CalAction::Offset => Calibration::SetOffset(number()?),
                    CalAction::Kind => Calibration::SetKind(match value.as_deref() {
                        Some("load-cell") => SensorKind::LoadCell,
                        Some("pressure") => SensorKind::PressureTransducer,
                        _ => bail!("calibrate kind: `load-cell` or `pressure`"),
                    }),
                },
            }
        }
        Line::ClearFaults => Command::ClearFaults,
        Line::Configure { item, value } => Command::Configure(match item {
            ConfigKind::Divider => ConfigItem::TelemetryDivider(*value),
            ConfigKind::Teeth => ConfigItem::Teeth(*value),
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
    if let Some(c) = command_of(line)? {
        let o = s.command(c)?;
        println!("{o}");
        if !o.accepted {
            return Err(Stop::Rejected(o));
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
            s.run_for(limit, |_, seen| {
                if *until_end && end.ended(seen) {
                    Flow::Done
                } else {
                    Flow::Continue
                }
            })?;
            if let Some(st) = s.board.status() {
                println!(
                    "wait: board {} at t = {:.3} s, {:.2} km/h",
                    state_name(st.state),
                    s.link.now_s(),
                    st.vehicle_speed_kmh
                );
            }
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

/// Parses the sim fault options.
pub fn sim_faults(specs: &[String]) -> Result<SimFaults> {
    let mut f = SimFaults::default();
    for spec in specs {
        let (k, v) = spec
            .split_once('=')
            .ok_or_else(|| anyhow!("--sim-fault {spec}: expected KIND=SECONDS"))?;
        let t: f64 = v
            .parse()
            .ok()
            .filter(|t: &f64| t.is_finite() && *t >= 0.0)
            .ok_or_else(|| anyhow!("--sim-fault {spec}: `{v}` is not a time in s"))?;
        match k {
            "board-lost" => f.board_lost_at_s = Some(t),
            "bus-off" => f.bus_off_at_s = Some(t),
            "alive-frozen" => f.status_alive_frozen_at_s = Some(t),
            _ => bail!("--sim-fault {spec}: kinds are board-lost, bus-off, alive-frozen"),
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

/// The lines of a session script.
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
        lines.push(one.line);
    }
    Ok(lines)
}

/// Runs lines in one session; the recording is written however it ends.
pub fn run_session<T: Transport>(s: &mut Session<T>, lines: &[Line], alone: bool) -> Result<()> {
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
    result.map_err(|e| anyhow!("{e}"))
}

/// `hils rig`.
pub fn main(args: RigArgs) -> Result<()> {
    match &args.command {
        RigCommand::Run(a) => programme::main(&args, a),
        RigCommand::Session { file } => {
            let text = std::fs::read_to_string(file)
                .map_err(|e| anyhow!("cannot read {}: {e}", file.display()))?;
            let lines = parse_script(file, &text)?;
            let mut s = Session::new(open(&args)?, args.lost_after_s);
            run_session(&mut s, &lines, false)
        }
        RigCommand::Line(line) => {
            let mut s = Session::new(open(&args)?, args.lost_after_s);
            run_session(&mut s, std::slice::from_ref(line), true)
        }
    }
}
