//! Replaying a measured run in a model: the plant driven by the measured brake inputs from
//! the measured initial speed, compared with every logged quantity the model predicts.
//!
//! # Inputs
//!
//! Each wheelset's pad clamp force comes from its measured clamp force (`f_clamp*_n`, the
//! input where logged, as the spec says) or from its cylinder pressure through Eq (1)
//! (`Caliper::clamp_force`, the plant's copy), linearly interpolated between samples.
//! WSP venting is in those measured inputs, so the replay needs no WSP of its own. Empty
//! input cells are filled by linear interpolation between the neighbouring samples
//! (counted in the notes). Model extensions act here too: a sensor gain divides the reading,
//! an actuator lag filters the pad force behind the pressure (first order, exact
//! discretisation).
//!
//! # Comparison
//!
//! Samples are grouped in bins of [`Prepared::bin_s`] (20 ms, or longer for slow logs);
//! each channel's measured bin mean is compared with the model at the mean time of that
//! bin's samples (exact for signals linear over the bin). A bin's weight is its noise:
//! the channel's sample noise (robust estimate from second differences) over the square
//! root of the bin's sample count, or the noise of the bin means themselves (correlated
//! sensor noise) if larger, never below the channel's floor (the resolution the
//! model is expected to reach; see [`Group::floor`]). Wheel speeds weigh less while the
//! measured wheel slides (slide transients are where two simulators differ most).
//!
//! Bins are assigned to blocks of [`VALIDATION_BLOCK_S`]; every third block is validation
//! data that no fit sees.

use hils_plant::brake::Caliper;
use hils_plant::friction::DiscPadFriction;
use hils_plant::{BrakeInput, Params, Plant, Rail, WHEELSETS};

use crate::measured::RunLog;

/// Kind of a compared channel.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Quantity {
    /// Vehicle speed v_ref, m/s.
    VRef,
    /// Wheel circumferential speed r omega_j, m/s.
    WheelSpeed(usize),
    /// Tangential brake force f_brake_j, N.
    BrakeForce(usize),
    /// Axle load q_j, N.
    AxleLoad(usize),
    /// Pad force predicted from the cylinder pressure vs the measured clamp force, N
    /// (only where both are logged).
    PadFromPressure(usize),
    /// Disc temperature rise, degC (compared and reported, not fitted).
    DiscTemp(usize),
    /// Carbody acceleration, m/s^2 (compared and reported, not fitted).
    Accel,
}

/// Channel groups (for floors and for the fitted objective).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Group {
    Speeds,
    BrakeForces,
    AxleLoads,
    PadForces,
    DiscTemps,
    Accel,
}

impl Quantity {
    pub fn group(self) -> Group {
        match self {
            Quantity::VRef | Quantity::WheelSpeed(_) => Group::Speeds,
            Quantity::BrakeForce(_) => Group::BrakeForces,
            Quantity::AxleLoad(_) => Group::AxleLoads,
            Quantity::PadFromPressure(_) => Group::PadForces,
            Quantity::DiscTemp(_) => Group::DiscTemps,
            Quantity::Accel => Group::Accel,
        }
    }

    /// Column-like label.
    pub fn label(self) -> String {
        match self {
            Quantity::VRef => "v_ref".into(),
            Quantity::WheelSpeed(j) => format!("r*omega{}", j + 1),
            Quantity::BrakeForce(j) => format!("f_brake{}", j + 1),
            Quantity::AxleLoad(j) => format!("q{}", j + 1),
            Quantity::PadFromPressure(j) => format!("f_clamp{} from p_cyl{}", j + 1, j + 1),
            Quantity::DiscTemp(j) => format!("t_disc{}", j + 1),
            Quantity::Accel => "a_x".into(),
        }
    }

    pub fn unit(self) -> &'static str {
        match self.group() {
            Group::Speeds => "m/s",
            Group::BrakeForces | Group::AxleLoads | Group::PadForces => "N",
            Group::DiscTemps => "degC",
            Group::Accel => "m/s^2",
        }
    }
}

impl Group {
    /// Whether the group enters the fitted objective and the score. Disc temperatures and
    /// the carbody acceleration are compared and reported only: the thermal model's
    /// constants are not among the effects, and a_x is usually too noisy to add anything.
    pub fn fitted(self) -> bool {
        matches!(
            self,
            Group::Speeds | Group::BrakeForces | Group::AxleLoads | Group::PadForces
        )
    }

    /// Smallest bin sigma: the resolution to which the model is expected to reproduce a
    /// correct measurement (numerical step, a different simulator's discretisation),
    /// from the channel's typical magnitude `scale`.
    pub fn floor(self, scale: f64) -> f64 {
        match self {
            Group::Speeds => SPEED_FLOOR_MPS,
            Group::BrakeForces => (0.01 * scale).max(50.0),
            Group::AxleLoads => (0.02 * scale).max(200.0),
            Group::PadForces => (0.01 * scale).max(50.0),
            Group::DiscTemps => (0.03 * scale).max(1.0),
            Group::Accel => 0.05,
        }
    }
}

/// One compared channel of a prepared run.
#[derive(Clone, Debug)]
pub struct Channel {
    pub quantity: Quantity,
    /// Bins with samples of this channel.
    pub bins: Vec<usize>,
    /// Mean sample time of the channel's samples in each of those bins, s from the start.
    pub times: Vec<f64>,
    /// Measured bin means.
    pub measured: Vec<f64>,
    /// Bin sigmas (noise of the mean, floored; inflated for wheel speeds while sliding).
    pub sigma: Vec<f64>,
    /// Sample noise estimate of the raw channel.
    pub noise: f64,
    /// Typical magnitude (largest absolute bin mean).
    pub scale: f64,
}

/// Resolution of a replayed speed, m/s: the smallest bin sigma of a speed channel.
pub const SPEED_FLOOR_MPS: f64 = 0.02;

/// Resolution of a replayed speed relative to the speed lost since the start: two
/// simulators of the same vehicle (integration, rotating masses, creep) differ by about
/// 0.1-0.2 % of the deceleration, which integrates to this share of the speed lost.
/// Listed effects of interest change the deceleration by 1 % and more.
pub const SPEED_RESOLUTION: f64 = 0.0025;

/// Below this speed (v_ref and the wheel's) a brake force is static friction, m/s.
pub const STANDSTILL_MPS: f64 = 0.5;

/// Length of the blocks that alternate between fit (two) and validation (one), s: short,
/// so that transients (brake application, WSP cycles) fall in both.
pub const VALIDATION_BLOCK_S: f64 = 0.2;

/// How a wheelset's brake input is measured.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum InputKind {
    ClampForce,
    Pressure,
}

