//! Writing run logs in the format of `spec/measured-data.md` (section 1, run log).
//!
//! Metadata lines `# key: value` come before the header; then one header row and one row
//! per sample. Column names carry units, as the spec requires. Besides the spec's
//! columns (all optional ones filled) a simulated log has `mu_d1..4`, `creepage1..4`,
//! `adhesion1..4`, `x_m` (distance) and `v_ref_est_mps` (the brake unit's reference speed).

use std::io::Write;

use anyhow::Result;

use crate::scenario::Sample;

/// Column names of a simulated run log, in order.
pub fn columns() -> Vec<String> {
    let mut c = vec!["t_s".to_string(), "v_ref_mps".to_string()];
    let per = |c: &mut Vec<String>, pre: &str, suf: &str| {
        for j in 1..=4 {
            c.push(format!("{pre}{j}{suf}"));
        }
    };
    per(&mut c, "omega", "_radps");
    per(&mut c, "p_cyl", "_pa");
    per(&mut c, "f_clamp", "_n");
    per(&mut c, "f_brake", "_n");
    per(&mut c, "t_disc", "_c");
    per(&mut c, "q", "_n");
    per(&mut c, "wsp", "");
    c.push("a_x_mps2".into());
    c.push("cmd".into());
    per(&mut c, "mu_d", "");
    per(&mut c, "creepage", "");
    per(&mut c, "adhesion", "");
    c.push("x_m".into());
    c.push("v_ref_est_mps".into());
    c
}

/// Writes `# key: value` metadata, the header and the samples.
pub fn write_run_log<W: Write>(
    out: W,
    metadata: &[(&str, String)],
    samples: &[Sample],
) -> Result<()> {
    let mut out = std::io::BufWriter::new(out);
    for (k, v) in metadata {
        writeln!(out, "# {k}: {v}")?;
    }
    let mut w = csv::WriterBuilder::new().from_writer(out);
    w.write_record(columns())?;
    let mut row: Vec<String> = Vec::with_capacity(64);
    let g = |x: f64| format!("{x:.7}");
    for s in samples {
        row.clear();
        row.push(format!("{:.6}", s.t));
        row.push(g(s.v_ref));
        let four = |row: &mut Vec<String>, a: &[f64; 4], digits: usize| {
            for x in a {
                row.push(format!("{x:.digits$}"));
            }
        };
        four(&mut row, &s.omega, 6);
        four(&mut row, &s.p_cyl, 1);
        four(&mut row, &s.f_clamp, 2);
        four(&mut row, &s.f_brake, 2);
        four(&mut row, &s.t_disc, 4);
        four(&mut row, &s.q, 1);
        for b in s.wsp {
            row.push(if b { "1".into() } else { "0".into() });
        }
        row.push(format!("{:.6}", s.a_x));
        row.push(if s.eb { "EB".into() } else { "REL".into() });
        four(&mut row, &s.mu_d, 6);
        four(&mut row, &s.creepage, 7);
        four(&mut row, &s.adhesion, 6);
        row.push(format!("{:.4}", s.distance));
        row.push(g(s.v_ref_estimate));
        w.write_record(&row)?;
    }
    w.flush()?;
    Ok(())
}
