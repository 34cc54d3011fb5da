//! Set-up shared by the command-line tests of `hils`: running the binary, temporary
//! folders, small input files.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// A fresh temporary folder for a test (`tag` names it).
pub fn temp_dir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("hils-t-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Runs `hils` with `args` in the folder `cwd`.
pub fn hils_in(cwd: &Path, args: &[&std::ffi::OsStr]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_hils"))
        .current_dir(cwd)
        .args(args)
        .output()
        .unwrap()
}

/// Runs `hils`; checks that it succeeds; its standard output.
pub fn hils_ok(cwd: &Path, args: &[&std::ffi::OsStr]) -> String {
    let out = hils_in(cwd, args);
    assert!(
        out.status.success(),
        "hils {args:?} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// Runs `hils`; checks that it fails like any error (code 1, not an abort); its standard
/// error.
pub fn hils_err(cwd: &Path, args: &[&std::ffi::OsStr]) -> String {
    let out = hils_in(cwd, args);
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(
        out.status.code(),
        Some(1),
        "hils {args:?}: {err}\n{}",
        String::from_utf8_lossy(&out.stdout)
    );
    err
}

/// `OsStr`s of string arguments.
#[macro_export]
macro_rules! args {
    ($($a:expr),* $(,)?) => {
        &[$(std::ffi::OsStr::new($a)),*]
    };
}

/// The files in `dir` (names, sorted).
pub fn files_in(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .map(|r| {
            r.map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
                .collect()
        })
        .unwrap_or_default();
    v.sort();
    v
}

/// Eq (2) of the reference parameters written out (independent of the plant's code).
pub fn eq2(v: f64, t: f64) -> f64 {
    0.98 * 0.38 * (0.184 * (-0.1 * v).exp() + 1.0) * (0.105 * (-0.014 * t).exp() + 1.0)
}

/// A friction test (spec section 2) of `n` points on a grid of speeds and temperatures, Eq
/// (2) with a small deterministic noise.
pub fn friction_test_text(n: usize) -> String {
    let mut s = String::from("# source: test (synthetic, Eq 2)\nv_friction_mps,t_disc_c,mu\n");
    for i in 0..n {
        let v = 0.5 + (i % 40) as f64;
        let t = 5.0 * ((i / 40) % 60) as f64;
        let noise = 0.002 * (((i as f64) * 12.9898).sin() * 43758.5453).fract();
        s += &format!("{v},{t},{:.6}\n", eq2(v, t) + noise);
    }
    s
}

/// A WSP programme of one short run (`name`, 40 km/h, emergency, dry rail) or of the
/// given runs (TOML text of `[[run]]` tables).
pub fn short_programme(runs: &str) -> String {
    format!("[tracks.dry]\nbase = \"dry\"\n[tracks.low]\nbase = \"low\"\n{runs}")
}

/// One `[[run]]` table.
pub fn run_table(name: &str, speed_kmh: f64, demand: &str, track: &str) -> String {
    format!(
        "[[run]]\nname = \"{name}\"\nspeed_kmh = {speed_kmh:?}\ndemand = \"{demand}\"\ntrack = \"{track}\"\n"
    )
}

/// The shared folder (`../shared` beside the repository, or `HILS_SHARED_DIR`).
pub fn shared_dir() -> PathBuf {
    if let Some(d) = std::env::var_os("HILS_SHARED_DIR") {
        return PathBuf::from(d);
    }
    let beside = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared");
    if beside.exists() {
        beside
    } else {
        PathBuf::from("/work/shared")
    }
}
