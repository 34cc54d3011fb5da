//! `hils rig` end to end against the in-process board (`--interface sim`): the board's own
//! logic (`hils_rig_core::rig::Rig`) behind the in-process bus, the simulated brake unit as
//! the controller under test reading the wheel-speed frames. Every result here is read
//! from frames only, and checked against the board's own state or an independent run.

use std::path::PathBuf;

use hils::decode::rig_core::can::{
    Command, InjectedFault, RigMode, RigState, StartCommand, WHEEL_SPEED_MAX_KMH,
};
use hils::decode::rig_core::rig::Faults;
use hils::decode::rig_core::sensor::SensorFault;
use hils::rig::commands::Session;
use hils::rig::monitor::Alarm;
use hils::rig::sim::{SimBoard, SimFaults};
use hils::rig::{Line, parse_script, run_session};
use hils_brake_unit::BrakeDemand;
use hils_plant::{FrictionModel, Params, Rail};
use hils_sil::scenario::at_standstill;
use hils_sil::{ClosedLoop, KMH_PER_MPS};

fn session(faults: SimFaults) -> Session<SimBoard> {
    Session::new(SimBoard::new(faults, false), 0.5)
}

fn start(speed_kmh: f32) -> Command {
    Command::Start(StartCommand {
        mode: RigMode::Rig,
        rail: Rail::Wet,
        friction: FrictionModel::Variable,
        emergency: false,
        initial_speed_kmh: speed_kmh,
        track: false,
        // A fresh board's setup: one rail, the default vehicle.
        setup_digest: hils::decode::rig_core::digest::setup_digest(None, &Default::default()),
    })
}

/// Arms the board for the controller, then starts a rig-mode run at `speed_kmh`.
fn start_armed(s: &mut Session<SimBoard>, speed_kmh: f32) -> hils::rig::commands::Outcome {
    let o = s.command(Command::Arm).unwrap();
    assert!(o.accepted, "{o}");
    s.command(start(speed_kmh)).unwrap()
}

