//! The model description and the parameter resource come from the project's own tables:
//! every key of the parameter file is a parameter with the range validate() checks, every
//! output carries the run-log spec's name and unit, and the resource reads back to the
//! defaults (which equal the shared reference file: host-tests/tests/param_file.rs).

use hils_fmu::description::{model_description, parameter_file};
use hils_fmu::units;
use hils_fmu::variables::{Causality, Kind, VARIABLES, by_name, by_vr};
use hils_plant::keys::{KeyInfo, KeyValue, KeyVisitor, Keys};
use hils_sil::ParamFile;

/// Every key of the file with its info, in file order: whether it has a range, whether
/// it is a count.
fn keys() -> Vec<(KeyInfo, bool, bool)> {
    struct Collect(Vec<(KeyInfo, bool, bool)>);
    impl KeyVisitor for Collect {
        fn key(&mut self, info: &KeyInfo, value: KeyValue<'_>) {
            let count = matches!(value, KeyValue::Count(_));
            let ranged = count || matches!(value, KeyValue::Real(_));
            self.0.push((*info, ranged, count));
        }
    }
    let mut c = Collect(Vec::new());
    ParamFile::default().visit_keys(&mut c);
    c.0
}

#[test]
fn every_key_is_a_parameter_whose_range_is_what_validate_refuses_outside() {
    let keys = keys();
    assert!(keys.len() > 80, "{} keys", keys.len());
    for (info, ranged, count) in &keys {
        let v = by_name(info.name).unwrap_or_else(|| panic!("no variable for key {}", info.name));
        assert_eq!(v.causality, Causality::Parameter);
        if !ranged {
            continue;
        }
        let (min, max) = v.range.expect("ranged key without min/max");
        assert_eq!((min, max), (info.min, info.max), "{}", info.name);
        // Independent of the table: set a value just outside the range in a whole file and
        // ask the project's own validation.
        let margin = |x: f64| if *count { 1.0 } else { (x.abs() + 1.0) * 1e-3 };
        for outside in [min - margin(min), max + margin(max)] {
            if *count && outside < 0.0 {
                continue;
            }
            let mut file = ParamFile::default();
            set_key(&mut file, info.name, outside);
            let err = file.validate().expect_err(info.name);
            assert_eq!(err.key, info.name, "{outside}");
        }
    }
}

fn set_key(file: &mut ParamFile, name: &str, x: f64) {
    struct Set<'a>(&'a str, f64);
    impl KeyVisitor for Set<'_> {
        fn key(&mut self, info: &KeyInfo, value: KeyValue<'_>) {
            if info.name == self.0 {
                match value {
                    KeyValue::Real(v) => *v = self.1,
                    KeyValue::Count(n) => *n = self.1.max(0.0) as u32,
                    _ => {}
                }
            }
        }
    }
    file.visit_keys(&mut Set(name, x));
}

#[test]
fn outputs_carry_the_run_log_names_and_units() {
    for (name, unit) in [
        ("v_ref_mps", "m/s"),
        ("x_m", "m"),
        ("omega1_radps", "rad/s"),
        ("omega4_radps", "rad/s"),
        ("q2_n", "N"),
        ("f_brake3_n", "N"),
        ("t_disc4_c", "degC"),
        ("mu_d1", ""),
        ("creepage2", ""),
        ("adhesion3", ""),
    ] {
        let v = by_name(name).unwrap_or_else(|| panic!("no output {name}"));
        assert_eq!((v.causality, v.unit), (Causality::Output, unit), "{name}");
    }
    for j in 1..=4 {
        assert_eq!(by_name(&format!("wsp{j}")).unwrap().kind, Kind::Boolean);
        assert_eq!(
            by_name(&format!("p_cyl{j}_pa")).unwrap().causality,
            Causality::Input
        );
        assert_eq!(
            by_name(&format!("f_clamp{j}_n")).unwrap().causality,
            Causality::Input
        );
    }
    assert_eq!(
        by_name("brake_input").unwrap().causality,
        Causality::StructuralParameter
    );
}

#[test]
fn the_description_defines_every_unit_and_is_well_formed() {
    let xml = model_description(&ParamFile::default()).unwrap();
    for v in VARIABLES.iter().filter(|v| !v.unit.is_empty()) {
        assert!(units::find(v.unit).is_some(), "{}: unit {}", v.name, v.unit);
        assert!(
            xml.contains(&format!("<Unit name=\"{}\">", v.unit)),
            "{}",
            v.unit
        );
    }
    // Value references unique, names unique.
    let mut vrs: Vec<u32> = VARIABLES.iter().map(|v| v.vr).collect();
    vrs.dedup();
    assert_eq!(vrs.len(), VARIABLES.len());
    // Every output listed once in ModelStructure/Output.
    let outputs = VARIABLES
        .iter()
        .filter(|v| v.causality == Causality::Output)
        .count();
    assert_eq!(xml.matches("<Output ").count(), outputs);
    assert!(xml.contains("instantiationToken=\"{hils-plant-"));
}

#[test]
fn start_values_and_the_resource_are_the_given_files_values() {
    let mut file = ParamFile::default();
    file.plant.vehicle.carbody_mass = 41000.0;
    file.plant.friction.mu_d0 = 0.35;
    let xml = model_description(&file).unwrap();
    assert!(xml.contains("name=\"vehicle.carbody_mass\"") && xml.contains("start=\"41000.0\""));
    // The internal step and the default experiment's step follow the file's plant step.
    file.scenario.paper_eb.step_s = 5e-5;
    let xml = model_description(&file).unwrap();
    assert!(xml.contains("fixedInternalStepSize=\"5e-5\""));
    file.scenario.paper_eb.step_s = 1e-4;
    let text = parameter_file(&file, "a test");
    let back = hils_fmu::parse_params(&text, "resource").expect("the resource reads back");
    assert_eq!(back, file);
    let defaults =
        hils_fmu::parse_params(&parameter_file(&ParamFile::default(), "t"), "t").unwrap();
    assert_eq!(defaults, ParamFile::default());
}

/// Every value reference finds its variable; the gaps between the blocks and past the
/// last find none.
#[test]
fn every_value_reference_finds_its_variable_and_no_other_finds_one() {
    let top = VARIABLES.iter().map(|v| v.vr).max().unwrap();
    for vr in (0..=top + 2).chain([u32::MAX]) {
        let want = VARIABLES.iter().find(|v| v.vr == vr);
        assert_eq!(by_vr(vr).map(|v| &v.name), want.map(|v| &v.name), "vr {vr}");
    }
}
