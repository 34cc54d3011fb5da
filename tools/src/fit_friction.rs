//! `hils fit-friction`: fits paper Eq (2) to brake-dynamometer friction tests.
//!
//! mu_d = c mu_d0 (n_v e^(-m_v v_d) + 1)(n_T e^(-m_T T_d) + 1)               (Eq 2)
//!
//! with the correction constant c fixed (the parameter file's `friction.correction_c`,
//! 0.98 in the reference file, as in the paper) and the five parameters mu_d0, n_v, m_v,
//! n_T, m_T fitted by nonlinear least squares (Levenberg-Marquardt, [`crate::diagnose::lsq`])
//! from several starts. The model evaluated is the plant's own
//! [`hils_plant::friction::DiscPadFriction`] (one copy of Eq 2).
//!
//! Identifiability: mu_d0 is the friction at high speed and temperature. The product
//! c mu_d0 (1 + n_v e^(-m_v v))(1 + n_T e^(-m_T T)) separates mu_d0 from the factors only
//! when the points reach speeds and temperatures where the exponentials have decayed; when
//! they do not, the parameters are strongly correlated, their intervals are wide, and the
//! command says so (it warns on |correlation| > 0.95).
//!
//! # Large files
//!
//! The files are read in chunks and their points gathered in bounded memory
//! ([`gather`]): up to 200,000 points are fitted as they are; beyond, as the count-weighted
//! means of cells of a fine grid over (speed, temperature), with the intervals and the rms
//! from every point. 50 M points are read and fitted in a few tens of MB (docs/diagnosis.md,
//! "Large files"); progress bars show the reading (bytes) and the fit (starts).

pub mod gather;

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use clap::Args;
use hils_plant::FrictionModel;
use hils_plant::friction::DiscPadFriction;
use hils_plant::params::FrictionParams;
use serde::Serialize;

use crate::diagnose::lsq::{self, ParamSpec};
use indicatif::ProgressBar;

use crate::figures::{list_text, round_dp, round_sig};
use crate::measured::{ChannelMap, FrictionTest, stream_friction_test_with};
use crate::params_file::params_or_default;
use crate::plots::{Chart, Series, Style};

/// Arguments of `hils fit-friction`.
#[derive(Args, Debug, Clone)]
pub struct FitFrictionArgs {
    /// `--json`: the fitted parameters; `--report`: plots like the paper's Fig 2 and report.md.
    #[command(flatten)]
    pub out: crate::outputs::Outputs,
    /// Parameter file whose `friction.correction_c` is used (default: the reference values).
    #[arg(long)]
    pub params: Option<PathBuf>,
    /// Channel map (TOML): which of the files' channels or columns is which spec column,
    /// their units, and metadata (docs/mdf4.md). Without it the spec's names are expected.
    #[arg(long, value_name = "FILE")]
    pub map: Option<PathBuf>,
    /// Friction-test files (spec measured-data.md, section 2): CSV or MDF4 (.mf4).
    #[arg(required = true)]
    pub files: Vec<PathBuf>,
}

/// Names of the fitted parameters, in order.
pub const NAMES: [&str; 5] = ["mu_d0", "n_v", "m_v", "n_t", "m_t"];

/// A fit of Eq (2).
#[derive(Clone, Debug, Serialize)]
pub struct FrictionFit {
    pub mu_d0: f64,
    pub n_v: f64,
    pub m_v: f64,
    pub n_t: f64,
    pub m_t: f64,
    /// [low, high] per parameter.
    pub ci95: std::collections::BTreeMap<String, [f64; 2]>,
    /// Root mean square of mu - fitted mu.
    pub rms: f64,
    pub correction_c: f64,
    pub points: usize,
    pub skipped_rows: usize,
    pub files: Vec<String>,
    /// Warnings on identifiability and data coverage.
    pub warnings: Vec<String>,
    /// Parameter pairs with |correlation| > 0.95.
    pub correlated: Vec<(String, String, f64)>,
    /// When the points were fitted as cells (more than [`gather::EXACT_POINTS`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub cells: Option<CellsUsed>,
    pub wall_s: f64,
}

