//! Telemetry: the decimated record of a run, its defmt lines and their parser.
//!
//! The board logs one [`TelemetryRecord`] every `divider` plant steps (default 100: 100 Hz)
//! as a defmt line `tlm1 <48 fields>`, a [`RunHeader`] line `tlm1-start ...` when a run
//! starts and a `tlm1-end <step> <state>` line when it ends. The host decoder (`hils decode`)
//! gets the lines' text from defmt's decoder (or from a probe-rs log), parses them here
//! ([`parse_line`]) and writes a run-log CSV (`spec/measured-data.md`, section 1).
//! One copy of the layout: the format strings below and the parser use [`FIELDS`].
//!
//! Floats go through defmt as `{=f32}` (the decoder prints the shortest text that reads
//! back to the same f32), so a decoded record equals the board's bit for bit. NaN in
//! `p_cyl`/`f_clamp` means "not measured" (an empty cell in the CSV).
//!
//! **Integrity.** The last two fields are the record's sequence number in the run (`seq`:
//! 0, 1, 2, ... for every record the step made, sent or dropped, so a gap is a lost record)
//! and a CRC-32 ([`TelemetryRecord::crc32`]) over the binary values of all other fields,
//! computed by the logging task. A record whose values were changed on the way (a flipped
//! byte in the RTT capture that still decodes) fails the CRC and is rejected by
//! [`parse_line`] ([`ParseError::Crc`]) instead of being read as plausible data.

use crate::Code;
use crate::can::{RigMode, RigState};

/// Names of the fields of a `tlm1` line, in order (48).
pub const FIELDS: [&str; 48] = [
    "step",
    "state",
    "mode",
    "cmd",
    "driven",
    "valves",
    "v_ref",
    "omega1",
    "omega2",
    "omega3",
    "omega4",
    "p_cyl1",
    "p_cyl2",
    "p_cyl3",
    "p_cyl4",
    "f_clamp1",
    "f_clamp2",
    "f_clamp3",
    "f_clamp4",
    "f_brake1",
    "f_brake2",
    "f_brake3",
    "f_brake4",
    "t_disc1",
    "t_disc2",
    "t_disc3",
    "t_disc4",
    "q1",
    "q2",
    "q3",
    "q4",
    "mu_d1",
    "mu_d2",
    "mu_d3",
    "mu_d4",
    "a_x",
    "service_demand",
    "air_spring1",
    "air_spring2",
    "step_max_cycles",
    "step_mean_cycles",
    "overruns",
    "missed_ticks",
    "faults",
    "sensor_faults",
    "surfaces",
    "seq",
    "crc32",
];

/// Tag of a record line.
pub const RECORD_TAG: &str = "tlm1";
/// Tag of a run header line.
pub const HEADER_TAG: &str = "tlm1-start";
/// Tag of a run end line.
pub const END_TAG: &str = "tlm1-end";

