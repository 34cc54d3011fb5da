//! `hils decode` on real defmt frames: the committed fixture (firmware/rig-fixture/fixture:
//! a thumbv7em ELF that runs `hils_rig_core::script` and its raw defmt output from QEMU,
//! made by `firmware/rig-fixture/make-fixture.sh`) decodes to exactly the telemetry the
//! same script produces on the host, and the CSV it writes is a run log that the
//! diagnosis' reader (`hils::measured`) accepts.

use std::path::PathBuf;

use hils::decode::rig_core::hw::TelemetryEvent;
use hils::decode::rig_core::script;
use hils::decode::rig_core::telemetry::{RunHeader, TelemetryRecord};
use hils::decode::rig_core::valves::ValveStates;
use hils::decode::{Run, defmt_to_text, parse_runs, time_text};

fn fixture_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../firmware/rig-fixture/fixture")
}

fn fixture() -> (Vec<u8>, Vec<u8>) {
    let d = fixture_dir();
    (
        std::fs::read(d.join("rig-fixture.elf")).expect("fixture ELF"),
        std::fs::read(d.join("telemetry.defmt")).expect("fixture defmt capture"),
    )
}

/// The script's telemetry, computed on the host.
fn host_events() -> Vec<TelemetryEvent> {
    let mut events = Vec::new();
    script::run(|e| events.push(*e));
    events
}

/// Every field's bits, in the order of the line (floats as IEEE bits).
fn bits(r: &TelemetryRecord) -> Vec<u32> {
    let mut v = Vec::new();
    r.for_each_value(|x| v.push(x.bits()));
    v
}

fn decoded_runs() -> Vec<Run> {
    let (elf, raw) = fixture();
    let text = defmt_to_text(&elf, &raw).expect("decode the fixture");
    assert_eq!(text.malformed_frames, 0);
    parse_runs(text.lines.iter().map(String::as_str)).expect("telemetry lines parse")
}

/// The check of the issue: real defmt frames from a target build decode to the records the
/// board code made, every value bit for bit (the fixture ran the same code in QEMU).
#[test]
fn fixture_decodes_to_the_scripted_run_bit_for_bit() {
    let runs = decoded_runs();
    assert_eq!(runs.len(), 1);
    let run = &runs[0];
    let events = host_events();
    let TelemetryEvent::Header(h) = events[0] else {
        panic!("the script starts with a header")
    };
    assert_eq!(run.header, h);
    assert_eq!(
        run.header,
        RunHeader {
            mode: 1,
            rail: 0,
            friction: 0,
            initial_speed_kmh: 150.0,
            step_ns: 100_000,
            divider: 100,
            cpu_hz: 170_000_000,
            teeth: 90,
            pressure_channels: 0
        }
    );
    let host_records: Vec<TelemetryRecord> =
        events.iter().filter_map(TelemetryEvent::record).collect();
    assert_eq!(run.records.len(), host_records.len());
    assert_eq!(run.records.len() as u32, script::STEPS / 100 + 1);
    for (target, host) in run.records.iter().zip(&host_records) {
        assert_eq!(bits(target), bits(host), "record at step {}", host.step);
    }
    let Some(TelemetryEvent::End { step, state }) = events.last() else {
        panic!()
    };
    assert_eq!(run.end, Some((*step, *state)));
    assert_eq!(run.missing_records, 0);
    // The physics in the frames: from 150 km/h under EB, WSP vents wheelsets 2 and 4 near
    // 4 s (the paper's result) and the speed has fallen by 6 s.
    let vented: Vec<bool> = (0..4)
        .map(|j| run.records.iter().any(|r| r.valves & (1 << j) != 0))
        .collect();
    assert_eq!(vented, vec![false, true, false, true]);
    let last = run.records.last().unwrap();
    assert!(
        last.v_ref < 41.67 - 5.0 && last.v_ref > 20.0,
        "{}",
        last.v_ref
    );
}

