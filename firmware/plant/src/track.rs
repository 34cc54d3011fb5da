//! Adhesion along the track, and degraded adhesion that recovers (issue 13).
//!
//! # Zones
//!
//! A [`Track`] is a base [`Surface`] and up to [`MAX_ZONES`] zones `[start_m, end_m)`, each
//! with its surface. Positions are metres along the track from the leading wheelset's
//! position at the start (the train runs toward +x); wheelset j sits at
//! `distance + offset_j`, offset_j <= 0 for the trailing ones, so each wheelset sees the
//! zone under itself (a sudden change reaches wheelset 4 16.5 m after wheelset 1).
//!
//! # Contact sets ([`ContactSets`])
//!
//! Dry and wet are the parameter file's `[contact.dry]` and `[contact]`. The low and very
//! low sets keep the shape of Polach's wet set (k_A = 0.3, k_S = 0.1, A = 0.4, B = 0.2:
//! Polach, "Creep forces in simulations of traction vehicles running on adhesion limit",
//! Wear 258 (2005) 992-1000, and the paper's Table 2) with mu_0 lowered so that the
//! *available* adhesion (the peak of F/Q over creepage) lies in the bands of the WSP test
//! conditions of EN 15595 / UIC 541-05 named in issue 13: low 0.05-0.08
//! ([`LOW_ADHESION`], mu_0 = 0.08), very low about 0.03 ([`VERY_LOW_ADHESION`], mu_0 =
//! 0.035). Allotta et al. (Tribology International 69, 2014) report degraded adhesion of
//! this order on the Velim WSP tests. A test computes the peaks from the model.
//!
//! # Degraded adhesion that recovers ([`DegradedAdhesion`])
//!
//! After Allotta, Meli, Ridolfi, Rindi, "Development of an innovative wheel-rail contact
//! model for the analysis of degraded adhesion in railway systems", Tribology International
//! 69 (2014) 128-140: on a contaminated rail the friction coefficient rises from its
//! degraded value toward a recovered one as the energy dissipated in the contact removes
//! the contaminant,
//!
//!   mu = mu_deg(w) [1 + (R - 1) lambda],   lambda = 1 - exp(-W / W_0),
//!
//! with mu_deg(w) the zone's Eq (11), R = `recovered_mu_ratio`, W_0 = `energy_scale_j_per_m`,
//! and W the specific energy (J per metre of rail) dissipated on the rail under the wheel:
//! * its own contact's, P_j / v_j (P_j = F (v - r omega), the contact power), low-passed
//!   with `time_constant_s` (the contact heats and cleans while it slides);
//! * plus the energy the wheelsets ahead left on that rail (rail conditioning): each
//!   wheelset deposits P_j dt / cell length in the rail cell under it; a ring of
//!   [`CELLS`] cells of `cell_length_m` spans the vehicle, so a trailing wheelset reads what
//!   the leading ones dissipated where it now runs.
//! Only contaminated surfaces (low, very low) recover: on a clean rail lambda does not act.
//! Off by default (the paper scenario is bit-for-bit unchanged: the factor is then exactly 1).
//!
//! # Cost
//!
//! The zone lookup and the recovery of one wheelset are refreshed per step in turn (each
//! wheelset every 4 steps, 0.4 ms at 10 kHz, i.e. 4 cm at 100 m/s), one exp per step.

use crate::contact::Polach;
use crate::keys::{KeyInfo, KeyValue, KeyVisitor, Keys};
use crate::params::{AdhesionSet, ContactParams, ParamError, check};
use crate::real::Real;

/// Zones a track holds.
pub const MAX_ZONES: usize = 16;
/// Rail cells of the conditioning ring.
pub const CELLS: usize = 128;

/// The rail's surface: which contact set acts.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
#[cfg_attr(
    feature = "serde",
    derive(serde::Deserialize),
    serde(rename_all = "snake_case")
)]
#[repr(u8)]
pub enum Surface {
    /// `[contact.dry]`.
    Dry,
    /// `[contact]` (the paper's wet rail).
    #[default]
    Wet,
    /// Low adhesion (available ~0.05-0.08), contaminated.
    Low,
    /// Very low adhesion (available ~0.03), contaminated.
    VeryLow,
}

