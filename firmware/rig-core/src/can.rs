//! The CAN frame codec of the rig interface board (classic CAN, 11-bit identifiers,
//! 8 data bytes, Intel byte order). `hils.dbc` beside this crate describes the same frames;
//! a host test decodes frames made here with an independent DBC parser and checks every
//! signal both ways.
//!
//! | id | name | dir | period | content |
//! |---|---|---|---|---|
//! | 0x100 | `RIG_WHEEL_SPEED` | out | 1 ms | four wheel speeds (14 bit, 0.01 km/h), alive counter, checksum |
//! | 0x110 | `RIG_STATUS` | out | 10 ms | vehicle speed, deceleration, state, mode, command result, fault flags, counter, checksum |
//! | 0x120 | `RIG_DIAG` | out | 100 ms | step time max/mean, overruns, sensor fault kinds, bus-off count |
//! | 0x200 | `RIG_COMMAND` | in | on demand | multiplexed by opcode: start, stop, brake, fault injection, calibration, clear faults, configure; counter, checksum |
//!
//! **Checksum.** The high nibble of byte 7 is a CRC-4/G-704 (polynomial x^4 + x + 1,
//! reflected, init 0, no final xor) over the two bytes of the identifier (little endian),
//! data bytes 0-6 and the low nibble of byte 7 (the alive counter). Including the
//! identifier means a frame with the right bytes under the wrong identifier is rejected,
//! as in AUTOSAR E2E's data id. The **alive counter** (low nibble of byte 7) counts 0-15
//! and wraps, one step per frame sent.
//!
//! **Wheel-speed range.** Four speeds, an alive counter and a checksum fill the 64 bits of a
//! classic frame only with 14 bits per speed: 0.01 km/h resolution over 0-163.82 km/h. The
//! raw value 0x3FFF means "not available" (safe state, see [`crate::rig`]); speeds above
//! the range are sent as 163.82 km/h (0x3FFE) and flagged ([`crate::rig::Faults::SPEED_SATURATED`]).

use embedded_can::{Frame, Id, StandardId};
use hils_plant::{FrictionModel, Rail};

use crate::sensor::{SensorFault, SensorKind};

/// Identifier of `RIG_WHEEL_SPEED`.
pub const ID_WHEEL_SPEED: u16 = 0x100;
/// Identifier of `RIG_STATUS`.
pub const ID_STATUS: u16 = 0x110;
/// Identifier of `RIG_DIAG`.
pub const ID_DIAG: u16 = 0x120;
/// Identifier of `RIG_COMMAND`.
pub const ID_COMMAND: u16 = 0x200;

/// Wheel-speed resolution, km/h per bit.
pub const WHEEL_SPEED_RESOLUTION_KMH: f32 = 0.01;
/// Raw wheel speed meaning "not available".
pub const WHEEL_SPEED_NOT_AVAILABLE: u16 = 0x3FFF;
/// Largest raw wheel speed (163.82 km/h).
pub const WHEEL_SPEED_RAW_MAX: u16 = 0x3FFE;
/// Highest wheel speed the frame carries, km/h.
pub const WHEEL_SPEED_MAX_KMH: f32 = WHEEL_SPEED_RAW_MAX as f32 * WHEEL_SPEED_RESOLUTION_KMH;

/// A plain classic CAN frame implementing [`embedded_can::Frame`] (for targets and tools
/// without a HAL, and the tests).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ClassicFrame {
    pub id: Id,
    pub data: [u8; 8],
    pub len: u8,
    pub remote: bool,
}

impl Frame for ClassicFrame {
    fn new(id: impl Into<Id>, data: &[u8]) -> Option<Self> {
        if data.len() > 8 {
            return None;
        }
        let mut d = [0u8; 8];
        d[..data.len()].copy_from_slice(data);
        Some(Self {
            id: id.into(),
            data: d,
            len: data.len() as u8,
            remote: false,
        })
    }
    fn new_remote(id: impl Into<Id>, dlc: usize) -> Option<Self> {
        (dlc <= 8).then(|| Self {
            id: id.into(),
            data: [0; 8],
            len: dlc as u8,
            remote: true,
        })
    }
    fn is_extended(&self) -> bool {
        matches!(self.id, Id::Extended(_))
    }
    fn is_remote_frame(&self) -> bool {
        self.remote
    }
    fn id(&self) -> Id {
        self.id
    }
    fn dlc(&self) -> usize {
        self.len as usize
    }
    fn data(&self) -> &[u8] {
        if self.remote {
            &[]
        } else {
            &self.data[..(self.len as usize).min(8)]
        }
    }
}

/// Why a received frame was not accepted.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum DecodeError {
    /// Not the identifier of the message being decoded.
    WrongId,
    /// Extended identifier or remote frame.
    NotStandardData,
    /// Data length other than 8.
    WrongLength(u8),
    /// Checksum mismatch (expected, received).
    Checksum { expected: u8, received: u8 },
    /// Command opcode not defined.
    UnknownOpcode(u8),
    /// A field holds a value outside its defined range (names the field).
    BadValue(&'static str),
}

