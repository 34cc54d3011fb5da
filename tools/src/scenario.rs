//! Closed-loop scenarios (plant + simulated brake unit): the paper's emergency brake.

use std::time::Instant;

use anyhow::{Result, anyhow};
use hils_brake_unit::{BrakeDemand, ClosedLoop, UnitConfig};
use hils_plant::{FrictionModel, Params, Rail, Real, WHEELSETS};
use serde::Serialize;

/// One recorded sample of a run (SI units, f64 whatever the plant's precision).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Sample {
    pub t: f64,
    /// Carbody (true vehicle) speed, m/s.
    pub v_ref: f64,
    pub distance: f64,
    pub a_x: f64,
    pub eb: bool,
    pub omega: [f64; 4],
    pub p_cyl: [f64; 4],
    pub f_clamp: [f64; 4],
    pub f_brake: [f64; 4],
    pub t_disc: [f64; 4],
    pub q: [f64; 4],
    pub wsp: [bool; 4],
    pub mu_d: [f64; 4],
    pub creepage: [f64; 4],
    pub adhesion: [f64; 4],
    /// The brake unit's reference-speed estimate, m/s.
    pub v_ref_estimate: f64,
}

/// Options of a closed-loop EB run.
#[derive(Clone, Debug)]
pub struct EbOptions {
    pub rail: Rail,
    pub initial_speed_mps: f64,
    /// Record every this many plant steps (10 = 1 kHz at 0.1 ms).
    pub record_every: u32,
    /// Keep running this long after the stop, s.
    pub after_stop_s: f64,
    /// Give up this long after the EB command if the vehicle has not stopped, s.
    pub max_time_s: f64,
    /// Show a progress bar (runs longer than a second).
    pub progress: bool,
    pub unit: Option<UnitConfig>,
}

impl EbOptions {
    /// The paper's scenario as the parameter file describes it.
    pub fn paper(params: &Params) -> Self {
        let sc = &params.scenario.paper_eb;
        Self {
            rail: sc.rail,
            initial_speed_mps: sc.initial_speed_kmh / 3.6,
            record_every: 10,
            after_stop_s: 1.0,
            max_time_s: 120.0,
            progress: false,
            unit: None,
        }
    }
}

/// The summary of a run: `summary.json` (keys fixed by the plant issue).
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct Summary {
    pub stop_time_s: Option<f64>,
    pub stopping_distance_m: Option<f64>,
    pub slides: Vec<usize>,
    pub slide_onset_s: [Option<f64>; 4],
    pub axle_loads_static_n: [f64; 4],
    pub axle_loads_3s_n: [f64; 4],
    pub mu_d_at_s: std::collections::BTreeMap<String, f64>,
    pub mu_d_min: f64,
    pub mu_d_end: f64,
    pub peak_disc_temp_rise_c: [f64; 4],
    pub eb_pressure_pa: f64,
    pub steps: u64,
    pub wall_s: f64,
}

/// A finished run.
#[derive(Clone, Debug)]
pub struct Run {
    pub samples: Vec<Sample>,
    pub summary: Summary,
    /// Plant step, s.
    pub dt: f64,
    pub friction: FrictionModel,
    pub rail: Rail,
    pub initial_speed_mps: f64,
    /// Longest continuous lock (wheel below half the vehicle speed, above 5 km/h) per
    /// wheelset, s.
    pub longest_lock_s: [f64; 4],
    /// Flags the plant raised (or-ed over the run).
    pub plant_flags: u32,
}

fn record<F: Real>(sim: &ClosedLoop<F>, eb: bool) -> Sample {
    let o = sim.outputs();
    let u = sim.unit_outputs();
    let f = |x: F| x.to_f64();
    let w = |g: &dyn Fn(usize) -> f64| [g(0), g(1), g(2), g(3)];
    Sample {
        t: f(sim.plant.time()),
        v_ref: f(o.vehicle_speed),
        distance: f(o.distance),
        a_x: f(o.carbody_accel),
        eb,
        omega: w(&|j| f(o.wheelsets[j].omega)),
        p_cyl: w(&|j| f(u.cylinder_pressure[j])),
        f_clamp: w(&|j| f(o.wheelsets[j].clamp_force)),
        f_brake: w(&|j| f(o.wheelsets[j].brake_force)),
        t_disc: w(&|j| f(o.wheelsets[j].disc_temp)),
        q: w(&|j| f(o.wheelsets[j].axle_load)),
        wsp: [0, 1, 2, 3].map(|j| u.venting[j]),
        mu_d: w(&|j| f(o.wheelsets[j].mu_d)),
        creepage: w(&|j| f(o.wheelsets[j].creepage)),
        adhesion: w(&|j| f(o.wheelsets[j].adhesion)),
        v_ref_estimate: f(u.reference_speed),
    }
}

