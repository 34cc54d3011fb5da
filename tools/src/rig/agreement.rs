//! The rig against SIL on the same programme run (issue 21): the judge's figures of the
//! rig's log beside those of the SIL run, and whether they agree: air within
//! [`AIR_TOLERANCE`], WSP timer actions and the locks of every wheelset equal, nothing
//! "not measured" on the rig. The stopping distance's difference is shown (the rig's
//! controller reads the board's pulse trains and the plant the ADC's pressures, so a run on
//! a low adhesion rail is not the same stop to the millimetre).
//!
//! `hils rig run --programme` prints the table ([`table`]) after its summary, writes it into
//! the report and gives each rig run's JSON entry an `against_sil` object ([`Agreement`]).

use std::fmt::Write as _;

use serde::Serialize;

use crate::figures::round_dp;
use crate::wsp::metrics::Verdict;

/// Largest relative difference of the rig's air from SIL's that agrees (3 %).
pub const AIR_TOLERANCE: f64 = 0.03;

/// One run's rig figures against its SIL run's (JSON `against_sil`).
#[derive(Clone, Debug, Serialize)]
pub struct Agreement {
    /// (rig - SIL) / SIL of the air, % (None: not measured on the rig, or SIL vented none
    /// and the rig did).
    pub air_diff_pct: Option<f64>,
    /// (rig - SIL) / SIL of the stopping distance, % (None: a run that did not stop).
    pub stopping_distance_diff_pct: Option<f64>,
    /// The WSP timer actions are measured on the rig and equal SIL's.
    pub timer_actions_equal: bool,
    /// Every wheelset's lock count equals SIL's.
    pub locks_equal: bool,
    /// What the rig's log could not give (the judge's `not_measured`).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub not_measured: Vec<String>,
    /// Air within [`AIR_TOLERANCE`], timer actions and locks equal, nothing not measured.
    pub agrees: bool,
}

/// Relative difference (a - b) / b, % (a == b == 0: 0; b == 0 otherwise: None).
fn diff_pct(a: f64, b: f64) -> Option<f64> {
    if b != 0.0 {
        Some(100.0 * (a - b) / b)
    } else {
        (a == 0.0).then_some(0.0)
    }
}

/// The rig run's figures against the SIL run's.
pub fn agreement(rig: &Verdict, sil: &Verdict) -> Agreement {
    let air_diff = match (rig.air_consumption_l, sil.air_consumption_l) {
        (Some(r), Some(s)) => diff_pct(r, s),
        _ => None,
    };
    let stop_diff = match (rig.stopping_distance_m, sil.stopping_distance_m) {
        (Some(r), Some(s)) => diff_pct(r, s),
        _ => None,
    };
    let timer_equal =
        rig.wsp_timer_actions.is_some() && rig.wsp_timer_actions == sil.wsp_timer_actions;
    let locks_equal = rig.lock_count == sil.lock_count;
    let agrees = rig.not_measured.is_empty()
        && air_diff.is_some_and(|d| d.abs() <= 100.0 * AIR_TOLERANCE)
        && timer_equal
        && locks_equal;
    Agreement {
        air_diff_pct: air_diff.map(|d| round_dp(d, 2)),
        stopping_distance_diff_pct: stop_diff.map(|d| round_dp(d, 2)),
        timer_actions_equal: timer_equal,
        locks_equal,
        not_measured: rig.not_measured.clone(),
        agrees,
    }
}

/// A figure or "not measured".
fn or_not_measured<T: std::fmt::Display>(v: Option<T>) -> String {
    v.map_or_else(|| "not measured".to_string(), |v| v.to_string())
}

/// The Markdown table of the judged runs, `(rig, SIL)` verdict pairs.
pub fn table(pairs: &[(&Verdict, &Verdict)]) -> String {
    let mut t = format!(
        "Rig against SIL (air within {} %, WSP timer actions and locks equal):\n\n\
         | run | air rig l | air SIL l | air diff % | stop diff % | timer rig / SIL | locks rig / SIL | agrees |\n\
         |---|---:|---:|---:|---:|---:|---:|---|\n",
        100.0 * AIR_TOLERANCE
    );
    for (rig, sil) in pairs {
        let a = agreement(rig, sil);
        let locks = |v: &Verdict| v.lock_count.iter().sum::<u32>();
        let _ = writeln!(
            t,
            "| {} | {} | {} | {} | {} | {} / {} | {} / {} | {} |",
            rig.name,
            or_not_measured(rig.air_consumption_l.map(|x| format!("{x:.1}"))),
            or_not_measured(sil.air_consumption_l.map(|x| format!("{x:.1}"))),
            or_not_measured(a.air_diff_pct.map(|x| format!("{x:+.2}"))),
            a.stopping_distance_diff_pct
                .map_or_else(|| "no stop".to_string(), |x| format!("{x:+.2}")),
            or_not_measured(rig.wsp_timer_actions),
            or_not_measured(sil.wsp_timer_actions),
            locks(rig),
            locks(sil),
            if a.agrees { "yes" } else { "no" },
        );
    }
    t
}