/// One telemetry record (SI units).
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct TelemetryRecord {
    /// Plant steps since the run started (t = step x step time).
    pub step: u32,
    /// State of the rig ([`RigState`] code).
    pub state: u8,
    /// Mode of the run ([`RigMode`] code).
    pub mode: u8,
    /// Brake command in force (`hils_sil::Cmd` code of [`crate::can::BrakeCommand`]).
    pub cmd: u8,
    /// What the step drove on the controller's lines ([`crate::controller_io::DrivenOutputs::bits`]):
    /// bit 0 EB loop closed, 1 service PWM active, 2 air-spring DACs active.
    pub driven: u8,
    /// The WSP valves ([`crate::valves::ValveStates::bits`]): bits 0-3 dump, 4-7 hold,
    /// 8-11 dump known, 12-15 hold known (rig mode: the inputs wired; self-test: the
    /// simulated unit's valves, all known).
    pub valves: u16,
    /// Vehicle (carbody) speed, m/s.
    pub v_ref: f32,
    /// Wheelset angular speeds, rad/s.
    pub omega: [f32; 4],
    /// Cylinder pressure, Pa (NaN = not measured).
    pub p_cyl: [f32; 4],
    /// Pad clamp force per face, N (NaN = not measured).
    pub f_clamp: [f32; 4],
    /// Disc friction force at the friction radius, N (plant).
    pub f_brake: [f32; 4],
    /// Disc temperature rise, degC (plant, Eqs 3-6).
    pub t_disc: [f32; 4],
    /// Axle loads, N (plant).
    pub q: [f32; 4],
    /// Disc-pad friction coefficient (plant, Eq 2).
    pub mu_d: [f32; 4],
    /// Carbody longitudinal acceleration, m/s^2.
    pub a_x: f32,
    /// Service deceleration driven on the demand PWM, m/s^2 (0 while silent).
    pub service_demand: f32,
    /// Air-spring pressure of bogie 1 and 2 driven on the DACs, Pa (NaN while silent).
    pub air_spring: [f32; 2],
    /// Longest and mean step since the last record, CPU cycles.
    pub step_max_cycles: u32,
    /// Mean step since the last record, CPU cycles.
    pub step_mean_cycles: u32,
    /// Overruns and missed ticks since the run started.
    pub overruns: u32,
    /// Ticks lost since the run started.
    pub missed_ticks: u32,
    /// [`crate::rig::Faults`] bits.
    pub faults: u32,
    /// Sensor fault codes, 4 bits per channel (channel 1 in bits 0-3).
    pub sensor_faults: u16,
    /// The surface (zone) under each wheelset, 2 bits per wheelset (wheelset 1 in bits
    /// 0-1), [`crate::can::surface_code`]: 0 dry, 1 wet, 2 low, 3 very low.
    pub surfaces: u8,
    /// Number of the record in its run (0 = the t = 0 record), counting dropped ones.
    pub seq: u32,
}

/// The header of a run.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct RunHeader {
    /// Mode of the run ([`RigMode`] code).
    pub mode: u8,
    /// 0 wet, 1 dry.
    pub rail: u8,
    /// 0 variable (Eq 2), 1 constant mu_d0.
    pub friction: u8,
    /// Initial speed, km/h.
    pub initial_speed_kmh: f32,
    /// Plant step, ns (100 000).
    pub step_ns: u32,
    /// Telemetry every this many steps.
    pub divider: u32,
    /// CPU clock, Hz (for the cycle counts).
    pub cpu_hz: u32,
    /// Teeth of the simulated speed-sensor wheel.
    pub teeth: u16,
    /// Bit j set: channel j is a pressure transducer (else a load cell).
    pub pressure_channels: u8,
}

/// A parsed telemetry line.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Line {
    /// A `tlm1-start` line.
    Header(RunHeader),
    /// A `tlm1` record line.
    Record(TelemetryRecord),
    /// A `tlm1-end` line.
    End {
        /// Plant steps of the run.
        step: u32,
        /// Final state ([`RigState`] code).
        state: u8,
    },
}

/// Why a telemetry line could not be parsed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ParseError {
    /// Fewer or more fields than the tag has (found).
    FieldCount {
        /// Fields the tag has.
        expected: usize,
        /// Fields the line has.
        found: usize,
    },
    /// Field `index` (0-based, named in [`FIELDS`] for records) is not a number of its type.
    BadField {
        /// 0-based field index.
        index: usize,
    },
    /// The record's CRC-32 does not match its values (corrupted on the way).
    Crc {
        /// CRC-32 computed from the values.
        computed: u32,
        /// CRC-32 the line carries.
        received: u32,
    },
}

impl core::fmt::Display for ParseError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            ParseError::FieldCount { expected, found } => {
                write!(f, "{found} fields, expected {expected}")
            }
            ParseError::BadField { index } => match FIELDS.get(*index) {
                Some(name) => write!(f, "field {} (`{name}`) is not a number", index + 1),
                None => write!(f, "field {} is not a number", index + 1),
            },
            ParseError::Crc { computed, received } => write!(
                f,
                "record corrupted: CRC-32 {received:#010x} received, {computed:#010x} computed from its values"
            ),
        }
    }
}

struct Fields<'a> {
    it: core::str::SplitAsciiWhitespace<'a>,
    index: usize,
}

impl<'a> Fields<'a> {
    fn next<T: core::str::FromStr>(&mut self) -> Result<T, ParseError> {
        let i = self.index;
        self.index += 1;
        self.it
            .next()
            .ok_or(ParseError::BadField { index: i })?
            .parse()
            .map_err(|_| ParseError::BadField { index: i })
    }
    fn four(&mut self) -> Result<[f32; 4], ParseError> {
        Ok([self.next()?, self.next()?, self.next()?, self.next()?])
    }
}

