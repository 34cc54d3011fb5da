//! `hils.dbc` against the frame codec, both ways, with an independent DBC parser (`can-dbc`)
//! and a bit-by-bit signal packer written here from the DBC definitions.
//!
//! Way 1: a frame made by the codec is decoded signal by signal from the DBC (start bit,
//! length, byte order, sign, factor, offset, float type, multiplexor) and every signal
//! equals the value given to the codec. Way 2: a frame packed from the DBC (with the
//! checksum signal set to the documented CRC) is decoded by the codec and gives the values
//! back. Every signal of every message (of every multiplexer value) is covered, and no
//! signal is left unchecked.

use std::collections::BTreeMap;

use can_dbc::{
    ByteOrder, Dbc, MessageId, MultiplexIndicator, Signal, SignalExtendedValueType, ValueType,
};
use embedded_can::{Frame, StandardId};
use hils_plant::{FrictionModel, Rail, Surface};
use hils_rig_core::Code;
use hils_rig_core::can::{
    self, BrakeCommand, BrakeDemandFrame, Calibration, Command, CommandFrame, CommandResult,
    ConfigItem, DiagFrame, HealthFrame, InjectedFault, RigMode, RigState, StartCommand,
    StatusFrame, TrackCommand, VehicleKey, WheelSpeedFrame, ZoneFrame,
};
use hils_rig_core::controller_io::IoItem;
use hils_rig_core::sensor::{SensorFault, SensorKind};
use hils_rig_core::valves::ValveStates;
use proptest::prelude::*;

type TestFrame = can::ClassicFrame;

fn dbc() -> Dbc {
    let text = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/hils.dbc")).unwrap();
    Dbc::try_from(text.as_str()).expect("hils.dbc parses")
}

fn is_float(dbc: &Dbc, id: u16, s: &Signal) -> bool {
    matches!(
        dbc.extended_value_type_for_signal(MessageId::Standard(id), &s.name),
        Some(SignalExtendedValueType::IEEEfloat32Bit)
    )
}

/// Raw bits of a little-endian (Intel) signal, bit by bit.
fn raw_bits(s: &Signal, data: &[u8]) -> u64 {
    assert_eq!(s.byte_order, ByteOrder::LittleEndian, "{}", s.name);
    let mut raw = 0u64;
    for i in 0..s.size {
        let bit = s.start_bit + i;
        let b = (data[(bit / 8) as usize] >> (bit % 8)) & 1;
        raw |= (b as u64) << i;
    }
    raw
}

/// Physical value of a signal from the DBC definition.
fn dbc_get(dbc: &Dbc, id: u16, s: &Signal, data: &[u8]) -> f64 {
    let raw = raw_bits(s, data);
    if is_float(dbc, id, s) {
        assert_eq!(s.size, 32);
        return f32::from_bits(raw as u32) as f64 * s.factor + s.offset;
    }
    let value = match s.value_type {
        ValueType::Unsigned => raw as f64,
        ValueType::Signed => {
            let shift = 64 - s.size;
            (((raw << shift) as i64) >> shift) as f64
        }
    };
    value * s.factor + s.offset
}

/// Packs a physical value into a signal from the DBC definition.
fn dbc_put(dbc: &Dbc, id: u16, s: &Signal, data: &mut [u8], value: f64) {
    let raw: u64 = if is_float(dbc, id, s) {
        (((value - s.offset) / s.factor) as f32).to_bits() as u64
    } else {
        let r = ((value - s.offset) / s.factor).round() as i64;
        match s.value_type {
            ValueType::Unsigned => {
                assert!(
                    r >= 0 && (r as u64) < (1u64 << s.size),
                    "{} = {value}",
                    s.name
                );
                r as u64
            }
            ValueType::Signed => {
                assert!(
                    r >= -(1i64 << (s.size - 1)) && r < (1i64 << (s.size - 1)),
                    "{}",
                    s.name
                );
                (r as u64) & ((1u64 << s.size) - 1)
            }
        }
    };
    for i in 0..s.size {
        let bit = s.start_bit + i;
        let byte = &mut data[(bit / 8) as usize];
        *byte &= !(1 << (bit % 8));
        *byte |= (((raw >> i) & 1) as u8) << (bit % 8);
    }
}

