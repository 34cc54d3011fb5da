//! Bad measured files at the command line (issue 12): each gives an error naming the file,
//! row and column, exits like any error (code 1, not an abort), and writes nothing.

use std::path::{Path, PathBuf};
use std::process::Command;

use hils::measured::parse_run_log;

const HEADER: &str = "t_s,v_ref_mps,omega1_radps,omega2_radps,omega3_radps,omega4_radps,\
f_clamp1_n,f_clamp2_n,f_clamp3_n,f_clamp4_n\n";

/// A 10-row braking log whose times span `span_s`.
fn log_spanning(span_s: f64) -> String {
    log_sampled(span_s, 10)
}

/// A braking log of `rows` rows (30 -> 21 m/s, evenly spaced) whose times span `span_s`.
fn log_sampled(span_s: f64, rows: usize) -> String {
    let mut text = format!("# source: test\n# rail: dry\n{HEADER}");
    let last = (rows - 1) as f64;
    for i in 0..rows {
        let v = 30.0 - 9.0 * i as f64 / last;
        let omega = v / 0.43;
        text += &format!(
            "{},{v},{omega},{omega},{omega},{omega},20000,20000,20000,20000\n",
            i as f64 * span_s / last
        );
    }
    text
}

/// Runs `hils` with `args`, checks that it exits like any error (code 1, not an abort) and
/// returns its standard error.
fn hils_fails(args: &[&std::ffi::OsStr]) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_hils"))
        .args(args)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(out.status.code(), Some(1), "{err}");
    err
}