impl Surface {
    /// Every surface, in index order.
    pub const ALL: [Surface; 4] = [Surface::Dry, Surface::Wet, Surface::Low, Surface::VeryLow];

    /// Whether the rail is contaminated (its adhesion can recover).
    pub fn contaminated(self) -> bool {
        matches!(self, Surface::Low | Surface::VeryLow)
    }

    /// The name used in track files.
    pub fn name(self) -> &'static str {
        match self {
            Surface::Dry => "dry",
            Surface::Wet => "wet",
            Surface::Low => "low",
            Surface::VeryLow => "very_low",
        }
    }
}

/// Low adhesion set (available adhesion ~0.07; see the module doc for the sources).
pub const LOW_ADHESION: AdhesionSet = AdhesionSet {
    k_a: 0.30,
    k_s: 0.10,
    mu_0: 0.08,
    a_ratio: 0.40,
    b_exp: 0.20,
};

/// Very low adhesion set (available adhesion ~0.03).
pub const VERY_LOW_ADHESION: AdhesionSet = AdhesionSet {
    k_a: 0.30,
    k_s: 0.10,
    mu_0: 0.035,
    a_ratio: 0.40,
    b_exp: 0.20,
};

/// The low and very low contact sets (dry and wet come from `[contact]`).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(
    feature = "serde",
    derive(serde::Deserialize),
    serde(deny_unknown_fields)
)]
pub struct ContactSets {
    /// Low adhesion.
    #[cfg_attr(feature = "serde", serde(default = "low_default"))]
    pub low: AdhesionSet,
    /// Very low adhesion.
    #[cfg_attr(feature = "serde", serde(default = "very_low_default"))]
    pub very_low: AdhesionSet,
}

#[cfg(feature = "serde")]
fn low_default() -> AdhesionSet {
    LOW_ADHESION
}
#[cfg(feature = "serde")]
fn very_low_default() -> AdhesionSet {
    VERY_LOW_ADHESION
}

impl Default for ContactSets {
    fn default() -> Self {
        Self {
            low: LOW_ADHESION,
            very_low: VERY_LOW_ADHESION,
        }
    }
}

impl ContactSets {
    /// The Polach set of a surface.
    pub fn set(&self, contact: &ContactParams, surface: Surface) -> AdhesionSet {
        match surface {
            Surface::Dry => contact.set(crate::Rail::Dry),
            Surface::Wet => contact.set(crate::Rail::Wet),
            Surface::Low => self.low,
            Surface::VeryLow => self.very_low,
        }
    }

    /// Checks both sets' ranges (the key names the set and the value: `sets.low.mu_0`).
    pub fn validate(&self) -> Result<(), ParamError> {
        let keys = |set: &'static str| match set {
            "low" => [
                "sets.low.k_a",
                "sets.low.k_s",
                "sets.low.mu_0",
                "sets.low.a_ratio",
                "sets.low.b_exp",
            ],
            _ => [
                "sets.very_low.k_a",
                "sets.very_low.k_s",
                "sets.very_low.mu_0",
                "sets.very_low.a_ratio",
                "sets.very_low.b_exp",
            ],
        };
        for (set, name) in [(&self.low, "low"), (&self.very_low, "very_low")] {
            let [k_a, k_s, mu_0, a_ratio, b_exp] = keys(name);
            check(k_a, set.k_a, 1e-3, 100.0)?;
            check(k_s, set.k_s, 1e-3, 100.0)?;
            check(mu_0, set.mu_0, 1e-3, 2.0)?;
            check(a_ratio, set.a_ratio, 0.0, 1.0)?;
            check(b_exp, set.b_exp, 0.0, 100.0)?;
        }
        Ok(())
    }
}

/// One zone of the track.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
#[cfg_attr(
    feature = "serde",
    derive(serde::Deserialize),
    serde(deny_unknown_fields)
)]
pub struct Zone {
    /// Start, m along the track.
    pub start_m: f64,
    /// End (exclusive), m.
    pub end_m: f64,
    /// Its surface.
    pub surface: Surface,
}