fn out_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("hils-rig-test-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Independent reference: the SIL loop in f64 from the same start, brake at t = 0; the time
/// to standstill, s.
fn sil_stop_s(rail: Rail, demand: BrakeDemand, speed_kmh: f64) -> f64 {
    let mut sil =
        ClosedLoop::<f64>::new(&Params::default(), rail, speed_kmh / KMH_PER_MPS).unwrap();
    sil.set_demand(demand);
    let mut steps = 0u32;
    while !at_standstill({
        sil.step();
        sil.plant.vehicle_speed()
    }) {
        steps += 1;
    }
    steps as f64 * 1e-4
}

fn script(text: &str) -> Vec<Line> {
    parse_script(&PathBuf::from("test.rig"), text).expect("script parses")
}

#[test]
fn start_status_stop_agree_with_the_board() {
    let mut s = session(SimFaults::default());
    assert_eq!(s.status().unwrap().state, RigState::Idle);
    let o = start_armed(&mut s, 80.0);
    assert!(o.accepted, "{o}");
    s.run_for(0.15, |_, _| hils::rig::commands::Flow::Continue)
        .unwrap();
    assert_eq!(s.board.armed(), Some(true));
    assert_eq!(o.status.state, RigState::Running);
    assert_eq!(s.link.rig().state(), RigState::Running);
    // The status frame's speed is the board's plant speed (0.01 km/h resolution).
    let st = s.next_status(1).unwrap();
    let v = s.link.rig().outputs().unwrap().vehicle_speed * hils::decode::rig_core::KMH_PER_MPS;
    assert!(
        (st.vehicle_speed_kmh - v).abs() < 0.05,
        "{} vs {v}",
        st.vehicle_speed_kmh
    );
    // The wheel-speed frames carry the four speeds while the run is live.
    let (_, w) = s.board.wheel_speed.unwrap();
    assert!(
        w.speeds_kmh
            .iter()
            .all(|x| x.is_some_and(|x| (x - 80.0).abs() < 1.0))
    );
    let o = s.command(Command::Stop).unwrap();
    assert!(o.accepted, "{o}");
    assert_eq!(o.status.state, RigState::Stopped);
    assert_eq!(s.link.rig().state(), RigState::Stopped);
    // Safe state: the speeds are "not available" in the next wheel-speed frames, and
    // RIG_HEALTH says the stop disarmed the board.
    s.run_for(0.15, |_, _| hils::rig::commands::Flow::Continue)
        .unwrap();
    let (_, w) = s.board.wheel_speed.unwrap();
    assert_eq!(w.speeds_kmh, [None; 4]);
    assert_eq!(s.board.armed(), Some(false));
    assert_eq!(
        s.board.health.unwrap().1.disarmed,
        Some(hils::decode::rig_core::arming::Disarm::Stop)
    );
    assert_eq!(s.board.counts.bad, 0);
    assert_eq!(
        (s.board.wheel_alive.lost, s.board.status_alive.lost),
        (0, 0)
    );
}

#[test]
fn rejections_are_reported_with_the_board_rule() {
    let mut s = session(SimFaults::default());
    let o = s.command(Command::Stop).unwrap();
    assert!(!o.accepted);
    assert!(
        o.reason
            .as_deref()
            .unwrap()
            .contains("no run to stop (state idle)"),
        "{o}"
    );
    assert!(o.status.faults as u32 & Faults::COMMAND_REJECTED.bits() != 0);
    // A rig-mode start on a board not armed for the controller.
    let o = s.command(start(60.0)).unwrap();
    assert!(!o.accepted);
    assert!(
        o.reason
            .as_deref()
            .unwrap()
            .contains("not armed for a controller"),
        "{o}"
    );
    assert_eq!(s.link.rig().state(), RigState::Idle);
    let o = start_armed(&mut s, WHEEL_SPEED_MAX_KMH + 10.0);
    assert!(!o.accepted);
    assert!(
        o.reason
            .as_deref()
            .unwrap()
            .contains(&format!("outside 0-{WHEEL_SPEED_MAX_KMH:.2} km/h")),
        "{o}"
    );
    assert_eq!(s.link.rig().state(), RigState::Idle);
    assert!(s.command(start(60.0)).unwrap().accepted);
    let o = s.command(start(60.0)).unwrap();
    assert!(!o.accepted);
    assert!(
        o.reason.as_deref().unwrap().contains("a run is active"),
        "{o}"
    );
    // The run goes on: a rejected command changes nothing.
    assert_eq!(s.link.rig().state(), RigState::Running);
}

#[test]
fn injected_sensor_fault_ends_the_run_and_blocks_a_start_until_cleared() {
    let mut s = session(SimFaults::default());
    assert!(start_armed(&mut s, 60.0).accepted);
    let o = s
        .command(Command::InjectFault {
            channel: 1,
            fault: Some(InjectedFault::Open),
        })
        .unwrap();
    assert!(o.accepted, "{o}");
    // The board latches the fault after its debounce and goes to its safe state.
    let mut state = RigState::Running;
    s.run_for(0.2, |b, _| {
        state = b.status().unwrap().state;
        if state == RigState::Fault {
            hils::rig::commands::Flow::Done
        } else {
            hils::rig::commands::Flow::Continue
        }
    })
    .unwrap();
    assert_eq!(state, RigState::Fault);
    let st = s.board.status().unwrap();
    assert!(
        st.faults as u32 & 0x2 != 0,
        "sensor 2 flagged: {:#x}",
        st.faults
    );
    assert!(st.faults as u32 & Faults::FAULT_INJECTED.bits() != 0);
    s.run_for(0.2, |_, _| hils::rig::commands::Flow::Continue)
        .unwrap();
    assert_eq!(
        s.board.diag.unwrap().1.sensor_faults[1],
        Some(SensorFault::Open)
    );
    let o = s.command(start(60.0)).unwrap();
    assert!(!o.accepted);
    assert!(o.reason.as_deref().unwrap().contains("channel(s) 2"), "{o}");
    let remove = Command::InjectFault {
        channel: 1,
        fault: None,
    };
    assert!(s.command(remove).unwrap().accepted);
    let o = s.command(Command::ClearFaults).unwrap();
    assert!(o.accepted);
    assert_eq!(o.status.state, RigState::Stopped);
    assert!(start_armed(&mut s, 60.0).accepted);
}

/// The rig loop over CAN (speeds quantised to 0.01 km/h and held 1 ms, pressures through a
/// 12-bit ADC with noise) stops the train as the SIL loop does, and its run log is read by
/// the diagnosis, whose replay of the board-measured inputs explains it within the noise.
#[test]
fn eb_run_over_the_bus_matches_sil_and_its_log_is_diagnosed() {
    let dir = out_dir("eb");
    let csv = dir.join("run.csv");
    let mut s = session(SimFaults::default());
    let lines = script(&format!(
        "record --out {}\nstart --speed-kmh 100 --rail wet --friction variable --arm\nbrake eb\nwait --until-end\n",
        csv.display()
    ));
    run_session(&mut s, &lines, false).expect("session");
    assert_eq!(s.link.rig().state(), RigState::Finished);

    // The board's pulse channels over the whole stop, on the timer model: every period
    // against the setting it was loaded from. Dithered, the differences cancel (their
    // sum stays within a few counts); undithered, each period would be short by the
    // setting's fraction, -0.5 count on average.
    for (j, d) in s.link.pulse_dither_check().iter().enumerate() {
        assert!(
            d.periods > 5_000,
            "wheelset {}: {} periods",
            j + 1,
            d.periods
        );
        assert!(
            d.sum_error_counts.abs() < 0.001 * d.periods as f64,
            "wheelset {}: {:.1} counts over {} periods",
            j + 1,
            d.sum_error_counts,
            d.periods
        );
    }

    let sil_stop_s = sil_stop_s(Rail::Wet, BrakeDemand::Emergency, 100.0);

    let log = hils::measured::read_run_log(&csv).expect("reader accepts the rig log");
    assert_eq!(log.rail, Some(Rail::Wet));
    let eb_s: f64 = log.metadata.get("eb_command_s").unwrap().parse().unwrap();
    let stop_row = log.v_ref_mps.iter().position(|&v| v < 0.05).expect("stops");
    let rig_stop_s = log.t_s[stop_row] - eb_s;
    assert!(
        (rig_stop_s - sil_stop_s).abs() < 0.03 * sil_stop_s,
        "rig {rig_stop_s} s vs SIL {sil_stop_s} s"
    );
    // 1 kHz rows; omega * r is the frame's wheel speed within its 0.01 km/h.
    assert!((log.median_interval_s() - 1e-3).abs() < 1e-9);
    assert!(log.p_cyl_pa.iter().all(|p| p.is_some()));
    let r = Params::default().vehicle.wheel_radius;
    let peak = log.p_cyl_pa[0]
        .as_ref()
        .unwrap()
        .iter()
        .cloned()
        .fold(0.0, f64::max);
    assert!(peak > 1e5, "EB pressure measured by the board: {peak} Pa");
    assert!((log.omega_radps[0][0] * r * KMH_PER_MPS - 100.0).abs() < 0.01);

    let json = dir.join("diag.json");
    hils::diagnose::main(hils::diagnose::DiagnoseArgs {
        baseline: PathBuf::from(env!("CARGO_MANIFEST_DIR"))
            .join("../../shared/spec/reference-parameters.toml"),
        out: hils::outputs::Outputs {
            json: Some(json.clone()),
            report: None,
        },
        step_s: hils::diagnose::replay::REPLAY_STEP_S,
        // The board's log has the spec's column names: no channel map.
        map: None,
        files: vec![csv],
    })
    .expect("hils diagnose reads the rig log");
    let d: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(json).unwrap()).unwrap();
    assert_eq!(d["discrepancy"], false, "{d}");
}

