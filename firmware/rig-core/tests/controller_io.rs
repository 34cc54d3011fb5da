//! The controller I/O through the real-time step (issue 21): the valve inputs reach the
//! step's states and the wheel-speed frames only where wired; the EB loop, the service
//! demand PWM and the air-spring DACs follow the brake command and the plant only while the
//! arming gate says the outputs are live ([`Rig::controller_outputs_live`]), and are the safe
//! outputs (loop open = emergency brake, PWM and DACs silent) after a reset, when idle,
//! stopped, disarmed, in a self-test run and on every fault, from the tick it happens.

use hils_brake_unit::BrakeDemand;
use hils_plant::{FrictionModel, Rail};
use hils_rig_core::can::{
    BrakeCommand, Calibration, ClassicFrame, Command, CommandFrame, ConfigItem, ID_WHEEL_SPEED_12,
    InjectedFault, RigMode, RigState, StartCommand, WheelSpeedFrame,
};
use hils_rig_core::controller_io::{DrivenOutputs, IoItem};
use hils_rig_core::hw::{RigIo, TelemetryEvent};
use hils_rig_core::pulse::PulseRegisters;
use hils_rig_core::rig::{CommandError, Rig, RigConfig};
use hils_rig_core::sensor::{ADC_SEQUENCE_LEN, SensorKind};
use hils_rig_core::valves::{DEBOUNCE_TICKS, ValveLevels, ValveWiring};

/// The board's pins as the step sees them: the ADC reading a cylinder pressure of 200 kPa
/// on every channel (with noise), the valve port, and what the step drove last.
struct Pins {
    tick: u64,
    adc: bool,
    valve_levels: ValveLevels,
    driven: Option<DrivenOutputs>,
    /// The outputs were set in every step so far.
    set_each_step: bool,
    frames: Vec<ClassicFrame>,
}

impl Pins {
    fn new() -> Self {
        Self {
            tick: 0,
            adc: true,
            valve_levels: ValveLevels::of_coils([false; 4], [false; 4], &ValveWiring::ALL),
            driven: None,
            set_each_step: true,
            frames: Vec::new(),
        }
    }
    fn driven(&self) -> DrivenOutputs {
        self.driven.expect("the step drove the controller outputs")
    }
}

impl RigIo for Pins {
    type Frame = ClassicFrame;
    fn adc_sequence(&mut self) -> Option<[u16; ADC_SEQUENCE_LEN]> {
        // Whether last step set the outputs (checked before this step's).
        self.set_each_step &= self.tick == 0 || self.driven.is_some();
        self.driven = None;
        self.tick += 1;
        // 200 kPa on the default transducer characteristic (10 % + 80 % per MPa), +-2 counts.
        let counts = 4095.0 * (0.1 + 0.8 * 0.2);
        self.adc.then(|| {
            core::array::from_fn(|rank| {
                (counts + ((self.tick as usize * 7 + rank * 13) % 5) as f64 - 2.0) as u16
            })
        })
    }
    fn set_pulse(&mut self, _: usize, _: &PulseRegisters) {}
    fn queue_frame(&mut self, frame: ClassicFrame) -> bool {
        self.frames.push(frame);
        true
    }
    fn queue_telemetry(&mut self, _: &TelemetryEvent) -> bool {
        true
    }
    fn valve_levels(&mut self) -> ValveLevels {
        self.valve_levels
    }
    fn set_controller_outputs(&mut self, outputs: &DrivenOutputs) {
        self.driven = Some(*outputs);
    }
}

fn command(rig: &mut Rig, counter: &mut u8, c: Command) -> Result<Command, CommandError> {
    *counter = (*counter + 1) & 0x0F;
    let f: ClassicFrame = CommandFrame {
        command: c,
        counter: *counter,
    }
    .encode()
    .unwrap();
    rig.command_frame(&f)
        .and_then(|c| rig.build_pending().map(|_| c))
}

fn rig_start() -> Command {
    Command::Start(StartCommand {
        mode: RigMode::Rig,
        rail: Rail::Wet,
        friction: FrictionModel::Variable,
        emergency: false,
        initial_speed_kmh: 80.0,
        track: false,
        setup_digest: hils_rig_core::digest::setup_digest(None, &Default::default()),
    })
}

/// A rig with pressure transducers on every channel and every valve input wired, its
/// pins, and its command counter.
fn rig() -> (Rig, Pins, u8) {
    rig_wired(ValveWiring::ALL)
}

