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

/// `(key, field)` rows of WSP values: the file's key is `wsp.` and the field's name.
macro_rules! wsp_fields {
    ($($field:ident),* $(,)?) => {
        [$((concat!("wsp.", stringify!($field)), |c| &mut c.wsp.$field)),*]
    };
}

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
    let wsp: [Field; 12] = wsp_fields! {
        deficit_min, deficit_ratio, reapply_ratio, decel_threshold, recover_accel,
        caught_up_accel, lock_ratio, vent_max, hold_max, min_speed, ref_max_decel, accel_filter,
    };
    let fields = brake_unit.into_iter().chain(wsp);
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
