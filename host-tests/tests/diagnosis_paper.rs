//! The diagnosis on the project's own simulation of the paper's emergency brake (issue 3,
//! "done when"): a run of `hils simulate --friction variable` (closed loop, f32, 0.1 ms,
//! written with the run-log writer) diagnosed against the reference parameters with
//! constant friction names friction-speed and friction-temperature, recovers Table 1
//! within 15 %, and shows the wheel slides the baseline misses. Also: the replay itself
//! (accuracy of the coarser replay steps, the two input kinds agree), and the run-log
//! round trip through the reader.

use std::path::Path;
use std::sync::OnceLock;

use hils::diagnose::replay::{Model, Prepared, Split, replay, score, slides};
use hils::diagnose::{Outcome, diagnose};
use hils::measured::{RunLog, parse_run_log};
use hils::runlog::write_run_log;
use hils::scenario::{EbOptions, Run, run_eb};
use hils_plant::{FrictionModel, Params};

fn variable_run() -> &'static Run {
    static R: OnceLock<Run> = OnceLock::new();
    R.get_or_init(|| {
        let p = hils_sil::ParamFile::default();
        run_eb::<f32>(&p, &EbOptions::paper(&p)).expect("runs")
    })
}

fn log_text(run: &Run) -> String {
    let metadata = vec![
        ("source", "hils simulate".to_string()),
        ("rail", "wet".to_string()),
        ("initial_speed_kmh", "150".to_string()),
        ("eb_command_s", "0".to_string()),
    ];
    let mut buf = Vec::new();
    write_run_log(&mut buf, &metadata, &run.samples).expect("writes");
    String::from_utf8(buf).expect("utf-8")
}

fn variable_log() -> &'static RunLog {
    static L: OnceLock<RunLog> = OnceLock::new();
    L.get_or_init(|| parse_run_log(Path::new("run.csv"), &log_text(variable_run())).expect("reads"))
}

fn constant_baseline() -> Params {
    let mut p = Params::default();
    p.friction.model = FrictionModel::Constant;
    p
}

fn paper_outcome() -> &'static Outcome {
    static O: OnceLock<Outcome> = OnceLock::new();
    O.get_or_init(|| {
        diagnose(
            &constant_baseline(),
            "constant",
            std::slice::from_ref(variable_log()),
            1e-3,
        )
        .expect("runs")
    })
}

#[test]
fn run_log_round_trip_keeps_every_sample_and_column() {
    let run = variable_run();
    let log = variable_log();
    assert_eq!(log.len(), run.samples.len());
    for (s, i) in run.samples.iter().zip(0..) {
        assert!((log.t_s[i] - s.t_s).abs() < 1e-6);
        assert!((log.v_ref_mps[i] - s.v_ref_mps).abs() < 1e-6);
        assert!((log.omega_radps[3][i] - s.omega_radps[3]).abs() < 1e-5);
        assert!((log.p_cyl_pa[1].as_ref().unwrap()[i] - s.p_cyl_pa[1]).abs() < 0.06);
    }
    assert!(log.f_brake_n.iter().all(|c| c.is_some()) && log.q_n.iter().all(|c| c.is_some()));
    assert!(
        log.unknown_columns.contains(&"mu_d1".to_string()),
        "{:?}",
        log.unknown_columns
    );
    assert_eq!(log.metadata.get("rail"), Some("wet"));
    assert!(log.missing.is_empty());
}

#[test]
fn replay_at_coarser_steps_keeps_the_speeds_and_the_slides() {
    // The true model (reference parameters, variable friction) replayed from the measured
    // inputs: the error is numerical only. 0.1 ms (the run's own step) down to 4 ms (the
    // diagnosis' fit step).
    let log = variable_log();
    let truth = Params::default();
    let mut errors = Vec::new();
    for dt in [1e-4, 1e-3, 4e-3] {
        let run = Prepared::new(log, &truth, dt);
        let rep = replay(&run, &Model::new(&truth)).expect("replays");
        let s = score(&run, &rep, Split::All);
        errors.push((dt, s.speed_rms(), s.rms()));
        assert_eq!(
            slides(&rep.v_bin, &rep.wheel_bin),
            [false, true, false, true],
            "dt {dt}"
        );
    }
    eprintln!("replay accuracy (step, speed rms m/s, rms in noise units): {errors:?}");
    for (dt, speed, rms) in errors {
        assert!(speed < 0.015, "dt {dt}: speed error {speed} m/s");
        assert!(rms < 0.5, "dt {dt}: normalised error {rms}");
    }
}