/// A measured run prepared for replays.
#[derive(Clone, Debug)]
pub struct Prepared {
    pub name: String,
    pub rail: Rail,
    /// Whether the rail came from the file's metadata (else the baseline's scenario rail).
    pub rail_from_metadata: bool,
    /// Start time of the log, s (replays start here).
    pub t0: f64,
    /// Sample times from t0, s.
    pub t: Vec<f64>,
    pub duration: f64,
    /// Measured initial speed, m/s.
    pub v0: f64,
    /// Measured initial disc temperature rise, degC (None: the baseline's ambient_rise).
    pub disc_temp0: Option<f64>,
    pub input_kind: [InputKind; WHEELSETS],
    /// Input readings per wheelset at the samples (gaps filled), N or Pa.
    pub input: [Vec<f64>; WHEELSETS],
    /// Pressure readings where the clamp force is the input (observation), Pa.
    pub pressure_obs: [Option<Vec<f64>>; WHEELSETS],
    /// Measured disc temperature rise per wheelset at the samples (gaps filled), degC:
    /// where logged, Eq (2) is evaluated at it (the disc-thermal link is checked on its own).
    pub disc_temp_input: [Option<Vec<f64>>; WHEELSETS],
    pub bin_s: f64,
    pub n_bins: usize,
    /// Validation flag per bin.
    pub validation: Vec<bool>,
    pub channels: Vec<Channel>,
    /// Measured bin means of v_ref and wheel speeds (NaN where none), for slides and plots.
    pub v_bin: Vec<f64>,
    pub wheel_bin: [Vec<f64>; WHEELSETS],
    pub bin_time: Vec<f64>,
    /// WSP vent flag per wheelset (any sample in the log).
    pub wsp_any: [bool; WHEELSETS],
    pub wsp_logged: bool,
    /// Other measured per-bin context for the report: disc temperature (mean of wheelsets),
    /// clamp force (mean input), NaN where unknown.
    pub clamp_bin: Vec<f64>,
    pub disc_temp_bin: Vec<f64>,
    pub notes: Vec<String>,
    /// The plant step of replays, s.
    pub dt: f64,
    /// Per plant step: index of the sample at or before it and the interpolation weight.
    step_map: Vec<(u32, f32)>,
}

pub use crate::measured::noise_sigma;

/// Noise that grows with the measured level, sigma(x) = sqrt(a^2 + (r x)^2), from the
/// noise of the samples above and below the median |x| (a speed sensor's relative error:
/// a phonic wheel's tooth-pitch error, a radar's scale error). Returns (a, r); r = 0
/// where the upper half is not noisier than the lower half.
fn noise_by_level(t: &[f64], x: &[f64]) -> (f64, f64) {
    let mut mags: Vec<f64> = x
        .iter()
        .filter(|v| v.is_finite())
        .map(|v| v.abs())
        .collect();
    if mags.len() < 16 {
        return (noise_sigma(t, x), 0.0);
    }
    mags.sort_by(f64::total_cmp);
    let median = mags[mags.len() / 2];
    let half = |upper: bool| -> (f64, f64) {
        let masked: Vec<f64> = x
            .iter()
            .map(|&v| {
                if (v.abs() > median) == upper {
                    v
                } else {
                    f64::NAN
                }
            })
            .collect();
        let part = if upper {
            &mags[mags.len() / 2..]
        } else {
            &mags[..mags.len() / 2]
        };
        (noise_sigma(t, &masked), part[part.len() / 2])
    };
    let ((lo, v_lo), (hi, v_hi)) = (half(false), half(true));
    if !(hi > lo && v_hi > v_lo) {
        return (noise_sigma(t, x), 0.0);
    }
    let r2 = (hi * hi - lo * lo) / (v_hi * v_hi - v_lo * v_lo);
    ((lo * lo - r2 * v_lo * v_lo).max(0.0).sqrt(), r2.sqrt())
}

/// Quantile `q` of the finite values within +-`half` samples of each sample (NaN where none).
fn running_quantile(x: &[f64], half: usize, q: f64) -> Vec<f64> {
    // Evaluated every `step` samples and held in between: the slip baseline varies slowly.
    let step = (half / 8).max(1);
    let mut out = vec![f64::NAN; x.len()];
    let mut window: Vec<f64> = Vec::with_capacity(2 * half + 1);
    let mut i = 0;
    while i < x.len() {
        window.clear();
        let lo = i.saturating_sub(half);
        let hi = (i + half + 1).min(x.len());
        window.extend(x[lo..hi].iter().copied().filter(|v| v.is_finite()));
        let m = if window.is_empty() {
            f64::NAN
        } else {
            let k = ((window.len() - 1) as f64 * q).round() as usize;
            *window.select_nth_unstable_by(k, f64::total_cmp).1
        };
        for o in out.iter_mut().skip(i).take(step) {
            *o = m;
        }
        i += step;
    }
    out
}

/// Fills NaN gaps by linear interpolation (ends: nearest value); returns the count filled.
fn fill_gaps(t: &[f64], x: &mut [f64]) -> usize {
    let known: Vec<usize> = (0..x.len()).filter(|&i| x[i].is_finite()).collect();
    if known.is_empty() {
        return 0;
    }
    let mut filled = 0;
    let mut k = 0;
    for i in 0..x.len() {
        if x[i].is_finite() {
            continue;
        }
        while k + 1 < known.len() && known[k + 1] < i {
            k += 1;
        }
        let (a, b) = (known[k], known.get(k + 1).copied());
        x[i] = match b {
            Some(b) if a < i => x[a] + (x[b] - x[a]) * (t[i] - t[a]) / (t[b] - t[a]),
            _ if a > i => x[a],
            _ => x[a],
        };
        filled += 1;
    }
    filled
}

/// Initial speed: intercept of a quadratic fitted to v_ref over the first 0.5 s (at least
/// 5 samples), robust to sensor noise.
fn initial_speed(t: &[f64], v: &[f64]) -> f64 {
    let pts: Vec<(f64, f64)> = t
        .iter()
        .zip(v)
        .filter(|(_, v)| v.is_finite())
        .enumerate()
        .take_while(|(k, (t, _))| **t <= 0.5 || *k < 5)
        .map(|(_, (t, v))| (*t, *v))
        .collect();
    if pts.len() < 3 {
        return pts.first().map(|p| p.1).unwrap_or(0.0).max(0.0);
    }
    // Least squares of v = a + b t + c t^2 (normal equations, 3x3).
    let mut s = [[0.0f64; 4]; 3];
    for (t, v) in &pts {
        let basis = [1.0, *t, t * t];
        for r in 0..3 {
            for c in 0..3 {
                s[r][c] += basis[r] * basis[c];
            }
            s[r][3] += basis[r] * v;
        }
    }
    let m = nalgebra::Matrix3::new(
        s[0][0], s[0][1], s[0][2], s[1][0], s[1][1], s[1][2], s[2][0], s[2][1], s[2][2],
    );
    let rhs = nalgebra::Vector3::new(s[0][3], s[1][3], s[2][3]);
    match m.lu().solve(&rhs) {
        Some(x) if x[0].is_finite() => x[0].max(0.0),
        _ => pts[0].1.max(0.0),
    }
}

