//! The real-time step against a mock of the board (ADC, pulse timers, CAN queue, log queue):
//! runs, outputs, schedules, the safe state and command handling.

use embedded_can::{Frame, Id, StandardId};
use hils_brake_unit::BrakeDemand;
use hils_plant::{BrakeInput, FrictionModel, Params, Plant, Rail};
use hils_rig_core::Code;
use hils_rig_core::can::{
    BrakeCommand, Calibration, ClassicFrame, Command, CommandFrame, CommandResult, ConfigItem,
    DiagFrame, HealthFrame, ID_DIAG, ID_HEALTH, ID_STATUS, ID_WHEEL_SPEED_12, ID_WHEEL_SPEED_34,
    InjectedFault, RigMode, RigState, StartCommand, StatusFrame, WheelSpeedFrame,
};
use hils_rig_core::hw::{RigIo, TelemetryEvent};
use hils_rig_core::pulse::PulseRegisters;
use hils_rig_core::rig::{Built, CommandError, Faults, Rig, RigConfig, SimStore, Simulation};
use hils_rig_core::sensor::{ADC_SEQUENCE_LEN, SensorFault, SensorKind};
use hils_rig_core::telemetry::TelemetryRecord;
use hils_rig_core::valves::ValveStates;
use hils_sil::ClosedLoop;
use std::cell::Cell;
use std::rc::Rc;

type TestFrame = ClassicFrame;

fn sid(f: &TestFrame) -> u16 {
    match f.id {
        Id::Standard(s) => s.as_raw(),
        Id::Extended(_) => 0xFFFF,
    }
}

/// The board as the step sees it, recording everything.
struct MockBoard {
    /// Counts each channel reads (before noise); `None` = no fresh sequence.
    adc_counts: Option<[f64; 4]>,
    tick: u64,
    frames: Vec<(u64, TestFrame)>,
    telemetry: Vec<TelemetryEvent>,
    pulses: [Option<PulseRegisters>; 4],
    frame_room: usize,
    telemetry_room: usize,
}

impl MockBoard {
    fn new() -> Self {
        Self {
            adc_counts: Some([409.5; 4]),
            tick: 0,
            frames: vec![],
            telemetry: vec![],
            pulses: [None; 4],
            frame_room: usize::MAX,
            telemetry_room: usize::MAX,
        }
    }
    fn records(&self) -> Vec<TelemetryRecord> {
        self.telemetry
            .iter()
            .filter_map(TelemetryEvent::record)
            .collect()
    }
    fn frames_with(&self, id: u16) -> Vec<&(u64, TestFrame)> {
        self.frames.iter().filter(|(_, f)| sid(f) == id).collect()
    }
}

impl RigIo for MockBoard {
    type Frame = TestFrame;
    fn adc_sequence(&mut self) -> Option<[u16; ADC_SEQUENCE_LEN]> {
        self.tick += 1;
        let counts = self.adc_counts?;
        // Live-sensor noise of +-2 counts, different per rank and tick.
        Some(core::array::from_fn(|rank| {
            let n = ((self.tick as usize * 7 + rank * 13) % 5) as f64 - 2.0;
            (counts[rank % 4] + n).round().clamp(0.0, 4095.0) as u16
        }))
    }
    fn set_pulse(&mut self, wheelset: usize, registers: &PulseRegisters) {
        self.pulses[wheelset] = Some(*registers);
    }
    fn queue_frame(&mut self, frame: TestFrame) -> bool {
        if self.frame_room == 0 {
            return false;
        }
        self.frame_room = self.frame_room.saturating_sub(1);
        self.frames.push((self.tick, frame));
        true
    }
    fn queue_telemetry(&mut self, event: &TelemetryEvent) -> bool {
        if self.telemetry_room == 0 {
            return false;
        }
        self.telemetry_room = self.telemetry_room.saturating_sub(1);
        self.telemetry.push(*event);
        true
    }
}

fn command(rig: &mut Rig, counter: u8, c: Command) -> Result<Command, CommandError> {
    let f: TestFrame = CommandFrame {
        command: c,
        counter,
    }
    .encode()
    .unwrap();
    // A start is only requested by the step; build it here, as the board's builder would.
    rig.command_frame(&f)
        .and_then(|c| rig.build_pending().map(|_| c))
}

fn paper_start(friction: FrictionModel) -> Command {
    Command::paper_self_test(friction)
}

/// Arms the rig for a controller (command with alive counter `counter`).
fn arm(rig: &mut Rig, counter: u8) {
    command(rig, counter, Command::Arm).unwrap();
}

/// A rig on the Nucleo board and its mock I/O, the paper's self-test started (command 1).
fn paper_self_test_started(friction: FrictionModel) -> (Rig, MockBoard) {
    let mut rig = Rig::new(RigConfig::nucleo_g474re());
    command(&mut rig, 1, paper_start(friction)).unwrap();
    (rig, MockBoard::new())
}

/// A rig on the Nucleo board with four load cells reading 3 kN, a rig-mode run at 60 km/h
/// started (command 1).
fn rig_run_started_at_3_kn() -> (Rig, MockBoard) {
    let mut rig = Rig::new(RigConfig::nucleo_g474re());
    let mut io = MockBoard::new();
    io.adc_counts = Some([load_cell_counts(3000.0); 4]);
    arm(&mut rig, 15);
    command(&mut rig, 1, rig_start(60.0)).unwrap();
    (rig, io)
}

/// The setup digest of a run on one rail with the default vehicle (a fresh rig's).
fn default_setup_digest() -> u16 {
    hils_rig_core::digest::setup_digest(None, &Default::default())
}

/// A rig-mode start (measured brake inputs) on the wet rail with Eq (2), no EB.
fn rig_start(initial_speed_kmh: f32) -> Command {
    Command::Start(StartCommand {
        mode: RigMode::Rig,
        rail: Rail::Wet,
        friction: FrictionModel::Variable,
        emergency: false,
        initial_speed_kmh,
        track: false,
        setup_digest: default_setup_digest(),
    })
}

/// The four speeds of the last wheel-speed cycle (both frames, same alive counter).
fn last_wheel_speeds(io: &MockBoard) -> [Option<f32>; 4] {
    let decode = |id| {
        let (_, f) = io.frames_with(id).last().copied().unwrap().clone();
        WheelSpeedFrame::decode(&f).unwrap()
    };
    let (a, b) = (decode(ID_WHEEL_SPEED_12), decode(ID_WHEEL_SPEED_34));
    assert_eq!(a.counter, b.counter);
    [
        a.speeds_kmh[0],
        a.speeds_kmh[1],
        b.speeds_kmh[0],
        b.speeds_kmh[1],
    ]
}

/// Makes `channel` a pressure transducer (command with alive counter `counter`).
fn make_pressure_channel(rig: &mut Rig, counter: u8, channel: u8) {
    let c = Command::Calibrate {
        channel,
        action: Calibration::SetKind(SensorKind::PressureTransducer),
    };
    command(rig, counter, c).unwrap();
}

