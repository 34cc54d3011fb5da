//! The pad force (Eq 1's clamp force after the optional actuator lag) never leaves
//! [0, clamp-force limit] and never overshoots its target, for any input sequence and lag:
//! `pad + (target - pad) rate` rounds in f32 and, unguarded, can exceed the clamp limit by
//! one ulp (issue 12, item 7).

use hils_plant::brake::Caliper;
use hils_plant::{BrakeInput, Params, Plant, Rail};

/// Deterministic pseudo-random f32 in [lo, hi) (xorshift).
fn next(state: &mut u64, lo: f32, hi: f32) -> f32 {
    *state ^= *state << 13;
    *state ^= *state >> 7;
    *state ^= *state << 17;
    lo + (hi - lo) * ((*state >> 40) as f32 / (1u64 << 24) as f32)
}

#[test]
fn pad_force_stays_within_its_clamp_and_its_target() {
    let mut seed = 0x9E37_79B9_7F4A_7C15u64;
    for lag_s in [0.0, 1e-5, 1e-4, 3e-4, 0.05, 0.4] {
        let mut p = Params::default();
        p.brake.actuator_lag_s = lag_s;
        let limit = Caliper::<f32>::new(&p.brake).clamp_force_limit;
        let mut plant = Plant::<f32>::new(&p, Rail::Dry, 30.0).unwrap();
        let mut last = [0.0f32; 4];
        for step in 0..4000 {
            // Targets at and beyond the limit, at zero and anywhere between.
            let input = |s: &mut u64| match step % 4 {
                0 => limit,
                1 => next(s, 0.0, limit),
                2 => next(s, 0.9 * limit, 2.0 * limit),
                _ => next(s, -0.01 * limit, 0.01 * limit),
            };
            let targets = [0; 4].map(|_| input(&mut seed));
            plant.step(&targets.map(BrakeInput::ClampForce));
            let o = plant.outputs();
            for j in 0..4 {
                let pad = o.wheelsets[j].clamp_force;
                let target = targets[j].clamp(0.0, limit);
                assert!(
                    (0.0..=limit).contains(&pad),
                    "lag {lag_s} s, step {step}: pad force {pad} outside [0, {limit}]"
                );
                let (lo, hi) = (last[j].min(target), last[j].max(target));
                assert!(
                    (lo..=hi).contains(&pad),
                    "lag {lag_s} s, step {step}: pad {pad} left [{lo}, {hi}]"
                );
                if lag_s == 0.0 {
                    assert_eq!(pad, target, "no lag: the pad force is the input");
                }
                last[j] = pad;
            }
        }
    }
}

/// A NaN brake input uses the wheelset's last valid value and is flagged: without lag the
/// pad force stays at that value; with lag it keeps moving toward it, exactly as if that
/// value had been sent again (plant.rs, "Bad input").
#[test]
fn a_nan_input_acts_as_the_last_valid_value() {
    use hils_plant::Flags;
    for lag_s in [0.0, 0.05] {
        let mut p = Params::default();
        p.brake.actuator_lag_s = lag_s;
        let mut with_nan = Plant::<f32>::new(&p, Rail::Dry, 30.0).unwrap();
        let mut repeated = with_nan.clone();
        let valid = [BrakeInput::ClampForce(20_000.0); 4];
        for _ in 0..100 {
            with_nan.step(&valid);
            repeated.step(&valid);
        }
        let mut nan = valid;
        nan[1] = BrakeInput::ClampForce(f32::NAN);
        let before = with_nan.outputs().wheelsets[1].clamp_force;
        for _ in 0..20 {
            let flags = with_nan.step(&nan);
            assert!(flags.contains(Flags::wheelset_bit(Flags::INPUT_NOT_FINITE, 1)));
            assert!(
                !repeated
                    .step(&valid)
                    .contains(Flags::wheelset_bit(Flags::INPUT_NOT_FINITE, 1))
            );
            let (a, b) = (with_nan.outputs(), repeated.outputs());
            assert_eq!(
                a.wheelsets[1].clamp_force, b.wheelsets[1].clamp_force,
                "lag {lag_s}"
            );
        }
        let after = with_nan.outputs().wheelsets[1].clamp_force;
        if lag_s > 0.0 {
            assert!(
                after > before,
                "with lag the pad keeps rising: {before} -> {after}"
            );
        } else {
            assert_eq!(after, 20_000.0);
        }
    }
}

/// Non-finite inputs of either kind (NaN, +-inf; clamp force or cylinder pressure), also
/// as the very first input: flagged, and the last valid value (none yet: 0) used.
#[test]
fn non_finite_inputs_of_either_kind_use_the_last_valid_value() {
    use hils_plant::Flags;
    for lag_s in [0.0, 0.05] {
        let mut p = Params::default();
        p.brake.actuator_lag_s = lag_s;
        for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
            let kinds = [
                BrakeInput::ClampForce(bad),
                BrakeInput::CylinderPressure(bad),
            ];
            for input in kinds {
                let mut plant = Plant::<f32>::new(&p, Rail::Dry, 30.0).unwrap();
                // The first input non-finite: nothing valid yet, no brake.
                let flags = plant.step(&[input; 4]);
                for j in 0..4 {
                    assert!(flags.contains(Flags::wheelset_bit(Flags::INPUT_NOT_FINITE, j)));
                    assert_eq!(plant.outputs().wheelsets[j].clamp_force, 0.0);
                }
                // After a valid pressure, the bad value acts as that pressure again.
                let valid = BrakeInput::CylinderPressure(300e3);
                let mut reference = plant.clone();
                plant.step(&[valid; 4]);
                reference.step(&[valid; 4]);
                plant.step(&[input; 4]);
                reference.step(&[valid; 4]);
                let (a, b) = (plant.outputs(), reference.outputs());
                for j in 0..4 {
                    assert_eq!(a.wheelsets[j].clamp_force, b.wheelsets[j].clamp_force);
                    assert!(a.wheelsets[j].clamp_force > 0.0);
                }
            }
        }
    }
}
