//! The simulated brake unit in the closed loop: the EB pressure (load weighing) decelerates
//! the nominal vehicle at the EB setting.

use hils_brake_unit::{BrakeDemand, BrakeUnitParams, UnitConfig, eb_pressure};
use hils_plant::{FrictionModel, Params, Rail};
use hils_sil::ClosedLoop;

#[test]
fn eb_pressure_decelerates_the_nominal_vehicle_at_5_kmh_per_s() {
    let p = Params::default();
    let eb_deceleration_mps2 = BrakeUnitParams::default().eb_deceleration_mps2;
    // Hand: M_eff = 43 400 + 4 * 280 / 0.43^2 = 49 457.3 kg; T_b per wheelset =
    // M_eff * 1.3889 * 0.43 / 4 = 7 384.3 N m; f_clamp = T_b / (0.38 * 0.275 * 4) = 17 665.8 N;
    // P = (f_clamp / 2.5 + 1000) / 0.0227 = 355 345 Pa.
    let hand = ((49_457.3 * 1.3889 * 0.43 / 4.0) / (0.38 * 0.275 * 4.0) / 2.5 + 1000.0) / 0.0227;
    assert!(
        (eb_pressure(&p, eb_deceleration_mps2) - hand).abs() < 5.0,
        "{} vs {hand}",
        eb_pressure(&p, eb_deceleration_mps2)
    );

    // Closed loop, constant mu_d0, WSP off: the steady deceleration is the EB setting.
    let mut p = p;
    p.friction.model = FrictionModel::Constant;
    let mut config = UnitConfig::new(1e-4);
    config.wsp_enabled = false;
    let mut sim = ClosedLoop::<f64>::with_config(&p, Rail::Wet, 150.0 / 3.6, &config).unwrap();
    sim.set_demand(BrakeDemand::Emergency);
    let mut v8 = 0.0;
    for step in 1..=200_000 {
        sim.step();
        if step == 80_000 {
            v8 = sim.outputs().vehicle_speed;
        }
    }
    let decel = (v8 - sim.outputs().vehicle_speed) / 12.0;
    assert!(
        (decel - 1.3889).abs() < 0.01 * 1.3889,
        "deceleration {decel}"
    );
}

#[test]
fn a_service_demand_decelerates_the_nominal_vehicle_as_demanded() {
    // Issue 25: the service pressure was the EB pressure times the deceleration share, which
    // leaves the retaining spring's K_r / A_c = 44 kPa out of proportion: 0.6 m/s^2 gave
    // 0.49. The brake force (the clamp force) is in proportion now. Constant mu_d0, dry
    // rail, WSP off: the steady deceleration is the demand.
    let mut p = Params::default();
    p.friction.model = FrictionModel::Constant;
    let mut config = UnitConfig::new(1e-4);
    config.wsp_enabled = false;
    for demand in [0.3f32, 0.6, 1.0] {
        let mut sim = ClosedLoop::<f64>::with_config(&p, Rail::Dry, 120.0 / 3.6, &config).unwrap();
        sim.set_demand(BrakeDemand::Service {
            deceleration_mps2: demand,
        });
        let mut v4 = 0.0;
        for step in 1..=140_000 {
            sim.step();
            if step == 40_000 {
                v4 = sim.outputs().vehicle_speed;
            }
        }
        let decel = (v4 - sim.outputs().vehicle_speed) / 10.0;
        assert!(
            (decel - demand as f64).abs() < 0.01 * demand as f64,
            "demand {demand}: deceleration {decel}"
        );
    }
}