/// Why a track is refused.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum TrackError {
    /// More than [`MAX_ZONES`] zones.
    TooManyZones,
    /// Zone `index` has end <= start or a bound that is not finite.
    BadZone {
        /// 0-based zone index.
        index: usize,
    },
    /// Zone `index` starts before the previous one ends (zones are in order, disjoint).
    Overlap {
        /// 0-based zone index.
        index: usize,
    },
}

impl core::fmt::Display for TrackError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            TrackError::TooManyZones => write!(f, "a track holds at most {MAX_ZONES} zones"),
            TrackError::BadZone { index } => {
                write!(
                    f,
                    "zone {}: end_m must be finite and above start_m",
                    index + 1
                )
            }
            TrackError::Overlap { index } => write!(
                f,
                "zone {}: starts before zone {} ends (zones in order, disjoint)",
                index + 1,
                index
            ),
        }
    }
}

/// A track: base surface and ordered, disjoint zones.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Track {
    base: Surface,
    zones: [Zone; MAX_ZONES],
    count: usize,
}

impl Track {
    /// One surface everywhere.
    pub fn uniform(surface: Surface) -> Self {
        Self {
            base: surface,
            zones: [Zone::default(); MAX_ZONES],
            count: 0,
        }
    }

    /// `zones` on `base`; refuses more than [`MAX_ZONES`], empty or non-finite zones and
    /// zones out of order or overlapping.
    pub fn new(base: Surface, zones: &[Zone]) -> Result<Self, TrackError> {
        if zones.len() > MAX_ZONES {
            return Err(TrackError::TooManyZones);
        }
        let mut track = Self::uniform(base);
        for (index, z) in zones.iter().enumerate() {
            if !(z.start_m.is_finite() && z.end_m.is_finite() && z.end_m > z.start_m) {
                return Err(TrackError::BadZone { index });
            }
            if index > 0 && z.start_m < zones[index - 1].end_m {
                return Err(TrackError::Overlap { index });
            }
            track.zones[index] = *z;
        }
        track.count = zones.len();
        Ok(track)
    }

    /// The base surface.
    pub fn base(&self) -> Surface {
        self.base
    }

    /// The zones.
    pub fn zones(&self) -> &[Zone] {
        &self.zones[..self.count]
    }

    /// The surface at `x_m` (the base outside every zone, and for NaN).
    pub fn surface_at(&self, x_m: f64) -> Surface {
        self.zones()
            .iter()
            .find(|z| x_m >= z.start_m && x_m < z.end_m)
            .map_or(self.base, |z| z.surface)
    }
}

/// `[degraded_adhesion]` of the parameter file: recovery of contaminated rails (Allotta
/// et al. 2014). Off by default.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(
    feature = "serde",
    derive(serde::Deserialize),
    serde(deny_unknown_fields)
)]
pub struct DegradedAdhesionParams {
    /// Whether the recovery acts.
    pub enabled: bool,
    /// Recovered over degraded friction, R (>= 1).
    pub recovered_mu_ratio: f64,
    /// Specific energy W_0 that gives 63 % of the recovery, J per metre of rail.
    pub energy_scale_j_per_m: f64,
    /// Low-pass of a contact's own dissipation, s.
    pub time_constant_s: f64,
    /// Length of a rail cell of the conditioning ring, m ([`CELLS`] of them must span the
    /// vehicle).
    pub cell_length_m: f64,
}

impl Default for DegradedAdhesionParams {
    fn default() -> Self {
        Self {
            enabled: false,
            recovered_mu_ratio: 2.0,
            energy_scale_j_per_m: 1500.0,
            time_constant_s: 0.1,
            cell_length_m: 0.25,
        }
    }
}

impl DegradedAdhesionParams {
    /// Checks every value against the range of its key ([`Keys`]); the error names the key.
    pub fn validate(&self) -> Result<(), ParamError> {
        crate::keys::check_keys(self)
    }

    /// Checks that the conditioning ring spans a vehicle whose wheelsets lie `span_m` (m)
    /// apart (first to last), with [`RING_MARGIN_CELLS`] cells to spare: below, a trailing
    /// wheelset's cell would share its slot with a leading one's and reset it (tag
    /// collision), silently losing the conditioning. The error names the key.
    pub fn validate_span(&self, span_m: f64) -> Result<(), ParamError> {
        let shortest = span_m / (CELLS - RING_MARGIN_CELLS) as f64;
        check(
            "degraded_adhesion.cell_length_m",
            self.cell_length_m,
            shortest.max(0.05),
            10.0,
        )
    }
}