/// The cells a large set of points was fitted as ([`gather`]).
#[derive(Clone, Debug, Serialize)]
pub struct CellsUsed {
    pub count: usize,
    pub width_v_mps: f64,
    pub width_t_c: f64,
}

impl FrictionFit {
    /// The fit with every figure rounded to what it means (JSON and terminal): each parameter
    /// and its interval to [`FrictionFit::decimals`], rms to 3 significant digits,
    /// correlations to 1e-3, times to 1 ms.
    pub fn rounded(&self) -> FrictionFit {
        let names_values = NAMES
            .iter()
            .zip([self.mu_d0, self.n_v, self.m_v, self.n_t, self.m_t]);
        let x: Vec<f64> = names_values
            .map(|(name, x)| round_dp(x, self.decimals(name, x)))
            .collect();
        FrictionFit {
            mu_d0: x[0],
            n_v: x[1],
            m_v: x[2],
            n_t: x[3],
            m_t: x[4],
            ci95: self
                .ci95
                .iter()
                .map(|(k, [lo, hi])| {
                    let d = self.decimals(k, 0.5 * (lo + hi));
                    (k.clone(), [round_dp(*lo, d), round_dp(*hi, d)])
                })
                .collect(),
            rms: round_sig(self.rms, 3),
            correlated: self
                .correlated
                .iter()
                .map(|(a, b, r)| (a.clone(), b.clone(), round_dp(*r, 3)))
                .collect(),
            cells: self.cells.as_ref().map(|c| CellsUsed {
                count: c.count,
                width_v_mps: round_sig(c.width_v_mps, 3),
                width_t_c: round_sig(c.width_t_c, 3),
            }),
            wall_s: round_dp(self.wall_s, 3),
            ..self.clone()
        }
    }
}

impl FrictionFit {
    /// Decimals of parameter `name` (value `x`) and its interval: 5 significant digits, or
    /// 2 of the interval's half-width when that is finer (50 M points pin mu_d0 to 3e-6).
    pub fn decimals(&self, name: &str, x: f64) -> u32 {
        let decimals_for = |y: f64, digits: i32| digits - 1 - y.abs().log10().floor() as i32;
        let sig5 = if x.is_finite() && x != 0.0 {
            decimals_for(x, 5)
        } else {
            5
        };
        let half = self
            .ci95
            .get(name)
            .map_or(f64::NAN, |[lo, hi]| 0.5 * (hi - lo));
        let of_interval = if half.is_finite() && half > 0.0 {
            decimals_for(half, 2)
        } else {
            0
        };
        sig5.max(of_interval).clamp(0, 12) as u32
    }

    /// The fit as friction parameters (variable model, c as fitted with).
    pub fn params(&self) -> FrictionParams {
        FrictionParams {
            model: FrictionModel::Variable,
            mu_d0: self.mu_d0,
            n_v: self.n_v,
            m_v: self.m_v,
            n_t: self.n_t,
            m_t: self.m_t,
            correction_c: self.correction_c,
            k_p: 0.0,
        }
    }
}

/// Eq (2) through the plant's implementation.
pub fn eq2(p: &FrictionParams, v_d: f64, t_d: f64) -> f64 {
    DiscPadFriction::<f64>::new(p).mu_d(v_d, t_d, 0.0)
}

fn with(x: &[f64], c: f64) -> FrictionParams {
    FrictionParams {
        model: FrictionModel::Variable,
        mu_d0: x[0],
        n_v: x[1],
        m_v: x[2],
        n_t: x[3],
        m_t: x[4],
        correction_c: c,
        k_p: 0.0,
    }
}

/// Fewest distinct friction speeds and disc temperatures that can determine Eq (2)'s
/// two factors (a level, an amplitude and a decay each).
pub const MIN_DISTINCT: usize = 3;

/// Degenerate data (too few distinct speeds or temperatures to determine Eq (2)) is an
/// error, not a fit with meaningless intervals.
fn check_spread(v: &[f64], t: &[f64]) -> Result<()> {
    for (what, x) in [("friction speeds", v), ("disc temperatures", t)] {
        let mut d: Vec<f64> = x.to_vec();
        d.sort_by(f64::total_cmp);
        d.dedup();
        if d.len() < MIN_DISTINCT {
            bail!(
                "degenerate data: {} distinct {what} ({}); Eq (2) needs at least {MIN_DISTINCT} \
                 to separate its level, amplitude and decay",
                d.len(),
                list_text(&d)
            );
        }
    }
    Ok(())
}

