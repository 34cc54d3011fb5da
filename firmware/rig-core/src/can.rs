//! The CAN frame codec of the rig interface board (classic CAN, 11-bit identifiers,
//! 8 data bytes, Intel byte order). `hils.dbc` beside this crate describes the same frames;
//! a host test decodes frames made here with an independent DBC parser and checks every
//! signal both ways.
//!
//! | id | name | dir | period | content |
//! |---|---|---|---|---|
//! | 0x100 | `RIG_WHEEL_SPEED_12` | out | 1 ms | wheel speeds of wheelsets 1, 2 (16 bit, 0.01 km/h), alive counter, checksum |
//! | 0x101 | `RIG_WHEEL_SPEED_34` | out | 1 ms | wheel speeds of wheelsets 3, 4 (16 bit, 0.01 km/h), alive counter, checksum |
//! | 0x102 | `RIG_BRAKE_DEMAND` | out | 10 ms and on change (optional) | EB loop closed, service deceleration: the PWM's demand as a frame |
//! | 0x110 | `RIG_STATUS` | out | 10 ms | vehicle speed, deceleration, state, mode, command result, fault flags, counter, checksum |
//! | 0x120 | `RIG_DIAG` | out | 100 ms | step time max/mean, overruns, sensor fault kinds, bus-off count |
//! | 0x200 | `RIG_COMMAND` | in | on demand | multiplexed by opcode: start, stop, brake, fault injection, calibration, clear faults, configure, track zone, track commit/clear, vehicle; counter, checksum |
//!
//! **Tracks and vehicles by command** (issue 13 item 5). A track (a base surface and up to
//! [`hils_plant::track::MAX_ZONES`] zones, `hils_plant::track`) reaches the board as one
//! `TrackZone` frame per zone (index, start and end at 0.1 m over 0-104 857.5 m, surface
//! code) and a `Track` commit frame (base surface, zone count) that checks the zones
//! (all received, ordered, disjoint) and keeps the track; `Track` clear forgets it. A
//! `Start` with `StartTrack` = 1 runs on the kept track (the rail bit is then unused). A
//! `Vehicle` frame sets one `[vehicle]` value (IEEE float) of the board's plant for the
//! following starts, or resets the default vehicle. Surface codes: 0 dry, 1 wet, 2 low,
//! 3 very low (4-7 undefined: refused).
//!
//! **Checksum.** The high nibble of byte 7 is a CRC-4/G-704 (polynomial x^4 + x + 1,
//! reflected, init 0, no final xor) over the two bytes of the identifier (little endian),
//! data bytes 0-6 and the low nibble of byte 7 (the alive counter). Including the
//! identifier means a frame with the right bytes under the wrong identifier is rejected,
//! as in AUTOSAR E2E's data id. The **alive counter** (low nibble of byte 7) counts 0-15
//! and wraps, one step per frame sent.
//!
//! **Wheel-speed range.** Two frames of two wheelsets each (sent in the same tick with the
//! same alive counter, so a receiver can pair them), 16 bits per speed: 0.01 km/h resolution
//! over 0-655.34 km/h, beyond any vehicle or WSP test (four 14-bit speeds in one frame
//! stopped at 163.82 km/h). The raw value 0xFFFF means "not available" (safe state, see
//! [`crate::rig`]); speeds above the range are sent as 655.34 km/h (0xFFFE) and flagged
//! ([`crate::rig::Faults::SPEED_SATURATED`]). Byte 4 carries the two wheelsets' valve
//! inputs as the step sampled them (`Dump1`, `Hold1`, `Dump2`, `Hold2`, 2 bits each: 0 off,
//! 1 energised, 3 not wired; [`crate::valves`]); bytes 5-6 are reserved (0).

use embedded_can::{Frame, Id, StandardId};
use hils_plant::{FrictionModel, Rail, Surface, Zone};

use num_enum::{IntoPrimitive, TryFromPrimitive};

use crate::Code;
use crate::arming::Disarm;

use crate::controller_io::IoItem;
pub use crate::sensor::InjectedFault;
use crate::sensor::{SensorFault, SensorKind};
use crate::valves::ValveStates;

/// Identifier of `RIG_WHEEL_SPEED_12` (wheelsets 1 and 2).
pub const ID_WHEEL_SPEED_12: u16 = 0x100;
/// Identifier of `RIG_WHEEL_SPEED_34` (wheelsets 3 and 4).
pub const ID_WHEEL_SPEED_34: u16 = 0x101;
/// The wheel-speed identifiers by pair of wheelsets ([`WheelSpeedFrame::pair`]).
pub const ID_WHEEL_SPEEDS: [u16; 2] = [ID_WHEEL_SPEED_12, ID_WHEEL_SPEED_34];
/// Identifier of `RIG_BRAKE_DEMAND` (board -> controller, optional).
pub const ID_BRAKE_DEMAND: u16 = 0x102;
/// Identifier of `RIG_STATUS`.
pub const ID_STATUS: u16 = 0x110;
/// Identifier of `RIG_DIAG`.
pub const ID_DIAG: u16 = 0x120;
/// `RIG_HEALTH` (board -> bus): the board's own health (stack, receive losses, arming), 100 ms.
pub const ID_HEALTH: u16 = 0x121;
/// Identifier of `RIG_COMMAND`.
pub const ID_COMMAND: u16 = 0x200;

/// Wheel-speed resolution, km/h per bit.
pub const WHEEL_SPEED_RESOLUTION_KMH: f32 = 0.01;
/// Raw wheel speed meaning "not available".
pub const WHEEL_SPEED_NOT_AVAILABLE: u16 = 0xFFFF;
/// Largest raw wheel speed (655.34 km/h).
pub const WHEEL_SPEED_RAW_MAX: u16 = 0xFFFE;
/// Highest wheel speed the frame carries, km/h.
pub const WHEEL_SPEED_MAX_KMH: f32 = WHEEL_SPEED_RAW_MAX as f32 * WHEEL_SPEED_RESOLUTION_KMH;

/// A plain classic CAN frame implementing [`embedded_can::Frame`] (for targets and tools
/// without a HAL, and the tests).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ClassicFrame {
    /// Standard or extended identifier.
    pub id: Id,
    /// Data bytes; the first `len` are used.
    pub data: [u8; 8],
    /// Data length code, 0-8 bytes.
    pub len: u8,
    /// A remote frame (requests data, carries none).
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
    Checksum {
        /// The checksum computed from the frame.
        expected: u8,
        /// The checksum the frame carries.
        received: u8,
    },
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

/// CRC-4/G-704 (reflected, polynomial x^4 + x + 1 as 0x0C) of `bits` more bits of `crc`,
/// one bit at a time: the definition [`CRC4_BYTE`] is built from.
const fn crc4_bits(mut crc: u8, bits: u32) -> u8 {
    let mut k = 0;
    while k < bits {
        crc = if crc & 1 != 0 {
            (crc >> 1) ^ 0x0C
        } else {
            crc >> 1
        };
        k += 1;
    }
    crc
}

/// The CRC-4 register after a whole byte, indexed by `register ^ byte` (the register is
/// 4 bits, so every index is a byte): one lookup a byte instead of eight shifts. The step
/// seals a frame every 0.5 ms on average; bit by bit a frame's checksum cost ~600
/// instructions on the Cortex-M4F (`hils target-cost --rig`). 256 B in flash.
static CRC4_BYTE: [u8; 256] = {
    let mut table = [0u8; 256];
    let mut i = 0;
    while i < 256 {
        table[i] = crc4_bits(i as u8, 8);
        i += 1;
    }
    table
};

/// Feeds whole bytes into a CRC-4/G-704 register.
#[inline]
fn crc4_bytes(mut crc: u8, bytes: &[u8]) -> u8 {
    for &b in bytes {
        crc = CRC4_BYTE[(crc ^ b) as usize];
    }
    crc
}

/// CRC-4/G-704 over the identifier, data bytes 0-6 and the counter nibble (see module doc).
pub fn checksum(id: u16, data: &[u8; 8]) -> u8 {
    let crc = crc4_bytes(0, &id.to_le_bytes());
    let crc = crc4_bytes(crc, &data[..7]);
    crc4_bits(crc ^ (data[7] & 0x0F), 4) & 0x0F
}

/// Plain CRC-4/G-704 of a byte string (the catalogue check: "123456789" -> 0x7).
pub fn crc4_g704(bytes: &[u8]) -> u8 {
    crc4_bytes(0, bytes) & 0x0F
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
    sealed::COUNTER.put_raw(&mut data, (counter & 0x0F) as u64);
    let crc = checksum(id, &data);
    sealed::CHECKSUM.put_raw(&mut data, crc as u64);
    F::new(StandardId::new(id)?, &data)
}

