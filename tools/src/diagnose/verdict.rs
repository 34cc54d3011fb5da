//! The verdict stage of `hils diagnose`: the diagnosis JSON ([`super::json::Report`]) from
//! the values of the stages before it: causes ordered by their gain alone, the findings
//! with their confidence intervals, the gain, the slides, the localisation and every
//! effect tried.

use std::collections::BTreeMap;

use hils_plant::{Params, Rail};

use super::baseline::Baseline;
use super::causes::Causes;
use super::effects::Effect;
use super::json::{Finding, Gain, Report, Slides, Tried};
use super::links;
use super::replay::{self, Prepared, Replay, Score};
use super::search::SetFit;
use super::settle::Settled;

/// The report of the stages; `baseline`, `files`, `notes` and `wall_s` are left empty for
/// the caller.
pub fn judge(baseline: &Params, base: &Baseline, causes: &Causes, settled: &Settled) -> Report {
    let runs = &base.d.runs;
    let rail = base.d.rail();
    let findings = findings(baseline, rail, runs, causes, &settled.result);
    Report {
        baseline: String::new(),
        files: Vec::new(),
        discrepancy: base.discrepancy,
        causes: findings.iter().map(|f| f.effect.clone()).collect(),
        confounded: settled.confounded.clone(),
        unexplained_share: settled.unexplained_share,
        findings,
        gain: gain(runs, &base.validation, &settled.result.validation),
        slides: slides(runs, &base.replays, &settled.replays),
        localisation: links::localise(runs, &base.replays, &settled.replays),
        tried: tried(baseline, rail, causes),
        notes: Vec::new(),
        wall_s: 0.0,
    }
}

/// Share of the fit-step baseline's validation error that `v` removes.
fn gain_of(causes: &Causes, v: &Score) -> f64 {
    let replay::ComparedRms {
        reference: b,
        candidate: e,
    } = replay::compare(&causes.fit_base_validation, v);
    if b > 0.0 { 1.0 - e / b } else { 0.0 }
}

/// The gain of effect `e` alone (fit-step single against the fit-step baseline).
fn single_gain(causes: &Causes, e: Effect) -> f64 {
    causes
        .singles
        .iter()
        .find(|s| s.effects == [e])
        .map(|s| gain_of(causes, &s.validation))
        .unwrap_or(0.0)
}

/// The findings, causes ordered by their gain alone.
fn findings(
    baseline: &Params,
    rail: Rail,
    runs: &[Prepared],
    causes: &Causes,
    result: &SetFit,
) -> Vec<Finding> {
    let mut order: Vec<usize> = (0..result.effects.len()).collect();
    order.sort_by(|&a, &b| {
        single_gain(causes, result.effects[b]).total_cmp(&single_gain(causes, result.effects[a]))
    });
    order
        .iter()
        .map(|&k| {
            let e = result.effects[k];
            let mut params = BTreeMap::new();
            let mut ci95 = BTreeMap::new();
            for (i, key) in param_keys(e, baseline, rail).iter().enumerate() {
                let x = result.x[k][i];
                let h = result.ci95_half[k][i];
                params.insert(key.to_string(), x);
                ci95.insert(key.to_string(), [x - h, x + h]);
            }
            Finding {
                effect: e.name().to_string(),
                params,
                ci95,
                gain: single_gain(causes, e),
                sensor: sensor_of(e, &runs[0]),
            }
        })
        .collect()
}

fn param_keys(e: Effect, baseline: &Params, rail: Rail) -> Vec<&'static str> {
    e.params(baseline, rail)
        .into_iter()
        .map(|(k, _)| k)
        .collect()
}