/// Counts a load cell shows for a clamp force with the default calibration (f64).
fn load_cell_counts(force_n: f64) -> f64 {
    4095.0 * (0.1 + 0.8 * force_n / 40_000.0)
}

#[test]
fn self_test_paper_run_matches_the_closed_loop_and_streams_it() {
    let (mut rig, mut io) = paper_self_test_started(FrictionModel::Variable);
    // The same closed loop, stepped directly (one copy of the physics: must agree bit for bit).
    let params = Params::default();
    let mut reference = ClosedLoop::<f32>::new(&params, Rail::Wet, 150.0 / 3.6).unwrap();
    reference.set_demand(BrakeDemand::Emergency);
    let mut ticks = 0u32;
    while rig.state() == RigState::Running && ticks < 400_000 {
        rig.step(&mut io);
        rig.record_timing(
            ticks.wrapping_mul(17_000),
            ticks.wrapping_mul(17_000).wrapping_add(6_000),
            false,
        );
        ticks += 1;
        if rig.state() == RigState::Running || rig.state() == RigState::Finished {
            reference.step();
            let o = rig.outputs().unwrap();
            assert_eq!(
                o.vehicle_speed.to_bits(),
                reference.outputs().vehicle_speed.to_bits()
            );
        }
    }
    assert_eq!(rig.state(), RigState::Finished);
    // A self-test run never drives the controller-facing outputs (the arming gate), at rest
    // after it neither.
    for _ in 0..100 {
        rig.step(&mut io);
        ticks += 1;
        assert!(rig.pulses().iter().all(|p| p.is_silent()));
        assert_eq!(rig.wheel_speeds_kmh(), [None; 4]);
    }
    let stop_s = rig.run_steps() as f64 * 1e-4;
    // The paper scenario with variable friction stops at ~29.1 s (host f64: 29.06 s).
    assert!((stop_s - 29.1).abs() < 0.3, "stop at {stop_s} s");

    // Telemetry: header, a record at t = 0 and every 100 steps, a final record, end line.
    assert!(
        matches!(io.telemetry.first(), Some(TelemetryEvent::Header(h)) if h.mode == 1 && h.divider == 100 && h.initial_speed_kmh == 150.0)
    );
    assert!(matches!(
        io.telemetry.last(),
        Some(TelemetryEvent::End { state: 2, .. })
    ));
    let recs = io.records();
    assert_eq!(recs[0].step, 0);
    assert!((recs[0].v_ref - 150.0 / 3.6).abs() < 1e-4);
    for w in recs.windows(2).take(recs.len() - 2) {
        assert_eq!(w[1].step - w[0].step, 100);
    }
    assert_eq!(
        recs.len() as u32,
        rig.run_steps() / 100 + 2 - (rig.run_steps() % 100 == 0) as u32
    );
    // WSP vents on wheelsets 2 and 4 only (the paper's result), and the bits say "known".
    let mut vented = [false; 4];
    for r in &recs {
        let valves = ValveStates::of_bits(r.valves);
        assert_eq!((valves.dump_known, valves.hold_known), (0x0F, 0x0F));
        assert_eq!(r.cmd, 1);
        for (j, v) in vented.iter_mut().enumerate() {
            *v |= valves.venting(j).unwrap();
        }
        // Self-test: pressure from the unit, clamp force = Eq 1 of that pressure.
        for j in 0..4 {
            let eq1 = ((0.0227 * r.p_cyl[j] as f64 - 1000.0).max(0.0)) * 2.5;
            assert!(r.f_clamp[j].is_finite() && r.p_cyl[j].is_finite());
            assert!(
                (r.f_clamp[j] as f64 - eq1).abs() < 1.0 + 1e-4 * eq1,
                "{} vs {eq1}",
                r.f_clamp[j]
            );
        }
        assert_eq!(
            (r.step_max_cycles, r.overruns),
            (if r.step == 0 { 0 } else { 6000 }, 0)
        );
    }
    assert_eq!(vented, [false, true, false, true]);

    // CAN: a wheel-speed frame every 10 ticks, counter 0..15, "not available" throughout
    // (a self-test run never drives the controller); the speeds are in the status frame.
    for (pair, id) in [ID_WHEEL_SPEED_12, ID_WHEEL_SPEED_34]
        .into_iter()
        .enumerate()
    {
        let ws = io.frames_with(id);
        assert_eq!(ws.len() as u32, ticks / 10);
        for (k, (_, f)) in ws.iter().enumerate() {
            let d = WheelSpeedFrame::decode(f).unwrap();
            assert_eq!((d.pair, d.counter as usize), (pair, k % 16));
            assert_eq!(d.speeds_kmh, [None; 2]);
        }
    }
    let status = io.frames_with(ID_STATUS);
    assert_eq!(status.len() as u32, (ticks + 95) / 100);
    let s = StatusFrame::decode(&status[1000].1).unwrap(); // at 10 s
    assert_eq!(
        (s.state, s.mode, s.command_result),
        (
            RigState::Running,
            RigMode::SelfTest,
            CommandResult::Accepted
        )
    );
    assert!(
        s.deceleration_mps2 > 0.5 && s.deceleration_mps2 < 2.0,
        "{}",
        s.deceleration_mps2
    );
    let diag = io.frames_with(ID_DIAG);
    assert_eq!(diag.len() as u32, (ticks + 950) / 1000);
    let d = DiagFrame::decode(&diag[3].1).unwrap();
    // 6000 cycles at 170 MHz = 35.29 us.
    assert!((d.step_max_us - 35.29).abs() < 0.01 && (d.step_mean_us - 35.29).abs() < 0.01);
    assert_eq!(d.overruns, 0);
}

#[test]
fn wheel_speed_outputs_follow_the_plant_in_an_armed_rig_run() {
    for teeth in [90u16, 45] {
        let mut rig = Rig::new(RigConfig::nucleo_g474re());
        let mut io = MockBoard::new();
        io.adc_counts = Some([load_cell_counts(6000.0); 4]);
        command(&mut rig, 1, Command::Configure(ConfigItem::Teeth(teeth))).unwrap();
        arm(&mut rig, 2);
        command(&mut rig, 3, rig_start(150.0)).unwrap();
        for _ in 0..50_000 {
            rig.step(&mut io);
            let o = rig.outputs().unwrap();
            let r = 0.43f64;
            for j in 0..4 {
                let omega = o.wheelsets[j].omega as f64;
                // Pulse frequency within 0.1 % of teeth omega / 2 pi.
                let p = io.pulses[j].unwrap();
                let f = 170e6 / ((p.psc as f64 + 1.0) * (p.arr as f64 + 1.0));
                let want = teeth as f64 * omega / (2.0 * std::f64::consts::PI);
                assert!((f / want - 1.0).abs() < 1e-3);
                // The speed the frame carries: r omega in km/h.
                let kmh = rig.wheel_speeds_kmh()[j].unwrap() as f64;
                assert!((kmh - omega * r * 3.6).abs() < 1e-3 * kmh.max(1.0));
            }
        }
        assert!(rig.outputs().unwrap().vehicle_speed < 150.0 / 3.6 - 1.0);
        // Decoded frames agree with the speeds within half the resolution.
        let sent = last_wheel_speeds(&io);
        for j in 0..4 {
            let v = rig.wheel_speeds_kmh()[j].unwrap();
            assert!((sent[j].unwrap() - v).abs() <= 0.0051, "{j}");
        }
    }
}