/// Checks identifier, kind and length; returns the data.
fn data_of<F: Frame>(frame: &F, id: u16) -> Result<[u8; 8], DecodeError> {
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
    bytes
        .try_into()
        .map_err(|_| DecodeError::WrongLength(bytes.len() as u8))
}

/// Checks identifier, kind, length and checksum; returns the data and the counter.
fn open<F: Frame>(frame: &F, id: u16) -> Result<([u8; 8], u8), DecodeError> {
    let data = data_of(frame, id)?;
    let expected = checksum(id, &data);
    let received = sealed::CHECKSUM.get_raw(&data) as u8;
    if expected != received {
        return Err(DecodeError::Checksum { expected, received });
    }
    Ok((data, sealed::COUNTER.get_raw(&data) as u8))
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

/// An enum signal's value (derived `u8` conversion); an undefined code is an error naming
/// the signal.
fn decode_enum<T: TryFrom<u8>>(d: &[u8; 8], signal: Signal) -> Result<T, DecodeError> {
    T::try_from(signal.get_raw(d) as u8).map_err(|_| DecodeError::BadValue(signal.name))
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
// Signal layouts: one table per frame, the same data for encode, decode and the DBC check.

/// One signal of a frame (Intel byte order, bit 0 = LSB of byte 0): `len` bits from
/// `start`; physical value = raw x `scale` + `offset`. `hils.dbc` describes the same
/// signals under the same names (a test compares every field).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Signal {
    /// The signal's name in `hils.dbc`.
    pub name: &'static str,
    /// Start bit.
    pub start: u32,
    /// Length, bits.
    pub len: u32,
    /// Physical units per bit.
    pub scale: f32,
    /// Physical value at raw 0.
    pub offset: f32,
    /// Two's complement raw value.
    pub signed: bool,
}

impl Signal {
    const fn raw(name: &'static str, start: u32, len: u32) -> Self {
        Self::scaled(name, start, len, 1.0)
    }

    const fn scaled(name: &'static str, start: u32, len: u32, scale: f32) -> Self {
        Self {
            name,
            start,
            len,
            scale,
            offset: 0.0,
            signed: false,
        }
    }

    const fn signed(self) -> Self {
        Self {
            signed: true,
            ..self
        }
    }

    /// The raw bits of the signal.
    pub fn get_raw(&self, data: &[u8; 8]) -> u64 {
        get_bits(data, self.start, self.len)
    }

    /// Writes raw bits (bits above `len` are dropped).
    pub fn put_raw(&self, data: &mut [u8; 8], raw: u64) {
        put_bits(data, self.start, self.len, raw);
    }

    /// The physical value.
    pub fn get(&self, data: &[u8; 8]) -> f32 {
        let raw = self.get_raw(data);
        let x = if self.signed {
            let shift = 64 - self.len;
            (((raw << shift) as i64) >> shift) as f32
        } else {
            raw as f32
        };
        x * self.scale + self.offset
    }

    /// Writes a physical value, rounded to the nearest step and limited to the signal's
    /// range (NaN -> raw 0).
    pub fn put(&self, data: &mut [u8; 8], value: f32) {
        let v = value - self.offset;
        let raw = if self.signed {
            let max = (1i32 << (self.len - 1)) - 1;
            quantize_signed(v, self.scale, -max - 1, max) as i64 as u64
        } else {
            quantize(v, self.scale, self.max_raw()) as u64
        };
        self.put_raw(data, raw);
    }

    /// The largest raw value of an unsigned signal.
    pub const fn max_raw(&self) -> u32 {
        if self.len >= 32 {
            u32::MAX
        } else {
            (1u32 << self.len) - 1
        }
    }
}

/// The alive counter and checksum of the sealed frames (same bits in each).
pub mod sealed {
    use super::Signal;
    /// Alive counter, low nibble of byte 7.
    pub const COUNTER: Signal = Signal::raw("Alive", 56, 4);
    /// CRC-4, high nibble of byte 7.
    pub const CHECKSUM: Signal = Signal::raw("Checksum", 60, 4);
}

/// `RIG_WHEEL_SPEED_12` (0x100) and `RIG_WHEEL_SPEED_34` (0x101).
pub mod wheel_speed {
    use super::Signal;
    /// `WheelSpeed1..4`, km/h (16 bits at 0.01; 0xFFFF = not available), by frame.
    pub const SPEEDS: [[Signal; 2]; 2] = [
        [
            Signal::scaled("WheelSpeed1", 0, 16, 0.01),
            Signal::scaled("WheelSpeed2", 16, 16, 0.01),
        ],
        [
            Signal::scaled("WheelSpeed3", 0, 16, 0.01),
            Signal::scaled("WheelSpeed4", 16, 16, 0.01),
        ],
    ];
    /// `Dump1..4`, `Hold1..4`: the valve inputs of the frame's wheelsets, `[dump, hold]`
    /// per wheelset (2 bits: 0 off, 1 energised, 3 not wired).
    pub const VALVES: [[[Signal; 2]; 2]; 2] = [
        [
            [Signal::raw("Dump1", 32, 2), Signal::raw("Hold1", 34, 2)],
            [Signal::raw("Dump2", 36, 2), Signal::raw("Hold2", 38, 2)],
        ],
        [
            [Signal::raw("Dump3", 32, 2), Signal::raw("Hold3", 34, 2)],
            [Signal::raw("Dump4", 36, 2), Signal::raw("Hold4", 38, 2)],
        ],
    ];
    /// Every signal of `RIG_WHEEL_SPEED_12`.
    pub const ALL_12: [Signal; 8] = [
        SPEEDS[0][0],
        SPEEDS[0][1],
        VALVES[0][0][0],
        VALVES[0][0][1],
        VALVES[0][1][0],
        VALVES[0][1][1],
        Signal::raw("WheelSpeed12Alive", 56, 4),
        Signal::raw("WheelSpeed12Checksum", 60, 4),
    ];
    /// Every signal of `RIG_WHEEL_SPEED_34`.
    pub const ALL_34: [Signal; 8] = [
        SPEEDS[1][0],
        SPEEDS[1][1],
        VALVES[1][0][0],
        VALVES[1][0][1],
        VALVES[1][1][0],
        VALVES[1][1][1],
        Signal::raw("WheelSpeed34Alive", 56, 4),
        Signal::raw("WheelSpeed34Checksum", 60, 4),
    ];
}

/// `RIG_BRAKE_DEMAND` (0x102).
pub mod brake_demand {
    use super::Signal;
    /// 1: the EB loop is closed (no emergency brake); 0: open (emergency brake).
    pub const EB_LOOP_CLOSED: Signal = Signal::raw("EbLoopClosed", 0, 1);
    /// Service deceleration demanded, m/s^2 (0.001 m/s^2 per bit).
    pub const SERVICE: Signal = Signal::scaled("ServiceDemand", 16, 16, 0.001);
    /// Every signal of the frame.
    pub const ALL: [Signal; 4] = [
        EB_LOOP_CLOSED,
        SERVICE,
        Signal::raw("DemandAlive", 56, 4),
        Signal::raw("DemandChecksum", 60, 4),
    ];
}

/// `RIG_STATUS` (0x110).
pub mod status {
    use super::Signal;
    /// Vehicle speed, km/h.
    pub const VEHICLE_SPEED: Signal = Signal::scaled("VehicleSpeed", 0, 16, 0.01);
    /// Deceleration, m/s^2 (signed).
    pub const DECELERATION: Signal = Signal::scaled("Deceleration", 16, 16, 0.001).signed();
    /// [`super::RigState`].
    pub const STATE: Signal = Signal::raw("RigState", 32, 4);
    /// [`super::RigMode`].
    pub const MODE: Signal = Signal::raw("RigMode", 36, 2);
    /// [`super::CommandResult`].
    pub const COMMAND_RESULT: Signal = Signal::raw("CommandResult", 38, 2);
    /// Low 16 bits of the fault flags.
    pub const FAULTS: Signal = Signal::raw("FaultFlags", 40, 16);
    /// Every signal of the frame.
    pub const ALL: [Signal; 8] = [
        VEHICLE_SPEED,
        DECELERATION,
        STATE,
        MODE,
        COMMAND_RESULT,
        FAULTS,
        Signal::raw("StatusAlive", 56, 4),
        Signal::raw("StatusChecksum", 60, 4),
    ];
}

/// `RIG_DIAG` (0x120).
pub mod diag {
    use super::Signal;
    /// Longest step, us.
    pub const STEP_MAX: Signal = Signal::scaled("StepTimeMax", 0, 16, 0.01);
    /// Mean step, us.
    pub const STEP_MEAN: Signal = Signal::scaled("StepTimeMean", 16, 16, 0.01);
    /// Overruns.
    pub const OVERRUNS: Signal = Signal::raw("Overruns", 32, 16);
    /// Sensor fault code of channel 1..4.
    pub const SENSOR_FAULTS: [Signal; 4] = [
        Signal::raw("SensorFault1", 48, 3),
        Signal::raw("SensorFault2", 51, 3),
        Signal::raw("SensorFault3", 54, 3),
        Signal::raw("SensorFault4", 57, 3),
    ];
    /// Bus-off events (saturating).
    pub const BUS_OFF_COUNT: Signal = Signal::raw("BusOffCount", 60, 4);
    /// Every signal of the frame.
    pub const ALL: [Signal; 8] = [
        STEP_MAX,
        STEP_MEAN,
        OVERRUNS,
        SENSOR_FAULTS[0],
        SENSOR_FAULTS[1],
        SENSOR_FAULTS[2],
        SENSOR_FAULTS[3],
        BUS_OFF_COUNT,
    ];
}

/// `RIG_HEALTH` (0x121).
pub mod health {
    use super::Signal;
    /// Stack high-water mark: the most stack ever used since power-up, bytes (4 B per bit).
    pub const STACK_PEAK: Signal = Signal::scaled("StackPeak", 0, 16, 4.0);
    /// `RIG_COMMAND` frames lost in reception since power-up, saturating; a lower bound:
    /// FDCAN RF0L is a flag, so losses before the interrupt clears it count once.
    pub const RX_LOST: Signal = Signal::raw("RxLost", 16, 8);
    /// ADC ring restarts after a stall (no progress, overrun) since power-up, saturating.
    pub const ADC_RESTARTS: Signal = Signal::raw("AdcRestarts", 24, 8);
    /// 1: armed for a controller ([`crate::arming`]).
    pub const ARMED: Signal = Signal::raw("Armed", 32, 1);
    /// Why disarmed ([`crate::arming::Disarm`] code; 0 while armed).
    pub const DISARM_CAUSE: Signal = Signal::raw("DisarmCause", 33, 3);
    /// Consecutive fault resets before this start (saturating at 15; 0 after a clean one).
    pub const FAULT_RESETS: Signal = Signal::raw("FaultResets", 36, 4);
    /// The stack's size, bytes (4 B per bit): [`STACK_PEAK`] is judged against it.
    pub const STACK_SIZE: Signal = Signal::scaled("StackSize", 40, 16, 4.0);
    /// Every signal of the frame.
    pub const ALL: [Signal; 9] = [
        STACK_PEAK,
        RX_LOST,
        ADC_RESTARTS,
        ARMED,
        DISARM_CAUSE,
        FAULT_RESETS,
        STACK_SIZE,
        Signal::raw("HealthAlive", 56, 4),
        Signal::raw("HealthChecksum", 60, 4),
    ];
}

/// `RIG_COMMAND` (0x200): the multiplexor `Opcode` and each opcode's signals.
pub mod command {
    use super::Signal;
    /// The multiplexor ([`super::Opcode`]).
    pub const OPCODE: Signal = Signal::raw("Opcode", 0, 8);
    /// Start: [`super::RigMode`].
    pub const START_MODE: Signal = Signal::raw("StartMode", 8, 2);
    /// Start: 0 wet, 1 dry.
    pub const START_RAIL: Signal = Signal::raw("StartRail", 10, 1);
    /// Start: 0 variable, 1 constant friction.
    pub const START_FRICTION: Signal = Signal::raw("StartFriction", 11, 1);
    /// Start: EB at t = 0 (self-test).
    pub const START_EMERGENCY: Signal = Signal::raw("StartEmergency", 12, 1);
    /// Start: initial speed, km/h.
    pub const START_SPEED: Signal = Signal::scaled("StartSpeed", 16, 16, 0.01);
    /// Brake: [`super::brake_signal_code`].
    pub const BRAKE_DEMAND: Signal = Signal::raw("BrakeDemand", 8, 2);
    /// Brake: service deceleration, m/s^2.
    pub const SERVICE_DECELERATION: Signal = Signal::scaled("ServiceDeceleration", 16, 16, 0.001);
    /// Fault injection: channel 0-3.
    pub const FAULT_CHANNEL: Signal = Signal::raw("FaultChannel", 8, 8);
    /// Fault injection: [`crate::Code::code`].
    pub const INJECTED_FAULT: Signal = Signal::raw("InjectedFault", 16, 8);
    /// Calibration: channel 0-3.
    pub const CAL_CHANNEL: Signal = Signal::raw("CalChannel", 8, 8);
    /// Calibration: action (0 tare, 1 gain, 2 offset, 3 kind).
    pub const CAL_ACTION: Signal = Signal::raw("CalAction", 16, 8);
    /// Calibration: value, IEEE f32 bits.
    pub const CAL_VALUE: Signal = Signal::raw("CalValue", 24, 32).signed();
    /// Configuration: item (0 telemetry divider, 1 teeth).
    pub const CONFIG_ITEM: Signal = Signal::raw("ConfigItem", 8, 8);
    /// Configuration: value.
    pub const CONFIG_VALUE: Signal = Signal::raw("ConfigValue", 16, 16);
    /// Start: 1 = run on the track kept by `Track` commit (`StartRail` unused).
    pub const START_TRACK: Signal = Signal::raw("StartTrack", 13, 1);
    /// Start: the setup digest ([`crate::digest::setup_digest`]) of the track and vehicle
    /// the host sent; the board rejects the start when its own differs.
    pub const START_DIGEST: Signal = Signal::raw("StartDigest", 32, 16);
    /// Brake: service brake step (BrakeDemand 3), 1-based.
    pub const SERVICE_STEP: Signal = Signal::raw("ServiceStep", 32, 8);
    /// Track zone: index 0-31 (the board keeps 0-15).
    pub const ZONE_INDEX: Signal = Signal::raw("ZoneIndex", 8, 5);
    /// Track zone: surface code ([`super::surface_code`]).
    pub const ZONE_SURFACE: Signal = Signal::raw("ZoneSurface", 13, 3);
    /// Track zone: start, m (0.1 m per bit).
    pub const ZONE_START: Signal = Signal::scaled("ZoneStart", 16, 20, 0.1);
    /// Track zone: end (exclusive), m (0.1 m per bit).
    pub const ZONE_END: Signal = Signal::scaled("ZoneEnd", 36, 20, 0.1);
    /// Track: 0 clear, 1 commit.
    pub const TRACK_ACTION: Signal = Signal::raw("TrackAction", 8, 1);
    /// Track commit: base surface code.
    pub const TRACK_BASE: Signal = Signal::raw("TrackBase", 9, 3);
    /// Track commit: number of zones (0-31; the board keeps up to 16).
    pub const TRACK_ZONES: Signal = Signal::raw("TrackZones", 16, 5);
    /// Vehicle: which value ([`super::VehicleKey`]).
    pub const VEHICLE_KEY: Signal = Signal::raw("VehicleKey", 8, 8);
    /// Vehicle: the value, IEEE f32 bits (SI units of the `[vehicle]` key).
    pub const VEHICLE_VALUE: Signal = Signal::raw("VehicleValue", 24, 32).signed();
    /// Every signal of the frame, multiplexed ones included.
    pub const ALL: [Signal; 29] = [
        OPCODE,
        START_MODE,
        START_RAIL,
        START_FRICTION,
        START_EMERGENCY,
        START_SPEED,
        BRAKE_DEMAND,
        SERVICE_DECELERATION,
        FAULT_CHANNEL,
        INJECTED_FAULT,
        CAL_CHANNEL,
        CAL_ACTION,
        CAL_VALUE,
        CONFIG_ITEM,
        CONFIG_VALUE,
        START_TRACK,
        START_DIGEST,
        SERVICE_STEP,
        ZONE_INDEX,
        ZONE_SURFACE,
        ZONE_START,
        ZONE_END,
        TRACK_ACTION,
        TRACK_BASE,
        TRACK_ZONES,
        VEHICLE_KEY,
        VEHICLE_VALUE,
        Signal::raw("CommandAlive", 56, 4),
        Signal::raw("CommandChecksum", 60, 4),
    ];
}

/// Every frame's identifier and signal table (what `hils.dbc` must describe).
pub const FRAMES: [(u16, &[Signal]); 7] = [
    (ID_WHEEL_SPEED_12, &wheel_speed::ALL_12),
    (ID_WHEEL_SPEED_34, &wheel_speed::ALL_34),
    (ID_BRAKE_DEMAND, &brake_demand::ALL),
    (ID_STATUS, &status::ALL),
    (ID_DIAG, &diag::ALL),
    (ID_HEALTH, &health::ALL),
    (ID_COMMAND, &command::ALL),
];

/// The opcodes of `RIG_COMMAND` (byte 0), in one place: 1-12 in declaration order.
#[derive(Clone, Copy, Debug, PartialEq, Eq, IntoPrimitive, TryFromPrimitive)]
#[repr(u8)]
pub enum Opcode {
    /// [`Command::Start`].
    Start = 1,
    /// [`Command::Stop`].
    Stop,
    /// [`Command::Brake`].
    Brake,
    /// [`Command::InjectFault`].
    InjectFault,
    /// [`Command::Calibrate`].
    Calibrate,
    /// [`Command::ClearFaults`].
    ClearFaults,
    /// [`Command::Configure`].
    Configure,
    /// [`Command::TrackZone`].
    TrackZone,
    /// [`Command::Track`].
    Track,
    /// [`Command::Vehicle`].
    Vehicle,
    /// [`Command::Arm`].
    Arm,
    /// [`Command::Disarm`].
    Disarm,
}

/// The code of a surface in `RIG_COMMAND` and telemetry: 0 dry, 1 wet, 2 low, 3 very low
/// (the order of [`Surface::ALL`]).
pub fn surface_code(s: Surface) -> u8 {
    s as u8
}

/// The surface of a code (`None` for 4-7).
pub fn surface_of_code(code: u8) -> Option<Surface> {
    Surface::ALL.get(code as usize).copied()
}

/// Zone positions per bit in `TrackZone`, m.
pub const ZONE_RESOLUTION_M: f64 = 0.1;
/// Farthest zone bound `TrackZone` carries, m.
pub const ZONE_MAX_M: f64 = ((1u32 << 20) - 1) as f64 * ZONE_RESOLUTION_M;

/// Which `[vehicle]` value a `Vehicle` command sets (`VehicleKey`; 255 = back to the
/// default vehicle). The keys a WSP programme's vehicle variants may change.
#[derive(Clone, Copy, Debug, PartialEq, Eq, IntoPrimitive, TryFromPrimitive)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum VehicleKey {
    /// `carbody_mass`, kg.
    CarbodyMass = 0,
    /// `carbody_pitch_inertia`, kg m^2.
    CarbodyPitchInertia,
    /// `bogie_mass`, kg.
    BogieMass,
    /// `wheelset_mass`, kg.
    WheelsetMass,
    /// `wheel_radius`, m.
    WheelRadius,
    /// Every value back to the default vehicle (the value is unused).
    Default = 255,
}

