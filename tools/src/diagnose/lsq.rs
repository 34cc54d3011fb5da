//! Nonlinear least squares (Levenberg-Marquardt from the `levenberg-marquardt` crate) with
//! a finite-difference Jacobian evaluated in parallel (rayon), bounds by clamping, and
//! 95 % confidence intervals from the Jacobian at the solution.
//!
//! The model is any function from parameters to a residual vector (already weighted).
//! Parameters are mapped internally so that one finite-difference step and the LM trust
//! region suit every parameter, and bounds hold without sticking: x = lo + (hi - lo)
//! (sin(theta) + 1) / 2 with theta = theta0 + kappa z (the MINUIT transform), kappa chosen
//! so that dx/dz = scale at the start. A parameter pushed to a bound can come back.

use levenberg_marquardt::{LeastSquaresProblem, LevenbergMarquardt};
use nalgebra::storage::Owned;
use nalgebra::{DMatrix, DVector, Dyn};
use rayon::prelude::*;

/// A parameter to fit: start value, typical scale (the size of a meaningful change) and
/// bounds.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ParamSpec {
    pub start: f64,
    pub scale: f64,
    pub min: f64,
    pub max: f64,
}

impl ParamSpec {
    pub fn new(start: f64, scale: f64, min: f64, max: f64) -> Self {
        Self {
            start,
            scale,
            min,
            max,
        }
    }
}

/// The result of a fit.
#[derive(Clone, Debug)]
pub struct Fit {
    /// Fitted parameters (within bounds).
    pub x: Vec<f64>,
    /// Residuals at the solution.
    pub residuals: Vec<f64>,
    /// Sum of squared residuals.
    pub ssr: f64,
    /// Half-widths of the 95 % confidence intervals (NaN where not identifiable).
    pub ci95_half: Vec<f64>,
    /// Correlation matrix of the estimates (row-major, n x n).
    pub correlation: Vec<f64>,
    /// Residual evaluations used.
    pub evaluations: usize,
    /// The solver's termination reason, for messages.
    pub termination: String,
    /// Jacobian at the solution with respect to the scaled parameters z (x = x0 + z scale).
    pub jacobian: Option<DMatrix<f64>>,
}

/// The bounded map from the internal variable z to a parameter.
#[derive(Clone, Copy, Debug)]
struct Transform {
    lo: f64,
    hi: f64,
    theta0: f64,
    kappa: f64,
}

impl Transform {
    fn of(s: &ParamSpec) -> Self {
        let (lo, hi) = (s.min, s.max);
        let half = 0.5 * (hi - lo);
        let u = ((s.start - lo) / half - 1.0).clamp(-0.998, 0.998);
        let theta0 = u.asin();
        let kappa = (s.scale / (half * theta0.cos())).min(1.0);
        Self {
            lo,
            hi,
            theta0,
            kappa,
        }
    }
    fn x(&self, z: f64) -> f64 {
        let x = self.lo + 0.5 * (self.hi - self.lo) * ((self.theta0 + self.kappa * z).sin() + 1.0);
        x.clamp(self.lo, self.hi)
    }
    /// dx/dz.
    fn slope(&self, z: f64) -> f64 {
        0.5 * (self.hi - self.lo) * (self.theta0 + self.kappa * z).cos() * self.kappa
    }
}

type Model<'a> = dyn Fn(&[f64]) -> Option<Vec<f64>> + Sync + 'a;

struct Problem<'a> {
    model: &'a Model<'a>,
    specs: &'a [ParamSpec],
    z: DVector<f64>,
    residuals: Option<Vec<f64>>,
    fd_step: f64,
    evaluations: std::sync::atomic::AtomicUsize,
    /// Residual count (from the start point): a failed evaluation gives a penalty vector.
    m: usize,
    /// Hard cap on model evaluations (Jacobian columns included): beyond it the solver
    /// is stopped and the best point seen is the result.
    cap: usize,
    /// Best point seen (sum of squares, z, residuals).
    best: std::sync::Mutex<Option<(f64, DVector<f64>, Vec<f64>)>>,
}

/// Residual of a failed model evaluation (refused parameters): far worse than any fit.
const PENALTY: f64 = 1.0e4;

impl Problem<'_> {
    fn to_x(&self, z: &DVector<f64>) -> Vec<f64> {
        self.specs
            .iter()
            .zip(z.iter())
            .map(|(s, zi)| Transform::of(s).x(*zi))
            .collect()
    }

    fn eval(&self, z: &DVector<f64>) -> Option<Vec<f64>> {
        if self
            .evaluations
            .fetch_add(1, std::sync::atomic::Ordering::Relaxed)
            >= self.cap
        {
            return None;
        }
        let r = (self.model)(&self.to_x(z))
            .filter(|r| r.iter().all(|v| v.is_finite()) && (self.m == 0 || r.len() == self.m));
        let r = match r {
            Some(r) => r,
            None if self.m > 0 => vec![PENALTY; self.m],
            None => return None,
        };
        let ssr: f64 = r.iter().map(|x| x * x).sum();
        let mut best = self.best.lock().unwrap_or_else(|e| e.into_inner());
        if best.as_ref().is_none_or(|b| ssr < b.0) {
            *best = Some((ssr, z.clone(), r.clone()));
        }
        Some(r)
    }
}

