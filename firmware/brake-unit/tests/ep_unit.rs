//! The paper's brake unit (issue 13): EP valve with PI control and hysteresis
//! compensation, service brake steps, pulsed WSP reapply.

mod common;

use hils_brake_unit::ep::{EpConstants, EpValve};
use hils_brake_unit::{BrakeDemand, BrakeUnitParams, Valve};

/// Control cycles until the pilot stays within `tol` Pa of `target` (from 0).
fn settling_cycles(compensate: bool, target: f64, tol: f64) -> usize {
    let mut params = BrakeUnitParams::default();
    params.ep_hysteresis_compensation = compensate;
    let k = EpConstants::<f64>::new(&params, 1e-3, 500e3);
    let mut ep = EpValve::default();
    let mut last_out = 0;
    for n in 0..20_000 {
        let p = ep.update(&k, target);
        if (p - target).abs() > tol {
            last_out = n + 1;
        }
    }
    last_out
}

#[test]
fn ep_valve_reaches_the_target_and_compensation_speeds_it_up() {
    for target in [100e3, 250e3, 355e3] {
        let with = settling_cycles(true, target, 500.0);
        let without = settling_cycles(false, target, 500.0);
        // Within 0.5 kPa in well under a second with compensation (pilot lag 30 ms)...
        assert!(with < 400, "{target}: {with} cycles");
        // ...and the play of 15 kPa costs the uncompensated PI a wind-up of h/2.
        assert!(without > with, "{target}: {without} vs {with}");
    }
}

#[test]
fn ep_valve_follows_falling_targets_and_stays_in_supply() {
    let params = BrakeUnitParams::default();
    let k = EpConstants::<f32>::new(&params, 1e-3, 500e3);
    let mut ep = EpValve::default();
    for target in [300e3f32, 120e3, 0.0, 1e9, -5.0] {
        let mut p = 0.0;
        for _ in 0..3000 {
            p = ep.update(&k, target);
            assert!((0.0..=500e3).contains(&p), "{p}");
        }
        let want = target.clamp(0.0, 500e3);
        assert!((p - want).abs() < 1e3, "{target}: {p}");
    }
}

#[test]
fn service_steps_scale_the_pressure() {
    let mut unit = common::reference_unit::<f64>();
    let eb = unit.eb_pressure();
    let speeds = [30.0; 4];
    let mut at = Vec::new();
    for step in [1u8, 4, 7, 9] {
        unit.set_demand(BrakeDemand::ServiceStep { step });
        let mut pressure = 0.0;
        for _ in 0..60_000 {
            pressure = unit.step(&speeds).cylinder_pressure_pa[0];
        }
        at.push(pressure);
    }
    // step/7 of the 1.0 m/s^2 full service over the 1.3889 m/s^2 EB; above 7: step 7.
    for (i, step) in [1.0, 4.0, 7.0, 7.0].into_iter().enumerate() {
        let want = eb * step / 7.0 * 1.0 / 1.3889;
        assert!(
            (at[i] - want).abs() < 0.005 * eb,
            "step {step}: {} vs {want}",
            at[i]
        );
    }
}

#[test]
fn wsp_reapplies_in_pulses() {
    // Wheel 4 slides at 3 s and recovers; after the WSP's hold the cylinder refills in
    // steps: held plateaus between fills.
    let mut unit = common::emergency_unit::<f64>();
    let dt = common::DT;
    let mut v = 40.0;
    let mut trace = Vec::new();
    let mut valves = Vec::new();
    for step in 0..80_000 {
        let t = step as f64 * dt;
        v -= 1.3 * dt;
        let w4 = if (3.0..3.3).contains(&t) {
            v - 8.0 * (t - 3.0)
        } else if (3.3..3.6).contains(&t) {
            (v - 2.4 + 10.0 * (t - 3.3)).min(v)
        } else {
            v
        };
        let out = unit.step(&[v, v, v, w4]);
        trace.push(out.cylinder_pressure_pa[3]);
        valves.push(out.valves[3]);
    }
    let last_wsp = valves
        .iter()
        .rposition(|&x| x != Valve::Apply)
        .expect("WSP acted");
    let low = trace[last_wsp..]
        .iter()
        .copied()
        .fold(f64::INFINITY, f64::min);
    let eb = unit.eb_pressure();
    assert!(low < 0.9 * eb, "vented to {low}");
    // After the WSP, while refilling below 90 % of EB: plateaus (no change over 1 ms)
    // alternate with fills.
    let refill: Vec<f64> = trace[last_wsp..]
        .iter()
        .copied()
        .take_while(|&p| p < 0.9 * eb)
        .collect();
    let steps_flat = refill.windows(2).filter(|w| w[1] == w[0]).count();
    let steps_rising = refill.windows(2).filter(|w| w[1] > w[0]).count();
    assert!(
        steps_flat > 100 && steps_rising > 100,
        "{steps_flat} {steps_rising}"
    );
}

/// Cycles until the pilot stays within `tol` Pa of `low` after rising to `high` and
/// settling there (a reversal of the valve's motion).
fn settling_after_reversal(compensate: bool, high: f64, low: f64, tol: f64) -> (usize, f64) {
    let mut params = BrakeUnitParams::default();
    params.ep_hysteresis_compensation = compensate;
    let k = EpConstants::<f64>::new(&params, 1e-3, 500e3);
    let mut ep = EpValve::default();
    for _ in 0..5000 {
        ep.update(&k, high);
    }
    let before = ep.pilot();
    let mut last_out = 0;
    for n in 0..20_000 {
        if (ep.update(&k, low) - low).abs() > tol {
            last_out = n + 1;
        }
    }
    (last_out, before)
}

#[test]
fn hysteresis_compensation_acts_on_a_reversal() {
    // Rising to 300 kPa, then falling to 150 kPa: the valve's output must cross its whole
    // play h (15 kPa) before it moves down. The compensation switches its +h/2 to -h/2 with
    // the direction, so the pilot settles as fast as on the way up; the plain PI winds its
    // integral through the play first.
    for (high, low) in [(300e3, 150e3), (200e3, 190e3)] {
        let (with, before) = settling_after_reversal(true, high, low, 500.0);
        let (without, _) = settling_after_reversal(false, high, low, 500.0);
        assert!(
            (before - high).abs() < 500.0,
            "did not settle at {high}: {before}"
        );
        assert!(with < 400, "{high} -> {low}: {with} cycles");
        assert!(without > with, "{high} -> {low}: {without} vs {with}");
    }
}