impl VehicleKey {
    /// The `[vehicle]` key of the parameter file (and of a programme's vehicle variant).
    pub fn name(self) -> &'static str {
        match self {
            VehicleKey::CarbodyMass => "carbody_mass",
            VehicleKey::CarbodyPitchInertia => "carbody_pitch_inertia",
            VehicleKey::BogieMass => "bogie_mass",
            VehicleKey::WheelsetMass => "wheelset_mass",
            VehicleKey::WheelRadius => "wheel_radius",
            VehicleKey::Default => "default",
        }
    }

    /// The keys that set a value (all but `Default`).
    pub const VALUES: [VehicleKey; 5] = [
        VehicleKey::CarbodyMass,
        VehicleKey::CarbodyPitchInertia,
        VehicleKey::BogieMass,
        VehicleKey::WheelsetMass,
        VehicleKey::WheelRadius,
    ];

    /// This key's field of `v` (None for `Default`).
    pub fn field(self, v: &mut hils_plant::params::VehicleParams) -> Option<&mut f64> {
        Some(match self {
            VehicleKey::CarbodyMass => &mut v.carbody_mass,
            VehicleKey::CarbodyPitchInertia => &mut v.carbody_pitch_inertia,
            VehicleKey::BogieMass => &mut v.bogie_mass,
            VehicleKey::WheelsetMass => &mut v.wheelset_mass,
            VehicleKey::WheelRadius => &mut v.wheel_radius,
            VehicleKey::Default => return None,
        })
    }

    /// Sets this key of `v` (nothing for `Default`).
    pub fn apply(self, v: &mut hils_plant::params::VehicleParams, value: f32) {
        if let Some(slot) = self.field(v) {
            *slot = value as f64;
        }
    }

    /// This key's value in `v` (0 for `Default`).
    pub fn value(self, v: &hils_plant::params::VehicleParams) -> f64 {
        let mut copy = *v;
        self.field(&mut copy).map_or(0.0, |x| *x)
    }
}