impl LeastSquaresProblem<f64, Dyn, Dyn> for Problem<'_> {
    type ResidualStorage = Owned<f64, Dyn>;
    type JacobianStorage = Owned<f64, Dyn, Dyn>;
    type ParameterStorage = Owned<f64, Dyn>;

    fn set_params(&mut self, z: &DVector<f64>) {
        self.z.copy_from(z);
        self.residuals = self.eval(z);
    }

    fn params(&self) -> DVector<f64> {
        self.z.clone()
    }

    fn residuals(&self) -> Option<DVector<f64>> {
        self.residuals
            .as_ref()
            .map(|r| DVector::from_column_slice(r))
    }

    fn jacobian(&self) -> Option<DMatrix<f64>> {
        let r0 = self.residuals.as_ref()?;
        let n = self.z.len();
        let m = r0.len();
        let cols: Vec<Option<Vec<f64>>> = (0..n)
            .into_par_iter()
            .map(|i| {
                let h = self.fd_step;
                let mut z = self.z.clone();
                z[i] += h;
                let r = self.eval(&z)?;
                Some(r.iter().zip(r0).map(|(a, b)| (a - b) / h).collect())
            })
            .collect();
        let mut j = DMatrix::zeros(m, n);
        for (i, c) in cols.into_iter().enumerate() {
            let c = c?;
            j.set_column(i, &DVector::from_vec(c));
        }
        Some(j)
    }
}

/// Two-sided 97.5 % quantile of Student's t with `dof` degrees of freedom
/// (Cornish-Fisher expansion; exact to 1e-3 for dof >= 3).
pub fn t975(dof: f64) -> f64 {
    let z = 1.959_963_984_540_054_f64;
    if !(dof > 0.0) {
        return f64::NAN;
    }
    let g1 = (z.powi(3) + z) / 4.0;
    let g2 = (5.0 * z.powi(5) + 16.0 * z.powi(3) + 3.0 * z) / 96.0;
    let g3 = (3.0 * z.powi(7) + 19.0 * z.powi(5) + 17.0 * z.powi(3) - 15.0 * z) / 384.0;
    z + g1 / dof + g2 / dof.powi(2) + g3 / dof.powi(3)
}

/// Fits `model` (parameters -> weighted residuals) from the specs' start values.
/// `fd_step` is the finite-difference step as a share of each parameter's scale;
/// `max_evaluations` bounds the work (model evaluations, Jacobian columns included; the
/// best point seen is the result when it runs out), `tol` is the relative tolerance on the sum of
/// squares and on the (scaled) parameters. `dof_share` (0, 1] is the share of residuals that
/// are independent (for autocorrelated residuals), used for the confidence intervals.
pub fn fit(
    model: &Model<'_>,
    specs: &[ParamSpec],
    fd_step: f64,
    max_evaluations: usize,
    tol: f64,
    dof_share: f64,
) -> Option<Fit> {
    let n = specs.len();
    let mut problem = Problem {
        model,
        specs,
        z: DVector::zeros(n),
        residuals: None,
        fd_step,
        evaluations: std::sync::atomic::AtomicUsize::new(0),
        m: 0,
        cap: max_evaluations.max(n + 2),
        best: std::sync::Mutex::new(None),
    };
    problem.set_params(&DVector::zeros(n));
    problem.m = problem.residuals.as_ref()?.len();
    let patience = max_evaluations.max(2);
    let (problem, report) = LevenbergMarquardt::new()
        .with_patience(patience)
        .with_ftol(tol)
        .with_xtol(tol)
        .with_stepbound(10.0)
        .minimize(problem);
    // The best point evaluated (LM returns its last accepted point; they agree unless a
    // Jacobian column happened to improve on it).
    let (_, best_z, residuals) = problem
        .best
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .clone()?;
    let x = problem.to_x(&best_z);
    let ssr: f64 = residuals.iter().map(|r| r * r).sum();
    let mut at = Problem {
        model,
        specs,
        z: best_z.clone(),
        residuals: Some(residuals.clone()),
        fd_step,
        evaluations: std::sync::atomic::AtomicUsize::new(0),
        m: residuals.len(),
        cap: usize::MAX,
        best: std::sync::Mutex::new(None),
    };
    let jacobian = at.jacobian();
    let (ci95_half, correlation) = match &jacobian {
        Some(j) => {
            let slopes: Vec<f64> = specs
                .iter()
                .zip(best_z.iter())
                .map(|(s, z)| Transform::of(s).slope(*z))
                .collect();
            confidence(j, &slopes, ssr, residuals.len(), dof_share)
        }
        None => (vec![f64::NAN; n], vec![f64::NAN; n * n]),
    };
    at.z = best_z;
    let evaluations = problem
        .evaluations
        .load(std::sync::atomic::Ordering::Relaxed)
        + at.evaluations.load(std::sync::atomic::Ordering::Relaxed);
    Some(Fit {
        x,
        residuals,
        ssr,
        ci95_half,
        correlation,
        evaluations,
        termination: format!("{:?}", report.termination),
        jacobian,
    })
}