/// Largest condition number of the column-scaled Jacobian for which (J^T J)^-1 is
/// computed to a few digits in f64 (its condition is the square: 1e12 of 1e16).
const MAX_CONDITION: f64 = 1e6;

/// The 95 % half-widths and correlations of a fit, or NaN (undefined, with a warning)
/// when they mean nothing: a numerically singular Jacobian (its inverse gives
/// correlations outside [-1, 1]) or zero residuals (exact data: zero-width intervals).
fn covariance_or_undefined(fit: &lsq::Fit, warnings: &mut Vec<String>) -> (Vec<f64>, Vec<f64>) {
    let n = fit.x.len();
    let undefined = (vec![f64::NAN; n], vec![f64::NAN; n * n]);
    // Columns scaled to unit length: the condition of the parameters' correlation
    // structure, independent of their units.
    let condition = fit.jacobian.as_ref().map_or(f64::INFINITY, |j| {
        let mut j = j.clone();
        for mut c in j.column_iter_mut() {
            let norm = c.norm();
            if norm > 0.0 {
                c /= norm;
            }
        }
        let s = j.svd(false, false).singular_values;
        s.max() / s.min()
    });
    if !(condition <= MAX_CONDITION) {
        warnings.push(format!(
            "confidence intervals and correlations undefined: the information matrix is \
             numerically singular (condition {condition:.2e} > {MAX_CONDITION:.0e}); \
             the points do not determine all five parameters"
        ));
        return undefined;
    }
    if !(fit.ssr > 0.0) {
        warnings.push(
            "confidence intervals undefined: the residuals are zero (exact data)".to_string(),
        );
        return (vec![f64::NAN; n], fit.correlation.clone());
    }
    (fit.ci95_half.clone(), fit.correlation.clone())
}

/// Fits Eq (2) to points (v_d m/s, T_d degC, mu) with c fixed.
pub fn fit_points(v: &[f64], t: &[f64], mu: &[f64], c: f64) -> Result<FrictionFit> {
    let data = Data {
        v,
        t,
        mu,
        weight: None,
        points: mu.len(),
        ss_within: 0.0,
    };
    fit_data(&data, c, &ProgressBar::hidden())
}

/// Fits Eq (2) to the cells of a large set of points ([`gather`]): each cell's mean point
/// weighted by its count.
pub fn fit_cells(cells: &gather::Cells, c: f64, bar: &ProgressBar) -> Result<FrictionFit> {
    let (v, t, mu, n, ss_within) = cells.means();
    let weight: Vec<f64> = n.iter().map(|n| n.sqrt()).collect();
    let data = Data {
        v: &v,
        t: &t,
        mu: &mu,
        weight: Some(&weight),
        points: n.iter().sum::<f64>() as usize,
        ss_within,
    };
    let mut fit = fit_data(&data, c, bar)?;
    fit.cells = Some(CellsUsed {
        count: v.len(),
        width_v_mps: cells.width.0,
        width_t_c: cells.width.1,
    });
    Ok(fit)
}

/// What a fit takes: points (or cell means with the square root of their counts as
/// weights), the number of points and the sum of squares within the cells.
struct Data<'a> {
    v: &'a [f64],
    t: &'a [f64],
    mu: &'a [f64],
    weight: Option<&'a [f64]>,
    points: usize,
    ss_within: f64,
}