/// Whether bin `b` of width `bin_s` is validation data (every third block of
/// [`VALIDATION_BLOCK_S`], by the bin's start).
pub fn is_validation_bin(b: usize, bin_s: f64) -> bool {
    ((b as f64 * bin_s / VALIDATION_BLOCK_S) as usize) % 3 == 2
}

/// Comparison bin width for a log with median interval `dt_s`: 20 ms, or 2 samples.
pub fn bin_width(dt_s: f64) -> f64 {
    (2.0 * dt_s).max(0.02)
}

/// Per-bin sums of a channel's finite samples: values, sample times and counts.
struct BinSums {
    sum: Vec<f64>,
    t_sum: Vec<f64>,
    count: Vec<u32>,
}

impl BinSums {
    /// Sums the finite samples `x[i]` (at times `t[i]`) into `n_bins` bins by `bin_of(t)`.
    fn new(t: &[f64], x: &[f64], n_bins: usize, bin_of: impl Fn(f64) -> usize) -> Self {
        let mut sums = BinSums {
            sum: vec![0.0; n_bins],
            t_sum: vec![0.0; n_bins],
            count: vec![0; n_bins],
        };
        for (&ti, &xi) in t.iter().zip(x) {
            if xi.is_finite() {
                let b = bin_of(ti);
                sums.sum[b] += xi;
                sums.t_sum[b] += ti;
                sums.count[b] += 1;
            }
        }
        sums
    }

    /// Mean of bin `b`; NaN where it holds no sample.
    fn mean(&self, b: usize) -> f64 {
        if self.count[b] > 0 {
            self.sum[b] / self.count[b] as f64
        } else {
            f64::NAN
        }
    }
}

/// The measured brake inputs of a run, gaps filled: clamp forces or cylinder pressures
/// per wheelset, and the pressures logged beside clamp forces (for the Eq 1 check).
struct BrakeInputs {
    kind: [InputKind; WHEELSETS],
    input: [Vec<f64>; WHEELSETS],
    pressure_obs: [Option<Vec<f64>>; WHEELSETS],
}

impl BrakeInputs {
    fn new(log: &RunLog, t: &[f64], notes: &mut Vec<String>) -> Self {
        let mut input_kind = [InputKind::Pressure; WHEELSETS];
        let mut input: [Vec<f64>; WHEELSETS] = Default::default();
        let mut pressure_obs: [Option<Vec<f64>>; WHEELSETS] = Default::default();
        for j in 0..WHEELSETS {
            let (kind, col, name) = match (&log.f_clamp_n[j], &log.p_cyl_pa[j]) {
                (Some(f), _) => (InputKind::ClampForce, f, format!("f_clamp{}_n", j + 1)),
                (None, Some(p)) => (InputKind::Pressure, p, format!("p_cyl{}_pa", j + 1)),
                (None, None) => unreachable!("the reader requires an input per wheelset"),
            };
            input_kind[j] = kind;
            let mut x = col.clone();
            if x.iter().all(|v| v.is_nan()) {
                notes.push(format!("{name}: no value at all; the input is taken as 0"));
                x.iter_mut().for_each(|v| *v = 0.0);
            }
            // Gaps and empty cells are bridged (the admission stage checked they can be,
            // and its notes say so per column).
            fill_gaps(t, &mut x);
            input[j] = x;
            if kind == InputKind::ClampForce {
                pressure_obs[j] = pressure_beside_clamp(log, t, j);
            }
        }
        BrakeInputs {
            kind: input_kind,
            input,
            pressure_obs,
        }
    }

    /// The clamp force per sample, mean of the wheelsets (pressures through Eq 1), N.
    fn mean_clamp_force(&self, baseline: &Params, n: usize) -> Vec<f64> {
        let caliper = Caliper::<f64>::new(&baseline.brake);
        (0..n)
            .map(|i| {
                (0..WHEELSETS)
                    .map(|j| match self.kind[j] {
                        InputKind::ClampForce => self.input[j][i],
                        InputKind::Pressure => caliper.clamp_force(self.input[j][i]),
                    })
                    .sum::<f64>()
                    / WHEELSETS as f64
            })
            .collect()
    }
}

/// The cylinder pressure of wheelset `j` logged beside its clamp force, gaps filled.
fn pressure_beside_clamp(log: &RunLog, t: &[f64], j: usize) -> Option<Vec<f64>> {
    let mut p = log.p_cyl_pa[j].clone()?;
    if !p.iter().any(|v| v.is_finite()) {
        return None;
    }
    fill_gaps(t, &mut p);
    Some(p)
}

/// Measured disc temperatures that drive Eq (2) (at least one reading per second).
fn disc_temp_inputs(
    log: &RunLog,
    t: &[f64],
    duration: f64,
    notes: &mut Vec<String>,
) -> [Option<Vec<f64>>; WHEELSETS] {
    let disc_temp_input: [Option<Vec<f64>>; WHEELSETS] = std::array::from_fn(|j| {
        let mut x = log.t_disc_c[j].clone()?;
        let known = x.iter().filter(|v| v.is_finite()).count();
        // Too sparse to drive the friction (fewer than one reading per second).
        if (known as f64) < duration.max(1.0) {
            return None;
        }
        fill_gaps(t, &mut x);
        Some(x)
    });
    if disc_temp_input.iter().any(|x| x.is_some()) {
        notes.push(
            "t_disc logged: where Eq (2) acts it is evaluated at the measured disc temperature; the thermal model is checked on the disc-thermal link".to_string(),
        );
    }
    disc_temp_input
}

/// The comparison bins of a run and its validation blocks.
struct Bins {
    bin_s: f64,
    n_bins: usize,
    validation: Vec<bool>,
    bin_time: Vec<f64>,
}

impl Bins {
    fn new(log: &RunLog, duration: f64) -> Self {
        let bin_s = bin_width(log.median_interval_s());
        let n_bins = ((duration / bin_s).floor() as usize + 1).max(1);
        Bins {
            bin_s,
            n_bins,
            validation: (0..n_bins).map(|b| is_validation_bin(b, bin_s)).collect(),
            bin_time: (0..n_bins).map(|b| (b as f64 + 0.5) * bin_s).collect(),
        }
    }

    fn bin_of(&self, ti: f64) -> usize {
        ((ti / self.bin_s) as usize).min(self.n_bins - 1)
    }

    fn sums(&self, t: &[f64], x: &[f64]) -> BinSums {
        BinSums::new(t, x, self.n_bins, |ti| self.bin_of(ti))
    }

    /// Bin means of the finite samples of `x`; NaN in empty bins.
    fn means(&self, t: &[f64], x: &[f64]) -> Vec<f64> {
        let sums = self.sums(t, x);
        (0..self.n_bins).map(|b| sums.mean(b)).collect()
    }
}

