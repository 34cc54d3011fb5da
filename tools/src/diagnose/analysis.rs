//! The analysis stage of `hils diagnose`: when the baseline's error grows and what it goes
//! with (friction speed, disc temperature, ...), and the measured slides; read by the report.

use hils_plant::WHEELSETS;

use super::replay::{Prepared, Quantity, Replay};

/// What the baseline's error goes with, for one run.
#[derive(Clone, Debug, Default)]
pub struct RunAnalysis {
    pub name: String,
    /// First time the v_ref error exceeds 3 bin sigmas, s.
    pub first_exceed_s: Option<f64>,
    /// Time and value of the largest v_ref error (model - measured), s and m/s.
    pub max_error: (f64, f64),
    /// Mean relative deceleration error while braking (model decel / measured - 1).
    pub mean_relative_decel_error: f64,
    /// Pearson correlation of the relative deceleration error with each variable.
    pub correlations: Vec<(&'static str, f64)>,
    /// Points (variables, relative decel error) while braking: friction speed m/s, disc
    /// temperature degC, vehicle speed m/s, clamp force N, time s, creepage, error.
    pub points: Vec<[f64; 7]>,
    /// Slide intervals (wheelset 1-based, start s, end s) in the measured data.
    pub measured_slides: Vec<(usize, f64, f64)>,
}

/// What the baseline's error goes with, all runs.
#[derive(Clone, Debug, Default)]
pub struct Analysis {
    pub runs: Vec<RunAnalysis>,
}

pub const VARIABLES: [&str; 6] = [
    "friction speed",
    "disc temperature",
    "vehicle speed",
    "clamp force",
    "time",
    "creepage",
];
pub const UNITS: [&str; 6] = ["m/s", "degC", "m/s", "kN", "s", ""];

fn pearson(x: &[f64], y: &[f64]) -> f64 {
    let n = x.len() as f64;
    if x.len() < 3 {
        return f64::NAN;
    }
    let mx = x.iter().sum::<f64>() / n;
    let my = y.iter().sum::<f64>() / n;
    let (mut sxy, mut sxx, mut syy) = (0.0, 0.0, 0.0);
    for (a, b) in x.iter().zip(y) {
        sxy += (a - mx) * (b - my);
        sxx += (a - mx) * (a - mx);
        syy += (b - my) * (b - my);
    }
    if sxx <= 0.0 || syy <= 0.0 {
        f64::NAN
    } else {
        sxy / (sxx * syy).sqrt()
    }
}

/// Slide intervals from bin means (the slide threshold of [`super::replay::slides`]).
fn slide_intervals(
    run: &Prepared,
    v: &[f64],
    wheel: &[Vec<f64>; WHEELSETS],
) -> Vec<(usize, f64, f64)> {
    let mut out = Vec::new();
    for j in 0..WHEELSETS {
        let mut start: Option<f64> = None;
        for b in 0..run.n_bins {
            let (vb, wb) = (v[b], wheel[j][b]);
            let sliding =
                vb.is_finite() && wb.is_finite() && vb > 1.5 && vb - wb > (0.05 * vb).max(0.5);
            match (sliding, start) {
                (true, None) => start = Some(run.bin_time[b]),
                (false, Some(s)) => {
                    out.push((j + 1, s, run.bin_time[b]));
                    start = None;
                }
                _ => {}
            }
        }
        if let Some(s) = start {
            out.push((j + 1, s, run.duration));
        }
    }
    out
}

/// Analyses the baseline's error: when it grows, and what it goes with.
pub fn analyse(runs: &[Prepared], baseline: &[Replay]) -> Analysis {
    let mut out = Analysis::default();
    for (run, rep) in runs.iter().zip(baseline) {
        let mut a = RunAnalysis {
            name: run.name.clone(),
            ..Default::default()
        };
        let n = run.n_bins;
        let e: Vec<f64> = (0..n).map(|b| rep.v_bin[b] - run.v_bin[b]).collect();
        if let Some(c) = run.channels.iter().find(|c| c.quantity == Quantity::VRef) {
            for (k, &b) in c.bins.iter().enumerate() {
                if (rep.v_bin[b] - c.measured[k]).abs() > 3.0 * c.sigma[k] {
                    a.first_exceed_s = Some(run.bin_time[b]);
                    break;
                }
            }
        }
        for b in 0..n {
            if e[b].is_finite() && e[b].abs() > a.max_error.1.abs() {
                a.max_error = (run.bin_time[b], e[b]);
            }
        }
        // Deceleration error over +-0.25 s.
        let k = ((0.25 / run.bin_s).round() as usize).max(1);
        let clamp_max = run
            .clamp_bin
            .iter()
            .cloned()
            .filter(|x| x.is_finite())
            .fold(0.0f64, f64::max);
        let slides = slide_intervals(run, &run.v_bin, &run.wheel_bin);
        let in_slide = |t: f64| slides.iter().any(|(_, s, e)| t >= s - 0.3 && t <= e + 0.3);
        let ratio = 0.275 / 0.43;
        for b in k..n.saturating_sub(k) {
            let span = 2.0 * k as f64 * run.bin_s;
            let decel_meas = -(run.v_bin[b + k] - run.v_bin[b - k]) / span;
            let decel_err = -(e[b + k] - e[b - k]) / span;
            let v = run.v_bin[b];
            let t = run.bin_time[b];
            if !(decel_meas > 0.2
                && v > 1.0
                && run.clamp_bin[b] > 0.3 * clamp_max
                && decel_err.is_finite())
            {
                continue;
            }
            if in_slide(t) {
                continue;
            }
            let w: f64 =
                (0..WHEELSETS).map(|j| run.wheel_bin[j][b]).sum::<f64>() / WHEELSETS as f64;
            let temp = if run.disc_temp_bin[b].is_finite() {
                run.disc_temp_bin[b]
            } else {
                rep.disc_temp_bin.iter().map(|x| x[b]).sum::<f64>() / WHEELSETS as f64
            };
            let creep = (v - w) / v.max(0.1);
            a.points.push([
                w * ratio,
                temp,
                v,
                run.clamp_bin[b] / 1e3,
                t,
                creep,
                decel_err / decel_meas,
            ]);
        }
        if !a.points.is_empty() {
            a.mean_relative_decel_error =
                a.points.iter().map(|p| p[6]).sum::<f64>() / a.points.len() as f64;
            let y: Vec<f64> = a.points.iter().map(|p| p[6]).collect();
            for (i, name) in VARIABLES.iter().enumerate() {
                let x: Vec<f64> = a.points.iter().map(|p| p[i]).collect();
                a.correlations.push((name, pearson(&x, &y)));
            }
            a.correlations
                .sort_by(|x, y| y.1.abs().total_cmp(&x.1.abs()));
        }
        a.measured_slides = slides;
        out.runs.push(a);
    }
    out
}