/// Runs an emergency brake: EB command at t = 0 from `opts.initial_speed_mps`, until the
/// carbody speed falls to 0.01 m/s, plus `after_stop_s`.
pub fn run_eb<F: Real>(params: &Params, opts: &EbOptions) -> Result<Run> {
    let started = Instant::now();
    let config = opts
        .unit
        .unwrap_or_else(|| UnitConfig::new(params.scenario.paper_eb.step));
    let mut sim =
        ClosedLoop::<F>::with_config(params, opts.rail, F::of(opts.initial_speed_mps), &config)
            .map_err(|e| anyhow!("cannot build the simulation: {e}"))?;
    let dt = config.dt;
    let static_loads = sim.outputs().wheelsets.map(|w| w.axle_load.to_f64());
    sim.set_demand(BrakeDemand::Emergency);

    let max_steps = (opts.max_time_s / dt).ceil() as u64;
    let after_steps = (opts.after_stop_s / dt).ceil() as u64;
    let mut samples = vec![record(&sim, true)];
    let mut stop: Option<(u64, f64, f64)> = None;
    let mut at_3s = None;
    let steps_3s = (3.0 / dt).round() as u64;
    let mut peak_temp = [0.0f64; 4];
    let mut mu_d_min = f64::INFINITY;
    let mut lock_run = [0.0f64; 4];
    let mut longest_lock = [0.0f64; 4];
    // The bar appears only once a run has taken a second (short runs stay quiet).
    let bar = opts.progress.then(|| {
        let bar = indicatif::ProgressBar::with_draw_target(
            Some(max_steps),
            indicatif::ProgressDrawTarget::hidden(),
        );
        bar.set_style(
            indicatif::ProgressStyle::with_template(
                "{spinner} simulated {msg} [{bar:30}] {pos}/{len} steps",
            )
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
        );
        bar
    });
    let mut bar_shown = false;
    let mut steps = 0u64;
    let radius = sim.plant.wheel_radius().to_f64();
    while steps < max_steps {
        let o = sim.step();
        steps += 1;
        let v = o.vehicle_speed.to_f64();
        let mut mu_sum = 0.0;
        for j in 0..WHEELSETS {
            let w = &o.wheelsets[j];
            peak_temp[j] = peak_temp[j].max(w.disc_temp.to_f64());
            mu_sum += w.mu_d.to_f64();
            // Lock: the wheel below half the vehicle speed while the vehicle runs > 5 km/h.
            let wheel = w.omega.to_f64() * radius;
            if v > 5.0 / 3.6 && wheel < 0.5 * v {
                lock_run[j] += dt;
                longest_lock[j] = longest_lock[j].max(lock_run[j]);
            } else {
                lock_run[j] = 0.0;
            }
        }
        if stop.is_none() {
            mu_d_min = mu_d_min.min(mu_sum / 4.0);
            if v <= 0.01 {
                stop = Some((steps, steps as f64 * dt, o.distance.to_f64()));
            }
        }
        if steps == steps_3s {
            at_3s = Some(o.wheelsets.map(|w| w.axle_load.to_f64()));
        }
        if steps % opts.record_every as u64 == 0 {
            samples.push(record(&sim, true));
        }
        if let Some(bar) = &bar {
            if steps % 10_000 == 0 {
                if !bar_shown && started.elapsed().as_secs_f64() > 1.0 {
                    bar.set_draw_target(indicatif::ProgressDrawTarget::stderr());
                    bar_shown = true;
                }
                bar.set_position(steps);
                bar.set_message(format!("{:.1} s, {:.1} km/h", steps as f64 * dt, v * 3.6));
            }
        }
        if let Some((s, _, _)) = stop {
            if steps >= s + after_steps {
                break;
            }
        }
    }
    if let Some(bar) = bar {
        bar.finish_and_clear();
    }

    let mean_mu_at = |t: f64| -> f64 {
        let i = samples
            .partition_point(|s| s.t < t - 1e-9)
            .min(samples.len() - 1);
        samples[i].mu_d.iter().sum::<f64>() / 4.0
    };
    let stop_time = stop.map(|s| s.1);
    let mu_d_end = match stop_time {
        Some(t) => mean_mu_at(t),
        None => samples
            .last()
            .map(|s| s.mu_d.iter().sum::<f64>() / 4.0)
            .unwrap_or(f64::NAN),
    };
    let onsets = sim.unit.first_vent_time();
    let slides: Vec<usize> = (0..4)
        .filter(|&j| onsets[j].is_some())
        .map(|j| j + 1)
        .collect();
    let mut mu_at = std::collections::BTreeMap::new();
    for t in [0.0, 10.0, 20.0] {
        mu_at.insert(format!("{}", t as u32), mean_mu_at(t));
    }
    let summary = Summary {
        stop_time_s: stop_time,
        stopping_distance_m: stop.map(|s| s.2),
        slides,
        slide_onset_s: onsets,
        axle_loads_static_n: static_loads,
        axle_loads_3s_n: at_3s.unwrap_or([f64::NAN; 4]),
        mu_d_at_s: mu_at,
        mu_d_min,
        mu_d_end,
        peak_disc_temp_rise_c: peak_temp,
        eb_pressure_pa: sim.unit.eb_pressure().to_f64(),
        steps,
        wall_s: started.elapsed().as_secs_f64(),
    };
    Ok(Run {
        samples,
        summary,
        dt,
        friction: params.friction.model,
        rail: opts.rail,
        initial_speed_mps: opts.initial_speed_mps,
        longest_lock_s: longest_lock,
        plant_flags: sim.plant.sticky_flags().0,
    })
}