#[test]
fn a_lost_board_ends_the_session_and_keeps_the_recording() {
    let dir = out_dir("lost");
    let csv = dir.join("run.csv");
    let faults = SimFaults {
        board_lost_at_s: Some(1.0),
        ..Default::default()
    };
    let mut s = session(faults);
    let lines = script(&format!(
        "record --out {}\nstart --speed-kmh 100 --rail wet --friction variable --arm\nbrake eb\nwait --until-end\n",
        csv.display()
    ));
    let e = run_session(&mut s, &lines, false).unwrap_err();
    assert!(e.to_string().contains("board lost"), "{e}");
    // Silent from 1.0 s; declared lost 0.5 s later.
    let now = hils::rig::transport::Transport::now_s(&s.link);
    assert!((1.49..1.51).contains(&now), "{now}");
    let log = hils::measured::read_run_log(&csv).expect("recording kept");
    let last = *log.t_s.last().unwrap();
    assert!((0.9..1.0).contains(&last), "recorded up to {last} s");
    assert!(log.metadata.get("end").unwrap().contains("board lost"));
}

/// A session with `faults` simulated, started at 100 km/h and run up to 5 s: the session
/// and the alarm that must end it before then.
fn session_ended_by(faults: SimFaults) -> (Session<SimBoard>, Alarm) {
    let mut s = session(faults);
    assert!(start_armed(&mut s, 100.0).accepted);
    let e = s
        .run_for(5.0, |_, _| hils::rig::commands::Flow::Continue)
        .unwrap_err();
    (s, e)
}

#[test]
fn bus_off_and_a_stuck_alive_counter_end_the_session() {
    let (_, e) = session_ended_by(SimFaults {
        bus_off_at_s: Some(0.3),
        ..Default::default()
    });
    assert_eq!(e, Alarm::HostBusOff);

    let (s, e) = session_ended_by(SimFaults {
        status_alive_frozen_at_s: Some(0.5),
        ..Default::default()
    });
    assert_eq!(
        e,
        Alarm::AliveStuck {
            frame: "RIG_STATUS",
            repeats: 3
        }
    );
    // Stuck at the third identical counter: two status periods after the freeze.
    let now = hils::rig::transport::Transport::now_s(&s.link);
    assert!((0.51..0.53).contains(&now), "{now}");
}

#[test]
fn a_rejected_script_line_ends_the_session_with_a_non_zero_result() {
    let mut s = session(SimFaults::default());
    let lines = script("start --speed-kmh 50 --arm\nstart --speed-kmh 50\nbrake eb\n");
    let e = run_session(&mut s, &lines, false).unwrap_err();
    assert!(e.to_string().contains("rejected: a run is active"), "{e}");
    // The line after the rejection did not run: no brake command reached the controller,
    // the train coasts.
    s.run_for(1.0, |_, _| hils::rig::commands::Flow::Continue)
        .unwrap();
    let st = s.board.status().unwrap();
    assert_eq!(st.state, RigState::Running);
    assert!(
        st.deceleration_mps2.abs() < 0.05,
        "{}",
        st.deceleration_mps2
    );
    assert!(parse_script(&PathBuf::from("x"), "brake sideways\n").is_err());
    // A bad value is refused with its line before the session sends anything.
    let e = parse_script(&PathBuf::from("x"), "status\ninject 9 open\n").unwrap_err();
    assert!(
        format!("{e:#}").contains("x:2") && format!("{e:#}").contains("channel 9"),
        "{e:#}"
    );
    let e = parse_script(&PathBuf::from("x"), "configure io no-such-io.toml\n").unwrap_err();
    assert!(
        format!("{e:#}").contains("x:1") && format!("{e:#}").contains("no-such-io.toml"),
        "{e:#}"
    );
}

