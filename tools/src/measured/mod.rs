//! Reading measured data: run logs and brake-dynamometer friction tests, in the formats of
//! `spec/measured-data.md`, one module per stage and format: [`table`] (CSV cells,
//! metadata, errors, checks), [`run_log`] (section 1) and [`friction_test`] (section 2).
//! Column names come from the one schema, `hils_sil::record`.
//!
//! Both kinds are CSV files with `# key: value` metadata lines before one header row. Units
//! are part of every column name, columns come in any order, unknown columns are kept (by
//! name) and ignored.
//!
//! # Error behaviour (the spec's "Bad input")
//!
//! The reader streams ([`table`]): row by row into typed columns, each cell checked as it
//! is read. A missing required column, a non-numeric cell in a numeric column, a NaN/inf
//! cell, a time that does not increase or spans more than [`MAX_SPAN_S`], or a value
//! outside its column's plausible range ([`limits`]: absolute physical bounds, one table
//! shared with `docs/measured-data-limits.md`) is an error that names the file, the line,
//! the data row and the column ([`MeasuredError`]). A UTF-8 byte-order mark before the
//! first line is not part of the text.
//!
//! * An empty cell means "not measured at this sample": it is kept as missing (`NaN` in the
//!   channel), never invented; every column's count of missing cells is in
//!   [`RunLog::missing`], and every tool that skips or repairs something says how many and
//!   why ([`RunLog::notes`], [`FrictionTest::notes`]).
//! * Small negative readings within a column's noise band (its lower limit) are kept as
//!   measured (a zero-centred sensor reads slightly negative at rest).

pub mod friction_test;
pub mod limits;
pub mod map;
mod mdf;
pub mod run_log;
pub mod table;
pub mod units;

use std::io::{BufRead, BufReader};
use std::path::Path;

pub use friction_test::{FrictionTest, RELEASED_SHARE, stream_friction_test};
pub use limits::{Limit, MAX_SPAN_S, plausible_range};
pub use map::ChannelMap;
pub use run_log::{PerWheelset, RunLog};
pub use table::{MeasuredError, Metadata, TextColumn, noise_sigma};

use table::{Kind, Table, file_error, read_table};

/// Either kind of measured file.
#[derive(Clone, Debug)]
pub enum Measured {
    Run(RunLog),
    Friction(FrictionTest),
}

/// Reads a measured file of either kind (decided by its columns: `v_friction_mps` makes a
/// friction test, `v_ref_mps` a run log), streaming: the file is never held whole.
pub fn read(path: &Path) -> Result<Measured, MeasuredError> {
    read_with(path, None)
}

/// Reads a measured file, CSV or MDF4 (told apart by the file's first bytes), its columns
/// named and its units converted by the channel `map` (None: the spec's names).
pub fn read_with(path: &Path, map: Option<&ChannelMap>) -> Result<Measured, MeasuredError> {
    let file =
        std::fs::File::open(path).map_err(|e| file_error(path, format!("cannot read: {e}")))?;
    let mut input = BufReader::with_capacity(1 << 16, file);
    let head = input
        .fill_buf()
        .map_err(|e| file_error(path, format!("cannot read: {e}")))?;
    not_mdf_under_an_mdf_name(path, head)?;
    if crate::mdf4::is_mdf(head) {
        let src = mdf_source(path, input.into_inner())?;
        return from_table(mdf::read_table(path, &src, map)?, map);
    }
    from_table(read_table(path, input, map)?, map)
}

/// Parses the text of a measured file of either kind (`path` names it in messages).
pub fn parse(path: &Path, text: &str) -> Result<Measured, MeasuredError> {
    parse_bytes(path, text.as_bytes())
}

/// Parses the bytes of a measured file of either kind (`path` names it in messages).
pub fn parse_bytes(path: &Path, bytes: &[u8]) -> Result<Measured, MeasuredError> {
    parse_bytes_with(path, bytes, None)
}

/// Parses the bytes of a measured file, CSV or MDF4, with a channel map.
pub fn parse_bytes_with(
    path: &Path,
    bytes: &[u8],
    map: Option<&ChannelMap>,
) -> Result<Measured, MeasuredError> {
    not_mdf_under_an_mdf_name(path, bytes)?;
    if crate::mdf4::is_mdf(bytes) {
        let src = crate::mdf4::blocks::Memory(bytes);
        return from_table(mdf::read_table(path, &src, map)?, map);
    }
    from_table(read_table(path, bytes, map)?, map)
}