/// A zone as `TrackZone` carries it: bounds in steps of 0.1 m (decimetres), so that the
/// board checks and keeps zones without floating point in its step (the plant's
/// [`Zone`] is built from it outside the step, [`ZoneFrame::zone`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct ZoneFrame {
    /// Start, 0.1 m.
    pub start_dm: u32,
    /// End (exclusive), 0.1 m.
    pub end_dm: u32,
    /// Surface of the zone (its contact set).
    pub surface: Surface,
}

impl ZoneFrame {
    /// The frame of a zone: `None` when a bound is outside 0-[`ZONE_MAX_M`] or off the
    /// 0.1 m grid (by more than 1e-6 m): nothing is rounded silently.
    pub fn of(zone: &Zone) -> Option<Self> {
        let dm = |x: f64| {
            let steps = x / ZONE_RESOLUTION_M;
            let r = (steps + 0.5) as u32; // in range: not negative
            (zone_in_range(x) && (steps - r as f64).abs() <= 1e-5).then_some(r)
        };
        Some(Self {
            start_dm: dm(zone.start_m)?,
            end_dm: dm(zone.end_m)?,
            surface: zone.surface,
        })
    }

    /// The plant's zone.
    pub fn zone(&self) -> Zone {
        Zone {
            start_m: self.start_dm as f64 * ZONE_RESOLUTION_M,
            end_m: self.end_dm as f64 * ZONE_RESOLUTION_M,
            surface: self.surface,
        }
    }
}

/// `Track` command: forget the kept track, or check and keep the zones received.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum TrackCommand {
    /// Forget the kept track and the zones received (starts on one rail again).
    Clear,
    /// Zones 0..`zones` (all received since the last commit or clear) on `base`.
    Commit {
        /// Surface outside the zones.
        base: Surface,
        /// Number of zones (indices 0..zones).
        zones: u8,
    },
}

// ---------------------------------------------------------------------------------------
// RIG_WHEEL_SPEED_12, RIG_WHEEL_SPEED_34

/// `RIG_WHEEL_SPEED_12` / `RIG_WHEEL_SPEED_34` (0x100 / 0x101, every 1 ms): two wheelsets'
/// circumferential speeds r omega, km/h. `None` = not available (raw 0xFFFF).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WheelSpeedFrame {
    /// 0: wheelsets 1 and 2 (0x100); 1: wheelsets 3 and 4 (0x101).
    pub pair: usize,
    /// Circumferential speeds r omega of the pair's two wheelsets, km/h (`None`: not available).
    pub speeds_kmh: [Option<f32>; 2],
    /// The valve inputs; the frame carries its pair's two wheelsets (a decoded frame knows
    /// only those).
    pub valves: ValveStates,
    /// Alive counter of the cycle (the same in both frames of a cycle).
    pub counter: u8,
}

impl WheelSpeedFrame {
    /// Raw value of a speed: rounded to 0.01 km/h, limited to 0..=655.34 km/h; negative
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

    /// The two frames of one cycle: the four wheelsets' speeds and valve inputs, one alive
    /// counter.
    pub fn cycle(speeds_kmh: [Option<f32>; 4], valves: ValveStates, counter: u8) -> [Self; 2] {
        core::array::from_fn(|pair| Self {
            pair,
            speeds_kmh: [speeds_kmh[2 * pair], speeds_kmh[2 * pair + 1]],
            valves,
            counter,
        })
    }

    /// The 2-bit code of a valve input: 0 off, 1 energised, 3 not wired.
    fn valve_code(state: Option<bool>) -> u64 {
        match state {
            Some(on) => on as u64,
            None => 3,
        }
    }

    /// The frame's identifier (`None` for a pair other than 0 or 1).
    pub fn id(&self) -> Option<u16> {
        ID_WHEEL_SPEEDS.get(self.pair).copied()
    }

    /// The frame's bytes (`None` for a pair other than 0 or 1 or a frame type that cannot hold them).
    pub fn encode<F: Frame>(&self) -> Option<F> {
        let id = self.id()?;
        let mut data = [0u8; 8];
        for (signal, s) in wheel_speed::SPEEDS[self.pair].iter().zip(self.speeds_kmh) {
            signal.put_raw(&mut data, Self::raw_speed(s).0 as u64);
        }
        for (k, [dump, hold]) in wheel_speed::VALVES[self.pair].iter().enumerate() {
            let j = 2 * self.pair + k;
            dump.put_raw(&mut data, Self::valve_code(self.valves.dump(j)));
            hold.put_raw(&mut data, Self::valve_code(self.valves.hold(j)));
        }
        seal(id, data, self.counter)
    }