/// `RIG_HEALTH` every 100 ms: the board's measurements as set, the arming and why not.
#[test]
fn health_frame_carries_the_board_health_and_the_arming() {
    use hils_rig_core::arming::Disarm;
    use hils_rig_core::rig::BoardHealth;
    let mut rig = Rig::new(RigConfig::nucleo_g474re());
    let mut io = MockBoard::new();
    let last = |io: &MockBoard| {
        let (_, f) = io.frames_with(ID_HEALTH).last().copied().unwrap().clone();
        HealthFrame::decode(&f).unwrap()
    };
    rig.set_board_health(BoardHealth {
        stack_peak_bytes: 9_000,
        stack_size_bytes: 32_768,
        rx_lost: 300,
        adc_restarts: 2,
        fault_resets: 1,
    });
    for _ in 0..1000 {
        rig.step(&mut io);
    }
    assert_eq!(io.frames_with(ID_HEALTH).len(), 1);
    let h = last(&io);
    assert_eq!(
        (
            h.stack_peak_bytes,
            h.stack_size_bytes,
            h.rx_lost,
            h.adc_restarts
        ),
        (9_000, 32_768, 255, 2)
    );
    assert_eq!((h.disarmed, h.fault_resets), (Some(Disarm::Reset), 1));
    arm(&mut rig, 1);
    for _ in 0..1000 {
        rig.step(&mut io);
    }
    assert_eq!(last(&io).disarmed, None);
    command(&mut rig, 2, Command::Disarm).unwrap();
    for _ in 0..1000 {
        rig.step(&mut io);
    }
    let h = last(&io);
    assert_eq!((h.disarmed, h.counter), (Some(Disarm::Command), 2));
}

/// The arming gate on the rig (issue 22 item 1): a rig-mode start needs `Arm`; `Stop`, a
/// fault, `Disarm` and a self-test start disarm, at once; a new rig (every reset) is
/// disarmed; a self-test run (the button's, the autostart's) never drives the outputs.
#[test]
fn outputs_a_controller_reads_move_only_while_armed() {
    use hils_rig_core::arming::{ArmRefused, Disarm};
    let live = |rig: &Rig, io: &MockBoard| {
        let speeds = last_wheel_speeds(io);
        let pulsing = io.pulses.iter().all(|p| !p.unwrap().is_silent());
        let silent = io.pulses.iter().all(|p| p.unwrap().is_silent());
        assert!(pulsing || silent);
        assert_eq!(rig.controller_outputs_live(), pulsing);
        assert_eq!(speeds.iter().all(Option::is_some), pulsing, "{speeds:?}");
        pulsing
    };
    let mut rig = Rig::new(RigConfig::nucleo_g474re());
    let mut io = MockBoard::new();
    io.adc_counts = Some([load_cell_counts(2000.0); 4]);
    assert_eq!(rig.arming().disarmed_by(), Some(Disarm::Reset));
    assert_eq!(
        command(&mut rig, 1, rig_start(100.0)),
        Err(CommandError::NotArmed)
    );
    // Armed: the run drives the outputs.
    arm(&mut rig, 2);
    command(&mut rig, 3, rig_start(100.0)).unwrap();
    for _ in 0..20 {
        rig.step(&mut io);
    }
    assert!(live(&rig, &io));
    // No arming during a run.
    assert_eq!(
        command(&mut rig, 4, Command::Arm),
        Err(CommandError::Arm(ArmRefused::Busy(RigState::Running)))
    );
    // Disarm during the run: safe at once (the same tick), the run goes on.
    command(&mut rig, 5, Command::Disarm).unwrap();
    for _ in 0..10 {
        rig.step(&mut io);
        assert!(io.pulses.iter().all(|p| p.unwrap().is_silent()));
    }
    assert!(!live(&rig, &io));
    assert_eq!(rig.state(), RigState::Running);
    assert_eq!(rig.arming().disarmed_by(), Some(Disarm::Command));
    // Stop disarms: the next rig start is refused until armed again.
    command(&mut rig, 6, Command::Stop).unwrap();
    rig.step(&mut io);
    assert_eq!(rig.arming().disarmed_by(), Some(Disarm::Command));
    arm(&mut rig, 7);
    command(&mut rig, 8, rig_start(100.0)).unwrap();
    for _ in 0..20 {
        rig.step(&mut io);
    }
    assert!(live(&rig, &io));
    command(&mut rig, 9, Command::Stop).unwrap();
    rig.step(&mut io);
    assert_eq!(rig.arming().disarmed_by(), Some(Disarm::Stop));
    assert!(io.pulses.iter().all(|p| p.unwrap().is_silent()));
    assert_eq!(
        command(&mut rig, 10, rig_start(100.0)),
        Err(CommandError::NotArmed)
    );
    // A fault disarms, and arming is refused until the faults are cleared.
    arm(&mut rig, 11);
    command(&mut rig, 12, rig_start(100.0)).unwrap();
    let open = Command::InjectFault {
        channel: 0,
        fault: Some(InjectedFault::Open),
    };
    command(&mut rig, 13, open).unwrap();
    for _ in 0..20 {
        rig.step(&mut io);
    }
    assert_eq!(rig.state(), RigState::Fault);
    assert_eq!(rig.arming().disarmed_by(), Some(Disarm::Fault));
    assert!(!live(&rig, &io));
    assert_eq!(
        command(&mut rig, 14, Command::Arm),
        Err(CommandError::Arm(ArmRefused::Faulted))
    );
    let remove = Command::InjectFault {
        channel: 0,
        fault: None,
    };
    command(&mut rig, 15, remove).unwrap();
    for _ in 0..100 {
        rig.step(&mut io);
    }
    command(&mut rig, 0, Command::ClearFaults).unwrap();
    assert_eq!(rig.state(), RigState::Stopped);
    arm(&mut rig, 1);
    // A self-test start (what the button and the autostart send, stamped on the kept
    // setup as the board does) disarms, and its run never drives the outputs.
    let button = rig.on_kept_setup(Command::paper_self_test(FrictionModel::Variable));
    rig.command(button).unwrap();
    rig.build_pending().unwrap();
    assert_eq!(rig.arming().disarmed_by(), Some(Disarm::SelfTest));
    for _ in 0..2000 {
        rig.step(&mut io);
        assert!(io.pulses.iter().all(|p| p.unwrap().is_silent()));
    }
    assert!(!live(&rig, &io));
    let (_, st) = io.frames_with(ID_STATUS).last().copied().unwrap().clone();
    let st = StatusFrame::decode(&st).unwrap();
    assert_eq!((st.state, st.mode), (RigState::Running, RigMode::SelfTest));
    assert!(
        st.vehicle_speed_kmh > 140.0,
        "the operator still sees the run"
    );
    // What a reset leaves: a new rig, disarmed.
    assert!(!Rig::new(RigConfig::nucleo_g474re()).arming().is_armed());
}

