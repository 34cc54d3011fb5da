//! Stage 2 of reading, section 2 of the spec: a brake-dynamometer friction test.

use std::path::PathBuf;

use hils_sil::record::friction_test::{F_CLAMP, F_FRICTION, MU, T, T_DISC, V_FRICTION};

use super::table::{MeasuredError, Metadata, Table};

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
    /// Points kept (`mu.len()`, or counted when streamed: [`stream_friction_test`]).
    pub points: usize,
}

/// Rows of a time series with a clamp force below this share of the file's largest clamp
/// force are brake-released samples: mu is undefined there, they are skipped (counted).
pub const RELEASED_SHARE: f64 = 0.05;

/// Where a friction test's mu comes from: its own column, or friction over clamp force.
enum MuSource {
    Direct(Vec<f64>),
    Forces(Vec<f64>, Vec<f64>),
}

/// mu of one row: a value (NaN: a needed cell is empty), or the brake released.
enum RowMu {
    Value(f64),
    Released,
}

/// A friction test from its table (every cell already checked against its column's
/// limits; the time, when present, measured and increasing).
pub(crate) fn from_table(mut table: Table) -> Result<FrictionTest, MeasuredError> {
    table.require_rows()?;
    let clamp_max = clamp_max_of(&table);
    let (mut out, counts) = points_of(&mut table, clamp_max)?;
    counts.finish(&mut out, &table)?;
    Ok(out)
}

/// Rows of a friction test skipped, by cause.
#[derive(Clone, Copy, Debug, Default)]
struct Skipped {
    /// A needed cell empty (not measured).
    empty: usize,
    /// Brake released (clamp force below [`RELEASED_SHARE`] of the largest).
    released: usize,
}

impl Skipped {
    /// The notes and the count of skipped rows; an error when no row gave a point.
    fn finish(self, out: &mut FrictionTest, table: &Table) -> Result<(), MeasuredError> {
        out.notes.extend(skip_notes(self.empty, self.released));
        out.skipped = self.empty + self.released;
        if out.points == 0 {
            return Err(table.err(0, 0, "", "no usable friction points (every row skipped)"));
        }
        Ok(())
    }
}

/// The largest clamp force of the table when mu comes from the forces (0 otherwise).
fn clamp_max_of(table: &Table) -> f64 {
    if table.index(MU.name(0)).is_some() {
        return 0.0;
    }
    match table.index(F_CLAMP.name(0)).map(|i| &table.columns[i]) {
        Some(super::table::Cells::Numeric(c, _)) => c
            .iter()
            .filter(|x| x.is_finite())
            .fold(0.0f64, |m, &x| m.max(x)),
        _ => 0.0,
    }
}

/// The points of the rows the table holds (`clamp_max`: the file's largest clamp force,
/// for mu from the forces) and the rows skipped.
fn points_of(table: &mut Table, clamp_max: f64) -> Result<(FrictionTest, Skipped), MeasuredError> {
    let required = |t: &Table, c: hils_sil::record::Channel| t.required(c.name(0), "friction test");
    let mut used = vec![false; table.header.len()];
    let i_v = required(table, V_FRICTION)?;
    let i_t = required(table, T_DISC)?;
    used[i_v] = true;
    used[i_t] = true;
    let v = table.numeric(i_v);
    let temp = table.numeric(i_t);
    let time = table.index(T.name(0)).map(|i| {
        used[i] = true;
        table.numeric(i)
    });
    let source = mu_source(table, &mut used)?;
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
    let mut skipped = Skipped::default();
    for r in 0..table.rows() {
        let mu = match row_mu(table, &source, clamp_max, r)? {
            RowMu::Value(mu) => mu,
            RowMu::Released => {
                skipped.released += 1;
                continue;
            }
        };
        if mu.is_nan() || v[r].is_nan() || temp[r].is_nan() {
            skipped.empty += 1;
            continue;
        }
        out.v_friction_mps.push(v[r]);
        out.t_disc_c.push(temp[r]);
        out.mu.push(mu);
        out.rows.push(table.rows_before + r + 1);
        if let Some(t) = &time {
            kept_t.push(t[r]);
        }
    }
    out.notes.extend(std::mem::take(&mut table.notes));
    out.points = out.mu.len();
    if time.is_some() {
        out.t_s = Some(kept_t);
    }
    Ok((out, skipped))
}

/// Rows per chunk of [`stream_friction_test`].
pub const CHUNK_ROWS: usize = 1 << 16;

/// Reads a friction test in chunks of [`CHUNK_ROWS`] rows, for files too large to hold
/// (tens of millions of points): `each` gets each chunk's points (rows numbered from the
/// file's first), which are then dropped. The same checks and the same points as
/// [`super::read_friction_test`]; mu from the forces needs the file's largest clamp force
/// first, so such a file is read twice. `open` opens the input (once or twice). Columns
/// are named and units converted by the channel `map` (None: the spec's names). Returns the
/// file's description without points (metadata, notes, rows skipped, `points` counted).
pub fn stream_friction_test<R: std::io::BufRead>(
    path: &std::path::Path,
    map: Option<&super::ChannelMap>,
    mut open: impl FnMut() -> std::io::Result<R>,
    each: impl FnMut(&FrictionTest) -> Result<(), MeasuredError>,
) -> Result<FrictionTest, MeasuredError> {
    use super::table::{file_error, read_table_chunks};
    let read = |chunk: &mut ChunkFn| {
        let input = open().map_err(|e| file_error(path, format!("cannot read: {e}")))?;
        read_table_chunks(path, input, map, CHUNK_ROWS, chunk)
    };
    stream_chunks(path, map, read, each)
}

