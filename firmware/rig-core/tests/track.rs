//! Tracks and vehicle variants by command (issue 13 item 5): zones sent in `TrackZone`
//! frames, checked and kept by `Track` commit, selected by `Start`; the run's plant sees
//! the zone under each wheelset; the rejections name their rule.

use hils_plant::track::TrackError;
use hils_plant::{FrictionModel, Params, Rail, Surface, Zone};
use hils_rig_core::can::{
    ClassicFrame, Command, CommandFrame, DecodeError, RigMode, RigState, StartCommand,
    TrackCommand, VehicleKey, ZoneFrame, surface_code,
};
use hils_rig_core::hw::{RigIo, TelemetryEvent};
use hils_rig_core::pulse::PulseRegisters;
use hils_rig_core::rig::{CommandError, Rig, RigConfig};
use hils_rig_core::sensor::ADC_SEQUENCE_LEN;

struct Io;

impl RigIo for Io {
    type Frame = ClassicFrame;
    fn adc_sequence(&mut self) -> Option<[u16; ADC_SEQUENCE_LEN]> {
        None
    }
    fn set_pulse(&mut self, _: usize, _: &PulseRegisters) {}
    fn queue_frame(&mut self, _: ClassicFrame) -> bool {
        true
    }
    fn queue_telemetry(&mut self, _: &TelemetryEvent) -> bool {
        true
    }
}

/// Sends a command as a frame (counter from `n`), builds a requested run as the builder would.
fn send(rig: &mut Rig, n: &mut u8, c: Command) -> Result<(), CommandError> {
    *n = n.wrapping_add(1);
    let f: ClassicFrame = CommandFrame {
        command: c,
        counter: *n & 0x0F,
    }
    .encode()
    .unwrap();
    rig.command_frame(&f)?;
    rig.build_pending()
}

fn zone(start_m: f64, end_m: f64, surface: Surface) -> Zone {
    Zone {
        start_m,
        end_m,
        surface,
    }
}

/// Loads `zones` on `base` by frames and commits them.
fn load(rig: &mut Rig, n: &mut u8, base: Surface, zones: &[Zone]) -> Result<(), CommandError> {
    for (i, z) in zones.iter().enumerate() {
        let zone = ZoneFrame::of(z).expect("on the 0.1 m grid");
        send(
            rig,
            n,
            Command::TrackZone {
                index: i as u8,
                zone,
            },
        )?;
    }
    commit(rig, n, base, zones.len() as u8)
}

/// Sends a track commit of `zones` zones on `base`.
fn commit(rig: &mut Rig, n: &mut u8, base: Surface, zones: u8) -> Result<(), CommandError> {
    send(rig, n, Command::Track(TrackCommand::Commit { base, zones }))
}

/// Zone 0 of a track: 0-10 m on `surface`.
fn first_zone(surface: Surface) -> Command {
    Command::TrackZone {
        index: 0,
        zone: ZoneFrame::of(&zone(0.0, 10.0, surface)).unwrap(),
    }
}

/// Sends zone 0 ([`first_zone`]) alone and then a commit of two zones: it is refused,
/// naming zone 1 as missing.
fn commit_without_zone_1(rig: &mut Rig, n: &mut u8, surface: Surface) {
    send(rig, n, first_zone(surface)).unwrap();
    assert_eq!(
        commit(rig, n, Surface::Wet, 2),
        Err(CommandError::TrackIncomplete { index: 1 })
    );
}

fn self_test_eb(speed_kmh: f32, track: bool) -> Command {
    Command::Start(StartCommand {
        mode: RigMode::SelfTest,
        rail: Rail::Dry,
        friction: FrictionModel::Variable,
        emergency: true,
        initial_speed_kmh: speed_kmh,
        track,
        setup_digest: 0,
    })
}

/// Sends a self-test EB start stamped with the digest of the rig's kept setup (the tests
/// of tracks and vehicles; the digest's own tests send the digest of what they sent).
fn start(rig: &mut Rig, n: &mut u8, speed_kmh: f32, track: bool) -> Result<(), CommandError> {
    let c = rig.on_kept_setup(self_test_eb(speed_kmh, track));
    send(rig, n, c)
}

