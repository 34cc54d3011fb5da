//! Scripted runs, the same on the target and on the host: the self-test telemetry run
//! ([`run`]) and the rig's cost sequence ([`CostRun`], `hils target-cost --rig`).
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

use hils_plant::{FrictionModel, Rail};

use crate::can::{Calibration, ClassicFrame, Command, RigMode, StartCommand};
use crate::digest::setup_digest;
use crate::hw::{RigIo, TelemetryEvent};
use crate::pulse::PulseRegisters;
use crate::rig::{Rig, RigConfig};
use crate::sensor::{ADC_SEQUENCE_LEN, InjectedFault, SensorKind};

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

/// The scripted starts, here beside the scripts that give them rather than in the frame
/// codec ([`crate::can`]), which so needs no digest.
impl Command {
    /// Start of the paper's scenario in self-test mode: 150 km/h, wet rail, EB at t = 0,
    /// on the default vehicle (its [`setup_digest`]; the board's user button
    /// stamps the kept vehicle's instead, [`crate::rig::Rig::on_kept_setup`]).
    pub fn paper_self_test(friction: FrictionModel) -> Command {
        Command::Start(StartCommand {
            mode: RigMode::SelfTest,
            rail: Rail::Wet,
            friction,
            emergency: true,
            initial_speed_kmh: 150.0,
            track: false,
            setup_digest: setup_digest(None, &Default::default()),
        })
    }
}

/// Ticks of the cost sequence ([`cost_command`]).
pub const COST_TICKS: u32 = 21_400;

/// The command the cost sequence (issue 11, `hils target-cost --rig`) gives at tick `k`,
/// carried out in that tick's step: the self-test paper scenario started and run 2 s,
/// stopped, armed, restarted in rig mode (measured brake inputs, 120 km/h), a sensor fault
/// injected (the run faults), removed, cleared, then a calibration (tare, gain, kind).
pub fn cost_command(k: u32) -> Option<Command> {
    let inject = |fault| Command::InjectFault { channel: 1, fault };
    let calibrate = |action| Command::Calibrate { channel: 0, action };
    Some(match k {
        0 => Command::paper_self_test(FrictionModel::Variable),
        20_000 => Command::Stop,
        20_005 => Command::Arm,
        20_010 => Command::Start(StartCommand {
            mode: RigMode::Rig,
            rail: Rail::Dry,
            friction: FrictionModel::Constant,
            emergency: false,
            initial_speed_kmh: 120.0,
            track: false,
            setup_digest: setup_digest(None, &Default::default()),
        }),
        21_010 => inject(Some(InjectedFault::Open)),
        21_100 => inject(None),
        21_200 => Command::ClearFaults,
        21_300 => calibrate(Calibration::Tare),
        21_310 => calibrate(Calibration::SetGain(10.5)),
        21_320 => calibrate(Calibration::SetKind(SensorKind::PressureTransducer)),
        _ => return None,
    })
}

/// The cost sequence on a rig with a mock board (live-zero ADC, queues that never fill).
pub struct CostRun {
    rig: Rig,
    io: ScriptIo<fn(&TelemetryEvent)>,
    tick: u32,
    rejected: u32,
}

impl Default for CostRun {
    fn default() -> Self {
        Self::new()
    }
}

impl CostRun {
    /// A rig on the Nucleo board with a mock board, before the first tick.
    pub fn new() -> Self {
        Self {
            rig: Rig::new(RigConfig::nucleo_g474re()),
            io: ScriptIo {
                tick: 0,
                sink: |_| {},
                frames: 0,
            },
            tick: 0,
            rejected: 0,
        }
    }

    /// One tick as the board's step interrupt does it: the sequence's command, if any, and
    /// `Rig::step`. `false` once the sequence is over (nothing done). Inline: compiled in
    /// the caller's crate, so `Rig::step` and `Rig::command` are too, at its optimisation
    /// level (the emulator's, set alike to the board's: Cargo.toml), as on the board,
    /// where the board crate instantiates them; not at rig-core's.
    #[inline]
    pub fn tick(&mut self) -> bool {
        if self.tick >= COST_TICKS {
            return false;
        }
        if let Some(c) = cost_command(self.tick)
            && self.rig.command(c).is_err()
        {
            self.rejected += 1;
        }
        self.rig.step(&mut self.io);
        self.tick += 1;
        true
    }

    /// Thread-mode work between ticks (building a requested run): not part of the step.
    #[inline]
    pub fn between_ticks(&mut self) {
        if self.rig.build_pending().is_err() {
            self.rejected += 1;
        }
    }

    /// The rig, for its state and counters.
    pub fn rig(&self) -> &Rig {
        &self.rig
    }

    /// Commands the rig refused (0 for the sequence as written).
    pub fn rejected(&self) -> u32 {
        self.rejected
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::can::RigState;

    /// The sequence reaches every state it is meant to exercise, with no command refused.
    #[test]
    fn the_cost_sequence_goes_through_each_phase() {
        let mut run = CostRun::new();
        let mut states = std::vec::Vec::new();
        while run.tick() {
            let s = run.rig().state();
            if states.last() != Some(&s) {
                states.push(s);
            }
            run.between_ticks();
        }
        assert_eq!(run.rejected(), 0);
        assert_eq!(
            states,
            [
                RigState::Starting,
                RigState::Running,
                RigState::Stopped,
                RigState::Starting,
                RigState::Running,
                RigState::Fault,
                RigState::Stopped
            ]
        );
        assert_eq!(run.rig().mode(), RigMode::Rig);
        assert_eq!(run.rig().sensors[0].kind, SensorKind::PressureTransducer);
    }
}