#[test]
fn pressure_and_clamp_force_inputs_replay_alike() {
    // Eq (1) consistency: dropping the clamp-force columns makes the replay use the
    // pressures through Eq (1); the result must not change beyond the logging resolution.
    let text = log_text(variable_run());
    let mut lines: Vec<String> = text.lines().map(String::from).collect();
    let header_at = lines.iter().position(|l| !l.starts_with('#')).unwrap();
    let header: Vec<&str> = lines[header_at].split(',').collect();
    let drop: Vec<usize> = header
        .iter()
        .enumerate()
        .filter(|(_, h)| h.starts_with("f_clamp"))
        .map(|(i, _)| i)
        .collect();
    for line in lines.iter_mut().skip(header_at) {
        let kept: Vec<&str> = line
            .split(',')
            .enumerate()
            .filter(|(i, _)| !drop.contains(i))
            .map(|(_, c)| c)
            .collect();
        *line = kept.join(",");
    }
    let pressure_only = parse_run_log(Path::new("p.csv"), &lines.join("\n")).expect("reads");
    assert!(pressure_only.f_clamp_n.iter().all(|c| c.is_none()));
    let truth = Params::default();
    let a = Prepared::new(variable_log(), &truth, 1e-3);
    let b = Prepared::new(&pressure_only, &truth, 1e-3);
    let ra = replay(&a, &Model::new(&truth)).unwrap();
    let rb = replay(&b, &Model::new(&truth)).unwrap();
    let max_dv = ra
        .v_bin
        .iter()
        .zip(&rb.v_bin)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max);
    assert!(
        max_dv < 0.01,
        "v differs by {max_dv} m/s between the input kinds"
    );
}

#[test]
fn paper_case_names_speed_and_temperature_with_table1_values() {
    let out = paper_outcome();
    let r = &out.report;
    eprintln!("{}", serde_json::to_string_pretty(r).unwrap());
    assert!(r.discrepancy);
    let mut causes = r.causes.clone();
    causes.sort();
    assert_eq!(causes, vec!["friction-speed", "friction-temperature"]);
    let table1 = Params::default().friction;
    let truth = [
        ("n_v", table1.n_v),
        ("m_v", table1.m_v),
        ("n_t", table1.n_t),
        ("m_t", table1.m_t),
    ];
    for (key, want) in truth {
        let f = r
            .findings
            .iter()
            .find(|f| f.params.contains_key(key))
            .expect("parameter reported");
        let got = f.params[key];
        assert!(
            (got - want).abs() / want < 0.15,
            "{key} = {got}, Table 1 {want}"
        );
        let [lo, hi] = f.ci95[key];
        assert!(lo < got && got < hi, "{key}: CI [{lo}, {hi}] around {got}");
    }
    assert!(r.gain.reduction >= 0.8, "reduction {}", r.gain.reduction);
    assert!(
        r.unexplained_share < 0.2,
        "unexplained {}",
        r.unexplained_share
    );
}

#[test]
fn paper_case_shows_the_slide_the_baseline_misses() {
    let r = &paper_outcome().report;
    assert_eq!(r.slides.measured, vec![2, 4]);
    assert_eq!(r.slides.baseline, Vec::<usize>::new());
    assert_eq!(r.slides.extended, vec![2, 4]);
}

#[test]
fn paper_case_report_names_the_cause_and_draws_the_plots() {
    let out = paper_outcome();
    let dir = std::env::temp_dir().join(format!("hils-diag-report-{}", std::process::id()));
    let files = hils::diagnose::report::write(&dir, out).expect("writes the report");
    let md = std::fs::read_to_string(dir.join("report.md")).unwrap();
    assert!(md.contains("friction-speed") && md.contains("friction-temperature"));
    assert!(md.contains("misses the wheel slide"), "{md}");
    for name in [
        "v_ref.svg",
        "wheel2.svg",
        "wheel4.svg",
        "residual_vs_friction_speed.svg",
        "residual_vs_disc_temperature.svg",
    ] {
        assert!(files.iter().any(|f| f.ends_with(name)), "{name} missing");
        let svg = std::fs::read_to_string(dir.join(name)).unwrap();
        assert!(
            svg.contains("<svg") && svg.len() > 2000,
            "{name} looks empty"
        );
    }
    // The baseline's braking shortfall goes with friction speed and disc temperature.
    let a = &out.analysis.runs[0];
    let r_of = |n: &str| {
        a.correlations
            .iter()
            .find(|(x, _)| *x == n)
            .map(|x| x.1)
            .unwrap()
    };
    assert!(
        a.mean_relative_decel_error < 0.0,
        "baseline should brake too weakly"
    );
    assert!(
        r_of("friction speed").abs() > 0.5 || r_of("disc temperature").abs() > 0.5,
        "{:?}",
        a.correlations
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn the_true_model_as_baseline_finds_no_discrepancy() {
    let out = diagnose(
        &Params::default(),
        "reference",
        std::slice::from_ref(variable_log()),
        1e-3,
    )
    .unwrap();
    assert!(!out.report.discrepancy, "{:?}", out.report.gain);
    assert!(out.report.causes.is_empty());
    assert_eq!(out.report.unexplained_share, 0.0);
}