const PROGRAMME: &str = r#"
[criteria]              # wsp-test's, judging the rig runs too
max_distance_ratio = 1.35
[tracks.wet]
base = "wet"
[tracks.dry]
base = "dry"
[tracks.low]
base = "low"
[tracks.off_grid]
base = "wet"
[[tracks.off_grid.zone]]
start_m = 10.05
end_m = 20.0
surface = "low"
[[run]]
name = "wet-eb-50"
speed_kmh = 50.0
demand = "emergency"
track = "wet"
[[run]]
name = "low-eb-50"
speed_kmh = 50.0
demand = "emergency"
track = "low"
[[run]]
name = "dry-service-40"
speed_kmh = 40.0
demand = "service:0.8"
track = "dry"
[[run]]
name = "off-grid-eb-50"
speed_kmh = 50.0
demand = "emergency"
track = "off_grid"
"#;

fn programme_args(
    dir: &std::path::Path,
    faults: &[&str],
) -> (hils::rig::RigArgs, hils::rig::programme::RunArgs) {
    let file = dir.join("programme.toml");
    std::fs::write(&file, PROGRAMME).unwrap();
    let run = hils::rig::programme::RunArgs {
        programme: file,
        out: hils::outputs::Outputs {
            json: Some(dir.join("out.json")),
            report: Some(dir.join("report")),
        },
        friction: hils::rig::FrictionArg::Variable,
        max_run_s: 120.0,
        settle_s: 3.0,
        only: None,
        arm: true,
        io: None,
    };
    let rig = hils::rig::RigArgs {
        interface: "sim".into(),
        lost_after_s: 0.5,
        realtime: false,
        sim_faults: faults.iter().map(|s| s.to_string()).collect(),
        command: hils::rig::RigCommand::Run(run.clone()),
    };
    (rig, run)
}

/// `hils rig run --programme` against the in-process board: the runs the board can run are
/// run (a low-adhesion track included, sent as track frames), recorded and judged by
/// `hils wsp-test`'s metrics (its JSON keys), the service brake reaches its demanded
/// deceleration, a run the frames cannot carry is listed with the reason; the report puts
/// each rig run beside its SIL run.
/// Without `--arm` a programme on a CAN interface is refused before anything is opened, sent
/// or written: running it would drive the controller under test. `--interface sim` drives
/// only its simulated controller: it runs without `--arm`, arming each run as with it.
#[test]
fn programme_without_arm_is_refused_on_a_can_interface_and_runs_on_sim() {
    let dir = out_dir("programme-unarmed");
    let (mut rig, mut run) = programme_args(&dir, &[]);
    run.arm = false;
    rig.interface = "can0".into();
    rig.command = hils::rig::RigCommand::Run(run.clone());
    let e = hils::rig::programme::main(&rig, &run).unwrap_err();
    assert!(format!("{e:#}").contains("--arm"), "{e:#}");
    assert!(!dir.join("out.json").exists() && !dir.join("report").exists());

    rig.interface = "sim".into();
    run.only = Some("dry-service-40".into());
    rig.command = hils::rig::RigCommand::Run(run.clone());
    hils::rig::programme::main(&rig, &run).expect("sim runs unarmed by the flag");
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("out.json")).unwrap()).unwrap();
    assert_eq!(json[0]["on_rig"], true, "{json}");
    assert_eq!(json[0]["end"], "finished", "{json}");
}

/// Outputs that would replace an input or a file of the run, and an `--only` that matches
/// no run, are refused before anything is run or written (the `--json` over the programme
/// replaced it; `--json DIR/NAME.csv` replaced the run's log; `--only` matching nothing
/// "passed" 0/0 runs with exit code 0).
#[test]
fn outputs_over_inputs_or_logs_and_an_empty_only_are_refused_before_running() {
    let dir = out_dir("programme-outputs");
    let (_, base) = programme_args(&dir, &[]);
    std::fs::create_dir_all(dir.join("report")).unwrap();
    let refused = |json: PathBuf, only: Option<&str>, want: &str| {
        let mut run = base.clone();
        run.out.json = Some(json);
        run.only = only.map(str::to_string);
        let (mut rig, _) = programme_args(&dir, &[]);
        rig.command = hils::rig::RigCommand::Run(run.clone());
        let e = format!("{:#}", hils::rig::programme::main(&rig, &run).unwrap_err());
        assert!(e.contains(want), "{want}: {e}");
    };
    refused(dir.join("programme.toml"), None, "--programme input");
    refused(
        dir.join("report/wet-eb-50.csv"),
        None,
        "wet-eb-50.csv of --report",
    );
    refused(dir.join("report/report.md"), None, "report.md of --report");
    refused(
        dir.join("out.json"),
        Some("no-such-run"),
        "--only no-such-run",
    );
    assert_eq!(
        std::fs::read_to_string(dir.join("programme.toml")).unwrap(),
        PROGRAMME
    );
    assert_eq!(std::fs::read_dir(dir.join("report")).unwrap().count(), 0);
    assert!(!dir.join("out.json").exists());
}

