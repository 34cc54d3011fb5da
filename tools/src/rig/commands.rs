//! A session with the board: each command is sent as a `RIG_COMMAND` frame and its result
//! read back from the status frame's `CommandResult`; frames in between feed the
//! [`BoardView`], the recorder and the live view.
//!
//! # Which result is ours
//!
//! `RIG_STATUS` carries the result of the *last* command (none/accepted/rejected), not which
//! command it was, nor why a rejection. The session therefore
//! * takes the second status frame after sending (the board acts on a command at its next
//!   tick; status frames come every 10 ms, so the second one is sent after the command was
//!   handled on any healthy bus, and a CAN frame is retransmitted until acknowledged);
//! * checks the effect where the status shows one (`start` -> running, `stop` -> stopped);
//! * names the reason of a rejection from the command and the status before it (state, fault
//!   flags, ranges of `rig-core`: see [`rejection_reason`]); when none applies, the first
//!   command of a session is sent once more with the next alive counter, because the board
//!   rejects a command whose counter equals the last one it took (`Repeated`), which a new
//!   process can hit by chance. A rejected command changes nothing on the board, so the
//!   repeat is safe.

use hils_plant::track::MAX_ZONES;
use hils_rig_core::can::{
    Calibration, ClassicFrame, Command, CommandFrame, CommandResult, RigMode, RigState,
    StartCommand, StatusFrame, TrackCommand, WHEEL_SPEED_MAX_KMH,
};
use hils_rig_core::rig::Faults;

use super::monitor::{Alarm, BoardView, Seen, state_name};
use super::record::Recorder;
use super::transport::Transport;

/// What came of a command.
#[derive(Clone, Debug, PartialEq)]
pub struct Outcome {
    pub command: Command,
    pub accepted: bool,
    /// Why it was rejected (or why an acceptance is in doubt).
    pub reason: Option<String>,
    /// The status frame the result was read from.
    pub status: StatusFrame,
}

impl std::fmt::Display for Outcome {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let verdict = if self.accepted {
            "accepted"
        } else {
            "rejected"
        };
        write!(f, "{}: {verdict}", command_name(&self.command))?;
        if let Some(r) = &self.reason {
            write!(f, ": {r}")?;
        }
        write!(f, " (board: {})", state_name(self.status.state))
    }
}

/// Lower-case name of a command.
pub fn command_name(c: &Command) -> &'static str {
    match c {
        Command::Start { .. } => "start",
        Command::Stop => "stop",
        Command::Brake(_) => "brake",
        Command::InjectFault { .. } => "inject",
        Command::Calibrate { .. } => "calibrate",
        Command::ClearFaults => "clear-faults",
        Command::Configure(_) => "configure",
        Command::TrackZone { .. } => "track-zone",
        Command::Track(TrackCommand::Commit { .. }) => "track-commit",
        Command::Track(TrackCommand::Clear) => "track-clear",
        Command::Vehicle { .. } => "vehicle",
        Command::Arm => "arm",
        Command::Disarm => "disarm",
    }
}

/// The sensor channels (1-based) flagged in the status frame's fault bits.
fn sensor_channels(faults: u16) -> Vec<String> {
    (0..4)
        .filter(|j| faults as u32 & (1 << j) & Faults::SENSOR.bits() != 0)
        .map(|j| (j + 1).to_string())
        .collect()
}

/// Why the board rejects a `Start` whose `StartDigest` differs from its kept setup
/// (`hils_rig_core::rig::CommandError::SetupMismatch`).
const SETUP_MISMATCH: &str =
    "the board's track/vehicle differs from what was sent: a frame was lost; resend";

/// Why the board rejects a rig-mode `Start` while not armed
/// (`hils_rig_core::rig::CommandError::NotArmed`).
pub const NOT_ARMED: &str = "the board is not armed for a controller: `hils rig arm` first (or `start --arm`); it disarms at every stop, fault and reset";

