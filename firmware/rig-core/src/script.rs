//! A scripted self-test run, the same on the target and on the host.
//!
//! The telemetry fixture (`firmware/rig-fixture`, run in QEMU) and the host test of
//! `hils decode` both call [`run`]: the first logs the events with defmt (real defmt frames
//! from a thumbv7em build), the second collects them and compares what the decoder reads
//! from those frames with them, value by value and bit by bit.
//!
//! The script: the paper's scenario in self-test mode (150 km/h, wet rail, variable
//! friction, EB at t = 0) for [`STEPS`] plant steps, then a `Stop` command and one more
//! step. The ADC reads live-zero counts with a deterministic noise pattern; the step
//! timing is synthetic (QEMU has no cycle counter): 5000 to 5600 cycles.

use hils_plant::FrictionModel;

use crate::can::{ClassicFrame, Command};
use crate::hw::{RigIo, TelemetryEvent};
use crate::pulse::PulseRegisters;
use crate::rig::{Rig, RigConfig};
use crate::sensor::ADC_SEQUENCE_LEN;

/// Plant steps of the scripted run (6 s: the EB, the WSP onsets near 4 s).
pub const STEPS: u32 = 60_000;

struct ScriptIo<S: FnMut(&TelemetryEvent)> {
    tick: u32,
    sink: S,
    frames: u32,
}

impl<S: FnMut(&TelemetryEvent)> RigIo for ScriptIo<S> {
    type Frame = ClassicFrame;
    fn adc_sequence(&mut self) -> Option<[u16; ADC_SEQUENCE_LEN]> {
        self.tick = self.tick.wrapping_add(1);
        let t = self.tick;
        Some(core::array::from_fn(|rank| {
            410 + ((t as usize * 7 + rank * 13) % 5) as u16
        }))
    }
    fn set_pulse(&mut self, _: usize, _: &PulseRegisters) {}
    fn queue_frame(&mut self, _: ClassicFrame) -> bool {
        self.frames = self.frames.wrapping_add(1);
        true
    }
    fn queue_telemetry(&mut self, event: &TelemetryEvent) -> bool {
        (self.sink)(event);
        true
    }
}

/// Runs the script, handing every telemetry event to `sink` in order. Returns the number
/// of CAN frames the run queued.
pub fn run(sink: impl FnMut(&TelemetryEvent)) -> u32 {
    let mut rig = Rig::new(RigConfig::nucleo_g474re());
    let mut io = ScriptIo {
        tick: 0,
        sink,
        frames: 0,
    };
    let start = Command::paper_self_test(FrictionModel::Variable);
    // The start cannot fail with the built-in parameters; if it did, the log would show
    // no header and the host check would fail.
    let _ = rig.command(start).and_then(|_| rig.build_pending());
    for k in 0..STEPS {
        rig.step(&mut io);
        let entry = k.wrapping_mul(17_000);
        rig.record_timing(entry, entry.wrapping_add(5_000 + (k % 7) * 100), false);
    }
    let _ = rig.command(Command::Stop);
    rig.step(&mut io);
    io.frames
}
