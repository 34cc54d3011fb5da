//! Physics of the plant's parts against hand values and independent derivations:
//! static loads, Polach identities (Eqs 9-12), Eq (2) against Table 1, Eq (1), the
//! quasi-static axle-load transfer under braking. (The reference parameter file is checked
//! with the tools' loader in `host-tests/tests/param_file.rs`.)

use hils_plant::contact::Polach;
use hils_plant::friction::DiscPadFriction;
use hils_plant::params::{FrictionModel, Params, Rail};
use hils_plant::{BrakeInput, Plant};

fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol
}

#[test]
fn static_axle_loads_are_equal_and_carry_the_weight() {
    let p = Params::default();
    let mut plant = Plant::<f64>::new(&p, Rail::Wet, 0.0).unwrap();
    // Stand still with brakes released for 2 s: nothing may move.
    for _ in 0..20_000 {
        plant.step(&[BrakeInput::ClampForce(0.0); 4]);
    }
    let o = plant.outputs();
    let weight = p.total_mass() * p.vehicle.g; // 43 400 kg * 9.81 = 425 754 N
    assert!(close(weight, 425_754.0, 1e-6));
    let sum: f64 = o.wheelsets.iter().map(|w| w.axle_load).sum();
    assert!(
        close(sum, weight, 1e-6 * weight),
        "sum {sum} vs weight {weight}"
    );
    for w in &o.wheelsets {
        // (35 000/2 + 2 500)/2 * 9.81 + 850 * 9.81 = 106 438.5 N
        assert!(
            close(w.axle_load, 106_438.5, 1e-6),
            "axle load {}",
            w.axle_load
        );
    }
    assert!(o.vehicle_speed.abs() < 1e-12);
    // The same in f32.
    let mut plant = Plant::<f32>::new(&p, Rail::Wet, 0.0).unwrap();
    for _ in 0..20_000 {
        plant.step(&[BrakeInput::ClampForce(0.0); 4]);
    }
    for w in &plant.outputs().wheelsets {
        assert!(
            close(w.axle_load as f64, 106_438.5, 0.05),
            "f32 axle load {}",
            w.axle_load
        );
    }
}

#[test]
fn polach_normalised_force_identities() {
    let p = Params::default();
    // F/(Q mu) at eps = 1: (2/pi)(k_A/(1 + k_A^2) + atan(k_s)).
    // dry: (2/pi)(1/2 + atan 0.4) = 0.56054 (the issue quotes 0.5606);
    // wet: (2/pi)(0.3/1.09 + atan 0.1) = 0.23867.
    let dry = Polach::<f64>::new(&p.contact, Rail::Dry);
    let wet = Polach::<f64>::new(&p.contact, Rail::Wet);
    assert!(
        close(dry.normalised_force(1.0), 0.5606, 1e-4),
        "{}",
        dry.normalised_force(1.0)
    );
    assert!(
        close(wet.normalised_force(1.0), 0.2387, 5e-5),
        "{}",
        wet.normalised_force(1.0)
    );
    // Tends to 1 for large eps (full slip: F = mu Q).
    for polach in [&dry, &wet] {
        assert!(close(polach.normalised_force(1e6), 1.0, 1e-4));
        assert!(polach.normalised_force(1e4) > 0.99);
    }
    // And the plant's evaluation (chord form) gives the same force as Eq (9) written out.
    let (u, v, q) = (0.5, 30.0, 100e3);
    let c = wet.evaluate(u, v, q);
    let k = 2.0 / 3.0
        * p.contact.shear_stiffness_c
        * std::f64::consts::PI
        * p.contact.semi_axis_a.powi(2)
        * p.contact.semi_axis_b;
    let mu = 0.21 * ((1.0 - 0.4) * (-0.2 * u).exp() + 0.4); // Eq (11)
    let s = u / v; // Eq (12)
    let eps = k * s / (q * mu); // Eq (10)
    let f = 2.0 * mu * q / std::f64::consts::PI
        * (0.3 * eps / (1.0 + (0.3 * eps).powi(2)) + (0.1 * eps).atan()); // Eq (9)
    assert!(close(c.force, f, 1e-9 * f), "{} vs {f}", c.force);
    assert!(close(c.mu, mu, 1e-15));
    // Odd in the slip velocity, zero at zero slip, finite chord there.
    let neg = wet.evaluate(-u, v, q);
    assert!(close(neg.force, -c.force, 1e-9 * f));
    let zero = wet.evaluate(0.0, v, q);
    assert_eq!(zero.force, 0.0);
    assert!(zero.chord.is_finite() && zero.chord > 0.0);
    // Unloaded wheel: no force.
    assert_eq!(wet.evaluate(u, v, 0.0).force, 0.0);
    assert_eq!(wet.evaluate(u, v, -5.0).force, 0.0);
}