/// Finds a telemetry line in a text line (a defmt message, or a probe-rs log line with a
/// timestamp and level before it) and parses it. `Ok(None)` for a line that is not
/// telemetry (other log messages, location lines).
pub fn parse_line(text: &str) -> Result<Option<Line>, ParseError> {
    // The tag is the first whitespace-separated word equal to a tag.
    let mut words = text.split_ascii_whitespace();
    let mut rest_start = None;
    let mut tag = "";
    while let Some(w) = words.next() {
        if w == RECORD_TAG || w == HEADER_TAG || w == END_TAG {
            tag = w;
            // Byte offset just after this word (words are subslices of `text`).
            let offset = w.as_ptr() as usize - text.as_ptr() as usize + w.len();
            rest_start = Some(offset);
            break;
        }
    }
    let Some(start) = rest_start else {
        return Ok(None);
    };
    let rest = text.get(start..).unwrap_or("");
    let count = rest.split_ascii_whitespace().count();
    let mut f = Fields {
        it: rest.split_ascii_whitespace(),
        index: 0,
    };
    let expect = |n: usize| {
        if count == n {
            Ok(())
        } else {
            Err(ParseError::FieldCount {
                expected: n,
                found: count,
            })
        }
    };
    Ok(Some(match tag {
        RECORD_TAG => {
            expect(FIELDS.len())?;
            let r = TelemetryRecord {
                step: f.next()?,
                state: f.next()?,
                mode: f.next()?,
                cmd: f.next()?,
                driven: f.next()?,
                valves: f.next()?,
                v_ref: f.next()?,
                omega: f.four()?,
                p_cyl: f.four()?,
                f_clamp: f.four()?,
                f_brake: f.four()?,
                t_disc: f.four()?,
                q: f.four()?,
                mu_d: f.four()?,
                a_x: f.next()?,
                service_demand: f.next()?,
                air_spring: [f.next()?, f.next()?],
                step_max_cycles: f.next()?,
                step_mean_cycles: f.next()?,
                overruns: f.next()?,
                missed_ticks: f.next()?,
                faults: f.next()?,
                sensor_faults: f.next()?,
                surfaces: f.next()?,
                seq: f.next()?,
            };
            let received: u32 = f.next()?;
            let computed = r.crc32();
            if received != computed {
                return Err(ParseError::Crc { computed, received });
            }
            Line::Record(r)
        }
        HEADER_TAG => {
            expect(9)?;
            Line::Header(RunHeader {
                mode: f.next()?,
                rail: f.next()?,
                friction: f.next()?,
                initial_speed_kmh: f.next()?,
                step_ns: f.next()?,
                divider: f.next()?,
                cpu_hz: f.next()?,
                teeth: f.next()?,
                pressure_channels: f.next()?,
            })
        }
        _ => {
            expect(2)?;
            Line::End {
                step: f.next()?,
                state: f.next()?,
            }
        }
    }))
}

/// CRC-32/ISO-HDLC (the zlib/Ethernet CRC: reflected polynomial 0xEDB88320, init and final
/// xor 0xFFFFFFFF; check value of "123456789" = 0xCBF43926), bitwise: run once per record
/// in the logging task, 170 bytes.
fn crc32_update(mut crc: u32, bytes: &[u8]) -> u32 {
    for &b in bytes {
        crc ^= b as u32;
        for _ in 0..8 {
            crc = (crc >> 1) ^ (0xEDB8_8320 & (crc & 1).wrapping_neg());
        }
    }
    crc
}

/// The value of one field of a `tlm1` line, in the type the line carries it in.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum FieldValue {
    /// A code or bit set of 8 bits.
    U8(u8),
    /// A bit set of 16 bits.
    U16(u16),
    /// A count or bit set of 32 bits.
    U32(u32),
    /// A float (SI units; NaN = not measured).
    F32(f32),
}

impl FieldValue {
    /// The value's bits (a float's IEEE bits, NaN payload included): equal bits, equal value.
    pub fn bits(self) -> u32 {
        match self {
            FieldValue::U8(x) => x as u32,
            FieldValue::U16(x) => x as u32,
            FieldValue::U32(x) => x,
            FieldValue::F32(x) => x.to_bits(),
        }
    }