/// The key table of `[degraded_adhesion]`, in file order (ranges checked by
/// [`DegradedAdhesionParams::validate`]).
impl Keys for DegradedAdhesionParams {
    fn visit_keys<V: KeyVisitor>(&mut self, v: &mut V) {
        let key = |name, doc, unit, min, max| KeyInfo {
            name,
            doc,
            unit,
            min,
            max,
        };
        v.key(
            &KeyInfo::unranged("degraded_adhesion.enabled", "Whether the recovery acts."),
            KeyValue::Flag(&mut self.enabled),
        );
        #[rustfmt::skip]
        let reals: [(KeyInfo, &mut f64); 4] = [
            (key("degraded_adhesion.recovered_mu_ratio", "Recovered over degraded friction, R (>= 1).", "", 1.0, 10.0), &mut self.recovered_mu_ratio),
            (key("degraded_adhesion.energy_scale_j_per_m", "Specific energy W_0 that gives 63 % of the recovery, J per metre of rail.", "J/m", 1.0, 1e7), &mut self.energy_scale_j_per_m),
            (key("degraded_adhesion.time_constant_s", "Low-pass of a contact's own dissipation, s.", "s", 1e-3, 10.0), &mut self.time_constant_s),
            (key("degraded_adhesion.cell_length_m", "Length of a rail cell of the conditioning ring, m (128 cells must span the vehicle).", "m", 0.05, 10.0), &mut self.cell_length_m),
        ];
        for (info, value) in reals {
            v.key(&info, KeyValue::Real(value));
        }
    }
}

/// Cells of the conditioning ring beyond the vehicle's span (the leading wheelset may move
/// a few cells per refresh).
pub const RING_MARGIN_CELLS: usize = 8;

/// The track as the plant steps it: one Polach model per surface, each wheelset's surface
/// and its recovery state.
#[derive(Clone, Debug)]
pub struct TrackAdhesion<F: Real> {
    track: Track,
    /// Zone bounds in the plant's precision (no f64 in the board's step).
    starts: [F; MAX_ZONES],
    ends: [F; MAX_ZONES],
    polach: [Polach<F>; 4],
    /// Whether the step has anything to do: zones to cross or degraded adhesion on (a
    /// uniform track without it costs the plant's step one flag test).
    active: bool,
    /// Surface under each wheelset (refreshed in turn).
    surface: [Surface; crate::params::WHEELSETS],
    /// The contact model of each wheelset's surface (a copy: no lookup in the step) and
    /// its friction factor, side by side (one address per wheelset in the step).
    wheel: [WheelContact<F>; crate::params::WHEELSETS],
    /// Positions between which each wheelset's surface cannot change, `[lo, hi)`, m: the
    /// zones are looked up again only when a wheelset leaves its interval.
    lo: [F; crate::params::WHEELSETS],
    hi: [F; crate::params::WHEELSETS],
    degraded: Option<Recovery<F>>,
}

/// The contact under one wheelset: the model of its surface and the recovery's factor.
#[derive(Clone, Copy, Debug)]
struct WheelContact<F> {
    polach: Polach<F>,
    /// Friction factor 1 + (R - 1) lambda (exactly 1 when degraded adhesion is off).
    mu_factor: F,
}

impl<F: Copy> WheelContact<F> {
    /// Takes `polach` as this wheelset's contact model. Out of line so that the copy's
    /// source and destination are distinct references (a `memcpy`): written in `locate`,
    /// two elements of the track's arrays the compiler cannot tell apart, it was a call
    /// of the 1.6 KiB `memmove`, which nothing else in the board's step calls.
    #[inline(never)]
    fn set_polach(&mut self, polach: &Polach<F>) {
        self.polach = *polach;
    }
}

