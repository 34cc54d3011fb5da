//! Stage 4: the same scenario on the host in f32, compared bit for bit with the target's
//! trajectory, and checked against what `hils simulate` records.

use anyhow::{Result, anyhow, bail};
use hils_plant::{FrictionModel, WHEELSETS};
use hils_sil::record::run_log;
use hils_sil::trace::{self, RECORD_EVERY};
use hils_sil::{EbScenario, ParamFile, TraceRow};
use serde::Serialize;

use crate::scenario::{EbOptions, run_eb};

/// The trajectory of the emulator's scenario computed on the host in f32, with the same
/// driver and row format, and the host run's step count and stop step.
pub fn host_trace(friction: FrictionModel) -> Result<(Vec<TraceRow>, u32, Option<u32>)> {
    let mut sc = EbScenario::<f32>::paper(friction, RECORD_EVERY).map_err(|e| anyhow!("{e}"))?;
    let mut rows = vec![TraceRow::of(&sc.sim)];
    loop {
        let adv = sc.advance(|sim| {
            sim.step();
        });
        if adv.record {
            rows.push(TraceRow::of(&sc.sim));
        }
        if adv.done {
            break;
        }
    }
    Ok((rows, sc.steps(), sc.stop_step()))
}

/// Names of the values of a [`TraceRow`]: `step`, `flags`, `valves`, then the columns
/// (run-record channel names, [`trace::columns`]).
pub fn column_names() -> Vec<String> {
    let mut names = vec!["step".to_string(), "flags".into(), "valves".into()];
    names.extend(trace::columns().map(|(c, j)| c.name(j).to_string()));
    names
}

/// The first difference between two trajectories.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Mismatch {
    pub row: usize,
    pub step: u32,
    pub column: String,
    pub target_bits: u32,
    pub host_bits: u32,
}

/// Result of the bit-for-bit comparison of one friction model's trajectories.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Comparison {
    pub friction: String,
    pub identical: bool,
    pub rows_target: usize,
    pub rows_host: usize,
    /// Values compared (rows x words).
    pub values_compared: usize,
    /// Values that differ.
    pub values_different: usize,
    pub first_mismatch: Option<Mismatch>,
}

/// Compares every word (step, flags, valves, every f32 bit pattern) of every row. The
/// trajectories are identical only if they also have the same number of rows.
pub fn compare(friction: &str, target: &[TraceRow], host: &[TraceRow]) -> Comparison {
    let names = column_names();
    let words = |r: &TraceRow| {
        let mut w = vec![r.step, r.flags, r.valves];
        w.extend_from_slice(&r.values);
        w
    };
    let mut values_compared = 0;
    let mut values_different = 0;
    let mut first_mismatch = None;
    for (i, (t, h)) in target.iter().zip(host).enumerate() {
        for (k, (a, b)) in words(t).into_iter().zip(words(h)).enumerate() {
            values_compared += 1;
            if a != b {
                values_different += 1;
                first_mismatch.get_or_insert(Mismatch {
                    row: i,
                    step: h.step,
                    column: names[k].clone(),
                    target_bits: a,
                    host_bits: b,
                });
            }
        }
    }
    Comparison {
        friction: friction.to_string(),
        identical: values_different == 0 && target.len() == host.len() && !host.is_empty(),
        rows_target: target.len(),
        rows_host: host.len(),
        values_compared,
        values_different,
        first_mismatch,
    }
}

/// Checks the host trajectory against what `hils simulate` records for the same run
/// (`run_eb::<f32>` sampled every [`RECORD_EVERY`] steps): the same samples, every
/// shared value equal (f32 to f64 and back is exact). Returns the number of values checked.
pub fn check_against_simulate(friction: FrictionModel, rows: &[TraceRow]) -> Result<usize> {
    let mut file = ParamFile::default();
    file.plant.friction.model = friction;
    let mut opts = EbOptions::paper(&file);
    opts.record_every = RECORD_EVERY;
    let run = run_eb::<f32>(&file, &opts)?;
    if run.samples.len() != rows.len() {
        bail!(
            "hils simulate records {} samples, the emulator scenario {}",
            run.samples.len(),
            rows.len()
        );
    }
    let mut checked = 0;
    for (i, (s, r)) in run.samples.iter().zip(rows).enumerate() {
        let mut same = |what: &dyn std::fmt::Display, sim: f64, row: f32| -> Result<()> {
            checked += 1;
            if sim as f32 != row || (sim.is_nan() != row.is_nan()) {
                bail!("sample {i}: {what} is {sim} in hils simulate but {row} in the trace");
            }
            Ok(())
        };
        // Every trace column the record holds, by channel (the trace's own have no value
        // in the record); the record's WSP is the trace's valve bits.
        for (k, (c, j)) in trace::columns().enumerate() {
            if let Some(sim) = s.value(c, j) {
                same(&c.name(j), sim, r.value(k))?;
            }
        }
        for j in 0..WHEELSETS {
            let sim = s.wsp[j] as u8 as f64;
            same(&run_log::WSP.name(j), sim, r.venting(j) as u8 as f32)?;
        }
    }
    // Every trace column that is a run-log channel must have been compared: a channel the
    // record fails to give (`RunRecord::value` -> None) is an error, not a skipped column.
    let per_row = trace::columns()
        .filter(|(c, _)| run_log::ALL.contains(c))
        .count()
        + WHEELSETS;
    if checked != rows.len() * per_row {
        bail!(
            "compared {checked} values, expected {} ({} rows x {per_row} run-log columns)",
            rows.len() * per_row,
            rows.len()
        );
    }
    Ok(checked)
}
