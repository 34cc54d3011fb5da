//! The outcome stage of `hils diagnose`: the causes found replayed at the command's step,
//! the share of the error they leave (no cause is claimed beyond [`MAX_UNEXPLAINED`]), and
//! the notes on look-alikes (method steps 5 and 7 of [`super`]).

use super::baseline::Baseline;
use super::causes::Causes;
use super::replay::{self, Model, Replay, Score, Split};
use super::search::{MAX_UNEXPLAINED, SetFit};

/// The extended model (baseline + the causes claimed) at the command's step.
pub struct Settled {
    pub result: SetFit,
    pub models: Vec<Model>,
    pub replays: Vec<Replay>,
    /// Share of the baseline's excess error over noise that the result leaves.
    pub unexplained_share: f64,
    pub confounded: Vec<Vec<String>>,
}

/// Replays the causes at the command's step and decides what is claimed; notes on
/// look-alikes and on a claim withdrawn go to `notes`.
pub fn settle(base: &Baseline, causes: &Causes, notes: &mut Vec<String>) -> Settled {
    let d = &base.d;
    for group in &causes.confounded {
        notes.push(format!(
            "look-alikes {}: {}",
            group.join(" / "),
            what_separates(group)
        ));
    }
    let mut effects = causes.effects.clone();
    let mut x = causes.x.clone();
    let mut ci = causes.ci95_half.clone();
    let mut confounded = causes.confounded.clone();
    let mut models = d.models(&effects, &x);
    let mut replays = d.replays(&models).unwrap_or_else(|| base.replays.clone());
    let mut validation = d.score(&replays, Split::Validation);
    let mut unexplained = if base.discrepancy {
        unexplained_share(&base.validation, &validation)
    } else {
        0.0
    };
    if base.discrepancy && !effects.is_empty() && unexplained > MAX_UNEXPLAINED {
        notes.push(format!(
            "the best combination of listed effects ({}) leaves {:.0} % of the error unexplained: no cause is claimed",
            effects.iter().map(|e| e.name()).collect::<Vec<_>>().join(" + "),
            unexplained * 100.0
        ));
        effects.clear();
        x.clear();
        ci.clear();
        confounded.clear();
        models = base.models.clone();
        replays = base.replays.clone();
        validation = base.validation.clone();
    }
    if base.discrepancy && effects.is_empty() {
        unexplained = 1.0;
    }
    let result = SetFit {
        effects,
        x,
        ci95_half: ci,
        fit: d.score(&replays, Split::Fit),
        validation,
        evaluations: causes.evaluations,
        residuals: vec![],
        jacobian: None,
    };
    Settled {
        result,
        models,
        replays,
        unexplained_share: unexplained,
        confounded,
    }
}

/// Share of the baseline's excess error over noise (compared where either errs,
/// [`replay::compare`]) that `extended` leaves.
fn unexplained_share(baseline: &Score, extended: &Score) -> f64 {
    let excess = |rms: f64| (rms * rms - 1.0).max(0.0);
    let replay::ComparedRms {
        reference: b,
        candidate: e,
    } = replay::compare(baseline, extended);
    (excess(e) / excess(b).max(1e-12)).sqrt().clamp(0.0, 1.0)
}

/// Which measurement would tell a group of look-alike effects apart (issue 9, item 3).
pub fn what_separates(group: &[String]) -> String {
    let has = |e: &str| group.iter().any(|g| g == e);
    let mut out = Vec::new();
    if has("mass") && group.len() > 1 {
        out.push("axle loads (q1..q4) measure the mass");
    }
    if has("friction-pressure") && group.len() > 1 {
        out.push("a second run at another clamp force separates friction-pressure");
    }
    if has("sensor-gain") && group.len() > 1 {
        out.push("f_brake, or both p_cyl and f_clamp, separate a sensor gain");
    }
    if has("friction-level") && group.len() > 1 {
        out.push("f_brake logged measures mu_d directly");
    }
    if has("gradient") || has("running-resistance") {
        out.push("a coasting phase or a second run at another speed separates gradient from running resistance");
    }
    if out.is_empty() {
        out.push("a run under other conditions (speed, clamp force, rail)");
    }
    out.join("; ")
}