/// State of the recovery model.
#[derive(Clone, Debug)]
struct Recovery<F> {
    ratio_minus_one: F,
    inv_energy_scale: F,
    /// Filter gain of the own dissipation per refresh (every 4 steps).
    own_gain: F,
    cell_length: F,
    inv_cell: F,
    /// Cell under each wheelset and where it ends, m (followed step by step in the
    /// plant's precision: no f64 in the board's step).
    cell: [i32; crate::params::WHEELSETS],
    cell_end: [F; crate::params::WHEELSETS],
    /// Energy per metre deposited in each cell, J/m, and the cell's index along the track.
    cell_energy: [F; CELLS],
    cell_tag: [i32; CELLS],
    /// Own low-passed specific dissipation P/v per wheelset, J/m.
    own: [F; crate::params::WHEELSETS],
    /// Energy each wheelset deposited in the cell it is in (removed from what it reads).
    own_in_cell: [F; crate::params::WHEELSETS],
    own_tag: [i32; crate::params::WHEELSETS],
}

impl<F: Real> TrackAdhesion<F> {
    /// The track's models on the plant's contact geometry, degraded adhesion per `degraded`,
    /// for a plant step `dt_s`.
    pub fn new(
        contact: &ContactParams,
        sets: &ContactSets,
        track: Track,
        degraded: &DegradedAdhesionParams,
        dt_s: f64,
    ) -> Result<Self, ParamError> {
        sets.validate()?;
        degraded.validate()?;
        let polach = Surface::ALL.map(|s| Polach::with_set(contact, &sets.set(contact, s)));
        let recovery = degraded.enabled.then(|| Recovery {
            ratio_minus_one: F::of(degraded.recovered_mu_ratio - 1.0),
            inv_energy_scale: F::of(1.0 / degraded.energy_scale_j_per_m),
            own_gain: F::of(1.0 - crate::math::exp_f64(-4.0 * dt_s / degraded.time_constant_s)),
            cell_length: F::of(degraded.cell_length_m),
            inv_cell: F::of(1.0 / degraded.cell_length_m),
            cell: [0; crate::params::WHEELSETS],
            cell_end: [F::of(degraded.cell_length_m); crate::params::WHEELSETS],
            cell_energy: [F::ZERO; CELLS],
            cell_tag: [i32::MIN; CELLS],
            own: [F::ZERO; crate::params::WHEELSETS],
            own_in_cell: [F::ZERO; crate::params::WHEELSETS],
            own_tag: [i32::MIN; crate::params::WHEELSETS],
        });
        let base = track.base();
        let mut starts = [F::ZERO; MAX_ZONES];
        let mut ends = [F::ZERO; MAX_ZONES];
        for (i, z) in track.zones().iter().enumerate() {
            starts[i] = F::of(z.start_m);
            ends[i] = F::of(z.end_m);
        }
        // A uniform track: every position lies in (-inf, inf); with zones, an empty interval
        // makes the first refresh of each wheelset look its surface up.
        let uniform = track.count == 0;
        let (lo, hi) = if uniform {
            (F::of(f64::NEG_INFINITY), F::of(f64::INFINITY))
        } else {
            (F::of(f64::INFINITY), F::of(f64::NEG_INFINITY))
        };
        Ok(Self {
            track,
            starts,
            ends,
            active: !uniform || recovery.is_some(),
            wheel: [WheelContact {
                polach: polach[base as usize],
                mu_factor: F::ONE,
            }; crate::params::WHEELSETS],
            polach,
            surface: [base; crate::params::WHEELSETS],
            lo: [lo; crate::params::WHEELSETS],
            hi: [hi; crate::params::WHEELSETS],
            degraded: recovery,
        })
    }

    /// The track.
    pub fn track(&self) -> &Track {
        &self.track
    }

    /// The contact model under wheelset `j` (0-based) and its friction factor.
    #[inline(always)]
    pub fn contact(&self, j: usize) -> (&Polach<F>, F) {
        let wheel = &self.wheel[j & 3];
        (&wheel.polach, wheel.mu_factor)
    }

    /// Whether [`Self::step`] has anything to do: the track has zones or degraded adhesion
    /// is on (false: the plant skips the call).
    #[inline(always)]
    pub fn active(&self) -> bool {
        self.active
    }

    /// The surface under each wheelset.
    pub fn surfaces(&self) -> [Surface; crate::params::WHEELSETS] {
        self.surface
    }

