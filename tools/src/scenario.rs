//! Closed-loop scenarios (plant + simulated brake unit): the paper's emergency brake, run
//! on the host with [`hils_sil::EbScenario`] (its stop rule) and summarised.

use std::time::Instant;

use anyhow::{Result, anyhow};
use hils_brake_unit::UnitConfig;
use hils_plant::{FrictionModel, Rail, Real, WHEELSETS};
use hils_sil::scenario::{AFTER_STOP_S, MAX_TIME_S};
use hils_sil::{ClosedLoop, Cmd, EbScenario, KMH_PER_MPS, ParamFile, RunRecord, StopRule};
use serde::Serialize;

use crate::figures::round_dp;

/// One recorded sample of a run: the run record of `hils_sil` (column names and units of
/// the run log).
pub type Sample = RunRecord;

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
    pub fn paper(file: &ParamFile) -> Self {
        let sc = &file.scenario.paper_eb;
        Self {
            rail: sc.rail,
            initial_speed_mps: sc.initial_speed_kmh / KMH_PER_MPS,
            record_every: 10,
            after_stop_s: AFTER_STOP_S,
            max_time_s: MAX_TIME_S,
            progress: false,
            unit: None,
        }
    }
}

/// The summary of a run: `summary.json` (keys fixed by the plant issue). A figure of an
/// instant the run did not reach (it stopped before) is None (`null`): mu_d at 10 s of a
/// run that stopped at 3.8 s is not reported.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct Summary {
    pub stop_time_s: Option<f64>,
    pub stopping_distance_m: Option<f64>,
    pub slides: Vec<usize>,
    pub slide_onset_s: [Option<f64>; 4],
    pub axle_loads_static_n: [f64; 4],
    /// At 3 s (None: the run stopped before).
    pub axle_loads_3s_n: Option<[f64; 4]>,
    /// Mean mu_d at 0, 10 and 20 s (None: after the stop).
    pub mu_d_at_s: std::collections::BTreeMap<String, Option<f64>>,
    pub mu_d_min: f64,
    pub mu_d_end: f64,
    pub peak_disc_temp_rise_c: [f64; 4],
    pub eb_pressure_pa: f64,
    pub steps: u64,
    pub wall_s: f64,
}

impl Summary {
    /// The summary with every figure rounded to its resolution (what `summary.json` and
    /// the terminal show): times 0.1 ms (the plant step), distance 1 mm, loads 0.1 N, mu_d
    /// 1e-4, temperatures 0.01 degC, pressure 1 Pa, wall time 1 ms.
    pub fn rounded(&self) -> Summary {
        let r = |x: f64, dp: u32| round_dp(x, dp);
        Summary {
            stop_time_s: self.stop_time_s.map(|t| r(t, 4)),
            stopping_distance_m: self.stopping_distance_m.map(|x| r(x, 3)),
            slides: self.slides.clone(),
            slide_onset_s: self.slide_onset_s.map(|t| t.map(|t| r(t, 4))),
            axle_loads_static_n: self.axle_loads_static_n.map(|q| r(q, 1)),
            axle_loads_3s_n: self.axle_loads_3s_n.map(|q| q.map(|q| r(q, 1))),
            mu_d_at_s: self
                .mu_d_at_s
                .iter()
                .map(|(k, mu)| (k.clone(), mu.map(|mu| r(mu, 4))))
                .collect(),
            mu_d_min: r(self.mu_d_min, 4),
            mu_d_end: r(self.mu_d_end, 4),
            peak_disc_temp_rise_c: self.peak_disc_temp_rise_c.map(|t| r(t, 2)),
            eb_pressure_pa: r(self.eb_pressure_pa, 0),
            steps: self.steps,
            wall_s: r(self.wall_s, 3),
        }
    }
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

/// Speed above which a wheel below half the vehicle speed counts as locked, m/s (5 km/h).
const LOCK_MIN_SPEED_MPS: f64 = 5.0 / KMH_PER_MPS;
/// Time at which the summary takes the axle loads, s (paper Fig 8B).
const AXLE_LOADS_AT_S: f64 = 3.0;
/// Steps between progress-bar updates.
const PROGRESS_EVERY: u32 = 10_000;

/// What a run keeps of every step (not only the recorded ones) for its summary.
struct Tracker {
    dt: f64,
    radius: f64,
    steps_3s: u32,
    at_3s: Option<[f64; WHEELSETS]>,
    /// (time, distance) of the stop.
    stop: Option<(f64, f64)>,
    peak_temp: [f64; WHEELSETS],
    mu_d_min: f64,
    lock_run: [f64; WHEELSETS],
    longest_lock: [f64; WHEELSETS],
}

impl Tracker {
    fn new(dt: f64, radius: f64) -> Self {
        Self {
            dt,
            radius,
            steps_3s: (AXLE_LOADS_AT_S / dt).round() as u32,
            at_3s: None,
            stop: None,
            peak_temp: [0.0; WHEELSETS],
            mu_d_min: f64::INFINITY,
            lock_run: [0.0; WHEELSETS],
            longest_lock: [0.0; WHEELSETS],
        }
    }

