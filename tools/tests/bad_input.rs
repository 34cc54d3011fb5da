//! Bad measured files at the command line (issue 12): each gives an error naming the file,
//! row and column, exits like any error (code 1, not an abort), and writes nothing.

use std::path::{Path, PathBuf};
use std::process::Command;

use hils::measured::parse_run_log;

const HEADER: &str = "t_s,v_ref_mps,omega1_radps,omega2_radps,omega3_radps,omega4_radps,\
f_clamp1_n,f_clamp2_n,f_clamp3_n,f_clamp4_n\n";

/// A 10-row braking log whose times span `span_s`.
fn log_spanning(span_s: f64) -> String {
    let mut text = format!("# source: test\n# rail: dry\n{HEADER}");
    for i in 0..10 {
        let v = 30.0 - i as f64;
        let omega = v / 0.43;
        text += &format!(
            "{},{v},{omega},{omega},{omega},{omega},20000,20000,20000,20000\n",
            i as f64 * span_s / 9.0
        );
    }
    text
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
    let out = Command::new(env!("CARGO_BIN_EXE_hils"))
        .arg("diagnose")
        .arg("--baseline")
        .arg(&baseline)
        .arg("--json")
        .arg(&json)
        .arg(&log)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("ms_as_s.csv") && err.contains("`t_s`"),
        "{err}"
    );
    assert!(err.contains("data row"), "{err}");
    assert!(!json.exists());
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Item 1, replay side: a plausible span (3000 s) at a fine step would still need 30 M
/// steps per replay: refused before anything is allocated, naming file, row and column.
#[test]
fn replay_budget_is_bounded() {
    let log = parse_run_log(Path::new("long.csv"), &log_spanning(3000.0)).unwrap();
    let p = hils_plant::Params::default();
    let e = hils::diagnose::diagnose(&p, "default", std::slice::from_ref(&log), 1e-4)
        .err()
        .expect("a 30 M-step replay accepted");
    let msg = e.to_string();
    assert!(
        msg.contains("long.csv") && msg.contains("(data row 10)"),
        "{msg}"
    );
    assert!(msg.contains("`t_s`") && msg.contains("steps"), "{msg}");
    // The same log at 1 ms steps (3 M) is still too long; a 300 s log is not refused.
    assert!(hils::diagnose::replay::check_budget(&log, 1e-3).is_err());
    let short = parse_run_log(Path::new("ok.csv"), &log_spanning(300.0)).unwrap();
    assert!(hils::diagnose::replay::check_budget(&short, 1e-3).is_ok());
}