/// The signals of a message active for a multiplexer value (None: not multiplexed).
fn active_signals(dbc: &Dbc, id: u16, mux: Option<u64>) -> Vec<Signal> {
    let msg = dbc
        .messages
        .iter()
        .find(|m| m.id == MessageId::Standard(id))
        .expect("message");
    assert_eq!(msg.size, 8);
    msg.signals
        .iter()
        .filter(|s| match s.multiplexer_indicator {
            MultiplexIndicator::Plain | MultiplexIndicator::Multiplexor => true,
            MultiplexIndicator::MultiplexedSignal(v) => Some(v) == mux,
            MultiplexIndicator::MultiplexorAndMultiplexedSignal(_) => panic!("not used"),
        })
        .cloned()
        .collect()
}

type Fields = BTreeMap<&'static str, f64>;

/// Way 1 and way 2 for one message value. `fields` lists every active DBC signal's
/// expected physical value (checksum included: way 1 checks it, way 2 recomputes it).
fn both_ways<T>(
    id: u16,
    mux: Option<u64>,
    encoded: &TestFrame,
    fields: &Fields,
    decode: impl Fn(&TestFrame) -> T,
    fields_of: impl Fn(&T) -> Fields,
    checksum_signal: Option<&str>,
) {
    let dbc = dbc();
    let signals = active_signals(&dbc, id, mux);
    let names: Vec<&str> = signals.iter().map(|s| s.name.as_str()).collect();
    let mut want: Vec<&str> = fields.keys().copied().collect();
    want.sort();
    let mut got = names.clone();
    got.sort();
    assert_eq!(
        got, want,
        "DBC signals of {id:#x}/{mux:?} vs the codec's fields"
    );

    // Way 1: codec -> bytes -> DBC.
    for s in &signals {
        let v = dbc_get(&dbc, id, s, encoded.data());
        let expect = fields[s.name.as_str()];
        let tol = if is_float(&dbc, id, s) {
            0.0
        } else {
            s.factor * 0.5 + 1e-9
        };
        assert!(
            (v - expect).abs() <= tol,
            "{}: DBC reads {v}, codec was given {expect}",
            s.name
        );
    }

    // Way 2: DBC -> bytes -> codec.
    let mut data = [0u8; 8];
    for s in &signals {
        if Some(s.name.as_str()) != checksum_signal {
            dbc_put(&dbc, id, s, &mut data, fields[s.name.as_str()]);
        }
    }
    if let Some(cs) = checksum_signal {
        let s = signals.iter().find(|s| s.name == cs).unwrap();
        let crc = can::checksum(id, &data);
        dbc_put(&dbc, id, s, &mut data, crc as f64);
    }
    let frame = TestFrame::new(StandardId::new(id).unwrap(), &data).unwrap();
    let back = fields_of(&decode(&frame));
    for (k, v) in fields {
        if Some(*k) == checksum_signal {
            continue;
        }
        let s = signals.iter().find(|s| s.name == *k).unwrap();
        let tol = if is_float(&dbc, id, s) {
            0.0
        } else {
            s.factor * 0.5 + 1e-9
        };
        assert!(
            (back[k] - v).abs() <= tol,
            "{k}: codec reads {}, DBC packed {v}",
            back[k]
        );
    }
}

fn checksum_of(f: &TestFrame) -> f64 {
    (f.data()[7] >> 4) as f64
}

