//! # hils-fmu-check: the packed FMU checked from outside
//!
//! * [`paper_run`]: `hils simulate`'s paper run (tools/src/scenario.rs `run_eb`) with every
//!   plant step recorded: the reference the FMU must equal bit for bit;
//! * [`expected`]: what that record says an FMU output is, by the output's name (the names
//!   of the run-log spec, written out here);
//! * [`description`]: the model description read back from the FMU (names, value
//!   references, types), independently of the FMU's own tables;
//! * [`direct`]: a direct Rust import of the FMU's shared library (dlopen, the FMI 3.0 C
//!   functions by name), as a co-simulation master would.
//!
//! The binary (`src/main.rs`) runs the checks and the speed figures; `scripts/fmu-check.sh`
//! and `scripts/fmu-bench.sh` call it with FMPy beside it.
#![allow(missing_docs)]

pub mod description;
pub mod direct;

use anyhow::{Result, anyhow};
use hils::scenario::{EbOptions, Run, run_eb};
use hils_sil::{ParamFile, RunRecord};

/// `hils simulate`'s paper run of `file` (f32), every plant step recorded
/// (`samples[k]` after step k, `samples[0]` the initial state).
pub fn paper_run(file: &ParamFile) -> Result<Run> {
    let mut opts = EbOptions::paper(file);
    opts.record_every = 1;
    run_eb::<f32>(file, &opts).map_err(|e| anyhow!("the paper run: {e}"))
}

/// The outputs a plant driven by its brake inputs does not model (the brake unit's).
pub const UNIT_OUTPUTS: [&str; 3] = ["p_cyl_unit", "wsp", "v_ref_est"];

/// The record's scalar outputs, by the FMU's output names (the run-log spec's).
const SCALARS: [&str; 4] = ["v_ref_mps", "x_m", "a_x_mps2", "v_ref_est_mps"];

/// The record's per-wheelset outputs: name stem and unit suffix (the run-log spec's names,
/// with `f_clamp_act` and `p_cyl_unit` for the outputs whose run-log names are inputs of
/// the FMU).
const PER_WHEELSET: [(&str, &str); 10] = [
    ("omega", "_radps"),
    ("q", "_n"),
    ("mu_d", ""),
    ("f_brake", "_n"),
    ("t_disc", "_c"),
    ("creepage", ""),
    ("adhesion", ""),
    ("f_clamp_act", "_n"),
    ("p_cyl_unit", "_pa"),
    ("wsp", ""),
];

/// The names of [`values`], in order.
pub fn names() -> Vec<String> {
    let mut names: Vec<String> = SCALARS.iter().map(|s| s.to_string()).collect();
    for (stem, unit) in PER_WHEELSET {
        names.extend((1..=4).map(|j| format!("{stem}{j}{unit}")));
    }
    names
}

/// What a record says each output of [`names`] is (written out field by field here, not
/// through the record's own channel lookup).
pub fn values(s: &RunRecord) -> Vec<f64> {
    let wsp = s.wsp.map(|w| if w { 1.0 } else { 0.0 });
    let per_wheelset: [&[f64; 4]; 10] = [
        &s.omega_radps,
        &s.q_n,
        &s.mu_d,
        &s.f_brake_n,
        &s.t_disc_c,
        &s.creepage,
        &s.adhesion,
        &s.f_clamp_n,
        &s.p_cyl_pa,
        &wsp,
    ];
    let mut v = vec![s.v_ref_mps, s.x_m, s.a_x_mps2, s.v_ref_est_mps];
    for w in per_wheelset {
        v.extend_from_slice(w);
    }
    v
}

/// The index in [`names`] of each of the FMU's outputs; an output the record does not hold
/// is an error (every output is compared).
pub fn columns(outputs: &[String]) -> Result<Vec<usize>> {
    let names = names();
    outputs
        .iter()
        .map(|o| {
            names.iter().position(|n| n == o).ok_or_else(|| {
                anyhow!("the FMU's output {o} has no value in hils simulate's record")
            })
        })
        .collect()
}

/// The first output whose value differs from the record's (bit for bit), as a message;
/// `columns` from [`columns`] for `outputs`, `skip` outputs the mode does not model.
pub fn first_difference(
    record: &RunRecord,
    outputs: &[String],
    columns: &[usize],
    values_got: &[f64],
    skip: &[&str],
    step: usize,
) -> Option<String> {
    let want = values(record);
    outputs
        .iter()
        .zip(columns)
        .zip(values_got)
        .filter(|((name, _), _)| !skip.iter().any(|p| name.starts_with(p)))
        .find_map(|((name, &c), got)| {
            (got.to_bits() != want[c].to_bits()).then(|| {
                format!(
                    "{name} at step {step} (t = {} s): FMU {got}, hils simulate {}",
                    record.t_s, want[c]
                )
            })
        })
}