/// Why the board (`hils_rig_core::rig::Rig::command`) rejects `command` in the state the
/// status frame `before` shows, and the arming the board last reported (`armed`, from
/// `RIG_HEALTH`; `None`: not seen yet); `None` when no rule applies.
pub fn rejection_reason(
    command: &Command,
    before: &StatusFrame,
    armed: Option<bool>,
) -> Option<String> {
    let running = before.state == RigState::Running;
    match command {
        Command::Start(StartCommand {
            mode,
            initial_speed_kmh,
            track,
            ..
        }) => {
            if running {
                Some("a run is active: stop it first".into())
            } else if !(0.0..=WHEEL_SPEED_MAX_KMH).contains(initial_speed_kmh) {
                Some(format!(
                    "initial speed {initial_speed_kmh} km/h is outside 0-{WHEEL_SPEED_MAX_KMH:.2} km/h (the wheel-speed frame's range)"
                ))
            } else if *mode == RigMode::Rig && before.faults as u32 & Faults::SENSOR.bits() != 0 {
                Some(format!(
                    "sensor fault latched on channel(s) {}: clear faults first (`hils rig clear-faults`)",
                    sensor_channels(before.faults).join(", ")
                ))
            } else if *mode == RigMode::Rig && armed == Some(false) {
                Some(NOT_ARMED.into())
            } else {
                // Not armed is a cause only while the board's arming is not known.
                let arming = if *mode == RigMode::Rig && armed.is_none() {
                    format!("{NOT_ARMED}; or ")
                } else {
                    String::new()
                };
                Some(if *track {
                    format!(
                        "{arming}no track kept on the board (send its zones and commit it first, `--track FILE`), or {SETUP_MISMATCH}"
                    )
                } else {
                    format!("{arming}{SETUP_MISMATCH}")
                })
            }
        }
        Command::TrackZone { index, .. } if *index as usize >= MAX_ZONES => Some(format!(
            "zone index {index}: a track holds at most {MAX_ZONES} zones"
        )),
        Command::Track(TrackCommand::Commit { zones, .. }) => Some(format!(
            "the board refused the track of {zones} zone(s): more than {MAX_ZONES}, a zone of 0..{zones} not received since the last commit, or zones empty, out of order or overlapping"
        )),
        // The first frame of a `start` (its default vehicle): the start's wording.
        Command::Vehicle { .. } if running => Some("a run is active: stop it first".into()),
        Command::Arm if matches!(before.state, RigState::Running | RigState::Starting) => {
            Some("a run is active: arm before the start".into())
        }
        Command::Arm => Some(
            "faults latched or the board in fault: clear them first (`hils rig clear-faults`)"
                .into(),
        ),
        Command::Stop if !running => Some(format!(
            "no run to stop (state {})",
            state_name(before.state)
        )),
        Command::Calibrate { .. } | Command::Configure(_) if running => {
            Some("not allowed during a run".into())
        }
        Command::Calibrate {
            action: Calibration::Tare,
            ..
        } => Some("tare needs an unloaded, plausible sensor (reading near zero, no fault)".into()),
        Command::Calibrate { .. } => Some("the channel refused the calibration value".into()),
        _ => None,
    }
}

/// A session with the board over a transport.
pub struct Session<T: Transport> {
    pub link: T,
    pub board: BoardView,
    /// No frame for this long (s) = the board is lost.
    pub lost_after_s: f64,
    counter: u8,
    commands_sent: u32,
    /// Session start on the transport's clock.
    started_s: f64,
    /// Recording, when on.
    pub recorder: Option<Recorder>,
    /// The last start command (run metadata for the recorder).
    pub last_start: Option<Command>,
    /// The layout of the track of the last start, when this session sent it
    /// (`start --track FILE`; `crate::wsp::programme::track_layout`).
    pub last_track_layout: Option<String>,
}

/// Whether to go on waiting.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Flow {
    Continue,
    Done,
}

impl<T: Transport> Session<T> {
    pub fn new(link: T, lost_after_s: f64) -> Self {
        // A counter a new process is unlikely to share with the last command the board took.
        let nanos = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map(|d| d.subsec_nanos())
            .unwrap_or(0);
        let started_s = link.now_s();
        Self {
            link,
            board: BoardView::default(),
            lost_after_s,
            counter: (nanos >> 10) as u8 & 0x0F,
            commands_sent: 0,
            started_s,
            recorder: None,
            last_start: None,
            last_track_layout: None,
        }
    }

    /// Receives one frame (at most `timeout_s`): updates the view and the recorder. An alarm
    /// when the board has been silent for `lost_after_s`, on a bus-off (host or board) or a
    /// stuck alive counter.
    pub fn pump(&mut self, timeout_s: f64) -> Result<Option<Seen>, Alarm> {
        let now = self.link.now_s();
        let last = self.board.last_frame_s.unwrap_or(self.started_s);
        let left = (last + self.lost_after_s - now).max(0.0);
        let got = self.link.receive(timeout_s.min(left));
        // The probe's telemetry is taken always (kept only while recording).
        let probe = self.link.take_probe();
        if let Some(rec) = &mut self.recorder {
            rec.push_probe(probe);
        }
        let Some(r) = got? else {
            let silent_s = self.link.now_s() - last;
            if silent_s >= self.lost_after_s {
                return Err(Alarm::BoardLost { silent_s });
            }
            return Ok(None);
        };
        let fed = self.board.feed(&r);
        if let (Some(rec), Ok((s, cycle))) = (&mut self.recorder, &fed) {
            rec.push(r.t_s, s, *cycle);
        }
        let (seen, _) = fed?;
        if let Seen::Status(s) = seen {
            if s.faults as u32 & Faults::CAN_BUS_OFF.bits() != 0 {
                return Err(Alarm::BoardBusOff);
            }
        }
        Ok(Some(seen))
    }