    /// Decodes either frame (the pair from the identifier).
    pub fn decode<F: Frame>(frame: &F) -> Result<Self, DecodeError> {
        let pair = match frame.id() {
            Id::Standard(id) if id.as_raw() == ID_WHEEL_SPEED_34 => 1,
            _ => 0,
        };
        let (data, counter) = open(frame, ID_WHEEL_SPEEDS[pair])?;
        let speeds_kmh = wheel_speed::SPEEDS[pair].map(|s| {
            if s.get_raw(&data) as u16 == WHEEL_SPEED_NOT_AVAILABLE {
                None
            } else {
                Some(s.get(&data))
            }
        });
        let mut valves = ValveStates::default();
        for (k, signals) in wheel_speed::VALVES[pair].iter().enumerate() {
            let bit = 1 << (2 * pair + k);
            for (signal, (state, known)) in signals.iter().zip([
                (&mut valves.dump, &mut valves.dump_known),
                (&mut valves.hold, &mut valves.hold_known),
            ]) {
                match signal.get_raw(&data) {
                    0 => *known |= bit,
                    1 => (*state, *known) = (*state | bit, *known | bit),
                    3 => {}
                    _ => return Err(DecodeError::BadValue(signal.name)),
                }
            }
        }
        Ok(Self {
            pair,
            speeds_kmh,
            valves,
            counter,
        })
    }
}

// ---------------------------------------------------------------------------------------
// RIG_BRAKE_DEMAND

/// `RIG_BRAKE_DEMAND` (0x102, optional: every 10 ms and in the tick the demand changes): the
/// brake demand the board drives on the train lines ([`crate::demand`]), for a controller
/// that takes it from the bus. The frame's absence (a timeout) is for the controller to
/// treat as an emergency brake, as an open loop.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BrakeDemandFrame {
    /// The EB loop is closed (no emergency brake).
    pub eb_loop_closed: bool,
    /// Service deceleration demanded, m/s^2 (0-65.535 at 0.001).
    pub service_mps2: f32,
    /// Alive counter, 0-15.
    pub counter: u8,
}

impl BrakeDemandFrame {
    /// The frame's bytes (`None` if the frame type cannot hold them).
    pub fn encode<F: Frame>(&self) -> Option<F> {
        let mut d = [0u8; 8];
        brake_demand::EB_LOOP_CLOSED.put_raw(&mut d, self.eb_loop_closed as u64);
        brake_demand::SERVICE.put(&mut d, self.service_mps2);
        seal(ID_BRAKE_DEMAND, d, self.counter)
    }

    /// Reads a `RIG_BRAKE_DEMAND` frame; refuses a wrong identifier, length or checksum.
    pub fn decode<F: Frame>(frame: &F) -> Result<Self, DecodeError> {
        let (d, counter) = open(frame, ID_BRAKE_DEMAND)?;
        Ok(Self {
            eb_loop_closed: brake_demand::EB_LOOP_CLOSED.get_raw(&d) == 1,
            service_mps2: brake_demand::SERVICE.get(&d),
            counter,
        })
    }
}

// ---------------------------------------------------------------------------------------
// RIG_STATUS

/// Run state of the board (4 bits in `RIG_STATUS`; codes 0-5 in declaration order).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, IntoPrimitive, TryFromPrimitive)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum RigState {
    /// No run: outputs in the safe state (silent, speeds not available).
    #[default]
    Idle,
    /// A run is being stepped at 10 kHz.
    Running,
    /// The run ended at standstill (vehicle speed <= 0.01 m/s).
    Finished,
    /// The run was stopped by command.
    Stopped,
    /// A fault latched during a run: safe state (see [`crate::rig`]).
    Fault,
    /// A run was requested: its simulation is being built outside the step; outputs in
    /// the safe state until it runs.
    Starting,
}

/// What closes the loop (2 bits in `RIG_STATUS`; 0 rig, 1 self-test).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, IntoPrimitive, TryFromPrimitive)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum RigMode {
    /// The real brake controller on the rig: brake inputs from the ADC channels.
    #[default]
    Rig,
    /// No rig: the simulated brake unit (`hils_sil::ClosedLoop`) closes the loop.
    SelfTest,
}

/// Result of the last command (2 bits in `RIG_STATUS`; 0 none, 1 accepted, 2 rejected).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, IntoPrimitive, TryFromPrimitive)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum CommandResult {
    #[default]
    /// No command received yet.
    None,
    /// The last command was accepted.
    Accepted,
    /// The last command was rejected (see [`crate::rig::CommandError`]).
    Rejected,
}

/// `RIG_STATUS` (0x110, every 10 ms).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StatusFrame {
    /// Vehicle (carbody) speed, km/h: 16 bits at 0.01 km/h (0-655.35).
    pub vehicle_speed_kmh: f32,
    /// Deceleration (-a_x), m/s^2: signed 16 bits at 0.001 m/s^2.
    pub deceleration_mps2: f32,
    /// State of the rig.
    pub state: RigState,
    /// Mode of the current (or last) run.
    pub mode: RigMode,
    /// Result of the last command.
    pub command_result: CommandResult,
    /// Low 16 bits of [`crate::rig::Faults`].
    pub faults: u16,
    /// Alive counter, 0-15.
    pub counter: u8,
}

impl StatusFrame {
    /// The frame's bytes (`None` if the frame type cannot hold them).
    pub fn encode<F: Frame>(&self) -> Option<F> {
        let mut d = [0u8; 8];
        status::VEHICLE_SPEED.put(&mut d, self.vehicle_speed_kmh);
        status::DECELERATION.put(&mut d, self.deceleration_mps2);
        status::STATE.put_raw(&mut d, u8::from(self.state) as u64);
        status::MODE.put_raw(&mut d, u8::from(self.mode) as u64);
        status::COMMAND_RESULT.put_raw(&mut d, u8::from(self.command_result) as u64);
        status::FAULTS.put_raw(&mut d, self.faults as u64);
        seal(ID_STATUS, d, self.counter)
    }