#[test]
fn arming_at_rest_or_after_a_failed_rebuild_makes_no_output_live() {
    // What a controller reads: the output enable (`controller_outputs_live`), the speeds
    // (0xFFFF = not available) and the pulse trains.
    let safe = |rig: &Rig, io: &MockBoard| {
        !rig.controller_outputs_live()
            && last_wheel_speeds(io).iter().all(Option::is_none)
            && io.pulses.iter().all(|p| p.unwrap().is_silent())
    };
    let mut rig = Rig::new(RigConfig::nucleo_g474re());
    let mut io = MockBoard::new();
    io.adc_counts = Some([load_cell_counts(2000.0); 4]);
    // An armed rig-mode run from standstill: `Finished` at once, at rest and live
    // (speeds 0.00 km/h), as documented.
    arm(&mut rig, 1);
    command(&mut rig, 2, rig_start(0.0)).unwrap();
    for _ in 0..20 {
        rig.step(&mut io);
    }
    assert_eq!(rig.state(), RigState::Finished);
    assert!(rig.controller_outputs_live());
    assert_eq!(last_wheel_speeds(&io), [Some(0.0); 4]);
    // Disarmed, then armed again at rest: nothing goes live (no run was set up armed).
    command(&mut rig, 3, Command::Disarm).unwrap();
    for _ in 0..20 {
        rig.step(&mut io);
    }
    assert!(safe(&rig, &io));
    arm(&mut rig, 4);
    for _ in 0..20 {
        rig.step(&mut io);
        assert!(safe(&rig, &io));
    }
    assert_eq!(rig.state(), RigState::Finished);
    // A new armed start whose build fails goes back to `Finished`: still safe.
    rig.command(rig_start(0.0)).unwrap();
    let req = rig.take_start_request().unwrap();
    assert_eq!(
        rig.install(Built {
            seq: req.seq,
            result: Err(CommandError::SpeedOutOfRange)
        }),
        Err(CommandError::SpeedOutOfRange)
    );
    assert_eq!(rig.state(), RigState::Finished);
    for _ in 0..20 {
        rig.step(&mut io);
        assert!(safe(&rig, &io));
    }
    // Only a run started armed drives them again.
    command(&mut rig, 5, rig_start(0.0)).unwrap();
    for _ in 0..20 {
        rig.step(&mut io);
    }
    assert!(rig.controller_outputs_live());
    assert_eq!(last_wheel_speeds(&io), [Some(0.0); 4]);
}

#[test]
fn rig_mode_steps_the_plant_with_the_measured_clamp_forces() {
    let mut rig = Rig::new(RigConfig::nucleo_g474re());
    let mut io = MockBoard::new();
    // Channel 3 is a pressure transducer; the others load cells.
    make_pressure_channel(&mut rig, 1, 2);
    let force = 12_000.0;
    let pressure = 350_000.0;
    let counts = [
        load_cell_counts(force),
        load_cell_counts(force),
        4095.0 * (0.1 + 0.8 * pressure / 1e6),
        load_cell_counts(force),
    ];
    io.adc_counts = Some(counts);
    arm(&mut rig, 14);
    command(&mut rig, 2, rig_start(100.0)).unwrap();
    let mut plant = Plant::<f32>::new(&Params::default(), Rail::Wet, 100.0 / 3.6).unwrap();
    for _ in 0..20_000 {
        rig.step(&mut io);
        // The reference gets the channel values the rig computed (scaling checked in the
        // sensor tests): the same inputs give the same plant, bit for bit.
        let v = |j: usize| rig.sensors[j].value();
        plant.step(&[
            BrakeInput::ClampForce(v(0)),
            BrakeInput::ClampForce(v(1)),
            BrakeInput::CylinderPressure(v(2)),
            BrakeInput::ClampForce(v(3)),
        ]);
        assert_eq!(
            rig.outputs().unwrap().vehicle_speed.to_bits(),
            plant.outputs().vehicle_speed.to_bits()
        );
        // Measured values agree with the applied force within a count of noise.
        assert!((v(0) as f64 - force).abs() < 2.0 * 40_000.0 / 3276.0);
        assert!((v(2) as f64 - pressure).abs() < 2.0 * 1e6 / 3276.0);
    }
    assert_eq!(rig.state(), RigState::Running);
    assert!(
        rig.outputs().unwrap().vehicle_speed < 100.0 / 3.6 - 1.0,
        "the brakes act"
    );
    // Rig-mode records: measured clamp force or pressure, NaN where not measured, valves
    // not known (no input wired by default).
    let r = *io.records().last().unwrap();
    assert!(r.p_cyl[0].is_nan() && r.f_clamp[2].is_nan());
    assert!((r.p_cyl[2] as f64 - pressure).abs() < 1000.0);
    assert!((r.f_clamp[0] as f64 - force).abs() < 30.0);
    assert_eq!((r.valves, r.cmd), (0, 0xFF));
}

