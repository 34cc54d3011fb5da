//! What the host knows of the board from the frames it receives: the latest wheel-speed,
//! status and diagnostic frames decoded by `rig-core`'s codec, frame counts, checksum and
//! decode errors, lost frames (gaps in the alive counters), and the alarms that end a
//! scripted run: the board lost (no frame within the timeout), a bus-off, a stuck alive
//! counter.
//!
//! Decoding goes through `hils_rig_core::can` only (the layout tables behind
//! `WheelSpeedFrame`, `StatusFrame`, `DiagFrame`): no bit position is known here.

use hils_rig_core::can::{
    BrakeDemandFrame, ClassicFrame, CommandFrame, DecodeError, DiagFrame, HealthFrame, RigState,
    StatusFrame, WheelSpeedFrame,
};
use hils_rig_core::valves::ValveStates;

use super::transport::{Received, TransportError};

/// A received frame, decoded.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Seen {
    WheelSpeed(WheelSpeedFrame),
    Status(StatusFrame),
    Diag(DiagFrame),
    /// `RIG_BRAKE_DEMAND` (the board's demand as a frame, when configured).
    BrakeDemand(BrakeDemandFrame),
    /// `RIG_HEALTH`: the board's own health and its arming.
    Health(HealthFrame),
    /// A `RIG_COMMAND` on the bus (another host's, or our own echoed by the interface).
    Command(CommandFrame),
    /// A frame of another identifier (not in `hils.dbc`; ignored, counted).
    Other,
    /// A frame of `hils.dbc` that does not decode (checksum, length, field range).
    Bad(DecodeError),
}

/// Decodes a frame with `rig-core`'s codec.
pub fn decode(frame: &ClassicFrame) -> Seen {
    fn pick<T>(r: Result<T, DecodeError>, f: fn(T) -> Seen) -> Option<Seen> {
        match r {
            Ok(v) => Some(f(v)),
            Err(DecodeError::WrongId) => None,
            Err(e) => Some(Seen::Bad(e)),
        }
    }
    pick(WheelSpeedFrame::decode(frame), Seen::WheelSpeed)
        .or_else(|| pick(StatusFrame::decode(frame), Seen::Status))
        .or_else(|| pick(DiagFrame::decode(frame), Seen::Diag))
        .or_else(|| pick(BrakeDemandFrame::decode(frame), Seen::BrakeDemand))
        .or_else(|| pick(HealthFrame::decode(frame), Seen::Health))
        .or_else(|| pick(CommandFrame::decode(frame), Seen::Command))
        .unwrap_or(Seen::Other)
}

/// The four wheelsets' speeds and valve inputs of one cycle: the `RIG_WHEEL_SPEED_12` and
/// `_34` frames that carry the same alive counter.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WheelSpeeds {
    pub speeds_kmh: [Option<f32>; 4],
    /// The valve inputs as the board sampled them in the frames' tick (not wired: not known).
    pub valves: ValveStates,
    pub counter: u8,
}

/// Pairs the two wheel-speed frames of a cycle; a half without its partner is counted.
#[derive(Clone, Copy, Debug, Default)]
pub struct Pairing {
    first: Option<WheelSpeedFrame>,
    /// Halves that found no partner of the same cycle.
    pub unpaired: u64,
}

impl Pairing {
    /// Takes one wheel-speed frame; the whole cycle once both halves are in.
    pub fn take(&mut self, w: WheelSpeedFrame) -> Option<WheelSpeeds> {
        if w.pair == 0 {
            self.unpaired += u64::from(self.first.replace(w).is_some());
            return None;
        }
        match self.first.take() {
            Some(f) if f.counter == w.counter => Some(WheelSpeeds {
                speeds_kmh: [
                    f.speeds_kmh[0],
                    f.speeds_kmh[1],
                    w.speeds_kmh[0],
                    w.speeds_kmh[1],
                ],
                valves: ValveStates {
                    dump: f.valves.dump | w.valves.dump,
                    hold: f.valves.hold | w.valves.hold,
                    dump_known: f.valves.dump_known | w.valves.dump_known,
                    hold_known: f.valves.hold_known | w.valves.hold_known,
                },
                counter: w.counter,
            }),
            other => {
                self.unpaired += 1 + u64::from(other.is_some());
                None
            }
        }
    }
}

