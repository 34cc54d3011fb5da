//! Stage 1 of reading: the CSV table (metadata lines, header, cells with their line
//! numbers), the error that names file, line, row and column, and the checks that both
//! formats share.

use std::fmt;
use std::io::{BufRead, Read};
use std::path::{Path, PathBuf};

use hils_sil::record::ColumnName;
use hils_sil::record::{friction_test as ft, run_log as rl};

use super::limits::{self, Limit};
use super::map::{ChannelMap, Resolved, resolve};
use super::units::ToSi;

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

    /// Fails when a key a tool may read is given twice with different values (`# rail:
    /// wet` and `# rail: dry`): the error names the key and both values. The same value
    /// repeated is fine; free texts (`comment`, `notes`) may repeat.
    pub fn check_repeats(&self, file: &Path) -> Result<(), MeasuredError> {
        for (i, (k, v)) in self.0.iter().enumerate() {
            if FREE_TEXT_KEYS.iter().any(|f| k.eq_ignore_ascii_case(f)) {
                continue;
            }
            if let Some((_, w)) = self.0[..i]
                .iter()
                .find(|(k2, w)| k2.eq_ignore_ascii_case(k) && !same_value(v, w))
            {
                return Err(MeasuredError {
                    column: k.clone(),
                    ..file_error(
                        file,
                        format!(
                            "metadata `{k}` is given twice with different values: `{w}` and `{v}`"
                        ),
                    )
                });
            }
        }
        Ok(())
    }

    /// Adds `extra` (from `origin`, e.g. the channel map) to the file's metadata. A key the
    /// file also gives is refused when the values differ (neither wins: the error names the
    /// key and both values); an equal value is kept once.
    pub fn merge(
        &mut self,
        file: &Path,
        extra: Vec<(String, String)>,
        origin: &str,
    ) -> Result<(), MeasuredError> {
        for (k, v) in extra {
            match self.get(&k) {
                Some(w) if !same_value(&v, w) => {
                    return Err(MeasuredError {
                        column: k.clone(),
                        ..file_error(
                            file,
                            format!(
                                "metadata `{k}`: the file says `{w}`, {origin} says `{v}`; \
                                 remove one (neither wins)"
                            ),
                        )
                    });
                }
                Some(_) => {}
                None => self.0.push((k, v)),
            }
        }
        Ok(())
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

/// Metadata keys that hold free text and may repeat with different values.
const FREE_TEXT_KEYS: [&str; 2] = ["comment", "notes"];

/// Two metadata values are the same: equal numbers, or equal texts ignoring case and
/// surrounding blanks.
fn same_value(a: &str, b: &str) -> bool {
    let (a, b) = (a.trim(), b.trim());
    match (a.parse::<f64>(), b.parse::<f64>()) {
        (Ok(x), Ok(y)) => x == y,
        _ => a.eq_ignore_ascii_case(b),
    }
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

/// A text column, interned: each distinct text once, a code per row (no `String` per
/// cell). `column[i]` is row i's text.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TextColumn {
    /// The distinct texts, in order of first appearance.
    pub values: Vec<String>,
    /// Per row: the index of its text in `values`.
    pub codes: Vec<u32>,
}

impl TextColumn {
    pub fn len(&self) -> usize {
        self.codes.len()
    }
    pub fn is_empty(&self) -> bool {
        self.codes.is_empty()
    }
    pub fn push(&mut self, text: &str) {
        let code = match self.values.iter().position(|v| v == text) {
            Some(c) => c,
            None => {
                self.values.push(text.to_string());
                self.values.len() - 1
            }
        };
        self.codes.push(code as u32);
    }
    /// The rows' texts in order.
    pub fn iter(&self) -> impl Iterator<Item = &str> {
        self.codes.iter().map(|&c| self.values[c as usize].as_str())
    }
}

impl std::ops::Index<usize> for TextColumn {
    type Output = String;
    fn index(&self, row: usize) -> &String {
        &self.values[self.codes[row] as usize]
    }
}

/// Most distinct texts a text column may hold (a command column has a handful).
const MAX_DISTINCT_TEXTS: usize = 1024;

/// How a column is read.
pub(crate) enum Cells {
    /// A known numeric column, checked against its [`Limit`] (empty cell = NaN).
    Numeric(Vec<f64>, Limit),
    /// A known text column.
    Text(TextColumn),
    /// A column the project does not use (kept by name, not read).
    Ignored,
}

/// The kind of a measured file, from its header.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum Kind {
    Run,
    Friction,
}

