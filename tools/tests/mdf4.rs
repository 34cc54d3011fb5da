//! MDF4 in and out (issue 23), checked against an independent implementation without
//! needing it at test time: the fixtures in `tests/data/mdf4/` were written by asammdf
//! (`python3 scripts/mdf4_asammdf.py fixtures tools/tests/data/mdf4`) as a CANape-like
//! recording (foreign names; km/h, bar, degC; wheel speeds, valves and command at 1 kHz,
//! radar and pressures at 250 Hz, disc temperatures at 50 Hz; integer channels with linear,
//! value-to-value and value-to-text conversions; a pressure dropout as invalidation bits)
//! sorted, unsorted (one data group, record ids) and deflate-compressed (DZ, transposed);
//! beside each, the spec CSV of the same data as asammdf decodes it (SI, empty cells where
//! a slow channel has no sample) and the channel map. The project's reader must give the
//! same run log from the MDF4 file and the map as from that CSV.

mod common;

use std::path::{Path, PathBuf};

use hils::measured::{ChannelMap, RunLog, read_run_log, read_run_log_with};

fn data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/mdf4")
        .join(name)
}

fn map(stem: &str) -> ChannelMap {
    ChannelMap::load(&data(&format!("{stem}.map.toml"))).expect("the fixture's map reads")
}

/// Columns equal within `rel` (relative; NaN = not measured, at the same samples).
fn same(name: &str, a: &[f64], b: &[f64], rel: f64) {
    assert_eq!(a.len(), b.len(), "{name}: length");
    for (i, (x, y)) in a.iter().zip(b).enumerate() {
        assert_eq!(x.is_nan(), y.is_nan(), "{name}[{i}]: {x} vs {y}");
        if !x.is_nan() {
            assert!(
                (x - y).abs() <= rel * y.abs().max(1.0),
                "{name}[{i}]: {x} vs {y}"
            );
        }
    }
}

fn same_logs(mf4: &RunLog, csv: &RunLog) {
    same("t_s", &mf4.t_s, &csv.t_s, 0.0);
    same("v_ref_mps", &mf4.v_ref_mps, &csv.v_ref_mps, 1e-12);
    for j in 0..4 {
        same("omega", &mf4.omega_radps[j], &csv.omega_radps[j], 1e-12);
        for (name, a, b) in [
            ("p_cyl", &mf4.p_cyl_pa[j], &csv.p_cyl_pa[j]),
            ("t_disc", &mf4.t_disc_c[j], &csv.t_disc_c[j]),
            ("wsp", &mf4.wsp[j], &csv.wsp[j]),
        ] {
            same(
                name,
                a.as_ref().expect(name),
                b.as_ref().expect(name),
                1e-12,
            );
        }
    }
    let (a, b) = (mf4.cmd.as_ref().unwrap(), csv.cmd.as_ref().unwrap());
    assert_eq!(a.iter().collect::<Vec<_>>(), b.iter().collect::<Vec<_>>());
    assert_eq!(mf4.missing, csv.missing);
    assert_eq!(mf4.rail, csv.rail);
    for key in ["rail", "initial_speed_kmh", "eb_command_s"] {
        assert_eq!(mf4.metadata.get(key), csv.metadata.get(key), "{key}");
    }
}

/// Sorted, unsorted and compressed: the same run log as the CSV asammdf decodes.
#[test]
fn asammdf_recordings_read_as_their_spec_csv() {
    for stem in ["canape_sorted", "canape_unsorted", "canape_dz"] {
        let m = map(stem);
        let mf4 = read_run_log_with(&data(&format!("{stem}.mf4")), Some(&m))
            .unwrap_or_else(|e| panic!("{stem}: {e}"));
        let csv = read_run_log(&data(&format!("{stem}.csv"))).unwrap();
        same_logs(&mf4, &csv);
        // The slow channels are on the 1 kHz grid at their own samples only, and said so.
        assert_eq!(mf4.missing.get("v_ref_mps"), Some(&150), "{stem}");
        assert!(
            mf4.notes.iter().any(
                |n| n.contains("Radar_Speed (v_ref_mps): 50 samples at 250 Hz")
                    && n.contains("not invented")
            ),
            "{stem}: {:?}",
            mf4.notes
        );
    }
}