/// Runs to standstill; the stopping distance (m, integrated from the vehicle speed) and
/// the surfaces seen under wheelset 1 and 4 at each position passed.
fn run(rig: &mut Rig) -> (f64, Vec<(f64, Surface, Surface)>) {
    let mut x = 0.0;
    let mut seen = Vec::new();
    for _ in 0..2_000_000 {
        rig.step(&mut Io);
        if rig.state() != RigState::Running {
            break;
        }
        let v = rig.outputs().unwrap().vehicle_speed as f64;
        x += v * 1e-4;
        let s = rig.surfaces().unwrap();
        seen.push((x, s[0], s[3]));
        if seen.len() % 997 == 0 {
            // The telemetry record logs the surface under each wheelset.
            let r = rig.record().unwrap();
            assert_eq!(core::array::from_fn(|j| r.surface(j)), s);
        }
    }
    assert_eq!(rig.state(), RigState::Finished);
    (x, seen)
}

#[test]
fn a_track_loaded_by_frames_puts_each_wheelset_on_its_zone() {
    let mut rig = Rig::new(RigConfig::nucleo_g474re());
    let mut n = 0;
    let zones = [zone(120.0, 220.0, Surface::Dry)];
    load(&mut rig, &mut n, Surface::Low, &zones).unwrap();
    let kept: Vec<Zone> = rig
        .track()
        .unwrap()
        .zones()
        .iter()
        .map(|z| z.zone())
        .collect();
    assert_eq!(kept, zones);
    start(&mut rig, &mut n, 120.0, true).unwrap();
    let (stop_change, seen) = run(&mut rig);
    // Wheelset 1 is on the dry zone from 120 m to 220 m (within one refresh, 4 steps), low
    // elsewhere; wheelset 4 (16.5 m behind: bogie base 14 m + wheel base 2.5 m) reaches
    // it 16.5 m later.
    let lag = 4.0 * 34.0 * 1e-4;
    for &(x, s1, s4) in &seen {
        if (x - 120.0).abs() > lag && (x - 220.0).abs() > lag {
            let dry = (120.0..220.0).contains(&x);
            assert_eq!(s1 == Surface::Dry, dry, "wheelset 1 at {x} m: {s1:?}");
        }
        let x4 = x - 16.5;
        if (x4 - 120.0).abs() > lag && (x4 - 220.0).abs() > lag {
            let dry = (120.0..220.0).contains(&x4);
            assert_eq!(s4 == Surface::Dry, dry, "wheelset 4 at {x4} m: {s4:?}");
        }
    }
    assert!(stop_change > 240.0, "the stop runs past the dry zone");
    // The same start on one low rail (the committed track, no zones), and on the dry rail
    // of the start frame (no track): the sudden change stops between the two.
    load(&mut rig, &mut n, Surface::Low, &[]).unwrap();
    start(&mut rig, &mut n, 120.0, true).unwrap();
    let (stop_low, _) = run(&mut rig);
    start(&mut rig, &mut n, 120.0, false).unwrap();
    let (stop_dry, seen_dry) = run(&mut rig);
    assert!(
        seen_dry
            .iter()
            .all(|s| s.1 == Surface::Dry && s.2 == Surface::Dry)
    );
    assert!(
        stop_dry < stop_change && stop_change < stop_low,
        "dry {stop_dry} change {stop_change} low {stop_low}"
    );
    // Low adhesion: the EB (about 1.39 m/s^2 on dry rail) is limited by ~0.07 g.
    let v0 = 120.0 / 3.6;
    assert!(stop_low > v0 * v0 / (2.0 * 0.08 * 9.81), "low {stop_low}");
}

