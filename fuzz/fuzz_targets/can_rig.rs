//! The CAN frame decoders and the rig's command handler with rig steps: arbitrary frames
//! (any identifier, length, payload) to every decoder and to `Rig::command_frame`, direct
//! commands (starts half the time with the kept setup's digest), sealed (valid checksum) frames of the track, track-zone and vehicle opcodes with
//! arbitrary payloads, builds of requested runs (on the kept track and vehicle), and steps
//! with arbitrary ADC sequences (or none). Invariants: a decoded frame re-encodes to the
//! same payload; in Idle, Stopped and Fault every pulse train is silent and every wheel
//! speed (state and sent frame) is "not available"; unless the rig is armed and runs in
//! rig mode (the arming gate), the same holds in every state; a kept track has at most 16 zones, each
//! not empty, in order and disjoint, and makes the plant's track.
#![no_main]

use embedded_can::{Frame, StandardId};
use hils_fuzz::Bytes;
use hils_rig_core::can::{
    ClassicFrame, CommandFrame, DiagFrame, HealthFrame, ID_COMMAND, ID_WHEEL_SPEEDS, Opcode,
    RigMode, RigState, StatusFrame, WheelSpeedFrame, checksum,
};
use hils_rig_core::hw::{RigIo, TelemetryEvent};
use hils_rig_core::pulse::PulseRegisters;
use hils_rig_core::rig::{Rig, RigConfig};
use hils_rig_core::sensor::ADC_SEQUENCE_LEN;
use libfuzzer_sys::fuzz_target;

struct FuzzIo {
    adc: Option<[u16; ADC_SEQUENCE_LEN]>,
    pulses: [Option<PulseRegisters>; 4],
    frames: Vec<ClassicFrame>,
}

impl RigIo for FuzzIo {
    type Frame = ClassicFrame;
    fn adc_sequence(&mut self) -> Option<[u16; ADC_SEQUENCE_LEN]> {
        self.adc
    }
    fn set_pulse(&mut self, wheelset: usize, registers: &PulseRegisters) {
        self.pulses[wheelset] = Some(*registers);
    }
    fn queue_frame(&mut self, frame: ClassicFrame) -> bool {
        self.frames.push(frame);
        true
    }
    fn queue_telemetry(&mut self, _: &TelemetryEvent) -> bool {
        true
    }
}

/// A frame from the bytes: identifier (mostly near the rig's), length 0-8, payload.
fn frame(b: &mut Bytes) -> ClassicFrame {
    let sel = b.u8();
    let id = match sel % 5 {
        0 => ID_COMMAND,
        1 => ID_WHEEL_SPEEDS[0],
        2 => ID_WHEEL_SPEEDS[1],
        _ => b.u16() & 0x7FF,
    };
    let len = (b.u8() % 9) as usize;
    let payload = b.take(len).to_vec();
    ClassicFrame::new(StandardId::new(id).unwrap(), &payload).unwrap()
}

/// Decodes with every decoder; what decodes re-encodes to the same payload.
fn decoders(f: &ClassicFrame) {
    macro_rules! round_trip {
        ($($frame:ident),*) => {$(
            if let Ok(x) = $frame::decode(f) {
                let again: ClassicFrame = x.encode().expect("re-encode");
                assert_eq!($frame::decode(&again), Ok(x));
            }
        )*};
    }
    round_trip!(WheelSpeedFrame, StatusFrame, DiagFrame, HealthFrame, CommandFrame);
}

/// A sealed command frame of the track, track-zone or vehicle opcode with payload bytes
/// from the fuzzer (the checksum right, so the board's checks past the CRC are reached).
fn sealed_track_frame(b: &mut Bytes) -> ClassicFrame {
    let opcode = [Opcode::TrackZone, Opcode::Track, Opcode::Vehicle][b.u8() as usize % 3];
    let mut d = [0u8; 8];
    d[0] = opcode.into();
    d[1..7].copy_from_slice(&core::array::from_fn::<u8, 6, _>(|_| b.u8()));
    d[7] = b.u8() & 0x0F;
    d[7] |= checksum(ID_COMMAND, &d) << 4;
    ClassicFrame::new(StandardId::new(ID_COMMAND).unwrap(), &d).unwrap()
}

/// The kept track's invariants.
fn check_track(rig: &Rig) {
    if let Some(t) = rig.track() {
        let z = t.zones();
        assert!(z.len() <= 16);
        for (i, zone) in z.iter().enumerate() {
            assert!(zone.end_dm > zone.start_dm, "{z:?}");
            if i > 0 {
                assert!(zone.start_dm >= z[i - 1].end_dm, "{z:?}");
            }
        }
        assert!(t.track().is_ok(), "{t:?}");
    }
}

fn check_safe_state(rig: &Rig, io: &FuzzIo) {
    // Not armed, or a self-test run: no output a controller reads moves (arming gate).
    let unarmed = !rig.arming().is_armed() || rig.mode() == RigMode::SelfTest;
    let safe = unarmed
        || matches!(
            rig.state(),
            RigState::Idle | RigState::Stopped | RigState::Fault
        );
    // `Finished` (at rest) is silent too; its speeds are 0.00 km/h, not "not available".
    if safe || rig.state() == RigState::Finished {
        assert!(
            rig.pulses().iter().all(|p| p.is_silent()),
            "{:?}",
            rig.state()
        );
        for p in io.pulses.iter().flatten() {
            assert!(p.is_silent(), "pulse written in {:?}", rig.state());
        }
    }
    if safe {
        assert_eq!(rig.wheel_speeds_kmh(), [None; 4], "{:?}", rig.state());
        for f in &io.frames {
            if let Ok(w) = WheelSpeedFrame::decode(f) {
                assert_eq!(w.speeds_kmh, [None; 2], "speeds sent in {:?}", rig.state());
            }
        }
    }
}

fuzz_target!(|data: &[u8]| {
    let mut b = Bytes(data);
    let mut rig = Rig::new(RigConfig::nucleo_g474re());
    let mut io = FuzzIo {
        adc: None,
        pulses: [None; 4],
        frames: Vec::new(),
    };
    while !b.is_empty() {
        match b.u8() % 6 {
            0 => {
                let f = frame(&mut b);
                decoders(&f);
                let _ = rig.command_frame(&f);
            }
            1 => {
                // A well-formed command frame (valid checksum) from a decoded command.
                let f = frame(&mut b);
                if let Ok(c) = CommandFrame::decode(&f) {
                    // Half the starts carry the kept setup's digest (else a run would
                    // almost never start: a 16-bit digest to guess).
                    let c = if b.u8() % 2 == 0 {
                        rig.on_kept_setup(c.command)
                    } else {
                        c.command
                    };
                    let _ = rig.command(c);
                }
            }
            2 | 3 => {
                let f = sealed_track_frame(&mut b);
                decoders(&f);
                let _ = rig.command_frame(&f);
                check_track(&rig);
                if b.u8() % 8 == 0 {
                    // Build a requested run here, as the board's builder would.
                    let _ = rig.build_pending();
                }
            }
            _ => {
                let steps = 1 + b.u8() as usize % 32;
                io.adc = match b.u8() % 4 {
                    0 => None,
                    1 => Some([b.u16() & 0x0FFF; ADC_SEQUENCE_LEN]),
                    _ => Some(core::array::from_fn(|_| 400 + (b.u8() as u16) * 4)),
                };
                for _ in 0..steps {
                    io.frames.clear();
                    io.pulses = [None; 4];
                    rig.step(&mut io);
                    check_safe_state(&rig, &io);
                }
            }
        }
    }
});