/// Initial speed: the median of the intercepts of v_ref and the wheel speeds (the wheels
/// roll freely before the brakes act; a radar's slow error or one sensor's offset does not
/// move the median), m/s.
fn initial_speed_median(t: &[f64], v_ref: &[f64], wheel_speed: &[Vec<f64>; WHEELSETS]) -> f64 {
    let mut v: Vec<f64> = std::iter::once(initial_speed(t, v_ref))
        .chain(wheel_speed.iter().map(|w| initial_speed(t, w)))
        .filter(|x| x.is_finite())
        .collect();
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Measured slip per bin that weighs a wheel speed less while the wheel slides. A slide
/// is a transient: the slip above its running 20 % quantile over +-2.5 s counts (a slowly
/// drifting offset between v_ref and the wheels, e.g. a speed-sensor drift, is not a slide
/// and keeps the wheel speeds' full weight; repeated WSP cycles still leave the quantile at
/// the rolling wheel's slip).
fn slide_inflation(v_bin: &[f64], wheel_bin: &[f64], bin_s: f64) -> Vec<f64> {
    let slip: Vec<f64> = v_bin.iter().zip(wheel_bin).map(|(v, w)| v - w).collect();
    let slow = running_quantile(&slip, ((2.5 / bin_s) as usize).max(1), 0.2);
    slip.iter()
        .zip(&slow)
        .map(|(s, m)| {
            let transient = if m.is_finite() { s.min(s - m) } else { *s };
            if transient.is_finite() && transient > 0.3 {
                transient
            } else {
                0.0
            }
        })
        .collect()
}

/// What the compared channels of a run are built from.
struct ChannelSetup<'a> {
    t: &'a [f64],
    bins: &'a Bins,
    v_bin: &'a [f64],
    wheel_bin: &'a [Vec<f64>; WHEELSETS],
    v0: f64,
}

impl ChannelSetup<'_> {
    /// Every compared channel of the log, in the order of [`Quantity`]'s groups.
    fn channels(
        &self,
        log: &RunLog,
        wheel_speed: &[Vec<f64>; WHEELSETS],
        pressure_obs: &[Option<Vec<f64>>; WHEELSETS],
    ) -> Vec<Channel> {
        let mut channels = Vec::new();
        let mut add = |quantity: Quantity, x: &[f64], slip_inflate: Option<&[f64]>| {
            channels.extend(self.channel(quantity, x, slip_inflate));
        };
        add(Quantity::VRef, &log.v_ref_mps, None);
        for j in 0..WHEELSETS {
            let inflate = slide_inflation(self.v_bin, &self.wheel_bin[j], self.bins.bin_s);
            add(Quantity::WheelSpeed(j), &wheel_speed[j], Some(&inflate));
        }
        for j in 0..WHEELSETS {
            if let Some(x) = &log.f_brake_n[j] {
                add(Quantity::BrakeForce(j), x, None);
            }
        }
        for j in 0..WHEELSETS {
            if let Some(x) = &log.q_n[j] {
                add(Quantity::AxleLoad(j), x, None);
            }
        }
        for j in 0..WHEELSETS {
            if pressure_obs[j].is_some() {
                if let Some(f) = &log.f_clamp_n[j] {
                    add(Quantity::PadFromPressure(j), f, None);
                }
            }
        }
        for j in 0..WHEELSETS {
            if let Some(x) = &log.t_disc_c[j] {
                add(Quantity::DiscTemp(j), x, None);
            }
        }
        if let Some(a) = &log.a_x_mps2 {
            add(Quantity::Accel, a, None);
        }
        channels
    }

    /// One compared channel: bin means of `x` with their noise (None: no bin to compare).
    fn channel(
        &self,
        quantity: Quantity,
        x: &[f64],
        slip_inflate: Option<&[f64]>,
    ) -> Option<Channel> {
        let (t, v_bin, wheel_bin, v0) = (self.t, self.v_bin, self.wheel_bin, self.v0);
        let noise = noise_sigma(t, x);
        // Speeds: noise that grows with the speed (sensor's relative error).
        let level_noise = if quantity.group() == Group::Speeds {
            noise_by_level(t, x)
        } else {
            (0.0, 0.0)
        };
        let BinSums {
            sum,
            t_sum: tsum,
            count: cnt,
        } = self.bins.sums(t, x);
        // A brake force at standstill is static friction (any value up to the limit
        // holds the wheel): compared only while the wheelset turns. Where its speed is not
        // measured (a dead sensor), the vehicle's standstill is the wheel's.
        let turning = |b: usize| match quantity {
            Quantity::BrakeForce(j) => {
                let w = wheel_bin[j][b];
                let wheel_still = !w.is_finite() || w < STANDSTILL_MPS;
                !(wheel_still && v_bin[b].abs() < STANDSTILL_MPS)
            }
            _ => true,
        };
        let bins: Vec<usize> = (0..self.bins.n_bins)
            .filter(|&b| cnt[b] > 0 && turning(b))
            .collect();
        if bins.is_empty() {
            return None;
        }
        let measured: Vec<f64> = bins.iter().map(|&b| sum[b] / cnt[b] as f64).collect();
        let scale = measured.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        let floor = quantity.group().floor(scale);
        // Speeds: a relative resolution of the integrated deceleration too.
        let speed_floor = |b: usize| -> f64 {
            let lost = v0 - v_bin[b];
            if quantity.group() == Group::Speeds && lost.is_finite() {
                floor.max(SPEED_RESOLUTION * lost)
            } else {
                floor
            }
        };
        // Noise of the bin means seen directly (catches correlated sensor noise that
        // the sample-to-sample estimate divided by sqrt(n) would underrate).
        let bin_t: Vec<f64> = bins.iter().map(|&b| tsum[b] / cnt[b] as f64).collect();
        let bin_noise = noise_sigma(&bin_t, &measured);
        let bin_level = if quantity.group() == Group::Speeds {
            noise_by_level(&bin_t, &measured)
        } else {
            (0.0, 0.0)
        };
        let at_level = |(a, r): (f64, f64), x: f64| (a * a + (r * x).powi(2)).sqrt();
        let sigma = bins
            .iter()
            .zip(&measured)
            .map(|(&b, &m)| {
                let sample = noise.max(at_level(level_noise, m));
                let s = (sample / (cnt[b] as f64).sqrt())
                    .max(bin_noise.max(at_level(bin_level, m)))
                    .max(speed_floor(b));
                match slip_inflate {
                    Some(slip) if slip[b].is_finite() => {
                        let extra = 0.1 * slip[b].abs();
                        (s * s + extra * extra).sqrt()
                    }
                    _ => s,
                }
            })
            .collect();
        Some(Channel {
            quantity,
            times: bin_t,
            bins,
            measured,
            sigma,
            noise,
            scale,
        })
    }
}

/// The rail condition as the metadata writes it (`wet`, `dry`).
pub fn rail_name(rail: Rail) -> &'static str {
    match rail {
        Rail::Wet => "wet",
        Rail::Dry => "dry",
    }
}

