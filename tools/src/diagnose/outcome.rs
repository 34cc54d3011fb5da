//! What a diagnosis computed: the value the chain of stages of [`super::diagnose`] ends
//! in, read by the JSON, the report and tests.

use hils_plant::Params;

use super::analysis::Analysis;
use super::json::Report;
use super::replay::{Model, Prepared, Replay};
use super::search::SetFit;

/// Everything the diagnosis computed (for the JSON, the report and tests).
pub struct Outcome {
    pub report: Report,
    /// Runs prepared at the final replay step.
    pub runs: Vec<Prepared>,
    pub baseline_replays: Vec<Replay>,
    pub extended_replays: Vec<Replay>,
    pub singles: Vec<SetFit>,
    pub result: SetFit,
    pub baseline_params: Params,
    pub extended_model: Vec<Model>,
    pub evaluations: usize,
    /// What the baseline's error goes with (for the report).
    pub analysis: Analysis,
}