/// Fits Eq (2) with c fixed (the best of several starts, `bar` counting them).
fn fit_data(d: &Data, c: f64, bar: &ProgressBar) -> Result<FrictionFit> {
    let started = std::time::Instant::now();
    let (v, t, mu) = (d.v, d.t, d.mu);
    let n = mu.len();
    if d.points < 6 {
        bail!(
            "{} friction points: at least 6 are needed to fit 5 parameters",
            d.points
        );
    }
    check_spread(v, t)?;
    let w = |i: usize| d.weight.map_or(1.0, |w| w[i]);
    let model = |x: &[f64]| -> Option<Vec<f64>> {
        let f = DiscPadFriction::<f64>::new(&with(x, c));
        Some(
            (0..n)
                .map(|i| w(i) * (f.mu_d(v[i], t[i], 0.0) - mu[i]))
                .collect(),
        )
    };
    let mu_min = mu.iter().cloned().fold(f64::INFINITY, f64::min);
    let v_max = v.iter().cloned().fold(0.0f64, f64::max).max(1.0);
    let t_max = t.iter().cloned().fold(0.0f64, f64::max).max(1.0);
    let best = best_of_starts(&model, mu_min / c, v_max, t_max, bar);
    let Some(best) = best else {
        bail!("the fit failed from every start")
    };
    let x = &best.x;
    let mut warnings = Vec::new();
    let (mut half, correlation) = covariance_or_undefined(&best, &mut warnings);
    // Cells: the residual variance is every point's (within-cell sums of squares added),
    // over the points' degrees of freedom, not the cells'.
    let ssr_all = best.ssr + d.ss_within;
    if d.weight.is_some() && best.ssr > 0.0 && n > 5 {
        let s2_cells = best.ssr / (n - 5) as f64;
        let s2_all = ssr_all / (d.points - 5) as f64;
        let scale = (s2_all / s2_cells).sqrt() * lsq::t975((d.points - 5) as f64)
            / lsq::t975((n - 5) as f64);
        half.iter_mut().for_each(|h| *h *= scale);
    }
    let mut ci95 = std::collections::BTreeMap::new();
    for (i, name) in NAMES.iter().enumerate() {
        ci95.insert(name.to_string(), [x[i] - half[i], x[i] + half[i]]);
    }
    let correlated = identifiability(x, &half, &correlation, v_max, t_max, &mut warnings);
    Ok(FrictionFit {
        mu_d0: x[0],
        n_v: x[1],
        m_v: x[2],
        n_t: x[3],
        m_t: x[4],
        ci95,
        rms: (ssr_all / d.points as f64).sqrt(),
        correction_c: c,
        points: d.points,
        skipped_rows: 0,
        files: Vec::new(),
        warnings,
        correlated,
        cells: None,
        wall_s: started.elapsed().as_secs_f64(),
    })
}

/// The best Levenberg-Marquardt fit of Eq (2) from starts whose decay constants spread over
/// the data's ranges (1/m between a tenth and twice the range; `v_max` m/s, `t_max` degC).
fn best_of_starts(
    model: &(dyn Fn(&[f64]) -> Option<Vec<f64>> + Sync),
    mu_d0_start: f64,
    v_max: f64,
    t_max: f64,
    bar: &ProgressBar,
) -> Option<lsq::Fit> {
    bar.set_length(9);
    let mut best: Option<lsq::Fit> = None;
    for kv in [0.3, 1.0, 3.0] {
        for kt in [0.3, 1.0, 3.0] {
            let m_v = kv / v_max * 3.0;
            let m_t = kt / t_max * 3.0;
            let specs = [
                ParamSpec::new(mu_d0_start, 0.05, 1e-3, 2.0),
                ParamSpec::new(0.1, 0.1, 0.0, 10.0),
                ParamSpec::new(m_v, m_v, 0.0, 10.0),
                ParamSpec::new(0.1, 0.1, 0.0, 10.0),
                ParamSpec::new(m_t, m_t, 0.0, 10.0),
            ];
            if let Some(f) = lsq::fit(model, &specs, 1e-6, 600, 1e-10, 1.0) {
                if best.as_ref().is_none_or(|b| f.ssr < b.ssr) {
                    best = Some(f);
                }
            }
            bar.inc(1);
        }
    }
    best
}