/// Initial disc temperature: the mean over the logged discs of their first readings, degC.
fn disc_temp0(log: &RunLog) -> Option<f64> {
    let firsts: Vec<f64> = log
        .t_disc_c
        .iter()
        .flatten()
        .filter_map(|c| {
            let k: Vec<f64> = c
                .iter()
                .take(10)
                .filter(|x| x.is_finite())
                .copied()
                .collect();
            (!k.is_empty()).then(|| k.iter().sum::<f64>() / k.len() as f64)
        })
        .collect();
    (!firsts.is_empty()).then(|| firsts.iter().sum::<f64>() / firsts.len() as f64)
}

/// Bin means of the mean logged disc temperature (NaN where none is logged), degC.
fn disc_temp_bin(log: &RunLog, t: &[f64], bins: &Bins) -> Vec<f64> {
    let cols: Vec<&Vec<f64>> = log.t_disc_c.iter().flatten().collect();
    if cols.is_empty() {
        return vec![f64::NAN; bins.n_bins];
    }
    let mean: Vec<f64> = (0..t.len())
        .map(|i| {
            let k: Vec<f64> = cols
                .iter()
                .map(|c| c[i])
                .filter(|x| x.is_finite())
                .collect();
            if k.is_empty() {
                f64::NAN
            } else {
                k.iter().sum::<f64>() / k.len() as f64
            }
        })
        .collect();
    bins.means(t, &mean)
}

impl Prepared {
    /// Prepares a run for replays at plant step `dt` with the baseline parameters
    /// (`rail` from the file's metadata, else the baseline's scenario rail).
    pub fn new(log: &RunLog, baseline: &Params, dt: f64) -> Prepared {
        let t0 = log.t_s[0];
        let t: Vec<f64> = log.t_s.iter().map(|x| x - t0).collect();
        let duration = *t.last().unwrap_or(&0.0);
        let mut notes = Vec::new();
        let (rail, rail_from_metadata) = match log.rail {
            Some(r) => (r, true),
            None => {
                notes.push(format!(
                    "no `rail` metadata: the baseline scenario's rail ({}) is used",
                    rail_name(Rail::default())
                ));
                (Rail::default(), false)
            }
        };
        let inputs = BrakeInputs::new(log, &t, &mut notes);
        let disc_temp_input = disc_temp_inputs(log, &t, duration, &mut notes);
        let bins = Bins::new(log, duration);
        let v_bin = bins.means(&t, &log.v_ref_mps);
        let r_w = baseline.vehicle.wheel_radius;
        let wheel_speed: [Vec<f64>; WHEELSETS] =
            std::array::from_fn(|j| log.omega_radps[j].iter().map(|w| w * r_w).collect());
        let wheel_bin: [Vec<f64>; WHEELSETS] =
            std::array::from_fn(|j| bins.means(&t, &wheel_speed[j]));
        let v0 = initial_speed_median(&t, &log.v_ref_mps, &wheel_speed);
        let channels = ChannelSetup {
            t: &t,
            bins: &bins,
            v_bin: &v_bin,
            wheel_bin: &wheel_bin,
            v0,
        }
        .channels(log, &wheel_speed, &inputs.pressure_obs);
        let clamp_bin = bins.means(&t, &inputs.mean_clamp_force(baseline, t.len()));
        let disc_temp_bin = disc_temp_bin(log, &t, &bins);
        let mut run = Prepared {
            name: log.name(),
            rail,
            rail_from_metadata,
            t0,
            t,
            duration,
            v0,
            disc_temp0: disc_temp0(log),
            input_kind: inputs.kind,
            input: inputs.input,
            pressure_obs: inputs.pressure_obs,
            disc_temp_input,
            bin_s: bins.bin_s,
            n_bins: bins.n_bins,
            validation: bins.validation,
            channels,
            v_bin,
            wheel_bin,
            bin_time: bins.bin_time,
            wsp_any: std::array::from_fn(|j| {
                log.wsp[j]
                    .as_ref()
                    .is_some_and(|w| w.iter().any(|&x| x == 1.0))
            }),
            wsp_logged: log.wsp.iter().any(|w| w.is_some()),
            clamp_bin,
            disc_temp_bin,
            notes,
            dt,
            step_map: Vec::new(),
        };
        run.set_step(dt);
        run
    }

    /// Sets the replay step and the input interpolation map.
    pub fn set_step(&mut self, dt: f64) {
        self.dt = dt;
        let steps = (self.duration / dt).ceil() as usize + 1;
        let mut map = Vec::with_capacity(steps + 1);
        let mut i = 0usize;
        for k in 0..=steps {
            let tk = k as f64 * dt;
            while i + 1 < self.t.len() && self.t[i + 1] <= tk {
                i += 1;
            }
            let w = if i + 1 < self.t.len() {
                ((tk - self.t[i]) / (self.t[i + 1] - self.t[i])).clamp(0.0, 1.0)
            } else {
                0.0
            };
            map.push((i as u32, w as f32));
        }
        self.step_map = map;
    }

    /// Slow, correlated error of v_ref (a radar's drift, a reference axle's creep): the part
    /// of v_ref's replay error that the rolling wheels do not share, d = e_v - median_j e_w,
    /// robust RMS (median of d^2 over that of a chi-square with one degree of freedom).
    /// A model error moves v_ref and the wheels alike and cancels in d; a sensor error of
    /// v_ref does not. None when fewer than 20 bins have two rolling wheels.
    pub fn vref_slow_sigma(&self, rep: &Replay) -> Option<f64> {
        let iv = self
            .channels
            .iter()
            .position(|c| c.quantity == Quantity::VRef)?;
        // Model-minus-measured wheel errors per bin, rolling wheels only.
        let mut wheel_err: Vec<Vec<f64>> = vec![Vec::new(); self.n_bins];
        for (c, pred) in self.channels.iter().zip(&rep.predicted) {
            let Quantity::WheelSpeed(j) = c.quantity else {
                continue;
            };
            for (k, &b) in c.bins.iter().enumerate() {
                let slip = self.v_bin[b] - self.wheel_bin[j][b];
                if slip.is_finite() && slip.abs() < 0.3 && self.v_bin[b] > 1.0 {
                    wheel_err[b].push(pred[k] - c.measured[k]);
                }
            }
        }
        let cv = &self.channels[iv];
        let mut d2: Vec<f64> = Vec::new();
        for (k, &b) in cv.bins.iter().enumerate() {
            let w = &mut wheel_err[b];
            if w.len() < 2 {
                continue;
            }
            w.sort_by(f64::total_cmp);
            let n = w.len();
            let med = if n % 2 == 1 {
                w[n / 2]
            } else {
                0.5 * (w[n / 2 - 1] + w[n / 2])
            };
            let d = rep.predicted[iv][k] - cv.measured[k] - med;
            if d.is_finite() {
                d2.push(d * d);
            }
        }
        if d2.len() < 20 {
            return None;
        }
        d2.sort_by(f64::total_cmp);
        Some((d2[d2.len() / 2] / 0.455).sqrt())
    }

