//! The prepare stage of `hils diagnose`: the runs prepared for replays, the baseline
//! replayed, v_ref's slow error (the noise model) and whether there is a discrepancy
//! (method steps 1-3 of [`super`]).

use hils_plant::Params;

use super::links;
use super::replay::{Model, Replay, Score, Split};
use super::search::{Diagnoser, NO_DISCREPANCY_RMS, SCAN_RMS};
use crate::measured::RunLog;

/// The baseline replayed at the command's step.
pub struct Baseline {
    /// The runs prepared at the command's step (v_ref's slow error set).
    pub d: Diagnoser,
    pub models: Vec<Model>,
    pub replays: Vec<Replay>,
    /// v_ref's slow error per run, m/s (None: not estimable).
    pub vref_slow_sigma_mps: Vec<Option<f64>>,
    pub validation: Score,
    /// Whether the baseline leaves an error beyond the noise anywhere: in the fitted
    /// channels, or on a link only compared (the disc temperatures).
    pub discrepancy: bool,
    /// Whether it does in the fitted channels (what the listed effects are fitted to: the
    /// search runs only then).
    pub fitted_discrepancy: bool,
}

/// The error when the baseline (or a model) cannot replay the runs.
pub fn numeric_fault() -> anyhow::Error {
    anyhow::anyhow!("the baseline cannot replay these runs (numeric fault)")
}

/// Prepares the runs and replays the baseline; with the notes of the reader and the replay.
pub fn prepare(
    baseline: &Params,
    logs: &[RunLog],
    step_s: f64,
) -> anyhow::Result<(Baseline, Vec<String>)> {
    let mut d = Diagnoser::new(baseline, logs, step_s)?;
    let mut notes = reader_notes(&d, logs);
    let models = d.models(&[], &[]);
    let replays = d.replays(&models).ok_or_else(numeric_fault)?;
    // Noise model of v_ref: its slow correlated error, from the baseline replay.
    let slow: Vec<Option<f64>> = d
        .runs
        .iter()
        .zip(&replays)
        .map(|(r, rep)| r.vref_slow_sigma(rep))
        .collect();
    for (i, s) in slow.iter().enumerate() {
        if let Some(s) = *s {
            d.runs[i].set_vref_slow_sigma(s);
            notes.push(format!(
                "{}: v_ref's slow error (the part of its error the rolling wheels do not share) is {s:.4} m/s rms; its bins weigh at most that",
                d.runs[i].name
            ));
        }
    }
    let validation = d.score(&replays, Split::Validation);
    let rms = validation.rms();
    let fitted_discrepancy = rms > NO_DISCREPANCY_RMS || validation.max_window_rms() > SCAN_RMS;
    let thermal: Vec<String> = links::errors(&d.runs, &replays)
        .into_iter()
        .filter(|(k, e)| k.0 == links::Link::DiscThermal && *e > links::LINK_EXPLAINED_RMS)
        .map(|(k, _)| links::key_name(k))
        .collect();
    if !fitted_discrepancy && !thermal.is_empty() {
        notes.push(format!(
            "the baseline explains every fitted channel but not the disc temperatures ({}): a \
             discrepancy no listed effect acts on alone (the thermal model's constants are not \
             among the effects); no cause is searched",
            thermal.join(", ")
        ));
    }
    let discrepancy = fitted_discrepancy || !thermal.is_empty();
    if std::env::var_os("HILS_DIAG_DEBUG").is_some() {
        eprintln!("baseline validation rms {rms:.2}");
        debug_errors(&d, &replays, &validation);
    }
    let base = Baseline {
        d,
        models,
        replays,
        vref_slow_sigma_mps: slow,
        validation,
        discrepancy,
        fitted_discrepancy,
    };
    Ok((base, notes))
}

/// What the reader and the replay skipped or repaired, per file.
fn reader_notes(d: &Diagnoser, logs: &[RunLog]) -> Vec<String> {
    let mut notes = Vec::new();
    for (log, run) in logs.iter().zip(&d.runs) {
        // The reader's notes are among the admission's (restated per column there).
        for n in &run.notes {
            notes.push(format!("{}: {n}", run.name));
        }
        if !log.unknown_columns.is_empty() {
            notes.push(format!(
                "{}: columns kept but not used: {}",
                run.name,
                log.unknown_columns.join(", ")
            ));
        }
    }
    notes
}

/// The baseline's mean error per channel in 3 s slices and its worst windows (stderr, with
/// HILS_DIAG_DEBUG set).
fn debug_errors(d: &Diagnoser, replays: &[Replay], validation: &Score) {
    for (run, rep) in d.runs.iter().zip(replays) {
        for (c, p) in run.channels.iter().zip(&rep.predicted) {
            let mut line = format!(
                "  {:>22} sig {:.4}:",
                c.quantity.label(),
                c.sigma[c.sigma.len() / 2]
            );
            let mut k = 0;
            let mut t = 0.0;
            while k < c.times.len() {
                let (mut sum, mut n) = (0.0, 0);
                while k < c.times.len() && c.times[k] < t + 3.0 {
                    sum += p[k] - c.measured[k];
                    n += 1;
                    k += 1;
                }
                line += &format!(" {:.3}", sum / n.max(1) as f64);
                t += 3.0;
            }
            eprintln!("{line}");
        }
    }
    for (k, (s, n)) in &validation.windows {
        let r = (s / *n as f64).sqrt();
        if r > 2.0 {
            eprintln!("  window {k:?}: rms {r:.2} over {n}");
        }
    }
}
