//! Reading measured data: run logs and brake-dynamometer friction tests, in the formats of
//! `spec/measured-data.md`.
//!
//! Both kinds are CSV files with `# key: value` metadata lines before one header row. Units
//! are part of every column name, columns come in any order, unknown columns are kept (by
//! name) and ignored.
//!
//! # Error behaviour (the spec's "Bad input")
//!
//! * A missing required column, a non-numeric cell in a numeric column, a time that does not
//!   increase, a NaN/inf cell, or a physically impossible value (negative pressure, force,
//!   speed or load beyond noise) is an error that names the file, the line, the data row and
//!   the column ([`MeasuredError`]).
//! * An empty cell means "not measured at this sample": it is kept as missing (`NaN` in the
//!   channel), never invented; every column's count of missing cells is in
//!   [`RunLog::missing`], and every tool that skips or repairs something says how many and
//!   why ([`RunLog::notes`], [`FrictionTest::notes`]).
//! * Small negative readings within the noise band (see [`negative_tolerance`]) are kept as
//!   measured (a zero-centred sensor reads slightly negative at rest).

use std::collections::BTreeMap;
use std::fmt;
use std::path::{Path, PathBuf};

use hils_plant::Rail;

/// A reading error that names the file, the line, the data row and the column.
#[derive(Clone, Debug, PartialEq)]
pub struct MeasuredError {
    pub file: PathBuf,
    /// 1-based line in the file (metadata and header lines counted); 0 = the whole file.
    pub line: usize,
    /// 1-based data row (the first row after the header is 1); 0 = not a data row.
    pub row: usize,
    /// Column name ("" = not about one column).
    pub column: String,
    pub message: String,
}

impl fmt::Display for MeasuredError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.file.display())?;
        if self.line > 0 {
            write!(f, ", line {}", self.line)?;
        }
        if self.row > 0 {
            write!(f, " (data row {})", self.row)?;
        }
        if !self.column.is_empty() {
            write!(f, ", column `{}`", self.column)?;
        }
        write!(f, ": {}", self.message)
    }
}

impl std::error::Error for MeasuredError {}

/// `# key: value` metadata lines, in file order (keys are free; duplicates are kept).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Metadata(pub Vec<(String, String)>);

impl Metadata {
    /// The last value of `key` (keys compare case-insensitively).
    pub fn get(&self, key: &str) -> Option<&str> {
        self.0
            .iter()
            .rev()
            .find(|(k, _)| k.eq_ignore_ascii_case(key))
            .map(|(_, v)| v.as_str())
    }

    /// A numeric value; an error naming the file and key when present but not a number.
    pub fn number(&self, key: &str, file: &Path) -> Result<Option<f64>, MeasuredError> {
        match self.get(key) {
            None => Ok(None),
            Some(v) => match v.trim().parse::<f64>() {
                Ok(x) if x.is_finite() => Ok(Some(x)),
                _ => Err(file_error(
                    file,
                    format!("metadata `{key}: {v}` is not a finite number"),
                )),
            },
        }
    }
}

/// One of the four wheelsets' values of a per-wheelset quantity; `None` when the column is
/// absent. Values are `NaN` where a cell was empty (not measured at that sample).
pub type PerWheelset = [Option<Vec<f64>>; 4];

/// A braking run (spec section 1).
#[derive(Clone, Debug, Default)]
pub struct RunLog {
    pub path: PathBuf,
    pub metadata: Metadata,
    /// Rail condition from the `rail` metadata (None when absent).
    pub rail: Option<Rail>,
    /// Time since the start of the log, s (strictly increasing).
    pub t_s: Vec<f64>,
    pub v_ref_mps: Vec<f64>,
    pub omega_radps: [Vec<f64>; 4],
    pub p_cyl_pa: PerWheelset,
    pub f_clamp_n: PerWheelset,
    pub f_brake_n: PerWheelset,
    pub t_disc_c: PerWheelset,
    pub q_n: PerWheelset,
    pub wsp: PerWheelset,
    pub a_x_mps2: Option<Vec<f64>>,
    pub cmd: Option<Vec<String>>,
    /// Columns the project does not use (kept by name, ignored).
    pub unknown_columns: Vec<String>,
    /// Empty cells per column (not measured at that sample).
    pub missing: BTreeMap<String, usize>,
    /// What the reader skipped or repaired, and why (empty: nothing).
    pub notes: Vec<String>,
}

impl RunLog {
    /// Number of samples.
    pub fn len(&self) -> usize {
        self.t_s.len()
    }

