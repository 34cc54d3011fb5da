//! Measured-data generator for the hidden-effect tests of the diagnosis (issue 3, item 4).
//!
//! A case runs the plant in a closed loop with the simulated brake unit
//! ([`hils_sil::ClosedLoop`], 0.1 ms, f64) with ONE effect switched on that the
//! diagnosis does not know, and writes only a run-log CSV (spec `measured-data.md`). The
//! effect, its magnitude, the scenario (speed 100-160 km/h, wet or dry rail, emergency or
//! stepped service brake, coasting before the brake command), the sample rate (100 Hz to
//! 2 kHz, uniform or jittered), the noise of every sensor, the logged column set and the
//! column order are all drawn from the seed.
//!
//! The brake unit is configured with the nominal (baseline) parameters, as a real one would
//! be: it does not know the hidden effect. For `sensor-gain` the plant is untouched and the
//! logged reading of one sensor is scaled; for `actuator-lag` the plant's pad force lags the
//! cylinder pressure (`brake.actuator_lag_s`) and both are logged.
//!
//! Column sets are drawn at random, but each effect's draw keeps what a rig engineer logs
//! to see that effect (see [`Kind`]); cases that cannot be told apart are built on purpose
//! by [`case_with`] and tested as such.

use std::fmt::Write as _;

use hils::diagnose::effects::Effect;
use hils::runlog;
use hils_brake_unit::{BrakeDemand, BrakeUnit, UnitConfig};
use hils_plant::{FrictionModel, Params, Rail, STEP_S, WHEELSETS};
use hils_sil::record::Channel;
use hils_sil::record::run_log::{
    self, A_X, CMD, F_BRAKE, F_CLAMP, OMEGA, P_CYL, Q, T, T_DISC, V_REF, WSP,
};
use hils_sil::scenario::{AFTER_STOP_S, MAX_TIME_S};
use hils_sil::{ClosedLoop, Cmd, KMH_PER_MPS, RunRecord, StopRule};
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};

/// Which effect to hide.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    /// No effect: noise only.
    None,
    /// One effect of the spec's table (the diagnosis' own list), hidden in the data.
    /// `SensorGainPressure` is drawn as `SensorGain` (which sensor follows the logged inputs).
    Hidden(Effect),
    /// The paper's case: friction speed and temperature with the Table 1 values.
    Paper,
    /// An effect outside the spec's list: the vehicle-speed sensor (radar) drifts, reading
    /// v + d t. No listed effect can explain it; the diagnosis must not blame one.
    Unlisted,
    /// One wheelset differs from the other three (issue 27; not a listed effect): the
    /// diagnosis must name no cause and localise the difference on that wheelset's link.
    Wheelset(WheelsetDiff),
}

/// What differs on one wheelset (drawn with the wheelset and the size from the seed).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WheelsetDiff {
    /// Its pads come from another batch: mu_d 10-15 % above or below the others'
    /// (the `disc-pad-friction` link of that wheelset).
    PadLevel,
    /// Its disc's heated mass differs by 25-60 % (the `disc-thermal` link).
    DiscMass,
    /// Its wheels are 1-2.5 % larger or smaller (the `wheel-rail` link).
    WheelRadius,
    /// Its caliper drags: a residual clamp force of 1.5-4 kN while released (the
    /// `pad-force` link).
    DragCaliper,
}

impl WheelsetDiff {
    /// The link of `spec/diagnosis.md` that shows the difference.
    pub fn link(self) -> &'static str {
        match self {
            WheelsetDiff::PadLevel => "disc-pad-friction",
            WheelsetDiff::DiscMass => "disc-thermal",
            WheelsetDiff::WheelRadius => "wheel-rail",
            WheelsetDiff::DragCaliper => "pad-force",
        }
    }
}

/// Every kind, in the order that numbers them (the number seeds a case's draw).
pub const KINDS: [Kind; 17] = [
    Kind::None,
    Kind::Hidden(Effect::FrictionSpeed),
    Kind::Hidden(Effect::FrictionTemperature),
    Kind::Paper,
    Kind::Hidden(Effect::FrictionLevel),
    Kind::Hidden(Effect::FrictionPressure),
    Kind::Hidden(Effect::Adhesion),
    Kind::Hidden(Effect::RunningResistance),
    Kind::Hidden(Effect::Gradient),
    Kind::Hidden(Effect::Mass),
    Kind::Hidden(Effect::ActuatorLag),
    Kind::Hidden(Effect::SensorGain),
    Kind::Unlisted,
    Kind::Wheelset(WheelsetDiff::PadLevel),
    Kind::Wheelset(WheelsetDiff::DiscMass),
    Kind::Wheelset(WheelsetDiff::WheelRadius),
    Kind::Wheelset(WheelsetDiff::DragCaliper),
];

