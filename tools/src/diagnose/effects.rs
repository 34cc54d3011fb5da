//! The effects of `spec/diagnosis.md`: what each one changes in the baseline model, the
//! parameters a fit of it estimates (keys as in the spec), their start values, scales and
//! bounds.
//!
//! Disc-pad friction (paper Eq 2) with a constant-friction baseline: the extended model is
//! always Eq (2) as the baseline file defines it, correction c included:
//! mu_d = c mu_d0 (1 + n_v e^(-m_v v_d))(1 + n_T e^(-m_T T_d)). An effect of friction speed
//! alone fits n_v, m_v with the temperature factor held at 1 (n_T = 0), and likewise.
//! A level difference that remains (e.g. a c that the data do not have) is
//! `friction-level`, never a bent shape parameter (issue 9, nuisances). With a variable
//! baseline the effects free the baseline's own Eq (2) parameters.

use hils_plant::{FrictionModel, Params, Rail};

use super::lsq::ParamSpec;
use super::replay::{Model, Prepared, Quantity};

/// An effect of the spec's table. `SensorGainPressure` is the same named effect
/// (`sensor-gain`) acting on the pressure sensors where the clamp force is the input.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Effect {
    FrictionSpeed,
    FrictionTemperature,
    FrictionLevel,
    FrictionPressure,
    Adhesion,
    RunningResistance,
    Gradient,
    Mass,
    ActuatorLag,
    SensorGain,
    SensorGainPressure,
    /// Not a listed effect (issue 27): the pad friction of one wheelset (0-based) differs
    /// from the others' (a pad batch, a glazed disc), scaling its brake torque. The search
    /// fits it where the disc-pad-friction link shows such a wheelset, so that no listed
    /// vehicle-wide effect is bent to it; it is never named as a cause.
    WheelsetFriction(u8),
}

pub const ALL: [Effect; 11] = [
    Effect::FrictionSpeed,
    Effect::FrictionTemperature,
    Effect::FrictionLevel,
    Effect::FrictionPressure,
    Effect::Adhesion,
    Effect::RunningResistance,
    Effect::Gradient,
    Effect::Mass,
    Effect::ActuatorLag,
    Effect::SensorGain,
    Effect::SensorGainPressure,
];

/// Start values of one factor (n e^(-m x) + 1) of paper Eq (2): the baseline's own (n, m)
/// where the baseline is variable and both are positive, else `fallback`.
fn eq2_factor_start(variable: bool, baseline: (f64, f64), fallback: (f64, f64)) -> (f64, f64) {
    if variable && baseline.0 > 0.0 && baseline.1 > 0.0 {
        baseline
    } else {
        fallback
    }
}

