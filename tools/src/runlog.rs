//! The run-log format (`spec/measured-data.md`, section 1) as written: `# key: value`
//! metadata lines, one header row, one row per sample. Column names come from the one
//! schema, `hils_sil::record` (names, units, order); every writer (`hils simulate`,
//! `hils decode`, the diagnosis generator) goes through [`write_table`], and the reader
//! (`crate::measured`) names its columns through the same schema.
//!
//! A simulated log ([`write_run_log`]) has the spec's columns (all optional ones filled)
//! and `mu_d1..4`, `creepage1..4`, `adhesion1..4`, `x_m` (distance) and `v_ref_est_mps`
//! (the brake unit's reference speed).

use std::io::Write;

use anyhow::Result;
use hils_sil::RunRecord;
use hils_sil::record::Channel;
use hils_sil::record::run_log::*;

/// The channels of a simulated run log, in order.
pub const SIMULATED: [Channel; 16] = [
    T, V_REF, OMEGA, P_CYL, F_CLAMP, F_BRAKE, T_DISC, Q, WSP, A_X, CMD, MU_D, CREEPAGE, ADHESION,
    X, V_REF_EST,
];

/// The column names of `channels`, in order (per-wheelset channels give four).
pub fn column_names(channels: &[Channel]) -> Vec<String> {
    channels
        .iter()
        .flat_map(|c| (0..c.width()).map(move |j| c.name(j).to_string()))
        .collect()
}

/// Column names of a simulated run log, in order.
pub fn columns() -> Vec<String> {
    column_names(&SIMULATED)
}

/// Writes `# key: value` metadata, the header row and the rows (cells as text).
pub fn write_table<W: Write>(
    out: W,
    metadata: &[(&str, String)],
    header: &[String],
    rows: impl IntoIterator<Item = Vec<String>>,
) -> Result<()> {
    let mut out = std::io::BufWriter::new(out);
    for (k, v) in metadata {
        writeln!(out, "# {k}: {v}")?;
    }
    let mut w = csv::WriterBuilder::new().from_writer(out);
    w.write_record(header)?;
    for row in rows {
        w.write_record(&row)?;
    }
    w.flush()?;
    Ok(())
}

/// The decimals of each channel in a simulated log.
fn decimals(c: Channel) -> usize {
    match c {
        T | OMEGA | A_X | MU_D | ADHESION => 6,
        V_REF | V_REF_EST | CREEPAGE => 7,
        P_CYL | Q => 1,
        F_CLAMP | F_BRAKE => 2,
        T_DISC | X => 4,
        _ => 6,
    }
}

/// The cell of channel `c`, wheelset `j`, of a simulated sample.
fn cell(s: &RunRecord, c: Channel, j: usize) -> String {
    let x = match c {
        T => s.t_s,
        V_REF => s.v_ref_mps,
        OMEGA => s.omega_radps[j],
        P_CYL => s.p_cyl_pa[j],
        F_CLAMP => s.f_clamp_n[j],
        F_BRAKE => s.f_brake_n[j],
        T_DISC => s.t_disc_c[j],
        Q => s.q_n[j],
        WSP => return if s.wsp[j] { "1" } else { "0" }.to_string(),
        A_X => s.a_x_mps2,
        CMD => return s.cmd.text().to_string(),
        MU_D => s.mu_d[j],
        CREEPAGE => s.creepage[j],
        ADHESION => s.adhesion[j],
        X => s.x_m,
        V_REF_EST => s.v_ref_est_mps,
        _ => return String::new(),
    };
    format!("{x:.*}", decimals(c))
}

/// Writes a simulated run log: `# key: value` metadata, the header and the samples.
pub fn write_run_log<W: Write>(
    out: W,
    metadata: &[(&str, String)],
    samples: &[RunRecord],
) -> Result<()> {
    let rows = samples.iter().map(|s| {
        SIMULATED
            .iter()
            .flat_map(|&c| (0..c.width()).map(move |j| cell(s, c, j)))
            .collect()
    });
    write_table(out, metadata, &columns(), rows)
}
