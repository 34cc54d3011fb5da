//! Stage 5: the f32 run (the compiled-in math) against the f64 reference.

use anyhow::Result;
use hils_plant::{FrictionModel, WHEELSETS};
use hils_sil::ParamFile;
use serde::Serialize;

use crate::scenario::{EbOptions, Run, run_eb};

/// What one run of the paper's EB gives (f32 or f64).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RunFigures {
    /// Time of the stop, s.
    pub stop_time_s: Option<f64>,
    /// Distance to the stop, m.
    pub stopping_distance_m: Option<f64>,
    /// Wheelsets whose WSP acted.
    pub slides: Vec<usize>,
    /// First WSP vent per wheelset, s.
    pub slide_onsets_s: [Option<f64>; WHEELSETS],
}

impl RunFigures {
    fn of(run: &Run) -> Self {
        let s = &run.summary;
        Self {
            stop_time_s: s.stop_time_s,
            stopping_distance_m: s.stopping_distance_m,
            slides: s.slides.clone(),
            slide_onsets_s: s.slide_onset_s,
        }
    }
}

/// One friction model's f32 run (the compiled-in math) against the f64 reference.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Fidelity {
    /// Friction model.
    pub friction: String,
    /// The f32 run.
    pub f32: RunFigures,
    /// The f64 reference.
    pub f64: RunFigures,
    /// (f32 - f64) / f64 of the stopping distance, percent.
    pub stopping_distance_error_pct: Option<f64>,
    /// Largest |onset f32 - onset f64| over wheelsets that slide in both, ms.
    pub slide_onset_max_diff_ms: Option<f64>,
    /// Largest |mu_d f32 - mu_d f64| over the 1 kHz samples and wheelsets while moving.
    pub mu_d_max_abs_diff: f64,
    /// Mean over wheelsets of the same, RMS over time.
    pub mu_d_rms_diff: f64,
}

/// The f32 run against the f64 run of the paper's EB (`hils simulate`'s runs, 1 kHz).
pub fn fidelity(friction: FrictionModel) -> Result<Fidelity> {
    let mut file = ParamFile::default();
    file.plant.friction.model = friction;
    let opts = EbOptions::paper(&file);
    let a = run_eb::<f32>(&file, &opts)?;
    let b = run_eb::<f64>(&file, &opts)?;
    Ok(compare_runs(friction, &a, &b))
}

fn compare_runs(friction: FrictionModel, a: &Run, b: &Run) -> Fidelity {
    let (sa, sb) = (&a.summary, &b.summary);
    let onsets_diff = (0..WHEELSETS)
        .filter_map(|j| Some((sa.slide_onset_s[j]? - sb.slide_onset_s[j]?).abs() * 1e3))
        .fold(None, |m: Option<f64>, d| Some(m.map_or(d, |m| m.max(d))));
    let mut max_diff = 0.0f64;
    let (mut sq, mut n) = (0.0f64, 0usize);
    let end = sb.stop_time_s.unwrap_or(f64::INFINITY);
    for (x, y) in a.samples.iter().zip(&b.samples) {
        if y.t_s > end {
            break;
        }
        for j in 0..WHEELSETS {
            let d = (x.mu_d[j] - y.mu_d[j]).abs();
            max_diff = max_diff.max(d);
            sq += d * d;
            n += 1;
        }
    }
    let err = match (sa.stopping_distance_m, sb.stopping_distance_m) {
        (Some(x), Some(y)) => Some((x - y) / y * 100.0),
        _ => None,
    };
    Fidelity {
        friction: friction_name(friction).to_string(),
        f32: RunFigures::of(a),
        f64: RunFigures::of(b),
        stopping_distance_error_pct: err,
        slide_onset_max_diff_ms: onsets_diff,
        mu_d_max_abs_diff: max_diff,
        mu_d_rms_diff: (sq / n.max(1) as f64).sqrt(),
    }
}

pub(crate) fn friction_name(f: FrictionModel) -> &'static str {
    match f {
        FrictionModel::Variable => "variable",
        FrictionModel::Constant => "constant",
    }
}