impl Effect {
    /// The spec's name.
    pub fn name(self) -> &'static str {
        match self {
            Effect::FrictionSpeed => "friction-speed",
            Effect::FrictionTemperature => "friction-temperature",
            Effect::FrictionLevel => "friction-level",
            Effect::FrictionPressure => "friction-pressure",
            Effect::Adhesion => "adhesion",
            Effect::RunningResistance => "running-resistance",
            Effect::Gradient => "gradient",
            Effect::Mass => "mass",
            Effect::ActuatorLag => "actuator-lag",
            Effect::SensorGain | Effect::SensorGainPressure => "sensor-gain",
            Effect::WheelsetFriction(j) => [
                "wheelset-friction-1",
                "wheelset-friction-2",
                "wheelset-friction-3",
                "wheelset-friction-4",
            ][j as usize % 4],
        }
    }

    /// Whether the effect is one of the spec's list (a cause the diagnosis may name).
    pub fn is_listed(self) -> bool {
        !matches!(self, Effect::WheelsetFriction(_))
    }

    /// Words for the report.
    pub fn describe(self) -> &'static str {
        match self {
            Effect::FrictionSpeed => "the disc-pad friction rises as the friction speed falls",
            Effect::FrictionTemperature => "the disc-pad friction falls as the disc heats up",
            Effect::FrictionLevel => "the steady disc-pad friction differs from the baseline's",
            Effect::FrictionPressure => "the disc-pad friction depends on the pad normal force",
            Effect::Adhesion => "the wheel-rail adhesion differs from the baseline's",
            Effect::RunningResistance => "aerodynamic and rolling drag act on the vehicle",
            Effect::Gradient => "the track is not level",
            Effect::Mass => "the vehicle's mass differs from the baseline's",
            Effect::ActuatorLag => "the pad force follows the cylinder pressure with a lag",
            Effect::SensorGain => "a brake-input sensor (clamp force or pressure) reads scaled",
            Effect::SensorGainPressure => "a cylinder-pressure sensor reads scaled",
            Effect::WheelsetFriction(_) => {
                "the pad friction of one wheelset differs from the others' (not a listed effect)"
            }
        }
    }

    /// Whether the data can show the effect at all.
    pub fn applicable(self, runs: &[Prepared]) -> bool {
        match self {
            Effect::ActuatorLag => runs
                .iter()
                .any(|r| r.has_pressure_input() || r.has_pressure_and_force()),
            Effect::SensorGainPressure => runs.iter().any(|r| r.has_pressure_and_force()),
            Effect::Adhesion => {
                // One rail set is fitted: all runs must share it.
                runs.windows(2).all(|w| w[0].rail == w[1].rail)
            }
            _ => true,
        }
    }

    /// Parameter keys and fit specs for a baseline.
    pub fn params(self, base: &Params, rail: Rail) -> Vec<(&'static str, ParamSpec)> {
        let f = &base.friction;
        let variable = f.model == FrictionModel::Variable;
        match self {
            Effect::FrictionSpeed => {
                let (n, m) = eq2_factor_start(variable, (f.n_v, f.m_v), (0.1, 0.1));
                vec![
                    ("n_v", ParamSpec::new(n, 0.05, 0.0, 3.0)),
                    ("m_v", ParamSpec::new(m, 0.05, 0.0, 2.0)),
                ]
            }
            Effect::FrictionTemperature => {
                let (n, m) = eq2_factor_start(variable, (f.n_t, f.m_t), (0.1, 0.01));
                vec![
                    ("n_t", ParamSpec::new(n, 0.05, 0.0, 3.0)),
                    ("m_t", ParamSpec::new(m, 0.005, 0.0, 0.5)),
                ]
            }
            Effect::FrictionLevel => vec![("mu_d0", ParamSpec::new(f.mu_d0, 0.02, 0.05, 1.5))],
            Effect::FrictionPressure => vec![("k_p", ParamSpec::new(f.k_p, 0.02, -0.5, 2.0))],
            Effect::Adhesion => {
                // mu_0 (the friction level of the rail, what separates wet from dry) only:
                // the replay's slide dynamics have cliffs in the creep-slope factors (a
                // slightly stiffer k_a locks a wheel for good under the measured, not
                // adapting, WSP inputs), which stalls a joint fit short of the truth.
                let set = base.contact.set(rail);
                vec![("mu_0", ParamSpec::new(set.mu_0, 0.1 * set.mu_0, 0.02, 1.5))]
            }
            Effect::RunningResistance => {
                let r = &base.resistance;
                vec![
                    ("davis_a_n", ParamSpec::new(r.davis_a_n, 1000.0, 0.0, 2.0e5)),
                    (
                        "davis_c_n_per_mps2",
                        ParamSpec::new(r.davis_c_n_per_mps2, 2.0, 0.0, 500.0),
                    ),
                ]
            }
            Effect::Gradient => {
                vec![(
                    "gradient_permille",
                    ParamSpec::new(base.track.gradient_permille, 2.0, -40.0, 40.0),
                )]
            }
            Effect::Mass => {
                let m = base.total_mass();
                let fixed = m - base.vehicle.carbody_mass;
                vec![(
                    "mass_kg",
                    ParamSpec::new(m, 0.03 * m, fixed + 1.0e3, fixed + 1.0e6),
                )]
            }
            Effect::ActuatorLag => {
                vec![(
                    "tau_s",
                    ParamSpec::new(base.brake.actuator_lag_s.max(0.02), 0.05, 0.0, 3.0),
                )]
            }
            Effect::SensorGain | Effect::SensorGainPressure => (0..4)
                .map(|j| {
                    (
                        ["gain1", "gain2", "gain3", "gain4"][j],
                        ParamSpec::new(1.0, 0.05, 0.3, 3.0),
                    )
                })
                .collect(),
            Effect::WheelsetFriction(_) => vec![("mu_scale", ParamSpec::new(1.0, 0.02, 0.3, 3.0))],
        }
    }

    /// The parameter values at which the effect, added to a model, leaves it unchanged
    /// (`model` = the current model, built without this effect; `start` = the effect's
    /// start values). The linearised score test probes the effect from here.
    pub fn neutral(self, model: &Model, rail: Rail, start: &[f64]) -> Vec<f64> {
        let p = &model.params;
        let f = &p.friction;
        let variable = f.model == FrictionModel::Variable;
        match self {
            // With a constant model the factor is absent at n = 0 (any m); with a variable
            // model (baseline, or the other factor fitted, this one held at 1) the model's
            // own values reproduce it.
            Effect::FrictionSpeed => {
                if variable {
                    vec![f.n_v, f.m_v]
                } else {
                    vec![0.0, start[1]]
                }
            }
            Effect::FrictionTemperature => {
                if variable {
                    vec![f.n_t, f.m_t]
                } else {
                    vec![0.0, start[1]]
                }
            }
            Effect::FrictionLevel => vec![f.mu_d0],
            Effect::FrictionPressure => vec![f.k_p],
            Effect::Adhesion => vec![p.contact.set(rail).mu_0],
            Effect::RunningResistance => {
                vec![p.resistance.davis_a_n, p.resistance.davis_c_n_per_mps2]
            }
            Effect::Gradient => vec![p.track.gradient_permille],
            Effect::Mass => vec![p.total_mass()],
            Effect::ActuatorLag => vec![model.actuator_lag_s],
            Effect::SensorGain => model.input_gain.to_vec(),
            Effect::SensorGainPressure => model.pressure_obs_gain.to_vec(),
            Effect::WheelsetFriction(j) => vec![model.wheelset_mu_scale[j as usize % 4]],
        }
    }
}

