//! The FMU gives `hils simulate`'s numbers bit for bit: its paper run (tools/src/scenario.rs
//! `run_eb`, every plant step recorded) against the FMU driven through its C API
//! (a) as the plant alone, with the run's cylinder pressures as inputs at a 0.1 ms
//! communication step, and (b) as the closed loop (`brake_input = brake_unit`, `cmd = EB`)
//! at 1 ms; every output at every communication point. `scripts/fmu-check.sh` shows the
//! same through FMPy with the packed FMU.

mod common;

use common::{Fmu, OK, resources};
use hils::scenario::{EbOptions, Run, run_eb};
use hils_fmu::variables::{Causality, Kind, VARIABLES};
use hils_sil::{ParamFile, RunRecord};

/// The paper run of `hils simulate` (f32), every step recorded.
fn paper_run(file: &ParamFile) -> Run {
    let mut opts = EbOptions::paper(file);
    opts.record_every = 1;
    run_eb::<f32>(file, &opts).expect("paper run")
}

/// What a record says an output is, by the output's name (written out here, not through
/// the record's own channel lookup).
fn expected(s: &RunRecord, name: &str) -> Option<f64> {
    let wheelset = |stem: &str, unit: &str| -> Option<usize> {
        let rest = name.strip_prefix(stem)?.strip_suffix(unit)?;
        match rest {
            "1" | "2" | "3" | "4" => Some(rest.parse::<usize>().ok()? - 1),
            _ => None,
        }
    };
    let scalars = [
        ("v_ref_mps", s.v_ref_mps),
        ("x_m", s.x_m),
        ("a_x_mps2", s.a_x_mps2),
        ("v_ref_est_mps", s.v_ref_est_mps),
    ];
    if let Some((_, x)) = scalars.iter().find(|(n, _)| *n == name) {
        return Some(*x);
    }
    let per_wheelset: [(&str, &str, &[f64; 4]); 11] = [
        ("omega", "_radps", &s.omega_radps),
        ("q", "_n", &s.q_n),
        ("mu_d", "", &s.mu_d),
        ("f_brake", "_n", &s.f_brake_n),
        ("t_disc", "_c", &s.t_disc_c),
        ("creepage", "", &s.creepage),
        ("adhesion", "", &s.adhesion),
        ("f_clamp_act", "_n", &s.f_clamp_n),
        ("p_cyl_unit", "_pa", &s.p_cyl_pa),
        ("wsp", "", &s.wsp.map(|w| w as u8 as f64)),
        ("", "", &[0.0; 4]),
    ];
    per_wheelset
        .iter()
        .filter(|(stem, _, _)| !stem.is_empty())
        .find_map(|(stem, unit, values)| wheelset(stem, unit).map(|j| values[j]))
}

/// Compares every Float64 and Boolean output of the FMU with the record, bit for bit;
/// `skip` names outputs the mode does not model.
fn compare(fmu: &Fmu, s: &RunRecord, step: usize, skip: &[&str]) -> usize {
    let mut compared = 0;
    for v in VARIABLES
        .iter()
        .filter(|v| v.causality == Causality::Output)
    {
        if skip.iter().any(|p| v.name.starts_with(p)) {
            continue;
        }
        let got = match v.kind {
            Kind::Float64 => fmu.get_f64(&v.name),
            Kind::Boolean => fmu.get_bool(&v.name) as u8 as f64,
            _ => continue,
        };
        let want = expected(s, &v.name).unwrap_or_else(|| panic!("no expectation for {}", v.name));
        assert_eq!(
            got.to_bits(),
            want.to_bits(),
            "{} at step {step} (t = {} s): FMU {got}, hils simulate {want}",
            v.name,
            s.t_s
        );
        compared += 1;
    }
    compared
}

#[test]
fn plant_driven_by_the_paper_runs_pressures_gives_its_numbers_bit_for_bit() {
    let file = ParamFile::default();
    let run = paper_run(&file);
    let fmu = Fmu::new(&resources("plant", &file));
    fmu.init();
    let dt = file.scenario.paper_eb.step_s;
    let skip = ["p_cyl_unit", "wsp", "v_ref_est"];
    let mut values = compare(&fmu, &run.samples[0], 0, &skip);
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
        values += compare(&fmu, s, k, &skip);
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
    let run = paper_run(&file);
    let fmu = Fmu::new(&resources("loop", &file));
    assert_eq!(fmu.set_i64("brake_input", 2), OK);
    assert_eq!(fmu.set_i64("cmd", 1), OK);
    fmu.init();
    let h = 1e-3;
    let every = 10;
    let mut t = 0.0;
    let mut points = 0;
    let mut vented = [false; 4];
    for (k, s) in run.samples.iter().enumerate().step_by(every).skip(1) {
        assert_eq!(fmu.step(t, h), OK, "{}", fmu.last());
        t += h;
        compare(&fmu, s, k, &[]);
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
