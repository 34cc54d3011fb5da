//! Outliers in measured channels (issue 24 item 7): single-sample spikes such as the
//! electromagnetic interference on a phonic-wheel input (a sample at 0, or a jump) are
//! found, counted and kept out of the judgement (set to "not measured").
//!
//! A spike is an excursion of at most [`MAX_SPIKE_SAMPLES`] samples, spanning at most
//! [`MAX_SPIKE_S`], that departs from the line between the samples on either side of it in
//! one direction by more than the channel's tolerance, while those two samples agree with
//! each other far better than with it (so a step, a held value that changes, or a ramp is
//! never a spike). The tolerance is the largest of [`SPIKE_SIGMAS`] times the channel's
//! robust noise, [`SPIKE_RANGE_SHARE`] of its robust range and, for wheel speeds, the most
//! a wheel can depart and come back within the excursion ([`wheel_rim_accel_max_mps2`]).
//! A real slide lasts tens of milliseconds and shows on the wheel's deceleration before
//! it: it is never a spike, and a spike never counts as a slide.

use hils_plant::Params;
use hils_plant::brake::Caliper;

use crate::measured::noise_sigma;

/// Most consecutive samples one spike may take.
pub const MAX_SPIKE_SAMPLES: usize = 2;
/// Longest span of a spike's samples, s (a real slide lasts tens of ms).
pub const MAX_SPIKE_S: f64 = 0.01;
/// Smallest departure of a spike in multiples of the channel's robust sample noise (a
/// Gaussian departure this large has a probability below 1e-15).
pub const SPIKE_SIGMAS: f64 = 10.0;
/// Smallest departure of a spike as a share of the channel's robust range (quantisation,
/// held values and sensor-specific ripple stay below it).
pub const SPIKE_RANGE_SHARE: f64 = 0.02;
/// Largest friction coefficient the method considers (the friction-level fit's bound).
pub const MU_MAX: f64 = 1.5;

/// Largest circumferential acceleration of a wheel, m/s^2: the largest brake torque (MU_MAX
/// at the caliper's largest clamp force) plus the largest adhesion torque (a coefficient of
/// 1 at the static axle load), over the wheelset's spin inertia, times the wheel radius.
/// About 170 m/s^2 for the reference vehicle: a wheel cannot leave its speed and come back
/// faster.
pub fn wheel_rim_accel_max_mps2(p: &Params) -> f64 {
    let v = &p.vehicle;
    let clamp = Caliper::<f64>::new(&p.brake).clamp_force_limit;
    let brake = MU_MAX * clamp * p.brake.friction_faces as f64 * p.brake.friction_radius;
    let axle_load = p.total_mass() * v.g / hils_plant::WHEELSETS as f64;
    let adhesion = axle_load * v.wheel_radius;
    (brake + adhesion) / v.wheelset_spin_inertia * v.wheel_radius
}

/// Value at quantile `q` of the sorted slice.
fn quantile(sorted: &[f64], q: f64) -> f64 {
    sorted[((sorted.len() - 1) as f64 * q).round() as usize]
}

/// The channel's tolerance for spikes (see the module doc) before the physical bound.
fn base_tolerance(t: &[f64], x: &[f64]) -> f64 {
    let mut sorted = x.to_vec();
    sorted.sort_by(f64::total_cmp);
    let range = quantile(&sorted, 0.999) - quantile(&sorted, 0.001);
    (SPIKE_SIGMAS * noise_sigma(t, x)).max(SPIKE_RANGE_SHARE * range)
}