    /// The value the CRC covers and its width in bytes (little-endian): a float's bit
    /// pattern, every NaN as the canonical quiet NaN.
    fn crc_word(self) -> (u32, usize) {
        match self {
            FieldValue::U8(x) => (x as u32, 1),
            FieldValue::U16(x) => (x as u32, 2),
            FieldValue::U32(x) => (x, 4),
            FieldValue::F32(x) => (if x.is_nan() { f32::NAN } else { x }.to_bits(), 4),
        }
    }
}

/// The value as the decoder prints it (defmt's text of `{=u8}`, `{=f32}`, ...: the shortest
/// text that reads back to the same value).
impl core::fmt::Display for FieldValue {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {
            FieldValue::F32(x) => write!(f, "{x}"),
            integer => write!(f, "{}", integer.bits()),
        }
    }
}

impl TelemetryRecord {
    /// Calls `visit` with the value of every field but the CRC, in the order of [`FIELDS`]
    /// (the one walk over the fields, used by [`TelemetryRecord::crc32`]).
    pub fn for_each_value(&self, mut visit: impl FnMut(FieldValue)) {
        // Every field named: a new one does not compile until it has its place here.
        let TelemetryRecord {
            step,
            state,
            mode,
            cmd,
            driven,
            valves,
            v_ref,
            omega,
            p_cyl,
            f_clamp,
            f_brake,
            t_disc,
            q,
            mu_d,
            a_x,
            service_demand,
            air_spring,
            step_max_cycles,
            step_mean_cycles,
            overruns,
            missed_ticks,
            faults,
            sensor_faults,
            surfaces,
            seq,
        } = self;
        visit(FieldValue::U32(*step));
        for code in [state, mode, cmd, driven] {
            visit(FieldValue::U8(*code));
        }
        visit(FieldValue::U16(*valves));
        visit(FieldValue::F32(*v_ref));
        for values in [omega, p_cyl, f_clamp, f_brake, t_disc, q, mu_d] {
            values.iter().for_each(|&x| visit(FieldValue::F32(x)));
        }
        for x in [a_x, service_demand, &air_spring[0], &air_spring[1]] {
            visit(FieldValue::F32(*x));
        }
        for count in [
            step_max_cycles,
            step_mean_cycles,
            overruns,
            missed_ticks,
            faults,
        ] {
            visit(FieldValue::U32(*count));
        }
        visit(FieldValue::U16(*sensor_faults));
        visit(FieldValue::U8(*surfaces));
        visit(FieldValue::U32(*seq));
    }

    /// CRC-32 over the little-endian bytes of every field but the CRC itself, in the order
    /// of [`FIELDS`]; floats as their bit patterns, every NaN as the canonical quiet NaN
    /// (the text line says only `NaN`, whatever the payload).
    pub fn crc32(&self) -> u32 {
        let mut c = !0;
        self.for_each_value(|v| {
            let (word, len) = v.crc_word();
            c = crc32_update(c, &word.to_le_bytes()[..len]);
        });
        !c
    }

    /// The state as a [`RigState`] (`None` for an unknown code).
    pub fn rig_state(&self) -> Option<RigState> {
        RigState::from_raw(self.state)
    }
    /// The mode as a [`RigMode`] (`None` for an unknown code).
    pub fn rig_mode(&self) -> Option<RigMode> {
        RigMode::from_raw(self.mode)
    }