impl core::fmt::Display for DecodeError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            DecodeError::WrongId => f.write_str("wrong identifier"),
            DecodeError::NotStandardData => f.write_str("not a standard data frame"),
            DecodeError::WrongLength(n) => write!(f, "data length {n}, expected 8"),
            DecodeError::Checksum { expected, received } => {
                write!(f, "checksum {received:#x}, expected {expected:#x}")
            }
            DecodeError::UnknownOpcode(op) => write!(f, "unknown command opcode {op}"),
            DecodeError::BadValue(field) => write!(f, "value of `{field}` out of range"),
        }
    }
}

/// CRC-4/G-704 over the identifier, data bytes 0-6 and the counter nibble (see module doc).
pub fn checksum(id: u16, data: &[u8; 8]) -> u8 {
    let mut crc = 0u8;
    let mut feed = |byte: u8, bits: u32| {
        crc ^= byte;
        for _ in 0..bits {
            crc = if crc & 1 != 0 {
                (crc >> 1) ^ 0x0C
            } else {
                crc >> 1
            };
        }
    };
    feed(id as u8, 8);
    feed((id >> 8) as u8, 8);
    for &b in &data[..7] {
        feed(b, 8);
    }
    feed(data[7] & 0x0F, 4);
    crc & 0x0F
}

/// Plain CRC-4/G-704 of a byte string (the catalogue check: "123456789" -> 0x7).
pub fn crc4_g704(bytes: &[u8]) -> u8 {
    let mut crc = 0u8;
    for &b in bytes {
        crc ^= b;
        for _ in 0..8 {
            crc = if crc & 1 != 0 {
                (crc >> 1) ^ 0x0C
            } else {
                crc >> 1
            };
        }
    }
    crc & 0x0F
}

/// Reads an Intel (little-endian) signal of `len` bits from `start` (bit 0 = LSB of byte 0).
#[inline]
pub fn get_bits(data: &[u8; 8], start: u32, len: u32) -> u64 {
    let word = u64::from_le_bytes(*data);
    let shifted = word.checked_shr(start).unwrap_or(0);
    if len >= 64 {
        shifted
    } else {
        shifted & ((1u64 << len) - 1)
    }
}

/// Writes an Intel signal; bits of `value` above `len` are dropped.
#[inline]
pub fn put_bits(data: &mut [u8; 8], start: u32, len: u32, value: u64) {
    let mask = if len >= 64 {
        u64::MAX
    } else {
        (1u64 << len) - 1
    };
    let mut word = u64::from_le_bytes(*data);
    let m = mask.checked_shl(start).unwrap_or(0);
    word = (word & !m) | ((value & mask).checked_shl(start).unwrap_or(0) & m);
    *data = word.to_le_bytes();
}

/// Finishes a frame: counter in the low nibble of byte 7, checksum in the high nibble.
fn seal<F: Frame>(id: u16, mut data: [u8; 8], counter: u8) -> Option<F> {
    put_bits(&mut data, 56, 4, (counter & 0x0F) as u64);
    let crc = checksum(id, &data);
    put_bits(&mut data, 60, 4, crc as u64);
    F::new(StandardId::new(id)?, &data)
}

/// Checks identifier, kind, length and checksum; returns the data and the counter.
fn open<F: Frame>(frame: &F, id: u16) -> Result<([u8; 8], u8), DecodeError> {
    let Id::Standard(sid) = frame.id() else {
        return Err(DecodeError::NotStandardData);
    };
    if frame.is_remote_frame() {
        return Err(DecodeError::NotStandardData);
    }
    if sid.as_raw() != id {
        return Err(DecodeError::WrongId);
    }
    let bytes = frame.data();
    let data: [u8; 8] = bytes
        .try_into()
        .map_err(|_| DecodeError::WrongLength(bytes.len() as u8))?;
    let expected = checksum(id, &data);
    let received = (data[7] >> 4) & 0x0F;
    if expected != received {
        return Err(DecodeError::Checksum { expected, received });
    }
    Ok((data, data[7] & 0x0F))
}

/// Round-to-nearest of a non-negative finite value into `0..=max` (NaN -> 0).
#[inline]
fn quantize(value: f32, resolution: f32, max: u32) -> u32 {
    let x = value / resolution + 0.5;
    if x >= 0.0 {
        if x < max as f32 { x as u32 } else { max }
    } else {
        0
    }
}

/// Signed round-to-nearest into `min..=max` (NaN -> 0).
#[inline]
fn quantize_signed(value: f32, resolution: f32, min: i32, max: i32) -> i32 {
    let x = value / resolution;
    if !(x == x) {
        return 0;
    }
    let r = if x >= 0.0 { x + 0.5 } else { x - 0.5 };
    if r >= max as f32 {
        max
    } else if r <= min as f32 {
        min
    } else {
        r as i32
    }
}

// ---------------------------------------------------------------------------------------
// RIG_WHEEL_SPEED

/// `RIG_WHEEL_SPEED` (0x100, every 1 ms): the four wheelsets' circumferential speeds
/// r omega, km/h. `None` = not available (raw 0x3FFF).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WheelSpeedFrame {
    pub speeds_kmh: [Option<f32>; 4],
    pub counter: u8,
}

impl WheelSpeedFrame {
    /// Start bits of `WheelSpeed1..4` (14 bits each).
    pub const STARTS: [u32; 4] = [0, 14, 28, 42];

