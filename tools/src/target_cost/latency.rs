//! The rig's input-to-output latency (issue 21 item 4; the paper names latency as the
//! accuracy limit of a HILS), in steps of the board's own logic (`hils_rig_core::rig::Rig`,
//! the code the board runs, stepped on the host with a mock of its pins) and in
//! microseconds:
//!
//! * **brake input -> pulse train**: a step change of the four brake inputs (0 -> 500 kPa
//!   of cylinder pressure) in the ADC sequence a tick reads; the tick whose pulse-timer
//!   registers first differ from those of the same run without the change;
//! * **brake input -> CAN**: the same change; the first `RIG_WHEEL_SPEED` frame that differs;
//! * **valve input -> state**: a valve coil energised on the port a tick reads; the tick its
//!   debounced state shows it (what the telemetry and the frames carry).
//!
//! Each is measured at 20 phases of the change against the 1 ms frame schedule: min and
//! max in steps (the jitter is their difference). Microseconds add what the step logic does
//! not see: the ADC samples 50 us before the tick that reads them (TIM3_CC4 at mid-period,
//! docs/rig.md), the step's own run time up to its outputs (the emulator's maximum
//! instructions at 170 MHz and one instruction a cycle: a lower bound; the board's
//! `RIG_DIAG` `step_max_us` gives it on the hardware), a new pulse period starts at the
//! timer's next update (up to one period later: 1.1 ms at 160 km/h, 90 teeth), and a CAN
//! frame takes 0.22-0.27 ms on an idle bus at 500 kbit/s (111-135 bits with stuffing).

use hils_plant::{FrictionModel, Rail};
use hils_rig_core::can::{
    BrakeCommand, Calibration, ClassicFrame, Command, CommandFrame, ConfigItem, RigMode,
    StartCommand, WheelSpeedFrame,
};
use hils_rig_core::controller_io::IoItem;
use hils_rig_core::hw::{RigIo, TelemetryEvent};
use hils_rig_core::pulse::PulseRegisters;
use hils_rig_core::rig::{Rig, RigConfig};
use hils_rig_core::sensor::{ADC_SEQUENCE_LEN, SensorKind};
use hils_rig_core::valves::{ValveLevels, ValveWiring};
use serde::Serialize;

/// Board step period, us.
const STEP_US: f64 = 100.0;
/// ADC sampling before the tick that reads the sequence, us (TIM3_CC4 at mid-period).
const ADC_LEAD_US: f64 = 50.0;
/// Board clock, MHz.
const CPU_MHZ: f64 = 170.0;
/// Phases of the change against the 1 ms frame schedule.
const PHASES: u64 = 20;

/// The board's pins as the step sees them.
struct Pins {
    pressure_counts: u16,
    levels: ValveLevels,
    pulses: [Option<PulseRegisters>; 4],
    wheel_frame: Option<[u8; 8]>,
}

impl RigIo for Pins {
    type Frame = ClassicFrame;
    fn adc_sequence(&mut self) -> Option<[u16; ADC_SEQUENCE_LEN]> {
        self.wheel_frame = None;
        // One count of alternating noise, so no channel reads stuck.
        self.pulses = [None; 4];
        Some(core::array::from_fn(|rank| {
            self.pressure_counts + (rank % 2) as u16
        }))
    }
    fn set_pulse(&mut self, wheelset: usize, registers: &PulseRegisters) {
        self.pulses[wheelset] = Some(*registers);
    }
    fn queue_frame(&mut self, frame: ClassicFrame) -> bool {
        if WheelSpeedFrame::decode(&frame).is_ok_and(|w| w.pair == 0) {
            self.wheel_frame = Some(frame.data);
        }
        true
    }
    fn queue_telemetry(&mut self, _: &TelemetryEvent) -> bool {
        true
    }
    fn valve_levels(&mut self) -> ValveLevels {
        self.levels
    }
}

/// ADC counts of a cylinder pressure on the default transducer characteristic.
fn counts(p_pa: f64) -> u16 {
    (4095.0 * (0.1 + 0.8 * p_pa / 1e6)) as u16
}

/// A rig in an armed rig-mode run at 120 km/h (pressure transducers, every valve input
/// wired), `ticks` steps in.
fn running_rig(ticks: u64) -> (Rig, Pins) {
    let mut rig = Rig::new(RigConfig::nucleo_g474re());
    let kind = |channel| Command::Calibrate {
        channel,
        action: Calibration::SetKind(SensorKind::PressureTransducer),
    };
    let start = Command::Start(StartCommand {
        mode: RigMode::Rig,
        rail: Rail::Wet,
        friction: FrictionModel::Variable,
        emergency: false,
        initial_speed_kmh: 120.0,
        track: false,
        setup_digest: hils_rig_core::digest::setup_digest(None, &Default::default()),
    });
    let wiring = ConfigItem::Io(IoItem::ValveWiring, ValveWiring::ALL.code());
    let commands = (0..4).map(kind).chain([
        Command::Configure(wiring),
        Command::Arm,
        Command::Brake(BrakeCommand::Emergency),
        start,
    ]);
    for (k, c) in commands.enumerate() {
        let frame: Option<ClassicFrame> = CommandFrame {
            command: c,
            counter: (k & 0x0F) as u8,
        }
        .encode();
        if let Some(f) = frame {
            let _ = rig.command_frame(&f);
            let _ = rig.build_pending();
        }
    }
    let mut pins = Pins {
        pressure_counts: counts(0.0),
        levels: ValveLevels::of_coils([false; 4], [false; 4], &ValveWiring::ALL),
        pulses: [None; 4],
        wheel_frame: None,
    };
    for _ in 0..ticks {
        rig.step(&mut pins);
    }
    (rig, pins)
}