    /// Reads a `RIG_STATUS` frame; refuses a wrong identifier, length or raw value.
    pub fn decode<F: Frame>(frame: &F) -> Result<Self, DecodeError> {
        let (d, counter) = open(frame, ID_STATUS)?;
        Ok(Self {
            vehicle_speed_kmh: status::VEHICLE_SPEED.get(&d),
            deceleration_mps2: status::DECELERATION.get(&d),
            state: decode_enum(&d, status::STATE)?,
            mode: decode_enum(&d, status::MODE)?,
            command_result: decode_enum(&d, status::COMMAND_RESULT)?,
            faults: status::FAULTS.get_raw(&d) as u16,
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
    /// Latched fault of each sensor channel (3 bits each, [`crate::Code::code`]).
    pub sensor_faults: [Option<SensorFault>; 4],
    /// Bus-off events since power-up (saturates at 15).
    pub bus_off_count: u8,
}

impl DiagFrame {
    /// The frame's bytes (`None` if the frame type cannot hold them).
    pub fn encode<F: Frame>(&self) -> Option<F> {
        let mut d = [0u8; 8];
        diag::STEP_MAX.put(&mut d, self.step_max_us);
        diag::STEP_MEAN.put(&mut d, self.step_mean_us);
        diag::OVERRUNS.put_raw(&mut d, self.overruns as u64);
        for (s, f) in diag::SENSOR_FAULTS.iter().zip(self.sensor_faults) {
            s.put_raw(&mut d, SensorFault::code(f) as u64);
        }
        diag::BUS_OFF_COUNT.put_raw(&mut d, self.bus_off_count.min(15) as u64);
        F::new(StandardId::new(ID_DIAG)?, &d)
    }

    /// Reads a `RIG_DIAG` frame; refuses a wrong identifier, length or raw value.
    pub fn decode<F: Frame>(frame: &F) -> Result<Self, DecodeError> {
        let d = data_of(frame, ID_DIAG)?;
        let mut sensor_faults = [None; 4];
        for (j, s) in diag::SENSOR_FAULTS.iter().enumerate() {
            sensor_faults[j] = SensorFault::from_code(s.get_raw(&d) as u8)
                .ok_or(DecodeError::BadValue("SensorFault"))?;
        }
        Ok(Self {
            step_max_us: diag::STEP_MAX.get(&d),
            step_mean_us: diag::STEP_MEAN.get(&d),
            overruns: diag::OVERRUNS.get_raw(&d) as u16,
            sensor_faults,
            bus_off_count: diag::BUS_OFF_COUNT.get_raw(&d) as u8,
        })
    }
}

// ---------------------------------------------------------------------------------------
// RIG_HEALTH

/// `RIG_HEALTH` (0x121, every 100 ms): the board's own health, sealed like `RIG_STATUS`.
/// (`RIG_DIAG` has no bit left.)
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct HealthFrame {
    /// Stack high-water mark since power-up, bytes (sent to 4 B, at most 262 140).
    pub stack_peak_bytes: u32,
    /// The stack's size, bytes (sent to 4 B).
    pub stack_size_bytes: u32,
    /// Command frames lost in reception since power-up, at least (saturates at 255; RF0L
    /// is a flag: losses before the interrupt clears it count once).
    pub rx_lost: u8,
    /// ADC ring restarts since power-up (saturates at 255).
    pub adc_restarts: u8,
    /// `None` while armed for a controller; else why not.
    pub disarmed: Option<Disarm>,
    /// Consecutive fault resets before this start (saturates at 15).
    pub fault_resets: u8,
    /// Alive counter, 0-15.
    pub counter: u8,
}

impl HealthFrame {
    /// The frame's bytes (`None` if the frame type cannot hold them).
    pub fn encode<F: Frame>(&self) -> Option<F> {
        let bytes = |b: u32| (b / 4).min(health::STACK_PEAK.max_raw()) as u64;
        let mut d = [0u8; 8];
        health::STACK_PEAK.put_raw(&mut d, bytes(self.stack_peak_bytes));
        health::STACK_SIZE.put_raw(&mut d, bytes(self.stack_size_bytes));
        health::RX_LOST.put_raw(&mut d, self.rx_lost as u64);
        health::ADC_RESTARTS.put_raw(&mut d, self.adc_restarts as u64);
        health::ARMED.put_raw(&mut d, self.disarmed.is_none() as u64);
        health::DISARM_CAUSE.put_raw(&mut d, self.disarmed.map_or(0, u8::from) as u64);
        health::FAULT_RESETS.put_raw(&mut d, self.fault_resets.min(15) as u64);
        seal(ID_HEALTH, d, self.counter)
    }

    /// Reads a `RIG_HEALTH` frame; refuses a wrong identifier, length, checksum or cause.
    pub fn decode<F: Frame>(frame: &F) -> Result<Self, DecodeError> {
        let (d, counter) = open(frame, ID_HEALTH)?;
        let armed = health::ARMED.get_raw(&d) == 1;
        let cause: Disarm = decode_enum(&d, health::DISARM_CAUSE)?;
        Ok(Self {
            stack_peak_bytes: health::STACK_PEAK.get_raw(&d) as u32 * 4,
            stack_size_bytes: health::STACK_SIZE.get_raw(&d) as u32 * 4,
            rx_lost: health::RX_LOST.get_raw(&d) as u8,
            adc_restarts: health::ADC_RESTARTS.get_raw(&d) as u8,
            disarmed: (!armed).then_some(cause),
            fault_resets: health::FAULT_RESETS.get_raw(&d) as u8,
            counter,
        })
    }
}

// ---------------------------------------------------------------------------------------
// RIG_COMMAND

/// Brake command of the self-test mode and of `Brake` commands: the simulated brake unit's
/// demand itself (one type; its `BrakeDemand` signal code is [`brake_signal_code`]).
pub use hils_brake_unit::BrakeDemand as BrakeCommand;

/// The `BrakeDemand` signal (0 release, 1 EB, 2 service deceleration, 3 service step).
pub fn brake_signal_code(b: BrakeCommand) -> u8 {
    match b {
        BrakeCommand::Release => 0,
        BrakeCommand::Emergency => 1,
        BrakeCommand::Service { .. } => 2,
        BrakeCommand::ServiceStep { .. } => 3,
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
    /// A controller I/O item (codes 2-14) and its value in the item's unit
    /// ([`crate::controller_io::IoItem`], range checked when decoded).
    Io(IoItem, u16),
}

/// The values of a `Start` command (the signals `Start*` of opcode 1).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StartCommand {
    /// Self-test (simulated brake unit) or rig (measured brake inputs).
    pub mode: RigMode,
    /// Rail condition: the Polach set (paper Table 2 wet, `[contact.dry]`).
    pub rail: Rail,
    /// Disc-pad friction law (paper Eq (2) or constant mu_d0).
    pub friction: FrictionModel,
    /// The simulated brake unit gets the EB command at t = 0.
    pub emergency: bool,
    /// Initial speed, km/h.
    pub initial_speed_kmh: f32,
    /// Run on the track kept by [`Command::Track`] commit (else one `rail` everywhere).
    pub track: bool,
    /// [`crate::digest::setup_digest`] of the run's track (`None` unless `track`) and
    /// vehicle as the sender set them up: a lost `Track` or `Vehicle` frame makes the
    /// board's differ, and the start is rejected.
    pub setup_digest: u16,
}

/// A command received in `RIG_COMMAND` (0x200).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Command {
    /// Opcode 1: start a run from `initial_speed_kmh` (0.01 km/h per bit; the board
    /// accepts 0-655.34, the wheel-speed frames' range). `emergency`: the self-test's
    /// simulated brake unit gets the EB command at t = 0 (the paper's scenario).
    Start(StartCommand),
    /// Opcode 2: stop the run (outputs to the safe state).
    Stop,
    /// Opcode 3: brake command of the self-test mode.
    Brake(BrakeCommand),
    /// Opcode 4: inject (or with `None` remove) a sensor fault on channel 0-3.
    InjectFault {
        /// Sensor channel, 0-3.
        channel: u8,
        /// The fault to inject (`None`: remove the injected fault).
        fault: Option<InjectedFault>,
    },
    /// Opcode 5: calibrate channel 0-3 (only while no run is active).
    Calibrate {
        /// Sensor channel, 0-3.
        channel: u8,
        /// What to calibrate.
        action: Calibration,
    },
    /// Opcode 6: clear latched faults whose cause is gone.
    ClearFaults,
    /// Opcode 7: configuration (only while no run is active).
    Configure(ConfigItem),
    /// Opcode 8: zone `index` of the next track (kept by [`Command::Track`] commit).
    TrackZone {
        /// Zone index, 0-based (below 16).
        index: u8,
        /// The zone.
        zone: ZoneFrame,
    },
    /// Opcode 9: commit or clear the track.
    Track(TrackCommand),
    /// Opcode 10: one `[vehicle]` value of the following runs (only while no run is active).
    Vehicle {
        /// Which value (or the default vehicle).
        key: VehicleKey,
        /// The value, in the unit of its `[vehicle]` key (kg, kg m^2, m).
        value: f32,
    },
    /// Opcode 11: arm the rig for a controller: the outputs a controller reads go live in
    /// the following rig-mode runs ([`crate::arming`]).
    Arm,
    /// Opcode 12: disarm: the outputs a controller reads go to their safe values at once.
    Disarm,
}

impl Command {
    /// The opcode of the command (byte 0 of `RIG_COMMAND`).
    pub fn opcode(&self) -> u8 {
        self.kind().into()
    }

    /// The command's [`Opcode`].
    pub fn kind(&self) -> Opcode {
        match self {
            Command::Start(_) => Opcode::Start,
            Command::Stop => Opcode::Stop,
            Command::Brake(_) => Opcode::Brake,
            Command::InjectFault { .. } => Opcode::InjectFault,
            Command::Calibrate { .. } => Opcode::Calibrate,
            Command::ClearFaults => Opcode::ClearFaults,
            Command::Configure(_) => Opcode::Configure,
            Command::TrackZone { .. } => Opcode::TrackZone,
            Command::Track(_) => Opcode::Track,
            Command::Vehicle { .. } => Opcode::Vehicle,
            Command::Arm => Opcode::Arm,
            Command::Disarm => Opcode::Disarm,
        }
    }
}

/// `RIG_COMMAND` frame: a command and its alive counter.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CommandFrame {
    /// The command.
    pub command: Command,
    /// Alive counter, 0-15: the same counter as the last command is refused as a repeat.
    pub counter: u8,
}

/// The code of a rail condition in frames and telemetry: 0 wet, 1 dry.
pub fn rail_code(r: Rail) -> u8 {
    match r {
        Rail::Wet => 0,
        Rail::Dry => 1,
    }
}

/// The code of a friction model in frames and telemetry: 0 variable (Eq 2), 1 constant.
pub fn friction_code(f: FrictionModel) -> u8 {
    match f {
        FrictionModel::Variable => 0,
        FrictionModel::Constant => 1,
    }
}

impl CommandFrame {
    /// The frame (`None` if the HAL frame type refuses it).
    pub fn encode<F: Frame>(&self) -> Option<F> {
        use command::*;
        let mut d = [0u8; 8];
        OPCODE.put_raw(&mut d, self.command.opcode() as u64);
        match self.command {
            Command::Start(start) => {
                START_TRACK.put_raw(&mut d, start.track as u64);
                START_DIGEST.put_raw(&mut d, start.setup_digest as u64);
                START_MODE.put_raw(&mut d, u8::from(start.mode) as u64);
                START_RAIL.put_raw(&mut d, rail_code(start.rail) as u64);
                START_FRICTION.put_raw(&mut d, friction_code(start.friction) as u64);
                START_EMERGENCY.put_raw(&mut d, start.emergency as u64);
                START_SPEED.put(&mut d, start.initial_speed_kmh);
            }
            Command::Stop | Command::ClearFaults | Command::Arm | Command::Disarm => {}
            Command::Brake(b) => {
                BRAKE_DEMAND.put_raw(&mut d, brake_signal_code(b) as u64);
                match b {
                    BrakeCommand::Service { deceleration_mps2 } => {
                        SERVICE_DECELERATION.put(&mut d, deceleration_mps2)
                    }
                    BrakeCommand::ServiceStep { step } => SERVICE_STEP.put_raw(&mut d, step as u64),
                    _ => {}
                }
            }
            Command::InjectFault { channel, fault } => {
                FAULT_CHANNEL.put_raw(&mut d, channel as u64);
                INJECTED_FAULT.put_raw(&mut d, InjectedFault::code(fault) as u64);
            }
            Command::Calibrate { channel, action } => {
                CAL_CHANNEL.put_raw(&mut d, channel as u64);
                let (code, value) = match action {
                    Calibration::Tare => (0, None),
                    Calibration::SetGain(g) => (1, Some(g)),
                    Calibration::SetOffset(o) => (2, Some(o)),
                    Calibration::SetKind(k) => (3, Some(k as u8 as f32)),
                };
                CAL_ACTION.put_raw(&mut d, code);
                if let Some(x) = value {
                    CAL_VALUE.put_raw(&mut d, x.to_bits() as u64);
                }
            }
            Command::Configure(item) => {
                let (code, value) = match item {
                    ConfigItem::TelemetryDivider(v) => (0, v),
                    ConfigItem::Teeth(v) => (1, v),
                    ConfigItem::Io(item, v) => (u8::from(item) as u64, v),
                };
                CONFIG_ITEM.put_raw(&mut d, code);
                CONFIG_VALUE.put_raw(&mut d, value as u64);
            }
            Command::TrackZone { index, zone } => {
                ZONE_INDEX.put_raw(&mut d, index as u64);
                ZONE_SURFACE.put_raw(&mut d, surface_code(zone.surface) as u64);
                ZONE_START.put_raw(&mut d, zone.start_dm as u64);
                ZONE_END.put_raw(&mut d, zone.end_dm as u64);
            }
            Command::Track(TrackCommand::Clear) => {}
            Command::Track(TrackCommand::Commit { base, zones }) => {
                TRACK_ACTION.put_raw(&mut d, 1);
                TRACK_BASE.put_raw(&mut d, surface_code(base) as u64);
                TRACK_ZONES.put_raw(&mut d, zones as u64);
            }
            Command::Vehicle { key, value } => {
                VEHICLE_KEY.put_raw(&mut d, u8::from(key) as u64);
                VEHICLE_VALUE.put_raw(&mut d, value.to_bits() as u64);
            }
        }
        seal(ID_COMMAND, d, self.counter)
    }