#[test]
fn eq2_matches_hand_values_of_table_1() {
    let p = Params::default();
    let f = DiscPadFriction::<f64>::new(&p.friction);
    // mu_d = c mu_d0 (n_v e^(-m_v v_d) + 1)(n_T e^(-m_T T_d) + 1), c mu_d0 = 0.98 * 0.38 = 0.3724
    let cases = [
        // v_d = 0, T_d = 0: 0.3724 * 1.184 * 1.105 = 0.487218
        (0.0, 0.0, 0.487218),
        // Fig 2a point, 9.6 m/s and 50 degC: 1 + 0.184 e^-0.96 = 1.070452,
        // 1 + 0.105 e^-0.7 = 1.052141 -> 0.419422
        (9.6, 50.0, 0.419422),
        // Fig 2b point, 20 m/s and 50 degC: 1 + 0.184 e^-2 = 1.024902 -> 0.401574
        (20.0, 50.0, 0.401574),
        // 9.6 m/s, 200 degC: 1 + 0.105 e^-2.8 = 1.006385 -> 0.401182
        (9.6, 200.0, 0.401182),
        // Start of the paper's EB: 150 km/h -> v_d = 41.667/0.43*0.275 = 26.65 m/s, cold:
        // 1 + 0.184 e^-2.665 = 1.012802 -> 0.416772
        (26.65, 0.0, 0.416772),
    ];
    for (v_d, t_d, hand) in cases {
        let mu = f.mu_d(v_d, t_d, 0.0);
        assert!(
            close(mu, hand, 2e-6),
            "mu_d({v_d}, {t_d}) = {mu}, hand {hand}"
        );
        let mu32 = DiscPadFriction::<f32>::new(&p.friction).mu_d(v_d as f32, t_d as f32, 0.0);
        assert!(
            close(mu32 as f64, hand, 2e-6),
            "f32 mu_d({v_d}, {t_d}) = {mu32}"
        );
    }
    // Constant model: mu_d0 whatever the speed and temperature.
    let mut constant = p.friction;
    constant.model = FrictionModel::Constant;
    let c = DiscPadFriction::<f64>::new(&constant);
    assert_eq!(c.mu_d(0.0, 0.0, 0.0), 0.38);
    assert_eq!(c.mu_d(30.0, 250.0, 20e3), 0.38);
    // Pressure extension: +5 % per 10 kN.
    let mut kp = p.friction;
    kp.k_p = 0.05;
    let e = DiscPadFriction::<f64>::new(&kp);
    assert!(close(e.mu_d(9.6, 50.0, 20e3), 0.419422 * 1.10, 2e-6));
}

#[test]
fn eq1_clamp_force_and_torque() {
    let p = Params::default();
    let cal = hils_plant::brake::Caliper::<f64>::new(&p.brake);
    // f_clamp = (A_c P_c - K_r) r_c = (0.0227 * 355 345 - 1000) * 2.5 = 17 666.3 N
    let f = cal.clamp_force(355_345.0);
    assert!(close(f, (0.0227 * 355_345.0 - 1000.0) * 2.5, 1e-9));
    // Below the retaining spring there is no force.
    assert_eq!(cal.clamp_force(40_000.0), 0.0);
    // T_b = mu_d f l_p N_d
    assert!(close(cal.torque(0.38, f), 0.38 * f * 0.275 * 4.0, 1e-9));
    let back = hils_plant::brake::pressure_for_clamp_force(&p.brake, f);
    assert!(close(back, 355_345.0, 1e-6));
}

/// Quasi-static axle loads during steady braking, derived independently from the
/// free-body diagrams: every body decelerates at `a`, wheel spin at a/r, nothing
/// oscillates. Returns the four axle loads.
fn quasi_static_axle_loads(p: &Params, a: f64, torques: [f64; 4]) -> [f64; 4] {
    let v = &p.vehicle;
    let s = &p.suspension;
    let r = v.wheel_radius;
    let q_static = ((v.carbody_mass / 2.0 + v.bogie_mass) / 2.0 + v.wheelset_mass) * v.g;
    // Rail force and primary longitudinal force on each wheelset (Eqs 7, 8 with dv/dt = -a).
    let rail = torques.map(|t| (t - v.wheelset_spin_inertia * a / r) / r);
    let primary_on_ws = rail.map(|f| f - v.wheelset_mass * a);
    let mut q = [0.0; 4];
    // Carbody pitch: the secondary longitudinal forces (total m_c a backward on the
    // carbody) act (h_sl - h_c) below... balanced by the bogies' vertical forces.
    let h_sl = s.secondary_longitudinal_height;
    let carbody_moment = (v.carbody_cog_height - h_sl) * v.carbody_mass * a;
    let d_secondary = carbody_moment / v.bogie_base; // + on bogie 1, - on bogie 2
    for i in 0..2 {
        let (j0, j1) = (2 * i, 2 * i + 1);
        // Secondary longitudinal force on the bogie (forward): bogie mass balance.
        let f_sec = -v.bogie_mass * a + primary_on_ws[j0] + primary_on_ws[j1];
        // Bogie pitch (nose-up positive) about its COG = 0:
        // -(h_sl - h_b) f_sec - (h_b - h_pl) (P0 + P1) - T0 - T1 + (b/2)(dP0 - dP1) = 0
        let h_b = v.bogie_cog_height;
        let h_pl = s.primary_longitudinal_height;
        let moment = -(h_sl - h_b) * f_sec
            - (h_b - h_pl) * (primary_on_ws[j0] + primary_on_ws[j1])
            - torques[j0]
            - torques[j1];
        let diff = -moment / (v.wheel_base / 2.0); // dP_lead - dP_trail
        let bogie_extra = if i == 0 { d_secondary } else { -d_secondary };
        q[j0] = q_static + 0.5 * (bogie_extra + diff);
        q[j1] = q_static + 0.5 * (bogie_extra - diff);
    }
    q
}