#[test]
fn latched_sensor_fault_puts_a_rig_run_in_the_safe_state() {
    let mut rig = Rig::new(RigConfig::nucleo_g474re());
    let mut io = MockBoard::new();
    io.adc_counts = Some([load_cell_counts(8000.0); 4]);
    let start = rig_start(120.0);
    arm(&mut rig, 15);
    command(&mut rig, 1, start).unwrap();
    for _ in 0..1000 {
        rig.step(&mut io);
    }
    assert!(io.pulses.iter().all(|p| !p.unwrap().is_silent()));
    command(
        &mut rig,
        2,
        Command::InjectFault {
            channel: 1,
            fault: Some(InjectedFault::Open),
        },
    )
    .unwrap();
    let steps_before = rig.run_steps();
    let mut fault_tick = None;
    for k in 1..=20 {
        rig.step(&mut io);
        if rig.state() == RigState::Fault && fault_tick.is_none() {
            fault_tick = Some(k);
        }
    }
    // Latched after the 10-step debounce, acted on in the same tick.
    assert_eq!(fault_tick, Some(10));
    assert_eq!(
        rig.run_steps(),
        steps_before + 9,
        "the plant is no longer stepped"
    );
    // Safe state: silent trains, speeds not available, status says Fault + channel 2 + injection.
    assert!(io.pulses.iter().all(|p| p.unwrap().is_silent()));
    assert_eq!(rig.wheel_speeds_kmh(), [None; 4]);
    for _ in 0..200 {
        rig.step(&mut io);
    }
    assert_eq!(last_wheel_speeds(&io), [None; 4]);
    let (_, st) = io.frames_with(ID_STATUS).last().copied().unwrap().clone();
    let st = StatusFrame::decode(&st).unwrap();
    assert_eq!(st.state, RigState::Fault);
    assert_eq!(
        st.faults as u32 & (Faults::SENSOR | Faults::FAULT_INJECTED).bits(),
        0b10 | Faults::FAULT_INJECTED.bits()
    );
    assert!(matches!(
        io.telemetry.last(),
        Some(TelemetryEvent::End { state: 4, .. })
    ));
    let last = io.records().last().copied().unwrap();
    assert_eq!(
        last.sensor_faults,
        (SensorFault::code(Some(SensorFault::Open)) as u16) << 4
    );

    // A new rig run is refused while the fault is latched; clearing needs the cause gone.
    assert_eq!(command(&mut rig, 3, start), Err(CommandError::SensorFaults));
    command(&mut rig, 4, Command::ClearFaults).unwrap();
    assert_eq!(rig.state(), RigState::Fault);
    command(
        &mut rig,
        5,
        Command::InjectFault {
            channel: 1,
            fault: None,
        },
    )
    .unwrap();
    // The debounce score decays one per clean step: 90 steps after the cause went.
    for _ in 0..89 {
        rig.step(&mut io);
    }
    command(&mut rig, 6, Command::ClearFaults).unwrap();
    assert_eq!(rig.state(), RigState::Fault, "cause gone only 89 steps ago");
    rig.step(&mut io);
    command(&mut rig, 8, Command::ClearFaults).unwrap();
    assert_eq!(rig.state(), RigState::Stopped);
    assert_eq!(rig.faults().bits() & 0xFFFF, 0);
    // The fault disarmed the rig: armed again for the next run.
    arm(&mut rig, 12);
    command(&mut rig, 9, start).unwrap();
    assert_eq!(rig.state(), RigState::Running);
}

#[test]
fn each_plausibility_fault_stops_a_rig_run_and_self_test_only_reports() {
    for fault in [
        InjectedFault::Open,
        InjectedFault::Short,
        InjectedFault::OutOfRange,
        InjectedFault::Stuck,
    ] {
        for mode in [RigMode::Rig, RigMode::SelfTest] {
            let mut rig = Rig::new(RigConfig::nucleo_g474re());
            let mut io = MockBoard::new();
            io.adc_counts = Some([load_cell_counts(5000.0); 4]);
            arm(&mut rig, 15);
            command(
                &mut rig,
                1,
                Command::Start(StartCommand {
                    mode,
                    rail: Rail::Wet,
                    friction: FrictionModel::Constant,
                    emergency: true,
                    initial_speed_kmh: 150.0,
                    track: false,
                    setup_digest: default_setup_digest(),
                }),
            )
            .unwrap();
            rig.step(&mut io);
            command(
                &mut rig,
                2,
                Command::InjectFault {
                    channel: 3,
                    fault: Some(fault),
                },
            )
            .unwrap();
            for _ in 0..6000 {
                rig.step(&mut io);
            }
            assert!(rig.faults().bits() & (1 << 3) != 0, "{fault:?} {mode:?}");
            let want = if mode == RigMode::Rig {
                RigState::Fault
            } else {
                RigState::Running
            };
            assert_eq!(rig.state(), want, "{fault:?} {mode:?}");
        }
    }
}

#[test]
fn stale_adc_stops_a_rig_run_after_ten_ticks() {
    let (mut rig, mut io) = rig_run_started_at_3_kn();
    for _ in 0..100 {
        rig.step(&mut io);
    }
    io.adc_counts = None;
    for k in 1..=9 {
        rig.step(&mut io);
        assert_eq!(rig.state(), RigState::Running, "tick {k}");
        assert!(rig.faults().intersects(Faults::ADC_STALE));
    }
    rig.step(&mut io);
    assert_eq!(rig.state(), RigState::Fault);
}

#[test]
fn start_is_built_outside_the_step_and_handed_over() {
    let mut rig = Rig::new(RigConfig::nucleo_g474re());
    let mut io = MockBoard::new();
    let start = paper_start(FrictionModel::Variable);
    // The step's command path only requests the run.
    rig.command(start).unwrap();
    assert_eq!(rig.state(), RigState::Starting);
    assert_eq!(
        rig.command(start),
        Err(CommandError::NotNow(RigState::Starting))
    );
    for _ in 0..50 {
        rig.step(&mut io);
    }
    // Nothing runs, outputs safe, no run events until the simulation arrives.
    assert_eq!(rig.state(), RigState::Starting);
    assert_eq!(rig.run_steps(), 0);
    assert!(rig.outputs().is_none());
    assert!(io.pulses.iter().all(|p| p.unwrap().is_silent()));
    assert!(io.telemetry.is_empty());
    let (_, st) = io.frames_with(ID_STATUS).last().copied().unwrap().clone();
    assert_eq!(StatusFrame::decode(&st).unwrap().state, RigState::Starting);
    // The builder gets the request once.
    let req = rig.take_start_request().unwrap();
    assert_eq!(rig.take_start_request(), None);
    assert_eq!(req.mode, RigMode::SelfTest);
    rig.install(req.build()).unwrap();
    assert_eq!(rig.state(), RigState::Running);
    rig.step(&mut io);
    assert_eq!(rig.run_steps(), 1);
    assert!(matches!(
        io.telemetry.first(),
        Some(TelemetryEvent::Header(_))
    ));
    // The same run as one built directly (independent construction).
    let mut c = ClosedLoop::<f32>::new(&Params::default(), Rail::Wet, 150.0 / 3.6).unwrap();
    c.set_demand(BrakeDemand::Emergency);
    c.step();
    assert_eq!(
        rig.outputs().unwrap().vehicle_speed,
        c.outputs().vehicle_speed
    );

    // Stop while starting cancels; a simulation arriving late is discarded.
    rig.command(Command::Stop).unwrap();
    rig.step(&mut io);
    rig.command(start).unwrap();
    let req = rig.take_start_request().unwrap();
    rig.command(Command::Stop).unwrap();
    assert_eq!(rig.state(), RigState::Stopped);
    assert!(rig.install(req.build()).is_err());
    assert_eq!(rig.state(), RigState::Stopped);
    assert!(rig.outputs().is_none());

    // A failed build goes back to the state before, with the command rejected.
    rig.command(start).unwrap();
    let req = rig.take_start_request().unwrap();
    assert_eq!(
        rig.install(Built {
            seq: req.seq,
            result: Err(CommandError::SpeedOutOfRange)
        }),
        Err(CommandError::SpeedOutOfRange)
    );
    assert_eq!(rig.state(), RigState::Stopped);
    assert!(rig.faults().intersects(Faults::COMMAND_REJECTED));
}