fn temp_dir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("hils-bad-{tag}-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Item 1: a 10-row log over 30 000 s (milliseconds logged as seconds) made `hils
/// diagnose` abort on a 960 MB allocation; now the reader refuses it, naming the column.
#[test]
fn diagnose_refuses_a_30000_s_log_and_writes_nothing() {
    let dir = temp_dir("span");
    let log = dir.join("ms_as_s.csv");
    std::fs::write(&log, log_spanning(30_000.0)).unwrap();
    let baseline = std::env::var_os("HILS_SHARED_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared"))
        .join("spec/reference-parameters.toml");
    let json = dir.join("out.json");
    let err = hils_fails(&[
        "diagnose".as_ref(),
        "--baseline".as_ref(),
        baseline.as_os_str(),
        "--json".as_ref(),
        json.as_os_str(),
        log.as_os_str(),
    ]);
    assert!(
        err.contains("ms_as_s.csv") && err.contains("`t_s`"),
        "{err}"
    );
    assert!(err.contains("data row"), "{err}");
    assert!(!json.exists());
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Item 1, replay side: a log the method can judge (sampled at 10 Hz, braking) that spans
/// 1200 s would need 12 M steps per replay at 0.1 ms: refused before anything is allocated,
/// naming file, row and column. (A coarser log, as 10 rows over 3000 s, is refused earlier
/// by the admission as too coarse, so it would not reach the budget.)
#[test]
fn replay_budget_is_bounded() {
    let rows = 12_001;
    let text = log_sampled(1200.0, rows);
    let log = parse_run_log(Path::new("long.csv"), &text).unwrap();
    let p = hils_plant::Params::default();
    // The admission alone accepts it: the refusal below is the budget's.
    assert!(hils::diagnose::admit::admit(&p, std::slice::from_ref(&log)).is_ok());
    let e = hils::diagnose::diagnose(&p, "default", std::slice::from_ref(&log), 1e-4)
        .err()
        .expect("a 12 M-step replay accepted");
    let msg = e.to_string();
    assert!(
        msg.contains("long.csv") && msg.contains(&format!("(data row {rows})")),
        "{msg}"
    );
    assert!(msg.contains("`t_s`") && msg.contains("steps"), "{msg}");
    assert!(!msg.contains("cannot judge"), "{msg}");
    // The same log at 1 ms steps (1.2 M) is still too long; a 90 s log is not refused.
    assert!(hils::diagnose::replay::check_budget(&log, 1e-3).is_err());
    let short = parse_run_log(Path::new("ok.csv"), &log_sampled(90.0, 901)).unwrap();
    assert!(hils::diagnose::replay::check_budget(&short, 1e-4).is_ok());
    assert!(hils::diagnose::replay::check_budget(&short, 1e-3).is_ok());
}

/// Eq (2) written out (independent of the plant's code).
fn eq2(v: f64, t: f64) -> f64 {
    0.98 * 0.38 * (0.184 * (-0.1 * v).exp() + 1.0) * (0.105 * (-0.014 * t).exp() + 1.0)
}

/// Item 6: degenerate friction data is an error; a fit's correlations are within [-1, 1]
/// (or undefined, with a warning) and no interval has zero width.
#[test]
fn fit_friction_on_degenerate_data() {
    use hils::fit_friction::fit_points;
    // One disc temperature only: an error naming the problem.
    let v: Vec<f64> = (0..20).map(|i| 1.0 + i as f64).collect();
    let t = vec![50.0; 20];
    let mu: Vec<f64> = v.iter().map(|&v| eq2(v, 50.0)).collect();
    let e = fit_points(&v, &t, &mu, 0.98).unwrap_err().to_string();
    assert!(
        e.contains("degenerate") && e.contains("disc temperatures"),
        "{e}"
    );
    // Item 16: the values in words, not a Rust debug list (`[50.0]`).
    assert!(e.contains("(50)") && !e.contains('['), "{e}");
    // Near-degenerate and exact sets: whatever the fit, its statistics are meaningful.
    let mut seed = 12345u64;
    let mut rnd = || {
        seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (seed >> 11) as f64 / (1u64 << 53) as f64
    };
    for case in 0..12 {
        let n = 6 + case;
        let (v_span, t_span, noise) =
            [(0.01, 0.01, 0.0), (30.0, 300.0, 0.0), (2.0, 5.0, 1e-3)][case % 3];
        let v: Vec<f64> = (0..n)
            .map(|i| 5.0 + v_span * (i % 3) as f64 + 1e-3 * rnd())
            .collect();
        let t: Vec<f64> = (0..n)
            .map(|i| 20.0 + t_span * (i / 2 % 3) as f64 + 1e-3 * rnd())
            .collect();
        let mu: Vec<f64> = v
            .iter()
            .zip(&t)
            .map(|(&v, &t)| eq2(v, t) + noise * (rnd() - 0.5))
            .collect();
        let Ok(fit) = fit_points(&v, &t, &mu, 0.98) else {
            continue;
        };
        for (a, b, r) in &fit.correlated {
            assert!(
                r.is_nan() || r.abs() <= 1.0,
                "case {case}: {a}-{b} correlation {r}"
            );
        }
        for (name, [lo, hi]) in &fit.ci95 {
            let undefined = lo.is_nan() && hi.is_nan();
            assert!(
                undefined || hi > lo,
                "case {case}: {name} interval [{lo}, {hi}]"
            );
            if undefined {
                assert!(
                    fit.warnings.iter().any(|w| w.contains("undefined")),
                    "{:?}",
                    fit.warnings
                );
            }
        }
    }
}

/// Fuzz finding (decode target): a telemetry record with an implausible value (v_ref 1549
/// m/s from a corrupt line) became a CSV the reader refuses. Now `hils decode` refuses the
/// record, naming its step and column, and writes no file.
#[test]
fn decode_refuses_implausible_records_and_writes_nothing() {
    let dir = temp_dir("decode");
    let input = dir.join("capture.log");
    let case = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../fuzz/seeds/decode/regression-implausible-v-ref.log");
    std::fs::copy(&case, &input).unwrap();
    let csv = dir.join("run.csv");
    let err = hils_fails(&[
        "decode".as_ref(),
        input.as_os_str(),
        "--out".as_ref(),
        csv.as_os_str(),
    ]);
    assert!(
        err.contains("step 100") && err.contains("`v_ref_mps` = 1549"),
        "{err}"
    );
    assert!(!csv.exists());
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Fuzz finding (decode target): with a 1 ns step the records (100 ns apart) were written
/// with 6 decimals, all at t = 0, and the reader refused the CSV. Times are now exact.
#[test]
fn decode_writes_exact_times() {
    let case = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../fuzz/seeds/decode/regression-100ns-records.log");
    let text = std::fs::read_to_string(case).unwrap();
    let runs = hils::decode::parse_runs(text.lines()).unwrap();
    let mut csv = Vec::new();
    runs[0].write_csv(&mut csv, "test").unwrap();
    let log = hils::measured::parse_bytes(Path::new("d.csv"), &csv).unwrap();
    let hils::measured::Measured::Run(log) = log else {
        panic!("not a run log")
    };
    assert_eq!(log.t_s, vec![0.0, 1e-7, 2e-7, 3e-7]);
}

/// Fuzz finding (decode target): a run header with an infinite initial speed went into the
/// CSV's metadata, which the reader refuses. The header is refused, naming its line.
#[test]
fn decode_refuses_a_non_finite_initial_speed() {
    let case = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../fuzz/seeds/decode/regression-inf-initial-speed.log");
    let text = std::fs::read_to_string(case).unwrap();
    let e = hils::decode::parse_runs(text.lines())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("line 1") && e.contains("initial speed inf"),
        "{e}"
    );
}

/// Issue 24 item 19: with `RUST_BACKTRACE=1` in the environment a user error printed a
/// 40-line backtrace (anyhow captures one). Now it is the message and its causes, exit
/// code 1, whatever the environment says.
#[test]
fn a_user_error_is_a_message_not_a_backtrace() {
    for backtrace in ["1", "full"] {
        let out = Command::new(env!("CARGO_BIN_EXE_hils"))
            .env("RUST_BACKTRACE", backtrace)
            .env("RUST_LIB_BACKTRACE", backtrace)
            .args(["fit-friction", "/nonexistent/friction-test.csv"])
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{err}");
        assert!(err.contains("/nonexistent/friction-test.csv"), "{err}");
        assert!(!err.to_lowercase().contains("backtrace"), "{err}");
        assert!(err.lines().count() <= 3, "{err}");
    }
}

/// A programme of one run on a low track (`run` replaces its keys), with `extra` tables.
fn programme_text(criteria: &str, run: &str, extra: &str) -> String {
    format!("[criteria]\n{criteria}\n[tracks.low]\nbase = \"low\"\n{extra}\n[[run]]\n{run}\n")
}

const RUN: &str =
    "name = \"low-eb-120\"\nspeed_kmh = 120.0\ndemand = \"emergency\"\ntrack = \"low\"";

/// Issue 24 item 6: programme values were not range-checked (`demand = "service:100"`,
/// `step:99` of 7 steps, `max_distance_ratio = -1` or `nan` were accepted). Now every value
/// of the format is checked when the programme is read, before any run, and the error names
/// the file and the key.
#[test]
fn programme_values_are_range_checked_naming_the_key() {
    use hils::wsp::programme::Programme;
    let dir = temp_dir("programme-values");
    let run_with = |key: &str, value: &str| -> String {
        RUN.lines()
            .map(|l| {
                if l.starts_with(key) {
                    format!("{key} = {value}")
                } else {
                    l.to_string()
                }
            })
            .collect::<Vec<_>>()
            .join("\n")
    };
    let mut cases: Vec<(String, &str)> = Vec::new();
    for (key, value) in [
        ("max_distance_ratio", "-1.0"),
        ("max_distance_ratio", "nan"),
        ("max_distance_ratio", "inf"),
        ("max_lock_s", "-0.5"),
        ("max_wsp_timer_actions", "-1"),
        ("max_air_consumption_l", "-5.0"),
        ("lock_speed_ratio", "1.5"),
        ("cylinder_stroke_m", "0.0"),
        ("pipe_volume_l", "nan"),
        ("min_speed_mps", "-1.0"),
    ] {
        cases.push((programme_text(&format!("{key} = {value}"), RUN, ""), key));
    }
    for (value, cause) in [
        ("\"service:100\"", "demand"),
        ("\"service:0\"", "demand"),
        ("\"service:nan\"", "demand"),
        ("\"step:99\"", "step 99 of 7"),
        ("\"step:0\"", "demand"),
        ("\"brake\"", "demand"),
    ] {
        cases.push((programme_text("", &run_with("demand", value), ""), cause));
    }
    for value in ["nan", "0.0", "1000.0", "-3.0"] {
        cases.push((
            programme_text("", &run_with("speed_kmh", value), ""),
            "speed_kmh",
        ));
    }
    for (zone, key) in [
        ("start_m = nan\nend_m = 10.0", "start_m"),
        ("start_m = 0.0\nend_m = inf", "end_m"),
        ("start_m = -5000.0\nend_m = 10.0", "start_m"),
    ] {
        let extra =
            format!("[tracks.z]\nbase = \"low\"\n[[tracks.z.zone]]\n{zone}\nsurface = \"dry\"\n");
        cases.push((programme_text("", RUN, &extra), key));
    }
    for (vehicle, key) in [
        ("carbody_mass = nan", "carbody_mass"),
        ("carbody_mass = -1.0", "carbody_mass"),
        ("wheel_radius = 9.0", "wheel_radius"),
        ("bogie_masss = 1.0", "bogie_masss"),
    ] {
        let extra = format!("[vehicles.v]\n{vehicle}\n");
        let run = format!("{RUN}\nvehicle = \"v\"");
        cases.push((programme_text("", &run, &extra), key));
    }
    cases.push((
        programme_text("", RUN, "[tracks.s]\nbase = \"low\"\n[tracks.s.sets.low]\nk_a = -1.0\nk_s = 0.1\nmu_0 = 0.08\na_ratio = 0.4\nb_exp = 0.2\n"),
        "sets.low.k_a",
    ));
    for (i, (text, cause)) in cases.iter().enumerate() {
        let path = dir.join(format!("p{i}.toml"));
        std::fs::write(&path, text).unwrap();
        let err = Programme::load(&path)
            .and_then(|p| p.runs(&hils_sil::ParamFile::default()))
            .err()
            .unwrap_or_else(|| panic!("case {i} ({cause}) accepted:\n{text}"));
        let msg = format!("{err:#}");
        assert!(msg.contains(cause), "case {i}: {msg}");
        assert!(msg.contains(&format!("p{i}.toml")), "case {i}: {msg}");
    }
    // The programme shipped with the project passes.
    let shipped = Path::new(env!("CARGO_MANIFEST_DIR")).join("../programmes/wsp-low-adhesion.toml");
    Programme::load(&shipped)
        .and_then(|p| p.runs(&hils_sil::ParamFile::default()))
        .unwrap();
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Issue 24 item 10: run names became file names unchecked: `name = "../../escape"` wrote
/// outside `--report`, `name = "eb/120"` failed after the run with the report half-written.
/// Now both are refused when the programme is read, naming `name`, and nothing is written.
#[test]
fn run_names_that_are_not_file_names_are_refused_before_any_run() {
    let dir = temp_dir("run-names");
    let work = dir.join("a/b");
    std::fs::create_dir_all(&work).unwrap();
    for name in ["../../escape", "eb/120", "..", ".hidden", "a b"] {
        let run = RUN.replace("low-eb-120", name);
        std::fs::write(work.join("p.toml"), programme_text("", &run, "")).unwrap();
        let out = Command::new(env!("CARGO_BIN_EXE_hils"))
            .current_dir(&work)
            .args([
                "wsp-test",
                "--programme",
                "p.toml",
                "--report",
                "rep",
                "--json",
                "out.json",
            ])
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{name}: {err}");
        assert!(
            err.contains("`name`") && err.contains("p.toml"),
            "{name}: {err}"
        );
        assert_eq!(tree(&dir), ["a", "a/b", "a/b/p.toml"], "{name}: files made");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Every path under `dir`, relative, sorted.
fn tree(dir: &Path) -> Vec<String> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            out.push(p.strip_prefix(dir).unwrap().display().to_string());
            if p.is_dir() {
                stack.push(p);
            }
        }
    }
    out.sort();
    out
}

/// A session script with no command line (an empty file, or only comments: the wrong file
/// given) exited 0 having done nothing; now an error naming the file.
#[test]
fn a_session_script_without_a_command_line_is_an_error() {
    let dir = std::env::temp_dir().join(format!("hils-empty-script-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let script = dir.join("empty.rig");
    std::fs::write(&script, "\n# only a comment\n   \n").unwrap();
    let err = hils_fails(&[
        "rig".as_ref(),
        "--interface".as_ref(),
        "sim".as_ref(),
        "session".as_ref(),
        script.as_os_str(),
    ]);
    assert!(
        err.contains("empty.rig") && err.contains("no command line"),
        "{err}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}
