//! `BrakeUnit::new` refuses every value it cannot run with (issue 12, item 7): NaN, inf,
//! zero, negative and huge values of each `[brake_unit]` field, of the WSP tuning, of the
//! plant parameters it is built from and of the periods; the error names the key.

use hils_brake_unit::{BrakeUnit, UnitConfig, UnitError};
use hils_plant::Params;

const BAD: [f64; 5] = [f64::NAN, f64::INFINITY, f64::NEG_INFINITY, -1.0, 1e300];

fn build(p: &Params, c: &UnitConfig) -> Result<BrakeUnit<f32>, UnitError> {
    BrakeUnit::<f32>::new(p, c)
}

fn key_of(e: UnitError) -> &'static str {
    match e {
        UnitError::Params(pe) => pe.key,
        other => panic!("expected a parameter error, got {other:?}"),
    }
}

/// The WSP tuning's fields, as accessors, in the order of [`WSP_KEYS`].
macro_rules! wsp_fields {
    ($($field:ident),* $(,)?) => {
        [$(|c: &mut UnitConfig| &mut c.wsp.$field),*]
    };
}

/// The keys the errors name, written out (not made from the field names, which carry units).
const WSP_KEYS: &str = "wsp.deficit_min wsp.deficit_ratio wsp.reapply_ratio \
    wsp.decel_threshold wsp.overbrake_decel wsp.overbrake_deficit_ratio wsp.turn_accel \
    wsp.caught_up_accel wsp.dump_share wsp.dump_settle wsp.memory_share wsp.probe_step_share \
    wsp.cap_share wsp.risen_share wsp.sudden_grip_accel wsp.lock_ratio wsp.vent_max \
    wsp.hold_max wsp.timer_inhibit wsp.min_speed wsp.ref_max_decel wsp.ref_decel_gain \
    wsp.ref_margin_decel wsp.accel_filter";

#[test]
fn every_brake_unit_and_wsp_value_is_checked() {
    let p = Params::default();
    type Field = (&'static str, fn(&mut UnitConfig) -> &mut f64);
    // `[brake_unit]`: the file's keys are the fields' names without their unit.
    let brake_unit: [Field; 4] = [
        ("brake_unit.eb_deceleration", |c| {
            &mut c.params.eb_deceleration_mps2
        }),
        ("brake_unit.fill_time_constant", |c| {
            &mut c.params.fill_time_constant_s
        }),
        ("brake_unit.vent_time_constant", |c| {
            &mut c.params.vent_time_constant_s
        }),
        ("brake_unit.dead_time", |c| &mut c.params.dead_time_s),
    ];
    let wsp: [fn(&mut UnitConfig) -> &mut f64; 24] = wsp_fields! {
        deficit_min_mps, deficit_ratio, reapply_ratio, decel_threshold_mps2,
        overbrake_decel_mps2, overbrake_deficit_ratio, turn_accel_mps2, caught_up_accel_mps2,
        dump_share, dump_settle_s, memory_share, probe_step_share, cap_share, risen_share,
        sudden_grip_accel_mps2, lock_ratio, vent_max_s, hold_max_s, timer_inhibit_s,
        min_speed_mps, ref_max_decel_mps2, ref_decel_gain, ref_margin_decel_mps2,
        accel_filter_s,
    };
    let wsp_keys: Vec<&str> = WSP_KEYS.split_whitespace().collect();
    assert_eq!(wsp_keys.len(), wsp.len());
    let fields = brake_unit.into_iter().chain(wsp_keys.into_iter().zip(wsp));
    assert!(build(&p, &UnitConfig::new(1e-4)).is_ok());
    for (key, field) in fields {
        for bad in BAD {
            // -1 is a legal wheel acceleration threshold; everything else is out of range.
            if bad == -1.0 && key.ends_with("accel") && !key.ends_with("filter") {
                continue;
            }
            let mut c = UnitConfig::new(1e-4);
            *field(&mut c) = bad;
            let e = build(&p, &c).expect_err(&format!("{key} = {bad} accepted"));
            assert_eq!(key_of(e), key, "{key} = {bad}");
        }
    }
}

#[test]
fn nan_dead_time_is_an_error_not_a_zero_delay() {
    let mut c = UnitConfig::new(1e-4);
    c.params.dead_time_s = f64::NAN;
    let e = build(&Params::default(), &c).unwrap_err();
    assert_eq!(key_of(e), "brake_unit.dead_time");
}

#[test]
fn plant_parameters_the_unit_uses_are_checked() {
    let mut p = Params::default();
    p.brake.supply_pressure = f64::NAN;
    let e = build(&p, &UnitConfig::new(1e-4)).unwrap_err();
    assert_eq!(key_of(e), "brake.supply_pressure");
    let mut p = Params::default();
    p.friction.mu_d0 = 0.0;
    assert!(build(&p, &UnitConfig::new(1e-4)).is_err());
}

#[test]
fn periods_must_be_positive_finite_and_at_most_a_second() {
    let p = Params::default();
    for bad in [0.0, -1e-4, f64::NAN, f64::INFINITY, 2.0] {
        let mut c = UnitConfig::new(1e-4);
        c.control_period_s = bad;
        assert_eq!(
            build(&p, &c).unwrap_err(),
            UnitError::BadPeriod,
            "cycle {bad}"
        );
        let c = UnitConfig::new(bad);
        assert_eq!(
            build(&p, &c).unwrap_err(),
            UnitError::BadPeriod,
            "step {bad}"
        );
    }
}
