//! The search stage of `hils diagnose`: single fits, forward selection with a beam,
//! backward elimination, look-alikes and the polish (method steps 4-5 of [`super`]).

use std::time::Instant;

use anyhow::{Result, bail};
use hils_plant::{Params, Rail};
use nalgebra::DMatrix;
use rayon::prelude::*;

use super::effects::{self, Effect};
use super::replay::{self, Model, Prepared, Replay, Score, Split};
use super::{links, lsq};
use crate::measured::RunLog;

/// Validation RMS (noise units) up to which the baseline explains the data...
pub const NO_DISCREPANCY_RMS: f64 = 1.5;
/// ...provided no 1 s window of a channel group exceeds this (a localised error, e.g. in
/// the brake application only, is a discrepancy too).
pub const SCAN_RMS: f64 = 2.5;
/// An effect is significant when it lowers the validation RMS by at least 10 % and removes
/// at least half a noise variance from the mean square.
pub fn significant(before: f64, after: f64) -> bool {
    after <= 0.9 * before && before * before - after * after >= 0.5
}
/// A second start path is explored when its single effect's error is within this factor.
pub const BEAM_TOLERANCE: f64 = 1.25;
/// Smallest material change of an effect's parameter, share of its scale.
pub const MIN_EFFECT: f64 = 0.2;
/// Start paths of the forward selection (the best single effects).
pub const BEAM: usize = 2;
/// A simpler fit is preferred unless a more complex one is better by this factor (and by
/// half a noise variance).
pub const PARSIMONY_TOLERANCE: f64 = 1.03;
/// Alternatives within this factor of the result's validation RMS are confounded with it.
pub const CONFOUND_TOLERANCE: f64 = 1.1;
/// No cause is claimed when more than this share of the excess error stays unexplained.
pub const MAX_UNEXPLAINED: f64 = 0.5;
/// Largest number of effects combined.
pub const MAX_EFFECTS: usize = 3;
/// The complexity (parameter count, [`SetFit::complexity`]) of an effect outside the
/// spec's list: more than any listed combination, so a listed explanation the data cannot
/// tell from it is preferred.
pub const OUT_OF_LIST_COMPLEXITY: usize = 16;

/// A fitted set of effects.
#[derive(Clone, Debug)]
pub struct SetFit {
    pub effects: Vec<Effect>,
    /// Parameters per effect.
    pub x: Vec<Vec<f64>>,
    pub ci95_half: Vec<Vec<f64>>,
    pub fit: Score,
    pub validation: Score,
    pub evaluations: usize,
    /// Weighted residuals on the fit bins at the solution.
    pub residuals: Vec<f64>,
    /// Their Jacobian in scaled parameters (columns in the order of `x`, flattened).
    pub jacobian: Option<DMatrix<f64>>,
    /// Validation error of every link of the signal chain (issue 27: an extension is judged
    /// on each).
    pub links: links::Errors,
}

impl SetFit {
    pub fn val(&self) -> f64 {
        self.validation.rms()
    }

    /// Whether `after` is significantly better than `self` on validation data (compared
    /// where either shows an error beyond the noise, [`replay::compare`]).
    pub fn improved_by(&self, after: &SetFit) -> bool {
        let replay::ComparedRms {
            reference: a,
            candidate: b,
        } = replay::compare(&self.validation, &after.validation);
        significant(a, b)
    }

    /// Number of parameters, an effect outside the spec's list counted as
    /// [`OUT_OF_LIST_COMPLEXITY`]: it is taken only where it is clearly better than every
    /// listed explanation.
    fn complexity(&self) -> usize {
        self.effects
            .iter()
            .zip(&self.x)
            .map(|(e, x)| {
                if e.is_listed() {
                    x.len()
                } else {
                    OUT_OF_LIST_COMPLEXITY
                }
            })
            .sum()
    }

    /// Whether the set makes a link worse than the baseline (`base`) beyond the noise.
    pub fn spoils(&self, base: &SetFit) -> bool {
        links::spoiled(&base.links, &self.links).is_some()
    }

    /// Columns of effect `k` in the flattened parameter vector.
    fn columns_of(&self, k: usize) -> std::ops::Range<usize> {
        let start: usize = self.x[..k].iter().map(|v| v.len()).sum();
        start..start + self.x[k].len()
    }
}

/// The diagnosis context: baseline and runs prepared for replays at one step.
pub struct Diagnoser {
    pub baseline: Params,
    pub runs: Vec<Prepared>,
    replays_done: std::sync::atomic::AtomicUsize,
}

/// A candidate effect probed at a fitted set: its neutral parameters and the Jacobian
/// columns of the fit residuals with respect to its scaled parameters.
struct Probe {
    effect: Effect,
    neutral: Vec<f64>,
    columns: DMatrix<f64>,
    specs: Vec<lsq::ParamSpec>,
    /// A friction factor probed by amplitude at several decay constants.
    factor_absent: bool,
    /// Parameter changes of the columns.
    directions: Vec<Vec<f64>>,
    /// Residuals with the effect added at its neutral parameters minus the set's (zero
    /// except for an Eq (2) factor added to a constant baseline: Eq (2) carries c).
    shift: Vec<f64>,
}

impl Probe {
    /// Residuals `r` of a set, moved to where this effect starts (its neutral point).
    fn shifted(&self, r: &[f64]) -> Vec<f64> {
        r.iter().zip(&self.shift).map(|(a, b)| a + b).collect()
    }
}

impl Diagnoser {
    pub fn new(baseline: &Params, logs: &[RunLog], step_s: f64) -> Result<Self> {
        if logs.is_empty() {
            bail!("no run logs to diagnose");
        }
        let mut runs = Vec::new();
        for log in logs {
            if log.len() < 10 {
                bail!(
                    "{}: only {} samples; a diagnosis needs at least 10",
                    log.path.display(),
                    log.len()
                );
            }
            let rail = log.rail.unwrap_or_default();
            let mut dt = step_s;
            if hils_plant::Plant::<f64>::with_step(baseline, rail, 10.0, dt).is_err() {
                dt = replay::replay_step(baseline, rail);
            }
            replay::check_budget(log, dt)?;
            runs.push(Prepared::new(log, baseline, dt));
        }
        Ok(Self {
            baseline: *baseline,
            runs,
            replays_done: Default::default(),
        })
    }

