//! `hils wsp-test --log` (issue 24 item 5): a log is judged only as the run it is (speed,
//! track, demand), by the one judging path `hils rig run` uses, and a metric the log does
//! not measure is not measured, its criterion not judged.

mod common;

use std::path::Path;

use common::*;

fn default_programme() -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../programmes/wsp-low-adhesion.toml")
}

/// The paper's 150 km/h wet EB judged as `low-eb-120` passed with a utilisation of 2.11.
/// Now it is refused, naming the speed and the track.
#[test]
fn a_log_of_another_run_is_refused_naming_what_differs() {
    let dir = temp_dir("wsp-log-other");
    hils_ok(&dir, args!["simulate", "--no-plots", "--out", "paper"]);
    let json = dir.join("out.json");
    let err = hils_err(
        &dir,
        args![
            "wsp-test",
            "--programme",
            default_programme().to_str().unwrap(),
            "--log",
            "paper/run.csv",
            "--run",
            "low-eb-120",
            "--json",
            json.to_str().unwrap()
        ],
    );
    assert!(err.contains("not run `low-eb-120`"), "{err}");
    assert!(err.contains("speed") && err.contains("150"), "{err}");
    assert!(err.contains("track") && err.contains("wet"), "{err}");
    assert!(!json.exists());
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The same recording judged by `hils rig run` and by `hils wsp-test --log` gave a 1,004 m
/// stop and 547 l on the rig, but no stop, 0.0 l and a passed WSP timer from wsp-test. Now
/// both take the one path: the same verdict, key for key. The rig logs the valve states
/// (issue 21: `wsp1..4`, `hold1..4`), so the air and the WSP timer are measured; the same
/// recording without them has its air estimated from the pressure falls and its WSP timer
/// null, not measured, its criterion not judged.
#[test]
fn the_rig_and_wsp_test_judge_a_recording_the_same() {
    let dir = temp_dir("wsp-log-same");
    let programme = dir.join("p.toml");
    std::fs::write(
        &programme,
        short_programme(&run_table("low-eb-60", 60.0, "emergency", "low")),
    )
    .unwrap();
    let p = programme.to_str().unwrap();
    hils_ok(
        &dir,
        args![
            "rig",
            "--interface",
            "sim",
            "run",
            "--arm",
            "--programme",
            p,
            "--report",
            "rig",
            "--json",
            "rig.json"
        ],
    );
    let judge = |log: &str, json: &str| -> serde_json::Value {
        hils_ok(
            &dir,
            args!["wsp-test", "--programme", p, "--log", log, "--json", json],
        );
        let text = std::fs::read_to_string(dir.join(json)).unwrap();
        serde_json::from_str::<serde_json::Value>(&text).unwrap()[0].clone()
    };
    let rig = serde_json::from_str::<serde_json::Value>(
        &std::fs::read_to_string(dir.join("rig.json")).unwrap(),
    )
    .unwrap()[0]
        .clone();
    let wsp = judge("rig/low-eb-60.csv", "wsp.json");
    for (key, value) in wsp.as_object().unwrap() {
        assert_eq!(&rig[key], value, "{key}: rig {rig}\nwsp-test {wsp}");
    }
    assert!(
        wsp["stopping_distance_m"].as_f64().unwrap() > 100.0,
        "{wsp}"
    );
    // The WSP acted on the low rail: measured air from the vent states, a measured timer.
    assert!(wsp["air_consumption_l"].as_f64().unwrap() > 1.0, "{wsp}");
    assert!(
        wsp.get("estimated_from_cylinder_pressure").is_none(),
        "{wsp}"
    );
    assert!(wsp.get("not_measured").is_none(), "{wsp}");
    assert_eq!(wsp["wsp_timer_actions"], 0, "{wsp}");
    assert_eq!(wsp["passed"], true, "{wsp}");
    // Without the valve columns: the air estimated, the timer not measured, not passed.
    let log = std::fs::read_to_string(dir.join("rig/low-eb-60.csv")).unwrap();
    std::fs::write(dir.join("no-valves.csv"), without_valve_columns(&log)).unwrap();
    let bare = judge("no-valves.csv", "bare.json");
    assert_eq!(
        bare["estimated_from_cylinder_pressure"],
        serde_json::json!(["air_consumption_l"])
    );
    let (air, estimate) = (
        wsp["air_consumption_l"].as_f64().unwrap(),
        bare["air_consumption_l"].as_f64().unwrap(),
    );
    assert!(
        (estimate - air).abs() <= 0.25 * air,
        "{estimate} l vs {air} l"
    );
    assert!(bare["wsp_timer_actions"].is_null(), "{bare}");
    assert_eq!(
        bare["not_measured"],
        serde_json::json!(["wsp_timer_actions"])
    );
    assert_eq!(bare["passed"], false);
    // The same recording without its track or with another demand is not that run.
    let log = std::fs::read_to_string(dir.join("rig/low-eb-60.csv")).unwrap();
    for (edit, cause) in [
        (log.replace("# track: low\n", ""), "names neither its track"),
        (
            log.replace("# demand: emergency", "# demand: service:0.8"),
            "demand",
        ),
        (log.replace("# track: low", "# track: very_low"), "track"),
    ] {
        std::fs::write(dir.join("edited.csv"), edit).unwrap();
        let err = hils_err(
            &dir,
            args!["wsp-test", "--programme", p, "--log", "edited.csv"],
        );
        assert!(err.contains(cause), "{cause}: {err}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `log` without its valve-state columns (`wsp1..4`, `hold1..4`), comment lines kept.
fn without_valve_columns(log: &str) -> String {
    let mut keep: Vec<bool> = Vec::new();
    let mut out = String::new();
    for line in log.lines() {
        if line.starts_with('#') {
            out += line;
        } else {
            let cells: Vec<&str> = line.split(',').collect();
            if keep.is_empty() {
                keep = cells
                    .iter()
                    .map(|c| !(c.starts_with("wsp") || c.starts_with("hold")))
                    .collect();
                assert_eq!(keep.iter().filter(|k| !**k).count(), 8, "{line}");
            }
            let kept: Vec<&str> = (cells.iter().zip(&keep))
                .filter(|(_, k)| **k)
                .map(|(c, _)| *c)
                .collect();
            out += &kept.join(",");
        }
        out.push('\n');
    }
    out
}

/// `hils simulate` of a 40 km/h EB on the dry rail into `dir/sim` (its log `sim/run.csv`),
/// returning the log's text.
fn simulate_dry_40(dir: &Path) -> String {
    hils_ok(
        dir,
        args![
            "simulate",
            "--no-plots",
            "--speed-kmh",
            "40",
            "--rail",
            "dry",
            "--out",
            "sim"
        ],
    );
    std::fs::read_to_string(dir.join("sim/run.csv")).unwrap()
}

/// A simulated log has the vent flags (`wsp1..4`) and the pressures, not the hold states:
/// its air is measured, its WSP timer is not (it was "passed" with 0).
#[test]
fn a_metric_the_log_does_not_measure_is_not_judged() {
    let dir = temp_dir("wsp-log-measured");
    std::fs::write(
        dir.join("p.toml"),
        short_programme(&run_table("dry-eb-40", 40.0, "emergency", "dry")),
    )
    .unwrap();
    simulate_dry_40(&dir);
    hils_ok(
        &dir,
        args![
            "wsp-test",
            "--programme",
            "p.toml",
            "--log",
            "sim/run.csv",
            "--run",
            "dry-eb-40",
            "--json",
            "v.json"
        ],
    );
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("v.json")).unwrap()).unwrap();
    let v = &v[0];
    assert!(v["air_consumption_l"].as_f64().is_some(), "{v}");
    assert!(v["wsp_timer_actions"].is_null(), "{v}");
    assert_eq!(v["passed"], false, "{v}");
    let timer = v["criteria"]
        .as_array()
        .unwrap()
        .iter()
        .find(|c| {
            c["criterion"]
                .as_str()
                .unwrap()
                .starts_with("wsp_timer_actions")
        })
        .unwrap()
        .clone();
    assert_eq!(timer["passed"], false);
    assert!(
        timer["criterion"]
            .as_str()
            .unwrap()
            .ends_with("(not measured: not judged)"),
        "{timer}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A laden run's log judged with `--run` as its tare variant passed with confidence (speed,
/// track and demand match; the vehicle is not in the log), and `--json` naming the log
/// replaced the recording with the verdict. Both are refused now, the log left intact.
#[test]
fn a_log_is_not_judged_as_another_run_of_its_programme_nor_overwritten() {
    let dir = temp_dir("wsp-log-named");
    let runs = run_table("dry-eb-40", 40.0, "emergency", "dry")
        + &run_table("dry-eb-40-tare", 40.0, "emergency", "dry")
        + "vehicle = \"tare\"\n";
    let programme = short_programme(&runs) + "[vehicles.tare]\ncarbody_mass = 26000.0\n";
    std::fs::write(dir.join("p.toml"), programme).unwrap();
    let text = simulate_dry_40(&dir);
    std::fs::write(dir.join("run.csv"), format!("# run: dry-eb-40\n{text}")).unwrap();
    let judge = |run: &str, json: &str, ok: bool| {
        let a = [
            "wsp-test",
            "--programme",
            "p.toml",
            "--log",
            "run.csv",
            "--run",
            run,
            "--json",
            json,
        ];
        let a: Vec<&std::ffi::OsStr> = a.iter().map(std::ffi::OsStr::new).collect();
        if ok {
            hils_ok(&dir, &a)
        } else {
            hils_err(&dir, &a)
        }
    };
    judge("dry-eb-40", "v.json", true);
    let err = judge("dry-eb-40-tare", "w.json", false);
    assert!(
        err.contains("# run: dry-eb-40") && err.contains("dry-eb-40-tare"),
        "{err}"
    );
    assert!(!dir.join("w.json").exists());
    let err = judge("dry-eb-40", "./run.csv", false);
    assert!(err.contains("--log input"), "{err}");
    assert!(
        std::fs::read_to_string(dir.join("run.csv"))
            .unwrap()
            .starts_with("# run: dry-eb-40\n")
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `text` (a run log) with the cells of the columns whose name starts with `stem` mapped
/// by `f`.
fn edited(text: &str, stem: &str, f: impl Fn(f64) -> f64) -> String {
    let mut cols = Vec::new();
    let mut out = String::new();
    for line in text.lines() {
        if line.starts_with('#') {
            out += line;
        } else if cols.is_empty() {
            cols = line.split(',').map(|c| c.starts_with(stem)).collect();
            out += line;
        } else {
            let cells: Vec<String> = line
                .split(',')
                .zip(&cols)
                .map(|(c, &on)| match c.parse::<f64>() {
                    Ok(x) if on => format!("{}", f(x)),
                    _ => c.to_string(),
                })
                .collect();
            out += &cells.join(",");
        }
        out.push('\n');
    }
    out
}

/// Pressures in kPa under `p_cyl*_pa` passed with 0.0 l of air (a rig log: 6.3 l), a
/// wheel speed in rev/min under `omega1_radps` passed unnoticed, and a dump valve input
/// stuck at 1 was judged as the unit's venting: all are refused now, naming the column.
#[test]
fn a_log_in_wrong_units_is_not_judged() {
    let dir = temp_dir("wsp-log-units");
    std::fs::write(
        dir.join("p.toml"),
        short_programme(&run_table("dry-eb-40", 40.0, "emergency", "dry")),
    )
    .unwrap();
    let text = simulate_dry_40(&dir);
    let rpm = 60.0 / std::f64::consts::TAU;
    let cases: [(&str, &str, fn(f64, f64) -> f64, &[&str]); 4] = [
        ("sim/run.csv", "", |x, _| x, &[]),
        (
            "kpa.csv",
            "p_cyl",
            |x, _| x * 1e-3,
            &["p_cyl1_pa", "not judged"],
        ),
        (
            "rpm.csv",
            "omega1",
            |x, rpm| x * rpm,
            &["omega1_radps", "rev/min"],
        ),
        // A dump valve input stuck at 1 (venting while the cylinder fills): no vent.
        ("stuck.csv", "wsp1", |_, _| 1.0, &["`wsp1`", "stuck"]),
    ];
    for (log, stem, f, want) in cases {
        if !stem.is_empty() {
            std::fs::write(dir.join(log), edited(&text, stem, |x| f(x, rpm))).unwrap();
        }
        let a = args![
            "wsp-test",
            "--programme",
            "p.toml",
            "--log",
            log,
            "--run",
            "dry-eb-40"
        ];
        if want.is_empty() {
            hils_ok(&dir, a);
        } else {
            let err = hils_err(&dir, a);
            assert!(want.iter().all(|w| err.contains(w)), "{log}: {err}");
        }
    }
    std::fs::remove_dir_all(&dir).unwrap();
}