    /// Logs the record as a defmt `tlm1` line (`println`: not filtered by `DEFMT_LOG`).
    #[cfg(feature = "defmt")]
    pub fn log(&self) {
        let r = self;
        defmt::println!(
            "tlm1 {=u32} {=u8} {=u8} {=u8} {=u8} {=u16} {=f32} {=f32} {=f32} {=f32} {=f32} {=f32} {=f32} {=f32} {=f32} {=f32} {=f32} {=f32} {=f32} {=f32} {=f32} {=f32} {=f32} {=f32} {=f32} {=f32} {=f32} {=f32} {=f32} {=f32} {=f32} {=f32} {=f32} {=f32} {=f32} {=f32} {=f32} {=f32} {=f32} {=u32} {=u32} {=u32} {=u32} {=u32} {=u16} {=u8} {=u32} {=u32}",
            r.step,
            r.state,
            r.mode,
            r.cmd,
            r.driven,
            r.valves,
            r.v_ref,
            r.omega[0],
            r.omega[1],
            r.omega[2],
            r.omega[3],
            r.p_cyl[0],
            r.p_cyl[1],
            r.p_cyl[2],
            r.p_cyl[3],
            r.f_clamp[0],
            r.f_clamp[1],
            r.f_clamp[2],
            r.f_clamp[3],
            r.f_brake[0],
            r.f_brake[1],
            r.f_brake[2],
            r.f_brake[3],
            r.t_disc[0],
            r.t_disc[1],
            r.t_disc[2],
            r.t_disc[3],
            r.q[0],
            r.q[1],
            r.q[2],
            r.q[3],
            r.mu_d[0],
            r.mu_d[1],
            r.mu_d[2],
            r.mu_d[3],
            r.a_x,
            r.service_demand,
            r.air_spring[0],
            r.air_spring[1],
            r.step_max_cycles,
            r.step_mean_cycles,
            r.overruns,
            r.missed_ticks,
            r.faults,
            r.sensor_faults,
            r.surfaces,
            r.seq,
            r.crc32()
        );
    }

    /// The surface under wheelset `j` (0-based).
    pub fn surface(&self, j: usize) -> hils_plant::Surface {
        let code = (self.surfaces >> (2 * (j & 3))) & 3;
        crate::can::surface_of_code(code).unwrap_or_default()
    }
}

impl RunHeader {
    /// Logs the header as a defmt `tlm1-start` line (`println`: not filtered by `DEFMT_LOG`).
    #[cfg(feature = "defmt")]
    pub fn log(&self) {
        let h = self;
        defmt::println!(
            "tlm1-start {=u8} {=u8} {=u8} {=f32} {=u32} {=u32} {=u32} {=u16} {=u8}",
            h.mode,
            h.rail,
            h.friction,
            h.initial_speed_kmh,
            h.step_ns,
            h.divider,
            h.cpu_hz,
            h.teeth,
            h.pressure_channels
        );
    }
}