/// The pairs of parameters the points cannot separate, with warnings for them, for
/// undefined intervals and for factors that hardly decay over the points' ranges.
fn identifiability(
    x: &[f64],
    half: &[f64],
    correlation: &[f64],
    v_max: f64,
    t_max: f64,
    warnings: &mut Vec<String>,
) -> Vec<(String, String, f64)> {
    let mut correlated = Vec::new();
    for a in 0..5 {
        for b in a + 1..5 {
            let r = correlation[a * 5 + b];
            if r.abs() > 0.95 || r.is_nan() {
                correlated.push((NAMES[a].to_string(), NAMES[b].to_string(), r));
            }
        }
    }
    if !correlated.is_empty() {
        warnings.push(format!(
            "parameters not separately identifiable from these points (|correlation| > 0.95: {}); \
         add points at higher friction speed / disc temperature",
            correlated
                .iter()
                .map(|(a, b, r)| format!("{a}-{b} {r:.3}"))
                .collect::<Vec<_>>()
                .join(", ")
        ));
    }
    if half.iter().any(|h| !h.is_finite()) {
        warnings
            .push("some confidence intervals are undefined (singular information matrix)".into());
    }
    let decay_v = x[2] * v_max;
    let decay_t = x[4] * t_max;
    if decay_v < 2.0 {
        warnings.push(format!(
        "the speed factor decays by only e^-{decay_v:.1} over the points' speed range: mu_d0 and n_v are confounded"
    ));
    }
    if decay_t < 2.0 {
        warnings.push(format!(
        "the temperature factor decays by only e^-{decay_t:.1} over the points' temperature range: mu_d0 and n_t are confounded"
    ));
    }
    correlated
}

/// Files larger than this (bytes, together) show progress bars while read and fitted.
const PROGRESS_BYTES: u64 = 20_000_000;

/// A progress bar on standard error (shown for long work only: `show`).
fn progress(show: bool, template: &str) -> ProgressBar {
    let bar = ProgressBar::with_draw_target(
        Some(0),
        if show {
            indicatif::ProgressDrawTarget::stderr()
        } else {
            indicatif::ProgressDrawTarget::hidden()
        },
    );
    if let Ok(style) = indicatif::ProgressStyle::with_template(template) {
        bar.set_style(style);
    }
    bar
}

/// Reads friction test `f` (in row chunks: a CSV, an MDF4 file's one channel group)
/// through the channel `map`, adding its points to `gathered`; `bar` counts the bytes read.
fn read_into(
    f: &Path,
    map: Option<&ChannelMap>,
    bar: &ProgressBar,
    gathered: &mut gather::Gathered,
) -> Result<FrictionTest, crate::measured::MeasuredError> {
    stream_friction_test_with(
        f,
        map,
        || {
            let file = std::fs::File::open(f)?;
            bar.inc_length(file.metadata()?.len());
            Ok(std::io::BufReader::with_capacity(
                1 << 16,
                bar.wrap_read(file),
            ))
        },
        |chunk| {
            for i in 0..chunk.mu.len() {
                gathered.add(chunk.v_friction_mps[i], chunk.t_disc_c[i], chunk.mu[i]);
            }
            Ok(())
        },
    )
}

/// `hils fit-friction`.
pub fn main(args: FitFrictionArgs) -> Result<()> {
    let started = std::time::Instant::now();
    let out = args.out.check()?;
    let params = params_or_default(args.params.as_deref())?;
    let c = params.plant.friction.correction_c;
    let map = crate::measured::load_map(args.map.as_deref())?;
    let bytes: u64 = args
        .files
        .iter()
        .filter_map(|f| std::fs::metadata(f).ok())
        .map(|m| m.len())
        .sum();
    let show = bytes > PROGRESS_BYTES;
    let bar = progress(
        show,
        "reading {bar:40} {bytes}/{total_bytes}, {elapsed_precise}, about {eta} to go",
    );
    let mut gathered = gather::Gathered::default();
    let mut skipped = 0;
    for f in &args.files {
        let test = read_into(f, map.as_ref(), &bar, &mut gathered)?;
        for note in &test.notes {
            crate::say!("{}: {note}", f.display());
        }
        skipped += test.skipped;
    }
    bar.finish_and_clear();
    let fit_bar = progress(
        show,
        "fitting {bar:40} {pos}/{len} starts, {elapsed_precise}",
    );
    let mut fit = match &gathered.cells {
        Some(cells) => fit_cells(cells, c, &fit_bar)?,
        None => {
            let (v, t, mu) = gathered.plot_points();
            fit_points(&v, &t, &mu, c)?
        }
    };
    fit_bar.finish_and_clear();
    fit.skipped_rows = skipped;
    fit.files = args.files.iter().map(|f| f.display().to_string()).collect();
    let shown = fit.rounded();
    print_fit(&shown);
    crate::say!(
        "  read and fitted in {:.1} s; peak memory {:.0} MB",
        started.elapsed().as_secs_f64(),
        crate::bench::peak_rss_bytes() as f64 / 1e6
    );
    out.write_json(&shown)?;
    let (v, t, mu) = gathered.plot_points();
    out.write_report(|dir| write_report(dir.path(), &fit, &v, &t, &mu))
}

