//! The setup digest of `Start` (`StartDigest`): a `Track` commit or `Vehicle` frame lost
//! on the bus leaves the board's kept setup as it was; the start, stamped with the digest
//! of what the sender set up, is then rejected (`SetupMismatch`) and nothing changes,
//! instead of a run on the earlier setup with the previous command's `Accepted` showing.

use hils_plant::{FrictionModel, Rail, Surface};
use hils_rig_core::can::{
    ClassicFrame, Command, CommandFrame, RigMode, RigState, TrackCommand, VehicleKey, ZoneFrame,
    surface_code,
};
use hils_rig_core::digest::{crc16, setup_digest};
use hils_rig_core::hw::{RigIo, TelemetryEvent};
use hils_rig_core::pulse::PulseRegisters;
use hils_rig_core::sensor::ADC_SEQUENCE_LEN;
use hils_rig_core::rig::{CommandError, Rig, RigConfig, TrackFrames, VehicleValues};
use proptest::prelude::*;

/// CRC-16/CCITT-FALSE byte by byte through a 256-entry table (a second implementation).
fn crc16_table(bytes: &[u8]) -> u16 {
    let table: Vec<u16> = (0..256u16)
        .map(|i| {
            (0..8).fold(i << 8, |c, _| {
                if c & 0x8000 != 0 {
                    (c << 1) ^ 0x1021
                } else {
                    c << 1
                }
            })
        })
        .collect();
    bytes.iter().fold(0xFFFF, |c, &b| {
        (c << 8) ^ table[((c >> 8) as u8 ^ b) as usize]
    })
}

/// The documented canonical bytes (`digest` module doc), written out independently.
fn canonical(track: Option<&TrackFrames>, vehicle: &VehicleValues) -> Vec<u8> {
    let mut b = Vec::new();
    match track {
        None => b.push(0xFF),
        Some(t) => {
            b.push(surface_code(t.base));
            b.push(t.zones().len() as u8);
            for z in t.zones() {
                b.extend(z.start_dm.to_le_bytes());
                b.extend(z.end_dm.to_le_bytes());
                b.push(surface_code(z.surface));
            }
        }
    }
    for v in vehicle.0 {
        match v {
            None => b.push(0),
            Some(x) => {
                b.push(1);
                b.extend(x.to_bits().to_le_bytes());
            }
        }
    }
    b
}

#[test]
fn crc16_is_ccitt_false() {
    // The catalogued check value of CRC-16/CCITT-FALSE (CRC-16/IBM-3740).
    assert_eq!(crc16(b"123456789"), 0x29B1);
    assert_eq!(crc16_table(b"123456789"), 0x29B1);
}

const SURFACES: [Surface; 4] = [Surface::Dry, Surface::Wet, Surface::Low, Surface::VeryLow];

fn zone(start_dm: u32, end_dm: u32, s: u8) -> ZoneFrame {
    ZoneFrame {
        start_dm,
        end_dm,
        surface: SURFACES[s as usize % 4],
    }
}

proptest! {
    /// The digest is the CRC of the documented bytes, and changes with every zone field,
    /// the base, the zone count and every vehicle value (set, changed or back to default).
    #[test]
    fn the_digest_covers_every_field(
        base in 0u8..4,
        raw in prop::collection::vec((1u32..1000, 1u32..1000, 0u8..4), 0..=16),
        values in prop::array::uniform5(prop::option::of(1.0f32..1.0e6)),
        pick in 0usize..64,
    ) {
        // Ordered, disjoint zones from gaps and lengths.
        let mut at = 0;
        let zones: Vec<ZoneFrame> = raw.iter().map(|&(gap, len, s)| {
            let z = zone(at + gap, at + gap + len, s);
            at = z.end_dm;
            z
        }).collect();
        let track = TrackFrames::new(SURFACES[base as usize], &zones).unwrap();
        let vehicle = VehicleValues(values);
        let d = setup_digest(Some(&track), &vehicle);
        prop_assert_eq!(d, crc16_table(&canonical(Some(&track), &vehicle)));
        prop_assert_ne!(d, setup_digest(None, &vehicle));
        let base2 = TrackFrames::new(SURFACES[(base as usize + 1) % 4], &zones).unwrap();
        prop_assert_ne!(d, setup_digest(Some(&base2), &vehicle));
        if !zones.is_empty() {
            let fewer = TrackFrames::new(track.base, &zones[..zones.len() - 1]).unwrap();
            prop_assert_ne!(d, setup_digest(Some(&fewer), &vehicle));
            // One field of one zone, each kind of field.
            let i = pick % zones.len();
            let mut changed = zones.clone();
            match pick % 3 {
                0 => changed[i].start_dm -= 1, // gap >= 1: still ordered
                1 => changed[i].end_dm += 1_000_000,
                _ => changed[i].surface = SURFACES[(surface_code(zones[i].surface) as usize + 1) % 4],
            }
            let mut changed = changed;
            if pick % 3 == 1 {
                // Keep the later zones after it.
                for z in &mut changed[i + 1..] {
                    z.start_dm += 1_000_000;
                    z.end_dm += 1_000_000;
                }
            }
            let t2 = TrackFrames::new(track.base, &changed).unwrap();
            prop_assert_ne!(d, setup_digest(Some(&t2), &vehicle));
        }
        let k = pick % 5;
        let mut v2 = vehicle;
        v2.0[k] = match vehicle.0[k] {
            None => Some(1.0),
            Some(x) => Some(f32::from_bits(x.to_bits() ^ 1)),
        };
        prop_assert_ne!(d, setup_digest(Some(&track), &v2));
        let mut v3 = vehicle;
        v3.0[k] = None;
        if vehicle.0[k].is_some() {
            prop_assert_ne!(d, setup_digest(Some(&track), &v3));
        }
    }
}

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