#[test]
fn programme_runs_each_run_on_the_board_and_reports() {
    let dir = out_dir("programme");
    let (rig, run) = programme_args(&dir, &[]);
    hils::rig::programme::main(&rig, &run).expect("programme");
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("out.json")).unwrap()).unwrap();
    let runs = json.as_array().unwrap();
    assert_eq!(runs.len(), 4);
    assert_eq!(runs[0]["end"], "finished");
    assert_eq!(runs[0]["on_rig"], true);
    for key in [
        "name",
        "passed",
        "stopping_distance_m",
        "allowed_distance_m",
        "distance_ratio",
        "adhesion_utilisation",
        "air_consumption_l",
        "max_lock_s",
        "lock_count",
        "wsp_timer_actions",
    ] {
        assert!(runs[0].get(key).is_some(), "key {key}: {}", runs[0]);
    }
    // The board reads the controller's valve coils (every input wired on the simulated
    // rig): air and WSP timer judged from them, nothing "not measured"; the log has the
    // valves and what the board drove.
    assert!(runs[0].get("not_measured").is_none(), "{}", runs[0]);
    for c in runs[0]["criteria"].as_array().unwrap() {
        assert!(
            !c["criterion"].as_str().unwrap().contains("not measured"),
            "{c}"
        );
    }
    let log = hils::measured::read_run_log(&dir.join("report").join("wet-eb-50.csv")).unwrap();
    for j in 0..4 {
        assert!(log.wsp[j].as_ref().unwrap().iter().all(|x| x.is_finite()));
        assert!(log.hold[j].as_ref().unwrap().iter().all(|x| x.is_finite()));
    }
    // The low-adhesion track runs on the board.
    assert_eq!(runs[1]["on_rig"], true, "{}", runs[1]);
    assert_eq!(runs[1]["end"], "finished");
    // Zone bounds off the TrackZone frame's 0.1 m grid: not run, with the reason.
    assert!(
        runs[3]["end"].as_str().unwrap().contains("0.1 m grid"),
        "{}",
        runs[3]
    );
    assert_eq!(runs[3]["on_rig"], false);
    assert_eq!(runs[3]["passed"], false);
    // Each run stops (from its brake command) as the SIL loop of the same start does (3 %).
    for (k, rail, demand, v) in [
        (0, Rail::Wet, BrakeDemand::Emergency, 50.0),
        (
            2,
            Rail::Dry,
            BrakeDemand::Service {
                deceleration_mps2: 0.8,
            },
            40.0,
        ),
    ] {
        let rig = runs[k]["stop_time_s"].as_f64().unwrap();
        let sil = sil_stop_s(rail, demand, v);
        assert!(
            (rig - sil).abs() < 0.03 * sil,
            "{}: rig {rig} s, SIL {sil} s",
            runs[k]["name"]
        );
    }
    // Stopping distance v0 t / 2 .. v0 t (decelerating throughout); the ratio is over the
    // allowed distance.
    let (t, x, allowed) = (
        runs[0]["stop_time_s"].as_f64().unwrap(),
        runs[0]["stopping_distance_m"].as_f64().unwrap(),
        runs[0]["allowed_distance_m"].as_f64().unwrap(),
    );
    let v0 = 50.0 / KMH_PER_MPS;
    assert!(x > 0.5 * v0 * t && x < v0 * t, "x {x} t {t}");
    // (The JSON's ratio is rounded to 1e-4 and the distances to the mm: issue 25.)
    let ratio = runs[0]["distance_ratio"].as_f64().unwrap();
    assert!(
        // The JSON's ratio is rounded to 1e-4 (issue 25).
        (ratio - x / allowed).abs() <= 0.5e-4 && allowed > 0.5 * v0 * t,
        "{}",
        runs[0]
    );
    for name in ["wet-eb-50", "dry-service-40"] {
        let log =
            hils::measured::read_run_log(&dir.join("report").join(format!("{name}.csv"))).unwrap();
        assert_eq!(log.metadata.get("run"), Some(name));
        assert!(
            log.v_ref_mps[0] > 10.0,
            "{name} starts at its speed: {}",
            log.v_ref_mps[0]
        );
    }
    let report = std::fs::read_to_string(dir.join("report").join("report.md")).unwrap();
    for row in [
        "| wet-eb-50 (rig) |",
        "| wet-eb-50 (SIL) |",
        "| low-eb-50 (rig) |",
        "| low-eb-50 (SIL) |",
        "| off-grid-eb-50 (SIL) |",
    ] {
        assert!(report.contains(row), "{row} in {report}");
    }
    assert!(report.contains("- off-grid-eb-50 (rig): not run on the rig: zone 1"));
    assert!(dir.join("report").join("wet-eb-50-rig-speeds.svg").exists());
    assert!(dir.join("report").join("wet-eb-50-sil-speeds.svg").exists());
}