    pub(super) fn rail(&self) -> Rail {
        self.runs[0].rail
    }

    /// Replays so far (all runs of one model count once).
    pub fn replays_done(&self) -> usize {
        self.replays_done.load(std::sync::atomic::Ordering::Relaxed)
    }

    /// Models of a set of effects with parameters, one per run (rails may differ).
    pub fn models(&self, effects: &[Effect], x: &[Vec<f64>]) -> Vec<Model> {
        self.runs
            .iter()
            .map(|run| {
                let active: Vec<(Effect, &[f64])> = effects
                    .iter()
                    .copied()
                    .zip(x.iter().map(|v| v.as_slice()))
                    .collect();
                effects::build(&self.baseline, run.rail, &active)
            })
            .collect()
    }

    /// Replays every run in a set of models.
    pub fn replays(&self, models: &[Model]) -> Option<Vec<Replay>> {
        self.replays_done
            .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        self.runs
            .iter()
            .zip(models)
            .map(|(r, m)| replay::replay(r, m))
            .collect()
    }

    pub fn score(&self, replays: &[Replay], split: Split) -> Score {
        let mut s = Score::default();
        for (i, (run, rep)) in self.runs.iter().zip(replays).enumerate() {
            s.add_run(i, &replay::score(run, rep, split));
        }
        s
    }

    /// Weighted fit-bin residuals of a set of effects with parameters.
    pub(super) fn residuals(&self, effects: &[Effect], x: &[Vec<f64>]) -> Option<Vec<f64>> {
        let reps = self.replays(&self.models(effects, x))?;
        let mut out = Vec::new();
        for (run, rep) in self.runs.iter().zip(&reps) {
            replay::weighted_residuals(run, rep, Split::Fit, &mut out);
        }
        Some(out)
    }

    fn specs(
        &self,
        effects: &[Effect],
        start: Option<&[Vec<f64>]>,
    ) -> (Vec<lsq::ParamSpec>, Vec<usize>) {
        let rail = self.rail();
        let mut specs = Vec::new();
        let mut sizes = Vec::new();
        for (k, e) in effects.iter().enumerate() {
            let mut p: Vec<_> = e
                .params(&self.baseline, rail)
                .into_iter()
                .map(|(_, s)| s)
                .collect();
            if let Some(st) = start {
                for (s, v) in p.iter_mut().zip(&st[k]) {
                    s.start = v.clamp(s.min, s.max);
                }
            }
            sizes.push(p.len());
            specs.extend(p);
        }
        (specs, sizes)
    }

    /// Fits a set of effects from start values (None: the effects' own starts).
    pub fn fit_set(&self, effects: &[Effect], start: Option<&[Vec<f64>]>) -> Option<SetFit> {
        match start {
            Some(x) => self.fit_set_with(effects, Some(x), FIT_PATIENCE, FIT_TOLERANCE),
            None => {
                // From the generic start values, scan each parameter coarsely first: a
                // replay that locks a wheel (too much brake for the adhesion) is flat to
                // small parameter steps, and LM would not leave it.
                let x0: Vec<Vec<f64>> = effects
                    .iter()
                    .map(|e| {
                        e.params(&self.baseline, self.rail())
                            .into_iter()
                            .map(|(_, p)| p.start)
                            .collect()
                    })
                    .collect();
                let ssr_of = |x: &[Vec<f64>]| {
                    self.residuals(effects, x)
                        .map(|r| r.iter().map(|v| v * v).sum())
                        .unwrap_or(f64::INFINITY)
                };
                // A friction factor's amplitude and decay constant trade off (slides make
                // the landscape multi-modal): scan from three decay constants.
                let mut starts = vec![x0.clone()];
                if let [Effect::FrictionSpeed | Effect::FrictionTemperature] = effects {
                    for f in [1.0 / 3.0, 3.0] {
                        let mut x = x0.clone();
                        x[0][1] *= f;
                        starts.push(x);
                    }
                }
                let (x, _) = starts
                    .into_par_iter()
                    .map(|x| {
                        let ssr = ssr_of(&x);
                        self.coordinate_search(effects, x, ssr, &COARSE_STEPS, 1)
                    })
                    .min_by(|a, b| a.1.total_cmp(&b.1))?;
                self.fit_set_with(effects, Some(&x), FIT_PATIENCE, FIT_TOLERANCE)
            }
        }
    }

    /// As [`Diagnoser::fit_set`] with a budget of `patience` replays per (parameter + 1) and
    /// a relative `tolerance`.
    pub fn fit_set_with(
        &self,
        effects: &[Effect],
        start: Option<&[Vec<f64>]>,
        patience: usize,
        tolerance: f64,
    ) -> Option<SetFit> {
        let (specs, sizes) = self.specs(effects, start);
        let split_x = |x: &[f64]| -> Vec<Vec<f64>> {
            let mut out = Vec::new();
            let mut i = 0;
            for n in &sizes {
                out.push(x[i..i + n].to_vec());
                i += n;
            }
            out
        };
        let model_fn = |x: &[f64]| -> Option<Vec<f64>> { self.residuals(effects, &split_x(x)) };
        // FD step 2 % of the parameter scale: slide onsets make the residuals step-like at
        // finer scales.
        let fit = lsq::fit(
            &model_fn,
            &specs,
            FD_STEP,
            patience * (specs.len() + 1),
            tolerance,
            1.0,
        )?;
        if std::env::var_os("HILS_DIAG_DEBUG").is_some() {
            eprintln!(
                "  fit {:?}: {} replays, {}, x = {:?}",
                effects, fit.evaluations, fit.termination, fit.x
            );
        }
        // Confidence intervals: the residuals are autocorrelated (a model error persists
        // over many bins): inflate by sqrt((1 + rho) / (1 - rho)) of the lag-1 correlation.
        // They are also never narrower than the weights' own sigmas allow (residual
        // variance at least 1 in noise units: the floors are the model's resolution).
        let rho = lag1(&fit.residuals).clamp(0.0, 0.99);
        let dof = (fit.residuals.len() as f64 - fit.x.len() as f64).max(1.0);
        let s2 = fit.ssr / dof;
        let inflate = ((1.0 + rho) / (1.0 - rho)).sqrt() * (1.0 / s2.max(1e-12)).sqrt().max(1.0);
        let xs = split_x(&fit.x);
        let ci: Vec<f64> = fit.ci95_half.iter().map(|h| h * inflate).collect();
        let reps = self.replays(&self.models(effects, &xs))?;
        Some(SetFit {
            links: links::errors(&self.runs, &reps),
            effects: effects.to_vec(),
            ci95_half: split_x(&ci),
            x: xs,
            fit: self.score(&reps, Split::Fit),
            validation: self.score(&reps, Split::Validation),
            evaluations: fit.evaluations,
            residuals: fit.residuals,
            jacobian: fit.jacobian,
        })
    }