    /// Receives frames for `duration_s` (transport clock) or until `each` says done.
    pub fn run_for(
        &mut self,
        duration_s: f64,
        mut each: impl FnMut(&BoardView, &Seen) -> Flow,
    ) -> Result<(), Alarm> {
        let end = self.link.now_s() + duration_s;
        loop {
            let left = end - self.link.now_s();
            if left <= 0.0 {
                return Ok(());
            }
            if let Some(seen) = self.pump(left)? {
                if each(&self.board, &seen) == Flow::Done {
                    return Ok(());
                }
            }
        }
    }

    /// Waits for the `n`-th status frame from now.
    pub fn next_status(&mut self, n: usize) -> Result<StatusFrame, Alarm> {
        let mut seen = 0;
        let mut last = None;
        while seen < n {
            if let Some(Seen::Status(s)) = self.pump(self.lost_after_s)? {
                seen += 1;
                last = Some(s);
            }
        }
        last.ok_or(Alarm::BoardLost {
            silent_s: self.lost_after_s,
        })
    }

    /// The status now (waits for one if none came yet).
    pub fn status(&mut self) -> Result<StatusFrame, Alarm> {
        match self.board.status() {
            Some(s) => Ok(s),
            None => self.next_status(1),
        }
    }

    fn send(&mut self, command: Command) -> Result<(), Alarm> {
        let frame: Option<ClassicFrame> = CommandFrame {
            command,
            counter: self.counter,
        }
        .encode();
        self.counter = (self.counter + 1) & 0x0F;
        self.commands_sent += 1;
        let frame = frame.ok_or_else(|| Alarm::Transport("command does not encode".into()))?;
        self.link.send(&frame)?;
        let t = self.link.now_s();
        if let Some(rec) = &mut self.recorder {
            rec.note_command(t, command);
        }
        if matches!(command, Command::Start { .. }) {
            self.last_start = Some(command);
        }
        Ok(())
    }

    /// Sends a command and reads its result (see the module doc).
    pub fn command(&mut self, command: Command) -> Result<Outcome, Alarm> {
        let before = self.status()?;
        let first = self.commands_sent == 0;
        self.send(command)?;
        let mut status = self.next_status(2)?;
        let mut reason = None;
        let mut accepted = status.command_result == CommandResult::Accepted;
        if !accepted {
            let rig_start = matches!(
                command,
                Command::Start(StartCommand {
                    mode: RigMode::Rig,
                    ..
                })
            );
            if rig_start && self.board.armed().is_none() {
                // RIG_HEALTH (every 100 ms) says whether the board is armed: wait for one
                // to name the reason exactly.
                self.run_for(0.15, |b, _| {
                    if b.armed().is_some() {
                        Flow::Done
                    } else {
                        Flow::Continue
                    }
                })?;
            }
            reason = rejection_reason(&command, &before, self.board.armed());
            if reason.is_none() && first {
                self.send(command)?;
                status = self.next_status(2)?;
                accepted = status.command_result == CommandResult::Accepted;
            }
            if !accepted && reason.is_none() {
                reason = Some(match status.command_result {
                    CommandResult::None => "no CommandResult from the board".to_string(),
                    _ => {
                        "the status frame carries no reason and no rule of the board's explains it"
                            .to_string()
                    }
                });
            }
        }
        if accepted {
            reason = effect_missing(&command, &status);
            accepted = reason.is_none();
        }
        Ok(Outcome {
            command,
            accepted,
            reason,
            status,
        })
    }
}

/// For an accepted command whose effect the status shows: why it is not there.
fn effect_missing(command: &Command, status: &StatusFrame) -> Option<String> {
    let ok = match command {
        Command::Start { .. } => matches!(status.state, RigState::Running | RigState::Finished),
        Command::Stop => status.state == RigState::Stopped,
        _ => true,
    };
    (!ok).then(|| {
        format!(
            "result `accepted`, but the board is {} (the result may be an earlier command's)",
            state_name(status.state)
        )
    })
}