    pub fn is_empty(&self) -> bool {
        self.t_s.is_empty()
    }

    /// File name for messages.
    pub fn name(&self) -> String {
        self.path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default()
    }

    /// Median sample interval, s.
    pub fn median_interval_s(&self) -> f64 {
        let mut d: Vec<f64> = self.t_s.windows(2).map(|w| w[1] - w[0]).collect();
        if d.is_empty() {
            return 0.0;
        }
        d.sort_by(f64::total_cmp);
        d[d.len() / 2]
    }
}

/// A brake-dynamometer friction test (spec section 2): points of (friction speed, disc
/// temperature rise, friction coefficient).
#[derive(Clone, Debug, Default)]
pub struct FrictionTest {
    pub path: PathBuf,
    pub metadata: Metadata,
    /// Time, s, when the file is a time series.
    pub t_s: Option<Vec<f64>>,
    pub v_friction_mps: Vec<f64>,
    pub t_disc_c: Vec<f64>,
    /// mu (given, or f_friction / f_clamp).
    pub mu: Vec<f64>,
    /// 1-based data row of each kept point (for messages).
    pub rows: Vec<usize>,
    pub unknown_columns: Vec<String>,
    /// What the reader skipped, and why.
    pub notes: Vec<String>,
    /// Rows skipped (not measured, or brake released).
    pub skipped: usize,
}

/// Either kind of measured file.
#[derive(Clone, Debug)]
pub enum Measured {
    Run(RunLog),
    Friction(FrictionTest),
}

/// Robust sample noise of a signal from second (divided) differences: for white noise of
/// sigma s, x_{i+1} - x_i - r (x_i - x_{i-1}) (r = dt_{i+1}/dt_i) has variance
/// s^2 (1 + (1 + r)^2 + r^2); the median absolute value gives s robustly (slides and
/// steps are outliers). `t` may be sample indices when the time is unknown.
pub fn noise_sigma(t: &[f64], x: &[f64]) -> f64 {
    let mut d = Vec::with_capacity(x.len());
    for i in 1..x.len().saturating_sub(1) {
        let (a, b, c) = (x[i - 1], x[i], x[i + 1]);
        if !(a.is_finite() && b.is_finite() && c.is_finite()) {
            continue;
        }
        let r = (t[i + 1] - t[i]) / (t[i] - t[i - 1]);
        let dd = (c - b) - r * (b - a);
        d.push(dd.abs() / (1.0 + (1.0 + r) * (1.0 + r) + r * r).sqrt());
    }
    if d.is_empty() {
        return 0.0;
    }
    d.sort_by(f64::total_cmp);
    // Median of |N(0, s)| = 0.6745 s.
    d[d.len() / 2] / 0.6745
}

/// Lower bound below which a reading of a non-negative quantity is physically impossible
/// (not noise): the largest of 2 % of the column's largest magnitude, six times the
/// column's noise (robust estimate) and `floor`.
pub fn negative_tolerance(values: &[f64], floor: f64) -> f64 {
    let max = values
        .iter()
        .filter(|x| x.is_finite())
        .fold(0.0f64, |m, x| m.max(x.abs()));
    let index: Vec<f64> = (0..values.len()).map(|i| i as f64).collect();
    (0.02 * max)
        .max(6.0 * noise_sigma(&index, values))
        .max(floor)
}

/// The raw table: metadata, header and text cells, with line numbers.
struct Table {
    path: PathBuf,
    metadata: Metadata,
    header: Vec<String>,
    header_line: usize,
    /// (line, cells)
    rows: Vec<(usize, Vec<String>)>,
}

impl Table {
    fn err(
        &self,
        line: usize,
        row: usize,
        column: &str,
        message: impl Into<String>,
    ) -> MeasuredError {
        MeasuredError {
            file: self.path.clone(),
            line,
            row,
            column: column.to_string(),
            message: message.into(),
        }
    }

    fn column(&self, name: &str) -> Option<usize> {
        self.header.iter().position(|h| h == name)
    }

    /// A required column of a file kind (`kind` names the spec section), or the error.
    fn required(&self, name: &str, kind: &str) -> Result<usize, MeasuredError> {
        self.column(name).ok_or_else(|| {
            self.err(
                self.header_line,
                0,
                name,
                format!("required column is missing (see measured-data.md, {kind})"),
            )
        })
    }