    /// Coordinate search on the fit data from `x` (sum of squares `ssr`): each parameter
    /// in turn tried at the relative `steps` of its value (of its scale near zero), within
    /// bounds; `rounds` rounds, each with steps four times smaller. Returns the parameters
    /// and their sum of squares.
    pub fn coordinate_search(
        &self,
        effects: &[Effect],
        x: Vec<Vec<f64>>,
        ssr: f64,
        steps: &[f64],
        rounds: usize,
    ) -> (Vec<Vec<f64>>, f64) {
        self.coordinate_search_of(effects, x, ssr, steps, rounds, None)
    }

    /// As [`Diagnoser::coordinate_search`], on effect `only` alone when given.
    pub fn coordinate_search_of(
        &self,
        effects: &[Effect],
        mut x: Vec<Vec<f64>>,
        mut ssr: f64,
        steps: &[f64],
        rounds: usize,
        only: Option<usize>,
    ) -> (Vec<Vec<f64>>, f64) {
        let rail = self.rail();
        let specs: Vec<Vec<lsq::ParamSpec>> = effects
            .iter()
            .map(|e| {
                e.params(&self.baseline, rail)
                    .into_iter()
                    .map(|(_, p)| p)
                    .collect()
            })
            .collect();
        for round in 0..rounds {
            let shrink = 0.25f64.powi(round as i32);
            for k in 0..effects.len() {
                if only.is_some_and(|o| o != k) {
                    continue;
                }
                for i in 0..x[k].len() {
                    let sp = specs[k][i];
                    let size = x[k][i].abs().max(sp.scale) * shrink;
                    let trials: Vec<f64> = steps
                        .iter()
                        .map(|d| (x[k][i] + d * size).clamp(sp.min, sp.max))
                        .collect();
                    let results: Vec<(f64, f64)> = trials
                        .par_iter()
                        .map(|&v| {
                            let mut xt = x.clone();
                            xt[k][i] = v;
                            let r = self.residuals(effects, &xt);
                            (
                                v,
                                r.map(|r| r.iter().map(|e| e * e).sum())
                                    .unwrap_or(f64::INFINITY),
                            )
                        })
                        .collect();
                    if let Some(&(v, best)) = results.iter().min_by(|a, b| a.1.total_cmp(&b.1)) {
                        if best < ssr {
                            ssr = best;
                            x[k][i] = v;
                        }
                    }
                }
            }
        }
        (x, ssr)
    }

    /// Whether effect `k` of a fitted set is physically material: some parameter differs
    /// from the value at which the effect changes nothing by at least [`MIN_EFFECT`] of
    /// its scale (a sensor gain of 1.002 that happens to shift a slide is not a cause).
    pub fn material(&self, set: &SetFit, k: usize) -> bool {
        let rail = self.rail();
        let mut effects = set.effects.clone();
        let mut xs = set.x.clone();
        let e = effects.remove(k);
        let x = xs.remove(k);
        let active: Vec<(Effect, &[f64])> = effects
            .iter()
            .copied()
            .zip(xs.iter().map(|v| v.as_slice()))
            .collect();
        let model = effects::build(&self.baseline, rail, &active);
        let specs = e.params(&self.baseline, rail);
        let starts: Vec<f64> = specs.iter().map(|(_, p)| p.start).collect();
        let neutral = e.neutral(&model, rail, &starts);
        let factor = matches!(e, Effect::FrictionSpeed | Effect::FrictionTemperature);
        if factor {
            // A friction factor must vary over the data: n (1 - e^(-m X)) from the slowest or
            // coldest to the fastest or hottest point (X: the largest friction speed of the
            // runs, or a 100 degC disc rise) changes mu_d by at least 1 % (a factor that does
            // not decay is a friction level).
            let range = match e {
                Effect::FrictionSpeed => {
                    let ratio =
                        self.baseline.brake.friction_radius / self.baseline.vehicle.wheel_radius;
                    self.runs.iter().map(|r| r.v0).fold(0.0, f64::max) * ratio
                }
                _ => 100.0,
            };
            return x[0] * (1.0 - (-x[1] * range).exp()) >= 0.01;
        }
        x.iter()
            .zip(&neutral)
            .zip(&specs)
            .any(|((v, n), (_, p))| (v - n).abs() >= MIN_EFFECT * p.scale)
    }