impl Kind {
    /// The kind's place in [`KINDS`].
    pub fn number(self) -> u64 {
        let kind = match self {
            Kind::Hidden(Effect::SensorGainPressure) => Kind::Hidden(Effect::SensorGain),
            k => k,
        };
        KINDS.iter().position(|k| *k == kind).unwrap_or(0) as u64
    }
}

/// Which sensor a `sensor-gain` case scales.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Sensor {
    Pressure,
    ClampForce,
}

/// The hidden truth of a case.
#[derive(Clone, Debug, PartialEq)]
pub struct Truth {
    pub kind: Kind,
    /// Effect names the diagnosis should name (spec names).
    pub causes: Vec<&'static str>,
    /// Parameter keys (spec keys) and true values.
    pub params: Vec<(String, f64)>,
    /// For sensor-gain: the sensor and wheelset (0-based).
    pub sensor: Option<(Sensor, usize)>,
    /// For a wheelset that differs: what, which (0-based) and the size (the value of the
    /// one parameter in `params`).
    pub wheelset: Option<(WheelsetDiff, usize, f64)>,
}

/// Which brake inputs are logged.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Inputs {
    Pressure,
    ClampForce,
    Both,
}

/// The drawn scenario and logging.
#[derive(Clone, Debug)]
pub struct Scenario {
    pub rail: Rail,
    pub speed_kmh: f64,
    /// Coasting before the brake command, s.
    pub coast_s: f64,
    /// Service-brake steps (share of the EB deceleration, duration s) before the EB; empty:
    /// emergency brake at once.
    pub service_steps: Vec<(f64, f64)>,
    pub sample_rate_hz: f64,
    pub jitter: bool,
    pub inputs: Inputs,
    pub log_f_brake: bool,
    pub log_t_disc: bool,
    pub log_q: bool,
    pub log_wsp: bool,
    pub log_a_x: bool,
    pub log_cmd: bool,
    /// Noise sigmas: v m/s, omega rad/s, pressure Pa, clamp N, brake force N, disc degC,
    /// load N, accel m/s^2.
    pub noise: [f64; 8],
    /// Log the way a field logger does (see [`field_logger`]): radar v_ref with a slow
    /// correlated error, phonic-wheel speeds, a drifting load-cell zero, thermocouples at
    /// 10 Hz. Off in the seeded draw (set by [`case_with`]).
    pub field_logger: bool,
}

/// A generated case: the CSV text, the baseline the diagnosis gets, and the truth.
#[derive(Clone, Debug)]
pub struct Case {
    pub seed: u64,
    pub truth: Truth,
    pub scenario: Scenario,
    pub csv: String,
    /// What the diagnosis is given as the baseline.
    pub baseline: Params,
}

/// The usual diagnosis baseline: the reference parameters with constant friction.
pub fn constant_baseline() -> Params {
    let mut p = Params::default();
    p.friction.model = FrictionModel::Constant;
    p
}

fn log_uniform(rng: &mut StdRng, lo: f64, hi: f64) -> f64 {
    (lo.ln() + rng.random::<f64>() * (hi.ln() - lo.ln())).exp()
}