/// Whether samples `k..k + m` (of the finite samples `t`, `x`) are a spike of `m` samples
/// with tolerance `tol` plus `rate` (units per s) times half the span between the samples
/// around it.
fn is_spike(t: &[f64], x: &[f64], k: usize, m: usize, tol: f64, rate: f64) -> bool {
    let (a, c) = (k - 1, k + m);
    if t[k + m - 1] - t[k] > MAX_SPIKE_S {
        return false;
    }
    let tol = tol + rate * (t[c] - t[a]) / 2.0;
    let mut smallest = f64::INFINITY;
    let mut sign = 0.0;
    for i in k..k + m {
        let line = x[a] + (x[c] - x[a]) * (t[i] - t[a]) / (t[c] - t[a]);
        let d = x[i] - line;
        if d.abs() <= tol || (sign != 0.0 && d.signum() != sign) {
            return false;
        }
        sign = d.signum();
        smallest = smallest.min(d.abs());
    }
    (x[c] - x[a]).abs() < 0.5 * smallest
}

/// Indices (into `x`) of the spike samples of a channel sampled at `t`; `rate` is the
/// channel's largest physical rate of change (units per s; 0 where none is used). Empty
/// (NaN) cells are skipped: neighbours are the finite samples around.
pub fn spike_indices(t: &[f64], x: &[f64], rate: f64) -> Vec<usize> {
    let idx: Vec<usize> = (0..x.len()).filter(|&i| x[i].is_finite()).collect();
    if idx.len() < 8 {
        return Vec::new();
    }
    let ts: Vec<f64> = idx.iter().map(|&i| t[i]).collect();
    let xs: Vec<f64> = idx.iter().map(|&i| x[i]).collect();
    let tol = base_tolerance(&ts, &xs);
    let mut out = Vec::new();
    let mut k = 1;
    while k + 1 < xs.len() {
        let width = (1..=MAX_SPIKE_SAMPLES)
            .take_while(|m| k + m < xs.len())
            .find(|&m| is_spike(&ts, &xs, k, m, tol, rate));
        match width {
            Some(m) => {
                out.extend(idx[k..k + m].iter().copied());
                k += m;
            }
            None => k += 1,
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A braking wheel at 1 kHz: speed falling at 1 m/s^2 with noise-free 10 ms held values
    /// (a phonic wheel read by an ECU), plus one sample at 0 and one two-sample jump.
    fn wheel() -> (Vec<f64>, Vec<f64>) {
        let t: Vec<f64> = (0..3000).map(|i| i as f64 * 1e-3).collect();
        let x = t
            .iter()
            .map(|&ti| {
                let held = (ti / 0.01).floor() * 0.01;
                (30.0 - 1.0 * held) / 0.43
            })
            .collect();
        (t, x)
    }

    #[test]
    fn spikes_found_and_held_values_kept() {
        let (t, mut x) = wheel();
        let rate = wheel_rim_accel_max_mps2(&Params::default()) / 0.43;
        assert!(spike_indices(&t, &x, rate).is_empty());
        x[500] = 0.0;
        x[1700] += 20.0;
        x[1701] += 19.0;
        assert_eq!(spike_indices(&t, &x, rate), vec![500, 1700, 1701]);
    }

    #[test]
    fn a_slide_is_no_spike() {
        // The wheel falls 3 m/s below the vehicle over 60 ms and recovers over 100 ms.
        let (t, mut x) = wheel();
        for (i, xi) in x.iter_mut().enumerate().skip(1000).take(160) {
            let k = (i - 1000) as f64;
            let dip = if k < 60.0 {
                k / 60.0
            } else {
                1.0 - (k - 60.0) / 100.0
            };
            *xi -= 3.0 / 0.43 * dip;
        }
        let rate = wheel_rim_accel_max_mps2(&Params::default()) / 0.43;
        assert!(spike_indices(&t, &x, rate).is_empty());
    }

    #[test]
    fn a_step_is_no_spike() {
        let t: Vec<f64> = (0..100).map(|i| i as f64 * 1e-2).collect();
        let x: Vec<f64> = (0..100).map(|i| if i < 50 { 0.0 } else { 3.5e5 }).collect();
        assert!(spike_indices(&t, &x, 0.0).is_empty());
    }
}