/// The table read: metadata, header and typed columns, with the line of every row.
pub(crate) struct Table {
    pub(crate) path: PathBuf,
    pub(crate) metadata: Metadata,
    pub(crate) header: Vec<String>,
    pub(crate) header_line: usize,
    pub(crate) kind: Kind,
    pub(crate) columns: Vec<Cells>,
    /// Each column's conversion to SI (a unit from the file or the channel map).
    pub(crate) to_si: Vec<ToSi>,
    /// Each column as messages name it: the file's name, with the spec column it fills.
    pub(crate) labels: Vec<String>,
    /// Each column's unit converted from (empty: the spec's own), for messages.
    pub(crate) units: Vec<String>,
    /// 1-based file line of each data row (0: a file without lines, MDF4).
    pub(crate) lines: Vec<u32>,
    /// What reading the table did that a user should know (channels put on the master
    /// time grid).
    pub(crate) notes: Vec<String>,
    /// Data rows read before the rows held (read in chunks: [`read_table_chunks`]).
    pub(crate) rows_before: usize,
    /// The time of the last row before the rows held (read in chunks).
    pub(crate) time_before: Option<f64>,
}

impl Table {
    pub(crate) fn err(
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

    /// An error about data row `r` (0-based) of column `idx`.
    pub(crate) fn row_err(
        &self,
        r: usize,
        idx: usize,
        message: impl Into<String>,
    ) -> MeasuredError {
        self.err(
            self.lines[r] as usize,
            self.rows_before + r + 1,
            &self.labels[idx],
            message,
        )
    }

    pub(crate) fn rows(&self) -> usize {
        self.lines.len()
    }

    pub(crate) fn column(&self, name: &str) -> Option<usize> {
        self.header.iter().position(|h| h == name)
    }

    /// The index of a schema column.
    pub(crate) fn index(&self, name: ColumnName) -> Option<usize> {
        self.column(&name.to_string())
    }

    /// A required column of a file kind (`kind` names the spec section), or the error.
    pub(crate) fn required(&self, name: ColumnName, kind: &str) -> Result<usize, MeasuredError> {
        self.index(name)
            .ok_or_else(|| self.missing_err(&[name.to_string()], kind))
    }

    /// The error for required quantities the file lacks: which, and which columns it has.
    pub(crate) fn missing_err(&self, missing: &[String], kind: &str) -> MeasuredError {
        let names: Vec<String> = self
            .labels
            .iter()
            .map(|l| l.split(" (").next().unwrap_or(l).to_string())
            .collect();
        self.err(
            self.header_line,
            0,
            &missing[0],
            format!(
                "required column is missing (see measured-data.md, {kind}): {} missing; the \
                 file's columns: {} (a channel map, --map FILE, names the file's columns \
                 for the spec's)",
                missing.join(", "),
                super::map::list_names(&names)
            ),
        )
    }

    /// Fails on a file without data rows.
    pub(crate) fn require_rows(&self) -> Result<(), MeasuredError> {
        if self.lines.is_empty() {
            return Err(self.err(self.header_line, 0, "", "no data rows"));
        }
        Ok(())
    }

    /// Takes a numeric column out of the table (moved, not copied).
    pub(crate) fn numeric(&mut self, idx: usize) -> Vec<f64> {
        match std::mem::replace(&mut self.columns[idx], Cells::Ignored) {
            Cells::Numeric(v, _) => v,
            other => {
                self.columns[idx] = other;
                Vec::new()
            }
        }
    }

    /// Takes a text column out of the table.
    pub(crate) fn text(&mut self, idx: usize) -> Option<TextColumn> {
        match std::mem::replace(&mut self.columns[idx], Cells::Ignored) {
            Cells::Text(t) => Some(t),
            other => {
                self.columns[idx] = other;
                None
            }
        }
    }
}

/// The byte-order mark some editors write before the first line.
const BOM: &str = "\u{feff}";

/// Reads the metadata lines before the header; returns them, the header line's text and
/// its 1-based line number. Blank lines there are allowed; a BOM before the first line is
/// dropped (it is not part of the text).
fn read_preamble<R: BufRead>(
    path: &Path,
    input: &mut R,
) -> Result<(Vec<(String, String)>, String, usize), MeasuredError> {
    let mut metadata = Vec::new();
    let mut buf = Vec::new();
    let mut line_no = 0usize;
    loop {
        buf.clear();
        let n = input
            .read_until(b'\n', &mut buf)
            .map_err(|e| file_error(path, format!("cannot read: {e}")))?;
        line_no += 1;
        if n == 0 {
            return Err(MeasuredError {
                line: line_no,
                ..file_error(path, "no header row")
            });
        }
        let text = std::str::from_utf8(&buf).map_err(|e| MeasuredError {
            line: line_no,
            ..file_error(path, format!("not UTF-8 text: {e}"))
        })?;
        let text = if line_no == 1 {
            text.strip_prefix(BOM).unwrap_or(text)
        } else {
            text
        };
        let trimmed = text.trim();
        if let Some(rest) = trimmed.strip_prefix('#') {
            let rest = rest.trim();
            if rest.is_empty() {
                continue;
            }
            match rest.split_once(':') {
                Some((k, v)) => metadata.push((k.trim().to_string(), v.trim().to_string())),
                // A comment without a key: kept as a free note.
                None => metadata.push(("comment".to_string(), rest.to_string())),
            }
        } else if !trimmed.is_empty() {
            return Ok((metadata, text.to_string(), line_no));
        }
    }
}

/// Checks the header's names (none empty, none twice).
fn check_header(path: &Path, header: &[String], line: usize) -> Result<(), MeasuredError> {
    let err = |column: &str, message: String| MeasuredError {
        line,
        column: column.to_string(),
        ..file_error(path, message)
    };
    for (i, h) in header.iter().enumerate() {
        if h.is_empty() {
            return Err(err("", format!("column {} has an empty name", i + 1)));
        }
        if header[..i].contains(h) {
            return Err(err(h, "column appears twice".into()));
        }
    }
    Ok(())
}

/// The file's kind from its header (`v_friction_mps`: friction test; `v_ref_mps` or
/// `omega1_radps`: run log), or the error.
pub(crate) fn kind_of(path: &Path, header: &[String], line: usize) -> Result<Kind, MeasuredError> {
    let has = |c: ColumnName| header.iter().any(|h| *h == c.to_string());
    if has(ft::V_FRICTION.name(0)) {
        Ok(Kind::Friction)
    } else if has(rl::V_REF.name(0)) || has(rl::OMEGA.name(0)) {
        Ok(Kind::Run)
    } else {
        Err(MeasuredError {
            line,
            ..file_error(
                path,
                format!(
                    "neither a run log (needs `t_s`, `v_ref_mps`, `omega1_radps`..) nor a \
                     friction test (needs `v_friction_mps`, `t_disc_c`, `mu` or `f_clamp_n` + \
                     `f_friction_n`); the file's columns: {} (a channel map, --map FILE, names \
                     the file's columns for the spec's)",
                    super::map::list_names(header)
                ),
            )
        })
    }
}

/// How each column of a file of `kind` is read.
fn cells_of(kind: Kind, header: &[String]) -> Vec<Cells> {
    let limits: &[Limit] = match kind {
        Kind::Run => &limits::RUN_LOG,
        Kind::Friction => &limits::FRICTION_TEST,
    };
    header
        .iter()
        .map(|h| {
            if kind == Kind::Run && *h == rl::CMD.name(0).to_string() {
                Cells::Text(TextColumn::default())
            } else {
                match limits::find(limits, h) {
                    Some(l) => Cells::Numeric(Vec::new(), l),
                    None => Cells::Ignored,
                }
            }
        })
        .collect()
}

/// Reads a measured file's table from a stream: metadata, header, then row by row into
/// typed columns (no `String` per cell). Every numeric cell is checked as it is read: a
/// number, finite, within its column's plausible range ([`limits`]); the time column has
/// no empty cell, increases strictly and spans at most [`limits::MAX_SPAN_S`].
pub(crate) fn read_table<R: BufRead>(
    path: &Path,
    input: R,
    map: Option<&ChannelMap>,
) -> Result<Table, MeasuredError> {
    read_table_chunks(path, input, map, usize::MAX, |_| Ok(()))
}

/// [`read_table`] in chunks of `chunk_rows` rows, for files too large to hold: each full
/// chunk is handed to `each` (the table holding those rows only; row numbers in errors
/// count from the file's first row), then dropped; the table returned holds the last,
/// partial chunk. Memory is bounded by the chunk, whatever the file's length.
pub(crate) fn read_table_chunks<R: BufRead>(
    path: &Path,
    mut input: R,
    map: Option<&ChannelMap>,
    chunk_rows: usize,
    mut each: impl FnMut(&mut Table) -> Result<(), MeasuredError>,
) -> Result<Table, MeasuredError> {
    let (metadata, header_text, header_line) = read_preamble(path, &mut input)?;
    let mut reader = csv::ReaderBuilder::new()
        .has_headers(true)
        .flexible(false)
        .trim(csv::Trim::All)
        .from_reader(std::io::Cursor::new(header_text.into_bytes()).chain(input));
    let header: Vec<String> = reader
        .headers()
        .map_err(|e| MeasuredError {
            line: header_line,
            ..file_error(path, format!("cannot read the header row: {e}"))
        })?
        .iter()
        .map(|h| h.trim().to_string())
        .collect();
    check_header(path, &header, header_line)?;
    let resolved = resolve(map, path, &header, &[]).map_err(|e| MeasuredError {
        line: header_line,
        ..e
    })?;
    let mut table = Table::new(path, Metadata(metadata), resolved, header_line)?;
    let time = table.column(&rl::T.name(0).to_string());
    let mut record = csv::ByteRecord::new();
    let mut t_first = None;
    loop {
        if table.lines.len() >= chunk_rows {
            table.hand_on(time, &mut each)?;
        }
        let r = table.lines.len();
        let more = reader.read_byte_record(&mut record).map_err(|e| {
            let line = e
                .position()
                .map_or(0, |p| p.line() as usize + header_line - 1);
            let row = table.rows_before + r + 1;
            table.err(line, row, "", format!("malformed CSV row: {e}"))
        })?;
        if !more {
            break;
        }
        let line = record
            .position()
            .map_or(0, |p| p.line() as usize + header_line - 1);
        table.lines.push(line as u32);
        for (idx, raw) in record.iter().enumerate() {
            table.push_cell(r, idx, raw)?;
        }
        if let Some(i) = time {
            table.check_time(r, i, &mut t_first)?;
        }
    }
    Ok(table)
}

impl Table {
    /// An empty table of the `resolved` columns (its kind from their spec names).
    pub(crate) fn new(
        path: &Path,
        metadata: Metadata,
        resolved: Vec<Resolved>,
        header_line: usize,
    ) -> Result<Table, MeasuredError> {
        let header: Vec<String> = resolved.iter().map(|r| r.target.clone()).collect();
        let kind = kind_of(path, &header, header_line)?;
        Ok(Table {
            path: path.to_path_buf(),
            metadata,
            columns: cells_of(kind, &header),
            header,
            header_line,
            kind,
            to_si: resolved.iter().map(|r| r.to_si).collect(),
            labels: resolved.iter().map(Resolved::label).collect(),
            units: resolved.into_iter().map(|r| r.unit).collect(),
            lines: Vec::new(),
            notes: Vec::new(),
            rows_before: 0,
            time_before: None,
        })
    }