    /// Raw value of a speed: rounded to 0.01 km/h, limited to 0..=163.82 km/h; negative
    /// speeds are sent as 0 (a speed sensor has no direction); `None`, NaN -> not available.
    /// Returns the raw value and whether the speed was above the range.
    pub fn raw_speed(speed_kmh: Option<f32>) -> (u16, bool) {
        match speed_kmh {
            Some(v) if v == v => {
                let saturated = v > WHEEL_SPEED_MAX_KMH + 0.005;
                (
                    quantize(v, WHEEL_SPEED_RESOLUTION_KMH, WHEEL_SPEED_RAW_MAX as u32) as u16,
                    saturated,
                )
            }
            _ => (WHEEL_SPEED_NOT_AVAILABLE, false),
        }
    }

    pub fn encode<F: Frame>(&self) -> Option<F> {
        let mut data = [0u8; 8];
        for (j, s) in self.speeds_kmh.iter().enumerate() {
            put_bits(&mut data, Self::STARTS[j], 14, Self::raw_speed(*s).0 as u64);
        }
        seal(ID_WHEEL_SPEED, data, self.counter)
    }

    pub fn decode<F: Frame>(frame: &F) -> Result<Self, DecodeError> {
        let (data, counter) = open(frame, ID_WHEEL_SPEED)?;
        let speeds_kmh = Self::STARTS.map(|s| {
            let raw = get_bits(&data, s, 14) as u16;
            if raw == WHEEL_SPEED_NOT_AVAILABLE {
                None
            } else {
                Some(raw as f32 * WHEEL_SPEED_RESOLUTION_KMH)
            }
        });
        Ok(Self {
            speeds_kmh,
            counter,
        })
    }
}

// ---------------------------------------------------------------------------------------
// RIG_STATUS

/// Run state of the board (4 bits in `RIG_STATUS`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum RigState {
    /// No run: outputs in the safe state (silent, speeds not available).
    #[default]
    Idle = 0,
    /// A run is being stepped at 10 kHz.
    Running = 1,
    /// The run ended at standstill (vehicle speed <= 0.01 m/s).
    Finished = 2,
    /// The run was stopped by command.
    Stopped = 3,
    /// A fault latched during a run: safe state (see [`crate::rig`]).
    Fault = 4,
}

impl RigState {
    pub fn from_raw(raw: u8) -> Option<Self> {
        Some(match raw {
            0 => RigState::Idle,
            1 => RigState::Running,
            2 => RigState::Finished,
            3 => RigState::Stopped,
            4 => RigState::Fault,
            _ => return None,
        })
    }
}

/// What closes the loop (2 bits in `RIG_STATUS`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum RigMode {
    /// The real brake controller on the rig: brake inputs from the ADC channels.
    #[default]
    Rig = 0,
    /// No rig: the simulated brake unit (`hils_brake_unit::ClosedLoop`) closes the loop.
    SelfTest = 1,
}

impl RigMode {
    pub fn from_raw(raw: u8) -> Option<Self> {
        match raw {
            0 => Some(RigMode::Rig),
            1 => Some(RigMode::SelfTest),
            _ => None,
        }
    }
}

/// Result of the last command (2 bits in `RIG_STATUS`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum CommandResult {
    #[default]
    None = 0,
    Accepted = 1,
    Rejected = 2,
}

impl CommandResult {
    pub fn from_raw(raw: u8) -> Option<Self> {
        match raw {
            0 => Some(CommandResult::None),
            1 => Some(CommandResult::Accepted),
            2 => Some(CommandResult::Rejected),
            _ => None,
        }
    }
}

/// `RIG_STATUS` (0x110, every 10 ms).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StatusFrame {
    /// Vehicle (carbody) speed, km/h: 16 bits at 0.01 km/h (0-655.35).
    pub vehicle_speed_kmh: f32,
    /// Deceleration (-a_x), m/s^2: signed 16 bits at 0.001 m/s^2.
    pub deceleration_mps2: f32,
    pub state: RigState,
    pub mode: RigMode,
    pub command_result: CommandResult,
    /// Low 16 bits of [`crate::rig::Faults`].
    pub faults: u16,
    pub counter: u8,
}

impl StatusFrame {
    pub fn encode<F: Frame>(&self) -> Option<F> {
        let mut d = [0u8; 8];
        put_bits(
            &mut d,
            0,
            16,
            quantize(self.vehicle_speed_kmh, 0.01, 0xFFFF) as u64,
        );
        let decel = quantize_signed(self.deceleration_mps2, 0.001, -32768, 32767);
        put_bits(&mut d, 16, 16, decel as i16 as u16 as u64);
        put_bits(&mut d, 32, 4, self.state as u64);
        put_bits(&mut d, 36, 2, self.mode as u64);
        put_bits(&mut d, 38, 2, self.command_result as u64);
        put_bits(&mut d, 40, 16, self.faults as u64);
        seal(ID_STATUS, d, self.counter)
    }

    pub fn decode<F: Frame>(frame: &F) -> Result<Self, DecodeError> {
        let (d, counter) = open(frame, ID_STATUS)?;
        Ok(Self {
            vehicle_speed_kmh: get_bits(&d, 0, 16) as f32 * 0.01,
            deceleration_mps2: (get_bits(&d, 16, 16) as u16 as i16) as f32 * 0.001,
            state: RigState::from_raw(get_bits(&d, 32, 4) as u8)
                .ok_or(DecodeError::BadValue("RigState"))?,
            mode: RigMode::from_raw(get_bits(&d, 36, 2) as u8)
                .ok_or(DecodeError::BadValue("RigMode"))?,
            command_result: CommandResult::from_raw(get_bits(&d, 38, 2) as u8)
                .ok_or(DecodeError::BadValue("CommandResult"))?,
            faults: get_bits(&d, 40, 16) as u16,
            counter,
        })
    }
}