/// A file named as an MDF file (`.mf4`, `.mdf`) whose first bytes are not an MDF
/// identification: an error saying so (it is not read as a CSV).
fn not_mdf_under_an_mdf_name(path: &Path, head: &[u8]) -> Result<(), MeasuredError> {
    let mdf_name = path
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("mf4") || e.eq_ignore_ascii_case("mdf"));
    if mdf_name && !crate::mdf4::is_mdf(head) {
        let shown: String = head
            .iter()
            .take(8)
            .map(|&b| if b.is_ascii_graphic() { b as char } else { '.' })
            .collect();
        return Err(file_error(
            path,
            format!(
                "not an MDF file: it starts with `{shown}`, an MDF file with `MDF     ` (a \
                 damaged file, or another format under an MDF name)"
            ),
        ));
    }
    Ok(())
}

fn from_table(mut table: Table, map: Option<&ChannelMap>) -> Result<Measured, MeasuredError> {
    check_metadata(&mut table, map)?;
    match table.kind {
        Kind::Friction => friction_test::from_table(table).map(Measured::Friction),
        Kind::Run => run_log::from_table(table).map(Measured::Run),
    }
}

/// Checks the table's metadata (no key given twice with different values) and adds the
/// channel `map`'s (a key both give must agree).
fn check_metadata(table: &mut Table, map: Option<&ChannelMap>) -> Result<(), MeasuredError> {
    table.metadata.check_repeats(&table.path)?;
    if let Some(map) = map {
        let origin = format!("the channel map {}", map.path.display());
        table
            .metadata
            .merge(&table.path, map.metadata_pairs(), &origin)?;
    }
    Ok(())
}

impl Measured {
    /// The file as the kind the caller wants (`pick`), or the error naming what it is.
    fn expect<T>(
        self,
        path: &Path,
        pick: fn(Measured) -> Option<T>,
        otherwise: &str,
    ) -> Result<T, MeasuredError> {
        pick(self).ok_or_else(|| file_error(path, otherwise))
    }

    fn run(self) -> Option<RunLog> {
        match self {
            Measured::Run(r) => Some(r),
            Measured::Friction(_) => None,
        }
    }

    fn friction(self) -> Option<FrictionTest> {
        match self {
            Measured::Friction(f) => Some(f),
            Measured::Run(_) => None,
        }
    }
}

/// The message for a friction test read as a run log, and the other way round.
const NOT_A_RUN_LOG: &str = "is a friction test (has `v_friction_mps`), not a run log";
const NOT_A_FRICTION_TEST: &str = "is a run log, not a friction test (needs `v_friction_mps`)";

/// Reads a run log (an error if the file is a friction test).
pub fn read_run_log(path: &Path) -> Result<RunLog, MeasuredError> {
    read(path)?.expect(path, Measured::run, NOT_A_RUN_LOG)
}

/// Parses a run log's text.
pub fn parse_run_log(path: &Path, text: &str) -> Result<RunLog, MeasuredError> {
    parse(path, text)?.expect(path, Measured::run, NOT_A_RUN_LOG)
}

/// Reads a run log, CSV or MDF4, through a channel map.
pub fn read_run_log_with(path: &Path, map: Option<&ChannelMap>) -> Result<RunLog, MeasuredError> {
    read_with(path, map)?.expect(path, Measured::run, NOT_A_RUN_LOG)
}

/// Reads a friction test (an error if the file is a run log).
pub fn read_friction_test(path: &Path) -> Result<FrictionTest, MeasuredError> {
    read(path)?.expect(path, Measured::friction, NOT_A_FRICTION_TEST)
}

/// Reads a friction test, CSV or MDF4, through a channel map.
pub fn read_friction_test_with(
    path: &Path,
    map: Option<&ChannelMap>,
) -> Result<FrictionTest, MeasuredError> {
    read_with(path, map)?.expect(path, Measured::friction, NOT_A_FRICTION_TEST)
}

/// The channel map of a `--map FILE` flag (None without one).
pub fn load_map(path: Option<&Path>) -> Result<Option<ChannelMap>, MeasuredError> {
    path.map(ChannelMap::load).transpose()
}