    /// How far a set departs from the baseline: the root sum of squares of each parameter's
    /// change from the value at which its effect changes nothing, in units of the parameter's
    /// scale (a friction factor by its amplitude alone). Among explanations the data cannot
    /// tell apart, the smallest change to the baseline is preferred ([`pick`]).
    pub fn departure(&self, set: &SetFit) -> f64 {
        let rail = self.rail();
        let mut sum = 0.0;
        for (k, e) in set.effects.iter().enumerate() {
            let others: Vec<(Effect, &[f64])> = (0..set.effects.len())
                .filter(|&i| i != k)
                .map(|i| (set.effects[i], set.x[i].as_slice()))
                .collect();
            let model = effects::build(&self.baseline, rail, &others);
            let specs = e.params(&self.baseline, rail);
            let starts: Vec<f64> = specs.iter().map(|(_, p)| p.start).collect();
            let neutral = e.neutral(&model, rail, &starts);
            let factor = matches!(e, Effect::FrictionSpeed | Effect::FrictionTemperature);
            for (i, ((v, n), (_, p))) in set.x[k].iter().zip(&neutral).zip(&specs).enumerate() {
                if !(factor && i == 1) {
                    sum += ((v - n) / p.scale).powi(2);
                }
            }
        }
        sum.sqrt()
    }

    /// Probes effect `a` at the fitted set `s`: Jacobian columns of the fit residuals with
    /// respect to `a`'s scaled parameters, from the parameters at which `a` changes nothing.
    fn probe(&self, s: &SetFit, a: Effect, hint: Option<&[f64]>) -> Option<Probe> {
        let rail = self.rail();
        let model = effects::build(
            &self.baseline,
            rail,
            &s.effects
                .iter()
                .copied()
                .zip(s.x.iter().map(|v| v.as_slice()))
                .collect::<Vec<_>>(),
        );
        let specs: Vec<lsq::ParamSpec> = a
            .params(&self.baseline, rail)
            .into_iter()
            .map(|(_, p)| p)
            .collect();
        let neutral = a.neutral(&model, rail, &probe_starts(&specs, hint));
        let mut effects = s.effects.clone();
        effects.push(a);
        let (factor_absent, directions) = probe_directions(a, &neutral, &specs);
        let mut xs0 = s.x.clone();
        xs0.push(neutral.clone());
        let r0 = self.residuals(&effects, &xs0)?;
        if r0.len() != s.residuals.len() {
            return None;
        }
        let cols: Vec<Option<Vec<f64>>> = directions
            .par_iter()
            .map(|dir| {
                let x: Vec<f64> = neutral.iter().zip(dir).map(|(n, d)| n + d).collect();
                // Column per unit of the probed parameter's scale.
                let h = dir
                    .iter()
                    .zip(&specs)
                    .map(|(d, sp)| d / sp.scale)
                    .find(|v| *v != 0.0)
                    .unwrap_or(FD_STEP);
                let mut xs = s.x.clone();
                xs.push(x);
                let r = self.residuals(&effects, &xs)?;
                (r.len() == r0.len()).then(|| r.iter().zip(&r0).map(|(a, b)| (a - b) / h).collect())
            })
            .collect();
        let m = s.residuals.len();
        let mut columns = DMatrix::zeros(m, directions.len());
        for (i, c) in cols.into_iter().enumerate() {
            columns.set_column(i, &nalgebra::DVector::from_vec(c?));
        }
        Some(Probe {
            effect: a,
            neutral,
            columns,
            specs,
            factor_absent,
            directions,
            shift: r0.iter().zip(&s.residuals).map(|(a, b)| a - b).collect(),
        })
    }
}

/// Fits stop at this relative change of the sum of squares / scaled parameters.
pub const FIT_TOLERANCE: f64 = 1e-3;
/// Fits stop after this many replays per (parameter + 1) (about as many iterations).
pub const FIT_PATIENCE: usize = 16;
/// Finite-difference step, share of each parameter's scale.
pub const FD_STEP: f64 = 0.02;
/// Replay step of the fits, s (the final scores use the command's step).
pub const FIT_STEP_S: f64 = 4.0e-3;
/// Relative steps of the coarse scan before a fit from generic start values.
pub const COARSE_STEPS: [f64; 8] = [-0.6, -0.3, -0.15, 0.15, 0.3, 0.6, 1.0, 2.0];
/// Relative steps of the final coordinate search at the command's step.
pub const FINE_STEPS: [f64; 10] = [
    -0.04, -0.02, -0.01, -0.005, -0.0025, 0.0025, 0.005, 0.01, 0.02, 0.04,
];
/// Budget of the final refinement at the command's step (replays per parameter + 1).
pub const REFINE_PATIENCE: usize = 5;
/// Candidates fitted per forward-selection step (the best of the linearised score test).
pub const CANDIDATES_PER_STEP: usize = 2;

/// The best of several fits of the same step: the lowest validation error, unless a fit
/// with fewer parameters explains the data as well (within [`PARSIMONY_TOLERANCE`]; then
/// the simplest such): a friction factor that does not decay is a friction level.
/// Start values of a probed effect: its fit alone (`hint`), unless a parameter ended on a
/// bound there (then it carries no shape information; the generic start is used).
fn probe_starts(specs: &[lsq::ParamSpec], hint: Option<&[f64]>) -> Vec<f64> {
    specs
        .iter()
        .enumerate()
        .map(|(i, p)| match hint {
            Some(h) if h[i] > p.min && h[i] < p.max => h[i],
            _ => p.start,
        })
        .collect()
}

/// Directions to probe effect `a` at `neutral`: each parameter; for a friction factor that
/// is absent (n = 0), the slope in m is zero, so the factor's amplitude is probed at three
/// decay constants instead (m/3, m, 3m; m from its fit alone). With whether it is absent.
fn probe_directions(a: Effect, neutral: &[f64], specs: &[lsq::ParamSpec]) -> (bool, Vec<Vec<f64>>) {
    let factor_absent =
        matches!(a, Effect::FrictionSpeed | Effect::FrictionTemperature) && neutral[0] == 0.0;
    let directions: Vec<Vec<f64>> = if factor_absent {
        let m = neutral[1].max(1e-6);
        [m / 3.0, m, 3.0 * m]
            .iter()
            .map(|&mm| vec![FD_STEP * specs[0].scale * 5.0, mm - m])
            .collect()
    } else {
        (0..specs.len())
            .map(|i| {
                let sp = &specs[i];
                let h = if neutral[i] + FD_STEP * sp.scale > sp.max {
                    -FD_STEP
                } else {
                    FD_STEP
                };
                let mut d = vec![0.0; specs.len()];
                d[i] = h * sp.scale;
                d
            })
            .collect()
    };
    (factor_absent, directions)
}