    /// Places wheelset `j` at track position `x_m` (m) for the cell ring (construction; the
    /// step then follows it cell by cell).
    pub fn place(&mut self, j: usize, x_m: F) {
        if let Some(r) = self.degraded.as_mut() {
            let len = r.cell_length.to_f64();
            let cell = libm::floor(x_m.to_f64() / len);
            let cell = if cell.is_finite() {
                cell.clamp(-1e9, 1e9)
            } else {
                0.0
            };
            r.cell[j] = cell as i32;
            r.cell_end[j] = F::of((cell + 1.0) * len);
        }
    }

    /// Looks up the surface under wheelset `j` at `x_m` and the interval around `x_m` in which
    /// it stays (between the nearest zone bounds); out of line, run only on a crossing.
    #[inline(never)]
    fn locate(&mut self, j: usize, x_m: F) {
        let mut surface = self.track.base;
        let mut lo = F::of(f64::NEG_INFINITY);
        let mut hi = F::of(f64::INFINITY);
        for i in 0..self.track.count {
            let (start, end) = (self.starts[i], self.ends[i]);
            if x_m >= start && x_m < end {
                surface = self.track.zones[i].surface;
            }
            for bound in [start, end] {
                if bound <= x_m {
                    lo = lo.max(bound);
                } else if bound < hi {
                    hi = bound;
                }
            }
        }
        if x_m.is_nan() {
            // Looked up again at the next refresh.
            (lo, hi) = (F::of(f64::INFINITY), F::of(f64::NEG_INFINITY));
        }
        self.surface[j] = surface;
        self.wheel[j].set_polach(&self.polach[surface as usize & 3]);
        self.lo[j] = lo;
        self.hi[j] = hi;
    }

    /// Refreshes wheelset `j` at track position `x_m` (m) with its speed (m/s) and the
    /// power dissipated in its contact (W), `elapsed_s` since its last refresh. Kept out of
    /// line (the plant's wheelset loop stays as it was); named `step` so the board places it in
    /// CCM SRAM with the plant's step (firmware/board/ccm.x).
    #[inline(never)]
    pub fn step(&mut self, j: usize, x_m: F, speed: F, contact_power: F, elapsed_s: F) {
        let j = j & 3;
        // NaN leaves every interval: looked up (base surface) as before.
        if !(x_m >= self.lo[j] && x_m < self.hi[j]) {
            self.locate(j, x_m);
        }
        let surface = self.surface[j];
        let Some(r) = self.degraded.as_mut() else {
            return;
        };
        // Follow the cell under the wheelset (a few cells per refresh at most; usually
        // none: the first test finds it inside its cell).
        for _ in 0..4 {
            if x_m >= r.cell_end[j] {
                r.cell[j] = r.cell[j].wrapping_add(1);
                r.cell_end[j] += r.cell_length;
            } else if x_m < r.cell_end[j] - r.cell_length {
                r.cell[j] = r.cell[j].wrapping_sub(1);
                r.cell_end[j] -= r.cell_length;
            } else {
                break;
            }
        }
        let tag = r.cell[j];
        let slot = tag.rem_euclid(CELLS as i32) as usize;
        if r.cell_tag[slot] != tag {
            r.cell_tag[slot] = tag;
            r.cell_energy[slot] = F::ZERO;
        }
        if r.own_tag[j] != tag {
            r.own_tag[j] = tag;
            r.own_in_cell[j] = F::ZERO;
        }
        let power = contact_power.abs();
        let power = if power.is_finite() { power } else { F::ZERO };
        let deposit = power * elapsed_s * r.inv_cell;
        let ahead = (r.cell_energy[slot] - r.own_in_cell[j]).max(F::ZERO);
        r.cell_energy[slot] += deposit;
        r.own_in_cell[j] += deposit;
        let per_metre = power / speed.abs().max(F::ONE);
        r.own[j] += (per_metre - r.own[j]) * r.own_gain;
        self.wheel[j].mu_factor = if surface.contaminated() {
            let lambda = F::ONE - (-(ahead + r.own[j]) * r.inv_energy_scale).exp();
            F::ONE + r.ratio_minus_one * lambda
        } else {
            F::ONE
        };
    }
}