#[test]
fn track_frames_are_refused_with_their_rule() {
    let mut rig = Rig::new(RigConfig::nucleo_g474re());
    let mut n = 0;
    // Start on the kept track before one is kept.
    assert_eq!(
        start(&mut rig, &mut n, 80.0, true),
        Err(CommandError::NoTrack)
    );
    // Zones out of order (the second starts before the first ends).
    let unordered = [
        zone(100.0, 200.0, Surface::Dry),
        zone(150.0, 300.0, Surface::Wet),
    ];
    assert_eq!(
        load(&mut rig, &mut n, Surface::Low, &unordered),
        Err(CommandError::Track(TrackError::Overlap { index: 1 }))
    );
    // Empty zone.
    assert_eq!(
        load(
            &mut rig,
            &mut n,
            Surface::Low,
            &[zone(50.0, 50.0, Surface::Dry)]
        ),
        Err(CommandError::Track(TrackError::BadZone { index: 0 }))
    );
    assert!(rig.track().is_none(), "a refused commit keeps no track");
    // Seventeen zones: the index 16 is refused, as is a commit of 17.
    let many: Vec<Zone> = (0..17)
        .map(|i| zone(10.0 * i as f64, 10.0 * i as f64 + 5.0, Surface::Dry))
        .collect();
    assert_eq!(
        load(&mut rig, &mut n, Surface::Wet, &many),
        Err(CommandError::Track(TrackError::TooManyZones))
    );
    assert_eq!(
        commit(&mut rig, &mut n, Surface::Wet, 17),
        Err(CommandError::Track(TrackError::TooManyZones))
    );
    // Sixteen are kept.
    load(&mut rig, &mut n, Surface::Wet, &many[..16]).unwrap();
    assert_eq!(rig.track().unwrap().zones().len(), 16);
    // A commit of zones not all received since the last commit: which one is missing.
    commit_without_zone_1(&mut rig, &mut n, Surface::Low);
    assert_eq!(
        rig.track().unwrap().zones().len(),
        16,
        "the last track stays"
    );
    // An unknown surface code (4-7) in a zone frame: the frame is refused, naming the field.
    let mut f: ClassicFrame = CommandFrame {
        command: first_zone(Surface::Low),
        counter: 9,
    }
    .encode()
    .unwrap();
    assert_eq!(surface_code(Surface::Low), 2);
    f.data[1] |= 0b111 << 5; // ZoneSurface = 7
    let crc = hils_rig_core::can::checksum(hils_rig_core::can::ID_COMMAND, &f.data);
    f.data[7] = (f.data[7] & 0x0F) | (crc << 4);
    assert_eq!(
        rig.command_frame(&f),
        Err(CommandError::Frame(DecodeError::BadValue("ZoneSurface")))
    );
    // Bounds off the 0.1 m grid or beyond the frame's range have no frame.
    assert!(ZoneFrame::of(&zone(0.05, 10.0, Surface::Low)).is_none());
    assert!(ZoneFrame::of(&zone(0.0, 2.0e5, Surface::Low)).is_none());
    assert!(ZoneFrame::of(&zone(-1.0, 10.0, Surface::Low)).is_none());
    // Clear forgets the track.
    send(&mut rig, &mut n, Command::Track(TrackCommand::Clear)).unwrap();
    assert!(rig.track().is_none());
    // A refused commit forgets its zones: a later commit whose zone 1 was lost on the bus is
    // refused, not completed with the refused attempt's zone 1.
    assert!(load(&mut rig, &mut n, Surface::Low, &unordered).is_err());
    commit_without_zone_1(&mut rig, &mut n, Surface::Dry);
    assert!(rig.track().is_none());
}