/// All files' points together.
pub fn pooled(tests: &[FrictionTest]) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    let mut v = Vec::new();
    let mut t = Vec::new();
    let mut mu = Vec::new();
    for x in tests {
        v.extend_from_slice(&x.v_friction_mps);
        t.extend_from_slice(&x.t_disc_c);
        mu.extend_from_slice(&x.mu);
    }
    (v, t, mu)
}

fn print_fit(f: &FrictionFit) {
    crate::say!(
        "Eq (2) fitted to {} points ({} rows skipped), c = {} fixed:",
        f.points,
        f.skipped_rows,
        f.correction_c
    );
    for (name, value) in NAMES.iter().zip([f.mu_d0, f.n_v, f.m_v, f.n_t, f.m_t]) {
        let [lo, hi] = f.ci95[*name];
        let d = f.decimals(name, value).max(5) as usize;
        crate::say!("  {name:6} = {value:10.d$}   95 % CI [{lo:.d$}, {hi:.d$}]");
    }
    crate::say!("  rms error of mu = {:.5}", f.rms);
    if let Some(c) = &f.cells {
        crate::say!(
            "  fitted as {} cells of {} m/s x {} degC (each cell's mean point weighted by its \
             count; intervals and rms from all points)",
            c.count,
            c.width_v_mps,
            c.width_t_c
        );
    }
    crate::say!("  fit time {:.3} s", f.wall_s);
    for w in &f.warnings {
        crate::say!("  warning: {w}");
    }
}

fn quantile(x: &[f64], q: f64) -> f64 {
    let mut s = x.to_vec();
    s.sort_by(f64::total_cmp);
    s[((s.len() - 1) as f64 * q).round() as usize]
}

/// One band of a Fig 2 panel: the measured points of the band (`symbol` near `at`) and
/// Eq (2) at the band's value over `0..x_hi`.
fn band_series(
    chart: &mut Chart,
    k: usize,
    points: Vec<(f64, f64)>,
    symbol: &str,
    at: &str,
    x_hi: f64,
    eq2_at: &dyn Fn(f64) -> f64,
) {
    chart.series.push(Series::new(
        format!("measured, {symbol} near {at}"),
        points,
        Style::Points,
        k,
    ));
    let curve = (0..=200).map(|i| {
        let x = x_hi * i as f64 / 200.0;
        (x, eq2_at(x))
    });
    chart.series.push(Series::new(
        format!("Eq (2) at {at}"),
        curve.collect(),
        Style::Solid,
        k,
    ));
}