/// Stops the run and steps once (its end record goes out: the next start can be built).
fn stop(rig: &mut Rig, n: &mut u8) {
    send(rig, n, Command::Stop).unwrap();
    rig.step(&mut Io);
}

/// Sends `c` as a frame (counter from `n`) and builds a requested run as the board would.
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

fn start(track: Option<&TrackFrames>, vehicle: &VehicleValues) -> Command {
    Command::Start {
        mode: RigMode::SelfTest,
        rail: Rail::Wet,
        friction: FrictionModel::Variable,
        emergency: true,
        initial_speed_kmh: 80.0,
        track: track.is_some(),
        setup_digest: setup_digest(track, vehicle),
    }
}

fn commit(base: Surface, zones: u8) -> Command {
    Command::Track(TrackCommand::Commit { base, zones })
}

/// A rejected start changes nothing: no run requested, the kept setup as it was.
fn assert_rejected_unchanged(rig: &mut Rig, n: &mut u8, c: Command) {
    let (track, vehicle, state) = (rig.track().copied(), *rig.vehicle(), rig.state());
    let r = send(rig, n, c);
    assert_eq!(
        r,
        Err(CommandError::SetupMismatch {
            kept: setup_digest(
                track
                    .as_ref()
                    .filter(|_| matches!(c, Command::Start { track: true, .. })),
                &vehicle
            )
        })
    );
    assert_eq!(rig.state(), state);
    assert_eq!(rig.take_start_request(), None);
    assert_eq!((rig.track().copied(), *rig.vehicle()), (track, vehicle));
}

#[test]
fn a_lost_commit_or_vehicle_frame_rejects_the_start() {
    let mut rig = Rig::new(RigConfig::nucleo_g474re());
    let mut n = 0;
    // Track A kept, vehicle variant 26 t.
    let a = [zone(100, 200, 2)];
    send(
        &mut rig,
        &mut n,
        Command::TrackZone {
            index: 0,
            zone: a[0],
        },
    )
    .unwrap();
    send(&mut rig, &mut n, commit(Surface::Wet, 1)).unwrap();
    send(
        &mut rig,
        &mut n,
        Command::Vehicle {
            key: VehicleKey::CarbodyMass,
            value: 26_000.0,
        },
    )
    .unwrap();
    // The host loads track B; its clear and its commit are lost: the board still has A.
    let b = [zone(300, 500, 3), zone(600, 700, 0)];
    for (i, z) in b.iter().enumerate() {
        send(
            &mut rig,
            &mut n,
            Command::TrackZone {
                index: i as u8,
                zone: *z,
            },
        )
        .unwrap();
    }
    let track_b = TrackFrames::new(Surface::Dry, &b).unwrap();
    let mut sent = VehicleValues::default();
    sent.set(VehicleKey::CarbodyMass, 26_000.0);
    assert_rejected_unchanged(&mut rig, &mut n, start(Some(&track_b), &sent));
    // Only the commit lost (the clear arrived): no track kept, rejected too.
    let mut m = Rig::new(RigConfig::nucleo_g474re());
    send(&mut m, &mut n, Command::Track(TrackCommand::Clear)).unwrap();
    for (i, z) in b.iter().enumerate() {
        let c = Command::TrackZone {
            index: i as u8,
            zone: *z,
        };
        send(&mut m, &mut n, c).unwrap();
    }
    assert_eq!(
        send(&mut m, &mut n, start(Some(&track_b), &sent)),
        Err(CommandError::NoTrack)
    );
    assert_eq!(m.state(), RigState::Idle);
    // Resent: accepted, the run is on B.
    send(&mut rig, &mut n, commit(Surface::Dry, 2)).unwrap();
    assert_eq!(rig.track(), Some(&track_b));
    send(&mut rig, &mut n, start(Some(&track_b), &sent)).unwrap();
    assert_eq!(rig.state(), RigState::Running);
    stop(&mut rig, &mut n);
    // A Vehicle default lost: the board keeps 26 t, the host started on the default vehicle.
    assert_rejected_unchanged(&mut rig, &mut n, start(None, &VehicleValues::default()));
    // A variant's value lost: the board has the default, the host sent 30 t.
    send(
        &mut rig,
        &mut n,
        Command::Vehicle {
            key: VehicleKey::Default,
            value: 0.0,
        },
    )
    .unwrap();
    let mut v30 = VehicleValues::default();
    v30.set(VehicleKey::CarbodyMass, 30_000.0);
    assert_rejected_unchanged(&mut rig, &mut n, start(None, &v30));
    assert_rejected_unchanged(&mut rig, &mut n, start(Some(&track_b), &v30));
    // The one-rail start does not depend on the kept track; the button's start (stamped
    // with the kept setup) runs whatever the board keeps.
    send(&mut rig, &mut n, start(None, &VehicleValues::default())).unwrap();
    assert_eq!(rig.state(), RigState::Running);
    stop(&mut rig, &mut n);
    send(
        &mut rig,
        &mut n,
        Command::Vehicle {
            key: VehicleKey::WheelRadius,
            value: 0.43,
        },
    )
    .unwrap();
    let button = rig.on_kept_setup(Command::paper_self_test(FrictionModel::Variable));
    rig.command(button).unwrap();
    assert_eq!(rig.state(), RigState::Starting);
}