/// Builds the model of a baseline with effects and their parameter values.
pub fn build(base: &Params, rail: Rail, active: &[(Effect, &[f64])]) -> Model {
    let mut model = Model::new(base);
    let p = &mut model.params;
    let has = |e: Effect| active.iter().any(|(a, _)| *a == e);
    let speed = has(Effect::FrictionSpeed);
    let temperature = has(Effect::FrictionTemperature);
    if p.friction.model == FrictionModel::Constant && (speed || temperature) {
        p.friction.model = FrictionModel::Variable;
        // Eq (2) with the file's c; a factor not fitted is held at 1 (n = 0).
        if !speed {
            p.friction.n_v = 0.0;
            p.friction.m_v = 0.0;
        }
        if !temperature {
            p.friction.n_t = 0.0;
            p.friction.m_t = 0.0;
        }
    }
    for (effect, x) in active {
        match effect {
            Effect::FrictionSpeed => {
                p.friction.n_v = x[0];
                p.friction.m_v = x[1];
            }
            Effect::FrictionTemperature => {
                p.friction.n_t = x[0];
                p.friction.m_t = x[1];
            }
            Effect::FrictionLevel => p.friction.mu_d0 = x[0],
            Effect::FrictionPressure => p.friction.k_p = x[0],
            Effect::Adhesion => {
                let set = p.contact.set_mut(rail);
                // set_mut order: k_a, k_s, mu_0, a_ratio, b_exp.
                *set[2] = x[0];
            }
            Effect::RunningResistance => {
                p.resistance.davis_a_n = x[0];
                p.resistance.davis_c_n_per_mps2 = x[1];
            }
            Effect::Gradient => p.track.gradient_permille = x[0],
            Effect::Mass => {
                let fixed = p.total_mass() - p.vehicle.carbody_mass;
                p.vehicle.carbody_mass = x[0] - fixed;
            }
            Effect::ActuatorLag => model.actuator_lag_s = x[0],
            Effect::SensorGain => model.input_gain.copy_from_slice(&x[..4]),
            Effect::SensorGainPressure => model.pressure_obs_gain.copy_from_slice(&x[..4]),
            Effect::WheelsetFriction(j) => model.wheelset_mu_scale[*j as usize % 4] = x[0],
        }
    }
    model
}

/// Whether a run shows anything the effect changes (e.g. actuator lag needs pressure).
pub fn shows(effect: Effect, run: &Prepared) -> bool {
    match effect {
        Effect::ActuatorLag => run.has_pressure_input() || run.has_pressure_and_force(),
        Effect::SensorGainPressure => {
            run.has_quantity(|q| matches!(q, Quantity::PadFromPressure(_)))
        }
        _ => true,
    }
}