#[test]
fn a_350_kmh_run_is_sent_unsaturated_at_0_01_kmh() {
    let mut rig = Rig::new(RigConfig::nucleo_g474re());
    let mut io = MockBoard::new();
    // An armed rig-mode run with no brake applied (load cells at zero).
    io.adc_counts = Some([load_cell_counts(0.0); 4]);
    arm(&mut rig, 15);
    command(&mut rig, 1, rig_start(350.0)).unwrap();
    for _ in 0..100 {
        rig.step(&mut io);
    }
    assert!(!rig.faults().intersects(Faults::SPEED_SATURATED));
    let sent = last_wheel_speeds(&io);
    for j in 0..4 {
        let v = rig.wheel_speeds_kmh()[j].unwrap();
        assert!(v > 349.0, "{v}");
        assert!((sent[j].unwrap() - v).abs() <= 0.0051 + 1e-5 * v, "{j}");
    }
}

// ---- Fault injection: the cases of issue 11, item 7 ----

#[test]
fn an_open_wire_on_nine_ticks_of_ten_faults_a_rig_run_in_bounded_time() {
    let mut rig = Rig::new(RigConfig::nucleo_g474re());
    let mut io = MockBoard::new();
    let good = load_cell_counts(6000.0);
    io.adc_counts = Some([good; 4]);
    arm(&mut rig, 15);
    command(&mut rig, 1, rig_start(100.0)).unwrap();
    for _ in 0..200 {
        rig.step(&mut io);
    }
    let mut fault_tick = None;
    for k in 0..200u32 {
        // Channel 1 open (0 V) on 9 ticks of 10.
        let ch1 = if k % 10 == 9 { good } else { 0.0 };
        io.adc_counts = Some([ch1, good, good, good]);
        rig.step(&mut io);
        if rig.state() == RigState::Fault {
            fault_tick = Some(k + 1);
            break;
        }
    }
    // Score +9 per open tick, -1 per clean one, latch at 90: tick 12 (independent count).
    assert_eq!(fault_tick, Some(12));
    assert!(rig.faults().bits() & (1) != 0);
    assert!(io.pulses.iter().all(|p| p.unwrap().is_silent()));
}

#[test]
fn set_kind_clears_no_fault_and_a_rig_start_stays_refused() {
    let mut rig = Rig::new(RigConfig::nucleo_g474re());
    let mut io = MockBoard::new();
    let good = load_cell_counts(0.0);
    // Channel 3 open while idle: latches before any run.
    io.adc_counts = Some([good, good, 0.0, good]);
    for _ in 0..20 {
        rig.step(&mut io);
    }
    assert!(rig.faults().bits() & (1 << 2) != 0);
    make_pressure_channel(&mut rig, 1, 2);
    assert!(
        rig.faults().bits() & (1 << 2) != 0,
        "SetKind cleared the fault"
    );
    command(&mut rig, 2, Command::ClearFaults).unwrap();
    assert!(
        rig.faults().bits() & (1 << 2) != 0,
        "cleared with the wire open"
    );
    assert_eq!(
        command(&mut rig, 3, rig_start(80.0)),
        Err(CommandError::SensorFaults)
    );
    // Wire repaired, debounce decayed (90 clean ticks): clear and start succeed.
    io.adc_counts = Some([good; 4]);
    for _ in 0..90 {
        rig.step(&mut io);
    }
    command(&mut rig, 4, Command::ClearFaults).unwrap();
    assert!(!rig.faults().intersects(Faults::SENSOR));
    arm(&mut rig, 14);
    command(&mut rig, 5, rig_start(80.0)).unwrap();
}

#[test]
fn a_stalled_dma_in_self_test_is_adc_stale_not_four_stuck_sensors() {
    let (mut rig, mut io) = paper_self_test_started(FrictionModel::Variable);
    for _ in 0..100 {
        rig.step(&mut io);
    }
    io.adc_counts = None;
    // Longer than the 5000-step stuck window.
    for _ in 0..6000 {
        rig.step(&mut io);
    }
    let f = rig.faults();
    assert!(f.intersects(Faults::ADC_STALE));
    assert!(!f.intersects(Faults::SENSOR), "{:#x}", f.bits());
    assert_eq!(
        rig.state(),
        RigState::Running,
        "self-test closes no loop on the ADC"
    );
    // The cause is present: ClearFaults keeps ADC_STALE.
    command(&mut rig, 2, Command::ClearFaults).unwrap();
    assert!(rig.faults().intersects(Faults::ADC_STALE));
    io.adc_counts = Some([409.5; 4]);
    rig.step(&mut io);
    command(&mut rig, 3, Command::ClearFaults).unwrap();
    assert!(!rig.faults().intersects(Faults::ADC_STALE));
}

#[test]
fn stale_adc_fault_is_not_cleared_while_the_adc_is_stale() {
    let (mut rig, mut io) = rig_run_started_at_3_kn();
    rig.step(&mut io);
    io.adc_counts = None;
    for _ in 0..20 {
        rig.step(&mut io);
    }
    assert_eq!(rig.state(), RigState::Fault);
    command(&mut rig, 2, Command::ClearFaults).unwrap();
    assert_eq!(rig.state(), RigState::Fault);
    assert!(rig.faults().intersects(Faults::ADC_STALE));
    io.adc_counts = Some([load_cell_counts(3000.0); 4]);
    rig.step(&mut io);
    command(&mut rig, 3, Command::ClearFaults).unwrap();
    assert_eq!(rig.state(), RigState::Stopped);
}

#[test]
fn bus_state_reaches_flags_and_diag_and_clear_is_passed_to_the_board() {
    let (mut rig, mut io) = paper_self_test_started(FrictionModel::Variable);
    rig.set_bus(true, false, 0);
    rig.step(&mut io);
    assert!(rig.faults().intersects(Faults::CAN_ERROR_PASSIVE));
    assert!(!rig.faults().intersects(Faults::CAN_BUS_OFF));
    rig.set_bus(false, true, 3);
    for _ in 0..1000 {
        rig.step(&mut io);
    }
    let f = rig.faults();
    assert!(f.intersects(Faults::CAN_BUS_OFF) && !f.intersects(Faults::CAN_ERROR_PASSIVE));
    let (_, d) = io.frames_with(ID_DIAG).last().copied().unwrap().clone();
    assert_eq!(DiagFrame::decode(&d).unwrap().bus_off_count, 3);
    // Bus faults are flagged, the run goes on.
    assert_eq!(rig.state(), RigState::Running);
    let (_, st) = io.frames_with(ID_STATUS).last().copied().unwrap().clone();
    assert!(StatusFrame::decode(&st).unwrap().faults as u32 & Faults::CAN_BUS_OFF.bits() != 0);
    // ClearFaults asks the board's monitor once; the flag goes only when the board says so.
    assert!(!rig.take_bus_clear());
    command(&mut rig, 2, Command::ClearFaults).unwrap();
    assert!(rig.take_bus_clear());
    assert!(!rig.take_bus_clear());
    assert!(rig.faults().intersects(Faults::CAN_BUS_OFF));
    rig.set_bus(false, false, 3);
    assert!(!rig.faults().intersects(Faults::CAN_BUS_OFF));
}

