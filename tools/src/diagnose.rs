//! `hils diagnose`: what the baseline model gets wrong on measured runs, why, and what
//! fixing it gains (`spec/diagnosis.md`).
//!
//! # Method
//!
//! 1. Each run log is replayed in the baseline ([`replay`]): the plant driven by the
//!    measured brake inputs (clamp forces, or cylinder pressures through Eq 1; WSP venting
//!    is in those inputs) from the measured initial speed, on the contact set of the file's
//!    `rail`. The model is compared with v_ref, the wheel speeds r omega_1..4 and every other
//!    logged quantity it predicts, in 20 ms bins, each residual over its noise
//!    (1 = noise level).
//!    Noise model (issue 9): v_ref's slow correlated error (a radar's drift) is the part of
//!    its baseline replay error that the rolling wheels do not share
//!    ([`replay::Prepared::vref_slow_sigma`]); speeds have a resolution relative to the
//!    speed lost ([`replay::SPEED_RESOLUTION`]); the initial speed is the median over v_ref
//!    and the wheels; a brake force at standstill (static friction) is not compared; where
//!    `t_disc` is logged, Eq (2) is evaluated at the measured disc temperature.
//! 2. Every third 0.2 s block of each run is validation data: fits never see it, and every
//!    decision (keep an effect, combine, confounded, gains) is made on it.
//! 3. **Discrepancy**: the baseline explains the data when its validation RMS (in noise
//!    units) is at most [`NO_DISCREPANCY_RMS`] and no 1 s window of a channel group exceeds
//!    [`SCAN_RMS`]. Models are compared over the windows where either errs beyond the noise
//!    ([`replay::compare`]), so an error confined to a transient is not diluted.
//! 4. Each effect of the spec's table ([`effects`]) is fitted alone (coarse scan, then
//!    Levenberg-Marquardt; rayon across effects and Jacobian columns). Then forward
//!    selection: effects ranked by a linearised score test at the current fit, the best two
//!    fitted jointly, the better added while it lowers the validation error significantly
//!    ([`significant`]); a simpler model that is not significantly worse wins (parsimony);
//!    backward elimination drops effects the others make redundant. The result is polished
//!    and refined at the command's replay step (LM, then a coordinate search).
//! 5. **Confounded**: an effect outside the result that, put in the place of a cause,
//!    explains the validation data as well (within [`CONFOUND_TOLERANCE`]) is listed with it.
//!    Look-alikes the linearised screen misses are refitted in a cause's place from their
//!    fits alone ([`lookalike_swaps`]); the notes say which channel would separate them.
//! 6. **Localisation** ([`links`]): each link of the signal chain that the logged channels
//!    observe (pad force, disc-pad friction, disc thermal, wheel-rail per wheelset, vehicle)
//!    with its baseline and extended error in noise units; a link that the effects found
//!    leave beyond [`links::LINK_EXPLAINED_RMS`] is `explained: false`.
//! 7. **Unexplained**: the share of the baseline's excess error over noise that remains;
//!    when the effects leave more than [`MAX_UNEXPLAINED`] of it, no cause is claimed.
//!
//! See docs/diagnosis.md for the user's view.

pub mod admit;
pub mod analysis;
pub mod baseline;
pub mod causes;
pub mod effects;
pub mod inputs;
pub mod json;
pub mod links;
pub mod lsq;
pub mod outcome;
pub mod plausible;
pub mod replay;
pub mod report;
pub mod search;
pub mod settle;
pub mod spikes;
pub mod verdict;

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Result;
use clap::Args;
use hils_plant::Params;

use crate::figures::list_text;
use crate::measured::{RunLog, read_run_log_with};
use crate::params_file::load_params;
pub use json::{Finding, Gain, Report, Slides, Tried};
pub use outcome::Outcome;
pub use search::*;
pub use settle::what_separates;

/// Arguments of `hils diagnose`.
#[derive(Args, Debug, Clone)]
pub struct DiagnoseArgs {
    /// Baseline parameter file (reference-parameters.toml or a variant).
    #[arg(long)]
    pub baseline: PathBuf,
    /// `--json`: the diagnosis JSON (spec/diagnosis.md); `--report`: report.md with SVG plots.
    #[command(flatten)]
    pub out: crate::outputs::Outputs,
    /// Replay step, s (default 1 ms; the plant's semi-implicit contact keeps it accurate,
    /// see docs/diagnosis.md).
    #[arg(long, default_value_t = replay::REPLAY_STEP_S, value_parser = crate::flags::step_s)]
    pub step_s: f64,
    /// Channel map (TOML): which of the files' channels or columns is which spec column,
    /// their units, and metadata (docs/mdf4.md). Without it the spec's names are expected.
    #[arg(long, value_name = "FILE")]
    pub map: Option<PathBuf>,
    /// Run logs (spec/measured-data.md, section 1): CSV or MDF4 (.mf4).
    #[arg(required = true)]
    pub files: Vec<PathBuf>,
}