    /// Decodes and checks a received frame: identifier, length, checksum, opcode and every
    /// field's range.
    pub fn decode<F: Frame>(frame: &F) -> Result<Self, DecodeError> {
        let (d, counter) = open(frame, ID_COMMAND)?;
        let raw_opcode = command::OPCODE.get_raw(&d) as u8;
        let opcode =
            Opcode::try_from(raw_opcode).map_err(|_| DecodeError::UnknownOpcode(raw_opcode))?;
        let command = match opcode {
            Opcode::Start => decode_start(&d)?,
            Opcode::Stop => Command::Stop,
            Opcode::Brake => Command::Brake(decode_brake(&d)?),
            Opcode::InjectFault => Command::InjectFault {
                channel: decode_channel(&d, command::FAULT_CHANNEL)?,
                fault: InjectedFault::from_code(command::INJECTED_FAULT.get_raw(&d) as u8)
                    .ok_or(DecodeError::BadValue("InjectedFault"))?,
            },
            Opcode::Calibrate => Command::Calibrate {
                channel: decode_channel(&d, command::CAL_CHANNEL)?,
                action: decode_calibration(&d)?,
            },
            Opcode::ClearFaults => Command::ClearFaults,
            Opcode::Configure => Command::Configure(decode_config(&d)?),
            Opcode::TrackZone => decode_zone(&d)?,
            Opcode::Track => decode_track(&d)?,
            Opcode::Vehicle => decode_vehicle(&d)?,
            Opcode::Arm => Command::Arm,
            Opcode::Disarm => Command::Disarm,
        };
        Ok(Self { command, counter })
    }
}

/// A channel number 0-3.
fn decode_channel(d: &[u8; 8], signal: Signal) -> Result<u8, DecodeError> {
    let c = signal.get_raw(d) as u8;
    if (c as usize) < crate::CHANNELS {
        Ok(c)
    } else {
        Err(DecodeError::BadValue("Channel"))
    }
}

fn decode_start(d: &[u8; 8]) -> Result<Command, DecodeError> {
    use command::*;
    let mode =
        RigMode::from_raw(START_MODE.get_raw(d) as u8).ok_or(DecodeError::BadValue("StartMode"))?;
    let rail = if START_RAIL.get_raw(d) == 0 {
        Rail::Wet
    } else {
        Rail::Dry
    };
    let friction = if START_FRICTION.get_raw(d) == 0 {
        FrictionModel::Variable
    } else {
        FrictionModel::Constant
    };
    Ok(Command::Start(StartCommand {
        mode,
        rail,
        friction,
        emergency: START_EMERGENCY.get_raw(d) == 1,
        initial_speed_kmh: START_SPEED.get(d),
        track: START_TRACK.get_raw(d) == 1,
        setup_digest: START_DIGEST.get_raw(d) as u16,
    }))
}

/// Whether a position fits `ZoneStart`/`ZoneEnd` (0 to [`ZONE_MAX_M`]).
pub fn zone_in_range(x_m: f64) -> bool {
    (0.0..=ZONE_MAX_M).contains(&x_m)
}

/// A surface code signal's surface (4-7: the signal named as out of range).
fn decode_surface(d: &[u8; 8], signal: Signal) -> Result<Surface, DecodeError> {
    surface_of_code(signal.get_raw(d) as u8).ok_or(DecodeError::BadValue(signal.name))
}

fn decode_zone(d: &[u8; 8]) -> Result<Command, DecodeError> {
    use command::*;
    Ok(Command::TrackZone {
        index: ZONE_INDEX.get_raw(d) as u8,
        zone: ZoneFrame {
            start_dm: ZONE_START.get_raw(d) as u32,
            end_dm: ZONE_END.get_raw(d) as u32,
            surface: decode_surface(d, ZONE_SURFACE)?,
        },
    })
}

fn decode_track(d: &[u8; 8]) -> Result<Command, DecodeError> {
    use command::*;
    Ok(Command::Track(if TRACK_ACTION.get_raw(d) == 0 {
        TrackCommand::Clear
    } else {
        TrackCommand::Commit {
            base: decode_surface(d, TRACK_BASE)?,
            zones: TRACK_ZONES.get_raw(d) as u8,
        }
    }))
}

fn decode_vehicle(d: &[u8; 8]) -> Result<Command, DecodeError> {
    use command::*;
    let key = decode_enum(d, VEHICLE_KEY)?;
    let value = f32::from_bits(VEHICLE_VALUE.get_raw(d) as u32);
    if key == VehicleKey::Default {
        // The value is unused: whatever the bits, the command is the same (fuzz finding:
        // a NaN here made the decoded command unequal to itself).
        return Ok(Command::Vehicle { key, value: 0.0 });
    }
    if !(value.is_finite() && value > 0.0) {
        return Err(DecodeError::BadValue("VehicleValue"));
    }
    Ok(Command::Vehicle { key, value })
}

fn decode_brake(d: &[u8; 8]) -> Result<BrakeCommand, DecodeError> {
    Ok(match command::BRAKE_DEMAND.get_raw(d) {
        0 => BrakeCommand::Release,
        1 => BrakeCommand::Emergency,
        2 => {
            let a = command::SERVICE_DECELERATION.get(d);
            if a > 10.0 {
                return Err(DecodeError::BadValue("ServiceDeceleration"));
            }
            BrakeCommand::Service {
                deceleration_mps2: a,
            }
        }
        3 => match command::SERVICE_STEP.get_raw(d) as u8 {
            0 => return Err(DecodeError::BadValue("ServiceStep")),
            step => BrakeCommand::ServiceStep { step },
        },
        _ => return Err(DecodeError::BadValue("BrakeDemand")),
    })
}

fn decode_calibration(d: &[u8; 8]) -> Result<Calibration, DecodeError> {
    let value = f32::from_bits(command::CAL_VALUE.get_raw(d) as u32);
    let bad = DecodeError::BadValue("CalibrationValue");
    Ok(match command::CAL_ACTION.get_raw(d) {
        0 => Calibration::Tare,
        1 if value.is_finite() && value != 0.0 => Calibration::SetGain(value),
        2 if value.is_finite() && (0.0..=4095.0).contains(&value) => Calibration::SetOffset(value),
        1 | 2 => return Err(bad),
        3 => Calibration::SetKind(match value {
            0.0 => SensorKind::LoadCell,
            1.0 => SensorKind::PressureTransducer,
            _ => return Err(DecodeError::BadValue("SensorKind")),
        }),
        _ => return Err(DecodeError::BadValue("CalibrationAction")),
    })
}

fn decode_config(d: &[u8; 8]) -> Result<ConfigItem, DecodeError> {
    let v = command::CONFIG_VALUE.get_raw(d) as u16;
    Ok(match command::CONFIG_ITEM.get_raw(d) {
        0 if (1..=10_000).contains(&v) => ConfigItem::TelemetryDivider(v),
        1 if (1..=1000).contains(&v) => ConfigItem::Teeth(v),
        0 | 1 => return Err(DecodeError::BadValue("ConfigValue")),
        code => match IoItem::from_raw(code as u8) {
            Some(item) if item.accepts(v) => ConfigItem::Io(item, v),
            Some(_) => return Err(DecodeError::BadValue("ConfigValue")),
            None => return Err(DecodeError::BadValue("ConfigItem")),
        },
    })
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

    /// The table-driven checksum against the CRC as a bit-serial shift register: the 76 bits
    /// (identifier, bytes 0-6, the counter nibble) least significant bit first, the register
    /// shifted right with x^4 + x + 1 reflected (0xC) fed back.
    #[test]
    fn checksum_equals_the_bit_serial_crc() {
        let serial = |id: u16, d: &[u8; 8]| {
            let word = (id as u128) | (u64::from_le_bytes(*d) as u128) << 16;
            let mut crc = 0u8;
            for k in 0..76 {
                let bit = ((word >> k) & 1) as u8;
                crc = if (crc ^ bit) & 1 != 0 {
                    (crc >> 1) ^ 0x0C
                } else {
                    crc >> 1
                };
            }
            crc
        };
        let mut x = 0x9E37_79B9_7F4A_7C15u64;
        for id in (0u16..0x800).step_by(7) {
            x = x.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1);
            let d = x.to_le_bytes();
            assert_eq!(checksum(id, &d), serial(id, &d), "id {id:#x} data {d:02x?}");
        }
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
        let speeds = [Some(350.0), Some(0.0), None, Some(655.34)];
        let valves = ValveStates {
            dump: 0b0101,
            hold: 0b0011,
            dump_known: 0b0111,
            hold_known: 0b1011,
        };
        let frames = WheelSpeedFrame::cycle(speeds, valves, 9);
        let mut back_valves = ValveStates::default();
        let mut back = [None; 4];
        for (pair, w) in frames.iter().enumerate() {
            let f: TestFrame = w.encode().unwrap();
            assert_eq!(
                f.id(),
                Id::Standard(StandardId::new(0x100 + pair as u16).unwrap())
            );
            let d = WheelSpeedFrame::decode(&f).unwrap();
            assert_eq!((d.pair, d.counter), (pair, 9));
            back_valves.dump |= d.valves.dump;
            back_valves.hold |= d.valves.hold;
            back_valves.dump_known |= d.valves.dump_known;
            back_valves.hold_known |= d.valves.hold_known;
            back[2 * pair..2 * pair + 2].copy_from_slice(&d.speeds_kmh);
        }
        for (a, b) in speeds.iter().zip(back.iter()) {
            match (a, b) {
                (Some(a), Some(b)) => {
                    assert!((a - b).abs() <= 0.005 + 3e-3 * 0.01 * a, "{a} vs {b}")
                }
                (None, None) => {}
                _ => panic!("{a:?} vs {b:?}"),
            }
        }
        // The valve inputs of both frames are the cycle's, not-wired ones not known.
        assert_eq!(back_valves, valves);
        // 350 km/h and above at 0.01 km/h: within half a step (f32 keeps 16 bits exactly).
        for raw in [35_000u16, 35_001, 65_534] {
            let v = raw as f32 * 0.01;
            assert_eq!(WheelSpeedFrame::raw_speed(Some(v)), (raw, false));
        }
        assert!(
            WheelSpeedFrame {
                pair: 2,
                speeds_kmh: [None; 2],
                valves: ValveStates::default(),
                counter: 0
            }
            .encode::<TestFrame>()
            .is_none()
        );
    }