/// Logs a `tlm1-end` line (`println`: not filtered by `DEFMT_LOG`).
#[cfg(feature = "defmt")]
pub fn log_end(step: u32, state: RigState) {
    defmt::println!("tlm1-end {=u32} {=u8}", step, state as u8);
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::format;
    use std::string::String;

    /// Writes a record as the decoder prints the defmt line (Rust `Display` of each value).
    fn text(r: &TelemetryRecord) -> String {
        let mut s = String::from(RECORD_TAG);
        r.for_each_value(|v| s += &format!(" {v}"));
        s + &format!(" {}", r.crc32())
    }

    fn sample() -> TelemetryRecord {
        TelemetryRecord {
            step: 41_000,
            state: 1,
            mode: 1,
            cmd: 1,
            driven: 0b101,
            valves: 0xFF_1A,
            v_ref: 38.5,
            omega: [88.1, 87.9, 1.0e-7, 0.0],
            p_cyl: [f32::NAN, 312_345.67, 0.1, 3.0e5],
            f_clamp: [17_664.1, f32::NAN, 0.0, -0.0],
            f_brake: [1.0, 2.0, 3.0, 4.0],
            t_disc: [12.5, 13.0, 14.0, 15.25],
            q: [99_000.0, 101_000.5, 98_000.25, 100_000.0],
            mu_d: [0.41, 0.39, 0.4, 0.42],
            a_x: -1.3889,
            service_demand: 0.8,
            air_spring: [5.05e5, f32::NAN],
            step_max_cycles: 9_000,
            step_mean_cycles: 7_000,
            overruns: 2,
            missed_ticks: 1,
            faults: 0x8001_0010,
            sensor_faults: 0x4010,
            surfaces: 0b11_10_01_00,
            seq: 410,
        }
    }

    fn same_bits(a: &TelemetryRecord, b: &TelemetryRecord) -> bool {
        let bits = |r: &TelemetryRecord| {
            let mut v = std::vec::Vec::new();
            r.for_each_value(|x| v.push(x.bits()));
            v
        };
        bits(a) == bits(b)
    }

    #[test]
    fn record_text_roundtrip_is_bit_exact_nan_and_signed_zero_included() {
        let r = sample();
        let line = text(&r);
        let Some(Line::Record(back)) = parse_line(&line).unwrap() else {
            panic!()
        };
        assert!(same_bits(&r, &back));
        assert_eq!(line.split_ascii_whitespace().count(), FIELDS.len() + 1);
    }

    #[test]
    fn probe_rs_log_line_prefixes_are_skipped() {
        let r = sample();
        let line = format!("4.100000 INFO  {}", text(&r));
        assert!(matches!(parse_line(&line), Ok(Some(Line::Record(_)))));
        assert_eq!(
            parse_line("└─ hils_rig_core::telemetry @ src/telemetry.rs:201"),
            Ok(None)
        );
        assert_eq!(parse_line("INFO  board started, self-test mode"), Ok(None));
        assert_eq!(parse_line(""), Ok(None));
    }

    #[test]
    fn header_and_end_lines() {
        let h = "tlm1-start 1 0 0 150 100000 100 170000000 90 5";
        assert_eq!(
            parse_line(h),
            Ok(Some(Line::Header(RunHeader {
                mode: 1,
                rail: 0,
                friction: 0,
                initial_speed_kmh: 150.0,
                step_ns: 100_000,
                divider: 100,
                cpu_hz: 170_000_000,
                teeth: 90,
                pressure_channels: 5
            })))
        );
        assert_eq!(
            parse_line("tlm1-end 290600 2"),
            Ok(Some(Line::End {
                step: 290_600,
                state: 2
            }))
        );
    }

    #[test]
    fn malformed_lines_name_the_field() {
        let r = sample();
        let line = text(&r);
        let short = line.rsplit_once(' ').unwrap().0;
        assert_eq!(
            parse_line(short),
            Err(ParseError::FieldCount {
                expected: 48,
                found: 47
            })
        );
        let bad = line.replacen(" 38.5 ", " 38.5x ", 1);
        assert_ne!(bad, line);
        let e = parse_line(&bad).unwrap_err();
        assert_eq!(e, ParseError::BadField { index: 6 });
        assert_eq!(std::format!("{e}"), "field 7 (`v_ref`) is not a number");
        // A u8 field holding 300.
        let bad = line.replacen("tlm1 41000 1", "tlm1 41000 300", 1);
        assert_eq!(parse_line(&bad), Err(ParseError::BadField { index: 1 }));
        assert_eq!(
            parse_line("tlm1-end 5"),
            Err(ParseError::FieldCount {
                expected: 2,
                found: 1
            })
        );
    }

    #[test]
    fn crc32_is_the_iso_hdlc_crc() {
        // The catalogue check value of CRC-32/ISO-HDLC.
        assert_eq!(!crc32_update(!0, b"123456789"), 0xCBF4_3926);
    }

    #[test]
    fn a_changed_value_fails_the_crc() {
        let r = sample();
        let line = text(&r);
        // v_ref 38.5 -> 38.25, p_cyl2 one digit lost, seq 410 -> 411.
        for (from, to) in [
            (" 38.5 ", " 38.25 "),
            (" 312345.66 ", " 312345.6 "),
            (" 410 ", " 411 "),
        ] {
            let bad = line.replacen(from, to, 1);
            assert_ne!(bad, line);
            assert!(
                matches!(parse_line(&bad), Err(ParseError::Crc { .. })),
                "{from}"
            );
        }
        // Every single-bit change of any field's binary value changes the CRC.
        let base = r.crc32();
        for bit in 0..32 {
            let mut m = r;
            m.v_ref = f32::from_bits(m.v_ref.to_bits() ^ (1 << bit));
            if m.v_ref.is_nan() {
                continue;
            }
            assert_ne!(m.crc32(), base, "v_ref bit {bit}");
            let mut m = r;
            m.faults ^= 1 << bit;
            assert_ne!(m.crc32(), base, "faults bit {bit}");
        }
    }

    proptest::proptest! {
        #[test]
        fn any_text_never_panics(s in "\\PC*") {
            let _ = parse_line(&s);
            let _ = parse_line(&format!("tlm1 {s}"));
        }

        #[test]
        fn any_float_roundtrips(x in proptest::num::f32::ANY) {
            let mut r = sample();
            r.omega[2] = x;
            r.a_x = x;
            let Some(Line::Record(back)) = parse_line(&text(&r)).unwrap() else { panic!() };
            proptest::prop_assert!(same_bits(&r, &back) || x.is_nan());
        }
    }
}