/// What a table reader hands each chunk of rows to.
pub(crate) type ChunkFn<'c> = dyn FnMut(&mut Table) -> Result<(), MeasuredError> + 'c;

/// [`stream_friction_test`] of a table reader of either format: `read` reads the file
/// once, handing each full chunk of [`CHUNK_ROWS`] rows to its argument and returning the
/// last (partial) chunk; it is called once, or twice for mu from the forces.
pub(crate) fn stream_chunks(
    path: &std::path::Path,
    map: Option<&super::ChannelMap>,
    mut read: impl FnMut(&mut ChunkFn) -> Result<Table, MeasuredError>,
    mut each: impl FnMut(&FrictionTest) -> Result<(), MeasuredError>,
) -> Result<FrictionTest, MeasuredError> {
    use super::table::{Kind, file_error};
    let (mut total, mut skipped) = (FrictionTest::default(), Skipped::default());
    let mut take = |t: &mut Table, clamp_max: f64| -> Result<(), MeasuredError> {
        let (chunk, s) = points_of(t, clamp_max)?;
        skipped.empty += s.empty;
        skipped.released += s.released;
        total.points += chunk.points;
        total.notes.extend(chunk.notes.iter().cloned());
        total.unknown_columns.clone_from(&chunk.unknown_columns);
        each(&chunk)
    };
    // First pass: the points when mu is a column; the largest clamp force when mu comes
    // from the forces (a second pass takes the points).
    let direct = |t: &Table| t.index(MU.name(0)).is_some();
    let clamp_max = std::cell::Cell::new(0.0f64);
    let mut first_pass = |t: &mut Table| -> Result<(), MeasuredError> {
        if t.kind != Kind::Friction {
            return Err(file_error(path, super::NOT_A_FRICTION_TEST));
        }
        if direct(t) {
            take(t, 0.0)
        } else {
            clamp_max.set(clamp_max.get().max(clamp_max_of(t)));
            Ok(())
        }
    };
    let mut last = read(&mut first_pass)?;
    first_pass(&mut last)?;
    if last.rows_before + last.rows() == 0 {
        return Err(last.err(last.header_line, 0, "", "no data rows"));
    }
    if !direct(&last) {
        let max = clamp_max.get();
        last = read(&mut |t| take(t, max))?;
        take(&mut last, max)?;
    }
    super::check_metadata(&mut last, map)?;
    total.path = last.path.clone();
    total.metadata = last.metadata.clone();
    skipped.finish(&mut total, &last)?;
    Ok(total)
}

/// The `mu` column, else both `f_clamp_n` and `f_friction_n` (marked used).
fn mu_source(table: &mut Table, used: &mut [bool]) -> Result<MuSource, MeasuredError> {
    if let Some(i) = table.index(MU.name(0)) {
        used[i] = true;
        return Ok(MuSource::Direct(table.numeric(i)));
    }
    let i_c = table.index(F_CLAMP.name(0));
    let i_f = table.index(F_FRICTION.name(0));
    match (i_c, i_f) {
        (Some(i_c), Some(i_f)) => {
            used[i_c] = true;
            used[i_f] = true;
            Ok(MuSource::Forces(table.numeric(i_c), table.numeric(i_f)))
        }
        _ => Err(table.err(
            table.header_line,
            0,
            "mu",
            "required column is missing: `mu`, or both `f_clamp_n` and `f_friction_n`",
        )),
    }
}

/// mu of row `r`; a clamp force below [`RELEASED_SHARE`] of `clamp_max` is the brake
/// released, a ratio outside [0, 2] an error naming the row.
fn row_mu(
    table: &Table,
    source: &MuSource,
    clamp_max: f64,
    r: usize,
) -> Result<RowMu, MeasuredError> {
    let (c, f) = match source {
        MuSource::Direct(mu) => return Ok(RowMu::Value(mu[r])),
        MuSource::Forces(c, f) => (c, f),
    };
    if c[r].is_nan() || f[r].is_nan() {
        return Ok(RowMu::Value(f64::NAN));
    }
    if c[r] < RELEASED_SHARE * clamp_max || c[r] <= 0.0 {
        return Ok(RowMu::Released);
    }
    let mu = f[r] / c[r];
    if !(0.0..=2.0).contains(&mu) {
        let i_f = table.index(F_FRICTION.name(0)).unwrap_or(0);
        return Err(table.row_err(
            r,
            i_f,
            format!("friction coefficient f_friction / f_clamp = {mu:.4} outside [0, 2]"),
        ));
    }
    Ok(RowMu::Value(mu))
}

/// The notes on the rows skipped: empty cells, brake released.
fn skip_notes(empty: usize, released: usize) -> Vec<String> {
    let mut notes = Vec::new();
    if empty > 0 {
        notes.push(format!(
            "{empty} row(s) skipped: a needed cell is empty (not measured)"
        ));
    }
    if released > 0 {
        notes.push(format!(
            "{released} row(s) skipped: brake released (clamp force below {:.0} % of the largest, mu undefined)",
            RELEASED_SHARE * 100.0
        ));
    }
    notes
}