fn pick(d: &Diagnoser, trials: Vec<SetFit>) -> Option<SetFit> {
    let best_idx =
        (0..trials.len()).min_by(|&a, &b| trials[a].val().total_cmp(&trials[b].val()))?;
    let best = &trials[best_idx];
    // The fits the best is not clearly better than (by the tolerance and by half a noise
    // variance: below the noise, relative differences mean nothing).
    let tied: Vec<usize> = (0..trials.len())
        .filter(|&i| {
            let replay::ComparedRms {
                reference: other,
                candidate: b,
            } = replay::compare(&trials[i].validation, &best.validation);
            !(b * PARSIMONY_TOLERANCE < other && other * other - b * b >= 0.5)
        })
        .collect();
    // Among them the simplest, then the smallest change to the baseline, then the lowest
    // error.
    let departure: Vec<f64> = trials.iter().map(|t| d.departure(t)).collect();
    let i = tied.into_iter().min_by(|&a, &b| {
        trials[a]
            .complexity()
            .cmp(&trials[b].complexity())
            .then(departure[a].total_cmp(&departure[b]))
            .then(trials[a].val().total_cmp(&trials[b].val()))
    })?;
    trials.into_iter().nth(i)
}

/// [J_a | J_b] side by side.
fn hcat(a: &DMatrix<f64>, b: &DMatrix<f64>) -> DMatrix<f64> {
    let mut m = DMatrix::zeros(a.nrows(), a.ncols() + b.ncols());
    m.columns_mut(0, a.ncols()).copy_from(a);
    m.columns_mut(a.ncols(), b.ncols()).copy_from(b);
    m
}

/// The start of a fit after adding a probed effect: the linearised step, within bounds
/// (a friction factor: the summed amplitude at the decay constant that carries most).
fn probe_start(p: &Probe, delta: &[f64]) -> Vec<f64> {
    if p.factor_absent {
        let (mut amp, mut best, mut m) = (0.0, 0.0, p.neutral[1]);
        for (dir, d) in p.directions.iter().zip(delta) {
            let a = d * p.specs[0].scale;
            amp += a;
            if a.abs() > best {
                best = a.abs();
                m = p.neutral[1] + dir[1];
            }
        }
        return vec![
            amp.clamp(0.0, p.specs[0].max),
            m.clamp(p.specs[1].min, p.specs[1].max),
        ];
    }
    p.neutral
        .iter()
        .zip(&p.specs)
        .zip(delta)
        .map(|((n, s), d)| {
            let step = d.clamp(-20.0, 20.0) * s.scale;
            (n + step).clamp(s.min, s.max)
        })
        .collect()
}

/// Progress on stderr when HILS_DIAG_DEBUG is set.
pub(super) fn debug(started: Instant, evaluations: usize, what: &str) {
    if std::env::var_os("HILS_DIAG_DEBUG").is_some() {
        eprintln!(
            "[{:7.2} s] {what}: {evaluations} replays so far",
            started.elapsed().as_secs_f64()
        );
    }
}

fn lag1(r: &[f64]) -> f64 {
    let n = r.len();
    if n < 3 {
        return 0.0;
    }
    let mean = r.iter().sum::<f64>() / n as f64;
    let var: f64 = r.iter().map(|x| (x - mean).powi(2)).sum();
    if var <= 0.0 {
        return 0.0;
    }
    r.windows(2)
        .map(|w| (w[0] - mean) * (w[1] - mean))
        .sum::<f64>()
        / var
}

/// The effects chosen by the search, and what could stand in for them.
pub(super) struct Search {
    pub(super) singles: Vec<SetFit>,
    pub(super) result: SetFit,
    pub(super) confounded: Vec<Vec<String>>,
}

/// Forward selection from `start` (a fitted single effect), then backward elimination.
/// Linearised probes (in parallel) of every applicable effect not in `current`, each
/// started from its own single fit where there is one.
fn probe_others(
    d: &Diagnoser,
    current: &SetFit,
    singles: &[SetFit],
    applicable: &[Effect],
) -> Vec<Probe> {
    let hint = |a: Effect| {
        singles
            .iter()
            .find(|s| s.effects == [a])
            .map(|s| s.x[0].as_slice())
    };
    applicable
        .par_iter()
        .filter(|a| !current.effects.iter().any(|c| c.name() == a.name()))
        .filter_map(|a| d.probe(current, *a, hint(*a)))
        .collect()
}

fn grow(
    d: &Diagnoser,
    base: &SetFit,
    start: SetFit,
    singles: &[SetFit],
    applicable: &[Effect],
    started: Instant,
) -> SetFit {
    // Forward selection.
    let mut current = start;
    // Below 0.7 x noise no addition can be significant (it must remove half a variance).
    while !current.effects.is_empty() && current.effects.len() < MAX_EFFECTS && current.val() >= 0.7
    {
        match forward_step(d, base, &current, singles, applicable) {
            Some(better) => current = better,
            None => break,
        }
    }
    debug(started, d.replays_done(), "forward selection");
    // Backward elimination: drop an effect the others make redundant (another optimum may
    // explain the data as well with fewer effects: parsimony).
    while current.effects.len() >= 2 {
        match backward_step(d, base, &current, singles) {
            Some(simpler) => current = simpler,
            None => break,
        }
    }
    debug(started, d.replays_done(), "backward elimination");
    current
}

