//! Outputs of every command (issue 24): paths checked before the work, files written whole
//! or not at all, `-` as standard output, nothing written where it was not asked for.

mod common;

use std::path::Path;

use common::*;

/// A path under a regular file: no folder can be made there, whoever runs the test (a
/// read-only folder does not stop root).
fn under_a_file(dir: &Path) -> std::path::PathBuf {
    let f = dir.join("plain-file");
    std::fs::write(&f, "not a folder").unwrap();
    f.join("report")
}

/// Item 13: `--json ok.json --report <not writable>` wrote the JSON, then failed (diagnose,
/// fit-friction, wsp-test, rig run). Now the report folder is checked before the work:
/// the command fails at once naming `--report`, and writes nothing.
#[test]
fn a_bad_report_folder_fails_before_the_work_and_nothing_is_written() {
    let dir = temp_dir("bad-report");
    let report = under_a_file(&dir);
    let report = report.to_str().unwrap();
    let ft = dir.join("ft.csv");
    std::fs::write(&ft, friction_test_text(400)).unwrap();
    let programme = dir.join("p.toml");
    std::fs::write(
        &programme,
        short_programme(&run_table("dry-eb-40", 40.0, "emergency", "dry")),
    )
    .unwrap();
    let baseline = shared_dir().join("spec/reference-parameters.toml");
    let log = dir.join("log.csv");
    hils_ok(
        &dir,
        args![
            "simulate",
            "--no-plots",
            "--speed-kmh",
            "40",
            "--out",
            "sim"
        ],
    );
    std::fs::copy(dir.join("sim/run.csv"), &log).unwrap();
    let cases: Vec<Vec<&str>> = vec![
        vec!["fit-friction", ft.to_str().unwrap()],
        vec!["wsp-test", "--programme", programme.to_str().unwrap()],
        vec![
            "diagnose",
            "--baseline",
            baseline.to_str().unwrap(),
            log.to_str().unwrap(),
        ],
        vec![
            "rig",
            "--interface",
            "sim",
            "run",
            "--programme",
            programme.to_str().unwrap(),
        ],
    ];
    for case in cases {
        let json = dir.join("ok.json");
        let mut a: Vec<&std::ffi::OsStr> = case.iter().map(std::ffi::OsStr::new).collect();
        a.extend([
            "--json".as_ref(),
            json.as_os_str(),
            "--report".as_ref(),
            report.as_ref(),
        ]);
        let err = hils_err(&dir, &a);
        assert!(err.contains("--report"), "{case:?}: {err}");
        assert!(!json.exists(), "{case:?}: the JSON was written");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Item 13: a `--json` file in a folder that does not exist fails before the work (a long
/// fit or programme is not run for nothing).
#[test]
fn a_json_file_in_a_missing_folder_fails_before_the_work() {
    let dir = temp_dir("bad-json");
    let programme = dir.join("p.toml");
    std::fs::write(
        &programme,
        short_programme(&run_table("dry-eb-40", 40.0, "emergency", "dry")),
    )
    .unwrap();
    let err = hils_err(
        &dir,
        args![
            "wsp-test",
            "--programme",
            programme.to_str().unwrap(),
            "--json",
            "no/such/folder/out.json",
            "--report",
            "rep"
        ],
    );
    assert!(
        err.contains("--json") && err.contains("does not exist"),
        "{err}"
    );
    assert_eq!(files_in(&dir), ["p.toml"]);
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Item 14: `--json -` and `decode -o -` wrote a file named `-`. Now `-` is standard
/// output: it holds the JSON (or the CSV) alone, the lines for people go to standard
/// error, and no file is made.
#[test]
fn dash_is_standard_output() {
    let dir = temp_dir("dash");
    std::fs::write(dir.join("ft.csv"), friction_test_text(400)).unwrap();
    let out = hils_ok(&dir, args!["fit-friction", "--json", "-", "ft.csv"]);
    let json: serde_json::Value = serde_json::from_str(&out).expect("stdout is the JSON alone");
    assert!(json["mu_d0"].as_f64().is_some(), "{json}");
    let case = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../fuzz/seeds/decode/regression-100ns-records.log");
    let out = hils_ok(&dir, args!["decode", case.to_str().unwrap(), "-o", "-"]);
    let log = hils::measured::parse_run_log(Path::new("stdout.csv"), &out)
        .expect("stdout is the run log alone");
    assert_eq!(log.len(), 4);
    assert_eq!(files_in(&dir), ["ft.csv"], "a file was made");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Item 11: `hils rig run` without `--report` wrote its run logs into the current folder
/// without saying so. Now `--report DIR` is required: without it the command fails before
/// any run, naming it, and writes nothing.
#[test]
fn rig_run_without_a_report_folder_writes_nothing() {
    let dir = temp_dir("rig-no-report");
    std::fs::write(
        dir.join("p.toml"),
        short_programme(&run_table("dry-eb-40", 40.0, "emergency", "dry")),
    )
    .unwrap();
    let err = hils_err(
        &dir,
        args![
            "rig",
            "--interface",
            "sim",
            "run",
            "--programme",
            "p.toml",
            "--json",
            "out.json"
        ],
    );
    assert!(
        err.contains("--report") && err.contains("nothing was run"),
        "{err}"
    );
    assert_eq!(files_in(&dir), ["p.toml"]);
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Runs a `hils rig --interface sim session` script in `dir`; (exit code, stdout, stderr).
fn rig_session(dir: &Path, script: &str) -> (Option<i32>, String, String) {
    std::fs::write(dir.join("s.rig"), script).unwrap();
    let out = hils_in(dir, args!["rig", "--interface", "sim", "session", "s.rig"]);
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// Item 12: `record --out` to a missing folder failed only after the whole run (the
/// recording lost). Now it fails before the session sends anything.
#[test]
fn a_recording_into_a_missing_folder_fails_before_the_run() {
    let dir = temp_dir("rig-record-missing");
    let (code, out, err) = rig_session(
        &dir,
        "record --out no/such/folder/run.csv\nstart --speed-kmh 40 --rail dry\nbrake eb\nwait --until-end\n",
    );
    assert_eq!(code, Some(1), "{out}{err}");
    assert!(
        err.contains("record --out") && err.contains("does not exist"),
        "{err}"
    );
    assert!(
        !out.contains("start: accepted"),
        "the run was started: {out}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Item 12: a second `record --out` silently dropped the first recording. Now the first is
/// ended and written when the second begins (and says so): both files are kept, each a run
/// log the reader takes; recording twice into one file is refused before the run.
#[test]
fn a_second_recording_keeps_the_first() {
    let dir = temp_dir("rig-record-twice");
    let (code, out, err) = rig_session(
        &dir,
        "record --out first.csv\nstart --speed-kmh 30 --rail dry\nbrake eb\nwait --for-s 1\nrecord --out second.csv\nwait --until-end\n",
    );
    assert_eq!(code, Some(0), "{out}{err}");
    assert!(
        out.contains("wrote first.csv") && out.contains("a new recording"),
        "{out}"
    );
    let first = hils::measured::read_run_log(&dir.join("first.csv")).unwrap();
    let second = hils::measured::read_run_log(&dir.join("second.csv")).unwrap();
    assert!(
        first.len() > 500 && second.len() > 500,
        "{} {}",
        first.len(),
        second.len()
    );
    // The second begins where the first ended: at a lower speed.
    assert!(second.v_ref_mps[0] < first.v_ref_mps[0] - 0.5);
    let (code, out, err) = rig_session(
        &dir,
        "record --out same.csv\nstart --speed-kmh 30 --rail dry\nrecord --out same.csv\n",
    );
    assert_eq!(code, Some(1), "{out}{err}");
    assert!(err.contains("appears twice"), "{err}");
    assert!(!out.contains("start: accepted"), "{out}");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Item 12: `wait --until-end` on a run that never ends returned success after its
/// board-time cap. Now it is an error naming the wait and the board's state.
#[test]
fn waiting_for_the_end_of_a_run_that_never_ends_is_an_error() {
    let dir = temp_dir("rig-wait");
    // No brake: the vehicle coasts, the run does not end.
    let (code, out, err) = rig_session(
        &dir,
        "start --speed-kmh 40 --rail dry\nwait --until-end --for-s 2\n",
    );
    assert_eq!(code, Some(1), "{out}{err}");
    assert!(
        err.contains("wait --until-end") && err.contains("did not end") && err.contains("running"),
        "{err}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Item 16: the rig's status was lower-cased Rust debug forms (`sensors 1:outofrange`,
/// `mode selftest`). Now each state, mode, result and sensor fault by its name.
#[test]
fn rig_status_names_states_and_faults_in_words() {
    let dir = temp_dir("rig-words");
    let (code, out, err) = rig_session(
        &dir,
        "start --speed-kmh 30 --rail dry\ninject 1 out-of-range\nwait --for-s 0.2\nstatus\n",
    );
    assert_eq!(code, Some(0), "{out}{err}");
    for words in [
        "state fault",
        "mode rig",
        "last command accepted",
        "1:out-of-range 2:ok",
    ] {
        assert!(out.contains(words), "no `{words}` in:\n{out}");
    }
    for debug in ["outofrange", "Some(", "None", "Rig", "Accepted", "Fault "] {
        assert!(!out.contains(debug), "`{debug}` in:\n{out}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Item 15: `summary.json` reported mu_d "at 10 s / 20 s" of a run that stopped at 3.8 s
/// (the standstill's value). Now an instant the run did not reach is `null`, and the
/// terminal says "not reached". Item 16: the terminal showed `[None, Some(4.54), None,
/// Some(4.061)]` and the JSON `641.7945556640625`: now words and figures rounded to their
/// resolution.
#[test]
fn simulate_reports_only_instants_within_the_run_in_words_and_rounded_figures() {
    let dir = temp_dir("simulate-summary");
    let out = hils_ok(
        &dir,
        args![
            "simulate",
            "--no-plots",
            "--speed-kmh",
            "30",
            "--rail",
            "dry",
            "--out",
            "short"
        ],
    );
    let s: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("short/summary.json")).unwrap())
            .unwrap();
    let stop = s["stop_time_s"].as_f64().unwrap();
    assert!(stop < 10.0, "{s}");
    assert!(s["mu_d_at_s"]["0"].as_f64().is_some(), "{s}");
    assert!(
        s["mu_d_at_s"]["10"].is_null() && s["mu_d_at_s"]["20"].is_null(),
        "{s}"
    );
    assert!(
        out.contains("10 s not reached") && out.contains("20 s not reached"),
        "{out}"
    );
    let out = hils_ok(&dir, args!["simulate", "--no-plots", "--out", "paper"]);
    for debug in ["Some(", "None", "[", "]"] {
        assert!(!out.contains(debug), "`{debug}` in: {out}");
    }
    assert!(out.contains("wheelsets 2 and 4"), "{out}");
    let text = std::fs::read_to_string(dir.join("paper/summary.json")).unwrap();
    let s: serde_json::Value = serde_json::from_str(&text).unwrap();
    // Every figure at its resolution: at most 4 decimals (mm, 0.1 ms, 1e-4 of mu_d).
    let numbers = text
        .split(|c: char| !(c.is_ascii_digit() || c == '.'))
        .filter(|t| t.contains('.'));
    for n in numbers {
        let decimals = n.len() - n.find('.').unwrap() - 1;
        assert!(decimals <= 4, "{n} in {text}");
    }
    let d = s["stopping_distance_m"].as_f64().unwrap();
    assert!((d - 641.795).abs() < 0.05, "{d}");
    std::fs::remove_dir_all(&dir).unwrap();
}
