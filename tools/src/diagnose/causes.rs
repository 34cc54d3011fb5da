//! The search stage of `hils diagnose`, run when there is a discrepancy: the runs prepared
//! at the fit step, the search for causes there ([`super::search`]), and the result refined
//! at the command's step (method steps 4-5 of [`super`]).

use std::time::Instant;

use hils_plant::Params;
use nalgebra::DMatrix;

use super::baseline::{Baseline, numeric_fault};
use super::effects::Effect;
use super::links;
use super::replay::{self, Score, Split};
use super::search::{
    Diagnoser, FINE_STEPS, FIT_STEP_S, FIT_TOLERANCE, REFINE_PATIENCE, SetFit, debug, search,
};
use crate::measured::RunLog;

/// The effects the search chose, with what it tried on the way.
pub struct Causes {
    /// Every effect fitted alone (at the fit step).
    pub singles: Vec<SetFit>,
    pub effects: Vec<Effect>,
    /// Parameters per effect, and their 95 % half-widths.
    pub x: Vec<Vec<f64>>,
    pub ci95_half: Vec<Vec<f64>>,
    pub confounded: Vec<Vec<String>>,
    /// The baseline's validation score at the fit step (the reference of the gains alone).
    pub fit_base_validation: Score,
    /// Replays of the diagnosis so far.
    pub evaluations: usize,
}

/// Searches the causes of the baseline's error (none when there is no discrepancy).
pub fn find(
    base: &Baseline,
    baseline: &Params,
    logs: &[RunLog],
    step_s: f64,
    started: Instant,
) -> anyhow::Result<Causes> {
    let mut fit_d = Diagnoser::new(baseline, logs, FIT_STEP_S.max(step_s))?;
    for (run, s) in fit_d.runs.iter_mut().zip(&base.vref_slow_sigma_mps) {
        if let Some(s) = *s {
            run.set_vref_slow_sigma(s);
        }
    }
    let mut causes = Causes {
        singles: Vec::new(),
        effects: vec![],
        x: vec![],
        ci95_half: vec![],
        confounded: Vec::new(),
        fit_base_validation: base.validation.clone(),
        evaluations: 0,
    };
    if base.fitted_discrepancy {
        let fit_base = fit_baseline(&fit_d)?;
        causes.fit_base_validation = fit_base.validation.clone();
        let unlisted: Vec<Effect> =
            links::odd_wheelsets(&base.d.runs, &base.replays, links::Link::DiscPadFriction)
                .into_iter()
                .map(|j| Effect::WheelsetFriction(j as u8))
                .collect();
        let s = search(&fit_d, &fit_base, &unlisted, started);
        causes.singles = s.singles;
        causes.effects = s.result.effects.clone();
        (causes.x, causes.ci95_half) = (s.result.x.clone(), s.result.ci95_half.clone());
        if !s.result.effects.is_empty() && fit_d.runs[0].dt != base.d.runs[0].dt {
            (causes.x, causes.ci95_half) = refine(&base.d, &s.result, &fit_d, started);
        }
        causes.confounded = s.confounded;
    }
    causes.evaluations = base.d.replays_done() + fit_d.replays_done();
    Ok(causes)
}

/// The baseline at the fit step, as a fitted set without effects.
fn fit_baseline(fit_d: &Diagnoser) -> anyhow::Result<SetFit> {
    let reps = fit_d
        .replays(&fit_d.models(&[], &[]))
        .ok_or_else(numeric_fault)?;
    let mut residuals = Vec::new();
    for (run, rep) in fit_d.runs.iter().zip(&reps) {
        replay::weighted_residuals(run, rep, Split::Fit, &mut residuals);
    }
    Ok(SetFit {
        links: links::errors(&fit_d.runs, &reps),
        effects: vec![],
        x: vec![],
        ci95_half: vec![],
        fit: fit_d.score(&reps, Split::Fit),
        validation: fit_d.score(&reps, Split::Validation),
        evaluations: 1,
        residuals,
        jacobian: Some(DMatrix::zeros(0, 0)),
    })
}

/// Refines the search's result at the final step `d` (slide timing is sensitive to the
/// step): a short LM continuation, then a coordinate search on the fit data, which also
/// steps up to the edge of the cliffs that slide replays have (a slightly poorer adhesion
/// locks a wheel for good under the measured WSP inputs), where LM stalls. Returns the
/// parameters and their 95 % half-widths.
fn refine(
    d: &Diagnoser,
    result: &SetFit,
    fit_d: &Diagnoser,
    started: Instant,
) -> (Vec<Vec<f64>>, Vec<Vec<f64>>) {
    let fit_ssr = |x: &[Vec<f64>]| -> f64 {
        d.residuals(&result.effects, x)
            .map(|r| r.iter().map(|v| v * v).sum())
            .unwrap_or(f64::INFINITY)
    };
    let mut x = result.x.clone();
    let mut ci = result.ci95_half.clone();
    let mut best = fit_ssr(&x);
    if let Some(r) = d.fit_set_with(&result.effects, Some(&x), REFINE_PATIENCE, FIT_TOLERANCE) {
        let ssr = fit_ssr(&r.x);
        if ssr <= best {
            best = ssr;
            x = r.x.clone();
            ci = r.ci95_half.clone();
        }
    }
    let (xs, _) = d.coordinate_search(&result.effects, x, best, &FINE_STEPS, 1);
    debug(
        started,
        d.replays_done() + fit_d.replays_done(),
        "refined at the final step",
    );
    (xs, ci)
}
