//! The numerical hazards of the 10 kHz f32 closed loop (plant + brake unit), each shown to
//! be real and handled: axle loads after 600 m agree in f32 and f64 (cancellation between
//! positions and deflections), creepage near standstill and a clean stop. The plant's own
//! hazards are in `firmware/plant/tests/numerics.rs`.

use hils_brake_unit::BrakeDemand;
use hils_plant::{Params, Rail};
use hils_sil::ClosedLoop;

#[test]
fn axle_loads_at_600_m_agree_in_f32_and_f64() {
    let p = Params::default();
    let mut a = ClosedLoop::<f32>::new(&p, Rail::Wet, 150.0 / 3.6).unwrap();
    let mut b = ClosedLoop::<f64>::new(&p, Rail::Wet, 150.0 / 3.6).unwrap();
    a.set_demand(BrakeDemand::Emergency);
    b.set_demand(BrakeDemand::Emergency);
    // 27 s: past 550 m, before the stop.
    for _ in 0..270_000 {
        a.step();
        b.step();
    }
    let (oa, ob) = (a.outputs(), b.outputs());
    assert!(ob.distance > 550.0);
    for j in 0..4 {
        let (qa, qb) = (oa.wheelsets[j].axle_load as f64, ob.wheelsets[j].axle_load);
        assert!(
            (qa - qb).abs() < 20.0,
            "wheelset {}: f32 {qa} vs f64 {qb}",
            j + 1
        );
    }
}

#[test]
fn clean_stop_no_backward_creep_no_nan() {
    for model in [
        hils_plant::FrictionModel::Variable,
        hils_plant::FrictionModel::Constant,
    ] {
        let mut p = Params::default();
        p.friction.model = model;
        let mut sim = ClosedLoop::<f32>::new(&p, Rail::Wet, 150.0 / 3.6).unwrap();
        sim.set_demand(BrakeDemand::Emergency);
        let mut stopped_at = None;
        let mut max_distance = 0.0f32;
        for step in 0..400_000u32 {
            sim.step();
            let o = sim.outputs();
            assert!(o.vehicle_speed.is_finite() && o.distance.is_finite());
            for w in &o.wheelsets {
                // A braked wheel never spins backwards.
                assert!(w.omega >= 0.0, "omega {} at step {step}", w.omega);
                assert!(w.creepage.is_finite() && w.adhesion_force.is_finite());
                assert!(w.mu_d.is_finite() && w.disc_temp.is_finite());
            }
            if stopped_at.is_none() && o.vehicle_speed <= 0.01 {
                stopped_at = Some(step);
            }
            max_distance = max_distance.max(o.distance);
            if stopped_at.is_some() {
                // After the stop the carbody only rocks on its suspension (millimetres).
                assert!(o.distance > max_distance - 0.01, "backward creep at {step}");
            }
        }
        let o = sim.outputs();
        let stop = stopped_at.expect("stopped") as f32 * 1e-4;
        assert!(stop < 35.0);
        // 5+ s after the stop: at rest.
        assert!(o.vehicle_speed.abs() < 2e-3, "{}", o.vehicle_speed);
        for w in &o.wheelsets {
            assert_eq!(w.omega, 0.0);
            assert!(w.speed.abs() < 2e-3);
        }
        assert_eq!(sim.plant.sticky_flags().0, 0);
    }
}