/// [`rig`] with the valve inputs of `wiring`.
fn rig_wired(wiring: ValveWiring) -> (Rig, Pins, u8) {
    let mut rig = Rig::new(RigConfig::nucleo_g474re());
    let mut n = 0;
    for channel in 0..4 {
        let kind = Calibration::SetKind(SensorKind::PressureTransducer);
        command(
            &mut rig,
            &mut n,
            Command::Calibrate {
                channel,
                action: kind,
            },
        )
        .unwrap();
    }
    let wiring = ConfigItem::Io(IoItem::ValveWiring, wiring.code());
    command(&mut rig, &mut n, Command::Configure(wiring)).unwrap();
    (rig, Pins::new(), n)
}

fn steps(rig: &mut Rig, pins: &mut Pins, n: usize) {
    for _ in 0..n {
        rig.step(pins);
    }
}

/// Steps `n` ticks, each one's outputs safe.
fn safe_for(rig: &mut Rig, pins: &mut Pins, n: usize, when: &str) {
    for k in 0..n {
        rig.step(pins);
        assert!(
            pins.driven().is_safe(),
            "{when}, tick {k}: {:?}",
            pins.driven()
        );
        assert!(!rig.controller_outputs_live(), "{when}");
        assert_eq!(pins.driven().bits(), 0, "{when}");
    }
}

/// An armed run (demand `brake`) stepped until its outputs are live.
fn armed_run(rig: &mut Rig, pins: &mut Pins, n: &mut u8, brake: BrakeCommand) {
    command(rig, n, Command::Arm).unwrap();
    command(rig, n, Command::Brake(brake)).unwrap();
    command(rig, n, rig_start()).unwrap();
    steps(rig, pins, 5);
    assert_eq!(rig.state(), RigState::Running);
    assert!(rig.controller_outputs_live());
}

#[test]
fn after_a_reset_and_while_idle_the_loop_is_open_and_the_outputs_silent() {
    let (mut rig, mut pins, mut n) = rig();
    safe_for(&mut rig, &mut pins, 100, "after the reset");
    // A brake command outside a run moves nothing; neither does a disarmed start.
    command(&mut rig, &mut n, Command::Brake(BrakeCommand::Release)).unwrap();
    safe_for(&mut rig, &mut pins, 10, "idle with a release command");
    assert_eq!(
        command(&mut rig, &mut n, rig_start()),
        Err(CommandError::NotArmed)
    );
    safe_for(&mut rig, &mut pins, 10, "a start refused");
    assert!(pins.set_each_step, "the step drives the outputs every tick");
}

#[test]
fn an_armed_run_drives_the_loop_the_pwm_and_the_load_as_commanded() {
    let (mut rig, mut pins, mut n) = rig();
    let io = rig.config().io;
    // Release: loop closed, PWM at the release duty (a live line, no demand), both bogies'
    // air springs on the DACs (the plant's load within the transducer's range).
    armed_run(&mut rig, &mut pins, &mut n, BrakeCommand::Release);
    let d = pins.driven();
    assert!(d.eb_loop_closed && !d.pwm.is_silent(), "{d:?}");
    let release = io.demand.decode_pwm(&d.pwm).unwrap();
    assert!(release.abs() < 0.01, "{release}");
    for (code, p) in d.dac.iter().zip(d.air_spring_pa) {
        assert!(*code > 0 && (2e5..8e5).contains(&p), "{d:?}");
        let read = io.load.read_pa(*code).unwrap();
        assert!((read - p).abs() < 1e-3 * p, "{read} {p}");
    }
    assert_eq!(d.bits(), 0b111);
    // Service 0.8 m/s^2: the PWM carries it (within a count); the loop stays closed.
    let service = BrakeCommand::Service {
        deceleration_mps2: 0.8,
    };
    command(&mut rig, &mut n, Command::Brake(service)).unwrap();
    steps(&mut rig, &mut pins, 2);
    let d = pins.driven();
    let read = io.demand.decode_pwm(&d.pwm).unwrap();
    assert!(d.eb_loop_closed && (read - 0.8).abs() < 0.01, "{read}");
    // Emergency: the loop opens (de-energised = emergency brake), the load stays driven.
    command(&mut rig, &mut n, Command::Brake(BrakeCommand::Emergency)).unwrap();
    steps(&mut rig, &mut pins, 1);
    let d = pins.driven();
    assert!(!d.eb_loop_closed && d.dac.iter().all(|&c| c > 0));
    let demand = hils_rig_core::demand::ControllerDemand {
        eb_loop_closed: d.eb_loop_closed,
        service_mps2: io.demand.decode_pwm(&d.pwm),
    };
    assert_eq!(demand.brake(&io.demand), BrakeDemand::Emergency);
}