/// asammdf stores a text column as a variable-length (VLSD) string: `canape_vlsd.mf4` is
/// `canape_dz.mf4` with `BrakeCmd` as a UTF-8 VLSD channel (its signal data in a DZ
/// block) instead of codes with a value-to-text conversion. asammdf reads both to the same
/// CSV (`scripts/mdf4_asammdf.py fixtures` checks that); so must the project's reader.
#[test]
fn an_asammdf_vlsd_text_channel_reads_as_its_csv() {
    let m = map("canape_dz");
    let mf4 =
        read_run_log_with(&data("canape_vlsd.mf4"), Some(&m)).unwrap_or_else(|e| panic!("{e}"));
    let csv = read_run_log(&data("canape_dz.csv")).unwrap();
    same_logs(&mf4, &csv);
    let cmd = mf4.cmd.as_ref().expect("cmd");
    assert_eq!(cmd.values, ["REL", "EB"]);
    let raw = std::fs::read(data("canape_vlsd.mf4")).unwrap();
    assert!(
        raw.windows(4).any(|w| w == b"##DZ"),
        "the fixture's data are compressed"
    );
}

/// A file the project writes reads back through the project's reader as its CSV does.
#[test]
fn written_mf4_reads_back_as_the_csv() {
    use hils::runlog::{Format, write_run_log_as};
    use hils_sil::{Cmd, RunRecord};
    let samples: Vec<RunRecord> = (0..500)
        .map(|i| {
            let t = i as f64 * 1e-3;
            let v = 40.0 - 1.3 * t;
            RunRecord {
                t_s: t,
                v_ref_mps: v,
                x_m: 40.0 * t,
                a_x_mps2: -1.3,
                cmd: if i < 10 { Cmd::Release } else { Cmd::Emergency },
                omega_radps: [0, 1, 2, 3].map(|j| (v - 0.01 * j as f64) / 0.43),
                p_cyl_pa: [0, 1, 2, 3].map(|j| (t * 1e6).min(3.5e5) + j as f64),
                f_clamp_n: [17_000.0; 4],
                f_brake_n: [6_500.0; 4],
                t_disc_c: [0, 1, 2, 3].map(|j| 20.0 * t + j as f64),
                q_n: [106_000.0; 4],
                wsp: [i % 100 < 20, false, true, false],
                mu_d: [0.38; 4],
                creepage: [0.01; 4],
                adhesion: [0.1; 4],
                v_ref_est_mps: v,
            }
        })
        .collect();
    let meta = vec![
        ("source", "test".to_string()),
        ("rail", "dry".to_string()),
        ("initial_speed_kmh", "144".to_string()),
        ("eb_command_s", "0.01".to_string()),
    ];
    let dir = std::env::temp_dir().join(format!("hils-mdf4-rt-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (csv_path, mf4_path) = (dir.join("run.csv"), dir.join("run.mf4"));
    for (format, path) in [(Format::Csv, &csv_path), (Format::Mf4, &mf4_path)] {
        let f = std::fs::File::create(path).unwrap();
        write_run_log_as(format, f, &meta, &samples).unwrap();
    }
    let csv = read_run_log(&csv_path).unwrap();
    let mf4 = read_run_log(&mf4_path).unwrap();
    same_logs(&mf4, &csv);
    same(
        "a_x",
        mf4.a_x_mps2.as_ref().unwrap(),
        csv.a_x_mps2.as_ref().unwrap(),
        0.0,
    );
    for j in 0..4 {
        for (a, b) in [
            (&mf4.f_clamp_n[j], &csv.f_clamp_n[j]),
            (&mf4.f_brake_n[j], &csv.f_brake_n[j]),
            (&mf4.q_n[j], &csv.q_n[j]),
        ] {
            same("forces", a.as_ref().unwrap(), b.as_ref().unwrap(), 0.0);
        }
    }
    assert_eq!(mf4.unknown_columns, csv.unknown_columns);
    std::fs::remove_dir_all(&dir).unwrap();
}

fn err_of(path: &Path, map: Option<&ChannelMap>) -> hils::measured::MeasuredError {
    match read_run_log_with(path, map) {
        Ok(_) => panic!("{} read without error", path.display()),
        Err(e) => e,
    }
}

/// Issue 23 item 6: truncated files, pointers outside the file, units that do not
/// convert, a map naming an absent channel: an error naming the file (and the channel).
#[test]
fn bad_mdf4_input_is_named_never_a_panic() {
    let dir = std::env::temp_dir().join(format!("hils-mdf4-bad-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let good = std::fs::read(data("canape_sorted.mf4")).unwrap();
    let m = map("canape_sorted");
    // Truncated anywhere: an error naming the file.
    for cut in [10, 64, 100, 500, 3000, good.len() / 2, good.len() - 9] {
        let p = dir.join(format!("cut{cut}.mf4"));
        std::fs::write(&p, &good[..cut]).unwrap();
        let e = err_of(&p, Some(&m));
        assert!(e.to_string().contains(&format!("cut{cut}.mf4")), "{e}");
    }
    // Not an MDF file under an MDF name (random bytes, a text): said so, not read as CSV.
    let random: Vec<u8> = (0..3000u32)
        .map(|i| (i.wrapping_mul(2654435761) >> 13) as u8)
        .collect();
    for (name, bytes) in [
        ("random.mf4", random),
        ("text.MF4", b"t_s,x\n0,1\n".to_vec()),
    ] {
        let p = dir.join(name);
        std::fs::write(&p, &bytes).unwrap();
        let e = err_of(&p, Some(&m));
        assert!(e.to_string().contains(name), "{e}");
        assert!(e.message.contains("not an MDF file"), "{e}");
    }
    // MDF 3: refused by its version.
    let mut mdf3 = good.clone();
    mdf3[8..16].copy_from_slice(b"3.30    ");
    mdf3[28..30].copy_from_slice(&330u16.to_le_bytes());
    let p = dir.join("old.mf4");
    std::fs::write(&p, &mdf3).unwrap();
    let e = err_of(&p, Some(&m));
    assert!(e.message.contains("MDF version 3.30"), "{e}");
    // Every 8-byte word that holds an address of a block, pointed past the end.
    let mut bad_pointers = 0;
    for at in (64..good.len() - 8).step_by(8) {
        let word = u64::from_le_bytes(good[at..at + 8].try_into().unwrap());
        if word >= 64 && word < good.len() as u64 && good[word as usize..].starts_with(b"##") {
            let mut b = good.clone();
            b[at..at + 8].copy_from_slice(&(good.len() as u64 + 4096).to_le_bytes());
            let p = dir.join("ptr.mf4");
            std::fs::write(&p, &b).unwrap();
            if let Err(e) = read_run_log_with(&p, Some(&m)) {
                assert!(e.to_string().contains("ptr.mf4"), "{e}");
                bad_pointers += 1;
            }
        }
    }
    assert!(bad_pointers > 20, "{bad_pointers} pointers refused");
    // A unit that does not convert, named with the channel.
    let text = std::fs::read_to_string(data("canape_sorted.map.toml")).unwrap();
    let wrong = text.replace(
        "from = \"BC_Pressure_1\"",
        "from = \"BC_Pressure_1\"\nunit = \"km/h\"",
    );
    let wrong = ChannelMap::parse(Path::new("wrong.toml"), &wrong).unwrap();
    let e = err_of(&data("canape_sorted.mf4"), Some(&wrong));
    assert_eq!(e.column, "BC_Pressure_1");
    assert!(e.message.contains("speed unit, not a pressure unit"), "{e}");
    // A map naming a channel the file does not have.
    let absent = text.replace("\"BC_Pressure_2\"", "\"BC_Pressure_9\"");
    let absent = ChannelMap::parse(Path::new("absent.toml"), &absent).unwrap();
    let e = err_of(&data("canape_sorted.mf4"), Some(&absent));
    assert_eq!(e.column, "BC_Pressure_9");
    assert!(e.to_string().contains("canape_sorted.mf4"), "{e}");
    // No map: which quantities are missing, which channels the file has.
    let e = err_of(&data("canape_sorted.mf4"), None);
    assert!(e.message.contains("WheelSpeed_Axle1"), "{e}");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The same map reads a CSV export with foreign names and units.
#[test]
fn the_map_reads_a_foreign_csv_export() {
    let text = "# rail: wet\nTime,Radar_Speed,WheelSpeed_Axle1,WheelSpeed_Axle2,WheelSpeed_Axle3,WheelSpeed_Axle4,BC_Pressure_1,BC_Pressure_2,BC_Pressure_3,BC_Pressure_4\n\
0.000,108.0,108.0,108.0,108.0,108.0,0.0,0.0,0.0,0.0\n\
0.001,107.9,107.9,107.9,107.9,107.9,3.5,3.5,3.5,3.5\n";
    let map_text = r#"wheel_radius_m = 0.43
[channels.t_s]
from = "Time"
unit = "s"
[channels.v_ref_mps]
from = "Radar_Speed"
unit = "km/h"
[channels.omega1_radps]
from = "WheelSpeed_Axle1"
unit = "km/h"
[channels.omega2_radps]
from = "WheelSpeed_Axle2"
unit = "km/h"
[channels.omega3_radps]
from = "WheelSpeed_Axle3"
unit = "km/h"
[channels.omega4_radps]
from = "WheelSpeed_Axle4"
unit = "km/h"
[channels.p_cyl1_pa]
from = "BC_Pressure_1"
unit = "bar"
[channels.p_cyl2_pa]
from = "BC_Pressure_2"
unit = "bar"
[channels.p_cyl3_pa]
from = "BC_Pressure_3"
unit = "bar"
[channels.p_cyl4_pa]
from = "BC_Pressure_4"
unit = "bar"
"#;
    let m = ChannelMap::parse(Path::new("m.toml"), map_text).unwrap();
    let r = hils::measured::parse_bytes_with(Path::new("export.csv"), text.as_bytes(), Some(&m))
        .unwrap();
    let hils::measured::Measured::Run(r) = r else {
        panic!("a run log")
    };
    assert!((r.v_ref_mps[0] - 30.0).abs() < 1e-12);
    assert!((r.omega_radps[0][0] - 30.0 / 0.43).abs() < 1e-9);
    assert_eq!(r.p_cyl_pa[3].as_ref().unwrap()[1], 3.5e5);
    // Without a unit for a CSV column the map renames: refused, naming the column.
    let no_unit = map_text.replacen("unit = \"bar\"\n", "", 1);
    let m = ChannelMap::parse(Path::new("m.toml"), &no_unit).unwrap();
    let e = hils::measured::parse_bytes_with(Path::new("export.csv"), text.as_bytes(), Some(&m))
        .unwrap_err();
    assert_eq!(e.column, "BC_Pressure_1");
    // The map's metadata against the file's: equal is fine, different refused (neither wins).
    let dry = format!("{map_text}[metadata]\nrail = \"dry\"\n");
    let m = ChannelMap::parse(Path::new("m.toml"), &dry).unwrap();
    let e = hils::measured::parse_bytes_with(Path::new("export.csv"), text.as_bytes(), Some(&m))
        .unwrap_err();
    assert_eq!(e.column, "rail");
    assert!(
        e.message.contains("`wet`") && e.message.contains("`dry`") && e.message.contains("m.toml"),
        "{e}"
    );
    assert!(
        !e.message.contains("  "),
        "a run of blanks in the message: {e}"
    );
    let wet = format!("{map_text}[metadata]\nrail = \"WET\"\n");
    let m = ChannelMap::parse(Path::new("m.toml"), &wet).unwrap();
    assert!(
        hils::measured::parse_bytes_with(Path::new("export.csv"), text.as_bytes(), Some(&m))
            .is_ok()
    );
}

/// Issue 24 item 4: `# rail: wet` then `# rail: dry` was taken silently (last wins); now
/// an error naming the key. The same value twice is fine.
#[test]
fn conflicting_repeated_metadata_is_an_error_naming_the_key() {
    let body = "t_s,v_ref_mps,omega1_radps,omega2_radps,omega3_radps,omega4_radps,f_clamp1_n,f_clamp2_n,f_clamp3_n,f_clamp4_n\n\
0,30,70,70,70,70,0,0,0,0\n0.001,30,70,70,70,70,0,0,0,0\n";
    let conflict = format!("# rail: wet\n# rail: dry\n{body}");
    let e = hils::measured::parse_run_log(Path::new("c.csv"), &conflict).unwrap_err();
    assert_eq!(e.column, "rail");
    assert!(
        e.message.contains("wet") && e.message.contains("dry"),
        "{e}"
    );
    let speed = format!("# initial_speed_kmh: 120\n# initial_speed_kmh: 125\n{body}");
    let e = hils::measured::parse_run_log(Path::new("c.csv"), &speed).unwrap_err();
    assert_eq!(e.column, "initial_speed_kmh");
    let repeated = format!(
        "# rail: wet\n# notes: a\n# notes: b\n# rail: Wet\n# initial_speed_kmh: 120\n# initial_speed_kmh: 120.0\n{body}"
    );
    assert!(hils::measured::parse_run_log(Path::new("c.csv"), &repeated).is_ok());
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(300))]
    /// Damaged recordings (bytes overwritten anywhere, the file cut anywhere): never a
    /// panic; a file that still reads has time finite and increasing, every channel as long
    /// as the time and every value empty or within its column's plausible range.
    #[test]
    fn damaged_mdf4_never_panics(
        edits in proptest::collection::vec((0usize..13_448, proptest::prelude::any::<u8>()), 1..8),
        cut in 64usize..13_448,
    ) {
        let mut bytes = std::fs::read(data("canape_sorted.mf4")).unwrap();
        for (at, b) in edits {
            if at < bytes.len() {
                bytes[at] = b;
            }
        }
        let m = map("canape_sorted");
        for b in [&bytes[..], &bytes[..cut.min(bytes.len())]] {
            if let Ok(hils::measured::Measured::Run(r)) =
                hils::measured::parse_bytes_with(Path::new("damaged.mf4"), b, Some(&m))
            {
                let n = r.t_s.len();
                assert!(r.t_s.windows(2).all(|w| w[1] > w[0]));
                let limit = |name: &str| hils::measured::plausible_range(name).unwrap();
                for (j, w) in r.omega_radps.iter().enumerate() {
                    assert_eq!(w.len(), n);
                    let range = limit(&format!("omega{}_radps", j + 1));
                    assert!(w.iter().all(|x| x.is_nan() || range.contains(x)));
                }
                for (j, p) in r.p_cyl_pa.iter().enumerate() {
                    if let Some(p) = p {
                        assert_eq!(p.len(), n);
                        let range = limit(&format!("p_cyl{}_pa", j + 1));
                        assert!(p.iter().all(|x| x.is_nan() || range.contains(x)));
                    }
                }
            }
        }
    }
}

/// The fit-friction figures of a JSON without what names the files and the time taken.
fn fit_figures(dir: &Path, json: &str) -> serde_json::Value {
    let text = std::fs::read_to_string(dir.join(json)).unwrap();
    let mut v: serde_json::Value = serde_json::from_str(&text).unwrap();
    let o = v.as_object_mut().unwrap();
    o.remove("files");
    o.remove("wall_s");
    v
}

/// `fit-friction` reads an MDF4 friction test in row chunks (its one channel group, chunk
/// by chunk of records) and fits it to exactly the figures of the CSV of the same numbers:
/// 250,000 points, four chunks, fitted as cells (beyond 200,000 points).
#[test]
fn fit_friction_of_an_mdf4_test_equals_its_csv() {
    use hils::mdf4::write::{Column, ColumnValues, write};
    let dir = common::temp_dir("mdf4-fit");
    let n = 250_000;
    let text = common::friction_test_text(n);
    std::fs::write(dir.join("ft.csv"), &text).unwrap();
    let mut cols = [Vec::new(), Vec::new(), Vec::new()];
    for line in text.lines().skip(2) {
        for (c, cell) in cols.iter_mut().zip(line.split(',')) {
            c.push(cell.parse::<f64>().unwrap());
        }
    }
    let columns: Vec<Column> = [("Speed", "m/s"), ("DiscTemp", "degC"), ("Mu", "")]
        .iter()
        .zip(cols)
        .map(|(&(name, unit), v)| Column {
            name,
            unit,
            comment: "",
            values: ColumnValues::Num(v),
        })
        .collect();
    let t: Vec<f64> = (0..n).map(|k| k as f64 * 1e-3).collect();
    let meta = [("source", "test (synthetic, Eq 2)".to_string())];
    let file = std::fs::File::create(dir.join("ft.mf4")).unwrap();
    write(file, "friction test", &meta, &t, &columns).unwrap();
    std::fs::write(
        dir.join("m.toml"),
        "[channels.v_friction_mps]\nfrom = \"Speed\"\n[channels.t_disc_c]\nfrom = \"DiscTemp\"\n\
         [channels.mu]\nfrom = \"Mu\"\nunit = \"-\"\n",
    )
    .unwrap();
    common::hils_ok(&dir, args!["fit-friction", "--json", "csv.json", "ft.csv"]);
    let mf4_args = args![
        "fit-friction",
        "--map",
        "m.toml",
        "--json",
        "mf4.json",
        "ft.mf4"
    ];
    common::hils_ok(&dir, mf4_args);
    let (csv, mf4) = (fit_figures(&dir, "csv.json"), fit_figures(&dir, "mf4.json"));
    assert_eq!(mf4["points"], n, "{mf4}");
    assert!(mf4["cells"].is_object(), "fitted as cells: {mf4}");
    assert_eq!(csv, mf4);
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A friction test whose channels are in two channel groups (DiscTemp at a tenth of the
/// rate; asammdf wrote it: `scripts/mdf4_asammdf.py friction ... --slow-temp`) is read
/// whole to put them on one time grid: the same points as the whole-file reader, and a
/// note that says it was not read in row chunks.
#[test]
fn a_friction_test_in_two_channel_groups_is_read_whole_and_says_so() {
    use hils::measured::{read_friction_test_with, stream_friction_test_with};
    let path = data("friction_two_rates.mf4");
    let m = map("friction_two_rates");
    let whole = read_friction_test_with(&path, Some(&m)).unwrap_or_else(|e| panic!("{e}"));
    let (mut mu, mut chunks) = (Vec::<f64>::new(), 0);
    let open = || std::fs::File::open(&path).map(std::io::BufReader::new);
    let streamed = stream_friction_test_with(&path, Some(&m), open, |c| {
        mu.extend(&c.mu);
        chunks += 1;
        Ok(())
    })
    .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(
        (chunks, mu.len()),
        (1, 50),
        "DiscTemp at every 10th of 500 rows"
    );
    assert_eq!(mu, whole.mu);
    assert_eq!(streamed.skipped, whole.skipped);
    assert!(
        streamed
            .notes
            .iter()
            .any(|n| n.contains("2 channel groups") && n.contains("read whole")),
        "{:?}",
        streamed.notes
    );
}