    /// Fails on a file without data rows.
    fn require_rows(&self) -> Result<(), MeasuredError> {
        if self.rows.is_empty() {
            return Err(self.err(self.header_line, 0, "", "no data rows"));
        }
        Ok(())
    }

    /// A numeric column: empty cells -> NaN; other non-numbers and NaN/inf -> error.
    fn numeric(&self, idx: usize) -> Result<Vec<f64>, MeasuredError> {
        let name = &self.header[idx];
        let mut out = Vec::with_capacity(self.rows.len());
        for (r, (line, cells)) in self.rows.iter().enumerate() {
            let cell = cells[idx].trim();
            if cell.is_empty() {
                out.push(f64::NAN);
                continue;
            }
            match cell.parse::<f64>() {
                Ok(x) if x.is_finite() => out.push(x),
                Ok(x) => {
                    return Err(self.err(
                        *line,
                        r + 1,
                        name,
                        format!("`{cell}` is not finite ({x})"),
                    ));
                }
                Err(_) => {
                    return Err(self.err(*line, r + 1, name, format!("`{cell}` is not a number")));
                }
            }
        }
        Ok(out)
    }
}

fn parse_table(path: &Path, text: &str) -> Result<Table, MeasuredError> {
    let err = |line: usize, message: String| MeasuredError {
        file: path.to_path_buf(),
        line,
        row: 0,
        column: String::new(),
        message,
    };
    let mut metadata = Vec::new();
    let mut offset = 0usize;
    let mut line_no = 0usize;
    // Metadata lines before the header; blank lines there are allowed.
    for line in text.split_inclusive('\n') {
        let trimmed = line.trim();
        if let Some(rest) = trimmed.strip_prefix('#') {
            line_no += 1;
            offset += line.len();
            let rest = rest.trim();
            if rest.is_empty() {
                continue;
            }
            match rest.split_once(':') {
                Some((k, v)) => metadata.push((k.trim().to_string(), v.trim().to_string())),
                // A comment without a key: kept as a free note.
                None => metadata.push(("comment".to_string(), rest.to_string())),
            }
        } else if trimmed.is_empty() {
            line_no += 1;
            offset += line.len();
        } else {
            break;
        }
    }
    let first_line = line_no + 1;
    let mut reader = csv::ReaderBuilder::new()
        .has_headers(true)
        .flexible(false)
        .trim(csv::Trim::All)
        .from_reader(text[offset..].as_bytes());
    let header: Vec<String> = reader
        .headers()
        .map_err(|e| err(first_line, format!("cannot read the header row: {e}")))?
        .iter()
        .map(|h| h.trim().to_string())
        .collect();
    if header.iter().all(|h| h.is_empty()) {
        return Err(err(first_line, "no header row".into()));
    }
    for (i, h) in header.iter().enumerate() {
        if h.is_empty() {
            return Err(err(
                first_line,
                format!("column {} has an empty name", i + 1),
            ));
        }
        if header[..i].contains(h) {
            return Err(MeasuredError {
                file: path.to_path_buf(),
                line: first_line,
                row: 0,
                column: h.clone(),
                message: "column appears twice".into(),
            });
        }
    }
    let mut rows = Vec::new();
    for (r, rec) in reader.records().enumerate() {
        let rec = rec.map_err(|e| {
            let line = e
                .position()
                .map(|p| p.line() as usize + line_no)
                .unwrap_or(0);
            MeasuredError {
                file: path.to_path_buf(),
                line,
                row: r + 1,
                column: String::new(),
                message: format!("malformed CSV row: {e}"),
            }
        })?;
        let line = rec
            .position()
            .map(|p| p.line() as usize + line_no)
            .unwrap_or(0);
        rows.push((line, rec.iter().map(|s| s.to_string()).collect()));
    }
    Ok(Table {
        path: path.to_path_buf(),
        metadata: Metadata(metadata),
        header,
        header_line: first_line,
        rows,
    })
}

/// Reads a measured file of either kind (decided by its columns: `v_friction_mps` makes a
/// friction test, `v_ref_mps` a run log).
pub fn read(path: &Path) -> Result<Measured, MeasuredError> {
    let text =
        std::fs::read_to_string(path).map_err(|e| file_error(path, format!("cannot read: {e}")))?;
    parse(path, &text)
}

/// An error about a whole file (no line, row or column).
fn file_error(path: &Path, message: impl Into<String>) -> MeasuredError {
    MeasuredError {
        file: path.to_path_buf(),
        line: 0,
        row: 0,
        column: String::new(),
        message: message.into(),
    }
}

