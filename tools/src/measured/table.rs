//! Stage 1 of reading: the CSV table (metadata lines, header, cells with their line
//! numbers), the error that names file, line, row and column, and the checks that both
//! formats share.

use std::fmt;
use std::path::{Path, PathBuf};

use hils_sil::record::ColumnName;

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
pub(crate) struct Table {
    pub(crate) path: PathBuf,
    pub(crate) metadata: Metadata,
    pub(crate) header: Vec<String>,
    pub(crate) header_line: usize,
    /// (line, cells)
    pub(crate) rows: Vec<(usize, Vec<String>)>,
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

    pub(crate) fn column(&self, name: &str) -> Option<usize> {
        self.header.iter().position(|h| h == name)
    }

    /// The index of a schema column.
    pub(crate) fn index(&self, name: ColumnName) -> Option<usize> {
        self.column(&name.to_string())
    }

    /// Whether the table has a schema column.
    pub(crate) fn has(&self, name: ColumnName) -> bool {
        self.index(name).is_some()
    }

    /// A required column of a file kind (`kind` names the spec section), or the error.
    pub(crate) fn required(&self, name: ColumnName, kind: &str) -> Result<usize, MeasuredError> {
        self.index(name).ok_or_else(|| {
            self.err(
                self.header_line,
                0,
                &name.to_string(),
                format!("required column is missing (see measured-data.md, {kind})"),
            )
        })
    }

    /// Fails on a file without data rows.
    pub(crate) fn require_rows(&self) -> Result<(), MeasuredError> {
        if self.rows.is_empty() {
            return Err(self.err(self.header_line, 0, "", "no data rows"));
        }
        Ok(())
    }

    /// A numeric column: empty cells -> NaN; other non-numbers and NaN/inf -> error.
    pub(crate) fn numeric(&self, idx: usize) -> Result<Vec<f64>, MeasuredError> {
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

pub(crate) fn parse_table(path: &Path, text: &str) -> Result<Table, MeasuredError> {
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

/// Every cell of a required column must be measured.
pub(crate) fn require_all(table: &Table, idx: usize, values: &[f64]) -> Result<(), MeasuredError> {
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
pub(crate) fn check_non_negative(
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

pub(crate) fn check_time(table: &Table, idx: usize, t: &[f64]) -> Result<(), MeasuredError> {
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
