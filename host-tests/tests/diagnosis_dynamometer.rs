//! `hils fit-friction` on brake-dynamometer data: Eq (2) recovered within 5 % from noisy
//! points and from noisy stop time series; honest warnings when the data cannot separate
//! the parameters; the reader's error behaviour on friction-test files.

use std::path::Path;

use hils::fit_friction::{NAMES, eq2, fit_points};
use hils::measured::parse_friction_test;
use hils_plant::Params;
use host_tests::generator::{dynamometer_points, dynamometer_stops};

fn table1() -> hils_plant::params::FrictionParams {
    Params::default().friction
}

fn values(f: &hils::fit_friction::FrictionFit) -> [f64; 5] {
    [f.mu_d0, f.n_v, f.m_v, f.n_t, f.m_t]
}

fn truth() -> [f64; 5] {
    let t = table1();
    [t.mu_d0, t.n_v, t.m_v, t.n_t, t.m_t]
}

fn assert_within(fit: &hils::fit_friction::FrictionFit, tolerance: f64, what: &str) {
    for ((name, got), want) in NAMES.iter().zip(values(fit)).zip(truth()) {
        let err = (got - want).abs() / want;
        assert!(
            err <= tolerance,
            "{what}: {name} = {got:.5}, Table 1 {want:.5} ({:.1} % off)",
            err * 100.0
        );
    }
}

#[test]
fn noisy_points_give_table1_within_5_percent() {
    for seed in [1u64, 2, 3] {
        // sigma 0.0015 on mu (0.4 %), 500 points over 0.5-32 m/s and 0-200 degC.
        let text = dynamometer_points(seed, &table1(), 0.0015, 500, 0.5..32.0, 0.0..200.0);
        let test = parse_friction_test(Path::new("points.csv"), &text).expect("reads");
        assert_eq!(test.mu.len(), 500);
        let fit = fit_points(&test.v_friction_mps, &test.t_disc_c, &test.mu, 0.98).expect("fits");
        eprintln!("seed {seed}: {fit:?}");
        assert_within(&fit, 0.05, &format!("points seed {seed}"));
        // RMS near the noise.
        assert!((fit.rms - 0.0015).abs() < 0.0003, "rms {}", fit.rms);
        assert!(fit.warnings.is_empty(), "{:?}", fit.warnings);
    }
}

#[test]
fn confidence_intervals_cover_the_truth_about_95_percent_of_the_time() {
    // 40 data sets with sigma 0.004: each parameter's 95 % interval must contain Table 1 in
    // at least 33 of them (binomial: 95 % coverage gives fewer than 34 with probability
    // below 1 %), and not in all of them by being absurdly wide (half-width < 30 %).
    let n = 40;
    let mut covered = [0usize; 5];
    for seed in 100..100 + n as u64 {
        let text = dynamometer_points(seed, &table1(), 0.004, 300, 0.5..32.0, 0.0..200.0);
        let test = parse_friction_test(Path::new("cov.csv"), &text).unwrap();
        let fit = fit_points(&test.v_friction_mps, &test.t_disc_c, &test.mu, 0.98).unwrap();
        for (k, (name, want)) in NAMES.iter().zip(truth()).enumerate() {
            let [lo, hi] = fit.ci95[*name];
            assert!(hi - lo < 0.6 * want, "{name}: CI [{lo}, {hi}] too wide");
            if lo <= want && want <= hi {
                covered[k] += 1;
            }
        }
    }
    for (name, c) in NAMES.iter().zip(covered) {
        assert!(
            c >= 33,
            "{name}: CI covered Table 1 in {c} of {n} data sets"
        );
    }
}

#[test]
fn noisy_stop_series_from_forces_give_table1_within_5_percent() {
    let text = dynamometer_stops(7, &table1(), 15.0);
    let test = parse_friction_test(Path::new("stops.csv"), &text).expect("reads");
    // The released rows (clamp force 0) are skipped and counted, never silently dropped.
    assert_eq!(test.skipped, 60, "{:?}", test.notes);
    assert!(test.notes.iter().any(|n| n.contains("brake released")));
    let fit = fit_points(&test.v_friction_mps, &test.t_disc_c, &test.mu, 0.98).expect("fits");
    assert_within(&fit, 0.05, "stops");
}

#[test]
fn fitted_curve_matches_the_plants_eq2_everywhere() {
    // Independent f64 check: the fitted model evaluated through the plant's Eq (2) against
    // Eq (2) written out here.
    let text = dynamometer_points(11, &table1(), 0.0, 200, 0.5..32.0, 0.0..300.0);
    let test = parse_friction_test(Path::new("exact.csv"), &text).expect("reads");
    let fit = fit_points(&test.v_friction_mps, &test.t_disc_c, &test.mu, 0.98).expect("fits");
    let p = fit.params();
    for v in [0.0, 5.0, 10.0, 20.0, 30.0] {
        for t in [0.0, 50.0, 150.0, 300.0] {
            let by_hand = 0.98
                * 0.38
                * (0.184 * (-0.1 * v as f64).exp() + 1.0)
                * (0.105 * (-0.014 * t as f64).exp() + 1.0);
            assert!(
                (eq2(&p, v, t) - by_hand).abs() < 2e-4,
                "v {v} T {t}: {} vs {by_hand}",
                eq2(&p, v, t)
            );
        }
    }
}

#[test]
fn points_that_cannot_separate_mu_d0_from_the_factors_are_reported() {
    // Only cold and slow points: the exponentials never decay, mu_d0 and n_v / n_t trade off.
    let text = dynamometer_points(5, &table1(), 0.004, 300, 0.5..4.0, 0.0..30.0);
    let test = parse_friction_test(Path::new("narrow.csv"), &text).expect("reads");
    let fit = fit_points(&test.v_friction_mps, &test.t_disc_c, &test.mu, 0.98).expect("fits");
    assert!(
        !fit.warnings.is_empty(),
        "no identifiability warning for narrow points: {fit:?}"
    );
}

#[test]
fn friction_file_errors_name_file_row_and_column() {
    let bad = "v_friction_mps,t_disc_c,mu\n10,20,0.4\n9,21,x\n";
    let e = parse_friction_test(Path::new("dyno.csv"), bad).unwrap_err();
    assert_eq!((e.row, e.column.as_str()), (2, "mu"));
    assert!(e.to_string().contains("dyno.csv"));
    let missing = "v_friction_mps,mu\n10,0.4\n";
    let e = parse_friction_test(Path::new("dyno.csv"), missing).unwrap_err();
    assert_eq!(e.column, "t_disc_c");
    let impossible = "v_friction_mps,t_disc_c,mu\n10,20,0.4\n9,21,3.5\n";
    let e = parse_friction_test(Path::new("dyno.csv"), impossible).unwrap_err();
    assert_eq!((e.row, e.column.as_str()), (2, "mu"));
    let nan = "v_friction_mps,t_disc_c,mu\n10,20,0.4\nNaN,21,0.4\n";
    let e = parse_friction_test(Path::new("dyno.csv"), nan).unwrap_err();
    assert_eq!((e.row, e.column.as_str()), (2, "v_friction_mps"));
    // Empty cells: skipped and counted.
    let gaps = "v_friction_mps,t_disc_c,mu\n10,20,0.4\n9,,0.41\n8,22,0.42\n";
    let t = parse_friction_test(Path::new("dyno.csv"), gaps).unwrap();
    assert_eq!((t.mu.len(), t.skipped), (2, 1));
}