/// Parses the text of a measured file of either kind (`path` names it in messages).
pub fn parse(path: &Path, text: &str) -> Result<Measured, MeasuredError> {
    let table = parse_table(path, text)?;
    if table.column("v_friction_mps").is_some() {
        friction_from_table(table).map(Measured::Friction)
    } else if table.column("v_ref_mps").is_some() || table.column("omega1_radps").is_some() {
        run_from_table(table).map(Measured::Run)
    } else {
        Err(table.err(
            table.header_line,
            0,
            "",
            "neither a run log (needs `t_s`, `v_ref_mps`, `omega1_radps`..) nor a friction test \
             (needs `v_friction_mps`, `t_disc_c`, `mu` or `f_clamp_n` + `f_friction_n`)",
        ))
    }
}

/// A run log, or the error for a file of the other kind.
fn run_log(path: &Path, measured: Measured) -> Result<RunLog, MeasuredError> {
    match measured {
        Measured::Run(r) => Ok(r),
        Measured::Friction(_) => Err(file_error(
            path,
            "is a friction test (has `v_friction_mps`), not a run log",
        )),
    }
}

/// A friction test, or the error for a file of the other kind.
fn friction_test(path: &Path, measured: Measured) -> Result<FrictionTest, MeasuredError> {
    match measured {
        Measured::Friction(f) => Ok(f),
        Measured::Run(_) => Err(file_error(
            path,
            "is a run log, not a friction test (needs `v_friction_mps`)",
        )),
    }
}

/// Reads a run log (an error if the file is a friction test).
pub fn read_run_log(path: &Path) -> Result<RunLog, MeasuredError> {
    run_log(path, read(path)?)
}

/// Parses a run log's text.
pub fn parse_run_log(path: &Path, text: &str) -> Result<RunLog, MeasuredError> {
    run_log(path, parse(path, text)?)
}

/// Reads a friction test (an error if the file is a run log).
pub fn read_friction_test(path: &Path) -> Result<FrictionTest, MeasuredError> {
    friction_test(path, read(path)?)
}

/// Parses a friction test's text.
pub fn parse_friction_test(path: &Path, text: &str) -> Result<FrictionTest, MeasuredError> {
    friction_test(path, parse(path, text)?)
}

/// Every cell of a required column must be measured.
fn require_all(table: &Table, idx: usize, values: &[f64]) -> Result<(), MeasuredError> {
    if let Some(r) = values.iter().position(|x| x.is_nan()) {
        return Err(table.err(
            table.rows[r].0,
            r + 1,
            &table.header[idx],
            "empty cell in a required column",
        ));
    }
    Ok(())
}

/// Non-negative quantity: values below -tolerance are impossible.
fn check_non_negative(
    table: &Table,
    idx: usize,
    values: &[f64],
    floor: f64,
    what: &str,
) -> Result<(), MeasuredError> {
    let tol = negative_tolerance(values, floor);
    if let Some(r) = values.iter().position(|&x| x < -tol) {
        return Err(table.err(
            table.rows[r].0,
            r + 1,
            &table.header[idx],
            format!(
                "negative {what} {} beyond noise (tolerance -{tol:.4})",
                values[r]
            ),
        ));
    }
    Ok(())
}

fn check_time(table: &Table, idx: usize, t: &[f64]) -> Result<(), MeasuredError> {
    for r in 1..t.len() {
        if !(t[r] > t[r - 1]) {
            return Err(table.err(
                table.rows[r].0,
                r + 1,
                &table.header[idx],
                format!("time does not increase ({} after {})", t[r], t[r - 1]),
            ));
        }
    }
    Ok(())
}