/// A `Track` commit or `Vehicle` frame lost on the bus leaves the board's kept setup as it
/// was; the start, stamped with the digest of what the sender set up (`StartDigest`), is
/// rejected (`SetupMismatch`) and nothing changes, instead of a run on the earlier setup
/// with the previous command's `Accepted` showing.
#[test]
fn a_lost_commit_or_vehicle_frame_rejects_the_start() {
    use hils_rig_core::digest::setup_digest;
    use hils_rig_core::setup::{TrackFrames, VehicleValues};
    let stamped = |track: Option<&TrackFrames>, vehicle: &VehicleValues| {
        let mut c = self_test_eb(80.0, track.is_some());
        if let Command::Start(start) = &mut c {
            start.setup_digest = setup_digest(track, vehicle);
        }
        c
    };
    // A rejected start changes nothing: no run requested, the kept setup as it was.
    let rejected = |rig: &mut Rig, n: &mut u8, c: Command| {
        let before = (rig.track().copied(), *rig.vehicle(), rig.state());
        let on_track = matches!(c, Command::Start(StartCommand { track: true, .. }));
        let kept = setup_digest(before.0.as_ref().filter(|_| on_track), &before.1);
        assert_eq!(send(rig, n, c), Err(CommandError::SetupMismatch { kept }));
        assert_eq!(rig.take_start_request(), None);
        assert_eq!((rig.track().copied(), *rig.vehicle(), rig.state()), before);
    };
    let stop = |rig: &mut Rig, n: &mut u8| {
        send(rig, n, Command::Stop).unwrap();
        rig.step(&mut Io); // the run's end record
    };
    let vehicle = |key, value| Command::Vehicle { key, value };
    let mut rig = Rig::new(RigConfig::nucleo_g474re());
    let mut n = 0;
    // Track A kept, vehicle variant 26 t.
    load(
        &mut rig,
        &mut n,
        Surface::Wet,
        &[zone(10.0, 20.0, Surface::Low)],
    )
    .unwrap();
    send(&mut rig, &mut n, vehicle(VehicleKey::CarbodyMass, 26_000.0)).unwrap();
    // The host loads track B; its clear and its commit are lost: the board still has A.
    let b = [
        zone(30.0, 50.0, Surface::VeryLow),
        zone(60.0, 70.0, Surface::Dry),
    ];
    let b_frames = b.map(|z| ZoneFrame::of(&z).unwrap());
    for (i, zone) in b_frames.iter().enumerate() {
        let c = Command::TrackZone {
            index: i as u8,
            zone: *zone,
        };
        send(&mut rig, &mut n, c).unwrap();
    }
    let track_b = TrackFrames::new(Surface::Dry, &b_frames).unwrap();
    let mut sent = VehicleValues::default();
    sent.set(VehicleKey::CarbodyMass, 26_000.0);
    rejected(&mut rig, &mut n, stamped(Some(&track_b), &sent));
    // Only the commit lost (the clear arrived): no track kept, rejected too.
    let mut fresh = Rig::new(RigConfig::nucleo_g474re());
    send(&mut fresh, &mut n, Command::Track(TrackCommand::Clear)).unwrap();
    assert_eq!(
        send(&mut fresh, &mut n, stamped(Some(&track_b), &sent)),
        Err(CommandError::NoTrack)
    );
    // Resent: accepted, the run is on B.
    commit(&mut rig, &mut n, Surface::Dry, 2).unwrap();
    assert_eq!(rig.track(), Some(&track_b));
    send(&mut rig, &mut n, stamped(Some(&track_b), &sent)).unwrap();
    assert_eq!(rig.state(), RigState::Running);
    stop(&mut rig, &mut n);
    // A Vehicle default lost: the board keeps 26 t, the host started on the default vehicle.
    rejected(&mut rig, &mut n, stamped(None, &VehicleValues::default()));
    // A variant's value lost: the board has the default, the host sent 30 t.
    send(&mut rig, &mut n, vehicle(VehicleKey::Default, 0.0)).unwrap();
    let mut v30 = VehicleValues::default();
    v30.set(VehicleKey::CarbodyMass, 30_000.0);
    rejected(&mut rig, &mut n, stamped(None, &v30));
    rejected(&mut rig, &mut n, stamped(Some(&track_b), &v30));
    // A one-rail start does not depend on the kept track; the button's start (stamped
    // with the kept setup) runs on whatever the board keeps.
    send(&mut rig, &mut n, stamped(None, &VehicleValues::default())).unwrap();
    assert_eq!(rig.state(), RigState::Running);
    stop(&mut rig, &mut n);
    send(&mut rig, &mut n, vehicle(VehicleKey::WheelRadius, 0.43)).unwrap();
    let button = rig.on_kept_setup(Command::paper_self_test(FrictionModel::Variable));
    rig.command(button).unwrap();
    assert_eq!(rig.state(), RigState::Starting);
}

#[test]
fn a_vehicle_variant_by_command_sets_the_run_s_axle_loads() {
    let mut rig = Rig::new(RigConfig::nucleo_g474re());
    let mut n = 0;
    let p = Params::default();
    let static_load = |carbody: f64| {
        (carbody + 2.0 * p.vehicle.bogie_mass + 4.0 * p.vehicle.wheelset_mass) * p.vehicle.g
    };
    let key = VehicleKey::CarbodyMass;
    for (mass, expected) in [
        (Some(26_000.0), static_load(26_000.0)),
        (None, static_load(p.vehicle.carbody_mass)),
    ] {
        let c = match mass {
            Some(m) => Command::Vehicle { key, value: m },
            None => Command::Vehicle {
                key: VehicleKey::Default,
                value: 0.0,
            },
        };
        send(&mut rig, &mut n, c).unwrap();
        start(&mut rig, &mut n, 60.0, false).unwrap();
        rig.step(&mut Io);
        let q: f64 = rig
            .outputs()
            .unwrap()
            .wheelsets
            .iter()
            .map(|w| w.axle_load as f64)
            .sum();
        assert!(
            (q - expected).abs() < 1e-3 * expected,
            "{mass:?}: {q} N vs {expected} N"
        );
        send(&mut rig, &mut n, Command::Stop).unwrap();
        rig.step(&mut Io); // the run's end record
    }
    // Not while a run is active; a value outside the plant's range fails the start.
    start(&mut rig, &mut n, 60.0, false).unwrap();
    assert_eq!(
        send(&mut rig, &mut n, Command::Vehicle { key, value: 1.0 }),
        Err(CommandError::NotNow(RigState::Running))
    );
    send(&mut rig, &mut n, Command::Stop).unwrap();
    rig.step(&mut Io);
    send(&mut rig, &mut n, Command::Vehicle { key, value: 1.0 }).unwrap();
    assert!(matches!(
        start(&mut rig, &mut n, 60.0, false),
        Err(CommandError::Build(_))
    ));
    assert_ne!(rig.state(), RigState::Running);
}