#[test]
fn a_lost_board_ends_the_programme_and_keeps_what_ran() {
    let dir = out_dir("programme-lost");
    let (rig, run) = programme_args(&dir, &["board-lost=6.0"]);
    let e = hils::rig::programme::main(&rig, &run).unwrap_err();
    assert!(e.to_string().contains("board lost"), "{e}");
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("out.json")).unwrap()).unwrap();
    let runs = json.as_array().unwrap();
    assert!(
        runs[0]["end"]
            .as_str()
            .unwrap()
            .contains("ended early: board lost")
    );
    assert!(
        runs[3]["end"]
            .as_str()
            .unwrap()
            .starts_with("not run: the programme ended")
    );
    let log = hils::measured::read_run_log(&dir.join("report").join("wet-eb-50.csv")).unwrap();
    assert!(*log.t_s.last().unwrap() > 2.5);
}

const LOW_ADHESION: &str = r#"
[criteria]
max_distance_ratio = 1.35
[tracks.low_dry_low]           # sudden changes: low -> dry -> low
base = "low"
[[tracks.low_dry_low.zone]]
start_m = 120.0
end_m = 220.0
surface = "dry"
[tracks.low]
base = "low"
[vehicles.tare]
carbody_mass = 26000.0
[[run]]
name = "change-eb-80"
speed_kmh = 80.0
demand = "emergency"
track = "low_dry_low"
[[run]]
name = "low-eb-60-tare"
speed_kmh = 60.0
demand = "emergency"
track = "low"
vehicle = "tare"
[[run]]
name = "low-service-60"
speed_kmh = 60.0
demand = "service:0.8"
track = "low"
"#;

/// A low-adhesion programme on the board (the sudden change low -> dry -> low, a tare
/// vehicle on a low rail, a service brake): the tracks and the vehicle go over the bus, the
/// real WSP loop (the simulated unit reading the pulse trains, its demand from the EB loop
/// and the PWM, its load from the DACs, its valve coils on the board's inputs) runs them,
/// and each run agrees with its SIL run as issue 21 asks: every criterion judged (nothing
/// "not measured"), air within 3 %, WSP timer actions and locks equal, stopping distance
/// within 1 %; both judged by the same criteria.
#[test]
fn a_low_adhesion_programme_runs_on_the_board_as_in_sil() {
    let dir = out_dir("low-adhesion");
    let (rig, mut run) = programme_args(&dir, &[]);
    std::fs::write(&run.programme, LOW_ADHESION).unwrap();
    run.settle_s = 1.0;
    hils::rig::programme::main(&rig, &run).expect("programme");
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("out.json")).unwrap()).unwrap();
    let runs = json.as_array().unwrap();
    assert_eq!(runs.len(), 3);
    let (criteria, board_runs) =
        hils::rig::programme::load(&run.programme, hils::rig::FrictionArg::Variable).unwrap();
    for (r, b) in runs.iter().zip(&board_runs) {
        assert_eq!(r["on_rig"], true, "{r}");
        assert_eq!(r["end"], "finished", "{r}");
        let sil = hils::wsp::run_one(b.run.clone(), &criteria).unwrap();
        let (x_rig, x_sil) = (
            r["stopping_distance_m"].as_f64().unwrap(),
            sil.verdict.stopping_distance_m.unwrap(),
        );
        assert!(
            (x_rig - x_sil).abs() < 0.01 * x_sil,
            "{}: rig {x_rig} m, SIL {x_sil} m",
            r["name"]
        );
        // Every criterion judged from the valve columns; air, timer and locks as SIL's.
        assert!(r.get("not_measured").is_none(), "{r}");
        assert!(
            r["criteria"]
                .as_array()
                .unwrap()
                .iter()
                .all(|c| c["passed"] == true),
            "{r}"
        );
        let (air_rig, air_sil) = (
            r["air_consumption_l"].as_f64().unwrap(),
            sil.verdict.air_consumption_l.unwrap(),
        );
        assert!(
            air_sil > 5.0,
            "{}: WSP vents in SIL: {air_sil} l",
            r["name"]
        );
        assert!(
            (air_rig - air_sil).abs() <= 0.03 * air_sil,
            "{}: air rig {air_rig} l, SIL {air_sil} l",
            r["name"]
        );
        assert_eq!(
            r["wsp_timer_actions"].as_u64(),
            sil.verdict.wsp_timer_actions.map(u64::from),
            "{r}"
        );
        let locks: Vec<u64> = r["lock_count"]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_u64().unwrap())
            .collect();
        assert_eq!(locks, sil.verdict.lock_count.map(u64::from), "{r}");
        assert_eq!(r["against_sil"]["agrees"], true, "{r}");
        // Same allowed distance (0.1 %: the rig's from the logged speed at the brake
        // command): the same track and vehicle judged the same way.
        let allowed = sil.verdict.allowed_distance_m;
        assert!(
            (r["allowed_distance_m"].as_f64().unwrap() - allowed).abs() < 1e-3 * allowed,
            "{r}"
        );
        // Low adhesion limits the stop: far beyond the dry-rail EB stop (1.39 m/s^2).
        let v0 = b.run.speed_mps;
        assert!(
            x_rig > 1.5 * v0 * v0 / (2.0 * 1.39),
            "{}: {x_rig} m",
            r["name"]
        );
    }
    // The log carries the zone under each wheelset and its available adhesion: wheelset 1
    // on the dry zone (well inside 120-220 m) and on the low rail before it.
    let log = std::fs::read_to_string(dir.join("report").join("change-eb-80.csv")).unwrap();
    let mut rows = csv::ReaderBuilder::new()
        .comment(Some(b'#'))
        .from_reader(log.as_bytes());
    let head = rows.headers().unwrap().clone();
    let col = |n: &str| head.iter().position(|h| h == n).unwrap();
    let (c_t, c_v, c_s, c_mu) = (
        col("t_s"),
        col("v_ref_mps"),
        col("surface1"),
        col("mu_avail1"),
    );
    let (mut x, mut t_prev, mut seen_dry, mut seen_low) = (0.0, None::<f64>, false, false);
    for row in rows.records() {
        let row = row.unwrap();
        let (t, v): (f64, f64) = (row[c_t].parse().unwrap(), row[c_v].parse().unwrap());
        x += v * t_prev.map_or(0.0, |p| t - p);
        t_prev = Some(t);
        let mu: f64 = row[c_mu].parse().unwrap();
        if (140.0..200.0).contains(&x) {
            assert_eq!(&row[c_s], "dry", "at {x} m");
            assert!(mu > 0.15, "dry mu_avail {mu}");
            seen_dry = true;
        } else if x < 100.0 && v > 5.0 {
            assert_eq!(&row[c_s], "low", "at {x} m");
            assert!((0.05..0.09).contains(&mu), "low mu_avail {mu}");
            seen_low = true;
        }
    }
    assert!(seen_dry && seen_low);
    // The dry zone (120-220 m) shortens the stop against the same start on one low rail.
    let change = runs[0]["stopping_distance_m"].as_f64().unwrap();
    let mut low = board_runs[0].run.clone();
    low.track = hils_plant::Track::uniform(hils_plant::Surface::Low);
    let low = hils::wsp::run_one(low, &criteria)
        .unwrap()
        .verdict
        .stopping_distance_m
        .unwrap();
    assert!(change < low - 5.0, "change {change} m, uniform low {low} m");
}