/// Reads a friction test, CSV or MDF4, through a channel map, handing its points to `each`
/// in chunks of [`friction_test::CHUNK_ROWS`] rows (memory bounded whatever its length):
/// a CSV through [`stream_friction_test`] (`open` opens its bytes, once or twice), an MDF4
/// file chunk by chunk of its records when every channel used is in one channel group,
/// else whole (channel groups at different rates are put on one time grid: a note says
/// so; docs/mdf4.md). Returns the test without points (`points` counted).
pub fn stream_friction_test_with<R: BufRead>(
    path: &Path,
    map: Option<&ChannelMap>,
    open: impl FnMut() -> std::io::Result<R>,
    each: impl FnMut(&FrictionTest) -> Result<(), MeasuredError>,
) -> Result<FrictionTest, MeasuredError> {
    let mut head = Vec::with_capacity(8);
    std::fs::File::open(path)
        .and_then(|f| std::io::Read::read_to_end(&mut std::io::Read::take(f, 8), &mut head))
        .map_err(|e| file_error(path, format!("cannot read: {e}")))?;
    not_mdf_under_an_mdf_name(path, &head)?;
    if !crate::mdf4::is_mdf(&head) {
        return stream_friction_test(path, map, open, each);
    }
    let read = |chunk: &mut friction_test::ChunkFn| {
        let file =
            std::fs::File::open(path).map_err(|e| file_error(path, format!("cannot read: {e}")))?;
        let src = mdf_source(path, file)?;
        mdf::read_table_chunks(path, &src, map, friction_test::CHUNK_ROWS, chunk)
    };
    friction_test::stream_chunks(path, map, read, each)
}

/// The MDF4 file `file` (at `path`) as a source read piecewise.
fn mdf_source(
    path: &Path,
    file: std::fs::File,
) -> Result<crate::mdf4::blocks::FileSource, MeasuredError> {
    crate::mdf4::blocks::FileSource::new(file)
        .map_err(|e| file_error(path, format!("cannot read: {e}")))
}

/// Parses a friction test's text.
pub fn parse_friction_test(path: &Path, text: &str) -> Result<FrictionTest, MeasuredError> {
    parse(path, text)?.expect(path, Measured::friction, NOT_A_FRICTION_TEST)
}