// ---------------------------------------------------------------------------------------
// RIG_DIAG

/// `RIG_DIAG` (0x120, every 100 ms): real-time health. No counter or checksum (all 64 bits
/// carry data; the frame is informative, nothing acts on it).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DiagFrame {
    /// Longest step since the last diagnostic frame, us (16 bits at 0.01 us, 0-655.35).
    pub step_max_us: f32,
    /// Mean step since the last diagnostic frame, us (16 bits at 0.01 us).
    pub step_mean_us: f32,
    /// Overruns since the run started (saturates at 65535).
    pub overruns: u16,
    /// Latched fault of each sensor channel (3 bits each, [`SensorFault::code`]).
    pub sensor_faults: [Option<SensorFault>; 4],
    /// Bus-off events since power-up (saturates at 15).
    pub bus_off_count: u8,
}

impl DiagFrame {
    pub const SENSOR_STARTS: [u32; 4] = [48, 51, 54, 57];

    pub fn encode<F: Frame>(&self) -> Option<F> {
        let mut d = [0u8; 8];
        put_bits(
            &mut d,
            0,
            16,
            quantize(self.step_max_us, 0.01, 0xFFFF) as u64,
        );
        put_bits(
            &mut d,
            16,
            16,
            quantize(self.step_mean_us, 0.01, 0xFFFF) as u64,
        );
        put_bits(&mut d, 32, 16, self.overruns as u64);
        for (j, f) in self.sensor_faults.iter().enumerate() {
            put_bits(
                &mut d,
                Self::SENSOR_STARTS[j],
                3,
                SensorFault::code(*f) as u64,
            );
        }
        put_bits(&mut d, 60, 4, self.bus_off_count.min(15) as u64);
        F::new(StandardId::new(ID_DIAG)?, &d)
    }

    pub fn decode<F: Frame>(frame: &F) -> Result<Self, DecodeError> {
        let Id::Standard(sid) = frame.id() else {
            return Err(DecodeError::NotStandardData);
        };
        if frame.is_remote_frame() {
            return Err(DecodeError::NotStandardData);
        }
        if sid.as_raw() != ID_DIAG {
            return Err(DecodeError::WrongId);
        }
        let bytes = frame.data();
        let d: [u8; 8] = bytes
            .try_into()
            .map_err(|_| DecodeError::WrongLength(bytes.len() as u8))?;
        let mut sensor_faults = [None; 4];
        for (j, s) in Self::SENSOR_STARTS.iter().enumerate() {
            sensor_faults[j] = SensorFault::from_code(get_bits(&d, *s, 3) as u8)
                .ok_or(DecodeError::BadValue("SensorFault"))?;
        }
        Ok(Self {
            step_max_us: get_bits(&d, 0, 16) as f32 * 0.01,
            step_mean_us: get_bits(&d, 16, 16) as f32 * 0.01,
            overruns: get_bits(&d, 32, 16) as u16,
            sensor_faults,
            bus_off_count: get_bits(&d, 60, 4) as u8,
        })
    }
}

// ---------------------------------------------------------------------------------------
// RIG_COMMAND

/// Brake command of the self-test mode (the simulated brake unit's demand).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum BrakeCommand {
    Release,
    Emergency,
    /// Service brake for a deceleration, m/s^2 (0.001 m/s^2 per bit, 0-10).
    Service {
        deceleration_mps2: f32,
    },
}

impl BrakeCommand {
    /// Code of the `cmd` column of the run log (0 release, 1 EB, 2 service).
    pub fn code(self) -> u8 {
        match self {
            BrakeCommand::Release => 0,
            BrakeCommand::Emergency => 1,
            BrakeCommand::Service { .. } => 2,
        }
    }
}

/// A sensor fault to inject (tests the plausibility chain and the safe state on the rig).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum InjectedFault {
    /// The channel reads 0 counts (open wire with the input pull-down).
    Open,
    /// The channel reads full scale (short to the supply).
    Short,
    /// The channel's oversampled reading freezes at its present value.
    Stuck,
    /// The channel reads 10 % of the span above its plausible range.
    OutOfRange,
}

impl InjectedFault {
    fn code(f: Option<InjectedFault>) -> u8 {
        match f {
            None => 0,
            Some(InjectedFault::Open) => 1,
            Some(InjectedFault::Short) => 2,
            Some(InjectedFault::Stuck) => 3,
            Some(InjectedFault::OutOfRange) => 4,
        }
    }
    fn from_code(c: u8) -> Option<Option<InjectedFault>> {
        Some(match c {
            0 => None,
            1 => Some(InjectedFault::Open),
            2 => Some(InjectedFault::Short),
            3 => Some(InjectedFault::Stuck),
            4 => Some(InjectedFault::OutOfRange),
            _ => return None,
        })
    }
}

/// A calibration action on one channel.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Calibration {
    /// Zero: the present reading becomes the offset (no load on the sensor).
    Tare,
    /// Gain, physical unit per ADC count (N or Pa per count).
    SetGain(f32),
    /// Offset, ADC counts at zero load.
    SetOffset(f32),
    /// Channel measures this quantity (resets the calibration to the kind's default);
    /// sent as the float 0.0 (load cell) or 1.0 (pressure transducer).
    SetKind(SensorKind),
}