/// One step of the forward selection: `current` with the best added effect, when that
/// is a significant and material improvement.
fn forward_step(
    d: &Diagnoser,
    base: &SetFit,
    current: &SetFit,
    singles: &[SetFit],
    applicable: &[Effect],
) -> Option<SetFit> {
    let j_s = current.jacobian.clone()?;
    let probes = probe_others(d, current, singles, applicable);
    let mut ranked: Vec<(f64, &Probe, Vec<f64>)> = probes
        .iter()
        .map(|p| {
            let (ssr, delta) =
                lsq::linear_ssr(&p.shifted(&current.residuals), &hcat(&j_s, &p.columns));
            let own = delta[j_s.ncols()..].to_vec();
            (ssr, p, own)
        })
        .collect();
    ranked.sort_by(|a, b| a.0.total_cmp(&b.0));
    if std::env::var_os("HILS_DIAG_DEBUG").is_some() {
        let ssr0: f64 = current.residuals.iter().map(|r| r * r).sum();
        for (ssr, p, _) in &ranked {
            eprintln!(
                "  probe {:?} at {:?}: ssr {ssr0:.0} -> {ssr:.0}",
                p.effect, current.effects
            );
        }
    }
    let best_pred = ranked.first().map(|r| r.0).unwrap_or(0.0);
    // Stop when even the best linearised prediction (with 20 % to spare) is not a
    // significant improvement on the fit data.
    let n_fit = current.residuals.len().max(1) as f64;
    let rms_now = (current.residuals.iter().map(|r| r * r).sum::<f64>() / n_fit).sqrt();
    if !significant(rms_now, 0.8 * (best_pred / n_fit).sqrt()) {
        return None;
    }
    let mut chosen: Vec<(Effect, Vec<f64>)> = ranked
        .iter()
        .take(CANDIDATES_PER_STEP)
        .filter(|r| r.0 <= 1.5 * best_pred + 1.0)
        .map(|(_, p, delta)| (p.effect, probe_start(p, delta)))
        .collect();
    add_friction_factors(d, current, singles, applicable, &mut chosen);
    let additions: Vec<SetFit> = fit_additions(d, current, &chosen)
        .into_iter()
        .filter(|s| !s.spoils(base))
        .collect();
    let best = pick(d, additions)?;
    (current.improved_by(&best) && d.material(&best, best.effects.len() - 1)).then_some(best)
}

/// The best probes are joined by the friction factors always: their exponential shapes
/// are the least linear, so a linearised probe underrates them (the paper's second factor
/// only shows once the first is in). A factor starts from its fit alone when that one is
/// material, else from the generic start.
fn add_friction_factors(
    d: &Diagnoser,
    current: &SetFit,
    singles: &[SetFit],
    applicable: &[Effect],
    chosen: &mut Vec<(Effect, Vec<f64>)>,
) {
    for factor in [Effect::FrictionSpeed, Effect::FrictionTemperature] {
        let candidate = applicable.contains(&factor)
            && !current.effects.iter().any(|c| c.name() == factor.name());
        if candidate && !chosen.iter().any(|(e, _)| *e == factor) {
            let single = singles
                .iter()
                .find(|s| s.effects == [factor])
                .filter(|s| d.material(s, 0));
            let start = match single {
                Some(s) => s.x[0].clone(),
                None => factor
                    .params(&d.baseline, d.rail())
                    .into_iter()
                    .map(|(_, p)| p.start)
                    .collect(),
            };
            chosen.push((factor, start));
        }
    }
}

/// `current` with each chosen effect added (from its start), fitted (in parallel).
fn fit_additions(d: &Diagnoser, current: &SetFit, chosen: &[(Effect, Vec<f64>)]) -> Vec<SetFit> {
    chosen
        .par_iter()
        .filter_map(|(effect, own_start)| {
            let mut effects = current.effects.clone();
            effects.push(*effect);
            let mut start = current.x.clone();
            start.push(own_start.clone());
            // Scan the added effect coarsely first (slides make the landscape rough:
            // LM may not leave its start).
            let ssr = d
                .residuals(&effects, &start)
                .map(|r| r.iter().map(|v| v * v).sum())
                .unwrap_or(f64::INFINITY);
            let (start, _) = d.coordinate_search_of(
                &effects,
                start,
                ssr,
                &COARSE_STEPS,
                1,
                Some(effects.len() - 1),
            );
            d.fit_set(&effects, Some(&start))
        })
        .collect()
}

/// One step of the backward elimination: the best set without one of `current`'s
/// effects, when it is not significantly worse.
fn backward_step(
    d: &Diagnoser,
    base: &SetFit,
    current: &SetFit,
    singles: &[SetFit],
) -> Option<SetFit> {
    let without: Vec<SetFit> = elimination_starts(current, singles)
        .into_par_iter()
        .filter_map(|(k, start)| {
            let mut effects = current.effects.clone();
            effects.remove(k);
            // One effect left, started from its own fit alone: that fit is the answer.
            if let Some(single) = singles
                .iter()
                .find(|s| s.effects == effects && s.x == start)
            {
                return Some(single.clone());
            }
            d.fit_set(&effects, Some(&start))
        })
        .collect();
    let best = without
        .into_iter()
        .filter(|s| !s.spoils(base))
        .min_by(|a, b| a.val().total_cmp(&b.val()))?;
    (!best.improved_by(current)).then_some(best)
}

/// Starts of the refits without effect k, for every k: the current values (the others
/// may have compensated for k) and each remaining effect's fit alone.
fn elimination_starts(current: &SetFit, singles: &[SetFit]) -> Vec<(usize, Vec<Vec<f64>>)> {
    let redundant: Vec<usize> = (0..current.effects.len()).collect();
    redundant
        .iter()
        .flat_map(|&k| {
            let mut from_current = current.x.clone();
            from_current.remove(k);
            let mut from_singles = Vec::new();
            for (i, e) in current.effects.iter().enumerate() {
                if i != k {
                    let single = singles
                        .iter()
                        .find(|s| s.effects == [*e])
                        .map(|s| s.x[0].clone());
                    from_singles.push(single.unwrap_or_else(|| current.x[i].clone()));
                }
            }
            if from_singles == from_current {
                vec![(k, from_current)]
            } else {
                vec![(k, from_current), (k, from_singles)]
            }
        })
        .collect()
}