fn wheel_fields(w: &WheelSpeedFrame, frame: Option<&TestFrame>) -> Fields {
    let mut m = Fields::new();
    let (names, alive, crc) = match w.pair {
        0 => (
            ["WheelSpeed1", "WheelSpeed2"],
            "WheelSpeed12Alive",
            "WheelSpeed12Checksum",
        ),
        _ => (
            ["WheelSpeed3", "WheelSpeed4"],
            "WheelSpeed34Alive",
            "WheelSpeed34Checksum",
        ),
    };
    for (j, n) in names.iter().enumerate() {
        // Not available: raw 0xFFFF = 655.35 km/h in the DBC's scaling.
        m.insert(n, w.speeds_kmh[j].map(|v| v as f64).unwrap_or(655.35));
    }
    // The valve inputs of the pair's wheelsets: 0 off, 1 energised, 3 not wired.
    const VALVE_NAMES: [[&str; 2]; 4] = [
        ["Dump1", "Hold1"],
        ["Dump2", "Hold2"],
        ["Dump3", "Hold3"],
        ["Dump4", "Hold4"],
    ];
    let code = |x: Option<bool>| x.map_or(3.0, |on| on as u8 as f64);
    for j in 2 * w.pair..2 * w.pair + 2 {
        m.insert(VALVE_NAMES[j][0], code(w.valves.dump(j)));
        m.insert(VALVE_NAMES[j][1], code(w.valves.hold(j)));
    }
    m.insert(alive, w.counter as f64);
    m.insert(crc, frame.map(checksum_of).unwrap_or(0.0));
    m
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 200, ..Default::default() })]

    /// Both wheel-speed frames over the whole 16-bit range, half the cases at or above
    /// 350 km/h (raw 35 000).
    #[test]
    fn wheel_speed_frames(speeds in proptest::array::uniform4(proptest::option::weighted(0.9,
                              prop_oneof![0u32..=65534, 35_000u32..=65534])), counter in 0u8..16,
                          valve_bits: u16) {
        let kmh = speeds.map(|s| s.map(|r| r as f32 * 0.01));
        let valves = ValveStates::of_bits(valve_bits);
        for w in WheelSpeedFrame::cycle(kmh, valves, counter) {
            let f: TestFrame = w.encode().unwrap();
            let checksum = if w.pair == 0 { "WheelSpeed12Checksum" } else { "WheelSpeed34Checksum" };
            both_ways(w.id().unwrap(), None, &f, &wheel_fields(&w, Some(&f)),
                |f| WheelSpeedFrame::decode(f).unwrap(), |w| wheel_fields(w, None), Some(checksum));
        }
    }

    #[test]
    fn status_frame(speed in 0u32..=65535, decel in -32768i32..=32767, state in 0u8..6, mode in 0u8..2,
                    result in 0u8..3, faults: u16, counter in 0u8..16) {
        let s = StatusFrame {
            vehicle_speed_kmh: speed as f32 * 0.01,
            deceleration_mps2: decel as f32 * 0.001,
            state: RigState::from_raw(state).unwrap(),
            mode: RigMode::from_raw(mode).unwrap(),
            command_result: CommandResult::from_raw(result).unwrap(),
            faults,
            counter,
        };
        let fields = |s: &StatusFrame, f: Option<&TestFrame>| -> Fields {
            Fields::from([
                ("VehicleSpeed", s.vehicle_speed_kmh as f64),
                ("Deceleration", s.deceleration_mps2 as f64),
                ("RigState", s.state as u8 as f64),
                ("RigMode", s.mode as u8 as f64),
                ("CommandResult", s.command_result as u8 as f64),
                ("FaultFlags", s.faults as f64),
                ("StatusAlive", s.counter as f64),
                ("StatusChecksum", f.map(checksum_of).unwrap_or(0.0)),
            ])
        };
        let f: TestFrame = s.encode().unwrap();
        both_ways(can::ID_STATUS, None, &f, &fields(&s, Some(&f)),
            |f| StatusFrame::decode(f).unwrap(), |s| fields(s, None), Some("StatusChecksum"));
    }

    #[test]
    fn brake_demand_frame(closed: bool, demand in 0u32..=65535, counter in 0u8..16) {
        let d = BrakeDemandFrame { eb_loop_closed: closed, service_mps2: demand as f32 * 0.001, counter };
        let fields = |d: &BrakeDemandFrame, f: Option<&TestFrame>| -> Fields {
            Fields::from([
                ("EbLoopClosed", d.eb_loop_closed as u8 as f64),
                ("ServiceDemand", d.service_mps2 as f64),
                ("DemandAlive", d.counter as f64),
                ("DemandChecksum", f.map(checksum_of).unwrap_or(0.0)),
            ])
        };
        let f: TestFrame = d.encode().unwrap();
        both_ways(can::ID_BRAKE_DEMAND, None, &f, &fields(&d, Some(&f)),
            |f| BrakeDemandFrame::decode(f).unwrap(), |d| fields(d, None), Some("DemandChecksum"));
    }

    #[test]
    fn diag_frame(max in 0u32..=65535, mean in 0u32..=65535, overruns: u16, sensors in proptest::array::uniform4(0u8..6), bus_off in 0u8..16) {
        let d = DiagFrame {
            step_max_us: max as f32 * 0.01,
            step_mean_us: mean as f32 * 0.01,
            overruns,
            sensor_faults: sensors.map(|c| SensorFault::from_code(c).unwrap()),
            bus_off_count: bus_off,
        };
        let fields = |d: &DiagFrame| -> Fields {
            let mut m = Fields::from([
                ("StepTimeMax", d.step_max_us as f64),
                ("StepTimeMean", d.step_mean_us as f64),
                ("Overruns", d.overruns as f64),
                ("BusOffCount", d.bus_off_count as f64),
            ]);
            for (j, n) in ["SensorFault1", "SensorFault2", "SensorFault3", "SensorFault4"].iter().enumerate() {
                m.insert(n, SensorFault::code(d.sensor_faults[j]) as f64);
            }
            m
        };
        let f: TestFrame = d.encode().unwrap();
        both_ways(can::ID_DIAG, None, &f, &fields(&d), |f| DiagFrame::decode(f).unwrap(), fields, None);
    }

    #[test]
    fn health_frame(peak in 0u32..=65535, size in 0u32..=65535, rx_lost: u8, adc: u8,
                    cause in proptest::option::of(0u8..5), resets in 0u8..16, counter in 0u8..16) {
        use hils_rig_core::arming::Disarm;
        let h = HealthFrame {
            stack_peak_bytes: peak * 4,
            stack_size_bytes: size * 4,
            rx_lost,
            adc_restarts: adc,
            disarmed: cause.map(|c| Disarm::try_from(c).unwrap()),
            fault_resets: resets,
            counter,
        };
        let fields = |h: &HealthFrame, f: Option<&TestFrame>| -> Fields {
            Fields::from([
                ("StackPeak", h.stack_peak_bytes as f64),
                ("StackSize", h.stack_size_bytes as f64),
                ("RxLost", h.rx_lost as f64),
                ("AdcRestarts", h.adc_restarts as f64),
                ("Armed", h.disarmed.is_none() as u8 as f64),
                ("DisarmCause", h.disarmed.map_or(0, u8::from) as f64),
                ("FaultResets", h.fault_resets as f64),
                ("HealthAlive", h.counter as f64),
                ("HealthChecksum", f.map(checksum_of).unwrap_or(0.0)),
            ])
        };
        let f: TestFrame = h.encode().unwrap();
        both_ways(can::ID_HEALTH, None, &f, &fields(&h, Some(&f)),
            |f| HealthFrame::decode(f).unwrap(), |h| fields(h, None), Some("HealthChecksum"));
    }

    #[test]
    fn command_frame(pick in 0usize..15, a in 0u32..=16382, b in 0u32..=10000, ch in 0u8..4, k in 0u8..5,
                     flags in 0u8..32, gain in 0.001f32..1.0e6, counter in 0u8..16,
                     zone in (0u32..(1 << 20), 0u32..(1 << 20), 0u8..32, 0u8..4, 1u8..=255),
                     digest in 0u16..=u16::MAX) {
        let surface = |c: u8| [Surface::Dry, Surface::Wet, Surface::Low, Surface::VeryLow][c as usize % 4];
        let command = match pick {
            0 => Command::Start(StartCommand {
                mode: if flags & 1 == 0 { RigMode::Rig } else { RigMode::SelfTest },
                rail: if flags & 2 == 0 { Rail::Wet } else { Rail::Dry },
                friction: if flags & 4 == 0 { FrictionModel::Variable } else { FrictionModel::Constant },
                emergency: flags & 8 != 0,
                initial_speed_kmh: a as f32 * 0.01,
                track: flags & 16 != 0,
                setup_digest: digest,
            }),
            1 => Command::Stop,
            2 => Command::Brake(match k % 4 {
                0 => BrakeCommand::Release,
                1 => BrakeCommand::Emergency,
                2 => BrakeCommand::Service { deceleration_mps2: b as f32 * 0.001 },
                _ => BrakeCommand::ServiceStep { step: zone.4 },
            }),
            3 => Command::InjectFault { channel: ch, fault: match k {
                0 => None, 1 => Some(InjectedFault::Open), 2 => Some(InjectedFault::Short),
                3 => Some(InjectedFault::Stuck), _ => Some(InjectedFault::OutOfRange) } },
            4 => Command::Calibrate { channel: ch, action: Calibration::Tare },
            5 => Command::Calibrate { channel: ch, action: if k % 2 == 0 { Calibration::SetGain(gain) } else { Calibration::SetOffset(gain.min(4095.0)) } },
            6 => Command::Calibrate { channel: ch, action: Calibration::SetKind(if k % 2 == 0 { SensorKind::LoadCell } else { SensorKind::PressureTransducer }) },
            7 => Command::ClearFaults,
            12 => Command::Arm,
            13 => Command::Disarm,
            9 => Command::TrackZone { index: zone.2, zone: ZoneFrame {
                start_dm: zone.0, end_dm: zone.1, surface: surface(zone.3) } },
            10 => Command::Track(if flags & 1 == 0 { TrackCommand::Clear } else {
                TrackCommand::Commit { base: surface(zone.3), zones: zone.2 } }),
            11 => if flags & 1 == 0 {
                Command::Vehicle { key: VehicleKey::Default, value: 0.0 } // value unused
            } else {
                Command::Vehicle { key: VehicleKey::VALUES[k as usize], value: gain }
            },
            8 => {
                let item = IoItem::ALL[(a as usize) % IoItem::ALL.len()];
                let (lo, hi) = item.range();
                Command::Configure(ConfigItem::Io(item, lo + (b as u16) % (hi - lo + 1)))
            }
            _ => Command::Configure(if k % 2 == 0 { ConfigItem::TelemetryDivider(b.max(1) as u16) } else { ConfigItem::Teeth((b % 1000).max(1) as u16) }),
        };
        let cf = CommandFrame { command, counter };
        let fields = |cf: &CommandFrame, f: Option<&TestFrame>| -> Fields {
            let mut m = Fields::new();
            m.insert("Opcode", cf.command.opcode() as f64);
            m.insert("CommandAlive", cf.counter as f64);
            m.insert("CommandChecksum", f.map(checksum_of).unwrap_or(0.0));
            match cf.command {
                Command::Start(StartCommand { mode, rail, friction, emergency, initial_speed_kmh, track, setup_digest }) => {
                    m.insert("StartTrack", track as u8 as f64);
                    m.insert("StartDigest", setup_digest as f64);
                    m.insert("StartMode", mode as u8 as f64);
                    m.insert("StartRail", (rail == Rail::Dry) as u8 as f64);
                    m.insert("StartFriction", (friction == FrictionModel::Constant) as u8 as f64);
                    m.insert("StartEmergency", emergency as u8 as f64);
                    m.insert("StartSpeed", initial_speed_kmh as f64);
                }
                Command::Brake(b) => {
                    m.insert(
                        "BrakeDemand",
                        match b {
                            BrakeCommand::Release => 0.0,
                            BrakeCommand::Emergency => 1.0,
                            BrakeCommand::Service { .. } => 2.0,
                            BrakeCommand::ServiceStep { .. } => 3.0,
                        },
                    );
                    let decel = if let BrakeCommand::Service { deceleration_mps2 } = b { deceleration_mps2 } else { 0.0 };
                    m.insert("ServiceDeceleration", decel as f64);
                    let step = if let BrakeCommand::ServiceStep { step } = b { step } else { 0 };
                    m.insert("ServiceStep", step as f64);
                }
                Command::InjectFault { channel, fault } => {
                    m.insert("FaultChannel", channel as f64);
                    m.insert("InjectedFault", match fault {
                        None => 0.0, Some(InjectedFault::Open) => 1.0, Some(InjectedFault::Short) => 2.0,
                        Some(InjectedFault::Stuck) => 3.0, Some(InjectedFault::OutOfRange) => 4.0 });
                }
                Command::Calibrate { channel, action } => {
                    m.insert("CalChannel", channel as f64);
                    let (code, value) = match action {
                        Calibration::Tare => (0.0, 0.0),
                        Calibration::SetGain(g) => (1.0, g as f64),
                        Calibration::SetOffset(o) => (2.0, o as f64),
                        Calibration::SetKind(k) => (3.0, k as u8 as f64),
                    };
                    m.insert("CalAction", code);
                    m.insert("CalValue", value);
                }
                Command::Configure(item) => {
                    let (code, v) = match item {
                        ConfigItem::TelemetryDivider(v) => (0.0, v),
                        ConfigItem::Teeth(v) => (1.0, v),
                        ConfigItem::Io(item, v) => (u8::from(item) as f64, v),
                    };
                    m.insert("ConfigItem", code);
                    m.insert("ConfigValue", v as f64);
                }
                Command::TrackZone { index, zone } => {
                    let code = |s: Surface| match s { Surface::Dry => 0.0, Surface::Wet => 1.0, Surface::Low => 2.0, Surface::VeryLow => 3.0 };
                    m.insert("ZoneIndex", index as f64);
                    m.insert("ZoneSurface", code(zone.surface));
                    m.insert("ZoneStart", zone.start_dm as f64 * 0.1);
                    m.insert("ZoneEnd", zone.end_dm as f64 * 0.1);
                }
                Command::Track(t) => {
                    let (action, base, zones) = match t {
                        TrackCommand::Clear => (0.0, 0.0, 0.0),
                        TrackCommand::Commit { base, zones } => (1.0, match base { Surface::Dry => 0.0, Surface::Wet => 1.0, Surface::Low => 2.0, Surface::VeryLow => 3.0 }, zones as f64),
                    };
                    m.insert("TrackAction", action);
                    m.insert("TrackBase", base);
                    m.insert("TrackZones", zones);
                }
                Command::Vehicle { key, value } => {
                    let code = match key { VehicleKey::CarbodyMass => 0.0, VehicleKey::CarbodyPitchInertia => 1.0,
                        VehicleKey::BogieMass => 2.0, VehicleKey::WheelsetMass => 3.0, VehicleKey::WheelRadius => 4.0, VehicleKey::Default => 255.0 };
                    m.insert("VehicleKey", code);
                    m.insert("VehicleValue", value as f64);
                }
                Command::Stop | Command::ClearFaults | Command::Arm | Command::Disarm => {}
            }
            m
        };
        let f: TestFrame = cf.encode().unwrap();
        both_ways(can::ID_COMMAND, Some(command.opcode() as u64), &f, &fields(&cf, Some(&f)),
            |f| CommandFrame::decode(f).unwrap(), |c| fields(c, None), Some("CommandChecksum"));
    }
}