    /// Checks value `x` (SI) of data row `r` in column `idx`: finite, within its limit.
    pub(crate) fn check_value(
        &self,
        r: usize,
        idx: usize,
        x: f64,
        limit: Limit,
    ) -> Result<(), MeasuredError> {
        if !x.is_finite() {
            return Err(self.row_err(r, idx, format!("{x} is not finite")));
        }
        if !limit.contains(x) {
            let from = match self.units[idx].as_str() {
                "" => String::new(),
                u => format!(" (converted from {u})"),
            };
            let msg = format!(
                "{x}{from} is outside the plausible range [{}, {}] ({}; docs/measured-data-limits.md)",
                limit.min, limit.max, limit.basis
            );
            return Err(self.row_err(r, idx, msg));
        }
        Ok(())
    }

    /// Hands the rows held (a chunk) to `each`, then drops them, keeping what the checks
    /// of the next rows need: the row count and the last time (`time`: the time column),
    /// read before `each`, which may take the columns.
    pub(crate) fn hand_on(
        &mut self,
        time: Option<usize>,
        each: &mut impl FnMut(&mut Table) -> Result<(), MeasuredError>,
    ) -> Result<(), MeasuredError> {
        let last = match time.map(|i| &self.columns[i]) {
            Some(Cells::Numeric(t, _)) => t.last().copied(),
            _ => None,
        };
        each(self)?;
        self.time_before = last.or(self.time_before);
        self.rows_before += self.lines.len();
        self.lines.clear();
        // Fresh columns: the chunk's were taken (moved out) by the caller.
        self.columns = cells_of(self.kind, &self.header);
        Ok(())
    }

