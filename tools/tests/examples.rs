//! The example files that ship with the project (issue 24 item 19): `fit-friction` can be
//! tried at once on `examples/friction-test-synthetic.csv`, which says it is synthetic and
//! is remade, byte for byte, by the command in its own metadata.

mod common;

use std::path::Path;

use common::*;

#[test]
fn the_friction_test_example_is_synthetic_fits_and_is_remade_by_its_command() {
    let example =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/friction-test-synthetic.csv");
    let text = std::fs::read_to_string(&example).expect("the example ships with the project");
    let source = text.lines().next().unwrap();
    assert!(source.starts_with("# source: SYNTHETIC"), "{source}");
    assert!(
        source.contains("hils bench --reader FILE --write-friction-points 2000"),
        "{source}"
    );
    let dir = temp_dir("example");
    let out = hils_ok(
        &dir,
        args![
            "fit-friction",
            "--json",
            "fit.json",
            example.to_str().unwrap()
        ],
    );
    assert!(out.contains("Eq (2) fitted to 2000 points"), "{out}");
    let fit: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("fit.json")).unwrap()).unwrap();
    // Eq (2)'s reference parameters the file was made from, within the fit's intervals.
    for (key, truth) in [
        ("mu_d0", 0.38),
        ("n_v", 0.184),
        ("m_v", 0.1),
        ("n_t", 0.105),
        ("m_t", 0.014),
    ] {
        let ci = fit["ci95"][key].as_array().unwrap();
        let (lo, hi) = (ci[0].as_f64().unwrap(), ci[1].as_f64().unwrap());
        assert!(
            lo <= truth && truth <= hi,
            "{key}: {truth} not in [{lo}, {hi}]"
        );
    }
    // Item 16: figures rounded to what they mean (the JSON had `0.37996127409530385`):
    // parameters and intervals to 5 significant digits (finer only for intervals narrower than
    // the example's), rms and correlations fewer, times to 1 ms.
    assert_rounded(&fit, "");
    hils_ok(
        &dir,
        args![
            "bench",
            "--reader",
            "again.csv",
            "--write-friction-points",
            "2000"
        ],
    );
    assert_eq!(
        std::fs::read_to_string(dir.join("again.csv")).unwrap(),
        text
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Every number of `v` has at most 5 significant digits (`wall_s`: at most 3 decimals).
fn assert_rounded(v: &serde_json::Value, key: &str) {
    match v {
        serde_json::Value::Object(m) => m.iter().for_each(|(k, v)| assert_rounded(v, k)),
        serde_json::Value::Array(a) => a.iter().for_each(|v| assert_rounded(v, key)),
        serde_json::Value::Number(n) => {
            let text = n.to_string();
            let mantissa = text.split(['e', 'E']).next().unwrap();
            if key == "wall_s" {
                let decimals = mantissa.split('.').nth(1).map_or(0, str::len);
                assert!(decimals <= 3, "{key}: {text}");
            } else {
                let digits = mantissa
                    .trim_start_matches(['-', '0', '.'])
                    .replace('.', "");
                assert!(digits.len() <= 5, "{key}: {text}");
            }
        }
        _ => {}
    }
}
