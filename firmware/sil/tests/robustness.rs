//! Property tests: no input, in or out of range, makes a step panic or produce NaN/inf;
//! out-of-range inputs are clamped and flagged; invalid parameters are refused.

use hils_brake_unit::{BrakeDemand, BrakeUnit, UnitConfig};
use hils_plant::{BrakeInput, Flags, Outputs, Params, Plant, Rail};
use hils_sil::{ClosedLoop, ParamFile};
use proptest::prelude::*;

/// Every f64 parameter of the file, mutable (for random variants).
fn fields(file: &mut ParamFile) -> Vec<&mut f64> {
    let u = &mut file.brake_unit;
    let p = &mut file.plant;
    let v = &mut p.vehicle;
    let s = &mut p.suspension;
    let c = &mut p.contact;
    let b = &mut p.brake;
    let f = &mut p.friction;
    let t = &mut p.thermal;
    let r = &mut p.resistance;
    vec![
        &mut v.g,
        &mut v.carbody_mass,
        &mut v.carbody_pitch_inertia,
        &mut v.carbody_cog_height,
        &mut v.bogie_mass,
        &mut v.bogie_pitch_inertia,
        &mut v.bogie_cog_height,
        &mut v.wheelset_mass,
        &mut v.wheelset_spin_inertia,
        &mut v.wheel_radius,
        &mut v.bogie_base,
        &mut v.wheel_base,
        &mut s.secondary_vertical_stiffness,
        &mut s.secondary_vertical_damping,
        &mut s.secondary_longitudinal_stiffness,
        &mut s.traction_link_stiffness,
        &mut s.secondary_longitudinal_damping,
        &mut s.secondary_longitudinal_height,
        &mut s.primary_vertical_stiffness,
        &mut s.primary_vertical_damping,
        &mut s.primary_longitudinal_stiffness,
        &mut s.primary_longitudinal_damping,
        &mut s.primary_longitudinal_height,
        &mut c.k_a,
        &mut c.k_s,
        &mut c.mu_0,
        &mut c.a_ratio,
        &mut c.b_exp,
        &mut c.semi_axis_a,
        &mut c.semi_axis_b,
        &mut c.shear_stiffness_c,
        &mut c.creep_speed_floor,
        &mut c.dry.k_a,
        &mut c.dry.mu_0,
        &mut b.piston_area,
        &mut b.retaining_spring_force,
        &mut b.lever_ratio,
        &mut b.friction_radius,
        &mut b.supply_pressure,
        &mut b.actuator_lag_s,
        &mut f.mu_d0,
        &mut f.n_v,
        &mut f.m_v,
        &mut f.n_t,
        &mut f.m_t,
        &mut f.correction_c,
        &mut f.k_p,
        &mut t.heat_partition,
        &mut t.disc_mass,
        &mut t.specific_heat,
        &mut t.alpha,
        &mut t.beta,
        &mut t.ambient_rise,
        &mut p.track.gradient_permille,
        &mut r.davis_a_n,
        &mut r.davis_b_n_per_mps,
        &mut r.davis_c_n_per_mps2,
        &mut u.eb_deceleration_mps2,
        &mut u.fill_time_constant_s,
        &mut u.vent_time_constant_s,
        &mut u.dead_time_s,
    ]
}

fn any_f32() -> impl Strategy<Value = f32> {
    prop_oneof![
        4 => -1.0e6f32..1.0e6f32,
        2 => 0.0f32..30_000.0f32,
        1 => Just(f32::NAN),
        1 => Just(f32::INFINITY),
        1 => Just(f32::NEG_INFINITY),
        1 => Just(f32::MAX),
        1 => Just(-f32::MAX),
        1 => Just(f32::MIN_POSITIVE),
        1 => Just(-0.0f32),
        1 => any::<f32>(),
    ]
}

fn any_input() -> impl Strategy<Value = BrakeInput<f32>> {
    prop_oneof![
        any_f32().prop_map(BrakeInput::ClampForce),
        any_f32().prop_map(BrakeInput::CylinderPressure),
    ]
}