#[test]
fn commands_are_checked_and_results_reported() {
    let mut rig = Rig::new(RigConfig::nucleo_g474re());
    let mut io = MockBoard::new();
    assert_eq!(
        command(&mut rig, 1, Command::Stop),
        Err(CommandError::NotNow(RigState::Idle))
    );
    assert!(rig.faults().intersects(Faults::COMMAND_REJECTED));
    command(&mut rig, 2, Command::ClearFaults).unwrap();
    assert!(!rig.faults().intersects(Faults::COMMAND_REJECTED));
    // Repeated counter: ignored.
    assert_eq!(
        command(&mut rig, 2, Command::ClearFaults),
        Err(CommandError::Repeated)
    );
    // Speed beyond the wheel-speed frame's range.
    let mut too_fast = paper_start(FrictionModel::Variable);
    if let Command::Start(s) = &mut too_fast {
        s.initial_speed_kmh = 700.0;
    }
    assert_eq!(
        command(&mut rig, 3, too_fast),
        Err(CommandError::SpeedOutOfRange)
    );
    // Configuration: divider 10 -> a record every 10 steps; teeth 45 -> half the frequency.
    command(
        &mut rig,
        4,
        Command::Configure(ConfigItem::TelemetryDivider(10)),
    )
    .unwrap();
    command(&mut rig, 5, Command::Configure(ConfigItem::Teeth(45))).unwrap();
    command(&mut rig, 6, paper_start(FrictionModel::Variable)).unwrap();
    for _ in 0..100 {
        rig.step(&mut io);
    }
    let steps: Vec<u32> = io.records().iter().map(|r| r.step).collect();
    assert_eq!(steps, (0..=100).step_by(10).collect::<Vec<_>>());
    // A self-test run drives no pulse train (teeth 45 takes effect in an armed rig run:
    // `wheel_speed_outputs_follow_the_plant_in_an_armed_rig_run`).
    assert!(io.pulses.iter().all(|p| p.unwrap().is_silent()));
    // Not during a run: calibration, configuration, a second start.
    assert_eq!(
        command(
            &mut rig,
            7,
            Command::Calibrate {
                channel: 0,
                action: Calibration::Tare
            }
        ),
        Err(CommandError::NotNow(RigState::Running))
    );
    assert_eq!(
        command(&mut rig, 8, Command::Configure(ConfigItem::Teeth(10))),
        Err(CommandError::NotNow(RigState::Running))
    );
    assert_eq!(
        command(&mut rig, 9, paper_start(FrictionModel::Constant)),
        Err(CommandError::NotNow(RigState::Running))
    );
    // A brake command during the self-test reaches the simulated unit: release -> the
    // cylinder pressure falls.
    command(&mut rig, 10, Command::Brake(BrakeCommand::Release)).unwrap();
    for _ in 0..20_000 {
        rig.step(&mut io);
    }
    let r = io.records().last().copied().unwrap();
    assert_eq!(r.cmd, 0);
    assert!(r.p_cyl.iter().all(|&p| p < 1000.0), "{:?}", r.p_cyl);
    // Stop: safe state and an end line.
    command(&mut rig, 11, Command::Stop).unwrap();
    rig.step(&mut io);
    assert_eq!(rig.state(), RigState::Stopped);
    assert!(io.pulses.iter().all(|p| p.unwrap().is_silent()));
    assert!(matches!(
        io.telemetry.last(),
        Some(TelemetryEvent::End { state: 3, .. })
    ));
    // Status reports the last result.
    for _ in 0..100 {
        rig.step(&mut io);
    }
    let (_, st) = io.frames_with(ID_STATUS).last().copied().unwrap().clone();
    assert_eq!(
        StatusFrame::decode(&st).unwrap().command_result,
        CommandResult::Accepted
    );
    // A corrupted command frame is rejected and reported.
    let mut bad: TestFrame = CommandFrame {
        command: Command::Stop,
        counter: 12,
    }
    .encode()
    .unwrap();
    bad.data[0] ^= 0x40;
    assert!(matches!(
        rig.command_frame(&bad),
        Err(CommandError::Frame(_))
    ));
    for _ in 0..100 {
        rig.step(&mut io);
    }
    let (_, st) = io.frames_with(ID_STATUS).last().copied().unwrap().clone();
    let st = StatusFrame::decode(&st).unwrap();
    assert_eq!(st.command_result, CommandResult::Rejected);
    assert!(st.faults as u32 & Faults::COMMAND_REJECTED.bits() != 0);
}

#[test]
fn idle_outputs_are_safe_and_frames_keep_coming() {
    let mut rig = Rig::new(RigConfig::nucleo_g474re());
    let mut io = MockBoard::new();
    io.adc_counts = None;
    for _ in 0..1000 {
        rig.step(&mut io);
    }
    assert!(io.pulses.iter().all(|p| p.unwrap().is_silent()));
    assert_eq!(io.frames_with(ID_WHEEL_SPEED_12).len(), 100);
    assert_eq!(io.frames_with(ID_WHEEL_SPEED_34).len(), 100);
    assert_eq!(io.frames_with(ID_STATUS).len(), 10);
    let (_, st) = io.frames_with(ID_STATUS)[9].clone();
    let st = StatusFrame::decode(&st).unwrap();
    assert_eq!((st.state, st.vehicle_speed_kmh), (RigState::Idle, 0.0));
    assert!(io.telemetry.is_empty(), "no run, no telemetry");
    // Without a rig the ADC is stale: flagged, but Idle stays Idle.
    assert!(rig.faults().intersects(Faults::ADC_STALE));
}

#[test]
fn full_queues_and_overruns_are_counted_and_flagged() {
    let (mut rig, mut io) = paper_self_test_started(FrictionModel::Variable);
    io.frame_room = 3;
    io.telemetry_room = 2;
    for k in 0..1000u32 {
        rig.step(&mut io);
        // Step 500 takes 18 000 cycles (> 17 000): an overrun; step 700 starts 3 periods late.
        let entry = k * 17_000 + if k >= 700 { 34_000 } else { 0 };
        let dur = if k == 500 { 18_000 } else { 5_000 };
        rig.record_timing(entry, entry + dur, false);
    }
    let f = rig.faults();
    assert!(f.intersects(Faults::CAN_TX_DROPPED));
    assert!(f.intersects(Faults::TELEMETRY_DROPPED));
    assert!(f.intersects(Faults::OVERRUN));
    assert!(f.intersects(Faults::MISSED_TICKS));
    assert_eq!(rig.timing().overruns, 1);
    assert_eq!(rig.timing().missed_ticks, 2);
    assert_eq!(rig.timing().run_max_cycles, 18_000);
    // The run goes on.
    assert_eq!(rig.state(), RigState::Running);
}