/// A configuration item.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ConfigItem {
    /// Telemetry every this many plant steps (100 = 100 Hz), 1-10000.
    TelemetryDivider(u16),
    /// Teeth of the simulated axle-speed-sensor wheel, 1-1000.
    Teeth(u16),
}

/// A command received in `RIG_COMMAND` (0x200).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Command {
    /// Opcode 1: start a run from `initial_speed_kmh` (0.01 km/h per bit; the board
    /// accepts 0-163.82, the wheel-speed frame's range). `emergency`: the self-test's
    /// simulated brake unit gets the EB command at t = 0 (the paper's scenario).
    Start {
        mode: RigMode,
        rail: Rail,
        friction: FrictionModel,
        emergency: bool,
        initial_speed_kmh: f32,
    },
    /// Opcode 2: stop the run (outputs to the safe state).
    Stop,
    /// Opcode 3: brake command of the self-test mode.
    Brake(BrakeCommand),
    /// Opcode 4: inject (or with `None` remove) a sensor fault on channel 0-3.
    InjectFault {
        channel: u8,
        fault: Option<InjectedFault>,
    },
    /// Opcode 5: calibrate channel 0-3 (only while no run is active).
    Calibrate { channel: u8, action: Calibration },
    /// Opcode 6: clear latched faults whose cause is gone.
    ClearFaults,
    /// Opcode 7: configuration (only while no run is active).
    Configure(ConfigItem),
}

impl Command {
    /// Start of the paper's scenario in self-test mode: 150 km/h, wet rail, EB at t = 0.
    pub fn paper_self_test(friction: FrictionModel) -> Command {
        Command::Start {
            mode: RigMode::SelfTest,
            rail: Rail::Wet,
            friction,
            emergency: true,
            initial_speed_kmh: 150.0,
        }
    }

    /// The opcode of the command (byte 0 of `RIG_COMMAND`).
    pub fn opcode(&self) -> u8 {
        match self {
            Command::Start { .. } => 1,
            Command::Stop => 2,
            Command::Brake(_) => 3,
            Command::InjectFault { .. } => 4,
            Command::Calibrate { .. } => 5,
            Command::ClearFaults => 6,
            Command::Configure(_) => 7,
        }
    }
}

/// `RIG_COMMAND` frame: a command and its alive counter.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CommandFrame {
    pub command: Command,
    pub counter: u8,
}

fn rail_code(r: Rail) -> u8 {
    match r {
        Rail::Wet => 0,
        Rail::Dry => 1,
    }
}

fn friction_code(f: FrictionModel) -> u8 {
    match f {
        FrictionModel::Variable => 0,
        FrictionModel::Constant => 1,
    }
}

impl CommandFrame {
    pub fn encode<F: Frame>(&self) -> Option<F> {
        let mut d = [0u8; 8];
        let f32_bits = |d: &mut [u8; 8], x: f32| put_bits(d, 24, 32, x.to_bits() as u64);
        match self.command {
            Command::Start {
                mode,
                rail,
                friction,
                emergency,
                initial_speed_kmh,
            } => {
                put_bits(&mut d, 0, 8, 1);
                put_bits(&mut d, 8, 2, mode as u64);
                put_bits(&mut d, 10, 1, rail_code(rail) as u64);
                put_bits(&mut d, 11, 1, friction_code(friction) as u64);
                put_bits(&mut d, 12, 1, emergency as u64);
                put_bits(
                    &mut d,
                    16,
                    16,
                    quantize(initial_speed_kmh, 0.01, 0xFFFF) as u64,
                );
            }
            Command::Stop => put_bits(&mut d, 0, 8, 2),
            Command::Brake(b) => {
                put_bits(&mut d, 0, 8, 3);
                put_bits(&mut d, 8, 2, b.code() as u64);
                if let BrakeCommand::Service { deceleration_mps2 } = b {
                    put_bits(
                        &mut d,
                        16,
                        16,
                        quantize(deceleration_mps2, 0.001, 0xFFFF) as u64,
                    );
                }
            }
            Command::InjectFault { channel, fault } => {
                put_bits(&mut d, 0, 8, 4);
                put_bits(&mut d, 8, 8, channel as u64);
                put_bits(&mut d, 16, 8, InjectedFault::code(fault) as u64);
            }
            Command::Calibrate { channel, action } => {
                put_bits(&mut d, 0, 8, 5);
                put_bits(&mut d, 8, 8, channel as u64);
                match action {
                    Calibration::Tare => put_bits(&mut d, 16, 8, 0),
                    Calibration::SetGain(g) => {
                        put_bits(&mut d, 16, 8, 1);
                        f32_bits(&mut d, g);
                    }
                    Calibration::SetOffset(o) => {
                        put_bits(&mut d, 16, 8, 2);
                        f32_bits(&mut d, o);
                    }
                    Calibration::SetKind(k) => {
                        put_bits(&mut d, 16, 8, 3);
                        f32_bits(&mut d, k as u8 as f32);
                    }
                }
            }
            Command::ClearFaults => put_bits(&mut d, 0, 8, 6),
            Command::Configure(item) => {
                put_bits(&mut d, 0, 8, 7);
                let (code, value) = match item {
                    ConfigItem::TelemetryDivider(v) => (0, v),
                    ConfigItem::Teeth(v) => (1, v),
                };
                put_bits(&mut d, 8, 8, code);
                put_bits(&mut d, 16, 16, value as u64);
            }
        }
        seal(ID_COMMAND, d, self.counter)
    }