fn assert_finite(o: &Outputs<f32>) {
    assert!(o.vehicle_speed.is_finite() && o.distance.is_finite() && o.carbody_accel.is_finite());
    assert!(o.damper_power.is_finite() && o.external_power.is_finite());
    for w in &o.wheelsets {
        for x in w.values() {
            assert!(x.is_finite(), "{o:?}");
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]

    #[test]
    fn any_brake_input_gives_finite_outputs_and_flags_bad_values(
        v0 in any_f32(),
        inputs in prop::collection::vec(prop::array::uniform4(any_input()), 1..40),
        repeat in 1usize..400,
    ) {
        let p = Params::default();
        let mut plant = Plant::<f32>::new(&p, Rail::Wet, v0).unwrap();
        let cal = hils_plant::brake::Caliper::<f32>::new(&p.brake);
        let flags0 = plant.outputs().flags;
        if !(v0.is_finite() && (0.0..=140.0).contains(&v0)) {
            prop_assert!(flags0.contains(Flags::INITIAL_SPEED_CLAMPED));
        } else {
            prop_assert!(!flags0.contains(Flags::INITIAL_SPEED_CLAMPED));
        }
        for step_inputs in &inputs {
            for _ in 0..repeat {
                plant.step(step_inputs);
                let o = plant.outputs();
                assert_finite(&o);
                for j in 0..4 {
                    let (value, limit) = match step_inputs[j] {
                        BrakeInput::ClampForce(f) => (f, cal.clamp_force_limit),
                        BrakeInput::CylinderPressure(p) => (p, cal.pressure_limit),
                    };
                    let w = &o.wheelsets[j];
                    prop_assert!(w.clamp_force >= 0.0 && w.clamp_force <= cal.clamp_force_limit);
                    let nan_bit = Flags::wheelset_bit(Flags::INPUT_NOT_FINITE, j);
                    let range_bit = Flags::wheelset_bit(Flags::INPUT_OUT_OF_RANGE, j);
                    if !value.is_finite() {
                        prop_assert!(o.flags.contains(nan_bit));
                    } else {
                        prop_assert!(!o.flags.contains(nan_bit));
                        let out = value > limit || value < -0.02 * limit;
                        prop_assert_eq!(o.flags.contains(range_bit), out);
                    }
                }
                prop_assert!(!o.flags.contains(Flags::NUMERIC_FAULT));
            }
        }
    }

    #[test]
    fn any_parameter_variant_is_refused_or_steps_finite(
        changes in prop::collection::vec((0usize..64, any::<f64>(), -6.0f64..6.0, any::<bool>()), 1..4),
        v0 in 0.0f32..140.0,
        clamp in 0.0f32..40_000.0,
        dry in any::<bool>(),
    ) {
        let mut file = ParamFile::default();
        {
            let mut f = fields(&mut file);
            let n = f.len();
            for (i, raw, log_scale, use_raw) in &changes {
                let x = &mut f[i % n];
                **x = if *use_raw { *raw } else { **x * 10f64.powf(*log_scale) };
            }
        }
        let rail = if dry { Rail::Dry } else { Rail::Wet };
        let p = file.plant;
        match ClosedLoop::<f32>::from_file(&file, rail, v0) {
            Err(_) => {
                // Refused: the validation must name a reason the values fail.
                prop_assert!(file.validate().is_err() || Plant::<f32>::new(&p, rail, v0).is_err()
                    || BrakeUnit::<f32>::new(&p, &file.unit_config()).is_err());
            }
            Ok(mut sim) => {
                sim.set_demand(BrakeDemand::Emergency);
                for _ in 0..3_000 {
                    sim.step();
                    let o = sim.outputs();
                    assert_finite(&o);
                    prop_assert!(!o.flags.contains(Flags::NUMERIC_FAULT));
                }
                let mut plant = Plant::<f32>::new(&p, rail, v0).unwrap();
                for _ in 0..3_000 {
                    plant.step(&[BrakeInput::ClampForce(clamp); 4]);
                    let o = plant.outputs();
                    assert_finite(&o);
                }
            }
        }
    }

    #[test]
    fn brake_unit_survives_any_wheel_speed(
        speeds in prop::collection::vec(prop::array::uniform4(any_f32()), 1..50),
        eb in any::<bool>(),
        service in any_f32(),
    ) {
        let p = Params::default();
        let mut unit = BrakeUnit::<f32>::new(&p, &UnitConfig::new(1e-4)).unwrap();
        unit.set_demand(if eb { BrakeDemand::Emergency } else { BrakeDemand::Service { deceleration_mps2: service } });
        for s in &speeds {
            for _ in 0..100 {
                let out = unit.step(s);
                for pc in out.cylinder_pressure_pa {
                    prop_assert!(pc.is_finite() && pc >= 0.0 && pc <= p.brake.supply_pressure as f32);
                }
                prop_assert!(out.reference_speed_mps.is_finite());
            }
        }
    }
}
