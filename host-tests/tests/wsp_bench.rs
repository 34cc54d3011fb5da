//! The WSP test bench (`hils wsp-test`, issue 13): the allowed distance against its closed
//! form, the metrics against hand-made traces, the default programme's runs against the
//! physics (no stop shorter than the adhesion allows), and bad programmes.

use std::path::Path;

use hils::wsp::metrics::{AllowedStop, AvailableAdhesion, Trace, judge, wheelset_offsets};
use hils::wsp::programme::{Criteria, Programme};
use hils_plant::track::ContactSets;
use hils_plant::{Params, Surface, Track};
use hils_sil::ParamFile;

fn allowed<'a>(adhesion: &'a AvailableAdhesion, track: &'a Track, demand: f64) -> AllowedStop<'a> {
    let p = Params::default();
    AllowedStop {
        adhesion,
        track,
        offsets: wheelset_offsets(&p),
        mass_ratio: p.total_mass() / p.effective_mass(),
        g: p.vehicle.g,
        demand_mps2: demand,
        response_s: 0.55,
    }
}

#[test]
fn allowed_distance_matches_the_closed_form_when_the_demand_limits() {
    // Dry rail: the adhesion exceeds the 1.0 m/s^2 demand at every speed, so the stop is
    // v0 t_r + v0^2 / (2 a).
    let p = Params::default();
    let adhesion = AvailableAdhesion::new(&p, &ContactSets::default());
    let track = Track::uniform(Surface::Dry);
    let stop = allowed(&adhesion, &track, 1.0);
    let v0: f64 = 30.0;
    let expected = v0 * 0.55 + v0 * v0 / 2.0;
    let got = stop.distance(v0);
    assert!((got / expected - 1.0).abs() < 1e-3, "{got} vs {expected}");
    // Very low rail: adhesion-limited, so longer than the demand allows and bounded by the
    // adhesion range of the set (0.025..0.035 g).
    let track = Track::uniform(Surface::VeryLow);
    let stop = allowed(&adhesion, &track, 1.0);
    let got = stop.distance(v0) - v0 * 0.55;
    let ratio = p.total_mass() / p.effective_mass();
    let (short, long) = (
        v0 * v0 / (2.0 * 0.036 * 9.81 * ratio),
        v0 * v0 / (2.0 * 0.024 * 9.81 * ratio),
    );
    assert!(got > short && got < long, "{short} < {got} < {long}");
}

/// A stop at constant 1 m/s^2 from 20 m/s sampled at 1 ms, wheelset 3 locked 0.5-0.8 s
/// and venting 0.5-1.0 s from 300 to 100 kPa, wheelset 4 venting 3.5 s without pressure.
fn hand_made_trace() -> Trace {
    let mut t = Trace::default();
    for k in 0..=20_000 {
        let time = k as f64 * 1e-3;
        let v = (20.0 - time).max(0.0);
        t.t_s.push(time);
        t.v_mps.push(v);
        t.x_m
            .push(20.0 * time.min(20.0) - 0.5 * time.min(20.0).powi(2));
        for j in 0..4 {
            let locked = j == 2 && (0.5..0.8).contains(&time);
            t.wheel_mps[j].push(if locked { 0.0 } else { v });
            let venting =
                (j == 2 && (0.5..1.0).contains(&time)) || (j == 3 && (2.0..5.5).contains(&time));
            t.venting[j].push(venting);
            let p = if j == 2 && venting {
                300e3 - 200e3 * (time - 0.5) / 0.5
            } else {
                300e3
            };
            t.p_cyl_pa[j].push(p);
        }
    }
    t
}

#[test]
fn metrics_of_a_hand_made_trace() {
    let p = Params::default();
    let adhesion = AvailableAdhesion::new(&p, &ContactSets::default());
    let track = Track::uniform(Surface::Dry);
    let c = Criteria::default();
    let v = judge(
        "hand",
        &hand_made_trace(),
        &allowed(&adhesion, &track, 1.0),
        &c,
    );
    // Stops (v <= 0.01 m/s) at 19.99 s, after 200 m.
    assert!((v.stopping_distance_m.unwrap() - 200.0).abs() < 0.05);
    assert!((v.stop_time_s.unwrap() - 19.99).abs() < 2e-3);
    // Lock of wheelset 3: 0.3 s, once; the others never.
    assert!((v.max_lock_s[2] - 0.3).abs() < 2e-3, "{:?}", v.max_lock_s);
    assert_eq!(v.lock_count, [0, 0, 1, 0]);
    // Air: 200 kPa vented from one 1.2 l cylinder = 1.2 * 200e3 / 101325 l (wheelset 4
    // vents without losing pressure: nothing).
    let air = 1.2 * 200e3 / 101_325.0;
    assert!(
        (v.air_consumption_l - air).abs() < 0.01 * air,
        "{}",
        v.air_consumption_l
    );
    // Wheelset 4 vented 3.5 s > the 3 s timer: one timer action.
    assert_eq!(v.wsp_timer_actions, 1);
    assert!(!v.passed);
    // Its slide: the lock is a deficit of 100 %.
    assert!((v.slide_onset_s[2].unwrap() - 0.5).abs() < 2e-3);
    assert_eq!(v.slide_onset_s[0], None);
}