    /// Reads one cell of data row `r` (0-based) into its column, checking it.
    fn push_cell(&mut self, r: usize, idx: usize, raw: &[u8]) -> Result<(), MeasuredError> {
        let cell = match std::str::from_utf8(raw) {
            Ok(c) => c,
            Err(_) => return Err(self.row_err(r, idx, "cell is not UTF-8 text")),
        };
        let (x, limit) = match &mut self.columns[idx] {
            Cells::Ignored => return Ok(()),
            Cells::Text(t) => {
                if t.values.len() >= MAX_DISTINCT_TEXTS && !t.values.iter().any(|v| v == cell) {
                    let msg = format!("more than {MAX_DISTINCT_TEXTS} distinct texts");
                    return Err(self.row_err(r, idx, msg));
                }
                t.push(cell);
                return Ok(());
            }
            Cells::Numeric(v, limit) => {
                if cell.is_empty() {
                    v.push(f64::NAN);
                    return Ok(());
                }
                (cell.parse::<f64>(), *limit)
            }
        };
        let x = match x {
            Ok(x) if x.is_finite() => self.to_si[idx].apply(x),
            Ok(x) => return Err(self.row_err(r, idx, format!("`{cell}` is not finite ({x})"))),
            Err(_) => return Err(self.row_err(r, idx, format!("`{cell}` is not a number"))),
        };
        self.check_value(r, idx, x, limit)?;
        if let Cells::Numeric(v, _) = &mut self.columns[idx] {
            v.push(x);
        }
        Ok(())
    }