/// Steps from the change on: the first tick (0 = the tick that read it) where `seen` says the
/// changed rig's outputs show it, against the unchanged one; None within 40 ticks.
fn ticks_until(
    phase: u64,
    change: impl Fn(&mut Pins),
    seen: impl Fn(&Rig, &Pins, &Rig, &Pins) -> bool,
) -> Option<u64> {
    let (mut a, mut pa) = running_rig(100 + phase);
    let (mut b, mut pb) = running_rig(100 + phase);
    change(&mut pb);
    (0..40).find(|_| {
        a.step(&mut pa);
        b.step(&mut pb);
        seen(&a, &pa, &b, &pb)
    })
}

/// Min and max over the phases, steps.
fn over_phases(one: impl Fn(u64) -> Option<u64>) -> Option<(u64, u64)> {
    let all: Option<Vec<u64>> = (0..PHASES).map(one).collect();
    let all = all?;
    Some((*all.iter().min()?, *all.iter().max()?))
}

/// One latency: steps (min, max) and microseconds (min, max).
#[derive(Clone, Debug, Serialize)]
pub struct Path {
    pub path: &'static str,
    pub steps_min: u64,
    pub steps_max: u64,
    pub us_min: f64,
    pub us_max: f64,
    /// What the microseconds add to the steps.
    pub includes: &'static str,
}

/// The rig's latencies (module doc); `step_instructions_max` from the emulator.
pub fn measure(step_instructions_max: u32) -> Vec<Path> {
    let step_us = step_instructions_max as f64 / CPU_MHZ;
    let brake = |p: &mut Pins| p.pressure_counts = counts(500e3);
    let pulse = over_phases(|ph| ticks_until(ph, brake, |_, a, _, b| a.pulses != b.pulses));
    let can = over_phases(|ph| {
        ticks_until(ph, brake, |_, a, _, b| {
            a.wheel_frame.is_some() && a.wheel_frame != b.wheel_frame
        })
    });
    let vent = |p: &mut Pins| {
        p.levels = ValveLevels::of_coils([true; 4], [true; 4], &ValveWiring::ALL);
    };
    let valve = over_phases(|ph| {
        ticks_until(ph, vent, |_, _, b, _| {
            b.valve_states().venting(0) == Some(true)
        })
    });
    // A brake input is sampled ADC_LEAD_US before the tick that reads it; a coil edge comes
    // at any time in the tick before the port read (0-100 us).
    let mut out = Vec::new();
    let mut push =
        |path, steps: Option<(u64, u64)>, lead_us: (f64, f64), extra_max_us: f64, includes| {
            if let Some((lo, hi)) = steps {
                out.push(Path {
                    path,
                    steps_min: lo,
                    steps_max: hi,
                    us_min: figures(lo as f64 * STEP_US + lead_us.0 + step_us),
                    us_max: figures(hi as f64 * STEP_US + lead_us.1 + step_us + extra_max_us),
                    includes,
                });
            }
        };
    let adc = (ADC_LEAD_US, ADC_LEAD_US);
    push(
        "brake input -> pulse-timer registers",
        pulse,
        adc,
        1111.0,
        "ADC 50 us before the tick, the step; max + one pulse period at 160 km/h (the new period starts at the timer's update)",
    );
    push(
        "brake input -> RIG_WHEEL_SPEED frame",
        can,
        adc,
        270.0,
        "ADC 50 us before the tick, the step; max + 0.27 ms on the bus (500 kbit/s, idle)",
    );
    push(
        "valve input -> valve state (telemetry, frames)",
        valve,
        (0.0, STEP_US),
        0.0,
        "the coil's edge 0-100 us before the port read, the debounce, the step; the frame then follows on its 1 ms schedule",
    );
    out
}

fn figures(us: f64) -> f64 {
    crate::figures::round_dp(us, 0)
}

/// The terminal text.
pub fn text(paths: &[Path], step_instructions_max: u32) -> String {
    let mut t = format!(
        "latency (rig-core on the host, 20 phases against the 1 ms frame schedule; us with the step's run time {:.0} us = {} instructions at 170 MHz, a lower bound):\n",
        step_instructions_max as f64 / CPU_MHZ,
        step_instructions_max
    );
    for p in paths {
        t += &format!(
            "  {:<48} {}-{} steps (jitter {}), {:.0}-{:.0} us ({})\n",
            p.path,
            p.steps_min,
            p.steps_max,
            p.steps_max - p.steps_min,
            p.us_min,
            p.us_max,
            p.includes
        );
    }
    t
}