#[test]
fn memory_of_the_rig_fits_the_board() {
    let size = core::mem::size_of::<Rig>();
    println!("size_of::<Rig>() = {size} bytes");
    // The board's static RAM budget is 32 KiB; the rig must leave room for the HAL,
    // the executor, the queues and the defmt buffer.
    assert!(size < 16 * 1024, "{size}");
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig { cases: 64, ..Default::default() })]
    /// Arbitrary command frames and ADC garbage between steps: nothing panics, outputs stay
    /// valid register values.
    #[test]
    fn arbitrary_commands_and_adc_never_panic(
        frames in proptest::collection::vec((0u16..0x800, proptest::collection::vec(proptest::num::u8::ANY, 0..9)), 1..40),
        adc in proptest::collection::vec(proptest::array::uniform4(0.0f64..5000.0), 1..40),
    ) {
        let mut rig = Rig::new(RigConfig::nucleo_g474re());
        let mut io = MockBoard::new();
        command(&mut rig, 15, paper_start(FrictionModel::Variable)).ok();
        for (k, (id, bytes)) in frames.iter().enumerate() {
            let f = TestFrame::new(StandardId::new(*id).unwrap(), bytes).unwrap();
            let _ = rig.command_frame(&f);
            io.adc_counts = Some(adc[k % adc.len()]);
            for _ in 0..50 {
                rig.step(&mut io);
            }
            for p in io.pulses.iter().flatten() {
                proptest::prop_assert!(p.arr <= 0xFFFF && p.ccr <= p.arr + 1);
            }
        }
    }
}

/// Start, Stop while starting, a second Start before the builder is done: the first build
/// must not run under the second request (it is refused and counted); the second runs.
#[test]
fn a_late_build_is_not_installed_under_a_later_start() {
    let mut rig = Rig::new(RigConfig::nucleo_g474re());
    let mut io = MockBoard::new();
    let first = paper_start(FrictionModel::Variable);
    let Command::Start(first_values) = first else {
        unreachable!()
    };
    let second = Command::Start(StartCommand {
        initial_speed_kmh: 80.0,
        track: false,
        setup_digest: default_setup_digest(),
        ..first_values
    });
    rig.command(first).unwrap();
    let req1 = rig.take_start_request().unwrap();
    rig.command(Command::Stop).unwrap();
    rig.command(second).unwrap();
    // The builder still has the first request (and the rig's simulation store).
    assert_eq!(rig.take_start_request(), None);
    for _ in 0..5 {
        rig.step(&mut io);
    }
    assert!(rig.outputs().is_none());
    // The builder finishes the first request only now.
    assert_eq!(
        rig.install(req1.build()),
        Err(CommandError::StaleBuild { seq: req1.seq })
    );
    assert_eq!(rig.state(), RigState::Starting);
    assert_eq!(rig.stale_builds(), 1);
    assert!(rig.outputs().is_none());
    let req2 = rig.take_start_request().unwrap();
    assert_ne!(req1.seq, req2.seq);
    rig.install(req2.build()).unwrap();
    rig.step(&mut io);
    // The run is the second request's: 80 km/h, not 150.
    let v_kmh = rig.outputs().unwrap().vehicle_speed * 3.6;
    assert!((v_kmh - 80.0).abs() < 0.5, "v = {v_kmh} km/h");
    assert_eq!(rig.stale_builds(), 1);
}

/// A request the board could not pass to a busy builder is offered again, once, and only
/// while it is still the pending one.
#[test]
fn a_request_not_passed_on_is_offered_again() {
    let mut rig = Rig::new(RigConfig::nucleo_g474re());
    rig.command(paper_start(FrictionModel::Variable)).unwrap();
    let req = rig.take_start_request().unwrap();
    assert_eq!(rig.take_start_request(), None);
    rig.retry_start_request(&req);
    assert_eq!(rig.take_start_request(), Some(req));
    rig.command(Command::Stop).unwrap();
    rig.retry_start_request(&req);
    assert_eq!(rig.take_start_request(), None);
}

/// A store outside the rig (as on the board) that counts the rig's accesses while the
/// builder owns it.
struct WatchedStore {
    sim: Simulation,
    lent: Rc<Cell<bool>>,
    touched_while_lent: Rc<Cell<u32>>,
}

impl SimStore for WatchedStore {
    fn sim(&self) -> &Simulation {
        if self.lent.get() {
            self.touched_while_lent
                .set(self.touched_while_lent.get() + 1);
        }
        &self.sim
    }
    fn sim_mut(&mut self) -> &mut Simulation {
        if self.lent.get() {
            self.touched_while_lent
                .set(self.touched_while_lent.get() + 1);
        }
        &mut self.sim
    }
}

/// While the builder owns the store (request handed out, no build back), nothing the
/// step does touches it: steps, Brake, Stop, a second Start.
#[test]
fn the_rig_leaves_a_lent_store_alone() {
    let lent = Rc::new(Cell::new(false));
    let touched = Rc::new(Cell::new(0));
    let store = WatchedStore {
        sim: Simulation::none(),
        lent: lent.clone(),
        touched_while_lent: touched.clone(),
    };
    let mut rig = Rig::with_store(RigConfig::nucleo_g474re(), store);
    let mut io = MockBoard::new();
    let start = paper_start(FrictionModel::Variable);
    rig.command(start).unwrap();
    let req = rig.take_start_request().unwrap();
    lent.set(true);
    for _ in 0..20 {
        rig.step(&mut io);
    }
    rig.command(Command::Brake(BrakeCommand::Release)).unwrap();
    rig.command(Command::Stop).unwrap();
    rig.step(&mut io);
    rig.command(start).unwrap();
    assert_eq!(rig.take_start_request(), None, "the store is still lent");
    for _ in 0..20 {
        rig.step(&mut io);
    }
    assert!(rig.outputs().is_none());
    assert_eq!(touched.get(), 0);
    // The stale build comes back; the store is the rig's again, the next request goes out.
    lent.set(false);
    assert_eq!(
        rig.install_in_place(Built {
            seq: req.seq,
            result: Ok(())
        }),
        Err(CommandError::StaleBuild { seq: req.seq })
    );
    let req2 = rig.take_start_request().unwrap();
    assert_eq!(req2.seq, req.seq + 1);
}
