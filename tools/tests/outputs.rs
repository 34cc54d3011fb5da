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