fn run_from_table(table: Table) -> Result<RunLog, MeasuredError> {
    let required = |name: &str| table.required(name, "run log");
    table.require_rows()?;
    let mut used = vec![false; table.header.len()];
    let mut missing = BTreeMap::new();
    let mut take = |idx: usize, used: &mut Vec<bool>| -> Result<Vec<f64>, MeasuredError> {
        used[idx] = true;
        let v = table.numeric(idx)?;
        let n = v.iter().filter(|x| x.is_nan()).count();
        if n > 0 {
            missing.insert(table.header[idx].clone(), n);
        }
        Ok(v)
    };

    let i_t = required("t_s")?;
    let t_s = take(i_t, &mut used)?;
    require_all(&table, i_t, &t_s)?;
    check_time(&table, i_t, &t_s)?;

    let i_v = required("v_ref_mps")?;
    let v_ref_mps = take(i_v, &mut used)?;
    check_non_negative(&table, i_v, &v_ref_mps, 0.3, "speed")?;

    let mut omega: [Vec<f64>; 4] = Default::default();
    for (j, slot) in omega.iter_mut().enumerate() {
        let i = required(&format!("omega{}_radps", j + 1))?;
        *slot = take(i, &mut used)?;
        check_non_negative(&table, i, slot, 0.7, "wheel speed")?;
    }

    let mut per = |prefix: &str,
                   suffix: &str,
                   floor: f64,
                   what: &str,
                   non_negative: bool,
                   used: &mut Vec<bool>|
     -> Result<PerWheelset, MeasuredError> {
        let mut out: PerWheelset = Default::default();
        for (j, slot) in out.iter_mut().enumerate() {
            let name = format!("{prefix}{}{suffix}", j + 1);
            if let Some(i) = table.column(&name) {
                let v = take(i, used)?;
                if non_negative {
                    check_non_negative(&table, i, &v, floor, what)?;
                }
                *slot = Some(v);
            }
        }
        Ok(out)
    };
    let p_cyl_pa = per("p_cyl", "_pa", 5.0e3, "pressure", true, &mut used)?;
    let f_clamp_n = per("f_clamp", "_n", 200.0, "clamp force", true, &mut used)?;
    let f_brake_n = per("f_brake", "_n", 200.0, "brake force", false, &mut used)?;
    let t_disc_c = per("t_disc", "_c", 1.0, "", false, &mut used)?;
    let q_n = per("q", "_n", 1000.0, "axle load", true, &mut used)?;
    let wsp = per("wsp", "", 0.0, "", false, &mut used)?;

    // Every wheelset needs a brake input: its clamp force or its cylinder pressure.
    for j in 0..4 {
        if p_cyl_pa[j].is_none() && f_clamp_n[j].is_none() {
            return Err(table.err(
                table.header_line,
                0,
                &format!("p_cyl{0}_pa or f_clamp{0}_n", j + 1),
                "required column is missing: wheelset's brake input (cylinder pressure or clamp force)",
            ));
        }
    }
    // WSP flags are 0/1.
    for j in 0..4 {
        if let Some(w) = &wsp[j] {
            if let Some(r) = w
                .iter()
                .position(|&x| !(x.is_nan() || x == 0.0 || x == 1.0))
            {
                let idx = table.column(&format!("wsp{}", j + 1)).unwrap_or(0);
                return Err(table.err(
                    table.rows[r].0,
                    r + 1,
                    &table.header[idx],
                    format!("`{}` is not 0 or 1", w[r]),
                ));
            }
        }
    }

    let a_x_mps2 = match table.column("a_x_mps2") {
        Some(i) => Some(take(i, &mut used)?),
        None => None,
    };
    let cmd = table.column("cmd").map(|i| {
        used[i] = true;
        table
            .rows
            .iter()
            .map(|(_, c)| c[i].trim().to_string())
            .collect()
    });
    let unknown_columns: Vec<String> = table
        .header
        .iter()
        .zip(&used)
        .filter(|(_, u)| !**u)
        .map(|(h, _)| h.clone())
        .collect();

    let path = table.path.clone();
    let rail = match table.metadata.get("rail") {
        None => None,
        Some(r) => match r.trim().to_ascii_lowercase().as_str() {
            "wet" => Some(Rail::Wet),
            "dry" => Some(Rail::Dry),
            other => {
                return Err(table.err(
                    0,
                    0,
                    "",
                    format!("metadata `rail: {other}`: must be `wet` or `dry`"),
                ));
            }
        },
    };
    table.metadata.number("initial_speed_kmh", &path)?;
    table.metadata.number("eb_command_s", &path)?;
    let mut notes = Vec::new();
    for (col, n) in &missing {
        notes.push(format!(
            "{col}: {n} empty cell(s) (not measured at those samples; left out, not invented)"
        ));
    }
    Ok(RunLog {
        path,
        metadata: table.metadata,
        rail,
        t_s,
        v_ref_mps,
        omega_radps: omega,
        p_cyl_pa,
        f_clamp_n,
        f_brake_n,
        t_disc_c,
        q_n,
        wsp,
        a_x_mps2,
        cmd,
        unknown_columns,
        missing,
        notes,
    })
}

/// Rows of a time series with a clamp force below this share of the file's largest clamp
/// force are brake-released samples: mu is undefined there, they are skipped (counted).
pub const RELEASED_SHARE: f64 = 0.05;