/// The CSV is a run log of spec/measured-data.md section 1: the diagnosis' reader takes it,
/// with the values of the records.
#[test]
fn decoded_csv_is_a_run_log_the_diagnosis_reads() {
    let runs = decoded_runs();
    let run = &runs[0];
    let dir = std::env::temp_dir().join(format!("hils-rig-decode-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("rig.csv");
    run.write_csv(std::fs::File::create(&path).unwrap(), "fixture")
        .unwrap();
    let log = hils::measured::read_run_log(&path).expect("the diagnosis reads the decoded CSV");
    assert_eq!(log.len(), run.records.len());
    assert_eq!(log.rail, Some(hils_plant::Rail::Wet));
    assert!(
        log.t_s.windows(2).all(|w| w[1] > w[0]),
        "time strictly increasing"
    );
    assert_eq!(log.t_s[1], 0.01);
    assert_eq!(log.metadata.get("initial_speed_kmh"), Some("150"));
    assert_eq!(log.metadata.get("eb_command_s"), Some("0"));
    for (k, r) in run.records.iter().enumerate() {
        let close = |a: f64, b: f32| (a - b as f64).abs() <= 1e-6 * (b.abs() as f64).max(1.0);
        assert!(close(log.v_ref_mps[k], r.v_ref));
        for j in 0..4 {
            assert!(close(log.omega_radps[j][k], r.omega[j]));
            assert!(close(log.p_cyl_pa[j].as_ref().unwrap()[k], r.p_cyl[j]));
            assert!(close(log.f_clamp_n[j].as_ref().unwrap()[k], r.f_clamp[j]));
            assert!(close(log.q_n[j].as_ref().unwrap()[k], r.q[j]));
            // Self-test: the simulated unit's valves (dump = vent, hold = vent or hold).
            let v = ValveStates::of_bits(r.valves);
            assert_eq!(
                log.wsp[j].as_ref().unwrap()[k],
                v.dump(j).unwrap() as u8 as f64
            );
            assert_eq!(
                log.hold[j].as_ref().unwrap()[k],
                v.hold(j).unwrap() as u8 as f64
            );
        }
    }
    assert_eq!(log.cmd.as_ref().unwrap()[0], "EB");
    std::fs::remove_dir_all(&dir).ok();
}

/// A probe-rs text log (timestamp, level, location lines around the messages) gives the
/// same run as the raw capture.
#[test]
fn text_log_gives_the_same_run_as_the_raw_capture() {
    let (elf, raw) = fixture();
    let text = defmt_to_text(&elf, &raw).unwrap();
    let mut log = String::from("      Erasing ✔ 100% [####################] 80.00 KiB\n");
    for (i, l) in text.lines.iter().enumerate() {
        log += &format!(
            "{:.6} INFO  {l}\n└─ board::telemetry_task @ firmware/board/src/main.rs:{}\n",
            i as f64 * 0.01,
            300 + i
        );
    }
    let runs = parse_runs(log.lines()).unwrap();
    let raw_runs = decoded_runs();
    assert_eq!(runs.len(), 1);
    assert_eq!(runs[0].header, raw_runs[0].header);
    assert_eq!(runs[0].end, raw_runs[0].end);
    for (a, b) in runs[0].records.iter().zip(&raw_runs[0].records) {
        assert_eq!(bits(a), bits(b));
    }
}

/// A capture cut short and a capture with bytes lost in the middle still decode; what is
/// lost is counted (missing records, malformed frames, no end line), not hidden.
#[test]
fn damaged_captures_report_what_is_lost() {
    let (elf, raw) = fixture();
    // Cut in the middle of the stream.
    let cut = &raw[..raw.len() / 2];
    let text = defmt_to_text(&elf, cut).unwrap();
    let runs = parse_runs(text.lines.iter().map(String::as_str)).unwrap();
    assert_eq!(runs[0].end, None);
    assert!(runs[0].records.len() < 400 && runs[0].records.len() > 200);
    // 5000 bytes lost in the middle (an RTT overflow): records missing, counted.
    let mut holed = raw[..30_000].to_vec();
    holed.extend_from_slice(&raw[35_000..]);
    let text = defmt_to_text(&elf, &holed).unwrap();
    let runs = parse_runs(text.lines.iter().map(String::as_str)).unwrap();
    let run = &runs[0];
    let lost = 601 - run.records.len() as u64;
    assert!(lost >= 30, "{lost}");
    assert_eq!(run.missing_records, lost, "every lost record is counted");
    assert!(text.malformed_frames <= 1);
    assert!(run.end.is_some());
    // Missing records appear in the CSV metadata.
    let mut csv = Vec::new();
    run.write_csv(&mut csv, "holed").unwrap();
    let csv = String::from_utf8(csv).unwrap();
    assert!(csv.contains(&format!("# missing_records: {lost}\n")));
}

/// Issue 11, item 8: flipped bytes in a raw capture never change a value silently. Each
/// capture with one byte flipped (at 97 places over the stream) decodes to records that
/// are all, bit for bit, the host's record of the same number; every record not in the
/// output is counted as missing, and those that failed their CRC as corrupt.
#[test]
fn a_flipped_byte_changes_no_value_silently() {
    let (elf, raw) = fixture();
    let host: Vec<TelemetryRecord> = host_events()
        .iter()
        .filter_map(TelemetryEvent::record)
        .collect();
    let (mut corrupt, mut missing) = (0, 0);
    for k in 0..97 {
        let at = 200 + k * (raw.len() - 400) / 97;
        let mut bad = raw.clone();
        bad[at] ^= 0x10;
        let Ok(text) = defmt_to_text(&elf, &bad) else {
            continue;
        };
        let Ok(runs) = parse_runs(text.lines.iter().map(String::as_str)) else {
            continue;
        };
        for run in &runs {
            for r in &run.records {
                let want = &host[r.seq as usize];
                assert_eq!(bits(r), bits(want), "flip at byte {at}: record {}", r.seq);
            }
            let last = run.records.last().map_or(0, |r| r.seq as u64 + 1);
            assert_eq!(
                run.records.len() as u64 + run.missing_records,
                last,
                "flip at byte {at}: every record up to the last is there or missing"
            );
            corrupt += run.corrupt_records;
            missing += run.missing_records;
        }
    }
    // The CRC did catch damaged records that still decoded (else this test checks little).
    assert!(
        corrupt > 0 && missing >= corrupt,
        "{corrupt} corrupt, {missing} missing"
    );
}

/// Issue 11, item 8: `t_s` cells are exact (integer ns) and distinct even for records
/// under 1 us apart (six decimals repeated them, and the reader refused the file).
#[test]
fn times_are_exact_and_distinct_below_a_microsecond() {
    assert_eq!(time_text(0), "0.000000000");
    assert_eq!(time_text(100_000), "0.000100000");
    assert_eq!(time_text(29_060_000_000), "29.060000000");
    let t: Vec<String> = (0..20).map(|k| time_text(k * 100)).collect();
    assert!(t.windows(2).all(|w| w[0] != w[1]), "{t:?}");
}

#[test]
fn bad_input_gives_clear_errors() {
    let e = parse_runs(["tlm1 1 2 3"]).unwrap_err().to_string();
    assert!(e.contains("line 1") && e.contains("44"), "{e}");
    let (elf, raw) = fixture();
    let text = defmt_to_text(&elf, &raw).unwrap();
    // Records without their run header (capture started mid-run).
    let e = parse_runs(text.lines[5..].iter().map(String::as_str))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("line 1") && e.contains("before any run header"),
        "{e}"
    );
    // A record whose value is not a number names the field.
    let mut lines = text.lines.clone();
    lines[3] = lines[3].replacen(" 41.666668 ", " 41.6x ", 1);
    let e = parse_runs(lines.iter().map(String::as_str))
        .unwrap_err()
        .to_string();
    assert!(e.contains("line 4") && e.contains("v_ref"), "{e}");
    // Steps that go backwards.
    let mut lines = text.lines.clone();
    lines.swap(3, 4);
    let e = parse_runs(lines.iter().map(String::as_str))
        .unwrap_err()
        .to_string();
    assert!(e.contains("does not increase"), "{e}");
    // An ELF that is not a defmt firmware.
    assert!(defmt_to_text(b"not an elf", &raw).is_err());
    // A binary capture read as text.
    let dir = std::env::temp_dir().join(format!("hils-rig-decode-bin-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let bin = dir.join("capture.defmt");
    std::fs::write(&bin, [0xffu8, 0xfe, 0x00, 0x80]).unwrap();
    let e = hils::decode::read_log(&bin, None).unwrap_err().to_string();
    assert!(e.contains("--elf"), "{e}");
    std::fs::remove_dir_all(&dir).ok();
}