#[test]
fn disarm_stop_and_self_test_make_the_outputs_safe_in_the_same_tick() {
    let (mut rig, mut pins, mut n) = rig();
    armed_run(&mut rig, &mut pins, &mut n, BrakeCommand::Release);
    command(&mut rig, &mut n, Command::Disarm).unwrap();
    safe_for(&mut rig, &mut pins, 10, "disarmed in a run");
    assert_eq!(rig.state(), RigState::Running);
    command(&mut rig, &mut n, Command::Stop).unwrap();
    safe_for(&mut rig, &mut pins, 10, "stopped");
    armed_run(&mut rig, &mut pins, &mut n, BrakeCommand::Release);
    command(&mut rig, &mut n, Command::Stop).unwrap();
    safe_for(&mut rig, &mut pins, 10, "stopped while armed");
    // A self-test run closes its loop on the board: nothing reaches the controller.
    command(&mut rig, &mut n, Command::Arm).unwrap();
    let self_test = rig.on_kept_setup(Command::paper_self_test(FrictionModel::Variable));
    command(&mut rig, &mut n, self_test).unwrap();
    safe_for(&mut rig, &mut pins, 200, "self-test run");
    assert_eq!(rig.state(), RigState::Running);
}

#[test]
fn every_fault_latches_the_loop_open_and_the_outputs_silent() {
    // A sensor fault (open wire, short, out of range, stuck), and a stalled ADC.
    for fault in [
        Some(InjectedFault::Open),
        Some(InjectedFault::Short),
        Some(InjectedFault::OutOfRange),
        None,
    ] {
        let (mut rig, mut pins, mut n) = rig();
        armed_run(&mut rig, &mut pins, &mut n, BrakeCommand::Release);
        match fault {
            Some(f) => {
                let c = Command::InjectFault {
                    channel: 2,
                    fault: Some(f),
                };
                command(&mut rig, &mut n, c).unwrap();
            }
            None => pins.adc = false,
        }
        let mut ticks = 0;
        while rig.state() == RigState::Running && ticks < 100 {
            rig.step(&mut pins);
            ticks += 1;
        }
        let what = format!("{fault:?}");
        assert_eq!(rig.state(), RigState::Fault, "{what}");
        // Safe from the tick the run ended, and it stays so: no arming while faulted.
        assert!(pins.driven().is_safe(), "{what}");
        safe_for(&mut rig, &mut pins, 50, &what);
        assert!(command(&mut rig, &mut n, Command::Arm).is_err(), "{what}");
        assert!(command(&mut rig, &mut n, rig_start()).is_err(), "{what}");
        safe_for(&mut rig, &mut pins, 10, &what);
    }
}

#[test]
fn valve_inputs_show_only_where_wired_after_the_debounce() {
    // Wheelset 1 vents, wheelset 2 holds (active-low stage).
    let coils = ValveLevels::of_coils(
        [true, false, false, false],
        [false, true, false, false],
        &ValveWiring::ALL,
    );
    let (mut rig, mut pins, mut n) = rig();
    armed_run(&mut rig, &mut pins, &mut n, BrakeCommand::Emergency);
    pins.valve_levels = coils;
    steps(&mut rig, &mut pins, DEBOUNCE_TICKS as usize - 1);
    assert_eq!(
        rig.valve_states().venting(0),
        Some(false),
        "before the debounce"
    );
    steps(&mut rig, &mut pins, 1);
    let v = rig.valve_states();
    assert!(
        v.venting(0) == Some(true) && v.holding(1) == Some(true),
        "{v:?}"
    );
    assert_eq!((v.venting(2), v.holding(3)), (Some(false), Some(false)));
    // The wheel-speed frame of wheelsets 1 and 2 carries them.
    steps(&mut rig, &mut pins, 20);
    let f = pins
        .frames
        .iter()
        .rev()
        .filter(
            |f| matches!(f.id, embedded_can::Id::Standard(s) if s.as_raw() == ID_WHEEL_SPEED_12),
        )
        .find_map(|f| WheelSpeedFrame::decode(f).ok())
        .unwrap();
    assert_eq!(
        (f.valves.venting(0), f.valves.holding(1)),
        (Some(true), Some(true))
    );
    // Not wired (the default, or only the dump inputs): not known, whatever the pins show.
    for wiring in [
        ValveWiring::default(),
        ValveWiring {
            hold: 0,
            ..ValveWiring::ALL
        },
    ] {
        let (mut rig, mut pins, mut n) = rig_wired(wiring);
        armed_run(&mut rig, &mut pins, &mut n, BrakeCommand::Emergency);
        pins.valve_levels = coils;
        steps(&mut rig, &mut pins, 10);
        let v = rig.valve_states();
        let dump_wired = wiring.dump != 0;
        assert_eq!(v.venting(0), dump_wired.then_some(true), "{v:?}");
        assert_eq!(v.holding(1), None, "{v:?}");
    }
}
