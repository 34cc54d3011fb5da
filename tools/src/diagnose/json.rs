//! The diagnosis JSON of `spec/diagnosis.md` (keys in the spec's order, plus a few extra
//! keys): the output format of `hils diagnose --json`.

use std::collections::BTreeMap;

use serde::Serialize;

use super::links;

/// One finding of the JSON.
#[derive(Clone, Debug, Serialize)]
pub struct Finding {
    pub effect: String,
    pub params: BTreeMap<String, f64>,
    pub ci95: BTreeMap<String, [f64; 2]>,
    /// Share of the baseline's validation error this effect alone removes.
    pub gain: f64,
    /// For `sensor-gain`: which sensors (`f_clamp`/`p_cyl` input, or `p_cyl` observation).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sensor: Option<String>,
}

#[derive(Clone, Debug, Serialize)]
pub struct Gain {
    pub metric: String,
    pub baseline: f64,
    pub extended: f64,
    pub reduction: f64,
    /// The same on the speeds alone (v_ref and r omega_1..4), m/s.
    pub speed_rms_mps: BTreeMap<String, f64>,
}

#[derive(Clone, Debug, Serialize)]
pub struct Slides {
    pub measured: Vec<usize>,
    pub baseline: Vec<usize>,
    pub extended: Vec<usize>,
}

/// The JSON document of `spec/diagnosis.md` (every key), plus a few extra keys.
#[derive(Clone, Debug, Serialize)]
pub struct Report {
    pub baseline: String,
    pub files: Vec<String>,
    pub discrepancy: bool,
    pub causes: Vec<String>,
    pub confounded: Vec<Vec<String>>,
    pub unexplained_share: f64,
    pub findings: Vec<Finding>,
    pub gain: Gain,
    pub slides: Slides,
    /// Each checkable link of the signal chain, baseline and extended error (noise units).
    pub localisation: Vec<links::LinkCheck>,
    /// Every effect tried alone: validation RMS and gain (extra key).
    pub tried: Vec<Tried>,
    /// What the reader or the replay skipped or repaired, per file (extra key).
    pub notes: Vec<String>,
    /// Wall time of the diagnosis, s (extra key).
    pub wall_s: f64,
}

/// An effect fitted alone.
#[derive(Clone, Debug, Serialize)]
pub struct Tried {
    pub effect: String,
    pub params: BTreeMap<String, f64>,
    pub validation_rms: f64,
    pub gain: f64,
}