    fn observe<F: Real>(&mut self, o: &hils_plant::Outputs<F>, steps: u32, stop_step: Option<u32>) {
        let v = o.vehicle_speed.to_f64();
        let mut mu_sum = 0.0;
        for j in 0..WHEELSETS {
            let w = &o.wheelsets[j];
            self.peak_temp[j] = self.peak_temp[j].max(w.disc_temp.to_f64());
            mu_sum += w.mu_d.to_f64();
            // Lock: the wheel below half the vehicle speed while the vehicle runs > 5 km/h.
            let wheel = w.omega.to_f64() * self.radius;
            if v > LOCK_MIN_SPEED_MPS && wheel < 0.5 * v {
                self.lock_run[j] += self.dt;
                self.longest_lock[j] = self.longest_lock[j].max(self.lock_run[j]);
            } else {
                self.lock_run[j] = 0.0;
            }
        }
        if self.stop.is_none() {
            self.mu_d_min = self.mu_d_min.min(mu_sum / WHEELSETS as f64);
            if stop_step == Some(steps) {
                self.stop = Some((steps as f64 * self.dt, o.distance.to_f64()));
            }
        }
        if steps == self.steps_3s {
            self.at_3s = Some(o.wheelsets.map(|w| w.axle_load.to_f64()));
        }
    }
}

/// The progress bar of a long run; it appears only once a run has taken a second.
struct Progress {
    bar: indicatif::ProgressBar,
    shown: bool,
}

impl Progress {
    fn new(max_steps: u32) -> Self {
        let bar = indicatif::ProgressBar::with_draw_target(
            Some(max_steps as u64),
            indicatif::ProgressDrawTarget::hidden(),
        );
        bar.set_style(
            indicatif::ProgressStyle::with_template(
                "{spinner} simulated {msg} [{bar:30}] {pos}/{len} steps",
            )
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
        );
        Self { bar, shown: false }
    }