    #[test]
    fn wheel_speed_saturates_and_flags_above_range() {
        assert_eq!(
            WheelSpeedFrame::raw_speed(Some(700.0)),
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
            pair: 0,
            speeds_kmh: [Some(100.0); 2],
            valves: ValveStates::default(),
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
            Command::Start(StartCommand {
                mode: RigMode::SelfTest,
                rail: Rail::Dry,
                friction: FrictionModel::Constant,
                emergency: true,
                initial_speed_kmh: 150.0,
                track: false,
                setup_digest: 0,
            }),
            Command::Start(StartCommand {
                mode: RigMode::Rig,
                rail: Rail::Wet,
                friction: FrictionModel::Variable,
                emergency: false,
                initial_speed_kmh: 80.25,
                track: true,
                setup_digest: 0xBEEF,
            }),
            Command::Brake(BrakeCommand::ServiceStep { step: 7 }),
            Command::TrackZone {
                index: 15,
                zone: ZoneFrame::of(&Zone {
                    start_m: 120.0,
                    end_m: 100_000.0,
                    surface: Surface::VeryLow,
                })
                .unwrap(),
            },
            Command::Track(TrackCommand::Commit {
                base: Surface::Low,
                zones: 16,
            }),
            Command::Track(TrackCommand::Clear),
            Command::Vehicle {
                key: VehicleKey::CarbodyMass,
                value: 26_000.0,
            },
            Command::Vehicle {
                key: VehicleKey::Default,
                value: 0.0,
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
                (Command::Start(a), Command::Start(b)) => {
                    assert!((a.initial_speed_kmh - b.initial_speed_kmh).abs() < 0.006);
                    // Every other value as sent.
                    let speed_as_received = StartCommand {
                        initial_speed_kmh: b.initial_speed_kmh,
                        ..*a
                    };
                    assert_eq!(speed_as_received, b);
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
        let nan = f32::NAN.to_bits().to_le_bytes();
        let cases: [([u8; 7], DecodeError); 14] = [
            ([0, 0, 0, 0, 0, 0, 0], DecodeError::UnknownOpcode(0)),
            ([99, 0, 0, 0, 0, 0, 0], DecodeError::UnknownOpcode(99)),
            ([4, 4, 1, 0, 0, 0, 0], DecodeError::BadValue("Channel")),
            (
                [4, 0, 9, 0, 0, 0, 0],
                DecodeError::BadValue("InjectedFault"),
            ),
            ([1, 3, 0, 0, 0, 0, 0], DecodeError::BadValue("StartMode")),
            (
                [5, 0, 1, nan[0], nan[1], nan[2], nan[3]],
                DecodeError::BadValue("CalibrationValue"),
            ),
            ([7, 0, 0, 0, 0, 0, 0], DecodeError::BadValue("ConfigValue")),
            ([7, 15, 1, 0, 0, 0, 0], DecodeError::BadValue("ConfigItem")),
            // An I/O item (5: the full-scale duty, 20-990 per mille) out of its range.
            ([7, 5, 1, 0, 0, 0, 0], DecodeError::BadValue("ConfigValue")),
            // Surface code 5 in a zone (bits 13-15 of byte 1), and as a track's base.
            (
                [8, 5 << 5, 0, 0, 0, 0, 0],
                DecodeError::BadValue("ZoneSurface"),
            ),
            (
                [9, 1 | (6 << 1), 0, 0, 0, 0, 0],
                DecodeError::BadValue("TrackBase"),
            ),
            (
                [10, 7, 0, 0, 0, 0x80, 0x3F],
                DecodeError::BadValue("VehicleKey"),
            ),
            (
                [10, 0, 0, nan[0], nan[1], nan[2], nan[3]],
                DecodeError::BadValue("VehicleValue"),
            ),
            ([3, 3, 0, 0, 0, 0, 0], DecodeError::BadValue("ServiceStep")),
        ];
        for (bytes, error) in cases {
            assert_eq!(
                CommandFrame::decode(&raw(bytes)),
                Err(error),
                "bytes {bytes:?}"
            );
        }
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
