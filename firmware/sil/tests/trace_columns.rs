//! The emulator trace's columns are channels of the run-record schema: the values a trace
//! row and a run record share are the same numbers under the same channel, and the trace's
//! own channels name the plant's outputs they hold.

use hils_plant::{FrictionModel, WheelsetOutput};
use hils_sil::record::{Channel, run_log};
use hils_sil::trace::{self, RECORD_EVERY, SCALAR_COLUMNS, WHEELSET_COLUMNS};
use hils_sil::{Cmd, EbScenario, RunRecord, TraceRow};

/// Mid-braking (WSP acting on the variable-friction run near 4 s), every shared value of
/// the trace row equals the run record's, channel by channel.
#[test]
fn trace_row_and_run_record_agree_on_every_shared_channel() {
    let mut sc = EbScenario::<f32>::paper(FrictionModel::Variable, RECORD_EVERY).expect("scenario");
    let mut records = 0;
    while sc.steps() < 45_000 {
        let adv = sc.advance(|sim| {
            sim.step();
        });
        assert!(!adv.done, "the run ended before 4.5 s");
        if !adv.record {
            continue;
        }
        let row = TraceRow::of(&sc.sim);
        let rec = RunRecord::of(&sc.sim, Cmd::Emergency);
        let mut shared = 0;
        for (k, (c, j)) in trace::columns().enumerate() {
            if let Some(x) = rec.value(c, j) {
                shared += 1;
                assert_eq!(
                    x as f32,
                    row.value(k),
                    "{} at step {}",
                    c.name(j),
                    sc.steps()
                );
            }
        }
        // t, v_ref, x, a_x, v_ref_est; omega, creepage, q, adhesion, mu_d, f_clamp,
        // f_brake, t_disc, p_cyl per wheelset.
        assert_eq!(shared, 5 + 9 * 4);
        for j in 0..4 {
            assert_eq!(
                rec.value(run_log::WSP, j),
                Some(row.venting(j) as u8 as f64)
            );
        }
        records += 1;
    }
    assert!(records >= 400);
}

/// Every channel the run record holds is a trace column (the WSP as the valve bits), so a
/// trace checks the whole record.
#[test]
fn every_record_channel_is_in_the_trace() {
    let rec = RunRecord::default();
    let in_trace = |c: &Channel| SCALAR_COLUMNS.contains(c) || WHEELSET_COLUMNS.contains(c);
    let held: Vec<Channel> = run_log::ALL
        .into_iter()
        .filter(|c| rec.value(*c, 0).is_some() && *c != run_log::WSP)
        .collect();
    assert_eq!(held.len(), 14);
    for c in held {
        assert!(in_trace(&c), "{} is not in the trace", c.name(0));
    }
}

/// The wheelset columns follow the plant's order of `WheelsetOutput::values`: the trace's
/// own channels carry the plant's names, the run log's the plant's units.
#[test]
fn wheelset_columns_follow_the_plant_outputs() {
    let names = WheelsetOutput::<f32>::NAMES;
    assert_eq!(names.len() + 1, WHEELSET_COLUMNS.len());
    for (c, name) in WHEELSET_COLUMNS.iter().zip(names) {
        assert!(name.ends_with(c.unit), "{} vs {name}", c.name(0));
        if !run_log::ALL.contains(c) {
            assert_eq!(format!("{}{}", c.stem, c.unit), name);
        }
    }
    assert_eq!(WHEELSET_COLUMNS[15], run_log::P_CYL);
}