    fn update(&mut self, started: Instant, steps: u32, dt: f64, v: f64) {
        if steps % PROGRESS_EVERY != 0 {
            return;
        }
        if !self.shown && started.elapsed().as_secs_f64() > 1.0 {
            self.bar
                .set_draw_target(indicatif::ProgressDrawTarget::stderr());
            self.shown = true;
        }
        self.bar.set_position(steps as u64);
        self.bar.set_message(format!(
            "{:.1} s, {:.1} km/h",
            steps as f64 * dt,
            v * KMH_PER_MPS
        ));
    }
}

/// Runs an emergency brake: EB command at t = 0 from `opts.initial_speed_mps`, until the
/// stop rule of `hils_sil` ends it (carbody at 0.01 m/s, plus `after_stop_s`).
pub fn run_eb<F: Real>(file: &ParamFile, opts: &EbOptions) -> Result<Run> {
    let started = Instant::now();
    let config = opts.unit.unwrap_or_else(|| file.unit_config());
    let sim = ClosedLoop::<F>::with_config(
        &file.plant,
        opts.rail,
        F::of(opts.initial_speed_mps),
        &config,
    )
    .map_err(|e| anyhow!("cannot build the simulation: {e}"))?;
    let dt = config.step_s;
    let static_loads = sim.outputs().wheelsets.map(|w| w.axle_load.to_f64());
    let rule = StopRule::new(dt, opts.after_stop_s, opts.max_time_s);
    let mut sc = EbScenario::from_loop(sim, rule, opts.record_every);
    let mut samples = vec![RunRecord::of(&sc.sim, Cmd::Emergency)];
    let mut tracker = Tracker::new(dt, sc.sim.plant.wheel_radius().to_f64());
    let mut progress = opts.progress.then(|| Progress::new(rule.max_steps()));
    loop {
        let advance = sc.advance(|s| {
            s.step();
        });
        let steps = sc.steps();
        tracker.observe(&sc.sim.outputs(), steps, sc.stop_step());
        if advance.record {
            samples.push(RunRecord::of(&sc.sim, Cmd::Emergency));
        }
        if let Some(p) = &mut progress {
            p.update(started, steps, dt, sc.sim.outputs().vehicle_speed.to_f64());
        }
        if advance.done {
            break;
        }
    }
    if let Some(p) = progress {
        p.bar.finish_and_clear();
    }
    let summary = summarise(&sc.sim, &samples, &tracker, static_loads, started);
    Ok(Run {
        samples,
        summary,
        dt,
        friction: file.plant.friction.model,
        rail: opts.rail,
        initial_speed_mps: opts.initial_speed_mps,
        longest_lock_s: tracker.longest_lock,
        plant_flags: sc.sim.plant.sticky_flags().0,
    })
}

/// The summary of a finished run.
fn summarise<F: Real>(
    sim: &ClosedLoop<F>,
    samples: &[Sample],
    tracker: &Tracker,
    static_loads: [f64; WHEELSETS],
    started: Instant,
) -> Summary {
    let mean_mu_at = |t: f64| -> f64 {
        let i = samples
            .partition_point(|s| s.t_s < t - 1e-9)
            .min(samples.len() - 1);
        samples[i].mean_mu_d()
    };
    let stop_time = tracker.stop.map(|s| s.0);
    let mu_d_end = match stop_time {
        Some(t) => mean_mu_at(t),
        None => samples.last().map(|s| s.mean_mu_d()).unwrap_or(f64::NAN),
    };
    let onsets = sim.unit.first_vent_time();
    let slides: Vec<usize> = (0..WHEELSETS)
        .filter(|&j| onsets[j].is_some())
        .map(|j| j + 1)
        .collect();
    // Only instants within the run (up to the stop, or the last sample without one).
    let last_s = stop_time.unwrap_or_else(|| samples.last().map_or(0.0, |s| s.t_s));
    let mut mu_at = std::collections::BTreeMap::new();
    for t in [0.0, 10.0, 20.0] {
        let within = t <= last_s + 1e-9;
        mu_at.insert(format!("{}", t as u32), within.then(|| mean_mu_at(t)));
    }
    Summary {
        stop_time_s: stop_time,
        stopping_distance_m: tracker.stop.map(|s| s.1),
        slides,
        slide_onset_s: onsets,
        axle_loads_static_n: static_loads,
        axle_loads_3s_n: tracker.at_3s.filter(|_| last_s >= AXLE_LOADS_AT_S),
        mu_d_at_s: mu_at,
        mu_d_min: tracker.mu_d_min,
        mu_d_end,
        peak_disc_temp_rise_c: tracker.peak_temp,
        eb_pressure_pa: sim.unit.eb_pressure().to_f64(),
        steps: sim.outputs().steps as u64,
        wall_s: started.elapsed().as_secs_f64(),
    }
}
