//! The numerical hazards of a 10 kHz f32 plant, each shown to be real and handled:
//! f32 cancellation (600 m positions vs millimetre deflections) and the stiff wheel-spin
//! equation (an explicit update chatters). The closed-loop hazards (axle loads at 600 m in
//! f32 and f64, a clean stop) are in `firmware/sil/tests/numerics.rs`.

use hils_plant::contact::Polach;
use hils_plant::{BrakeInput, Params, Plant, Rail};

#[test]
fn f32_absolute_sums_would_drift_but_the_plant_does_not() {
    // Coast at 40 m/s for 60 s (2.4 km) in f32 without brakes.
    let p = Params::default();
    let mut plant = Plant::<f32>::new(&p, Rail::Wet, 40.0).unwrap();
    let dt = plant.dt();
    let mut naive_distance = 0.0f32;
    let steps = 600_000;
    for _ in 0..steps {
        plant.step(&[BrakeInput::ClampForce(0.0); 4]);
        let o = plant.outputs();
        naive_distance += o.vehicle_speed * dt;
    }
    let o = plant.outputs();
    let exact = 40.0 * steps as f64 * dt as f64;
    // The hazard: a plain f32 running sum of v dt is off by metres after 2.4 km...
    let naive_error = (naive_distance as f64 - exact).abs();
    assert!(naive_error > 0.5, "naive f32 sum error {naive_error} m");
    // ...while the plant's compensated sum is exact to the f32 resolution of 2.4 km.
    assert!(
        (o.distance as f64 - exact).abs() < 1e-3,
        "plant distance {} vs {exact}",
        o.distance
    );
    // Speed unchanged (no force acts) and the suspension stays at its static state:
    // deflections integrate relative to their bodies, not as differences of 2.4 km positions.
    assert!((o.vehicle_speed - 40.0).abs() < 1e-5, "{}", o.vehicle_speed);
    for w in &o.wheelsets {
        assert!(
            (w.axle_load as f64 - 106_438.5).abs() < 0.05,
            "axle load {}",
            w.axle_load
        );
        assert!(w.slip_velocity.abs() < 1e-6);
    }
}

/// The slip equation of one wheelset at a fixed speed `v`, with a constant brake torque:
/// du/dt = r T_b / I - F(u) (1/m + r^2/I). Returns how many times the step-to-step change
/// of u flips sign on consecutive steps in the last half of `n` steps with an explicit
/// (forward Euler) update.
fn explicit_chatter(v: f64, n: usize) -> (usize, f64) {
    let p = Params::default();
    let polach = Polach::<f64>::new(&p.contact, Rail::Wet);
    let (m, i, r, dt) = (850.0, 280.0, 0.43, 1e-4);
    let k = 1.0 / m + r * r / i;
    let torque = 2_000.0;
    let (mut u, mut last_du, mut flips, mut last_flip) = (0.0f64, 0.0f64, 0, 0);
    for step in 0..n {
        let f = polach.evaluate(u, v, 106e3).force;
        let du = dt * (r * torque / i - k * f);
        if step > n / 2 && du * last_du < 0.0 {
            if step == last_flip + 1 {
                flips += 1;
            }
            last_flip = step;
        }
        last_du = du;
        u += du;
        if !u.is_finite() || u.abs() > 1e6 {
            return (n, u);
        }
    }
    (flips, u)
}

#[test]
fn explicit_spin_update_chatters_at_low_speed_the_plant_does_not() {
    // The contact time constant falls with speed: at 30 m/s an explicit step is fine...
    let (flips_fast, _) = explicit_chatter(30.0, 20_000);
    assert!(flips_fast < 5, "{flips_fast}");
    // ...at 0.2 m/s it oscillates from step to step (or diverges).
    let (flips_slow, _) = explicit_chatter(0.2, 20_000);
    assert!(flips_slow > 5_000, "{flips_slow}");

    // The plant brakes from 1 m/s to a stop at the same 0.1 ms step: the slip velocity
    // settles without step-to-step oscillation.
    let p = Params::default();
    let mut plant = Plant::<f64>::new(&p, Rail::Wet, 1.0).unwrap();
    let input = [BrakeInput::ClampForce(12_000.0); 4];
    let mut last = [0.0f64; 4];
    let mut last_du = [0.0f64; 4];
    // Chatter = the change of u flipping sign on consecutive steps (period-2 oscillation);
    // the suspension's physical oscillations (tens of Hz) flip it only every ~100 steps.
    let mut last_flip = [0usize; 4];
    let mut flips = 0;
    for step in 0..30_000 {
        plant.step(&input);
        let o = plant.outputs();
        for j in 0..4 {
            let u = o.wheelsets[j].slip_velocity;
            let du = u - last[j];
            if step > 100 && du * last_du[j] < 0.0 && du.abs() > 1e-9 {
                if step == last_flip[j] + 1 {
                    flips += 1;
                }
                last_flip[j] = step;
            }
            last_du[j] = du;
            last[j] = u;
            assert!(o.wheelsets[j].creepage.abs() <= 1.0 + 1e-9);
            assert!(o.wheelsets[j].omega >= 0.0);
        }
    }
    assert!(
        flips < 20,
        "{flips} step-to-step sign flips of the slip change"
    );
    // Stopped: wheels held by the brakes, wheelsets at rest; the carbody still rocks on its
    // lightly damped longitudinal suspension (mm/s).
    let o = plant.outputs();
    assert!(o.vehicle_speed.abs() < 0.01, "{}", o.vehicle_speed);
    for w in &o.wheelsets {
        assert_eq!(w.omega, 0.0);
        assert!(w.speed.abs() < 1e-3);
    }
}