/// For `sensor-gain`: which sensors (`f_clamp`/`p_cyl` input, or `p_cyl` observation).
fn sensor_of(e: Effect, run: &Prepared) -> Option<String> {
    match e {
        Effect::SensorGain => Some(
            run.input_kind
                .iter()
                .map(|k| match k {
                    replay::InputKind::ClampForce => "f_clamp",
                    replay::InputKind::Pressure => "p_cyl",
                })
                .collect::<Vec<_>>()
                .join(","),
        ),
        Effect::SensorGainPressure => Some("p_cyl".to_string()),
        _ => None,
    }
}

/// Wheelsets (1-based) that slide in any run, measured and in both models.
fn slides(runs: &[Prepared], base: &[Replay], ext: &[Replay]) -> Slides {
    let slide_set = |f: &dyn Fn(usize) -> [bool; 4]| -> Vec<usize> {
        let mut any = [false; 4];
        for i in 0..runs.len() {
            let s = f(i);
            for j in 0..4 {
                any[j] |= s[j];
            }
        }
        (0..4).filter(|&j| any[j]).map(|j| j + 1).collect()
    };
    Slides {
        measured: slide_set(&|i| {
            let r = &runs[i];
            let s = replay::slides(&r.v_bin, &r.wheel_bin);
            std::array::from_fn(|j| s[j] || r.wsp_any[j])
        }),
        baseline: slide_set(&|i| replay::slides(&base[i].v_bin, &base[i].wheel_bin)),
        extended: slide_set(&|i| replay::slides(&ext[i].v_bin, &ext[i].wheel_bin)),
    }
}

/// The gain of the extension on validation data (compared where either errs).
fn gain(runs: &[Prepared], base_val: &Score, ext_val: &Score) -> Gain {
    let mut speed = BTreeMap::new();
    speed.insert("baseline".to_string(), base_val.speed_rms());
    speed.insert("extended".to_string(), ext_val.speed_rms());
    let channels = fitted_channel_names(runs);
    let replay::ComparedRms {
        reference: rms_baseline,
        candidate: rms_extended,
    } = replay::compare(base_val, ext_val);
    Gain {
        metric: format!(
            "rms on validation data of the replay errors of {channels}, each over its noise level \
             (1 = noise), over the 1 s windows where the baseline or the extension errs beyond \
             1.5 x noise (all data if none); m/s figures of the speeds alone in speed_rms_mps"
        ),
        baseline: rms_baseline,
        extended: rms_extended,
        reduction: if rms_baseline > 0.0 {
            1.0 - rms_extended / rms_baseline
        } else {
            0.0
        },
        speed_rms_mps: speed,
    }
}

/// Every effect fitted alone: its parameters, validation RMS and gain.
fn tried(baseline: &Params, rail: Rail, causes: &Causes) -> Vec<Tried> {
    causes
        .singles
        .iter()
        .map(|s| {
            let e = s.effects[0];
            Tried {
                effect: match e {
                    Effect::SensorGainPressure => "sensor-gain (p_cyl observation)".into(),
                    Effect::WheelsetFriction(j) => {
                        format!("pad friction of wheelset {} (not a listed effect)", j + 1)
                    }
                    _ => e.name().into(),
                },
                params: param_keys(e, baseline, rail)
                    .iter()
                    .zip(&s.x[0])
                    .map(|(k, v)| (k.to_string(), *v))
                    .collect(),
                validation_rms: s.val(),
                gain: gain_of(causes, &s.validation),
            }
        })
        .collect()
}

fn fitted_channel_names(runs: &[Prepared]) -> String {
    let mut names: Vec<&str> = Vec::new();
    for r in runs {
        for c in &r.channels {
            if !c.quantity.group().fitted() {
                continue;
            }
            let n = match c.quantity.group() {
                replay::Group::Speeds => "v_ref and r*omega1..4",
                replay::Group::BrakeForces => "f_brake",
                replay::Group::AxleLoads => "q",
                replay::Group::PadForces => "f_clamp predicted from p_cyl",
                _ => continue,
            };
            if !names.contains(&n) {
                names.push(n);
            }
        }
    }
    names.join(", ")
}
