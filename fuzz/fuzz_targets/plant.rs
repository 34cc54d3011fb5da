//! The plant step with arbitrary brake inputs (any f32: NaN, inf, negative, huge) and
//! parameter variants (friction model, rail, speed, actuator lag, mass, supply pressure):
//! outputs finite and within their limits at every step; the vehicle gains neither speed
//! nor energy (kinetic + spring) under brakes.
#![no_main]

use hils_fuzz::Bytes;
use hils_plant::brake::Caliper;
use hils_plant::{BrakeInput, FrictionModel, Params, Plant, Rail};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let mut b = Bytes(data);
    let mut p = Params::default();
    let flags = b.u8();
    p.friction.model = if flags & 1 == 0 {
        FrictionModel::Variable
    } else {
        FrictionModel::Constant
    };
    let rail = if flags & 2 == 0 { Rail::Wet } else { Rail::Dry };
    p.brake.actuator_lag_s = if flags & 4 == 0 {
        0.0
    } else {
        b.within(0.0, 0.5)
    };
    p.vehicle.carbody_mass *= b.within(0.5, 2.0);
    p.brake.supply_pressure *= b.within(0.5, 1.5);
    let v0 = b.within(0.0, 100.0) as f32;
    let Ok(mut plant) = Plant::<f32>::new(&p, rail, v0) else {
        return;
    };
    let limit = Caliper::<f32>::new(&p.brake).clamp_force_limit;
    let e0 = plant.energy().kinetic + plant.energy().potential;
    while !b.is_empty() {
        let kinds = b.u8();
        let repeat = 1 + b.u8() as usize % 64;
        let inputs: [BrakeInput<f32>; 4] = core::array::from_fn(|j| {
            let x = b.f32();
            if kinds >> j & 1 == 0 {
                BrakeInput::ClampForce(x)
            } else {
                BrakeInput::CylinderPressure(x)
            }
        });
        for _ in 0..repeat {
            plant.step(&inputs);
            let o = plant.outputs();
            assert!(o.vehicle_speed.is_finite() && o.distance.is_finite());
            assert!(o.carbody_accel.is_finite() && o.carbody_pitch.is_finite());
            // Braking on a level track: no speed is gained (0.1 % for the suspension).
            // The carbody's speed may dip below 0 after a stop: it rocks back on the
            // traction links (firmware/plant/tests/stop.rs); the brakes never add energy.
            assert!(
                o.vehicle_speed <= v0 * 1.001 + 0.01,
                "vehicle speed {} from {v0}",
                o.vehicle_speed
            );
            let e = plant.energy();
            assert!(
                e.kinetic + e.potential <= e0 * 1.001 + 1.0,
                "energy {} J above the initial {e0} J (vehicle speed {})",
                e.kinetic + e.potential,
                o.vehicle_speed
            );
            for w in &o.wheelsets {
                assert!(w.values().iter().all(|x| x.is_finite()), "{w:?}");
                assert!(
                    (0.0..=limit).contains(&w.clamp_force),
                    "clamp force {} outside [0, {limit}]",
                    w.clamp_force
                );
                assert!((0.0..=2.0).contains(&w.mu_d), "mu_d {}", w.mu_d);
                assert!(w.axle_load >= 0.0, "axle load {}", w.axle_load);
            }
        }
    }
});