/// `hils rig start --track FILE` sends the zones and the commit, then starts on the track;
/// the board refuses unordered zones, a zone index past 16 and a start on no kept track,
/// each with its rule.
#[test]
fn start_with_a_track_file_and_track_rejections() {
    use hils::decode::rig_core::can::{TrackCommand, ZoneFrame};
    use hils_plant::{Surface, Zone};
    let dir = out_dir("track-file");
    let file = dir.join("track.toml");
    std::fs::write(
        &file,
        "base = \"very_low\"\n[[zone]]\nstart_m = 50.0\nend_m = 80.5\nsurface = \"wet\"\n",
    )
    .unwrap();
    let mut s = session(SimFaults::default());
    assert!(s.command(Command::Arm).unwrap().accepted);
    let mut no_track = start(60.0);
    if let Command::Start(s) = &mut no_track {
        s.track = true;
    }
    let o = s.command(no_track).unwrap();
    assert!(!o.accepted);
    assert!(
        o.reason.as_deref().unwrap().contains("no track kept"),
        "{o}"
    );
    let lines = script(&format!(
        "start --speed-kmh 60 --track {} --arm\n",
        file.display()
    ));
    run_session(&mut s, &lines, false).unwrap();
    assert_eq!(s.link.rig().state(), RigState::Running);
    let kept = s.link.rig().track().unwrap();
    assert_eq!(kept.base, Surface::VeryLow);
    assert_eq!(
        kept.zones().iter().map(|z| z.zone()).collect::<Vec<_>>(),
        vec![Zone {
            start_m: 50.0,
            end_m: 80.5,
            surface: Surface::Wet
        }]
    );
    assert_eq!(s.link.rig().surfaces().unwrap(), [Surface::VeryLow; 4]);
    assert!(s.command(Command::Stop).unwrap().accepted);
    // Unordered zones: the commit is refused with the rule; too many zones: the index.
    let zone = |a: f64, b: f64| {
        ZoneFrame::of(&Zone {
            start_m: a,
            end_m: b,
            surface: Surface::Dry,
        })
        .unwrap()
    };
    for (index, z) in [(0, zone(100.0, 200.0)), (1, zone(150.0, 300.0))] {
        assert!(
            s.command(Command::TrackZone { index, zone: z })
                .unwrap()
                .accepted
        );
    }
    let o = s
        .command(Command::Track(TrackCommand::Commit {
            base: Surface::Low,
            zones: 2,
        }))
        .unwrap();
    assert!(!o.accepted);
    assert!(o.reason.as_deref().unwrap().contains("out of order"), "{o}");
    let o = s
        .command(Command::TrackZone {
            index: 16,
            zone: zone(0.0, 1.0),
        })
        .unwrap();
    assert!(!o.accepted);
    assert!(
        o.reason.as_deref().unwrap().contains("at most 16 zones"),
        "{o}"
    );
    // The refused commit kept the last track.
    assert_eq!(s.link.rig().track().unwrap().base, Surface::VeryLow);
    // A track file the frames cannot carry is refused before anything is sent.
    std::fs::write(
        &file,
        "base = \"low\"\n[[zone]]\nstart_m = 1.23\nend_m = 5.0\nsurface = \"dry\"\n",
    )
    .unwrap();
    // (Now when the script is read, naming its line: before any line is sent.)
    let e = parse_script(
        &PathBuf::from("t.rig"),
        &format!(
            "status\nstart --speed-kmh 60 --track {} --arm\n",
            file.display()
        ),
    )
    .unwrap_err();
    assert!(
        format!("{e:#}").contains("t.rig:2") && format!("{e:#}").contains("0.1 m grid"),
        "{e:#}"
    );
}