/// Runs the diagnosis of `logs` against `baseline`; final scores at the replay step
/// `step_s`, fits at [`FIT_STEP_S`] (or `step_s` if finer). A chain of stages: prepare
/// (the baseline replayed), search (the causes), settle (what is claimed), verdict (the
/// JSON) and the analysis for the report.
pub fn diagnose(
    baseline: &Params,
    baseline_name: &str,
    logs: &[RunLog],
    step_s: f64,
) -> Result<Outcome> {
    let started = Instant::now();
    let admitted = admit::admit(baseline, logs)?;
    let logs = &admitted.logs[..];
    let (base, mut notes) = baseline::prepare(baseline, logs, step_s)?;
    notes.splice(0..0, admitted.notes);
    let causes = causes::find(&base, baseline, logs, step_s, started)?;
    let settled = settle::settle(&base, &causes, &mut notes);
    let analysis = analysis::analyse(&base.d.runs, &base.replays);
    let report = Report {
        baseline: baseline_name.to_string(),
        files: logs.iter().map(|l| l.path.display().to_string()).collect(),
        notes,
        wall_s: started.elapsed().as_secs_f64(),
        ..verdict::judge(baseline, &base, &causes, &settled)
    };
    search::debug(started, causes.evaluations, "done");
    Ok(Outcome {
        report,
        runs: base.d.runs,
        baseline_replays: base.replays,
        extended_replays: settled.replays,
        singles: causes.singles,
        result: settled.result,
        baseline_params: *baseline,
        extended_model: settled.models,
        evaluations: causes.evaluations,
        analysis,
    })
}

/// Reads the runs of `files`.
pub fn read_logs(files: &[PathBuf]) -> Result<Vec<RunLog>> {
    read_logs_with(files, None)
}

/// Reads the runs of `files` (CSV or MDF4) through the channel map at `map`, if any.
pub fn read_logs_with(files: &[PathBuf], map: Option<&std::path::Path>) -> Result<Vec<RunLog>> {
    let map = crate::measured::load_map(map)?;
    files
        .iter()
        .map(|f| read_run_log_with(f, map.as_ref()).map_err(anyhow::Error::from))
        .collect()
}

/// `hils diagnose`.
pub fn main(args: DiagnoseArgs) -> Result<()> {
    let outputs = args.out.check()?;
    let baseline = load_params(&args.baseline)?;
    let logs = read_logs_with(&args.files, args.map.as_deref())?;
    let name = args.baseline.display().to_string();
    let out = diagnose(&baseline.plant, &name, &logs, args.step_s)?;
    print_summary(&out);
    outputs.write_json(&out.report.rounded())?;
    outputs.write_report(|dir| report::write(dir.path(), &out))
}

fn print_summary(out: &Outcome) {
    let r = &out.report;
    for n in &r.notes {
        crate::say!("note: {n}");
    }
    crate::say!(
        "baseline validation error {:.2} x noise ({:.4} m/s on the speeds)",
        r.gain.baseline,
        r.gain.speed_rms_mps["baseline"]
    );
    if !r.discrepancy {
        crate::say!("no discrepancy: the baseline explains the data within its noise");
    } else if r.causes.is_empty() {
        crate::say!(
            "discrepancy, but no listed effect explains it: {:.0} % stays unexplained",
            r.unexplained_share * 100.0
        );
    } else {
        crate::say!("causes: {}", r.causes.join(", "));
        for f in &r.findings {
            let params: Vec<String> = f
                .params
                .iter()
                .map(|(k, v)| {
                    let [lo, hi] = f.ci95[k];
                    format!("{k} = {v:.5} [{lo:.5}, {hi:.5}]")
                })
                .collect();
            crate::say!(
                "  {}: {} (gain alone {:.2})",
                f.effect,
                params.join(", "),
                f.gain
            );
        }
        for g in &r.confounded {
            crate::say!("  the data cannot tell apart: {}", g.join(" / "));
        }
        crate::say!(
            "extended validation error {:.2} x noise ({:.4} m/s): reduction {:.3}, unexplained share {:.3}",
            r.gain.extended,
            r.gain.speed_rms_mps["extended"],
            r.gain.reduction,
            r.unexplained_share
        );
    }
    for l in r.localisation.iter().filter(|l| !l.explained) {
        let which = l
            .wheelset
            .map(|w| format!(" of wheelset {w}"))
            .unwrap_or_default();
        crate::say!("unexplained: {}{which}: {}", l.link, l.note);
    }
    crate::say!(
        "slides (wheelsets): measured {}, baseline {}, extended {}",
        list_text(&r.slides.measured),
        list_text(&r.slides.baseline),
        list_text(&r.slides.extended)
    );
    crate::say!(
        "diagnosed in {:.2} s ({} replays)",
        r.wall_s,
        out.evaluations
    );
}
