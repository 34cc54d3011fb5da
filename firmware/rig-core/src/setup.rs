//! The track and vehicle a run is set up with, as the board keeps them from `TrackZone`,
//! `Track` and `Vehicle` commands: the data under [`crate::digest`] and [`crate::rig`]
//! (which keeps one, `KeptSetup`), above the frame codec [`crate::can`] whose payload types
//! ([`ZoneFrame`], [`VehicleKey`]) they hold.

use hils_plant::params::VehicleParams;
use hils_plant::track::{MAX_ZONES, TrackError};
use hils_plant::{Surface, Track, Zone};

use crate::can::{VehicleKey, ZoneFrame};

/// A track as the board keeps it: the base and the zones as received (checked, in
/// 0.1 m steps: no floating point in the step); the plant's [`Track`] is made from it
/// when a run is built ([`TrackFrames::track`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TrackFrames {
    /// Surface outside the zones.
    pub base: Surface,
    zones: [ZoneFrame; MAX_ZONES],
    count: u8,
}

impl TrackFrames {
    /// `zones` on `base`, by the rules of [`Track::new`] (at most [`MAX_ZONES`], each not
    /// empty, in order and disjoint), on the frames' integer bounds.
    pub fn new(base: Surface, zones: &[ZoneFrame]) -> Result<Self, TrackError> {
        if zones.len() > MAX_ZONES {
            return Err(TrackError::TooManyZones);
        }
        let mut t = Self {
            base,
            zones: [ZoneFrame::default(); MAX_ZONES],
            count: zones.len() as u8,
        };
        for (index, z) in zones.iter().enumerate() {
            if z.end_dm <= z.start_dm {
                return Err(TrackError::BadZone { index });
            }
            if index > 0 && z.start_dm < zones[index - 1].end_dm {
                return Err(TrackError::Overlap { index });
            }
            t.zones[index] = *z;
        }
        Ok(t)
    }

    /// The zones.
    pub fn zones(&self) -> &[ZoneFrame] {
        &self.zones[..self.count as usize]
    }

    /// The plant's track (outside the step: floating point).
    pub fn track(&self) -> Result<Track, TrackError> {
        let mut zones = [Zone::default(); MAX_ZONES];
        for (z, f) in zones.iter_mut().zip(self.zones()) {
            *z = f.zone();
        }
        Track::new(self.base, &zones[..self.count as usize])
    }
}

/// The `[vehicle]` values set by `Vehicle` commands ([`VehicleKey::VALUES`] order; `None`:
/// the default), as received (f32: no conversion in the step); applied when a run is
/// built.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct VehicleValues(pub [Option<f32>; 5]);

impl VehicleValues {
    /// What a `Vehicle` command does: sets `key`'s value, or all back to the default
    /// (`VehicleKey::Default`).
    pub fn set(&mut self, key: VehicleKey, value: f32) {
        match VehicleKey::VALUES.iter().position(|k| *k == key) {
            Some(i) => self.0[i] = Some(value),
            None => *self = Self::default(),
        }
    }

    /// The default vehicle with these values.
    pub fn vehicle(&self) -> VehicleParams {
        let mut v = VehicleParams::default();
        for (key, value) in VehicleKey::VALUES.iter().zip(self.0) {
            if let Some(x) = value {
                key.apply(&mut v, x);
            }
        }
        v
    }
}