fn friction_from_table(table: Table) -> Result<FrictionTest, MeasuredError> {
    let required = |name: &str| table.required(name, "friction test");
    table.require_rows()?;
    let mut used = vec![false; table.header.len()];
    let i_v = required("v_friction_mps")?;
    let i_t = required("t_disc_c")?;
    used[i_v] = true;
    used[i_t] = true;
    let v = table.numeric(i_v)?;
    check_non_negative(&table, i_v, &v, 0.3, "friction speed")?;
    let temp = table.numeric(i_t)?;
    let time = match table.column("t_s") {
        Some(i) => {
            used[i] = true;
            let t = table.numeric(i)?;
            require_all(&table, i, &t)?;
            check_time(&table, i, &t)?;
            Some(t)
        }
        None => None,
    };
    enum MuSource {
        Direct(Vec<f64>),
        Forces(Vec<f64>, Vec<f64>),
    }
    let source = if let Some(i) = table.column("mu") {
        used[i] = true;
        let mu = table.numeric(i)?;
        if let Some(r) = mu.iter().position(|&m| m < 0.0 || m > 2.0) {
            return Err(table.err(
                table.rows[r].0,
                r + 1,
                "mu",
                format!("friction coefficient {} outside [0, 2]", mu[r]),
            ));
        }
        MuSource::Direct(mu)
    } else {
        let i_c = table.column("f_clamp_n");
        let i_f = table.column("f_friction_n");
        match (i_c, i_f) {
            (Some(i_c), Some(i_f)) => {
                used[i_c] = true;
                used[i_f] = true;
                let c = table.numeric(i_c)?;
                check_non_negative(&table, i_c, &c, 50.0, "clamp force")?;
                let f = table.numeric(i_f)?;
                MuSource::Forces(c, f)
            }
            _ => {
                return Err(table.err(
                    table.header_line,
                    0,
                    "mu",
                    "required column is missing: `mu`, or both `f_clamp_n` and `f_friction_n`",
                ));
            }
        }
    };
    let mut out = FrictionTest {
        path: table.path.clone(),
        metadata: table.metadata.clone(),
        t_s: None,
        unknown_columns: table
            .header
            .iter()
            .zip(&used)
            .filter(|(_, u)| !**u)
            .map(|(h, _)| h.clone())
            .collect(),
        ..Default::default()
    };
    let mut kept_t = Vec::new();
    let (mut empty, mut released) = (0usize, 0usize);
    let clamp_max = match &source {
        MuSource::Forces(c, _) => c
            .iter()
            .filter(|x| x.is_finite())
            .fold(0.0f64, |m, &x| m.max(x)),
        MuSource::Direct(_) => 0.0,
    };
    for r in 0..table.rows.len() {
        let mu = match &source {
            MuSource::Direct(mu) => mu[r],
            MuSource::Forces(c, f) => {
                if c[r].is_nan() || f[r].is_nan() {
                    f64::NAN
                } else if c[r] < RELEASED_SHARE * clamp_max || c[r] <= 0.0 {
                    released += 1;
                    continue;
                } else {
                    let mu = f[r] / c[r];
                    if !(0.0..=2.0).contains(&mu) {
                        return Err(table.err(
                            table.rows[r].0,
                            r + 1,
                            "f_friction_n",
                            format!(
                                "friction coefficient f_friction / f_clamp = {mu:.4} outside [0, 2]"
                            ),
                        ));
                    }
                    mu
                }
            }
        };
        if mu.is_nan() || v[r].is_nan() || temp[r].is_nan() {
            empty += 1;
            continue;
        }
        out.v_friction_mps.push(v[r]);
        out.t_disc_c.push(temp[r]);
        out.mu.push(mu);
        out.rows.push(r + 1);
        if let Some(t) = &time {
            kept_t.push(t[r]);
        }
    }
    if empty > 0 {
        out.notes.push(format!(
            "{empty} row(s) skipped: a needed cell is empty (not measured)"
        ));
    }
    if released > 0 {
        out.notes.push(format!(
            "{released} row(s) skipped: brake released (clamp force below {:.0} % of the largest, mu undefined)",
            RELEASED_SHARE * 100.0
        ));
    }
    out.skipped = empty + released;
    if time.is_some() {
        out.t_s = Some(kept_t);
    }
    if out.mu.is_empty() {
        return Err(table.err(0, 0, "", "no usable friction points (every row skipped)"));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

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
}
