//! The emulated target's scenario and trace format, checked on the host alone (no qemu):
//! what the emulator records is what `hils simulate` records, and the text format carries
//! every bit.

use hils::target_cost::{check_against_simulate, compare, host_trace};
use hils_plant::FrictionModel;
use hils_sil::TraceRow;
use hils_sil::trace::{LINE_LEN, RECORD_EVERY};

/// The emulator's scenario driver, run on the host in f32, records the same samples as
/// `hils simulate` (every 10 ms) with every shared value equal, for both friction models:
/// the stop rule, the run length and the EB timing are the same.
#[test]
fn scenario_driver_records_what_hils_simulate_records() {
    for friction in [FrictionModel::Variable, FrictionModel::Constant] {
        let (rows, steps, stop) = host_trace(friction).expect("host trace");
        let checked = check_against_simulate(friction, &rows).expect("same as hils simulate");
        // 5 shared scalars and 10 shared values per wheelset in every sample.
        assert_eq!(checked, rows.len() * (5 + 4 * 10));
        let stop = stop.expect("the vehicle stops");
        // One second (10 000 steps) after the stop, and a row every 100 steps from step 0.
        assert_eq!(steps, stop + 10_000);
        assert_eq!(rows.len() as u32, steps / RECORD_EVERY + 1);
        assert!(
            rows.iter()
                .enumerate()
                .all(|(i, r)| r.step == i as u32 * RECORD_EVERY)
        );
    }
}

/// Both runs end at rest after about half a minute, the variable friction run with the
/// WSP venting on some wheelset and the constant one without (the paper's contrast): the
/// trace holds the physics, not only numbers.
#[test]
fn traces_show_the_papers_contrast() {
    let vents = |rows: &[TraceRow]| {
        (0..4)
            .filter(|&j| rows.iter().any(|r| r.venting(j)))
            .count()
    };
    let (var, _, stop_var) = host_trace(FrictionModel::Variable).expect("variable");
    let (con, _, stop_con) = host_trace(FrictionModel::Constant).expect("constant");
    assert!(vents(&var) >= 1, "variable friction: no WSP activity");
    assert_eq!(vents(&con), 0, "constant friction: unexpected WSP activity");
    let t = |s: Option<u32>| s.expect("stops") as f64 * 1e-4;
    assert!((25.0..35.0).contains(&t(stop_var)) && (25.0..35.0).contains(&t(stop_con)));
    // A second after the stop the carbody only rocks on its suspension (a few cm/s,
    // decaying): column 1 is the vehicle speed.
    assert!(var.last().expect("rows").value(1).abs() < 0.1);
    assert!(con.last().expect("rows").value(1).abs() < 0.1);
}

/// Every row survives the text line the target sends: encode, decode, same bits (NaN
/// payloads and negative zero included).
#[test]
fn trace_lines_carry_every_bit() {
    let (rows, _, _) = host_trace(FrictionModel::Variable).expect("host trace");
    for r in rows.iter().step_by(37) {
        let mut buf = [0u8; LINE_LEN];
        r.encode(&mut buf);
        let line = std::str::from_utf8(&buf).expect("ascii");
        assert_eq!(TraceRow::decode(line), Some(*r));
    }
    let mut odd = rows[0];
    odd.values[0] = f32::NAN.to_bits() | 0x1234;
    odd.values[1] = (-0.0f32).to_bits();
    odd.values[2] = u32::MAX;
    let mut buf = [0u8; LINE_LEN];
    odd.encode(&mut buf);
    assert_eq!(
        TraceRow::decode(std::str::from_utf8(&buf).expect("ascii")),
        Some(odd)
    );
    // Truncated or padded lines are refused.
    let line = std::str::from_utf8(&buf).expect("ascii");
    assert_eq!(TraceRow::decode(&line[..LINE_LEN - 5]), None);
    assert_eq!(
        TraceRow::decode(&format!("{} 00000000", line.trim_end())),
        None
    );
}

/// The host trace is deterministic (the same run twice is identical bit for bit) and
/// differs from a run with another friction model: the comparison can fail.
#[test]
fn comparison_is_exact_and_can_fail() {
    let (a, _, _) = host_trace(FrictionModel::Variable).expect("run a");
    let (b, _, _) = host_trace(FrictionModel::Variable).expect("run b");
    assert!(compare("variable", &a, &b).identical);
    let (c, _, _) = host_trace(FrictionModel::Constant).expect("run c");
    let cmp = compare("variable", &a, &c);
    assert!(!cmp.identical);
    // Row 0 is the initial state; mu_d differs there already (Eq 2 vs mu_d0).
    assert_eq!(cmp.first_mismatch.expect("a difference").row, 0);
}
