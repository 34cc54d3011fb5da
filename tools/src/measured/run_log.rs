//! Stage 2 of reading, section 1 of the spec: a braking run's log.

use std::collections::BTreeMap;
use std::path::PathBuf;

use hils_plant::{Rail, WHEELSETS};
use hils_sil::record::Channel;
use hils_sil::record::run_log::{
    A_X, CMD, F_BRAKE, F_CLAMP, HOLD, OMEGA, P_CYL, Q, T, T_DISC, V_REF, WSP,
};

use super::table::{MeasuredError, Metadata, Table, TextColumn};

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
    /// WSP hold valve coil energised (`hold1..4`, rig logs).
    pub hold: PerWheelset,
    pub a_x_mps2: Option<Vec<f64>>,
    /// The `cmd` column's texts (interned: one copy of each distinct text).
    pub cmd: Option<TextColumn>,
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

/// The spec section the run-log errors name.
const KIND: &str = "run log";

/// The optional per-wheelset channels, in the order of the schema.
const OPTIONAL: [Channel; 7] = [P_CYL, F_CLAMP, F_BRAKE, T_DISC, Q, WSP, HOLD];

/// The columns taken so far and their empty-cell counts.
struct Taken {
    table: Table,
    used: Vec<bool>,
    missing: BTreeMap<String, usize>,
}

impl Taken {
    fn new(table: Table) -> Self {
        Self {
            used: vec![false; table.header.len()],
            table,
            missing: BTreeMap::new(),
        }
    }

    /// A numeric column, moved out of the table, marked used, its empty cells counted.
    fn take(&mut self, idx: usize) -> Vec<f64> {
        self.used[idx] = true;
        let v = self.table.numeric(idx);
        let n = v.iter().filter(|x| x.is_nan()).count();
        if n > 0 {
            self.missing.insert(self.table.header[idx].clone(), n);
        }
        v
    }

    /// A required column of the run log.
    fn required(&mut self, c: Channel, j: usize) -> Result<Vec<f64>, MeasuredError> {
        let i = self.table.required(c.name(j), KIND)?;
        Ok(self.take(i))
    }

    /// The four columns of an optional per-wheelset channel (those present).
    fn per_wheelset(&mut self, c: Channel) -> PerWheelset {
        let mut out: PerWheelset = Default::default();
        for (j, slot) in out.iter_mut().enumerate() {
            if let Some(i) = self.table.index(c.name(j)) {
                *slot = Some(self.take(i));
            }
        }
        out
    }

    /// The columns nobody took, by name.
    fn unknown(&self) -> Vec<String> {
        self.table
            .header
            .iter()
            .zip(&self.used)
            .filter(|(_, u)| !**u)
            .map(|(h, _)| h.clone())
            .collect()
    }
}

/// Every wheelset needs a brake input (its clamp force or its cylinder pressure); WSP
/// valve flags (`wsp`, `hold`) are 0/1.
fn check_inputs(
    table: &Table,
    p_cyl: &PerWheelset,
    f_clamp: &PerWheelset,
    valves: [(Channel, &PerWheelset); 2],
) -> Result<(), MeasuredError> {
    for j in 0..WHEELSETS {
        if p_cyl[j].is_none() && f_clamp[j].is_none() {
            return Err(table.err(
                table.header_line,
                0,
                &format!("{} or {}", P_CYL.name(j), F_CLAMP.name(j)),
                "required column is missing: wheelset's brake input (cylinder pressure or clamp force)",
            ));
        }
    }
    for (channel, flags) in valves {
        for j in 0..WHEELSETS {
            if let Some(w) = &flags[j] {
                if let Some(r) = w
                    .iter()
                    .position(|&x| !(x.is_nan() || x == 0.0 || x == 1.0))
                {
                    let idx = table.index(channel.name(j)).unwrap_or(0);
                    return Err(table.row_err(r, idx, format!("`{}` is not 0 or 1", w[r])));
                }
            }
        }
    }
    Ok(())
}

/// The `rail` metadata (None when absent; an error when neither wet nor dry).
fn rail_of(table: &Table) -> Result<Option<Rail>, MeasuredError> {
    match table.metadata.get("rail") {
        None => Ok(None),
        Some(r) => match r.trim().to_ascii_lowercase().as_str() {
            "wet" => Ok(Some(Rail::Wet)),
            "dry" => Ok(Some(Rail::Dry)),
            other => Err(table.err(
                0,
                0,
                "",
                format!("metadata `rail: {other}`: must be `wet` or `dry`"),
            )),
        },
    }
}

/// Every required quantity the table lacks, named at once with the file's columns.
fn check_required(table: &Table) -> Result<(), MeasuredError> {
    let mut missing: Vec<String> = Vec::new();
    let mut need = |name: String| {
        if table.column(&name).is_none() {
            missing.push(name);
        }
    };
    need(T.name(0).to_string());
    need(V_REF.name(0).to_string());
    for j in 0..WHEELSETS {
        need(OMEGA.name(j).to_string());
    }
    for j in 0..WHEELSETS {
        if table.index(P_CYL.name(j)).is_none() && table.index(F_CLAMP.name(j)).is_none() {
            missing.push(format!("{} or {}", P_CYL.name(j), F_CLAMP.name(j)));
        }
    }
    if missing.is_empty() {
        return Ok(());
    }
    Err(table.missing_err(&missing, KIND))
}

/// A run log from its table (every cell already checked against its column's limits).
pub(crate) fn from_table(table: Table) -> Result<RunLog, MeasuredError> {
    check_required(&table)?;
    table.require_rows()?;
    let rail = rail_of(&table)?;
    let path = table.path.clone();
    table.metadata.number("initial_speed_kmh", &path)?;
    table.metadata.number("eb_command_s", &path)?;
    let mut taken = Taken::new(table);
    let t_s = taken.required(T, 0)?;
    let v_ref_mps = taken.required(V_REF, 0)?;
    let mut omega: [Vec<f64>; WHEELSETS] = Default::default();
    for (j, slot) in omega.iter_mut().enumerate() {
        *slot = taken.required(OMEGA, j)?;
    }
    let [p_cyl_pa, f_clamp_n, f_brake_n, t_disc_c, q_n, wsp, hold] =
        OPTIONAL.map(|c| taken.per_wheelset(c));
    check_inputs(
        &taken.table,
        &p_cyl_pa,
        &f_clamp_n,
        [(WSP, &wsp), (HOLD, &hold)],
    )?;
    let a_x_mps2 = match taken.table.index(A_X.name(0)) {
        Some(i) => Some(taken.take(i)),
        None => None,
    };
    let cmd = match taken.table.index(CMD.name(0)) {
        Some(i) => {
            taken.used[i] = true;
            taken.table.text(i)
        }
        None => None,
    };
    let unknown_columns = taken.unknown();
    let missing = taken.missing;
    let mut notes: Vec<String> = std::mem::take(&mut taken.table.notes);
    notes.extend(missing.iter().map(|(col, n)| {
        format!("{col}: {n} empty cell(s) (not measured at those samples; left out, not invented)")
    }));
    Ok(RunLog {
        path,
        metadata: taken.table.metadata,
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
        hold,
        a_x_mps2,
        cmd,
        unknown_columns,
        missing,
        notes,
    })
}