fn programme_path() -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../programmes/wsp-low-adhesion.toml")
}

#[test]
fn default_programme_no_stop_beats_the_adhesion() {
    let programme = Programme::load(&programme_path()).unwrap();
    let runs = programme.runs(&ParamFile::default()).unwrap();
    assert!(runs.len() >= 6);
    for run in runs {
        let name = run.name.clone();
        let o = hils::wsp::run_one(run, &programme.criteria).unwrap();
        let v = &o.verdict;
        let ratio = v.distance_ratio.expect("stops");
        // The allowed distance is that of a perfect WSP: the simulated one (its brake
        // response included) cannot stop much shorter, and a working WSP stays close.
        assert!(ratio > 0.97 && ratio < 1.5, "{name}: ratio {ratio}");
        assert!(
            v.adhesion_utilisation > 0.5 && v.adhesion_utilisation < 1.05,
            "{name}: {}",
            v.adhesion_utilisation
        );
    }
}

#[test]
fn bad_programmes_are_refused_with_the_cause() {
    let dir = std::env::temp_dir().join(format!("wsp-bad-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let cases = [
        (
            "[[run]]\nname='a'\nspeed_kmh=100.0\ndemand='emergency'\ntrack='none'\n",
            "no track `none`",
        ),
        (
            "[tracks.t]\nbase='low'\n[[run]]\nname='a'\nspeed_kmh=100.0\ndemand='brake'\ntrack='t'\n",
            "demand",
        ),
        (
            "[tracks.t]\nbase='icy'\n[[run]]\nname='a'\nspeed_kmh=100.0\ndemand='emergency'\ntrack='t'\n",
            "icy",
        ),
        (
            "[tracks.t]\nbase='low'\n[[tracks.t.zone]]\nstart_m=10.0\nend_m=5.0\nsurface='dry'\n[[run]]\nname='a'\nspeed_kmh=100.0\ndemand='emergency'\ntrack='t'\n",
            "zone 1",
        ),
        (
            "[tracks.t]\nbase='low'\n[[run]]\nname='a'\nspeed_kmh=-3.0\ndemand='emergency'\ntrack='t'\n",
            "speed_kmh",
        ),
    ];
    for (i, (text, cause)) in cases.iter().enumerate() {
        let path = dir.join(format!("p{i}.toml"));
        std::fs::write(&path, text).unwrap();
        let err = Programme::load(&path)
            .and_then(|p| p.runs(&ParamFile::default()))
            .err()
            .unwrap_or_else(|| panic!("case {i} accepted"));
        let msg = format!("{err:#}");
        assert!(msg.contains(cause), "case {i}: {msg}");
    }
}

#[test]
fn degraded_adhesion_section_is_optional_and_checked() {
    use hils::params_file::parse_params;
    let reference = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/spec/reference-parameters.toml"),
    )
    .or_else(|_| std::fs::read_to_string("/work/shared/spec/reference-parameters.toml"))
    .unwrap();
    let off = parse_params(&reference, "reference").unwrap();
    assert!(!off.degraded_adhesion.enabled);
    let section = "\n[degraded_adhesion]\nenabled = true\nrecovered_mu_ratio = 1.5\n\
                   energy_scale_j_per_m = 800.0\ntime_constant_s = 0.2\ncell_length_m = 0.5\n";
    let on = parse_params(&(reference.clone() + section), "on").unwrap();
    assert!(on.degraded_adhesion.enabled);
    assert_eq!(on.degraded_adhesion.recovered_mu_ratio, 1.5);
    let bad = section.replace("1.5", "0.5");
    let err = parse_params(&(reference.clone() + &bad), "bad").unwrap_err();
    assert!(
        format!("{err}").contains("degraded_adhesion.recovered_mu_ratio"),
        "{err}"
    );
    let unknown = section.replace("enabled", "enable");
    assert!(parse_params(&(reference + &unknown), "unknown").is_err());
}
