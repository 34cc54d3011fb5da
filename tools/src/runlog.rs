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

/// The file format of a run log: the spec's CSV, or MDF4 (`.mf4`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Format {
    Csv,
    Mf4,
}

impl Format {
    /// The format of an output file by its extension (`.mf4`/`.mdf`: MDF4, else CSV).
    pub fn of_path(path: &std::path::Path) -> Format {
        match path.extension().and_then(|e| e.to_str()) {
            Some(e) if e.eq_ignore_ascii_case("mf4") || e.eq_ignore_ascii_case("mdf") => {
                Format::Mf4
            }
            _ => Format::Csv,
        }
    }

    /// The file extension.
    pub fn extension(self) -> &'static str {
        match self {
            Format::Csv => "csv",
            Format::Mf4 => "mf4",
        }
    }
}

/// The text columns of the schema (the others hold numbers).
const TEXT_CHANNELS: [Channel; 5] = [CMD, STATE, FAULTS, SENSOR_FAULTS, SURFACE];

/// What a schema channel holds, for a file that stores comments (MDF4).
pub fn comment(c: Channel) -> &'static str {
    match c {
        T => "time since the start of the log",
        V_REF => "true vehicle speed (radar or a non-braked reference)",
        OMEGA => "wheelset angular speed (wheelset 1 leads)",
        P_CYL => "brake cylinder pressure",
        F_CLAMP => "pad normal force per friction face",
        F_BRAKE => {
            "tangential friction force on the disc at the friction radius, summed over faces"
        }
        T_DISC => "disc temperature rise above ambient",
        Q => "wheelset (axle) load",
        WSP => "1 while the wheelset's WSP valve vents",
        A_X => "carbody longitudinal acceleration",
        CMD => "brake command in force (REL, EB, SB)",
        MU_D => "disc-pad friction coefficient (Eq 2)",
        CREEPAGE => "wheel-rail creepage",
        ADHESION => "adhesion coefficient used, F / Q",
        X => "distance run",
        V_REF_EST => "the brake unit's reference-speed estimate",
        STATE => "rig run state",
        FAULTS => "rig fault flags (hils_rig_core::rig::Faults bits)",
        SENSOR_FAULTS => "sensor fault codes, 4 bits per channel",
        STEP_MAX => "longest plant step since the last record",
        STEP_MEAN => "mean plant step since the last record",
        OVERRUNS => "step overruns since the run started",
        MISSED_TICKS => "missed ticks since the run started",
        SURFACE => "surface (zone) under the wheelset",
        MU_AVAIL => "available adhesion under the wheelset at v_ref",
        _ => "",
    }
}

/// Writes a run log in `format`: for CSV, [`write_table`]; for MDF4, the same columns
/// (same names, in order) with the schema's units and comments and the metadata as the
/// file's properties ([`crate::mdf4::write`]): numbers where the schema has numbers (an
/// empty cell: NaN, not measured), texts where it has texts. The first column is the time.
pub fn write_table_as<W: Write>(
    format: Format,
    out: W,
    metadata: &[(&str, String)],
    header: &[String],
    rows: impl IntoIterator<Item = Vec<String>>,
) -> Result<()> {
    match format {
        Format::Csv => write_table(out, metadata, header, rows),
        Format::Mf4 => write_mf4(out, metadata, header, rows),
    }
}

/// A column being collected for MDF4.
enum Collected {
    Num(Vec<f64>),
    Text(crate::measured::TextColumn),
}

fn write_mf4<W: Write>(
    out: W,
    metadata: &[(&str, String)],
    header: &[String],
    rows: impl IntoIterator<Item = Vec<String>>,
) -> Result<()> {
    use crate::mdf4::write::{Column, ColumnValues};
    let channels: Vec<Option<Channel>> = header
        .iter()
        .map(|h| Channel::find(&ALL, h).map(|(c, _)| c))
        .collect();
    if channels.first() != Some(&Some(T)) {
        anyhow::bail!("an MDF4 run log needs `t_s` as its first column");
    }
    let mut cols: Vec<Collected> = channels
        .iter()
        .map(|c| match c {
            // Texts where the schema has texts; numbers elsewhere (a column of another
            // writer's that turns out to hold texts becomes a text column below).
            Some(c) if TEXT_CHANNELS.contains(c) => Collected::Text(Default::default()),
            _ => Collected::Num(Vec::new()),
        })
        .collect();
    for (r, row) in rows.into_iter().enumerate() {
        for (i, (cell, col)) in row.iter().zip(cols.iter_mut()).enumerate() {
            match col {
                Collected::Num(v) if cell.is_empty() => v.push(f64::NAN),
                Collected::Num(v) => match cell.parse() {
                    Ok(x) => v.push(x),
                    // A column of texts the schema does not list as such: kept as texts.
                    Err(_) if i > 0 => {
                        let mut t = crate::measured::TextColumn::default();
                        for x in v.iter() {
                            t.push(&if x.is_nan() {
                                String::new()
                            } else {
                                format!("{x}")
                            });
                        }
                        t.push(cell);
                        *col = Collected::Text(t);
                    }
                    Err(_) => anyhow::bail!("row {}: time `{cell}` is not a number", r + 1),
                },
                Collected::Text(t) => t.push(cell),
            }
        }
    }
    let mut cols = cols.into_iter();
    let time = match cols.next() {
        Some(Collected::Num(t)) => t,
        _ => Vec::new(),
    };
    let columns: Vec<Column> = cols
        .zip(header.iter().zip(&channels).skip(1))
        .map(|(c, (name, ch))| Column {
            name,
            unit: ch.map_or("", |c| c.unit_symbol()),
            comment: ch.map_or("", comment),
            values: match c {
                Collected::Num(v) => ColumnValues::Num(v),
                Collected::Text(t) => ColumnValues::Text {
                    texts: t.values,
                    codes: t.codes,
                },
            },
        })
        .collect();
    let source = metadata
        .iter()
        .find(|(k, _)| *k == "source")
        .map_or(String::new(), |(_, v)| v.clone());
    crate::mdf4::write::write(out, &source, metadata, &time, &columns)?;
    Ok(())
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
    write_run_log_as(Format::Csv, out, metadata, samples)
}

/// Writes a simulated run log in `format` (the same cells either way).
pub fn write_run_log_as<W: Write>(
    format: Format,
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
    write_table_as(format, out, metadata, &columns(), rows)
}