#[test]
fn axle_load_transfer_matches_a_quasi_static_derivation() {
    let p = Params::default();
    let mut plant = Plant::<f64>::new(&p, Rail::Wet, 40.0).unwrap();
    // A constant clamp force well inside the adhesion limit; let the transient die out.
    let input = [BrakeInput::ClampForce(12_000.0); 4];
    for _ in 0..100_000 {
        plant.step(&input);
    }
    // Average over 1 s to remove any residual oscillation.
    let n = 10_000;
    let (mut a, mut q, mut t) = (0.0, [0.0; 4], [0.0; 4]);
    for _ in 0..n {
        plant.step(&input);
        let o = plant.outputs();
        a -= o.carbody_accel / n as f64;
        for j in 0..4 {
            q[j] += o.wheelsets[j].axle_load / n as f64;
            t[j] += o.wheelsets[j].brake_torque / n as f64;
        }
    }
    assert!(plant.outputs().vehicle_speed > 10.0, "still rolling");
    let expected = quasi_static_axle_loads(&p, a, t);
    for j in 0..4 {
        assert!(
            close(q[j], expected[j], 30.0),
            "wheelset {}: plant {:.1} N, quasi-static {:.1} N",
            j + 1,
            q[j],
            expected[j]
        );
    }
    // Leading wheelsets of each bogie carry more than the trailing ones; the transfer is
    // kilonewtons, and the brake reaction on the bogie frame is a large part of it.
    assert!(q[0] - q[1] > 5_000.0 && q[2] - q[3] > 5_000.0);
    let without_reaction = quasi_static_axle_loads(&p, a, [0.0; 4]);
    let reaction_share = (q[0] - q[1]) - (without_reaction[0] - without_reaction[1]);
    assert!(
        reaction_share > 3_000.0,
        "brake reaction moves {reaction_share} N"
    );
}

/// The air-spring (secondary vertical) forces: at rest half the carbody's weight on each
/// bogie (the load a car's air-spring transducers weigh); in steady braking the carbody's
/// pitch moment (h_c - h_sl) m_c a moves (h_c - h_sl) m_c a / bogie base onto the leading
/// bogie, as the free-body derivation above has it.
#[test]
fn air_spring_forces_weigh_the_carbody_and_show_the_load_transfer() {
    let p = Params::default();
    let v = &p.vehicle;
    let half = 0.5 * v.carbody_mass * v.g;
    let mut plant = Plant::<f64>::new(&p, Rail::Wet, 0.0).unwrap();
    for _ in 0..1000 {
        plant.step(&[BrakeInput::ClampForce(0.0); 4]);
    }
    for f in plant.air_spring_forces() {
        assert!(close(f, half, 1e-6 * half), "{f} vs {half}");
    }
    let f32_plant = Plant::<f32>::new(&p, Rail::Wet, 30.0).unwrap();
    for f in f32_plant.air_spring_forces() {
        assert!(close(f as f64, half, 0.05), "f32 {f}");
    }
    let mut plant = Plant::<f64>::new(&p, Rail::Wet, 40.0).unwrap();
    let input = [BrakeInput::ClampForce(12_000.0); 4];
    for _ in 0..100_000 {
        plant.step(&input);
    }
    let n = 10_000;
    let (mut a, mut f) = (0.0, [0.0; 2]);
    for _ in 0..n {
        plant.step(&input);
        a -= plant.outputs().carbody_accel / n as f64;
        for (i, x) in plant.air_spring_forces().iter().enumerate() {
            f[i] += x / n as f64;
        }
    }
    let moment =
        (v.carbody_cog_height - p.suspension.secondary_longitudinal_height) * v.carbody_mass * a;
    let transfer = moment / v.bogie_base;
    assert!(transfer > 500.0, "{transfer} N");
    assert!(
        close(f[0], half + transfer, 30.0),
        "{} vs {}",
        f[0],
        half + transfer
    );
    assert!(
        close(f[1], half - transfer, 30.0),
        "{} vs {}",
        f[1],
        half - transfer
    );
}
