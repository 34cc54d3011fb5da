//! The paper's emergency brake (150 km/h, wet rail, EB at t = 0) in the closed loop of
//! plant and simulated brake unit: the paper's results (Figs 8-10), the f32 run against
//! the f64 run, and the energy balance.

use std::sync::OnceLock;

use hils::scenario::{EbOptions, Run, run_eb};
use hils_brake_unit::BrakeDemand;
use hils_plant::{FrictionModel, Params, Rail};
use hils_sil::{ClosedLoop, KMH_PER_MPS, ParamFile};

fn params(model: FrictionModel) -> ParamFile {
    let mut p = ParamFile::default();
    p.plant.friction.model = model;
    p
}

fn run<F: hils_plant::Real>(model: FrictionModel) -> Run {
    let p = params(model);
    let mut opts = EbOptions::paper(&p);
    opts.record_every = 10;
    run_eb::<F>(&p, &opts).expect("run")
}

/// The four runs (variable and constant friction, f32 and f64), made once for every test.
struct Runs {
    variable_f32: Run,
    variable_f64: Run,
    constant_f32: Run,
    constant_f64: Run,
}

fn runs() -> &'static Runs {
    static R: OnceLock<Runs> = OnceLock::new();
    R.get_or_init(|| Runs {
        variable_f32: run::<f32>(FrictionModel::Variable),
        variable_f64: run::<f64>(FrictionModel::Variable),
        constant_f32: run::<f32>(FrictionModel::Constant),
        constant_f64: run::<f64>(FrictionModel::Constant),
    })
}

#[test]
fn constant_friction_no_wheelset_slides() {
    for run in [&runs().constant_f32, &runs().constant_f64] {
        let s = &run.summary;
        assert!(s.slides.is_empty(), "slides {:?}", s.slides);
        assert_eq!(s.slide_onset_s, [None; 4]);
        let stop = s.stop_time_s.expect("stops");
        assert!((26.0..=33.0).contains(&stop), "stop {stop}");
        assert_eq!(run.plant_flags, 0);
    }
}

#[test]
fn variable_friction_slides_on_wheelsets_2_and_4_only() {
    for run in [&runs().variable_f32, &runs().variable_f64] {
        let s = &run.summary;
        assert_eq!(s.slides, vec![2, 4], "onsets {:?}", s.slide_onset_s);
        for j in [1, 3] {
            let onset = s.slide_onset_s[j].expect("onset");
            assert!(
                (2.0..=6.0).contains(&onset),
                "wheelset {} onset {onset}",
                j + 1
            );
        }
        assert!(s.slide_onset_s[0].is_none() && s.slide_onset_s[2].is_none());
        let stop = s.stop_time_s.expect("stops");
        assert!((26.0..=33.0).contains(&stop), "stop {stop}");
        // The slides are real: the sliding wheels lag the vehicle by more than their
        // normal creep, the others never do.
        let max_deficit = |j: usize| {
            run.samples
                .iter()
                .filter(|x| x.v_ref_mps > 5.0)
                .map(|x| 1.0 - x.omega_radps[j] * 0.43 / x.v_ref_mps)
                .fold(0.0f64, f64::max)
        };
        assert!(max_deficit(1) > 0.06 && max_deficit(3) > 0.06);
        assert!(max_deficit(0) < 0.03 && max_deficit(2) < 0.03);
        // WSP keeps the wheels from locking: the longest lock is bounded (0.4 s).
        for lock in run.longest_lock_s {
            assert!(lock <= 0.4, "lock {lock} s");
        }
    }
}

#[test]
fn variable_mu_d_is_above_mu_d0_and_dips_in_the_middle() {
    let run = &runs().variable_f32;
    let stop = run.summary.stop_time_s.unwrap();
    let braking: Vec<_> = run.samples.iter().filter(|s| s.t_s <= stop).collect();
    let mu_d0 = 0.38;
    for s in &braking {
        for mu in s.mu_d {
            assert!(mu > mu_d0, "mu_d {mu} at {} s", s.t_s);
        }
    }
    // Fig 9: high at the start (cold disc), high at the end (low friction speed), lower in
    // between; the minimum lies well inside the stop.
    let mean = |s: &hils::scenario::Sample| s.mu_d.iter().sum::<f64>() / 4.0;
    let (i_min, min) = braking
        .iter()
        .enumerate()
        .map(|(i, s)| (i, mean(s)))
        .fold((0, f64::INFINITY), |a, b| if b.1 < a.1 { b } else { a });
    let start = mean(braking[0]);
    let end = mean(braking.last().unwrap());
    let t_min = braking[i_min].t_s;
    assert!(
        start > min + 0.015 && end > min + 0.03,
        "start {start}, min {min}, end {end}"
    );
    assert!(
        t_min > 0.2 * stop && t_min < 0.8 * stop,
        "minimum at {t_min} s of {stop}"
    );
    let s = &run.summary;
    assert!((s.mu_d_min - min).abs() < 2e-3);
    assert!(s.mu_d_at_s["0"] > s.mu_d_at_s["10"] && s.mu_d_at_s["20"] > s.mu_d_at_s["10"]);
}