/// Why a scripted run ends before its time.
#[derive(Clone, Debug, PartialEq)]
pub enum Alarm {
    /// No frame from the board for this long, s.
    BoardLost { silent_s: f64 },
    /// The host's CAN controller went bus-off.
    HostBusOff,
    /// The board flags a CAN bus-off in its status frame.
    BoardBusOff,
    /// A frame's alive counter stopped counting (the same value this many times in a row).
    AliveStuck { frame: &'static str, repeats: u32 },
    /// Another transport error.
    Transport(String),
}

impl std::fmt::Display for Alarm {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Alarm::BoardLost { silent_s } => {
                write!(f, "board lost: no frame for {silent_s:.3} s")
            }
            Alarm::HostBusOff => f.write_str("bus-off: the host's CAN controller is off the bus"),
            Alarm::BoardBusOff => f.write_str("bus-off: the board flags a CAN bus-off"),
            Alarm::AliveStuck { frame, repeats } => write!(
                f,
                "alive counter of {frame} stuck: the same value {repeats} times in a row"
            ),
            Alarm::Transport(e) => f.write_str(e),
        }
    }
}

impl std::error::Error for Alarm {}

impl From<TransportError> for Alarm {
    fn from(e: TransportError) -> Self {
        match e {
            TransportError::BusOff => Alarm::HostBusOff,
            TransportError::Io(s) => Alarm::Transport(s),
        }
    }
}

/// Consecutive identical alive counters that make a stuck counter.
pub const ALIVE_STUCK_REPEATS: u32 = 3;

/// Supervision of one frame's alive counter (0-15, +1 per frame).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct AliveCheck {
    last: Option<u8>,
    repeats: u32,
    /// Frames missed (counter gaps).
    pub lost: u64,
}

impl AliveCheck {
    /// Takes a counter; the number of identical counters in a row so far (1 = it counted).
    pub fn feed(&mut self, counter: u8) -> u32 {
        let c = counter & 0x0F;
        match self.last {
            Some(l) if l == c => self.repeats += 1,
            Some(l) => {
                self.repeats = 1;
                self.lost += (c.wrapping_sub(l).wrapping_sub(1) & 0x0F) as u64;
            }
            None => self.repeats = 1,
        }
        self.last = Some(c);
        self.repeats
    }
}

/// Frame counts.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Counts {
    pub wheel_speed: u64,
    pub status: u64,
    pub diag: u64,
    pub health: u64,
    pub other: u64,
    /// Frames of `hils.dbc` that did not decode.
    pub bad: u64,
}

/// The board as the host sees it.
#[derive(Clone, Debug, Default)]
pub struct BoardView {
    pub wheel_speed: Option<(f64, WheelSpeeds)>,
    pub wheel_pairing: Pairing,
    pub status: Option<(f64, StatusFrame)>,
    pub diag: Option<(f64, DiagFrame)>,
    pub health: Option<(f64, HealthFrame)>,
    pub counts: Counts,
    pub wheel_alive: AliveCheck,
    pub status_alive: AliveCheck,
    pub last_bad: Option<DecodeError>,
    pub last_frame_s: Option<f64>,
}

impl BoardView {
    /// Whether the board last reported itself armed for a controller (`RIG_HEALTH`; `None`:
    /// not seen yet).
    pub fn armed(&self) -> Option<bool> {
        self.health.map(|(_, h)| h.disarmed.is_none())
    }

