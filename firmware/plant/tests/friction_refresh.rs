//! Eq (2) as the step computes it: its two brackets refreshed in turn (one wheelset per
//! step, each every 8 steps) and mu_d = brackets x pressure extension every step.
//! Checked against an independent f64 evaluation of the paper's Eq (2).

use hils_plant::friction::DiscPadFriction;
use hils_plant::tracked::TrackedExp;
use hils_plant::{BrakeInput, FrictionModel, Params, Plant, Rail, Real, WHEELSETS};

/// Eq (2) in f64 from the parameter file: c mu_d0 (n_v e^(-m_v v_d) + 1)(n_T e^(-m_T T_d)
/// + 1) (1 + k_p f / 10 kN), or mu_d0 (1 + k_p f / 10 kN) with the constant model.
fn eq2(p: &Params, v_d: f64, t_d: f64, clamp_n: f64) -> f64 {
    let f = &p.friction;
    let pressure = 1.0 + f.k_p * clamp_n / 1.0e4;
    match f.model {
        FrictionModel::Constant => f.mu_d0 * pressure,
        FrictionModel::Variable => {
            f.correction_c
                * f.mu_d0
                * (f.n_v * (-f.m_v * v_d.abs()).exp() + 1.0)
                * (f.n_t * (-f.m_t * t_d).exp() + 1.0)
                * pressure
        }
    }
}

/// The composed functions the step uses (temperature bracket, speed bracket, pressure
/// extension), each tracker fresh at its argument, over the plant's range: within 1e-6
/// relative of the f64 Eq (2); the constant model gives mu_d0 exactly (k_p = 0).
#[test]
fn bracket_product_equals_eq2_over_the_range() {
    let mut p = Params::default();
    p.friction.k_p = 0.05; // the pressure extension on, so that its factor is checked too
    let r_f = p.brake.friction_radius;
    let fr = DiscPadFriction::<f32>::new(&p.friction);
    let exponent_per_spin = DiscPadFriction::<f32>::speed_exponent_per_spin(&p.friction, r_f);
    let mut worst = 0.0f64;
    for omega in [0.0f32, 0.5, 3.0, 10.0, 25.0, 50.0, 75.0, 97.0] {
        for t_d in [0.0f32, 5.0, 40.0, 120.0, 300.0, 600.0] {
            for clamp in [0.0f32, 5e3, 20e3, 40e3] {
                let mut temperature = fr.temperature_decay_at(t_d);
                let t = fr.scaled_temperature_factor_tracked(t_d, &mut temperature);
                let mut speed = TrackedExp::at(exponent_per_spin * omega);
                let brackets = fr.scaled_brackets_tracked(exponent_per_spin * omega, t, &mut speed);
                let mu = fr.mu_d_of_brackets(brackets, clamp) as f64;
                let exact = eq2(&p, omega as f64 * r_f, t_d as f64, clamp as f64);
                worst = worst.max((mu - exact).abs() / exact);
            }
        }
    }
    assert!(worst <= 1e-6, "worst relative error {worst:e}");
    assert!(
        worst > 0.0,
        "an f32 evaluation that matches f64 everywhere is suspicious"
    );

    p.friction.model = FrictionModel::Constant;
    p.friction.k_p = 0.0;
    let fr = DiscPadFriction::<f32>::new(&p.friction);
    let exponent_per_spin = DiscPadFriction::<f32>::speed_exponent_per_spin(&p.friction, r_f);
    let mut temperature = fr.temperature_decay_at(250.0);
    let t = fr.scaled_temperature_factor_tracked(250.0, &mut temperature);
    let mut speed = TrackedExp::at(exponent_per_spin * 80.0);
    let brackets = fr.scaled_brackets_tracked(exponent_per_spin * 80.0, t, &mut speed);
    assert_eq!(fr.mu_d_of_brackets(brackets, 30e3), p.friction.mu_d0 as f32);
}

/// In slides (full clamp force on a wet rail, the wheels lock and spin up again under no
/// WSP) the step's mu_d lags the spin speed by at most 7 steps: on every step it is within
/// n_v m_v l_p |d omega/dt|_max 7 dt (plus 1e-5 for f32 and the trackers) of Eq (2) at
/// the wheelset's spin speed, disc temperature and clamp force of that step. The mu_d
/// checked is the one the step braked with: while the disc turns (the brake slips) the
/// brake torque is mu_d f l_p N_d (Eq 1), the reported brake force times l_p.
fn mu_d_lags_eq2_in_a_slide<F: Real>() {
    let p = Params::default();
    let (f, r_f) = (&p.friction, p.brake.friction_radius);
    let mut plant = Plant::<F>::new(&p, Rail::Wet, F::of(40.0)).unwrap();
    let dt = plant.dt().to_f64();
    let full = [BrakeInput::ClampForce(F::of(0.9 * 40e3)); WHEELSETS];
    let release = [BrakeInput::ClampForce(F::ZERO); WHEELSETS];
    let (mut worst_ratio, mut max_rate, mut slid) = (0.0f64, 0.0f64, false);
    let (mut torque_checks, mut worst_torque) = (0u32, 0.0f64);
    let mut prev = plant.outputs();
    for n in 0..40_000 {
        // 0.3 s of full clamp force, 0.2 s released: slides that start and end.
        let inputs = if n % 5_000 < 3_000 { &full } else { &release };
        plant.step(inputs);
        let o = plant.outputs();
        for j in 0..WHEELSETS {
            let (w0, w) = (&prev.wheelsets[j], &o.wheelsets[j]);
            let (omega0, omega) = (w0.omega.to_f64(), w.omega.to_f64());
            let rate = (omega - omega0).abs() / dt;
            max_rate = max_rate.max(rate);
            slid |= w.creepage.to_f64() > 0.2;
            // Spin speed and disc temperature at the step's start, clamp force of the step.
            let exact = eq2(
                &p,
                omega0 * r_f,
                w0.disc_temp.to_f64(),
                w.clamp_force.to_f64(),
            );
            let relative = (w.mu_d.to_f64() - exact).abs() / exact;
            let bound = f.n_v * f.m_v * r_f * max_rate * 7.0 * dt + 1e-5;
            worst_ratio = worst_ratio.max(relative / bound);
            if omega > 1.0 && w.clamp_force.to_f64() > 0.0 {
                let torque = w.brake_torque.to_f64();
                let from_force = w.brake_force.to_f64() * r_f;
                worst_torque = worst_torque.max((torque - from_force).abs() / torque);
                torque_checks += 1;
            }
        }
        prev = o;
    }
    assert!(slid, "the run must slide to test the lag");
    assert!(
        max_rate > 20.0,
        "spin rate {max_rate} rad/s^2: no slide dynamics"
    );
    assert!(
        worst_ratio <= 1.0,
        "mu_d off Eq (2) by {worst_ratio} x the bound"
    );
    assert!(torque_checks > 10_000, "{torque_checks} braking steps");
    // A few f32 roundings between the two products (f64: none to speak of).
    let epsilon = if core::mem::size_of::<F>() == 4 {
        f64::from(f32::EPSILON)
    } else {
        f64::EPSILON
    };
    let rounding = 8.0 * epsilon;
    assert!(
        worst_torque <= rounding,
        "brake torque vs brake force: {worst_torque:e}"
    );
}

#[test]
fn mu_d_lags_eq2_by_at_most_seven_steps_in_a_slide_f32() {
    mu_d_lags_eq2_in_a_slide::<f32>();
}

#[test]
fn mu_d_lags_eq2_by_at_most_seven_steps_in_a_slide_f64() {
    mu_d_lags_eq2_in_a_slide::<f64>();
}