    /// Raises v_ref's bin sigmas to at least `sigma` (its slow error, see
    /// [`Prepared::vref_slow_sigma`]).
    pub fn set_vref_slow_sigma(&mut self, sigma: f64) {
        for c in self.channels.iter_mut() {
            if c.quantity == Quantity::VRef {
                c.sigma.iter_mut().for_each(|s| *s = s.max(sigma));
            }
        }
    }

    /// Whether any wheelset has both pressure and clamp force logged.
    pub fn has_pressure_and_force(&self) -> bool {
        self.pressure_obs.iter().any(|p| p.is_some())
    }

    /// Whether any wheelset is driven by its pressure (an actuator lag shows in the dynamics).
    pub fn has_pressure_input(&self) -> bool {
        self.input_kind.contains(&InputKind::Pressure)
    }

    pub fn has_quantity(&self, f: impl Fn(Quantity) -> bool) -> bool {
        self.channels.iter().any(|c| f(c.quantity))
    }
}

/// A model to replay: parameters and the extensions that act on the measured signals.
#[derive(Clone, Debug)]
pub struct Model {
    pub params: Params,
    /// Gain of each wheelset's brake-input sensor (reading = gain x true).
    pub input_gain: [f64; WHEELSETS],
    /// Gain of each pressure sensor that is only an observation (both logged).
    pub pressure_obs_gain: [f64; WHEELSETS],
    /// Lag of the pad force behind the cylinder pressure, s.
    pub actuator_lag_s: f64,
    /// Scale of each wheelset's brake torque for the same clamp force (a pad friction that
    /// differs per wheelset, [`super::effects::Effect::WheelsetFriction`]; 1 = none).
    pub wheelset_mu_scale: [f64; WHEELSETS],
}

impl Model {
    pub fn new(params: &Params) -> Self {
        let mut params = *params;
        let lag = params.brake.actuator_lag_s;
        // The replay applies the lag itself (to pressure-driven wheelsets only).
        params.brake.actuator_lag_s = 0.0;
        Model {
            params,
            input_gain: [1.0; WHEELSETS],
            pressure_obs_gain: [1.0; WHEELSETS],
            actuator_lag_s: lag,
            wheelset_mu_scale: [1.0; WHEELSETS],
        }
    }
}

/// Model predictions for one run.
#[derive(Clone, Debug)]
pub struct Replay {
    /// Per channel (as in `Prepared::channels`): model value at each bin's time.
    pub predicted: Vec<Vec<f64>>,
    /// Model bin values of v and wheel speeds (NaN where the run has no bin), for slides.
    pub v_bin: Vec<f64>,
    pub wheel_bin: [Vec<f64>; WHEELSETS],
    /// Per-bin model traces for the report (bin centres): mu_d, disc temp, creepage, clamp.
    pub mu_d_bin: [Vec<f64>; WHEELSETS],
    pub disc_temp_bin: [Vec<f64>; WHEELSETS],
    /// Plant flags or-ed over the replay.
    pub flags: u32,
}

/// First-order lag a' = a + (x - a)(1 - e^(-dt/tau)) (exact for a held input).
fn lag_gain(dt: f64, tau: f64) -> f64 {
    if tau > 0.0 {
        1.0 - (-dt / tau).exp()
    } else {
        1.0
    }
}

/// Which model outputs to record each step.
const TRACE: usize = 4 + 4 * WHEELSETS + 1;

/// Replays `run` in `model`. Returns None when the parameters are refused.
pub fn replay(run: &Prepared, model: &Model) -> Option<Replay> {
    let mut params = model.params;
    if let Some(td) = run.disc_temp0 {
        params.thermal.ambient_rise = td;
    }
    let dt = run.dt;
    let caliper = Caliper::<f64>::new(&params.brake);
    let lag = lag_gain(dt, model.actuator_lag_s);
    let traces = drive(run, model, &params, &caliper, lag)?;
    let pad_obs = pad_from_pressure(run, model, &caliper, lag);
    let steps = traces.steps();
    let interp = |col: usize, t: f64| -> f64 { at_time(|k| traces.trace[k][col], steps, dt, t) };
    // The measured clamp force is compared with the true pad force: reading / input gain.
    let predicted: Vec<Vec<f64>> = run
        .channels
        .iter()
        .map(|c| {
            c.times
                .iter()
                .map(|&t| match c.quantity {
                    Quantity::VRef => interp(0, t),
                    Quantity::Accel => interp(1, t),
                    Quantity::WheelSpeed(j) => interp(4 + 4 * j, t),
                    Quantity::BrakeForce(j) => interp(5 + 4 * j, t),
                    Quantity::AxleLoad(j) => interp(6 + 4 * j, t),
                    Quantity::DiscTemp(j) => interp(7 + 4 * j, t),
                    // Measured clamp reading = gain x true pad force; predicted reading:
                    Quantity::PadFromPressure(j) => pad_obs[j]
                        .as_ref()
                        .map(|s| at_time(|k| s[k], steps, dt, t) * model.input_gain[j])
                        .unwrap_or(f64::NAN),
                })
                .collect()
        })
        .collect();
    let bin_vals = |col: usize| -> Vec<f64> {
        run.bin_time
            .iter()
            .map(|&t| interp(col, t.min(run.duration)))
            .collect()
    };
    let mu_bin = |j: usize| -> Vec<f64> {
        run.bin_time
            .iter()
            .map(|&t| {
                let k = ((t.min(run.duration) / dt).round() as usize).min(steps);
                traces.mu_trace[k][j]
            })
            .collect()
    };
    Some(Replay {
        predicted,
        v_bin: bin_vals(0),
        wheel_bin: std::array::from_fn(|j| bin_vals(4 + 4 * j)),
        mu_d_bin: std::array::from_fn(mu_bin),
        disc_temp_bin: std::array::from_fn(|j| bin_vals(7 + 4 * j)),
        flags: traces.flags,
    })
}

/// The plant's outputs at every replay step.
struct Traces {
    /// v, a_x, then per wheelset speed, f_brake, q, t_disc.
    trace: Vec<[f64; TRACE]>,
    mu_trace: Vec<[f64; WHEELSETS]>,
    flags: u32,
}

impl Traces {
    fn steps(&self) -> usize {
        self.trace.len() - 1
    }
}

/// Input `x` at replay step `k` (linear between the log's samples).
fn at_step(run: &Prepared, x: &[f64], k: usize) -> f64 {
    let (i, w) = run.step_map[k];
    let i = i as usize;
    if i + 1 < x.len() {
        x[i] + (x[i + 1] - x[i]) * w as f64
    } else {
        x[i]
    }
}

/// A series recorded at every step (`x(k)`, `steps` + 1 values) at time `t`, linear.
fn at_time(x: impl Fn(usize) -> f64, steps: usize, dt: f64, t: f64) -> f64 {
    let q = t / dt;
    let k = (q.floor() as usize).min(steps);
    let w = q - k as f64;
    if k < steps {
        x(k) + (x(k + 1) - x(k)) * w
    } else {
        x(k)
    }
}