/// Fig 2 of the paper for this data: mu vs disc temperature (curves at low, median and high
/// friction speed of the points) and mu vs friction speed (curves at low, median and high
/// temperature); measured points coloured by the band of the other variable.
pub fn write_report(
    dir: &Path,
    fit: &FrictionFit,
    v: &[f64],
    t: &[f64],
    mu: &[f64],
) -> Result<Vec<PathBuf>> {
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let p = fit.params();
    let mut files = Vec::new();
    let bands = |x: &[f64]| [quantile(x, 0.1), quantile(x, 0.5), quantile(x, 0.9)];
    let (vb, tb) = (bands(v), bands(t));
    let band_of = |x: f64, b: &[f64; 3]| -> usize {
        let cuts = [(b[0] + b[1]) / 2.0, (b[1] + b[2]) / 2.0];
        if x < cuts[0] {
            0
        } else if x < cuts[1] {
            1
        } else {
            2
        }
    };
    let t_hi = t.iter().cloned().fold(0.0f64, f64::max) * 1.05 + 1.0;
    let v_hi = v.iter().cloned().fold(0.0f64, f64::max) * 1.05 + 0.5;

    let mut a = Chart::new(
        "Fig 2(a): friction coefficient vs disc temperature",
        "disc temperature rise T_d, degC",
        "mu_d",
    );
    let mut b = Chart::new(
        "Fig 2(b): friction coefficient vs friction speed",
        "friction speed v_d, m/s",
        "mu_d",
    );
    for k in 0..3 {
        // (a): against temperature, one speed band per colour; (b): the other way round.
        let in_band = |x: &[f64], b: &[f64; 3]| -> Vec<usize> {
            (0..mu.len()).filter(|&i| band_of(x[i], b) == k).collect()
        };
        let pts_a = in_band(v, &vb).iter().map(|&i| (t[i], mu[i])).collect();
        let pts_b = in_band(t, &tb).iter().map(|&i| (v[i], mu[i])).collect();
        let (speed, temp) = (format!("{:.1} m/s", vb[k]), format!("{:.0} degC", tb[k]));
        band_series(&mut a, k, pts_a, "v_d", &speed, t_hi, &|x| {
            eq2(&p, vb[k], x)
        });
        band_series(&mut b, k, pts_b, "T_d", &temp, v_hi, &|x| eq2(&p, x, tb[k]));
    }
    files.push(dir.join("fig2a_mu_vs_temperature.svg"));
    a.save_svg(files.last().unwrap())?;
    files.push(dir.join("fig2b_mu_vs_speed.svg"));
    b.save_svg(files.last().unwrap())?;

    let mut md = String::from("# Friction fit (paper Eq 2)\n\n");
    md += &format!(
        "{} points from {}; {} rows skipped; c = {} fixed.\n\n| parameter | value | 95 % CI |\n|---|---|---|\n",
        fit.points,
        fit.files.join(", "),
        fit.skipped_rows,
        fit.correction_c
    );
    for (name, value) in NAMES
        .iter()
        .zip([fit.mu_d0, fit.n_v, fit.m_v, fit.n_t, fit.m_t])
    {
        let [lo, hi] = fit.ci95[*name];
        md += &format!("| {name} | {value:.5} | [{lo:.5}, {hi:.5}] |\n");
    }
    md += &format!("\nrms error of mu: {:.5}\n\n", fit.rms);
    for w in &fit.warnings {
        md += &format!("**Warning:** {w}\n\n");
    }
    md += "![mu vs temperature](fig2a_mu_vs_temperature.svg)\n\n![mu vs speed](fig2b_mu_vs_speed.svg)\n";
    files.push(dir.join("report.md"));
    crate::outputs::write_file(files.last().unwrap(), md)?;
    Ok(files)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A fit whose parameters are all `x` with intervals of half-width `half`.
    fn fit_of(x: f64, half: f64) -> FrictionFit {
        let ci95 = NAMES
            .iter()
            .map(|n| (n.to_string(), [x - half, x + half]))
            .collect();
        let mut f = fit_points(
            &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0],
            &[10.0, 200.0, 30.0, 150.0, 50.0, 250.0, 70.0, 120.0],
            &[0.45, 0.42, 0.43, 0.41, 0.42, 0.39, 0.41, 0.40],
            0.98,
        )
        .unwrap();
        (f.mu_d0, f.n_v, f.m_v, f.n_t, f.m_t, f.ci95) = (x, x, x, x, x, ci95);
        f
    }

    /// Item 16: 5 significant digits, finer when the interval is (50 M points pin mu_d0 to
    /// a few 1e-6: rounded to 5 digits its interval read [0.38, 0.38]).
    #[test]
    fn parameters_and_intervals_are_rounded_to_what_they_mean() {
        let wide = fit_of(0.379_961_274, 6.6e-4).rounded();
        assert_eq!(wide.mu_d0, 0.37996);
        assert_eq!(wide.ci95["mu_d0"], [0.3793, 0.38062]);
        let narrow = fit_of(0.380_000_312_7, 3.1e-6).rounded();
        assert_eq!(narrow.mu_d0, 0.3800003);
        let [lo, hi] = narrow.ci95["mu_d0"];
        assert!(lo < narrow.mu_d0 && narrow.mu_d0 < hi, "{lo} {hi}");
        assert_eq!([lo, hi], [0.3799972, 0.3800034]);
    }
}