/// Look-alikes the linearised screen can miss (a swap whose linearisation fails, e.g. the
/// cause removed lets a wheel lock): for each cause of a set of two or more, the effects
/// whose fits alone explain the data about as well as that cause's fit alone (within
/// [`BEAM_TOLERANCE`]), at most [`LOOKALIKES_PER_CAUSE`], refitted in its place from their
/// fits alone and the other causes' values.
fn lookalike_swaps(
    d: &Diagnoser,
    current: &SetFit,
    singles: &[SetFit],
    already: &[(usize, Effect, SetFit)],
) -> Vec<(usize, Effect, SetFit)> {
    if current.effects.len() < 2 {
        return vec![];
    }
    let single_of = |e: Effect| singles.iter().find(|s| s.effects == [e]);
    let mut jobs: Vec<(usize, Effect, Vec<Vec<f64>>)> = Vec::new();
    for (k, e) in current.effects.iter().enumerate() {
        let Some(own) = single_of(*e) else { continue };
        let mut alts: Vec<&SetFit> = singles
            .iter()
            .filter(|s1| {
                let a = s1.effects[0];
                !current.effects.iter().any(|c| c.name() == a.name())
                    && !already.iter().any(|(kk, b, _)| *kk == k && *b == a)
                    && d.material(s1, 0)
                    && {
                        let replay::ComparedRms {
                            reference: now,
                            candidate: alt,
                        } = replay::compare(&own.validation, &s1.validation);
                        alt <= BEAM_TOLERANCE * now
                    }
            })
            .collect();
        alts.sort_by(|a, b| a.val().total_cmp(&b.val()));
        for s1 in alts.into_iter().take(LOOKALIKES_PER_CAUSE) {
            let mut start = current.x.clone();
            start.remove(k);
            start.push(s1.x[0].clone());
            jobs.push((k, s1.effects[0], start));
        }
    }
    jobs.into_par_iter()
        .filter_map(|(k, a, start)| {
            let mut effects = current.effects.clone();
            effects.remove(k);
            effects.push(a);
            d.fit_set_with(&effects, Some(&start), FIT_PATIENCE / 2, FIT_TOLERANCE)
                .map(|f| (k, a, f))
        })
        .collect()
}

/// Look-alike swaps refitted per cause (see [`lookalike_swaps`]).
pub const LOOKALIKES_PER_CAUSE: usize = 2;

/// Links of the signal chain (`links::localise`) that the model of `set` leaves
/// unexplained on validation data (None: the set cannot replay the runs).
fn unexplained_links(d: &Diagnoser, set: &SetFit) -> Option<usize> {
    let reps = d.replays(&d.models(&set.effects, &set.x))?;
    let checks = links::localise(&d.runs, &reps, &reps);
    Some(checks.iter().filter(|c| !c.explained).count())
}

/// Among look-alikes (the result and its confirmed swaps whose effect sits in one of the
/// `confounded` groups), the one that leaves the fewest links of the signal chain
/// unexplained: look-alikes explain the fitted channels equally, but a logged channel the
/// fit does not use (disc temperature: a heavier vehicle heats the discs more than a lower
/// friction level does) may contradict one of them. Ties keep the result; among
/// alternatives as good as each other, the lower validation error.
fn choose_by_links(
    d: &Diagnoser,
    current: SetFit,
    confirmed: &[(usize, Effect, SetFit)],
    confounded: &[Vec<String>],
) -> SetFit {
    if confounded.is_empty() {
        return current;
    }
    let in_group = |k: usize, a: Effect| {
        let own = current.effects[k].name();
        confounded
            .iter()
            .any(|g| g.iter().any(|n| n == own) && g.iter().any(|n| n == a.name()))
    };
    let alts: Vec<&SetFit> = confirmed
        .iter()
        .filter(|(k, a, _)| in_group(*k, *a))
        .map(|(_, _, f)| f)
        .collect();
    let Some(now) = unexplained_links(d, &current) else {
        return current;
    };
    if now == 0 || alts.is_empty() {
        return current;
    }
    let counted: Vec<(usize, &SetFit)> = alts
        .par_iter()
        .filter_map(|f| unexplained_links(d, f).map(|n| (n, *f)))
        .collect();
    let best = counted
        .into_iter()
        .filter(|(n, _)| *n < now)
        .min_by(|a, b| a.0.cmp(&b.0).then(a.1.val().total_cmp(&b.1.val())));
    match best {
        Some((_, f)) => f.clone(),
        None => current,
    }
}

/// Forward selection with linearised candidate ranking, backward elimination, and the
/// confounding check, all at the fit step.
///
/// `unlisted` are effects outside the spec's list that the data show (a wheelset whose pad
/// friction differs from the others'): fitted like the others so that no listed effect is
/// bent to them, never named as causes. A set that makes a link worse than the baseline
/// beyond the noise is never kept ([`SetFit::spoils`]).
pub(super) fn search(
    d: &Diagnoser,
    base: &SetFit,
    unlisted: &[Effect],
    started: Instant,
) -> Search {
    let applicable: Vec<Effect> = effects::ALL
        .iter()
        .copied()
        .filter(|e| e.applicable(&d.runs) && d.runs.iter().any(|r| effects::shows(*e, r)))
        .chain(unlisted.iter().copied())
        .collect();
    let singles: Vec<SetFit> = applicable
        .par_iter()
        .filter_map(|e| d.fit_set(&[*e], None))
        .collect();
    debug(started, d.replays_done(), "single effects fitted");
    // Forward selection and backward elimination from the best first effects (a beam:
    // two effects alone can explain about as much, and only one of them may lead to the
    // right combination); the best final set wins, the simplest among equals.
    let finals: Vec<SetFit> = first_effects(d, base, &singles)
        .into_par_iter()
        .map(|f| grow(d, base, f, &singles, &applicable, started))
        .collect();
    let mut current = pick(d, finals).unwrap_or_else(|| base.clone());
    // Confounded: could another effect stand in for a cause? Screen each swap with the
    // linearised fit, confirm the promising ones with a real fit on validation data.
    let mut confounded = Vec::new();
    if let (false, Some(j_s)) = (current.effects.is_empty(), current.jacobian.clone()) {
        let probes = probe_others(d, &current, &singles, &applicable);
        let swaps = screen_swaps(d, &current, &j_s, &probes);
        let confirmed = confirm_swaps(d, &current, &singles, &swaps);
        confounded = confounded_groups(base, &current, &confirmed);
        current = choose_by_links(d, current, &confirmed, &confounded);
    }
    debug(started, d.replays_done(), "confounded alternatives");
    // Polish: the fit that produced the result may have been cut by its budget on the way
    // (a flat valley of compensating parameters); continue it.
    if !current.effects.is_empty() {
        if let Some(p) = d.fit_set(&current.effects, Some(&current.x)) {
            if p.fit.rms() <= current.fit.rms() && !p.spoils(base) {
                current = p;
            }
        }
        debug(started, d.replays_done(), "polished");
    }
    Search {
        singles,
        result: current,
        confounded,
    }
}

