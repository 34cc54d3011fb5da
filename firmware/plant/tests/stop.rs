//! Stopping under full brake from low speed (the fuzz finding
//! `fuzz/findings/plant-vehicle-reverses-at-stop.bin`): the carbody rocks back on its
//! longitudinal suspension after the wheels stop (it was decelerated through the traction
//! links, which then release their stored energy), so its speed dips below zero for a
//! moment. What the brakes must not do, and what these tests check:
//! * add energy: kinetic + spring energy never exceeds the initial kinetic energy (level
//!   track, only brakes and dissipation);
//! * turn a wheel backwards: the clutch holds omega at 0, never below;
//! * move the vehicle backwards: after the stop it travels back no further than the
//!   springs can deflect with the energy it had (an elastic bound), and it comes to rest.

use hils_plant::{BrakeInput, Params, Plant, Rail};

/// Full brake (the input is clamped to the caliper's limit) from `v0` for `seconds`.
fn stop(rail: Rail, v0: f32, seconds: u32) {
    let p = Params::default();
    let mut plant = Plant::<f32>::new(&p, rail, v0).unwrap();
    let e = plant.energy();
    let e0 = e.kinetic + e.potential;
    // Elastic bound on the rock-back: a spring of stiffness k holding at most e0 deflects
    // at most sqrt(2 e0 / k); the carbody may swing back by twice the secondary (traction
    // link) plus primary deflections, plus 1 mm of wheel creep at standstill.
    let s = &p.suspension;
    let k_sl = s.secondary_longitudinal_stiffness * s.secondary_longitudinal_count as f64
        + s.traction_link_stiffness;
    let k_pl = s.primary_longitudinal_stiffness * s.primary_longitudinal_count as f64;
    let back_bound = 2.0 * ((2.0 * e0 / k_sl).sqrt() + (2.0 * e0 / k_pl).sqrt()) + 1e-3;
    let full = [BrakeInput::ClampForce(f32::MAX); 4];
    let steps = seconds * 10_000;
    let (mut x_max, mut back_max, mut v_min) = (0.0f64, 0.0f64, f32::MAX);
    let mut x_final_window = (f64::MAX, f64::MIN);
    for n in 0..steps {
        plant.step(&full);
        let o = plant.outputs();
        let e = plant.energy();
        assert!(
            e.kinetic + e.potential <= e0 * (1.0 + 1e-4) + 1e-3,
            "{rail:?} from {v0} m/s: energy {} > initial {e0} at step {n}",
            e.kinetic + e.potential
        );
        for (j, w) in o.wheelsets.iter().enumerate() {
            assert!(w.omega >= 0.0, "wheelset {j} spins backwards: {}", w.omega);
        }
        let x = o.distance as f64;
        x_max = x_max.max(x);
        back_max = back_max.max(x_max - x);
        v_min = v_min.min(o.vehicle_speed);
        if n >= steps - 10_000 {
            x_final_window = (x_final_window.0.min(x), x_final_window.1.max(x));
            assert!(
                o.vehicle_speed.abs() < 1e-4,
                "not at rest: {}",
                o.vehicle_speed
            );
        }
    }
    assert!(
        back_max <= back_bound,
        "{rail:?} from {v0} m/s: travelled back {back_max} m (bound {back_bound} m; min speed {v_min})"
    );
    // At rest over the last second: no creeping either way.
    assert!(
        x_final_window.1 - x_final_window.0 < 1e-4,
        "{rail:?} from {v0} m/s: moved {} m in the last second",
        x_final_window.1 - x_final_window.0
    );
}

#[test]
fn full_brake_stop_from_low_speed_adds_no_energy_and_does_not_reverse() {
    for rail in [Rail::Dry, Rail::Wet] {
        stop(rail, 0.39, 10);
    }
}

#[test]
fn full_brake_stop_from_walking_speed_adds_no_energy_and_does_not_reverse() {
    for rail in [Rail::Dry, Rail::Wet] {
        stop(rail, 3.0, 10);
    }
}