/// 95 % half-widths and correlations from J (in the internal variables, dx/dz = `slopes`)
/// at the solution:
/// cov = s^2 (J^T J)^-1, s^2 = SSR / (m - n), with the degrees of freedom reduced to the
/// independent share of the residuals.
fn confidence(
    j: &DMatrix<f64>,
    slopes: &[f64],
    ssr: f64,
    m: usize,
    dof_share: f64,
) -> (Vec<f64>, Vec<f64>) {
    let n = slopes.len();
    let jtj = j.transpose() * j;
    let m_eff = (m as f64 * dof_share.clamp(1e-6, 1.0)).max(n as f64 + 1.0);
    let dof = m_eff - n as f64;
    // s^2 from all residuals, then inflated by m / m_eff (fewer independent samples).
    let s2 = ssr / (m as f64 - n as f64).max(1.0) * (m as f64 / m_eff);
    let Some(inv) = jtj.clone().try_inverse() else {
        return (vec![f64::NAN; n], vec![f64::NAN; n * n]);
    };
    let t = t975(dof);
    let mut half = vec![f64::NAN; n];
    let mut corr = vec![f64::NAN; n * n];
    for a in 0..n {
        let var = inv[(a, a)] * s2;
        if var >= 0.0 {
            half[a] = t * var.sqrt() * slopes[a].abs();
        }
        for b in 0..n {
            let d = (inv[(a, a)] * inv[(b, b)]).sqrt();
            corr[a * n + b] = if d > 0.0 { inv[(a, b)] / d } else { f64::NAN };
        }
    }
    (half, corr)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn t_quantile_matches_tables() {
        assert!((t975(10.0) - 2.228).abs() < 2e-3);
        assert!((t975(30.0) - 2.042).abs() < 1e-3);
        assert!((t975(1e6) - 1.960).abs() < 1e-3);
    }

    #[test]
    fn fits_an_exponential_decay_with_honest_intervals() {
        // y = a exp(-b t) + noise (deterministic pseudo-noise with sigma 0.01).
        let (a, b) = (2.0, 0.7);
        let t: Vec<f64> = (0..200).map(|i| i as f64 * 0.05).collect();
        let noise: Vec<f64> = (0..200)
            .map(|i| 0.01 * ((i as f64 * 12.9898).sin() * 43758.5453).fract() * 3.4)
            .collect();
        let y: Vec<f64> = t
            .iter()
            .zip(&noise)
            .map(|(t, e)| a * (-b * t).exp() + e)
            .collect();
        let model = |x: &[f64]| -> Option<Vec<f64>> {
            Some(
                t.iter()
                    .zip(&y)
                    .map(|(t, y)| x[0] * (-x[1] * t).exp() - y)
                    .collect(),
            )
        };
        let specs = [
            ParamSpec::new(1.0, 1.0, 0.0, 10.0),
            ParamSpec::new(0.2, 0.5, 0.0, 10.0),
        ];
        let f = fit(&model, &specs, 1e-6, 400, 1e-9, 1.0).unwrap();
        assert!((f.x[0] - a).abs() < 0.02, "{:?}", f.x);
        assert!((f.x[1] - b).abs() < 0.02, "{:?}", f.x);
        assert!(
            f.ci95_half.iter().all(|h| *h > 0.0 && *h < 0.05),
            "{:?}",
            f.ci95_half
        );
        assert!((f.x[0] - a).abs() < 2.0 * f.ci95_half[0]);
    }
}

/// Linearised least squares: the smallest sum of squares of r + J d over d, and d
/// (SVD with small singular values cut, so collinear columns do not blow up).
pub fn linear_ssr(r: &[f64], j: &DMatrix<f64>) -> (f64, Vec<f64>) {
    let rv = DVector::from_column_slice(r);
    if j.ncols() == 0 {
        return (rv.norm_squared(), vec![]);
    }
    let svd = j.clone().svd(true, true);
    let max_sv = svd.singular_values.iter().cloned().fold(0.0f64, f64::max);
    let eps = (max_sv * 1e-8).max(1e-300);
    match svd.solve(&(-&rv), eps) {
        Ok(d) => {
            let res = &rv + j * &d;
            (res.norm_squared(), d.iter().copied().collect())
        }
        Err(_) => (rv.norm_squared(), vec![0.0; j.ncols()]),
    }
}