#[cfg(test)]
mod tests {
    use super::*;
    use hils_plant::Rail;
    fn p() -> &'static Path {
        Path::new("x.csv")
    }

    const GOOD: &str = "# source: test\n# rail: dry\n# initial_speed_kmh: 120\n\
t_s,v_ref_mps,omega1_radps,omega2_radps,omega3_radps,omega4_radps,p_cyl1_pa,p_cyl2_pa,p_cyl3_pa,p_cyl4_pa,extra\n\
0.0,33.3,77.5,77.5,77.5,77.5,0,0,0,0,a\n\
0.01,33.2,77.2,77.2,77.2,77.2,1000,1000,,1000,b\n";

    #[test]
    fn reads_metadata_columns_and_empty_cells() {
        let r = parse_run_log(p(), GOOD).unwrap();
        assert_eq!(r.len(), 2);
        assert_eq!(r.rail, Some(Rail::Dry));
        assert_eq!(r.metadata.get("source"), Some("test"));
        assert_eq!(r.unknown_columns, vec!["extra".to_string()]);
        assert!(r.p_cyl_pa[2].as_ref().unwrap()[1].is_nan());
        assert_eq!(r.missing.get("p_cyl3_pa"), Some(&1));
        assert_eq!(r.notes.len(), 1);
    }

    #[test]
    fn errors_name_line_row_and_column() {
        let bad = GOOD.replace("1000,1000,,1000", "1000,abc,,1000");
        let e = parse_run_log(p(), &bad).unwrap_err();
        assert_eq!((e.line, e.row, e.column.as_str()), (6, 2, "p_cyl2_pa"));
        let bad = GOOD.replace("0.01,33.2", "0.0,33.2");
        let e = parse_run_log(p(), &bad).unwrap_err();
        assert_eq!((e.row, e.column.as_str()), (2, "t_s"));
        let bad = GOOD.replace("1000,1000,,1000", "1000,-90000,,1000");
        let e = parse_run_log(p(), &bad).unwrap_err();
        assert_eq!(e.column, "p_cyl2_pa");
        let bad = GOOD.replace("33.2,77.2", "NaN,77.2");
        let e = parse_run_log(p(), &bad).unwrap_err();
        assert_eq!(e.column, "v_ref_mps");
        let bad = GOOD.replace(",omega4_radps", ",omega9_radps");
        let e = parse_run_log(p(), &bad).unwrap_err();
        assert_eq!(e.column, "omega4_radps");
        assert!(e.to_string().contains("x.csv"));
    }

    #[test]
    fn friction_test_from_forces_skips_released_rows_with_count() {
        let text = "t_s,v_friction_mps,t_disc_c,f_clamp_n,f_friction_n\n0,20,0,0,0\n0.1,19.9,1,10000,4000\n0.2,19.8,2,10000,\n";
        let f = parse_friction_test(p(), text).unwrap();
        assert_eq!(f.mu, vec![0.4]);
        assert_eq!(f.skipped, 2);
        assert_eq!(f.notes.len(), 2);
    }

    /// Issue 12 item 3: a UTF-8 byte-order mark before `#` metadata is not part of the
    /// text: the metadata stays metadata and errors name the right line.
    #[test]
    fn bom_before_metadata_is_dropped() {
        let text = format!("\u{feff}{GOOD}");
        let r = parse_run_log(p(), &text).unwrap();
        assert_eq!(r.metadata.get("source"), Some("test"));
        assert_eq!(r.len(), 2);
        let bad = text.replace("1000,1000,,1000", "1000,abc,,1000");
        let e = parse_run_log(p(), &bad).unwrap_err();
        assert_eq!((e.line, e.row, e.column.as_str()), (6, 2, "p_cyl2_pa"));
        // A BOM anywhere else is a cell's text: an error, not silently dropped.
        let bad = GOOD.replace("0.01,33.2", "\u{feff}0.01,33.2");
        let e = parse_run_log(p(), &bad).unwrap_err();
        assert_eq!((e.line, e.row, e.column.as_str()), (6, 2, "t_s"));
    }

    /// Issue 12 item 4: every value is checked against its column's absolute limits; an
    /// outlier in another row does not widen them, and there are upper bounds.
    #[test]
    fn outliers_do_not_hide_impossible_values() {
        let outlier = GOOD.replace("1000,1000,,1000", "1e12,1000,,1000");
        let e = parse_run_log(p(), &outlier).unwrap_err();
        assert_eq!((e.line, e.row, e.column.as_str()), (6, 2, "p_cyl1_pa"));
        assert!(e.message.contains("plausible range"), "{e}");
        // -1e9 Pa after a large (but plausible) pressure in an earlier row.
        let big_then_negative = GOOD
            .replace("0,0,0,0,a", "1.9e6,0,0,0,a")
            .replace("1000,1000,,1000", "-1e9,1000,,1000");
        let e = parse_run_log(p(), &big_then_negative).unwrap_err();
        assert_eq!((e.row, e.column.as_str()), (2, "p_cyl1_pa"));
        let fast = GOOD.replace("0.01,33.2", "0.01,1e300");
        let e = parse_run_log(p(), &fast).unwrap_err();
        assert_eq!((e.line, e.row, e.column.as_str()), (6, 2, "v_ref_mps"));
        // Within the noise band at rest: kept as measured.
        let noise = GOOD.replace("1000,1000,,1000", "-3000,1000,,1000");
        assert_eq!(
            parse_run_log(p(), &noise).unwrap().p_cyl_pa[0]
                .as_ref()
                .unwrap()[1],
            -3000.0
        );
    }

    /// Issue 12 item 1 (reader side): a log spanning more than `MAX_SPAN_S` (milliseconds
    /// logged as seconds) is an error naming the time column and the row.
    #[test]
    fn time_span_is_bounded() {
        let mut text = String::from(
            "t_s,v_ref_mps,omega1_radps,omega2_radps,omega3_radps,omega4_radps,f_clamp1_n,f_clamp2_n,f_clamp3_n,f_clamp4_n\n",
        );
        for i in 0..10 {
            text += &format!("{},30,70,70,70,70,0,0,0,0\n", i as f64 * 30_000.0 / 9.0);
        }
        let e = parse_run_log(p(), &text).unwrap_err();
        assert_eq!((e.line, e.row, e.column.as_str()), (4, 3, "t_s"));
        assert!(e.message.contains("spans"), "{e}");
    }

    /// The streaming file reader and the in-memory parser agree; the `cmd` column is
    /// interned, not a `String` per row.
    #[test]
    fn file_and_text_read_the_same() {
        let dir = std::env::temp_dir().join(format!("hils-reader-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("x.csv");
        let text = GOOD
            .replace(",extra", ",cmd")
            .replace(",a\n", ",EB\n")
            .replace(",b\n", ",EB\n");
        std::fs::write(&path, &text).unwrap();
        let a = read_run_log(&path).unwrap();
        let b = parse_run_log(&path, &text).unwrap();
        assert_eq!(a.t_s, b.t_s);
        assert_eq!(a.omega_radps, b.omega_radps);
        let cmd = a.cmd.unwrap();
        assert_eq!((cmd.len(), cmd.values.len()), (2, 1));
        assert_eq!(cmd[1], "EB");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// fit-friction's chunked reading goes through the channel map like the whole-file
    /// reader: the same points (units converted), and an error past the first chunk names
    /// the file's row (not the chunk's) and the column as the file and the map name it.
    #[test]
    fn chunks_read_through_the_map_like_the_whole_file() {
        let dir = std::env::temp_dir().join(format!("hils-chunk-map-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let map_text = "[channels.v_friction_mps]\nfrom = \"Speed\"\nunit = \"km/h\"\n\
                        [channels.t_disc_c]\nfrom = \"DiscTemp\"\nunit = \"degC\"\n[channels.mu]\nfrom = \"Mu\"\nunit = \"-\"\n";
        let map = ChannelMap::parse(&dir.join("m.toml"), map_text).unwrap();
        let rows = friction_test::CHUNK_ROWS + 10;
        let mut text = String::from("# source: test\nSpeed,DiscTemp,Mu\n");
        for r in 0..rows {
            text += &format!("{},{},0.35\n", 36.0 + (r % 100) as f64, (r % 300) as f64);
        }
        let path = dir.join("f.csv");
        std::fs::write(&path, &text).unwrap();
        let open = || std::fs::File::open(&path).map(BufReader::new);
        let (mut n, mut v0) = (0, f64::NAN);
        let streamed = stream_friction_test_with(&path, Some(&map), open, |c| {
            v0 = if n == 0 { c.v_friction_mps[0] } else { v0 };
            n += c.mu.len();
            Ok(())
        })
        .unwrap();
        let whole = read_friction_test_with(&path, Some(&map)).unwrap();
        assert_eq!((n, streamed.points, whole.mu.len()), (rows, rows, rows));
        assert!((v0 - 10.0).abs() < 1e-12, "36 km/h read as {v0} m/s");
        // Row CHUNK_ROWS + 5 (1-based) out of range: named by the file's row and label.
        let bad_row = friction_test::CHUNK_ROWS + 5;
        let mut lines: Vec<&str> = text.lines().collect();
        lines[1 + bad_row] = "36,5000,0.35";
        std::fs::write(&path, lines.join("\n") + "\n").unwrap();
        let e = stream_friction_test_with(&path, Some(&map), open, |_| Ok(())).unwrap_err();
        assert_eq!(e.row, bad_row, "{e}");
        assert_eq!(e.column, "DiscTemp (t_disc_c)", "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// A friction test of `rows` rows as an MDF4 file (one channel group, the time as its
    /// master: the project's writer) and as the CSV of the same numbers, in `dir`; mu
    /// given (`Mu`) and from the forces (`Clamp`, `Friction`: some rows released).
    fn friction_files(dir: &Path, rows: usize) -> (std::path::PathBuf, std::path::PathBuf) {
        use crate::mdf4::write::{Column, ColumnValues};
        let t: Vec<f64> = (0..rows).map(|r| r as f64 * 1e-3).collect();
        let speed_kmh: Vec<f64> = (0..rows).map(|r| 36.0 + (r % 100) as f64).collect();
        let temp: Vec<f64> = (0..rows).map(|r| (r % 300) as f64 * 0.5).collect();
        let clamp: Vec<f64> = (0..rows)
            .map(|r| {
                if r % 7 == 0 {
                    10.0
                } else {
                    20_000.0 + (r % 13) as f64
                }
            })
            .collect();
        let friction: Vec<f64> = (0..rows).map(|r| 7_000.0 + (r % 11) as f64).collect();
        let mu: Vec<f64> = (0..rows).map(|r| 0.3 + (r % 17) as f64 * 1e-3).collect();
        let named = [
            ("Speed", "km/h", &speed_kmh),
            ("DiscTemp", "degC", &temp),
            ("Clamp", "N", &clamp),
            ("Friction", "N", &friction),
            ("Mu", "-", &mu),
        ];
        let mut csv = String::from("# source: test\nt_s,Speed,DiscTemp,Clamp,Friction,Mu\n");
        for r in 0..rows {
            csv += &format!("{}", t[r]);
            for (_, _, v) in &named {
                csv += &format!(",{}", v[r]);
            }
            csv += "\n";
        }
        let columns: Vec<Column> = named
            .iter()
            .map(|(name, unit, v)| Column {
                name,
                unit,
                comment: "",
                values: ColumnValues::Num(v.to_vec()),
            })
            .collect();
        let (csv_path, mf4_path) = (dir.join("f.csv"), dir.join("f.mf4"));
        std::fs::write(&csv_path, csv).unwrap();
        let meta = [("source", "test".to_string())];
        let file = std::fs::File::create(&mf4_path).unwrap();
        crate::mdf4::write::write(file, "friction test", &meta, &t, &columns).unwrap();
        (csv_path, mf4_path)
    }

    /// The points `stream_friction_test_with` hands on, chunk after chunk, with the test.
    fn streamed(path: &Path, map: &ChannelMap) -> Result<(FrictionTest, usize), MeasuredError> {
        let open = || std::fs::File::open(path).map(BufReader::new);
        let (mut all, mut chunks) = (FrictionTest::default(), 0);
        let test = stream_friction_test_with(path, Some(map), open, |c| {
            all.v_friction_mps.extend(&c.v_friction_mps);
            all.t_disc_c.extend(&c.t_disc_c);
            all.mu.extend(&c.mu);
            all.rows.extend(&c.rows);
            chunks += 1;
            Ok(())
        })?;
        all.notes = test.notes;
        all.skipped = test.skipped;
        all.points = test.points;
        Ok((all, chunks))
    }

    /// An MDF4 friction test is read in row chunks, as a CSV: the same points (rows, units
    /// converted through the map, released rows skipped with the same notes) as the whole
    /// file read and as the CSV of the same numbers, mu given and from the forces (read
    /// twice); an error in a later chunk names the file's record (not the chunk's row) and
    /// the channel as the file and the map name it.
    #[test]
    fn an_mdf4_friction_test_streams_in_chunks_like_its_csv() {
        let dir = std::env::temp_dir().join(format!("hils-mdf-chunks-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let rows = 2 * friction_test::CHUNK_ROWS + 10;
        let (csv, mf4) = friction_files(&dir, rows);
        let maps = [
            "[channels.v_friction_mps]\nfrom = \"Speed\"\nunit = \"km/h\"\n\
             [channels.t_disc_c]\nfrom = \"DiscTemp\"\nunit = \"degC\"\n\
             [channels.mu]\nfrom = \"Mu\"\nunit = \"-\"\n",
            "[channels.v_friction_mps]\nfrom = \"Speed\"\nunit = \"km/h\"\n\
             [channels.t_disc_c]\nfrom = \"DiscTemp\"\nunit = \"degC\"\n\
             [channels.f_clamp_n]\nfrom = \"Clamp\"\nunit = \"N\"\n\
             [channels.f_friction_n]\nfrom = \"Friction\"\nunit = \"N\"\n",
        ];
        for (k, text) in maps.iter().enumerate() {
            let map = ChannelMap::parse(&dir.join("m.toml"), text).unwrap();
            let (from_mdf, chunks) = streamed(&mf4, &map).unwrap();
            let (from_csv, _) = streamed(&csv, &map).unwrap();
            let whole = read_friction_test_with(&mf4, Some(&map)).unwrap();
            assert_eq!(
                chunks,
                3,
                "map {k}: chunks of {} rows",
                friction_test::CHUNK_ROWS
            );
            for other in [&from_csv, &whole] {
                assert_eq!(from_mdf.v_friction_mps, other.v_friction_mps, "map {k}");
                assert_eq!(from_mdf.t_disc_c, other.t_disc_c, "map {k}");
                assert_eq!(from_mdf.mu, other.mu, "map {k}");
                assert_eq!(from_mdf.rows, other.rows, "map {k}");
                assert_eq!(from_mdf.skipped, other.skipped, "map {k}");
            }
            assert_eq!(from_mdf.notes, from_csv.notes, "map {k}");
            assert_eq!(from_mdf.points, whole.mu.len(), "map {k}");
            let kmh = 36.0 + ((from_mdf.rows[0] - 1) % 100) as f64;
            assert!(
                (from_mdf.v_friction_mps[0] - kmh / 3.6).abs() < 1e-12,
                "km/h in m/s"
            );
            let released = (0..rows).filter(|r| r % 7 == 0).count();
            assert_eq!(
                from_mdf.skipped,
                if k == 0 { 0 } else { released },
                "map {k}"
            );
        }
        // A bad value in the third chunk: its record named, not its row in the chunk.
        let map = ChannelMap::parse(&dir.join("m.toml"), maps[0]).unwrap();
        let bad_row = 2 * friction_test::CHUNK_ROWS + 5;
        let mut bytes = std::fs::read(&mf4).unwrap();
        let record = 8 * 6;
        let at = bytes.len() - rows * record + (bad_row - 1) * record + 16;
        bytes[at..at + 8].copy_from_slice(&5000.0f64.to_le_bytes());
        std::fs::write(&mf4, &bytes).unwrap();
        let e = streamed(&mf4, &map).unwrap_err();
        assert_eq!(
            (e.row, e.column.as_str()),
            (bad_row, "DiscTemp (t_disc_c)"),
            "{e}"
        );
        assert!(e.to_string().contains("f.mf4"), "{e}");
        // A time that stops increasing in the second chunk: its record named.
        let bad_row = friction_test::CHUNK_ROWS + 3;
        let at = bytes.len() - rows * record + (bad_row - 1) * record;
        bytes[at..at + 8].copy_from_slice(&0.0f64.to_le_bytes());
        std::fs::write(&mf4, &bytes).unwrap();
        let e = streamed(&mf4, &map).unwrap_err();
        assert_eq!(e.column, "t_s", "{e}");
        assert!(e.message.contains(&format!("at record {bad_row} ")), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// A time that does not increase at the first row of a later chunk (just after a chunk
    /// boundary) is an error naming that row, CSV and MDF4 alike: the last time of the
    /// chunk before is kept, though its points (with their time column) were handed on.
    #[test]
    fn a_time_repeated_just_after_a_chunk_boundary_is_an_error() {
        let dir = std::env::temp_dir().join(format!("hils-mdf-boundary-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let rows = friction_test::CHUNK_ROWS + 10;
        let (csv, mf4) = friction_files(&dir, rows);
        let map = ChannelMap::parse(
            &dir.join("m.toml"),
            "[channels.v_friction_mps]\nfrom = \"Speed\"\nunit = \"km/h\"\n\
             [channels.t_disc_c]\nfrom = \"DiscTemp\"\nunit = \"degC\"\n\
             [channels.mu]\nfrom = \"Mu\"\nunit = \"-\"\n",
        )
        .unwrap();
        // The second chunk's first row (1-based) gets the time of the row before.
        let row = friction_test::CHUNK_ROWS + 1;
        let before = (row - 2) as f64 * 1e-3;
        let mut bytes = std::fs::read(&mf4).unwrap();
        let record = 8 * 6;
        let at = bytes.len() - rows * record + (row - 1) * record;
        bytes[at..at + 8].copy_from_slice(&before.to_le_bytes());
        std::fs::write(&mf4, &bytes).unwrap();
        let text = std::fs::read_to_string(&csv).unwrap();
        let mut lines: Vec<String> = text.lines().map(String::from).collect();
        let line = &mut lines[row + 1]; // a comment line and the header first
        let rest = line.split_once(',').unwrap().1.to_string();
        *line = format!("{before},{rest}");
        std::fs::write(&csv, lines.join("\n") + "\n").unwrap();
        let e = streamed(&mf4, &map).unwrap_err();
        assert_eq!(e.column, "t_s", "{e}");
        assert!(e.message.contains(&format!("at record {row} ")), "{e}");
        let e = streamed(&csv, &map).unwrap_err();
        assert_eq!((e.row, e.column.as_str()), (row, "t_s"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// The doc's limits table is the reader's table.
    #[test]
    fn limits_doc_is_the_readers_table() {
        let doc = include_str!("../../../docs/measured-data-limits.md");
        let (_, rest) = doc
            .split_once("<!-- limits:begin -->")
            .expect("begin marker");
        let (table, _) = rest.split_once("<!-- limits:end -->").expect("end marker");
        assert_eq!(
            table.trim(),
            limits::markdown().trim(),
            "regenerate with `hils limits`"
        );
    }
}