fn gauss(rng: &mut StdRng) -> f64 {
    // Box-Muller.
    let u1: f64 = rng.random::<f64>().max(1e-300);
    let u2: f64 = rng.random();
    (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
}

/// Draws a scenario with the seed's randomness, then applies `kind`'s logging needs.
fn draw_scenario(rng: &mut StdRng, kind: Kind) -> Scenario {
    let rail = if rng.random::<f64>() < 0.5 {
        Rail::Wet
    } else {
        Rail::Dry
    };
    let rates = [100.0, 200.0, 250.0, 500.0, 1000.0, 2000.0];
    let inputs = match rng.random_range(0..3) {
        0 => Inputs::Pressure,
        1 => Inputs::ClampForce,
        _ => Inputs::Both,
    };
    let mut s = Scenario {
        rail,
        speed_kmh: rng.random_range(100.0..160.0),
        coast_s: if rng.random::<f64>() < 0.6 {
            rng.random_range(0.3..3.0)
        } else {
            0.0
        },
        service_steps: Vec::new(),
        sample_rate_hz: rates[rng.random_range(0..rates.len())],
        jitter: rng.random::<f64>() < 0.3,
        inputs,
        log_f_brake: rng.random::<f64>() < 0.5,
        log_t_disc: rng.random::<f64>() < 0.5,
        log_q: rng.random::<f64>() < 0.5,
        log_wsp: rng.random::<f64>() < 0.6,
        log_a_x: rng.random::<f64>() < 0.4,
        log_cmd: rng.random::<f64>() < 0.5,
        noise: [
            log_uniform(rng, 0.003, 0.03),
            log_uniform(rng, 0.005, 0.05),
            log_uniform(rng, 100.0, 1500.0),
            log_uniform(rng, 20.0, 200.0),
            log_uniform(rng, 30.0, 300.0),
            log_uniform(rng, 0.05, 0.5),
            log_uniform(rng, 100.0, 800.0),
            log_uniform(rng, 0.01, 0.1),
        ],
        field_logger: false,
    };
    // What each effect needs to be seen (a rig engineer logs it).
    match kind {
        // Pad force lags pressure: visible only where both are logged.
        Kind::Hidden(Effect::ActuatorLag) => s.inputs = Inputs::Both,
        // A scaled sensor: both logged, or the tangential force beside the pressure.
        Kind::Hidden(Effect::SensorGain) => {
            if s.inputs != Inputs::Both {
                s.inputs = Inputs::Pressure;
                s.log_f_brake = true;
            }
        }
        // Mass vs friction level: the axle loads tell.
        Kind::Hidden(Effect::Mass) => s.log_q = true,
        // Friction level vs a clamp-force gain and vs mass: pressure and force, loads.
        Kind::Hidden(Effect::FrictionLevel) => {
            s.inputs = Inputs::Both;
            s.log_q = true;
        }
        // Friction vs clamp force: the clamp force must vary (stepped service brake).
        Kind::Hidden(Effect::FrictionPressure) => {
            let n = rng.random_range(2..4);
            s.service_steps = (0..n)
                .map(|_| (rng.random_range(0.35..1.0), rng.random_range(5.0..9.0)))
                .collect();
            s.inputs = Inputs::Both;
            s.log_q = true;
        }
        // Resistance and gradient act while coasting too.
        Kind::Hidden(Effect::RunningResistance) | Kind::Hidden(Effect::Gradient) => {
            s.coast_s = rng.random_range(1.5..4.0)
        }
        // One wheelset's pads: forces logged (clamp and tangential) beside the pressures.
        Kind::Wheelset(WheelsetDiff::PadLevel) => {
            s.inputs = Inputs::Both;
            s.log_f_brake = true;
        }
        Kind::Wheelset(WheelsetDiff::DiscMass) => s.log_t_disc = true,
        // A dragging caliper shows on the load cell while the brake is released.
        Kind::Wheelset(WheelsetDiff::DragCaliper) => {
            s.inputs = Inputs::Both;
            s.coast_s = rng.random_range(2.0..4.0);
        }
        _ => {}
    }
    s
}

/// A case of `kind` drawn from `seed`.
pub fn case(kind: Kind, seed: u64) -> Case {
    case_with(kind, seed, |_| {})
}

/// A case of `kind` drawn from `seed`, with the scenario adjusted by `tweak` (e.g. to build a
/// case the diagnosis cannot resolve).
pub fn case_with(kind: Kind, seed: u64, tweak: impl FnOnce(&mut Scenario)) -> Case {
    let mut rng =
        StdRng::seed_from_u64(seed ^ (kind.number() + 1).wrapping_mul(0x9E37_79B9_7F4A_7C15));
    let mut scenario = draw_scenario(&mut rng, kind);
    tweak(&mut scenario);
    let nominal = constant_baseline();
    let mut truth_params = nominal;
    let mut sensor = None;
    let mut wheelset = None;
    let (causes, params): (Vec<&'static str>, Vec<(String, f64)>) = match kind {
        Kind::None => (vec![], vec![]),
        Kind::Hidden(Effect::FrictionSpeed) => {
            let (n, m) = (rng.random_range(0.12..0.3), rng.random_range(0.06..0.2));
            let f = &mut truth_params.friction;
            f.model = FrictionModel::Variable;
            // Eq (2) as the reference file defines it, correction c included (the
            // convention of measured data; a constant-friction fit sees c as a level).
            (f.n_v, f.m_v, f.n_t, f.m_t) = (n, m, 0.0, 0.0);
            (
                vec!["friction-speed"],
                vec![("n_v".into(), n), ("m_v".into(), m)],
            )
        }
        Kind::Hidden(Effect::FrictionTemperature) => {
            let (n, m) = (rng.random_range(0.08..0.25), rng.random_range(0.008..0.025));
            let f = &mut truth_params.friction;
            f.model = FrictionModel::Variable;
            (f.n_v, f.m_v, f.n_t, f.m_t) = (0.0, 0.0, n, m);
            (
                vec!["friction-temperature"],
                vec![("n_t".into(), n), ("m_t".into(), m)],
            )
        }
        Kind::Paper => {
            truth_params.friction = Params::default().friction;
            let f = truth_params.friction;
            (
                vec!["friction-speed", "friction-temperature"],
                vec![
                    ("n_v".into(), f.n_v),
                    ("m_v".into(), f.m_v),
                    ("n_t".into(), f.n_t),
                    ("m_t".into(), f.m_t),
                ],
            )
        }
        Kind::Hidden(Effect::FrictionLevel) => {
            let factor = if rng.random::<f64>() < 0.5 {
                rng.random_range(0.8..0.92)
            } else {
                rng.random_range(1.08..1.25)
            };
            truth_params.friction.mu_d0 *= factor;
            (
                vec!["friction-level"],
                vec![("mu_d0".into(), truth_params.friction.mu_d0)],
            )
        }
        Kind::Hidden(Effect::FrictionPressure) => {
            let k_p = rng.random_range(0.06..0.2);
            truth_params.friction.k_p = k_p;
            (vec!["friction-pressure"], vec![("k_p".into(), k_p)])
        }
        Kind::Hidden(Effect::Adhesion) => {
            // A poorer rail than the baseline's set assumes (wheels slide).
            let set = truth_params.contact.set_mut(scenario.rail);
            let mu_0 = match scenario.rail {
                Rail::Wet => rng.random_range(0.12..0.17),
                Rail::Dry => rng.random_range(0.13..0.18),
            };
            *set[2] = mu_0;
            (vec!["adhesion"], vec![("mu_0".into(), mu_0)])
        }
        Kind::Hidden(Effect::RunningResistance) => {
            let (a, cc) = (
                rng.random_range(2000.0..5000.0),
                rng.random_range(5.0..12.0),
            );
            truth_params.resistance.davis_a_n = a;
            truth_params.resistance.davis_c_n_per_mps2 = cc;
            (
                vec!["running-resistance"],
                vec![("davis_a_n".into(), a), ("davis_c_n_per_mps2".into(), cc)],
            )
        }
        Kind::Hidden(Effect::Gradient) => {
            let g =
                rng.random_range(3.0..10.0) * if rng.random::<f64>() < 0.5 { -1.0 } else { 1.0 };
            truth_params.track.gradient_permille = g;
            (vec!["gradient"], vec![("gradient_permille".into(), g)])
        }
        Kind::Hidden(Effect::Mass) => {
            let total = nominal.total_mass() * rng.random_range(1.1..1.3);
            truth_params.vehicle.carbody_mass =
                total - (nominal.total_mass() - nominal.vehicle.carbody_mass);
            (vec!["mass"], vec![("mass_kg".into(), total)])
        }
        Kind::Hidden(Effect::ActuatorLag) => {
            let tau = rng.random_range(0.06..0.35);
            truth_params.brake.actuator_lag_s = tau;
            (vec!["actuator-lag"], vec![("tau_s".into(), tau)])
        }
        Kind::Unlisted => (
            vec![],
            vec![("v_ref_drift_mps_per_s".into(), rng.random_range(0.02..0.05))],
        ),
        Kind::Hidden(Effect::SensorGain | Effect::SensorGainPressure) => {
            let j = rng.random_range(0..WHEELSETS);
            let g = if rng.random::<f64>() < 0.5 {
                rng.random_range(0.75..0.88)
            } else {
                rng.random_range(1.12..1.3)
            };
            let which = match scenario.inputs {
                Inputs::Pressure => Sensor::Pressure,
                Inputs::ClampForce => Sensor::ClampForce,
                Inputs::Both => {
                    if rng.random::<f64>() < 0.5 {
                        Sensor::Pressure
                    } else {
                        Sensor::ClampForce
                    }
                }
            };
            sensor = Some((which, j));
            (vec!["sensor-gain"], vec![(format!("gain{}", j + 1), g)])
        }
        // The diagnosis' effects outside the spec's list (one wheelset's pads) are drawn as
        // `Kind::Wheelset`; hidden as an effect, nothing is hidden.
        Kind::Hidden(_) => (vec![], vec![]),
        Kind::Wheelset(diff) => {
            let (key, size, j) = draw_wheelset_diff(diff, &nominal, &mut rng);
            wheelset = Some((diff, j, size));
            (vec![], vec![(key.to_string(), size)])
        }
    };
    let csv = simulate(
        &truth_params,
        &nominal,
        &scenario,
        kind,
        &params,
        (sensor, wheelset),
        &mut rng,
    );
    Case {
        seed,
        truth: Truth {
            kind,
            causes,
            params,
            sensor,
            wheelset,
        },
        scenario,
        csv,
        baseline: nominal,
    }
}

/// A wheelset difference drawn from `rng`: its parameter key, value and wheelset (0-based).
fn draw_wheelset_diff(
    diff: WheelsetDiff,
    nominal: &Params,
    rng: &mut StdRng,
) -> (&'static str, f64, usize) {
    let j = rng.random_range(0..WHEELSETS);
    let sign = if rng.random::<f64>() < 0.5 { -1.0 } else { 1.0 };
    let (key, size) = match diff {
        WheelsetDiff::PadLevel => ("mu_scale", 1.0 + sign * rng.random_range(0.10..0.15)),
        WheelsetDiff::DiscMass => {
            let f = rng.random_range(1.25..1.6);
            let m = nominal.thermal.disc_mass;
            ("disc_mass_kg", if sign > 0.0 { m * f } else { m / f })
        }
        WheelsetDiff::WheelRadius => {
            let r = nominal.vehicle.wheel_radius;
            ("radius_m", r * (1.0 + sign * rng.random_range(0.01..0.025)))
        }
        WheelsetDiff::DragCaliper => ("residual_clamp_n", rng.random_range(1500.0..4000.0)),
    };
    (key, size, j)
}

/// One wheelset's difference acting in a closed loop stepped by hand (the plant keeps one
/// set of parameters for all four wheelsets, so the difference acts on that wheelset's
/// brake input and on what is logged of it):
/// - pad level k: the pad force reaching the plant is k x Eq (1) (the same torque as
///   mu_d k x mu_d0 for a constant friction); the load cell logs Eq (1);
/// - wheel radius r_j: the plant's wheel (radius r) gets r / r_j of the torque (the same
///   rail force T / r_j); the logged angular speed is the plant's r / r_j (rolling at the
///   same circumferential speed) and the logged tangential force the true torque's;
///   the wheelset's inertia stays referred to r (a 2.5 % difference moves the vehicle's
///   deceleration by well under 0.1 %); the brake unit is calibrated for the real wheel;
/// - dragging caliper F_res: the pad force is max(Eq (1), F_res) (a stuck piston holds the
///   pads until the pressure force exceeds it); the load cell logs it;
/// - disc mass m_j: that disc's temperature is integrated beside the plant with Eqs (3)-(6)
///   at m_j from the plant's brake power (exact for a constant friction, which does not
///   depend on the disc temperature).
struct WheelsetTruth {
    diff: WheelsetDiff,
    j: usize,
    size: f64,
    caliper: hils_plant::brake::Caliper<f64>,
    thermal: hils_plant::thermal::DiscThermal<f64>,
    disc_temp: f64,
    r: f64,
}

impl WheelsetTruth {
    fn new(truth: &Params, (diff, j, size): (WheelsetDiff, usize, f64)) -> Self {
        let mut thermal = truth.thermal;
        if diff == WheelsetDiff::DiscMass {
            thermal.disc_mass = size;
        }
        WheelsetTruth {
            diff,
            j,
            size,
            caliper: hils_plant::brake::Caliper::new(&truth.brake),
            thermal: hils_plant::thermal::DiscThermal::new(&thermal),
            disc_temp: truth.thermal.ambient_rise,
            r: truth.vehicle.wheel_radius,
        }
    }

    /// The pad force of the wheelset for the unit's cylinder pressure `p`, N.
    fn clamp(&self, p: f64) -> f64 {
        let eq1 = self.caliper.clamp_force(p);
        match self.diff {
            WheelsetDiff::PadLevel => eq1 * self.size,
            WheelsetDiff::WheelRadius => eq1 * self.r / self.size,
            WheelsetDiff::DragCaliper => eq1.max(self.size),
            WheelsetDiff::DiscMass => eq1,
        }
    }

    /// One step of the loop with the difference acting; returns the unit's outputs.
    fn step(&mut self, sim: &mut ClosedLoop<f64>, dt: f64) -> hils_brake_unit::UnitOutputs<f64> {
        let u = sim.unit.step(&sim.plant.wheel_speeds());
        let mut inputs = u
            .cylinder_pressure_pa
            .map(hils_plant::BrakeInput::CylinderPressure);
        inputs[self.j] =
            hils_plant::BrakeInput::ClampForce(self.clamp(u.cylinder_pressure_pa[self.j]));
        sim.plant.step(&inputs);
        let w = sim.plant.outputs().wheelsets[self.j];
        self.disc_temp += self
            .thermal
            .rate(w.brake_power, self.disc_temp, w.omega * self.r)
            * dt;
        u
    }

    /// What is logged of the wheelset (see [`WheelsetTruth`]).
    fn log(&self, r: &mut RunRecord, u: &hils_brake_unit::UnitOutputs<f64>) {
        let j = self.j;
        r.p_cyl_pa = u.cylinder_pressure_pa;
        r.wsp = u.venting;
        let eq1 = self.caliper.clamp_force(u.cylinder_pressure_pa[j]);
        match self.diff {
            WheelsetDiff::PadLevel => r.f_clamp_n[j] = eq1,
            WheelsetDiff::WheelRadius => {
                r.f_clamp_n[j] = eq1;
                r.f_brake_n[j] *= self.size / self.r;
                r.omega_radps[j] *= self.r / self.size;
            }
            WheelsetDiff::DiscMass => r.t_disc_c[j] = self.disc_temp,
            WheelsetDiff::DragCaliper => {}
        }
    }
}

/// The truth run: the closed loop sampled at the scenario's rate (uniform or jittered),
/// with its brake schedule, until the stop rule of `hils_sil` ends it.
fn run_truth(
    truth: &Params,
    nominal: &Params,
    s: &Scenario,
    rng: &mut StdRng,
    wheelset: Option<(WheelsetDiff, usize, f64)>,
) -> Vec<RunRecord> {
    let dt = STEP_S;
    let config = UnitConfig::new(dt);
    let v0 = s.speed_kmh / KMH_PER_MPS;
    let mut sim =
        ClosedLoop::<f64>::with_config(truth, s.rail, v0, &config).expect("valid truth parameters");
    // The brake unit knows only the nominal vehicle.
    sim.unit = BrakeUnit::new(nominal, &config).expect("valid unit");

    // Sample steps (uniform or jittered).
    let period_steps = 1.0 / (s.sample_rate_hz * dt);
    let mut rows: Vec<RunRecord> = Vec::new();
    let mut next_sample = 0.0f64;
    let mut step = 0u32;
    let mut rule = StopRule::new(dt, AFTER_STOP_S, MAX_TIME_S);
    let coast_steps = (s.coast_s / dt).round() as u32;
    let mut schedule: Vec<(u32, BrakeDemand)> = Vec::new();
    let mut at = coast_steps;
    let eb_deceleration_mps2 = config.params.eb_deceleration_mps2;
    for &(share, dur) in &s.service_steps {
        let deceleration_mps2 = (share * eb_deceleration_mps2) as f32;
        schedule.push((at, BrakeDemand::Service { deceleration_mps2 }));
        at += (dur / dt).round() as u32;
    }
    schedule.push((at, BrakeDemand::Emergency));
    let mut cmd = Cmd::Release;
    let mut differs = wheelset.map(|w| WheelsetTruth::new(truth, w));
    let mut unit_out = None;
    loop {
        if let Some(&(when, demand)) = schedule.first() {
            if step >= when {
                sim.set_demand(demand);
                cmd = Cmd::of(demand);
                schedule.remove(0);
            }
        }
        if step as f64 >= next_sample {
            let mut r = RunRecord::of(&sim, cmd);
            r.t_s = step as f64 * dt;
            if let (Some(w), Some(u)) = (&differs, &unit_out) {
                w.log(&mut r, u);
            }
            rows.push(r);
            let jitter = if s.jitter {
                rng.random_range(-0.3..0.3)
            } else {
                0.0
            };
            next_sample = (rows.len() as f64 + jitter) * period_steps;
            next_sample = next_sample.max(step as f64 + 1.0);
        }
        match &mut differs {
            Some(w) => unit_out = Some(w.step(&mut sim, dt)),
            None => {
                sim.step();
            }
        }
        let v = sim.plant.vehicle_speed();
        step += 1;
        if rule.observe(step, v) {
            break;
        }
    }
    rows
}

/// The logged channels of a scenario, in the schema's order (then shuffled by the caller).
fn logged_channels(s: &Scenario) -> Vec<Channel> {
    let logged = |c: Channel| match c {
        P_CYL => s.inputs != Inputs::ClampForce,
        F_CLAMP => s.inputs != Inputs::Pressure,
        F_BRAKE => s.log_f_brake,
        T_DISC => s.log_t_disc,
        Q => s.log_q,
        WSP => s.log_wsp,
        A_X => s.log_a_x,
        CMD => s.log_cmd,
        _ => true,
    };
    run_log::SPEC.into_iter().filter(|&c| logged(c)).collect()
}

/// A measured cell: the value with the sensor's noise, at the logger's resolution.
fn noisy_cell(r: &RunRecord, c: Channel, j: usize, n: &[f64; 8], rng: &mut StdRng) -> String {
    match c {
        T => format!("{:.6}", r.t_s),
        V_REF => format!("{:.5}", r.v_ref_mps + n[0] * gauss(rng)),
        OMEGA => format!("{:.5}", r.omega_radps[j] + n[1] * gauss(rng)),
        P_CYL => format!("{:.1}", r.p_cyl_pa[j] + n[2] * gauss(rng)),
        F_CLAMP => format!("{:.2}", r.f_clamp_n[j] + n[3] * gauss(rng)),
        F_BRAKE => format!("{:.2}", r.f_brake_n[j] + n[4] * gauss(rng)),
        T_DISC => format!("{:.3}", r.t_disc_c[j] + n[5] * gauss(rng)),
        WSP => (if r.wsp[j] { "1" } else { "0" }).to_string(),
        Q => format!("{:.1}", r.q_n[j] + n[6] * gauss(rng)),
        A_X => format!("{:.4}", r.a_x_mps2 + n[7] * gauss(rng)),
        _ => r.cmd.text().to_string(),
    }
}

fn simulate(
    truth: &Params,
    nominal: &Params,
    s: &Scenario,
    kind: Kind,
    params: &[(String, f64)],
    (sensor, wheelset): (Option<(Sensor, usize)>, Option<(WheelsetDiff, usize, f64)>),
    rng: &mut StdRng,
) -> String {
    let mut rows = run_truth(truth, nominal, s, rng, wheelset);
    if s.field_logger {
        let mut artifacts = StdRng::seed_from_u64(rng.random());
        field_logger(&mut rows, &mut artifacts);
    }

    // Unlisted: the speed reference drifts.
    if kind == Kind::Unlisted {
        let drift = params[0].1;
        for r in &mut rows {
            r.v_ref_mps += drift * r.t_s;
        }
    }
    // Sensor gain: one sensor reads scaled.
    if let Some((which, j)) = sensor {
        let g = params[0].1;
        for r in &mut rows {
            match which {
                Sensor::Pressure => r.p_cyl_pa[j] *= g,
                Sensor::ClampForce => r.f_clamp_n[j] *= g,
            }
        }
    }

    // Columns (shuffled order).
    let mut cols = runlog::column_names(&logged_channels(s));
    for i in (1..cols.len()).rev() {
        let k = rng.random_range(0..=i);
        cols.swap(i, k);
    }
    let metadata = vec![
        (
            "source",
            "hidden-effect generator (seeded), not to be trusted by the diagnosis".to_string(),
        ),
        (
            "rail",
            if s.rail == Rail::Wet { "wet" } else { "dry" }.to_string(),
        ),
        ("initial_speed_kmh", format!("{:.0}", s.speed_kmh)),
        ("eb_command_s", format!("{:.3}", s.coast_s)),
    ];
    let mut metadata = metadata;
    if !s.jitter {
        metadata.push(("sample_rate_hz", format!("{}", s.sample_rate_hz)));
    }
    metadata.push(("notes", format!("case {kind:?}")));
    let cells: Vec<(Channel, usize)> = cols
        .iter()
        .map(|c| Channel::find(&run_log::SPEC, c).expect("a column of the schema"))
        .collect();
    let n = s.noise;
    let table: Vec<Vec<String>> = rows
        .iter()
        .map(|r| {
            cells
                .iter()
                .map(|&(c, j)| noisy_cell(r, c, j, &n, rng))
                .collect()
        })
        .collect();
    let mut table = table;
    if s.field_logger {
        thermocouples_at_10_hz(&rows, &cells, &mut table);
    }
    let mut out = Vec::new();
    runlog::write_table(&mut out, &metadata, &cols, table).expect("in-memory CSV");
    String::from_utf8(out).expect("utf-8")
}

/// Logger artifacts of field tests (the kinds in `shared/foreign-cases/README.md`), drawn
/// from `rng`: a Doppler radar v_ref with a slow first-order random error (0.02-0.05 m/s,
/// 2-6 s); phonic-wheel speeds (60-100 teeth: values updated every 10 ms by the ECU, a
/// tooth-pitch error of 0.2-0.6 % per update, 0 below one tooth per 0.3 s); one load cell
/// whose zero drifts by 50-150 N (time constant 20 s).
pub fn field_logger(rows: &mut [RunRecord], rng: &mut StdRng) {
    let slow_sigma = rng.random_range(0.02..0.05);
    let slow_tau = rng.random_range(2.0..6.0);
    let teeth = rng.random_range(60.0..100.0f64).round();
    let pitch = rng.random_range(0.002..0.006);
    let drift_n = rng.random_range(50.0..150.0) * if rng.random::<bool>() { 1.0 } else { -1.0 };
    let drift_j = rng.random_range(0..WHEELSETS);
    let omega_min = std::f64::consts::TAU / teeth / 0.3;
    let mut radar = slow_sigma * gauss(rng);
    let mut held = [0.0f64; WHEELSETS];
    let mut last_update = f64::NEG_INFINITY;
    let mut t_prev = rows.first().map(|r| r.t_s).unwrap_or(0.0);
    for r in rows.iter_mut() {
        let dt = r.t_s - t_prev;
        t_prev = r.t_s;
        let a = (-dt / slow_tau).exp();
        radar = radar * a + slow_sigma * (1.0 - a * a).sqrt() * gauss(rng);
        r.v_ref_mps += radar;
        if r.t_s - last_update >= 0.01 {
            last_update = r.t_s;
            for (h, w) in held.iter_mut().zip(&r.omega_radps) {
                *h = if *w < omega_min {
                    0.0
                } else {
                    w * (1.0 + pitch * gauss(rng))
                };
            }
        }
        r.omega_radps = held;
        r.f_clamp_n[drift_j] += drift_n * (1.0 - (-r.t_s / 20.0).exp());
    }
}

/// Thermocouples read at 10 Hz: `t_disc` cells between readings are empty.
fn thermocouples_at_10_hz(
    rows: &[RunRecord],
    cells: &[(Channel, usize)],
    table: &mut [Vec<String>],
) {
    let mut last = f64::NEG_INFINITY;
    for (r, row) in rows.iter().zip(table.iter_mut()) {
        let read = r.t_s - last >= 0.1;
        if read {
            last = r.t_s;
        }
        for (cell, &(c, _)) in row.iter_mut().zip(cells) {
            if c == T_DISC && !read {
                cell.clear();
            }
        }
    }
}

/// Noise-free friction points of Eq (2) (the plant's implementation) with Gaussian noise of
/// `sigma` on mu, at friction speeds and disc temperatures drawn uniformly from the ranges
/// (m/s, degC). Returns the CSV text of a points file.
pub fn dynamometer_points(
    seed: u64,
    friction: &hils_plant::params::FrictionParams,
    sigma: f64,
    n: usize,
    v_range: std::ops::Range<f64>,
    t_range: std::ops::Range<f64>,
) -> String {
    let mut rng = StdRng::seed_from_u64(seed);
    let f = hils_plant::friction::DiscPadFriction::<f64>::new(friction);
    let mut out = String::from(
        "# source: dynamometer generator\n# disc: steel, pad: organic\nv_friction_mps,t_disc_c,mu\n",
    );
    for _ in 0..n {
        let v = rng.random_range(v_range.clone());
        let t = rng.random_range(t_range.clone());
        let mu = f.mu_d(v, t, 0.0) + sigma * gauss(&mut rng);
        let _ = writeln!(out, "{v:.4},{t:.3},{mu:.5}");
    }
    out
}

/// A dynamometer time series: stops from `v0` with the clamp force and friction force
/// logged (mu = f_friction / f_clamp), the disc heating up, brake released before and after.
pub fn dynamometer_stops(
    seed: u64,
    friction: &hils_plant::params::FrictionParams,
    sigma_force: f64,
) -> String {
    let mut rng = StdRng::seed_from_u64(seed);
    let f = hils_plant::friction::DiscPadFriction::<f64>::new(friction);
    let mut out = String::from(
        "# source: dynamometer generator (stops)\nt_s,v_friction_mps,t_disc_c,f_clamp_n,f_friction_n\n",
    );
    let mut t = 0.0;
    let mut temp: f64 = 20.0;
    for stop in 0..6 {
        let mut v: f64 = 8.0 + 4.0 * stop as f64;
        let clamp = rng.random_range(8000.0..20000.0);
        // Released for 1 s (clamp 0): mu undefined, the reader skips these rows.
        for _ in 0..10 {
            let _ = writeln!(out, "{t:.2},{v:.4},{temp:.3},0.0,0.0");
            t += 0.1;
        }
        while v > 0.3 {
            let mu = f.mu_d(v, temp, clamp);
            let force = mu * clamp;
            let _ = writeln!(
                out,
                "{t:.2},{v:.4},{temp:.3},{:.2},{:.2}",
                clamp + sigma_force * gauss(&mut rng),
                force + sigma_force * gauss(&mut rng)
            );
            v -= 0.1 * 1.2;
            temp += 0.1 * force * v * 2e-4;
            t += 0.1;
        }
        temp = (temp * 0.6).max(20.0);
    }
    out
}