#[test]
fn axle_loads_during_braking_are_lightest_on_wheelsets_2_and_4() {
    for run in [&runs().variable_f32, &runs().constant_f32] {
        let q = run.summary.axle_loads_3s_n.expect("the run reaches 3 s");
        let mut order = [0usize, 1, 2, 3];
        order.sort_by(|&a, &b| q[a].partial_cmp(&q[b]).unwrap());
        let lightest: std::collections::BTreeSet<_> = order[..2].iter().copied().collect();
        assert_eq!(lightest, [1usize, 3].into_iter().collect(), "loads {q:?}");
        let total: f64 = q.iter().sum();
        let weight = Params::default().total_mass() * 9.81;
        assert!((total - weight).abs() < 0.01 * weight, "total {total}");
        // During steady braking (10-20 s) the order holds throughout.
        for s in run.samples.iter().filter(|s| s.t_s > 10.0 && s.t_s < 20.0) {
            assert!(
                s.q_n[1].max(s.q_n[3]) < s.q_n[0].min(s.q_n[2]),
                "{:?} at {}",
                s.q_n,
                s.t_s
            );
        }
    }
}

#[test]
fn f32_run_matches_f64_run() {
    for (a, b) in [
        (&runs().variable_f32, &runs().variable_f64),
        (&runs().constant_f32, &runs().constant_f64),
    ] {
        let (sa, sb) = (&a.summary, &b.summary);
        let (da, db) = (
            sa.stopping_distance_m.unwrap(),
            sb.stopping_distance_m.unwrap(),
        );
        assert!(
            (da - db).abs() <= 1e-3 * db,
            "stopping distance f32 {da} vs f64 {db}"
        );
        assert_eq!(sa.slides, sb.slides);
        for j in 0..4 {
            match (sa.slide_onset_s[j], sb.slide_onset_s[j]) {
                (Some(x), Some(y)) => assert!((x - y).abs() <= 0.010, "onset {x} vs {y}"),
                (None, None) => {}
                other => panic!("wheelset {}: {other:?}", j + 1),
            }
        }
        // The whole trajectory: vehicle speed within 0.05 % of the initial speed.
        for (x, y) in a.samples.iter().zip(&b.samples) {
            assert!(
                (x.v_ref_mps - y.v_ref_mps).abs() < 5e-4 * 41.67,
                "{} vs {} at {}",
                x.v_ref_mps,
                y.v_ref_mps,
                x.t_s
            );
        }
    }
}

/// Kinetic energy lost = brake work + dissipation in contacts and dampers (+ spring energy
/// change), integrated over the run in f64.
fn energy_balance(model: FrictionModel) -> (f64, f64, f64, f64) {
    let p = params(model);
    let mut sim = ClosedLoop::<f64>::from_file(&p, Rail::Wet, 150.0 / KMH_PER_MPS).unwrap();
    sim.set_demand(BrakeDemand::Emergency);
    let e0 = sim.plant.energy();
    let dt = sim.plant.dt();
    let (mut brake, mut contact, mut damper, mut external) = (0.0, 0.0, 0.0, 0.0);
    for _ in 0..350_000 {
        sim.step();
        let o = sim.outputs();
        for w in &o.wheelsets {
            brake += w.brake_power * dt;
            contact += w.contact_power * dt;
        }
        damper += o.damper_power * dt;
        external += o.external_power * dt;
    }
    let e1 = sim.plant.energy();
    assert!(sim.outputs().vehicle_speed.abs() < 0.05, "stopped");
    let lost = (e0.kinetic + e0.potential) - (e1.kinetic + e1.potential) + external;
    (lost, brake, contact, damper)
}

#[test]
fn energy_balance_closes_within_one_percent() {
    for model in [FrictionModel::Variable, FrictionModel::Constant] {
        let (lost, brake, contact, damper) = energy_balance(model);
        let dissipated = brake + contact + damper;
        let ke0 = 0.5 * Params::default().effective_mass() * (150.0f64 / KMH_PER_MPS).powi(2);
        assert!(
            (lost - ke0).abs() < 0.01 * ke0,
            "lost {lost} vs initial KE {ke0}"
        );
        assert!(
            (lost - dissipated).abs() < 0.01 * lost,
            "{model:?}: lost {lost:.0} J, brake {brake:.0} + contact {contact:.0} + dampers {damper:.0}"
        );
        assert!(brake > 0.9 * lost && contact > 0.0 && damper > 0.0);
    }
}

#[test]
fn summary_has_the_documented_keys() {
    let json = serde_json::to_value(&&runs().variable_f32.summary).unwrap();
    let keys: Vec<&str> = json
        .as_object()
        .unwrap()
        .keys()
        .map(|k| k.as_str())
        .collect();
    let mut expected = vec![
        "stop_time_s",
        "stopping_distance_m",
        "slides",
        "slide_onset_s",
        "axle_loads_static_n",
        "axle_loads_3s_n",
        "mu_d_at_s",
        "mu_d_min",
        "mu_d_end",
        "peak_disc_temp_rise_c",
        "eb_pressure_pa",
        "steps",
        "wall_s",
    ];
    expected.sort();
    let mut keys = keys;
    keys.sort();
    assert_eq!(keys, expected);
    let mu_keys: Vec<_> = json["mu_d_at_s"]
        .as_object()
        .unwrap()
        .keys()
        .cloned()
        .collect();
    assert_eq!(mu_keys, vec!["0", "10", "20"]);
    assert_eq!(json["slide_onset_s"].as_array().unwrap().len(), 4);
}