/// Drives the plant with the run's measured brake inputs (None: a numeric fault).
fn drive(
    run: &Prepared,
    model: &Model,
    params: &Params,
    caliper: &Caliper<f64>,
    lag: f64,
) -> Option<Traces> {
    let mut plant = Plant::<f64>::with_step(params, run.rail, run.v0, run.dt).ok()?;
    let friction = DiscPadFriction::<f64>::new(&params.friction);
    let measured_temp = params.friction.model == hils_plant::FrictionModel::Variable;
    let r_w = params.vehicle.wheel_radius;
    let clamp_of = |j: usize, x: f64| -> f64 {
        let reading = x / model.input_gain[j];
        match run.input_kind[j] {
            InputKind::ClampForce => reading,
            InputKind::Pressure => caliper.clamp_force(reading),
        }
    };
    // Pressure-driven wheelsets: pad force lags the pressure.
    let mut pad: [f64; WHEELSETS] = std::array::from_fn(|j| clamp_of(j, run.input[j][0]));
    let steps = run.step_map.len() - 1;
    let mut trace: Vec<[f64; TRACE]> = Vec::with_capacity(steps + 1);
    let mut mu_trace: Vec<[f64; WHEELSETS]> = Vec::with_capacity(steps + 1);
    trace.push(trace_row(&plant.outputs(), r_w));
    let scale = model.wheelset_mu_scale;
    mu_trace.push(std::array::from_fn(|j| {
        plant.outputs().wheelsets[j].mu_d * scale[j]
    }));
    let mut inputs = [BrakeInput::ClampForce(0.0); WHEELSETS];
    for k in 0..steps {
        for j in 0..WHEELSETS {
            let target = clamp_of(j, at_step(run, &run.input[j], k));
            let f = match run.input_kind[j] {
                InputKind::ClampForce => target,
                InputKind::Pressure => {
                    pad[j] += (target - pad[j]) * lag;
                    pad[j]
                }
            };
            // Eq (2) at the measured disc temperature: the pad force scaled by the ratio of
            // the temperature brackets (measured over modelled disc temperature).
            let f = match (&run.disc_temp_input[j], measured_temp) {
                (Some(td), true) => {
                    let model_td = plant.outputs().wheelsets[j].disc_temp;
                    f * friction.temperature_factor(at_step(run, td, k))
                        / friction.temperature_factor(model_td)
                }
                _ => f,
            };
            // A wheelset's own pad friction scales its torque as a scaled clamp force
            // would (the clamp force itself is the measured one).
            inputs[j] = BrakeInput::ClampForce(f * model.wheelset_mu_scale[j]);
        }
        plant.step(&inputs);
        let o = plant.outputs();
        trace.push(trace_row(&o, r_w));
        let scale = model.wheelset_mu_scale;
        mu_trace.push(std::array::from_fn(|j| o.wheelsets[j].mu_d * scale[j]));
    }
    let flags = plant.sticky_flags().0;
    if flags & hils_plant::Flags::NUMERIC_FAULT != 0 {
        return None;
    }
    Some(Traces {
        trace,
        mu_trace,
        flags,
    })
}

/// One row of [`Traces::trace`] from the plant's outputs (`r_w`: wheel radius, m).
fn trace_row(o: &hils_plant::Outputs<f64>, r_w: f64) -> [f64; TRACE] {
    let mut row = [0.0; TRACE];
    row[0] = o.vehicle_speed;
    row[1] = o.carbody_accel;
    for j in 0..WHEELSETS {
        let w = &o.wheelsets[j];
        row[4 + 4 * j] = w.omega * r_w;
        row[5 + 4 * j] = w.brake_force;
        row[6 + 4 * j] = w.axle_load;
        row[7 + 4 * j] = w.disc_temp;
    }
    row
}

/// Pad force predicted from pressure (observation channel): Eq (1) with the sensor gain,
/// lagged, at every step.
fn pad_from_pressure(
    run: &Prepared,
    model: &Model,
    caliper: &Caliper<f64>,
    lag: f64,
) -> [Option<Vec<f64>>; WHEELSETS] {
    let steps = run.step_map.len() - 1;
    let mut pad_obs: [Option<Vec<f64>>; WHEELSETS] = Default::default();
    for j in 0..WHEELSETS {
        if let Some(p) = &run.pressure_obs[j] {
            let g = model.pressure_obs_gain[j];
            let mut a = caliper.clamp_force(p[0] / g);
            let mut series = Vec::with_capacity(steps + 1);
            series.push(a);
            for k in 0..steps {
                let target = caliper.clamp_force(at_step(run, p, k) / g);
                a += (target - a) * lag;
                series.push(a);
            }
            pad_obs[j] = Some(series);
        }
    }
    pad_obs
}

/// Which bins a score uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Split {
    Fit,
    Validation,
    All,
}

impl Split {
    pub fn takes(self, validation: bool) -> bool {
        match self {
            Split::Fit => !validation,
            Split::Validation => validation,
            Split::All => true,
        }
    }
}

/// Weighted residuals (model - measured) / sigma of the fitted channels on a split.
pub fn weighted_residuals(run: &Prepared, rep: &Replay, split: Split, out: &mut Vec<f64>) {
    for (c, pred) in run.channels.iter().zip(&rep.predicted) {
        if !c.quantity.group().fitted() {
            continue;
        }
        for (k, &b) in c.bins.iter().enumerate() {
            if split.takes(run.validation[b]) {
                out.push((pred[k] - c.measured[k]) / c.sigma[k]);
            }
        }
    }
}

/// Length of the windows in which a localised discrepancy is looked for, s.
pub const WINDOW_S: f64 = 1.0;
/// A window's normalised RMS above this flags it as showing an error beyond the noise.
pub const WINDOW_FLAG_RMS: f64 = 1.5;
/// Windows with fewer residuals are not judged alone.
pub const WINDOW_MIN_COUNT: usize = 8;

/// Key of a window: (run, channel group, window index).
pub type WindowKey = (usize, Group, usize);

/// Error summary of one replay on a split.
#[derive(Clone, Debug, Default)]
pub struct Score {
    /// Sum of squared normalised residuals of the fitted channels, and their count.
    pub sum_sq: f64,
    pub count: usize,
    /// Sum of squared speed errors (v_ref and r omega), m^2/s^2, and their count.
    pub speed_sum_sq: f64,
    pub speed_count: usize,
    /// The same sums per window of [`WINDOW_S`] and channel group.
    pub windows: std::collections::BTreeMap<WindowKey, (f64, usize)>,
}