    /// Takes a received frame: what it is and, for the second frame of a wheel-speed
    /// cycle, the whole cycle; an alarm when an alive counter is stuck.
    pub fn feed(&mut self, r: &Received) -> Result<(Seen, Option<WheelSpeeds>), Alarm> {
        self.last_frame_s = Some(r.t_s);
        let seen = decode(&r.frame);
        let mut cycle = None;
        match seen {
            Seen::WheelSpeed(w) => {
                self.counts.wheel_speed += 1;
                cycle = self.wheel_pairing.take(w);
                if let Some(c) = cycle {
                    self.wheel_speed = Some((r.t_s, c));
                    check_alive(&mut self.wheel_alive, c.counter, "RIG_WHEEL_SPEED")?;
                }
            }
            Seen::Status(s) => {
                self.counts.status += 1;
                self.status = Some((r.t_s, s));
                check_alive(&mut self.status_alive, s.counter, "RIG_STATUS")?;
            }
            Seen::Diag(d) => {
                self.counts.diag += 1;
                self.diag = Some((r.t_s, d));
            }
            Seen::Health(h) => {
                self.counts.health += 1;
                self.health = Some((r.t_s, h));
            }
            Seen::Command(_) | Seen::BrakeDemand(_) | Seen::Other => self.counts.other += 1,
            Seen::Bad(e) => {
                self.counts.bad += 1;
                self.last_bad = Some(e);
            }
        }
        Ok((seen, cycle))
    }

    /// The latest status frame.
    pub fn status(&self) -> Option<StatusFrame> {
        self.status.map(|(_, s)| s)
    }
}

fn check_alive(a: &mut AliveCheck, counter: u8, frame: &'static str) -> Result<(), Alarm> {
    let repeats = a.feed(counter);
    if repeats >= ALIVE_STUCK_REPEATS {
        return Err(Alarm::AliveStuck { frame, repeats });
    }
    Ok(())
}

/// The name of a run mode (`rig`, `self-test`).
pub fn mode_name(m: hils_rig_core::can::RigMode) -> &'static str {
    match m {
        hils_rig_core::can::RigMode::Rig => "rig",
        hils_rig_core::can::RigMode::SelfTest => "self-test",
    }
}

/// The name of the last command's result (`none`, `accepted`, `rejected`).
pub fn result_name(r: hils_rig_core::can::CommandResult) -> &'static str {
    match r {
        hils_rig_core::can::CommandResult::None => "none",
        hils_rig_core::can::CommandResult::Accepted => "accepted",
        hils_rig_core::can::CommandResult::Rejected => "rejected",
    }
}

/// The name of a sensor fault (`open`, `short`, `out-of-range`, `stuck`, `adc-invalid`).
pub fn sensor_fault_name(f: hils_rig_core::sensor::SensorFault) -> &'static str {
    use hils_rig_core::sensor::SensorFault;
    match f {
        SensorFault::Open => "open",
        SensorFault::Short => "short",
        SensorFault::OutOfRange => "out-of-range",
        SensorFault::Stuck => "stuck",
        SensorFault::AdcInvalid => "adc-invalid",
    }
}

/// The name of a run state.
pub fn state_name(s: RigState) -> &'static str {
    match s {
        RigState::Idle => "idle",
        RigState::Starting => "starting",
        RigState::Running => "running",
        RigState::Finished => "finished",
        RigState::Stopped => "stopped",
        RigState::Fault => "fault",
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn alive_counts_gaps_across_the_wrap_and_repeats() {
        let mut a = AliveCheck::default();
        assert_eq!(a.feed(14), 1);
        assert_eq!(a.feed(15), 1);
        assert_eq!(a.feed(2), 1); // 0 and 1 lost across the wrap
        assert_eq!(a.lost, 2);
        assert_eq!(a.feed(2), 2);
        assert_eq!(a.feed(2), 3);
        assert_eq!(a.feed(3), 1);
        assert_eq!(a.lost, 2);
    }
}
