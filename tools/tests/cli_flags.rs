//! Every numeric flag of `hils` refuses 0 (where it means nothing), negatives, NaN, inf,
//! huge values and non-numbers with an error naming the flag, before anything runs or is
//! written (issue 12 item 2). Property test over each flag of `hils::flags::FLAGS`.

use clap::Parser;
use hils::cli::Cli;
use hils::flags::{FLAGS, FlagRange};
use proptest::prelude::*;

/// A command line that sets `flag` to `value` (and whatever else the command needs). A
/// positional value (a `flag` without `--`) follows `--`, so that a negative number is a
/// value, not an option.
fn argv(f: &FlagRange, value: &str) -> Vec<String> {
    let mut v = vec!["hils".to_string()];
    v.extend(f.command.split_whitespace().map(String::from));
    match f.command {
        "simulate" | "decode" => v.extend(["--out".into(), "/nonexistent/never-written".into()]),
        "diagnose" => v.extend(["--baseline".into(), "b.toml".into()]),
        "rig run" => v.extend(["--programme".into(), "/nonexistent/p.toml".into()]),
        _ => {}
    }
    if f.flag == "--write-log-mb" || f.flag == "--write-friction-points" {
        v.extend(["--reader".into(), "/nonexistent/never-written.csv".into()]);
    }
    if f.command == "decode" || f.command == "diagnose" {
        v.push("input.csv".into());
    }
    if !f.flag.starts_with("--") {
        v.extend(["--".into(), value.into()]);
    } else if f.flag == "--sim-fault" {
        v.push(format!("{}=board-lost={value}", f.flag));
    } else {
        v.push(format!("{}={value}", f.flag));
    }
    v
}

fn rejected(f: &FlagRange, value: &str) -> Result<(), TestCaseError> {
    match Cli::try_parse_from(argv(f, value)) {
        Ok(cli) => Err(TestCaseError::fail(format!(
            "{} {} {value} accepted: {cli:?}",
            f.command, f.flag
        ))),
        Err(e) => {
            let msg = e.to_string();
            prop_assert!(
                msg.contains(f.flag),
                "error does not name {}: {msg}",
                f.flag
            );
            Ok(())
        }
    }
}

/// Text of a bad value for a flag: out of range (below, above, negative, zero where the
/// range excludes it), not finite, or not a number.
fn bad_value(f: FlagRange) -> impl Strategy<Value = String> {
    let below = (f.min > 0.0).then_some(f.min);
    prop_oneof![
        Just("NaN".to_string()),
        Just("inf".to_string()),
        Just("-inf".to_string()),
        Just("1e300".to_string()),
        Just("-1".to_string()),
        Just("".to_string()),
        Just("abc".to_string()),
        Just("99999999999999999999999".to_string()),
        (f.max * 1.0001 + 1.0..1e308).prop_map(|x| format!("{x}")),
        (-1e308..-f64::MIN_POSITIVE).prop_map(|x| format!("{x}")),
        (0.0..below.unwrap_or(0.0).max(f64::MIN_POSITIVE))
            .prop_filter("below the minimum", move |x| below.is_some_and(|m| *x < m))
            .prop_map(|x| format!("{x}")),
    ]
}

proptest! {
    #[test]
    fn every_numeric_flag_refuses_bad_values(
        (i, value) in (0..FLAGS.len()).prop_flat_map(|i| (Just(i), bad_value(FLAGS[i])))
    ) {
        rejected(&FLAGS[i], &value)?;
    }
}

#[test]
fn zero_is_refused_by_every_flag_and_good_values_pass() {
    for f in FLAGS {
        rejected(&f, "0").unwrap();
        rejected(&f, "1e-300").unwrap();
        let mid = if f.integer {
            f.min.to_string()
        } else {
            ((f.min + f.max) / 2.0).to_string()
        };
        assert!(
            Cli::try_parse_from(argv(&f, &mid)).is_ok(),
            "{} {mid}",
            f.flag
        );
    }
    // Counts take whole numbers only.
    rejected(&hils::flags::REPEAT, "2.5").unwrap();
}

/// The binary: a bad flag exits with clap's usage error (2), prints the flag, and creates
/// nothing.
#[test]
fn simulate_with_zero_sample_rate_writes_nothing() {
    let out = std::env::temp_dir().join(format!("hils-flag-{}", std::process::id()));
    let status = std::process::Command::new(env!("CARGO_BIN_EXE_hils"))
        .args(["simulate", "--no-plots", "--sample-rate-hz", "0", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    assert_eq!(status.status.code(), Some(2));
    let err = String::from_utf8_lossy(&status.stderr);
    assert!(err.contains("--sample-rate-hz"), "{err}");
    assert!(!out.exists(), "output directory created");
}

/// The rig's typed values reach the CAN command unchanged, and a session script line with
/// a bad value fails at parse time naming the value (before anything is sent).
#[test]
fn rig_values_reach_the_command_and_bad_script_values_name_the_value() {
    use hils::decode::rig_core::can::{Calibration, Command, ConfigItem};
    use hils::decode::rig_core::sensor::SensorKind;
    let path = std::path::PathBuf::from("s.rig");
    let text = "calibrate 2 gain 12.5\ncalibrate 3 offset 409.5\ncalibrate 1 kind pressure\n\
                configure teeth 90\nbrake service 0.8\n";
    let lines = hils::rig::parse_script(&path, text).unwrap();
    let cmds: Vec<Command> = lines
        .iter()
        .flat_map(|l| hils::rig::commands_of(l).unwrap())
        .collect();
    assert_eq!(
        cmds[..4],
        [
            Command::Calibrate {
                channel: 1,
                action: Calibration::SetGain(12.5)
            },
            Command::Calibrate {
                channel: 2,
                action: Calibration::SetOffset(409.5)
            },
            Command::Calibrate {
                channel: 0,
                action: Calibration::SetKind(SensorKind::PressureTransducer)
            },
            Command::Configure(ConfigItem::Teeth(90)),
        ]
    );
    for (line, name) in [
        ("calibrate 2 gain 0", "GAIN"),
        ("calibrate 2 offset 5000", "COUNTS"),
        ("configure divider 20000", "STEPS"),
        ("brake service 11", "DECEL_MPS2"),
        ("watch --every-s 0", "--every-s"),
    ] {
        let e = hils::rig::parse_script(&path, line)
            .unwrap_err()
            .to_string();
        assert!(e.contains("s.rig:1") && e.contains(name), "{line}: {e}");
    }
}

/// `rig start --speed-kmh` accepts exactly the speeds the wheel-speed frames carry.
#[test]
fn rig_start_speed_range_is_the_wheel_speed_frames_range() {
    let top = hils::decode::rig_core::can::WHEEL_SPEED_MAX_KMH as f64;
    assert!(
        (hils::flags::RIG_SPEED_KMH.max - top).abs() < 0.005,
        "{top}"
    );
}