/// A `Track` commit or `Vehicle` frame lost on the bus: the board keeps its earlier setup,
/// the start (stamped by the host from all the frames it meant to send) is rejected with
/// the reason, and the board does not run; resent in full, the start runs.
#[test]
fn a_lost_setup_frame_makes_the_start_rejected_not_a_wrong_run() {
    use hils::decode::rig_core::can::{TrackCommand, VehicleKey, ZoneFrame};
    use hils::rig::track::with_setup_digest;
    use hils_plant::{Surface, Zone};
    let zone = ZoneFrame::of(&Zone {
        start_m: 20.0,
        end_m: 40.0,
        surface: Surface::Low,
    })
    .unwrap();
    let setup = [
        Command::Vehicle {
            key: VehicleKey::Default,
            value: 0.0,
        },
        Command::Vehicle {
            key: VehicleKey::CarbodyMass,
            value: 30_000.0,
        },
        Command::Track(TrackCommand::Clear),
        Command::TrackZone { index: 0, zone },
        Command::Track(TrackCommand::Commit {
            base: Surface::Wet,
            zones: 1,
        }),
    ];
    let mut on_track = start(60.0);
    if let Command::Start(s) = &mut on_track {
        s.track = true;
    }
    let on_track = with_setup_digest(&setup, on_track).unwrap();
    // Each frame that changes a fresh board's setup lost in turn: the variant's value, the
    // zone (the commit is then refused: no track kept), the commit. (The Vehicle default
    // and the Track clear change nothing on a fresh board: their loss is harmless here.)
    for lost in [1, 3, 4] {
        let mut s = session(SimFaults::default());
        assert!(s.command(Command::Arm).unwrap().accepted);
        for (i, c) in setup.iter().enumerate() {
            if i != lost {
                s.command(*c).unwrap();
            }
        }
        let o = s.command(on_track).unwrap();
        assert!(!o.accepted, "frame {lost} lost: {o}");
        assert!(
            o.reason
                .as_deref()
                .unwrap()
                .contains("differs from what was sent: a frame was lost; resend"),
            "{o}"
        );
        assert_ne!(s.link.rig().state(), RigState::Running);
        for c in &setup {
            assert!(s.command(*c).unwrap().accepted);
        }
        assert!(s.command(on_track).unwrap().accepted);
        assert_eq!(s.link.rig().state(), RigState::Running);
        assert_eq!(s.link.rig().vehicle().0[0], Some(30_000.0));
    }
}

/// `arm` and `disarm` as session lines: armed, the run drives the controller (it brakes on
/// the wheel speeds it reads); `disarm` during the run takes the speeds away at once
/// ("not available": the controller vents) while the board's run goes on.
#[test]
fn arm_and_disarm_lines_drive_and_release_the_controller() {
    let mut s = session(SimFaults::default());
    let lines = script("arm\nstart --speed-kmh 80\nbrake eb\nwait --for-s 1.0\n");
    run_session(&mut s, &lines, false).expect("session");
    let (_, w) = s.board.wheel_speed.unwrap();
    assert!(w.speeds_kmh.iter().all(Option::is_some), "{w:?}");
    let st = s.board.status().unwrap();
    assert!(st.deceleration_mps2 > 0.5, "the controller brakes: {st:?}");
    run_session(&mut s, &script("disarm\nwait --for-s 0.2\n"), false).expect("disarm");
    let (_, w) = s.board.wheel_speed.unwrap();
    assert_eq!(w.speeds_kmh, [None; 4]);
    assert_eq!(s.link.rig().state(), RigState::Running);
    assert_eq!(s.board.armed(), Some(false));
    // A second start needs a new `arm`: refused with the reason.
    let e = run_session(&mut s, &script("stop\nstart --speed-kmh 60\n"), false).unwrap_err();
    assert!(e.to_string().contains("not armed"), "{e}");
}