/// The start paths of the beam: the best material single effect that improves on the
/// baseline, and a second one only when its effect alone explains nearly as much.
fn first_effects(d: &Diagnoser, base: &SetFit, singles: &[SetFit]) -> Vec<SetFit> {
    let mut firsts: Vec<SetFit> = Vec::new();
    let material: Vec<SetFit> = singles
        .iter()
        .filter(|s| d.material(s, 0) && !s.spoils(base))
        .cloned()
        .collect();
    if let Some(best) = pick(d, material.clone()) {
        if base.improved_by(&best) {
            firsts.push(best);
        }
    }
    if let Some(first) = firsts.first().cloned() {
        let mut rest: Vec<&SetFit> = material
            .iter()
            .filter(|s| s.effects != first.effects)
            .collect();
        rest.sort_by(|a, b| a.val().total_cmp(&b.val()));
        // A second path only when its first effect explains nearly as much.
        firsts.extend(
            rest.into_iter()
                .take(BEAM - 1)
                .filter(|s| base.improved_by(s) && s.val() <= BEAM_TOLERANCE * first.val())
                .cloned(),
        );
    }
    firsts
}

/// A swap worth a real fit: cause k replaced by a probed effect (its linearised start),
/// the other causes' parameters.
type Swap<'a> = (usize, &'a Probe, Vec<f64>, Vec<Vec<f64>>);

/// Swaps of each cause for each probed effect that the linearised fit puts near the
/// result.
fn screen_swaps<'a>(
    d: &Diagnoser,
    current: &SetFit,
    j_s: &DMatrix<f64>,
    probes: &'a [Probe],
) -> Vec<Swap<'a>> {
    let ssr_s: f64 = current.residuals.iter().map(|r| r * r).sum();
    let mut swaps: Vec<Swap> = Vec::new();
    for k in 0..current.effects.len() {
        let mut effects = current.effects.clone();
        let mut xs = current.x.clone();
        effects.remove(k);
        xs.remove(k);
        let Some(r_without) = d.residuals(&effects, &xs) else {
            continue;
        };
        let keep: Vec<usize> = (0..j_s.ncols())
            .filter(|c| !current.columns_of(k).contains(c))
            .collect();
        let j_rest = j_s.select_columns(&keep);
        for p in probes {
            let (ssr, delta) = lsq::linear_ssr(&p.shifted(&r_without), &hcat(&j_rest, &p.columns));
            // Worth a real fit when the linearised swap comes near the result, or
            // explains the data to within the noise (then a small relative gap means
            // nothing).
            let screen = CONFOUND_TOLERANCE * CONFOUND_TOLERANCE * 1.5;
            let n_fit = r_without.len().max(1) as f64;
            if ssr <= (screen * ssr_s).max(n_fit) {
                let own = delta[j_rest.ncols()..].to_vec();
                swaps.push((k, p, own, xs.clone()));
            }
        }
    }
    swaps
}

/// The swaps fitted (in parallel), the look-alikes the screen misses, and for a single
/// cause every other material effect alone.
fn confirm_swaps(
    d: &Diagnoser,
    current: &SetFit,
    singles: &[SetFit],
    swaps: &[Swap],
) -> Vec<(usize, Effect, SetFit)> {
    let mut confirmed: Vec<(usize, Effect, SetFit)> = swaps
        .par_iter()
        .filter_map(|(k, p, delta, xs)| {
            let mut effects = current.effects.clone();
            effects.remove(*k);
            effects.push(p.effect);
            let mut start = xs.clone();
            start.push(probe_start(p, delta));
            d.fit_set(&effects, Some(&start)).map(|f| (*k, p.effect, f))
        })
        .collect();
    confirmed.extend(lookalike_swaps(d, current, singles, &confirmed));
    // A single cause: the other effects' fits alone are the swaps (no refit needed).
    if current.effects.len() == 1 {
        for s1 in singles {
            let a = s1.effects[0];
            if a.name() != current.effects[0].name()
                && d.material(s1, 0)
                && !confirmed.iter().any(|(_, b, _)| *b == a)
            {
                confirmed.push((0, a, s1.clone()));
            }
        }
    }
    confirmed
}

/// Each cause with the effects that explain the validation data as well in its place.
/// Alternatives that make a link worse than the baseline are told apart by that link; an
/// effect outside the spec's list is never listed.
fn confounded_groups(
    base: &SetFit,
    current: &SetFit,
    confirmed: &[(usize, Effect, SetFit)],
) -> Vec<Vec<String>> {
    let mut confounded = Vec::new();
    for (k, e) in current.effects.iter().enumerate() {
        if !e.is_listed() {
            continue;
        }
        let mut group = vec![e.name().to_string()];
        for (kk, a, f) in confirmed {
            let replay::ComparedRms {
                reference: now,
                candidate: alt,
            } = replay::compare(&current.validation, &f.validation);
            // Confounded: within the tolerance, or not significantly worse (below the
            // noise, relative differences mean nothing).
            if *kk == k
                && a.is_listed()
                && !f.spoils(base)
                && (alt <= CONFOUND_TOLERANCE * now || !significant(alt, now))
                && !group.contains(&a.name().to_string())
            {
                group.push(a.name().to_string());
            }
        }
        if group.len() > 1 {
            confounded.push(group);
        }
    }
    confounded
}
