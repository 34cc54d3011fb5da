//! Two instances with different parameter files run side by side in one process, stepped
//! in turn: each gives exactly what it gives alone (no shared state), and they differ as
//! their files do. An FMU state saved and restored replays the same numbers.

mod common;

use common::{Fmu, OK, resources};
use hils_plant::{FrictionModel, Rail};
use hils_sil::ParamFile;

/// The closed loop of `file` from `params_file` (empty: the resource's), EB at t = 0.
fn eb(resources: &std::path::Path, params_file: Option<&std::path::Path>) -> Fmu {
    let f = Fmu::new(resources);
    if let Some(p) = params_file {
        assert_eq!(
            f.set_string("params_file", &p.display().to_string()),
            OK,
            "{}",
            f.last()
        );
    }
    assert_eq!(f.set_i64("brake_input", 2), OK);
    assert_eq!(f.set_i64("cmd", 1), OK);
    f.init();
    f
}

const NAMES: [&str; 6] = [
    "v_ref_mps",
    "x_m",
    "omega2_radps",
    "q4_n",
    "mu_d1",
    "t_disc3_c",
];

fn sample(f: &Fmu) -> Vec<u64> {
    NAMES.iter().map(|n| f.get_f64(n).to_bits()).collect()
}

#[test]
fn two_instances_with_different_parameter_files_run_side_by_side_independently() {
    let reference = ParamFile::default();
    let mut other = reference;
    other.plant.friction.model = FrictionModel::Constant;
    other.scenario.paper_eb.rail = Rail::Dry;
    other.scenario.paper_eb.initial_speed_kmh = 120.0;
    let dir = resources("two", &reference);
    let other_file = dir.join("other.toml");
    std::fs::write(
        &other_file,
        hils_fmu::description::parameter_file(&other, "a test"),
    )
    .unwrap();

    // Alone, one after the other.
    let steps = 3000; // 3 s at 1 ms
    let run = |params: Option<&std::path::Path>| -> Vec<Vec<u64>> {
        let f = eb(&dir, params);
        (0..steps)
            .map(|k| {
                assert_eq!(f.step(k as f64 * 1e-3, 1e-3), OK);
                sample(&f)
            })
            .collect()
    };
    let alone_a = run(None);
    let alone_b = run(Some(&other_file));

    // Side by side, stepped in turn.
    let a = eb(&dir, None);
    let b = eb(&dir, Some(&other_file));
    assert_eq!(b.get_f64("scenario.paper_eb.initial_speed_kmh"), 120.0);
    assert_eq!(a.get_f64("scenario.paper_eb.initial_speed_kmh"), 150.0);
    for k in 0..steps {
        let t = k as f64 * 1e-3;
        assert_eq!(a.step(t, 1e-3), OK);
        assert_eq!(b.step(t, 1e-3), OK);
        assert_eq!(sample(&a), alone_a[k], "instance A at step {k}");
        assert_eq!(sample(&b), alone_b[k], "instance B at step {k}");
    }
    assert_ne!(alone_a[steps - 1], alone_b[steps - 1]);
    assert!(
        a.get_f64("v_ref_mps") > b.get_f64("v_ref_mps"),
        "150 km/h vs 120 km/h"
    );
}

#[test]
fn a_saved_fmu_state_replays_the_same_numbers() {
    use hils_fmu::abi::{fmi3FreeFMUState, fmi3GetFMUState, fmi3SetFMUState};
    let dir = resources("state", &ParamFile::default());
    let f = eb(&dir, None);
    for k in 0..2000 {
        assert_eq!(f.step(k as f64 * 1e-3, 1e-3), OK);
    }
    let mut state = std::ptr::null_mut();
    assert_eq!(unsafe { fmi3GetFMUState(f.ptr, &mut state) }, OK);
    let first: Vec<Vec<u64>> = (2000..4000)
        .map(|k| {
            assert_eq!(f.step(k as f64 * 1e-3, 1e-3), OK);
            sample(&f)
        })
        .collect();
    assert_eq!(unsafe { fmi3SetFMUState(f.ptr, state) }, OK);
    assert_eq!(f.get_f64("time"), 2.0);
    for (i, k) in (2000..4000).enumerate() {
        assert_eq!(f.step(k as f64 * 1e-3, 1e-3), OK);
        assert_eq!(sample(&f), first[i], "replay at step {k}");
    }
    assert_eq!(unsafe { fmi3FreeFMUState(f.ptr, &mut state) }, OK);
    assert!(state.is_null());
}