#[test]
fn dbc_describes_exactly_the_codec_messages_and_no_signals_overlap() {
    let dbc = dbc();
    let ids: Vec<u32> = dbc.messages.iter().map(|m| m.id.raw()).collect();
    assert_eq!(ids, vec![0x100, 0x101, 0x102, 0x110, 0x120, 0x121, 0x200]);
    for m in &dbc.messages {
        let MessageId::Standard(id) = m.id else {
            panic!()
        };
        let muxes: Vec<Option<u64>> = if id == can::ID_COMMAND {
            (1..=12).map(Some).collect()
        } else {
            vec![None]
        };
        for mux in muxes {
            let mut used = 0u64;
            for s in active_signals(&dbc, id, mux) {
                let mask = if s.size == 64 {
                    u64::MAX
                } else {
                    ((1u64 << s.size) - 1) << s.start_bit
                };
                assert_eq!(used & mask, 0, "{} overlaps in {id:#x}", s.name);
                assert!(s.start_bit + s.size <= 64);
                used |= mask;
            }
        }
    }
    // The cycle times the board keeps.
    let cycle = |id: u16| match dbc.message_attribute(MessageId::Standard(id), "GenMsgCycleTime") {
        Some(can_dbc::AttributeValue::Uint(v)) => *v as i64,
        Some(can_dbc::AttributeValue::Int(v)) => *v,
        other => panic!("{other:?}"),
    };
    assert_eq!(
        (
            cycle(0x100),
            cycle(0x102),
            cycle(0x110),
            cycle(0x120),
            cycle(0x121)
        ),
        (1, 10, 10, 100, 100)
    );
}

