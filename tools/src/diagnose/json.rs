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

/// Figures of the JSON at their resolution (`hils::figures`): fitted parameters and their
/// intervals to 4 significant digits, errors in noise units and gains to 0.001, shares and
/// the reduction to 1e-4, speeds to 0.1 mm/s, the wall time to 10 ms.
pub mod resolution {
    use crate::figures::{round_dp, round_sig};

    pub fn param(x: f64) -> f64 {
        round_sig(x, 4)
    }
    pub fn noise_units(x: f64) -> f64 {
        round_dp(x, 3)
    }
    pub fn share(x: f64) -> f64 {
        round_dp(x, 4)
    }
    pub fn speed_mps(x: f64) -> f64 {
        round_dp(x, 4)
    }
    pub fn seconds(x: f64) -> f64 {
        round_dp(x, 2)
    }
}

impl Report {
    /// The report with every figure rounded to its resolution ([`resolution`]), as the JSON
    /// is written: every key and type stay.
    pub fn rounded(&self) -> Report {
        use resolution::*;
        let params = |m: &BTreeMap<String, f64>| -> BTreeMap<String, f64> {
            m.iter().map(|(k, v)| (k.clone(), param(*v))).collect()
        };
        let mut r = self.clone();
        r.unexplained_share = share(r.unexplained_share);
        for f in &mut r.findings {
            f.params = params(&f.params);
            for ci in f.ci95.values_mut() {
                *ci = ci.map(param);
            }
            f.gain = noise_units(f.gain);
        }
        r.gain.baseline = noise_units(r.gain.baseline);
        r.gain.extended = noise_units(r.gain.extended);
        r.gain.reduction = share(r.gain.reduction);
        for v in r.gain.speed_rms_mps.values_mut() {
            *v = speed_mps(*v);
        }
        for l in &mut r.localisation {
            l.baseline_error = noise_units(l.baseline_error);
            l.extended_error = noise_units(l.extended_error);
        }
        for t in &mut r.tried {
            t.params = params(&t.params);
            t.validation_rms = noise_units(t.validation_rms);
            t.gain = noise_units(t.gain);
        }
        r.wall_s = seconds(r.wall_s);
        r
    }
}