    pub fn decode<F: Frame>(frame: &F) -> Result<Self, DecodeError> {
        let (d, counter) = open(frame, ID_COMMAND)?;
        let opcode = get_bits(&d, 0, 8) as u8;
        let channel = || -> Result<u8, DecodeError> {
            let c = get_bits(&d, 8, 8) as u8;
            if (c as usize) < crate::CHANNELS {
                Ok(c)
            } else {
                Err(DecodeError::BadValue("Channel"))
            }
        };
        let f32_value = || f32::from_bits(get_bits(&d, 24, 32) as u32);
        let command = match opcode {
            1 => {
                let mode = RigMode::from_raw(get_bits(&d, 8, 2) as u8)
                    .ok_or(DecodeError::BadValue("StartMode"))?;
                let rail = if get_bits(&d, 10, 1) == 0 {
                    Rail::Wet
                } else {
                    Rail::Dry
                };
                let friction = if get_bits(&d, 11, 1) == 0 {
                    FrictionModel::Variable
                } else {
                    FrictionModel::Constant
                };
                let emergency = get_bits(&d, 12, 1) == 1;
                let initial_speed_kmh = get_bits(&d, 16, 16) as f32 * 0.01;
                Command::Start {
                    mode,
                    rail,
                    friction,
                    emergency,
                    initial_speed_kmh,
                }
            }
            2 => Command::Stop,
            3 => Command::Brake(match get_bits(&d, 8, 2) {
                0 => BrakeCommand::Release,
                1 => BrakeCommand::Emergency,
                2 => {
                    let a = get_bits(&d, 16, 16) as f32 * 0.001;
                    if a > 10.0 {
                        return Err(DecodeError::BadValue("ServiceDeceleration"));
                    }
                    BrakeCommand::Service {
                        deceleration_mps2: a,
                    }
                }
                _ => return Err(DecodeError::BadValue("BrakeDemand")),
            }),
            4 => Command::InjectFault {
                channel: channel()?,
                fault: InjectedFault::from_code(get_bits(&d, 16, 8) as u8)
                    .ok_or(DecodeError::BadValue("InjectedFault"))?,
            },
            5 => {
                let channel = channel()?;
                let action = match get_bits(&d, 16, 8) {
                    0 => Calibration::Tare,
                    1 => {
                        let g = f32_value();
                        if !(g.is_finite() && g != 0.0) {
                            return Err(DecodeError::BadValue("CalibrationValue"));
                        }
                        Calibration::SetGain(g)
                    }
                    2 => {
                        let o = f32_value();
                        if !(o.is_finite() && (0.0..=4095.0).contains(&o)) {
                            return Err(DecodeError::BadValue("CalibrationValue"));
                        }
                        Calibration::SetOffset(o)
                    }
                    3 => Calibration::SetKind(match f32_value() {
                        0.0 => SensorKind::LoadCell,
                        1.0 => SensorKind::PressureTransducer,
                        _ => return Err(DecodeError::BadValue("SensorKind")),
                    }),
                    _ => return Err(DecodeError::BadValue("CalibrationAction")),
                };
                Command::Calibrate { channel, action }
            }
            6 => Command::ClearFaults,
            7 => {
                let v = get_bits(&d, 16, 16) as u16;
                Command::Configure(match get_bits(&d, 8, 8) {
                    0 if (1..=10_000).contains(&v) => ConfigItem::TelemetryDivider(v),
                    1 if (1..=1000).contains(&v) => ConfigItem::Teeth(v),
                    0 | 1 => return Err(DecodeError::BadValue("ConfigValue")),
                    _ => return Err(DecodeError::BadValue("ConfigItem")),
                })
            }
            op => return Err(DecodeError::UnknownOpcode(op)),
        };
        Ok(Self { command, counter })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    type TestFrame = ClassicFrame;

    #[test]
    fn crc4_g704_catalogue_check_value() {
        // Reveng catalogue: CRC-4/G-704 check = 0x7 over "123456789".
        assert_eq!(crc4_g704(b"123456789"), 0x7);
    }

    #[test]
    fn bits_roundtrip_every_position() {
        for start in 0..64 {
            for len in 1..=(64 - start) {
                let mut d = [0xA5u8; 8];
                let before = u64::from_le_bytes(d);
                let v = 0x1234_5678_9ABC_DEF1u64;
                put_bits(&mut d, start, len, v);
                let mask = if len == 64 { u64::MAX } else { (1 << len) - 1 };
                assert_eq!(get_bits(&d, start, len), v & mask);
                // Bits outside the signal are untouched.
                let outside = !(mask << start);
                assert_eq!(u64::from_le_bytes(d) & outside, before & outside);
            }
        }
    }

    #[test]
    fn wheel_speed_roundtrip_within_half_resolution() {
        let speeds = [Some(150.0), Some(0.0), None, Some(163.82)];
        let f: TestFrame = WheelSpeedFrame {
            speeds_kmh: speeds,
            counter: 9,
        }
        .encode()
        .unwrap();
        let back = WheelSpeedFrame::decode(&f).unwrap();
        assert_eq!(back.counter, 9);
        for (a, b) in speeds.iter().zip(back.speeds_kmh.iter()) {
            match (a, b) {
                (Some(a), Some(b)) => assert!((a - b).abs() <= 0.005 + 1e-4, "{a} vs {b}"),
                (None, None) => {}
                _ => panic!("{a:?} vs {b:?}"),
            }
        }
    }

    #[test]
    fn wheel_speed_saturates_and_flags_above_range() {
        assert_eq!(
            WheelSpeedFrame::raw_speed(Some(200.0)),
            (WHEEL_SPEED_RAW_MAX, true)
        );
        assert_eq!(WheelSpeedFrame::raw_speed(Some(-3.0)), (0, false));
        assert_eq!(
            WheelSpeedFrame::raw_speed(Some(f32::NAN)),
            (WHEEL_SPEED_NOT_AVAILABLE, false)
        );
        assert_eq!(WheelSpeedFrame::raw_speed(Some(0.004)), (0, false));
        assert_eq!(WheelSpeedFrame::raw_speed(Some(0.006)), (1, false));
    }

    #[test]
    fn corrupted_frames_are_rejected() {
        let f: TestFrame = WheelSpeedFrame {
            speeds_kmh: [Some(100.0); 4],
            counter: 3,
        }
        .encode()
        .unwrap();
        // Every single-bit error in the 64 bits is detected by the CRC (or changes nothing
        // that is checked: there is no such bit).
        for bit in 0..64 {
            let mut g = f.clone();
            g.data[bit / 8] ^= 1 << (bit % 8);
            assert!(
                matches!(
                    WheelSpeedFrame::decode(&g),
                    Err(DecodeError::Checksum { .. })
                ),
                "bit {bit}"
            );
        }
        // Right bytes, wrong identifier.
        let mut g = f.clone();
        g.id = StandardId::new(ID_STATUS).unwrap().into();
        assert_eq!(WheelSpeedFrame::decode(&g), Err(DecodeError::WrongId));
        assert!(matches!(
            StatusFrame::decode(&g),
            Err(DecodeError::Checksum { .. })
        ));
        let mut g = f.clone();
        g.len = 7;
        assert_eq!(
            WheelSpeedFrame::decode(&g),
            Err(DecodeError::WrongLength(7))
        );
        let mut g = f;
        g.remote = true;
        assert_eq!(
            WheelSpeedFrame::decode(&g),
            Err(DecodeError::NotStandardData)
        );
    }

    #[test]
    fn status_roundtrip_and_limits() {
        let s = StatusFrame {
            vehicle_speed_kmh: 123.45,
            deceleration_mps2: 1.389,
            state: RigState::Fault,
            mode: RigMode::SelfTest,
            command_result: CommandResult::Rejected,
            faults: 0xBEEF,
            counter: 15,
        };
        let f: TestFrame = s.encode().unwrap();
        let b = StatusFrame::decode(&f).unwrap();
        assert!((b.vehicle_speed_kmh - 123.45).abs() < 0.006);
        assert!((b.deceleration_mps2 - 1.389).abs() < 0.0006);
        assert_eq!(
            (b.state, b.mode, b.command_result, b.faults, b.counter),
            (s.state, s.mode, s.command_result, s.faults, 15)
        );
        let neg = StatusFrame {
            deceleration_mps2: -40.0,
            vehicle_speed_kmh: 1e9,
            ..s
        };
        let b = StatusFrame::decode(&neg.encode::<TestFrame>().unwrap()).unwrap();
        assert_eq!(b.deceleration_mps2, -32.768);
        assert!((b.vehicle_speed_kmh - 655.35).abs() < 0.01);
    }

    #[test]
    fn every_command_roundtrips() {
        let cmds = [
            Command::Start {
                mode: RigMode::SelfTest,
                rail: Rail::Dry,
                friction: FrictionModel::Constant,
                emergency: true,
                initial_speed_kmh: 150.0,
            },
            Command::Start {
                mode: RigMode::Rig,
                rail: Rail::Wet,
                friction: FrictionModel::Variable,
                emergency: false,
                initial_speed_kmh: 80.25,
            },
            Command::Stop,
            Command::Brake(BrakeCommand::Release),
            Command::Brake(BrakeCommand::Emergency),
            Command::Brake(BrakeCommand::Service {
                deceleration_mps2: 0.75,
            }),
            Command::InjectFault {
                channel: 3,
                fault: Some(InjectedFault::Stuck),
            },
            Command::InjectFault {
                channel: 0,
                fault: None,
            },
            Command::Calibrate {
                channel: 2,
                action: Calibration::Tare,
            },
            Command::Calibrate {
                channel: 1,
                action: Calibration::SetGain(12.5),
            },
            Command::Calibrate {
                channel: 1,
                action: Calibration::SetOffset(410.25),
            },
            Command::Calibrate {
                channel: 0,
                action: Calibration::SetKind(SensorKind::PressureTransducer),
            },
            Command::ClearFaults,
            Command::Configure(ConfigItem::TelemetryDivider(100)),
            Command::Configure(ConfigItem::Teeth(90)),
        ];
        for (i, c) in cmds.iter().enumerate() {
            let frame: TestFrame = CommandFrame {
                command: *c,
                counter: i as u8,
            }
            .encode()
            .unwrap();
            let back = CommandFrame::decode(&frame).unwrap();
            assert_eq!(back.counter, (i as u8) & 0x0F);
            match (c, back.command) {
                (
                    Command::Start {
                        initial_speed_kmh: a,
                        mode,
                        rail,
                        friction,
                        emergency,
                    },
                    Command::Start {
                        initial_speed_kmh: b,
                        mode: m2,
                        rail: r2,
                        friction: f2,
                        emergency: e2,
                    },
                ) => {
                    assert!((a - b).abs() < 0.006);
                    assert_eq!((*mode, *rail, *friction, *emergency), (m2, r2, f2, e2));
                }
                (
                    Command::Brake(BrakeCommand::Service {
                        deceleration_mps2: a,
                    }),
                    Command::Brake(BrakeCommand::Service {
                        deceleration_mps2: b,
                    }),
                ) => assert!((a - b).abs() < 0.0006),
                (a, b) => assert_eq!(*a, b),
            }
        }
    }

    #[test]
    fn bad_commands_are_rejected_with_the_field() {
        let raw = |bytes: [u8; 7]| -> TestFrame {
            let mut d = [0u8; 8];
            d[..7].copy_from_slice(&bytes);
            seal(ID_COMMAND, d, 1).unwrap()
        };
        assert_eq!(
            CommandFrame::decode(&raw([0, 0, 0, 0, 0, 0, 0])),
            Err(DecodeError::UnknownOpcode(0))
        );
        assert_eq!(
            CommandFrame::decode(&raw([99, 0, 0, 0, 0, 0, 0])),
            Err(DecodeError::UnknownOpcode(99))
        );
        assert_eq!(
            CommandFrame::decode(&raw([4, 4, 1, 0, 0, 0, 0])),
            Err(DecodeError::BadValue("Channel"))
        );
        assert_eq!(
            CommandFrame::decode(&raw([4, 0, 9, 0, 0, 0, 0])),
            Err(DecodeError::BadValue("InjectedFault"))
        );
        assert_eq!(
            CommandFrame::decode(&raw([1, 3, 0, 0, 0, 0, 0])),
            Err(DecodeError::BadValue("StartMode"))
        );
        let nan = f32::NAN.to_bits().to_le_bytes();
        assert_eq!(
            CommandFrame::decode(&raw([5, 0, 1, nan[0], nan[1], nan[2], nan[3]])),
            Err(DecodeError::BadValue("CalibrationValue"))
        );
        assert_eq!(
            CommandFrame::decode(&raw([7, 0, 0, 0, 0, 0, 0])),
            Err(DecodeError::BadValue("ConfigValue"))
        );
        assert_eq!(
            CommandFrame::decode(&raw([7, 5, 1, 0, 0, 0, 0])),
            Err(DecodeError::BadValue("ConfigItem"))
        );
    }

    #[test]
    fn diag_roundtrip() {
        let d = DiagFrame {
            step_max_us: 41.27,
            step_mean_us: 23.5,
            overruns: 7,
            sensor_faults: [
                None,
                Some(SensorFault::Open),
                Some(SensorFault::Stuck),
                Some(SensorFault::OutOfRange),
            ],
            bus_off_count: 20,
        };
        let b = DiagFrame::decode(&d.encode::<TestFrame>().unwrap()).unwrap();
        assert!((b.step_max_us - 41.27).abs() < 0.006);
        assert!((b.step_mean_us - 23.5).abs() < 0.006);
        assert_eq!(b.overruns, 7);
        assert_eq!(b.sensor_faults, d.sensor_faults);
        assert_eq!(b.bus_off_count, 15);
    }

    proptest::proptest! {
        /// Any 8 bytes under any identifier: decoding never panics, and a frame that
        /// decodes re-encodes to the same bytes (for frames with a checksum).
        #[test]
        fn decoding_arbitrary_frames_never_panics(
            id in 0u16..0x800, bytes in proptest::collection::vec(proptest::num::u8::ANY, 0..9), remote: bool
        ) {
            let mut f = TestFrame::new(StandardId::new(id).unwrap(), &bytes).unwrap();
            f.remote = remote;
            let _ = WheelSpeedFrame::decode(&f);
            let _ = StatusFrame::decode(&f);
            let _ = DiagFrame::decode(&f);
            if let Ok(c) = CommandFrame::decode(&f) {
                let again: TestFrame = c.encode().unwrap();
                let c2 = CommandFrame::decode(&again).unwrap();
                proptest::prop_assert_eq!(c.counter, c2.counter);
            }
            if let Ok(w) = WheelSpeedFrame::decode(&f) {
                let again: TestFrame = w.encode().unwrap();
                proptest::prop_assert_eq!(again.data, f.data);
            }
        }

        /// Any float speed (NaN, inf, negative, huge) encodes to a valid raw value.
        #[test]
        fn any_speed_encodes(v in proptest::num::f32::ANY) {
            let (raw, _) = WheelSpeedFrame::raw_speed(Some(v));
            proptest::prop_assert!(raw <= WHEEL_SPEED_NOT_AVAILABLE);
            if v.is_finite() && (0.0..=WHEEL_SPEED_MAX_KMH).contains(&v) {
                proptest::prop_assert!((raw as f32 * 0.01 - v).abs() <= 0.0051);
            }
        }
    }
}