impl Score {
    /// Adds another run's score (its windows re-keyed to run `run`).
    pub fn add_run(&mut self, run: usize, other: &Score) {
        self.sum_sq += other.sum_sq;
        self.count += other.count;
        self.speed_sum_sq += other.speed_sum_sq;
        self.speed_count += other.speed_count;
        for (&(_, g, w), &(s, n)) in &other.windows {
            let e = self.windows.entry((run, g, w)).or_insert((0.0, 0));
            e.0 += s;
            e.1 += n;
        }
    }
    /// RMS of the normalised residuals (1 = the noise level).
    pub fn rms(&self) -> f64 {
        if self.count == 0 {
            0.0
        } else {
            (self.sum_sq / self.count as f64).sqrt()
        }
    }
    /// RMS of the speed errors, m/s.
    pub fn speed_rms(&self) -> f64 {
        if self.speed_count == 0 {
            0.0
        } else {
            (self.speed_sum_sq / self.speed_count as f64).sqrt()
        }
    }
    /// Windows whose RMS exceeds [`WINDOW_FLAG_RMS`].
    pub fn flagged(&self) -> std::collections::BTreeSet<WindowKey> {
        self.windows
            .iter()
            .filter(|(_, (s, n))| {
                *n >= WINDOW_MIN_COUNT && (s / *n as f64).sqrt() > WINDOW_FLAG_RMS
            })
            .map(|(k, _)| *k)
            .collect()
    }
    /// The largest window RMS.
    pub fn max_window_rms(&self) -> f64 {
        self.windows
            .values()
            .filter(|(_, n)| *n >= WINDOW_MIN_COUNT)
            .map(|(s, n)| (s / *n as f64).sqrt())
            .fold(0.0, f64::max)
    }
    /// RMS over a set of windows.
    pub fn rms_over(&self, keys: &std::collections::BTreeSet<WindowKey>) -> f64 {
        let (mut s, mut n) = (0.0, 0usize);
        for k in keys {
            if let Some((a, b)) = self.windows.get(k) {
                s += a;
                n += b;
            }
        }
        if n == 0 { 0.0 } else { (s / n as f64).sqrt() }
    }
}

/// Two models' errors compared where either shows an error beyond the noise: the RMS of
/// each over the union of their flagged windows (over everything when neither has one).
/// This is the metric of every decision and of `gain`: an error confined to a short
/// transient (a brake application, a slide) is not diluted by the rest of the run.
pub fn compare(a: &Score, b: &Score) -> ComparedRms {
    let mut keys = a.flagged();
    keys.extend(b.flagged());
    let (reference, candidate) = if keys.is_empty() {
        (a.rms(), b.rms())
    } else {
        (a.rms_over(&keys), b.rms_over(&keys))
    };
    ComparedRms {
        reference,
        candidate,
    }
}

/// Two models' errors over the same windows ([`compare`]), in noise units.
#[derive(Clone, Copy, Debug)]
pub struct ComparedRms {
    /// RMS of the first (the reference: baseline, current set, simpler fit).
    pub reference: f64,
    /// RMS of the second (the candidate compared with it).
    pub candidate: f64,
}

pub fn score(run: &Prepared, rep: &Replay, split: Split) -> Score {
    let mut s = Score::default();
    for (c, pred) in run.channels.iter().zip(&rep.predicted) {
        let group = c.quantity.group();
        let fitted = group.fitted();
        let speed = group == Group::Speeds;
        for (k, &b) in c.bins.iter().enumerate() {
            if !split.takes(run.validation[b]) {
                continue;
            }
            let e = pred[k] - c.measured[k];
            if fitted {
                let z2 = (e / c.sigma[k]).powi(2);
                s.sum_sq += z2;
                s.count += 1;
                let w = (c.times[k] / WINDOW_S) as usize;
                let entry = s.windows.entry((0, group, w)).or_insert((0.0, 0));
                entry.0 += z2;
                entry.1 += 1;
            }
            if speed {
                s.speed_sum_sq += e * e;
                s.speed_count += 1;
            }
        }
    }
    s
}

/// Per-channel RMS error (units of the channel) of a replay on all bins.
pub fn channel_rms(run: &Prepared, rep: &Replay) -> Vec<(Quantity, f64, f64)> {
    run.channels
        .iter()
        .zip(&rep.predicted)
        .map(|(c, p)| {
            let n = c.measured.len().max(1) as f64;
            let e2: f64 = c
                .measured
                .iter()
                .zip(p)
                .map(|(m, p)| (p - m) * (p - m))
                .sum();
            (c.quantity, (e2 / n).sqrt(), c.noise)
        })
        .collect()
}

/// Slide threshold: a wheel slides when v - r omega exceeds max(0.5 m/s, 5 % of v) while the
/// vehicle runs faster than 1.5 m/s (the speed deficit a WSP acts on).
pub fn slides(v: &[f64], wheel: &[Vec<f64>; WHEELSETS]) -> [bool; WHEELSETS] {
    std::array::from_fn(|j| {
        v.iter().zip(&wheel[j]).any(|(&v, &w)| {
            v.is_finite() && w.is_finite() && v > 1.5 && v - w > (0.05 * v).max(0.5)
        })
    })
}

/// The plant step the replays use, s, and the reason (accuracy checked in the tests).
pub const REPLAY_STEP_S: f64 = 1.0e-3;

/// Smallest step the plant accepts for these parameters (tries 1 ms, then 0.5, 0.2, 0.1 ms).
pub fn replay_step(params: &Params, rail: Rail) -> f64 {
    for dt in [REPLAY_STEP_S, 5e-4, 2e-4, 1e-4] {
        if Plant::<f64>::with_step(params, rail, 10.0, dt).is_ok() {
            return dt;
        }
    }
    1e-4
}

/// Most plant steps one replay may take: its traces hold `TRACE + WHEELSETS` f64 and a
/// map entry per step (about 210 bytes), so 1 M steps are about 210 MB per replay (1000 s
/// at 1 ms). Longer is refused before anything is allocated (issue 12).
pub const MAX_REPLAY_STEPS: f64 = 1.0e6;

/// What a log asks of a replay at step `dt_s`: an error naming the file, its last row
/// and its time column when the steps exceed [`MAX_REPLAY_STEPS`].
pub fn check_budget(log: &RunLog, dt_s: f64) -> Result<(), crate::measured::MeasuredError> {
    let span_s = match (log.t_s.first(), log.t_s.last()) {
        (Some(a), Some(b)) => b - a,
        _ => 0.0,
    };
    let steps = span_s / dt_s;
    if steps <= MAX_REPLAY_STEPS {
        return Ok(());
    }
    let bytes = steps * ((TRACE + WHEELSETS) * 8 + 8) as f64;
    Err(crate::measured::MeasuredError {
        file: log.path.clone(),
        line: 0,
        row: log.len(),
        column: hils_sil::record::run_log::T.name(0).to_string(),
        message: format!(
            "the log spans {span_s} s: a replay at {dt_s} s steps would take {steps:.0} steps \
             (about {:.0} MB); at most {MAX_REPLAY_STEPS:.0} steps per replay",
            bytes / 1e6
        ),
    })
}