    /// The time of row `r`: measured, above the previous row's, within the span limit.
    pub(crate) fn check_time(
        &self,
        r: usize,
        idx: usize,
        first: &mut Option<f64>,
    ) -> Result<(), MeasuredError> {
        let Cells::Numeric(t, _) = &self.columns[idx] else {
            return Ok(());
        };
        let now = t[r];
        if now.is_nan() {
            return Err(self.row_err(r, idx, "empty cell in a required column"));
        }
        let before = if r > 0 {
            Some(t[r - 1])
        } else {
            self.time_before
        };
        if let Some(before) = before.filter(|&b| !(now > b)) {
            let msg = format!("time does not increase ({now} after {before})");
            return Err(self.row_err(r, idx, msg));
        }
        let t0 = *first.get_or_insert(now);
        if now - t0 > limits::MAX_SPAN_S {
            let msg = format!(
                "the log spans {} s from its first row; at most {} s is plausible \
                 (milliseconds logged as seconds?)",
                now - t0,
                limits::MAX_SPAN_S
            );
            return Err(self.row_err(r, idx, msg));
        }
        Ok(())
    }
}

/// An error about a whole file (no line, row or column).
pub(crate) fn file_error(path: &Path, message: impl Into<String>) -> MeasuredError {
    MeasuredError {
        file: path.to_path_buf(),
        line: 0,
        row: 0,
        column: String::new(),
        message: message.into(),
    }
}
