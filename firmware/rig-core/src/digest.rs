//! The setup digest of a `Start` (`StartDigest`): a CRC-16 over the track and vehicle a run
//! is to use, computed by the host from the frames it sent and by the board from what it
//! kept. A `Track` commit or `Vehicle` frame lost on the bus (adapter drop, board reset, RX
//! overflow) leaves the board with its previous setup; the status frame's `CommandResult`
//! then still shows the previous command's `Accepted`, but the digests differ and the board
//! rejects the `Start` ([`crate::rig::CommandError::SetupMismatch`]) instead of running a
//! setup the host did not send.
//!
//! Canonical bytes, in order: the track, `0xFF` when the run has none, else its base
//! surface code, zone count, and per zone its start and end (0.1 m, `u32` little endian)
//! and surface code; then per [`crate::can::VehicleKey::VALUES`] key `0` (default) or `1`
//! and the value's IEEE f32 bits (little endian).

use crate::can::surface_code;
use crate::setup::{TrackFrames, VehicleValues};

/// CRC-16/CCITT-FALSE (polynomial 0x1021, not reflected, init 0xFFFF, no final xor;
/// check value 0x29B1 for "123456789"), bitwise: a few bytes of flash, run only by a
/// `Start` on an idle board. One copy (not inlined per field: board flash).
#[inline(never)]
fn crc16_update(mut crc: u16, bytes: &[u8]) -> u16 {
    for &b in bytes {
        crc ^= (b as u16) << 8;
        for _ in 0..8 {
            crc = (crc << 1) ^ (0x1021 & (crc >> 15).wrapping_neg());
        }
    }
    crc
}

/// CRC-16/CCITT-FALSE of `bytes`.
pub fn crc16(bytes: &[u8]) -> u16 {
    crc16_update(0xFFFF, bytes)
}

/// The digest of a run's setup: its track (`None`: one rail everywhere, no track used)
/// and vehicle values (module doc).
pub fn setup_digest(track: Option<&TrackFrames>, vehicle: &VehicleValues) -> u16 {
    let mut crc = 0xFFFF;
    match track {
        None => crc = crc16_update(crc, &[0xFF]),
        Some(t) => {
            let zones = t.zones();
            crc = crc16_update(crc, &[surface_code(t.base), zones.len() as u8]);
            for z in zones {
                crc = crc16_update(crc, &z.start_dm.to_le_bytes());
                crc = crc16_update(crc, &z.end_dm.to_le_bytes());
                crc = crc16_update(crc, &[surface_code(z.surface)]);
            }
        }
    }
    for value in vehicle.0 {
        crc = match value {
            None => crc16_update(crc, &[0]),
            Some(x) => {
                let b = x.to_bits().to_le_bytes();
                crc16_update(crc, &[1, b[0], b[1], b[2], b[3]])
            }
        };
    }
    crc
}