/// The signal tables that the codec encodes and decodes with (`can::FRAMES`) are the DBC's
/// signals: the same names, start bits, lengths, byte order, scales, offsets and signs,
/// and no signal or message missing on either side.
#[test]
fn signal_tables_are_the_dbc() {
    let dbc = dbc();
    assert_eq!(dbc.messages.len(), can::FRAMES.len(), "messages");
    for (id, table) in can::FRAMES {
        let msg = dbc
            .messages
            .iter()
            .find(|m| m.id == MessageId::Standard(id))
            .unwrap_or_else(|| panic!("{id:#x} is not in hils.dbc"));
        let mut theirs: Vec<&str> = msg.signals.iter().map(|s| s.name.as_str()).collect();
        let mut ours: Vec<&str> = table.iter().map(|s| s.name).collect();
        theirs.sort();
        ours.sort();
        assert_eq!(ours, theirs, "signals of {id:#x}");
        for t in table {
            let s = msg.signals.iter().find(|s| s.name == t.name).unwrap();
            assert_eq!(s.byte_order, ByteOrder::LittleEndian, "{}", t.name);
            assert_eq!(
                (t.start as u64, t.len as u64),
                (s.start_bit, s.size),
                "{}: start, length",
                t.name
            );
            assert!(
                (t.scale as f64 - s.factor).abs() <= 1e-6 * s.factor.abs(),
                "{}: scale {} vs {}",
                t.name,
                t.scale,
                s.factor
            );
            assert_eq!(t.offset as f64, s.offset, "{}: offset", t.name);
            assert_eq!(
                t.signed,
                s.value_type == ValueType::Signed,
                "{}: sign",
                t.name
            );
        }
    }
}
