//! The setup digest of `Start` (`StartDigest`): the CRC and the bytes it covers (the
//! board's rejection of a start after a lost frame: `tests/track.rs`).

use hils_plant::Surface;
use hils_rig_core::can::{ZoneFrame, surface_code};
use hils_rig_core::digest::{crc16, setup_digest};
use hils_rig_core::setup::{TrackFrames, VehicleValues};
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
