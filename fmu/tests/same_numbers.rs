//! The FMU gives `hils simulate`'s numbers bit for bit: its paper run (tools/src/scenario.rs
//! `run_eb`, every plant step recorded) against the FMU driven through its C API
//! (a) as the plant alone, with the run's cylinder pressures as inputs at a 0.1 ms
//! communication step, and (b) as the closed loop (`brake_input = brake_unit`, `cmd = EB`)
//! at 1 ms; every output at every communication point. `scripts/fmu-check.sh` shows the
//! same with the packed FMU through FMPy, a direct import and rust-fmi's importer.

mod common;

use common::{Fmu, OK, resources};
use hils_fmu::variables::{Causality, Kind, VARIABLES};
use hils_fmu_check::{UNIT_OUTPUTS, columns, first_difference, paper_run};
use hils_sil::{ParamFile, RunRecord};

/// The FMU's Float64 and Boolean outputs, and their columns in the record's values.
fn outputs() -> (Vec<String>, Vec<usize>) {
    let names: Vec<String> = VARIABLES
        .iter()
        .filter(|v| {
            v.causality == Causality::Output && matches!(v.kind, Kind::Float64 | Kind::Boolean)
        })
        .map(|v| v.name.clone())
        .collect();
    let cols = columns(&names).expect("every output has a value in the record");
    (names, cols)
}

/// Every output compared with the record, bit for bit; the number of values compared.
fn compare(
    fmu: &Fmu,
    names: &[String],
    cols: &[usize],
    s: &RunRecord,
    k: usize,
    skip: &[&str],
) -> usize {
    let got: Vec<f64> = names
        .iter()
        .map(|n| {
            if n.starts_with("wsp") {
                fmu.get_bool(n) as u8 as f64
            } else {
                fmu.get_f64(n)
            }
        })
        .collect();
    if let Some(d) = first_difference(s, names, cols, &got, skip, k) {
        panic!("{d}");
    }
    names
        .iter()
        .filter(|n| !skip.iter().any(|p| n.starts_with(p)))
        .count()
}

#[test]
fn plant_driven_by_the_paper_runs_pressures_gives_its_numbers_bit_for_bit() {
    let file = ParamFile::default();
    let run = paper_run(&file).unwrap();
    let (names, cols) = outputs();
    let fmu = Fmu::new(&resources("plant", &file));
    fmu.init();
    let dt = file.scenario.paper_eb.step_s;
    let mut values = compare(&fmu, &names, &cols, &run.samples[0], 0, &UNIT_OUTPUTS);
    let mut t = 0.0;
    let mut slowest = f64::INFINITY;
    for (k, s) in run.samples.iter().enumerate().skip(1) {
        for j in 0..4 {
            assert_eq!(
                fmu.set_f64(&format!("p_cyl{}_pa", j + 1), s.p_cyl_pa[j]),
                OK
            );
        }
        assert_eq!(fmu.step(t, dt), OK, "step {k}: {}", fmu.last());
        t += dt;
        values += compare(&fmu, &names, &cols, s, k, &UNIT_OUTPUTS);
        slowest = slowest.min(fmu.get_f64("v_ref_mps"));
    }
    // The run braked to a stop with both slides of the paper: the comparison covered them.
    assert!(run.samples.len() > 290_000, "{} steps", run.samples.len());
    assert_eq!(run.summary.slides, vec![2, 4]);
    assert!(
        slowest <= 0.01,
        "the FMU's carbody stopped (slowest {slowest} m/s)"
    );
    println!(
        "{} steps, {values} values bit-identical",
        run.samples.len() - 1
    );
}

#[test]
fn closed_loop_at_1_ms_gives_the_paper_runs_numbers_bit_for_bit() {
    let file = ParamFile::default();
    let run = paper_run(&file).unwrap();
    let (names, cols) = outputs();
    let fmu = Fmu::new(&resources("loop", &file));
    assert_eq!(fmu.set_i64("brake_input", 2), OK);
    assert_eq!(fmu.set_i64("cmd", 1), OK);
    fmu.init();
    let h = 1e-3;
    let mut t = 0.0;
    let mut points = 0;
    let mut vented = [false; 4];
    for (k, s) in run.samples.iter().enumerate().step_by(10).skip(1) {
        assert_eq!(fmu.step(t, h), OK, "{}", fmu.last());
        t += h;
        compare(&fmu, &names, &cols, s, k, &[]);
        for (j, v) in vented.iter_mut().enumerate() {
            *v |= fmu.get_bool(&format!("wsp{}", j + 1));
        }
        points += 1;
    }
    assert!(points > 29_000);
    assert_eq!(
        vented,
        [false, true, false, true],
        "WSP acts on 2 and 4 as in the paper"
    );
}

#[test]
fn plant_driven_by_the_paper_runs_clamp_forces_gives_its_numbers_bit_for_bit() {
    // The pad force the closed loop's pressures made through Eq (1), given directly as a
    // load cell's: the plant takes it as it is (no lag in the reference vehicle), so the
    // run is the same.
    let file = ParamFile::default();
    let run = paper_run(&file).unwrap();
    let (names, cols) = outputs();
    let fmu = Fmu::new(&resources("clamp-force", &file));
    assert_eq!(fmu.set_i64("brake_input", 1), OK);
    fmu.init();
    let dt = file.scenario.paper_eb.step_s;
    let mut t = 0.0;
    for (k, s) in run.samples.iter().enumerate().skip(1) {
        for j in 0..4 {
            assert_eq!(
                fmu.set_f64(&format!("f_clamp{}_n", j + 1), s.f_clamp_n[j]),
                OK
            );
        }
        assert_eq!(fmu.step(t, dt), OK, "step {k}: {}", fmu.last());
        t += dt;
        compare(&fmu, &names, &cols, s, k, &UNIT_OUTPUTS);
    }
}
