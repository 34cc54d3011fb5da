//! The WSP test bench (`hils wsp-test`, issue 13): the allowed distance against its closed
//! form, the metrics against hand-made traces, the default programme's runs against the
//! physics (no stop shorter than the adhesion allows), and bad programmes.

use std::path::Path;

use hils::wsp::metrics::{
    AllowedStop, AvailableAdhesion, BrakeModel, MuFactors, Resistance, Trace, judge,
    wheelset_offsets,
};
use hils::wsp::programme::{Criteria, Programme};
use hils_plant::contact::Polach;
use hils_plant::track::ContactSets;
use hils_plant::{Params, Surface, Track};
use hils_sil::ParamFile;

fn allowed<'a>(adhesion: &'a AvailableAdhesion, track: &'a Track, demand: f64) -> AllowedStop<'a> {
    let p = Params::default();
    AllowedStop {
        adhesion,
        track,
        offsets: wheelset_offsets(&p),
        g: p.vehicle.g,
        resistance: Resistance::default(),
        brake: BrakeModel::Deceleration(demand),
        dead_time_s: 0.05,
        build_up_s: 0.5,
        mu_factor: None,
        recovers: false,
    }
}

#[test]
fn allowed_distance_matches_the_closed_form_when_the_demand_limits() {
    // Dry rail: the adhesion exceeds the 1.0 m/s^2 demand at every speed. The demand builds
    // up as a (1 - exp(-(t - t_d) / tau)) after the dead time; in closed form the stop is
    // v0 (t_d + tau) + v0^2 / (2 a) - a tau^2 / 2 (the exp term is ~0 at the stop). A long
    // tau makes the build-up term visible.
    let p = Params::default();
    let adhesion = AvailableAdhesion::new(&p, &ContactSets::default());
    let track = Track::uniform(Surface::Dry);
    let v0: f64 = 30.0;
    for (dead, tau) in [(0.05, 0.5), (0.3, 3.0)] {
        let mut stop = allowed(&adhesion, &track, 1.0);
        (stop.dead_time_s, stop.build_up_s) = (dead, tau);
        let expected = v0 * (dead + tau) + v0 * v0 / 2.0 - tau * tau / 2.0;
        let got = stop.distance(v0);
        assert!((got - expected).abs() < 0.05, "{got} vs {expected}");
    }
    // Davis resistance a + c v^2 alone (no brake: dead time beyond the stop) stops the
    // vehicle in x = M/(2c) ln(1 + c v0^2 / a) (closed form of v dv/dx = -(a + c v^2)/M).
    let (a, c, m) = (6000.0, 10.0, p.total_mass());
    let mut stop = allowed(&adhesion, &track, 1.0);
    stop.dead_time_s = 1e9;
    stop.resistance.davis_per_kg = [a / m, 0.0, c / m];
    let expected = m / (2.0 * c) * (1.0 + c * v0 * v0 / a).ln();
    let got = stop.distance(v0);
    assert!((got / expected - 1.0).abs() < 1e-3, "{got} vs {expected}");
}

/// Peak of F/Q over creepage of `surface` at `v`, found by golden-section search (an
/// independent check of the bench's grid table).
fn peak_adhesion(p: &Params, surface: Surface, v: f64) -> f64 {
    peak_of(p, surface, v).0
}

/// Peak of F/Q over creepage and the creepage of the peak (golden-section search).
fn peak_of(p: &Params, surface: Surface, v: f64) -> (f64, f64) {
    let sets = ContactSets::default();
    let polach = Polach::<f64>::with_set(&p.contact, &sets.set(&p.contact, surface));
    let q = p.total_mass() * p.vehicle.g / 4.0;
    let f = |s: f64| polach.adhesion_coefficient(s, v, q);
    let (mut lo, mut hi) = (1e-5_f64, 0.3_f64);
    let r = (5f64.sqrt() - 1.0) / 2.0;
    for _ in 0..80 {
        let (a, b) = (hi - r * (hi - lo), lo + r * (hi - lo));
        if f(a) < f(b) { lo = a } else { hi = b }
    }
    (f(0.5 * (lo + hi)), 0.5 * (lo + hi))
}

#[test]
fn adhesion_limit_is_mu_g_on_the_moving_mass() {
    // Rail forces decelerate the moving mass M (carbody, bogies, wheelsets; the spin
    // inertia is on the wheel side of the contact): a perfect WSP reaches g mu, not
    // g mu M / M_eff. On the very low rail with a demand that never limits, the stop is
    // the integral of v / (g mu(v)) dv with mu the curve's peak at each speed.
    let p = Params::default();
    let adhesion = AvailableAdhesion::new(&p, &ContactSets::default());
    let track = Track::uniform(Surface::VeryLow);
    for v in [3.0, 12.5, 27.0] {
        let mu = peak_adhesion(&p, Surface::VeryLow, v);
        let got = allowed(&adhesion, &track, 5.0).adhesion_decel(0.0, v);
        assert!(
            (got / (p.vehicle.g * mu) - 1.0).abs() < 2e-3,
            "{got} vs g {mu}"
        );
    }
    let mut stop = allowed(&adhesion, &track, 5.0);
    (stop.dead_time_s, stop.build_up_s) = (0.0, 0.0);
    let v0 = 30.0;
    let dv = 0.01;
    let expected: f64 = (0..(v0 / dv) as usize)
        .map(|i| {
            let v = (i as f64 + 0.5) * dv;
            v / (p.vehicle.g * peak_adhesion(&p, Surface::VeryLow, v)) * dv
        })
        .sum();
    let got = stop.distance(v0);
    assert!((got / expected - 1.0).abs() < 5e-3, "{got} vs {expected}");
}

#[test]
fn recovered_adhesion_is_the_reference_when_the_rail_recovers() {
    // With the logged friction factors (degraded adhesion on), the adhesion a perfect WSP
    // could use is the curve's peak times each wheelset's factor: factor 2 on every
    // wheelset doubles the adhesion-limited deceleration.
    let p = Params::default();
    let adhesion = AvailableAdhesion::new(&p, &ContactSets::default());
    let track = Track::uniform(Surface::Low);
    let x = vec![0.0, 10.0, 20.0];
    let factor = [
        vec![1.0, 2.0, 2.0],
        vec![1.0, 2.0, 2.0],
        vec![1.0, 2.0, 2.0],
        vec![1.0, 2.0, 2.0],
    ];
    let mut stop = allowed(&adhesion, &track, 5.0);
    let plain = stop.adhesion_decel(15.0, 20.0);
    stop.mu_factor = Some(MuFactors {
        x_m: &x,
        factor: &factor,
    });
    stop.recovers = true;
    assert!((stop.adhesion_decel(15.0, 20.0) / plain - 2.0).abs() < 1e-12);
    assert!((stop.adhesion_decel(5.0, 20.0) / plain - 1.0).abs() < 1e-12);
    // Without them a recovering rail cannot be judged: the verdict says why.
    stop.mu_factor = None;
    let v = judge(
        "recovering",
        &hand_made_trace(),
        &stop,
        &Criteria::default(),
    );
    assert!(!v.passed);
    assert!(
        v.criteria
            .iter()
            .any(|c| !c.passed && c.criterion.contains("adhesion reference")),
        "{:?}",
        v.criteria
    );
}

/// A stop at constant 1 m/s^2 from 20 m/s sampled at 1 ms, wheelset 3 locked 0.5-0.8 s
/// and venting 0.5-1.0 s from 300 to 100 kPa, wheelset 4 venting 3.5 s without pressure,
/// wheelset 1 venting 8-9 s, holding 9-9.5 s, venting 9.5-11.5 s (3.5 s without the brake),
/// wheelset 2 venting from 16.5 s to the end of the trace (still open).
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
            let venting = (j == 2 && (0.5..1.0).contains(&time))
                || (j == 3 && (2.0..5.5).contains(&time))
                || (j == 0 && ((8.0..9.0).contains(&time) || (9.5..11.5).contains(&time)))
                || (j == 1 && time >= 16.5);
            t.venting[j].push(venting);
            t.holding[j].push(j == 0 && (9.0..9.5).contains(&time));
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
    // The trace brakes at 1 m/s^2 from t = 0: the reference's brake does too.
    let mut stop = allowed(&adhesion, &track, 1.0);
    (stop.dead_time_s, stop.build_up_s) = (0.0, 0.0);
    let v = judge("hand", &hand_made_trace(), &stop, &c);
    // Stops (v <= 0.01 m/s) at 19.99 s, after 200 m.
    assert!((v.stopping_distance_m.unwrap() - 200.0).abs() < 0.05);
    assert!((v.stop_time_s.unwrap() - 19.99).abs() < 2e-3);
    // Lock of wheelset 3: 0.3 s, once; the others never.
    assert!((v.max_lock_s[2] - 0.3).abs() < 2e-3, "{:?}", v.max_lock_s);
    assert_eq!(v.lock_count, [0, 0, 1, 0]);
    // Air: 200 kPa vented from wheelset 3's channel: two caliper cylinders (4 friction
    // faces) of 0.0227 m^2 x 0.05 m stroke and a 0.5 l pipe = 2.77 l, so 2.77 l x 200 kPa /
    // 101.325 kPa = 5.468 l of free air (wheelsets 1, 2, 4 vent without losing pressure).
    let air = 2.77 * 200e3 / 101_325.0;
    let air_l = v.air_consumption_l.expect("air measured");
    assert!((air_l - air).abs() < 0.01 * air, "{air_l}");
    // WSP timer (3 s): wheelset 4's 3.5 s vent; wheelset 1's vent-hold-vent of 3.5 s (the
    // brake stays off throughout); wheelset 2's vent still open at the end (3.5 s).
    assert_eq!(v.wsp_timer_actions, Some(3));
    assert!(!v.passed);
    // Its slide: the lock is a deficit of 100 %.
    assert!((v.slide_onset_s[2].unwrap() - 0.5).abs() < 2e-3);
    assert_eq!(v.slide_onset_s[0], None);
    // Utilisation: on the dry rail the 1 m/s^2 demand limits, not the adhesion, and the
    // trace decelerates at 1 m/s^2: a working brake uses all of it (1.0, not a/(g mu)).
    assert!(
        (v.adhesion_utilisation - 1.0).abs() < 2e-3,
        "{}",
        v.adhesion_utilisation
    );
}

/// Judges `t` on a dry rail, 1 m/s^2 demand from t = 0 (an ideal brake, as the hand-made
/// traces brake), default criteria.
fn judge_on_dry(t: &Trace) -> hils::wsp::metrics::Verdict {
    let p = Params::default();
    let adhesion = AvailableAdhesion::new(&p, &ContactSets::default());
    let track = Track::uniform(Surface::Dry);
    let mut stop = allowed(&adhesion, &track, 1.0);
    (stop.dead_time_s, stop.build_up_s) = (0.0, 0.0);
    judge("dry", t, &stop, &Criteria::default())
}

#[test]
fn utilisation_counts_speed_rises() {
    // A trace that loses 1 m/s^2 but gains 5 m/s for 1 s in the middle (speed signal
    // jump): the speed actually lost is v(start) - v(end), rises included.
    let mut t = hand_made_trace();
    for k in 0..t.v_mps.len() {
        if (10.0..11.0).contains(&t.t_s[k]) {
            t.v_mps[k] += 5.0 * (t.t_s[k] - 10.0);
        } else if t.t_s[k] >= 11.0 {
            t.v_mps[k] = (t.v_mps[k] + 5.0).max(0.0);
        }
    }
    let v = judge_on_dry(&t);
    // The window runs from the response (0 s: an ideal brake) to the trace's end (20 s, at
    // 5 m/s, no stop): lost 20 - 5 = 15 m/s over 20 s of 1 m/s^2 (dropping the rise would
    // count 20 m/s lost instead).
    let expected = (20.0 - 5.0) / 20.0;
    assert!(
        (v.adhesion_utilisation - expected).abs() < 3e-3,
        "{} vs {expected}",
        v.adhesion_utilisation
    );
}

#[test]
fn log_gaps_are_filled_or_refused() {
    use hils::wsp::{MAX_GAP_S, fill_gaps};
    let t: Vec<f64> = (0..100).map(|k| k as f64 * 0.01).collect();
    // A 30 ms gap (3 samples) in a ramp is filled on the ramp and counted.
    let mut y: Vec<f64> = t.iter().map(|t| 10.0 - t).collect();
    for k in 40..43 {
        y[k] = f64::NAN;
    }
    let mut filled = vec![false; t.len()];
    fill_gaps(&t, &mut y, MAX_GAP_S, &mut filled).unwrap();
    assert_eq!(filled.iter().filter(|&&f| f).count(), 3);
    for k in 40..43 {
        assert!((y[k] - (10.0 - t[k])).abs() < 1e-9, "{}", y[k]);
    }
    // A 0.3 s gap is refused with its start time.
    for k in 50..80 {
        y[k] = f64::NAN;
    }
    let err = fill_gaps(&t, &mut y, MAX_GAP_S, &mut filled).unwrap_err();
    assert!((err - 0.5).abs() < 1e-9);
    // A column with no finite sample is refused.
    let mut all_nan = vec![f64::NAN; 5];
    assert!(fill_gaps(&t[..5], &mut all_nan, MAX_GAP_S, &mut vec![false; 5]).is_err());
}

#[test]
fn response_of_a_log_from_its_cylinder_pressures() {
    // p = P (1 - exp(-(t - 0.2) / 0.8)) after 0.2 s: the fit returns t_d 0.2 s, tau 0.8 s.
    let mut t = Trace::default();
    for k in 0..10_000 {
        let time = k as f64 * 1e-3;
        t.t_s.push(time);
        let p = if time > 0.2 {
            350e3 * (1.0 - (-(time - 0.2) / 0.8).exp())
        } else {
            0.0
        };
        for j in 0..4 {
            t.p_cyl_pa[j].push(p);
        }
    }
    let (dead, tau) = hils::wsp::response_of_log(&t, 350e3).unwrap();
    assert!(
        (dead - 0.2).abs() < 5e-3 && (tau - 0.8).abs() < 5e-3,
        "{dead} {tau}"
    );
    // A wheelset whose WSP acts (vents, or holds) before 63.2 % of the demand: its build-up
    // is not the brake's response; the others' still is. None when every wheelset's is cut.
    let acting_from = |k0: usize| (0..10_000).map(|k| k >= k0).collect::<Vec<bool>>();
    let mut cut = t.clone();
    cut.venting[0] = acting_from(500);
    cut.holding[1] = acting_from(500);
    let (dead_cut, tau_cut) = hils::wsp::response_of_log(&cut, 350e3).unwrap();
    assert!((dead_cut - dead).abs() < 1e-9 && (tau_cut - tau).abs() < 1e-9);
    for j in 0..4 {
        cut.venting[j] = acting_from(500);
    }
    assert!(hils::wsp::response_of_log(&cut, 350e3).is_none());
    // Not logged: no response (the parameter file's is used).
    assert!(
        hils::wsp::response_of_log(
            &Trace {
                t_s: t.t_s.clone(),
                ..Trace::default()
            },
            350e3
        )
        .is_none()
    );
}

#[test]
fn air_limit_is_the_usable_reservoir_air() {
    // The default programme's limit: a 150 l reservoir from the 500 kPa(g) supply down to
    // the laden EB cylinder pressure, at atmospheric pressure (isothermal).
    let p = Params::default();
    let file = ParamFile::default();
    let m_eff = p.effective_mass();
    let torque = m_eff * file.brake_unit.eb_deceleration_mps2 * p.vehicle.wheel_radius / 4.0;
    let b = &p.brake;
    let clamp = torque / (p.friction.mu_d0 * b.friction_radius * b.friction_faces as f64);
    let p_eb = (clamp / b.lever_ratio + b.retaining_spring_force) / b.piston_area;
    let usable = 150.0 * (b.supply_pressure - p_eb) / 101_325.0;
    let programme = Programme::load(&programme_path()).unwrap();
    let limit = programme.criteria.max_air_consumption_l;
    assert!(
        (limit / usable - 1.0).abs() < 0.01,
        "{limit} vs {usable} (p_EB {p_eb})"
    );
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
        no_stop_beats_the_adhesion(run, &programme.criteria);
    }
}

/// The allowed distance is that of a perfect WSP: the simulated one (its brake response
/// included) cannot stop shorter, and it cannot use more than all the adhesion.
fn no_stop_beats_the_adhesion(run: hils::wsp::programme::Run, criteria: &Criteria) {
    let name = run.name.clone();
    let o = hils::wsp::run_one(run, criteria).unwrap();
    let v = &o.verdict;
    let ratio = v.distance_ratio.expect("stops");
    assert!(ratio > 1.0 && ratio < 2.0, "{name}: ratio {ratio}");
    assert!(
        v.adhesion_utilisation > 0.5 && v.adhesion_utilisation <= 1.0,
        "{name}: {}",
        v.adhesion_utilisation
    );
}

#[test]
fn with_rail_cleaning_the_reference_is_the_cleaned_adhesion() {
    // [degraded_adhesion] on: the sliding wheelsets clean the rail and the stops shorten
    // (13-28 %). Judged against the uncleaned adhesion the ratios fell below 1 and the
    // utilisation above 1 (the bench measured the cleaning, not the WSP); against the
    // adhesion each wheelset actually had (logged friction factors) the WSP still cannot
    // beat a perfect one.
    let programme = Programme::load(&programme_path()).unwrap();
    let mut file = ParamFile::default();
    file.degraded_adhesion.enabled = true;
    let runs = programme.runs(&file).unwrap();
    for name in ["low-eb-120", "very-low-eb-60"] {
        let run = runs.iter().find(|r| r.name == name).unwrap().clone();
        no_stop_beats_the_adhesion(run, &programme.criteria);
    }
}

#[test]
fn bad_programmes_are_refused_with_the_cause() {
    let dir = std::env::temp_dir().join(format!("wsp-bad-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let cases = [
        (
            "[[run]]\nname='a'\nspeed_kmh=100.0\ndemand='emergency'\ntrack='none'\n",
            "no [tracks.none]",
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
    // The conditioning ring (128 cells) must span the vehicle's 16.5 m from the first to
    // the last wheelset with 8 cells to spare: 0.1375 m at least; 0.1 m cells (12.8 m)
    // would let the trailing wheelsets' cells collide with the leading ones'.
    let short = section.replace("cell_length_m = 0.5", "cell_length_m = 0.1");
    let err = parse_params(&(reference.clone() + &short), "short").unwrap_err();
    assert!(
        format!("{err}").contains("degraded_adhesion.cell_length_m"),
        "{err}"
    );
    let enough = section.replace("cell_length_m = 0.5", "cell_length_m = 0.14");
    assert!(parse_params(&(reference.clone() + &enough), "enough").is_ok());
    let unknown = section.replace("enabled", "enable");
    assert!(parse_params(&(reference + &unknown), "unknown").is_err());
}

#[test]
fn air_is_counted_on_the_valve_as_it_acts() {
    // The command vents 0.50-1.00 s; the cylinder feels it 50 ms later and falls from 300
    // to 100 kPa over 0.55-1.05 s. All 200 kPa leave through the dump valve: counted on the
    // acting valve (the command misses the last 50 ms, a quarter of the drop).
    let mut t = hand_made_trace();
    for k in 0..t.t_s.len() {
        let time = t.t_s[k];
        t.venting[2][k] = (0.5..1.0).contains(&time);
        t.p_cyl_pa[2][k] = 300e3 - 200e3 * ((time - 0.55) / 0.5).clamp(0.0, 1.0);
        for j in 0..4 {
            let acting = t.venting[j][k.saturating_sub(50)] && k >= 50;
            t.acting_vent[j].push(acting);
        }
    }
    let v = judge_on_dry(&t);
    let air = Criteria::default().channel_volume_l * 200e3 / 101_325.0;
    let air_l = v.air_consumption_l.expect("air measured");
    assert!((air_l / air - 1.0).abs() < 0.01, "{air_l} vs {air}");
}

#[test]
fn slide_onset_is_creep_beyond_the_adhesion_peak() {
    // Low rail, 20 m/s: from 2 s wheelset 1 creeps at 1.3 times the creepage of the curve's
    // peak (sliding: beyond the peak), wheelset 2 at 0.7 times (before the peak: no slide).
    // Both deficits are below the unit's own max(0.8 m/s, 6 % v) threshold, so the bench's onset
    // is independent of them.
    let p = Params::default();
    let adhesion = AvailableAdhesion::new(&p, &ContactSets::default());
    let track = Track::uniform(Surface::Low);
    let (_, s_peak) = peak_of(&p, Surface::Low, 20.0);
    assert!(
        1.3 * s_peak * 20.0 < (0.06f64 * 20.0).max(0.8),
        "peak creep {s_peak}"
    );
    let mut t = Trace::default();
    for k in 0..4000 {
        let time = k as f64 * 1e-3;
        t.t_s.push(time);
        t.v_mps.push(20.0);
        t.x_m.push(20.0 * time);
        for j in 0..4 {
            let creep = match j {
                0 if time >= 2.0 => 1.3 * s_peak,
                1 if time >= 2.0 => 0.7 * s_peak,
                _ => 0.0,
            };
            t.wheel_mps[j].push(20.0 * (1.0 - creep));
        }
    }
    let v = judge(
        "creep",
        &t,
        &allowed(&adhesion, &track, 1.0),
        &Criteria::default(),
    );
    assert!(
        (v.slide_onset_s[0].expect("slides") - 2.0).abs() < 2e-3,
        "{:?}",
        v.slide_onset_s
    );
    assert_eq!(v.slide_onset_s[1..], [None, None, None]);
}

/// The runs of a programme written out as TOML (in a temporary file), on the default
/// parameter file.
fn runs_of(name: &str, text: &str) -> (Vec<hils::wsp::programme::Run>, Criteria) {
    let dir = std::env::temp_dir().join(format!("wsp-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("programme.toml");
    std::fs::write(&path, text).unwrap();
    let programme = Programme::load(&path).unwrap();
    let runs = programme.runs(&ParamFile::default()).unwrap();
    (runs, programme.criteria)
}

#[test]
fn a_run_without_wsp_action_scores_one() {
    // Issue 25: where the WSP never acts and no wheel slides the brake has used all that
    // was asked of it, so the stop is the perfect WSP's and every adhesion it could use was
    // used. Before, the reference took the demand's nominal deceleration: EB on a dry rail
    // scored 0.94 / 1.07 (Eq (2)'s pad friction is above mu_d0), a 0.6 m/s^2 service brake
    // on the low rail 1.18 / 0.85 (the unit's service pressure left the retaining spring out).
    let (runs, criteria) = runs_of(
        "noslide",
        "[tracks.dry]\nbase = 'dry'\n[tracks.low]\nbase = 'low'\n\
         [[run]]\nname = 'dry-eb-120'\nspeed_kmh = 120.0\ndemand = 'emergency'\ntrack = 'dry'\n\
         [[run]]\nname = 'dry-service-120'\nspeed_kmh = 120.0\ndemand = 'service:0.8'\ntrack = 'dry'\n\
         [[run]]\nname = 'low-service-150'\nspeed_kmh = 150.0\ndemand = 'service:0.5'\ntrack = 'low'\n",
    );
    for run in runs {
        let name = run.name.clone();
        let o = hils::wsp::run_one(run, &criteria).unwrap();
        let acted = (0..4).any(|j| {
            o.trace.venting[j].iter().any(|&v| v) || o.trace.holding[j].iter().any(|&h| h)
        });
        assert!(!acted, "{name}: the WSP acted");
        let v = &o.verdict;
        let ratio = v.distance_ratio.expect("stops");
        assert!((ratio - 1.0).abs() < 0.02, "{name}: ratio {ratio}");
        assert!(
            (v.adhesion_utilisation - 1.0).abs() < 0.02,
            "{name}: utilisation {}",
            v.adhesion_utilisation
        );
        assert_eq!(v.air_consumption_l, Some(0.0), "{name}");
    }
}

#[test]
fn the_perfect_wsp_is_a_lower_bound_on_every_surface() {
    // EB from 120 km/h on each surface: no stop is shorter than the perfect WSP's (ratio
    // at least 1 within the integration's 0.5 %), none uses more than all the adhesion.
    let (runs, criteria) = runs_of(
        "bound",
        "[tracks.dry]\nbase = 'dry'\n[tracks.wet]\nbase = 'wet'\n[tracks.low]\nbase = 'low'\n\
         [tracks.very_low]\nbase = 'very_low'\n\
         [[run]]\nname = 'dry'\nspeed_kmh = 120.0\ndemand = 'emergency'\ntrack = 'dry'\n\
         [[run]]\nname = 'wet'\nspeed_kmh = 120.0\ndemand = 'emergency'\ntrack = 'wet'\n\
         [[run]]\nname = 'low'\nspeed_kmh = 120.0\ndemand = 'emergency'\ntrack = 'low'\n\
         [[run]]\nname = 'very_low'\nspeed_kmh = 120.0\ndemand = 'emergency'\ntrack = 'very_low'\n",
    );
    for run in runs {
        let name = run.name.clone();
        let v = hils::wsp::run_one(run, &criteria).unwrap().verdict;
        let ratio = v.distance_ratio.expect("stops");
        assert!(ratio > 0.995, "{name}: ratio {ratio}");
        assert!(
            v.adhesion_utilisation < 1.005,
            "{name}: utilisation {}",
            v.adhesion_utilisation
        );
    }
}

#[test]
fn pressure_memory_keeps_the_wheels_near_the_adhesion_peak() {
    // EB from 120 km/h on the low rail: once the first slides have set the memories (5 s),
    // each wheelset's pressure stays near the pressure at which its wheel slid (the WSP
    // reapplies to the memory and probes,
    // it does not dump to the bottom and refill), the wheels never fall far behind the
    // vehicle (no cycling between locked and rolling), and the stop is near a perfect WSP's.
    // The WSP of issue 13 vented each cycle from ~260 to ~80 kPa (0.3 of the median) and
    // let the wheels lose ~10 km/h (2.8 m/s).
    let programme = Programme::load(&programme_path()).unwrap();
    let run = programme
        .runs(&ParamFile::default())
        .unwrap()
        .into_iter()
        .find(|r| r.name == "low-eb-120")
        .unwrap();
    let o = hils::wsp::run_one(run, &programme.criteria).unwrap();
    let t = &o.trace;
    let after: Vec<usize> = (0..t.t_s.len())
        .filter(|&k| t.t_s[k] > 5.0 && t.v_mps[k] > 5.0)
        .collect();
    for j in 0..4 {
        let mut p: Vec<f64> = after.iter().map(|&k| t.p_cyl_pa[j][k]).collect();
        p.sort_by(f64::total_cmp);
        let median = p[p.len() / 2];
        let (low, high) = (p[0], p[p.len() - 1]);
        assert!(
            low > 0.6 * median && high < 1.4 * median,
            "wheelset {}: {low:.0}-{high:.0} Pa about {median:.0}",
            j + 1
        );
        // Slip velocity (the peak creep on this rail is 0.3-1.0 m/s from 5 to 44 m/s).
        let slip = after
            .iter()
            .map(|&k| t.v_mps[k] - t.wheel_mps[j][k])
            .fold(0.0f64, f64::max);
        assert!(slip < 1.5, "wheelset {}: slip {slip} m/s", j + 1);
    }
    let v = &o.verdict;
    assert!(v.passed, "{:?}", v.criteria);
    assert!(v.distance_ratio.unwrap() < 1.15 && v.adhesion_utilisation > 0.87);
}

#[test]
fn a_dry_patch_is_followed_back_to_the_full_demand() {
    // EB from 120 km/h on the low rail with a dry stretch from 200 m to 400 m: within a few
    // tenths of a second after wheelset 1 reaches it its WSP gives the full demand back (no
    // more hold or vent on the patch), and the cylinder then fills with the relay's lag
    // (0.5 s) to the EB pressure.
    let (runs, criteria) = runs_of(
        "drypatch",
        "[tracks.patch]\nbase = 'low'\n[[tracks.patch.zone]]\nstart_m = 200.0\nend_m = 400.0\n\
         surface = 'dry'\n[[run]]\nname = 'patch'\nspeed_kmh = 120.0\ndemand = 'emergency'\n\
         track = 'patch'\n",
    );
    let run = runs.into_iter().next().unwrap();
    let eb =
        hils_brake_unit::eb_pressure(&run.file.plant, run.file.brake_unit.eb_deceleration_mps2);
    let o = hils::wsp::run_one(run, &criteria).unwrap();
    let t = &o.trace;
    let k_in = t.x_m.iter().position(|&x| x >= 200.0).unwrap();
    // Wheelset 1 leaves the patch when the leading wheelset passes 400 m.
    let k_out = t.x_m.iter().position(|&x| x >= 400.0).unwrap();
    let t_in = t.t_s[k_in];
    let last_action = (k_in..k_out)
        .filter(|&k| t.venting[0][k] || t.holding[0][k])
        .map(|k| t.t_s[k])
        .fold(t_in, f64::max);
    assert!(
        last_action - t_in < 0.4,
        "wheelset 1 still held or vented {:.3} s into the patch",
        last_action - t_in
    );
    let full = (k_in..k_out)
        .find(|&k| t.p_cyl_pa[0][k] > 0.9 * eb)
        .map(|k| t.t_s[k] - t_in)
        .expect("back at 90 % of the EB pressure on the patch");
    assert!(full < 1.4, "90 % of EB {full:.3} s into the patch");
    let v = &o.verdict;
    assert!(v.distance_ratio.unwrap() < 1.15, "{:?}", v.distance_ratio);
}

#[test]
fn the_report_names_what_failed_and_rounds_its_figures() {
    // The hand-made trace fails the lock (none: 0.3 s < 1 s) ... it fails the WSP timer
    // (3 actions) and passes the rest on a dry rail.
    let v = judge_on_dry(&hand_made_trace());
    let row = hils::wsp::report::table(&[&v]);
    assert!(row.contains("| FAIL: WSP timer |"), "{row}");
    // No criterion that does not apply: the rail does not recover here.
    assert!(
        v.criteria
            .iter()
            .all(|c| !c.criterion.contains("adhesion reference")),
        "{:?}",
        v.criteria
    );
    // JSON figures at their resolution: mm, ms, 1e-4, 0.1 l.
    let json = serde_json::to_value(&v).unwrap();
    let decimals = |x: &serde_json::Value| {
        let s = x.to_string();
        s.split_once('.').map_or(0, |(_, d)| d.len())
    };
    assert!(decimals(&json["stopping_distance_m"]) <= 3, "{json}");
    assert!(decimals(&json["allowed_distance_m"]) <= 3, "{json}");
    assert!(decimals(&json["adhesion_utilisation"]) <= 4, "{json}");
    assert!(decimals(&json["air_consumption_l"]) <= 1, "{json}");
    assert!(decimals(&json["max_lock_s"][2]) <= 3, "{json}");
    // The criteria as a table with units and sources; per-wheelset figures as numbers.
    let criteria = hils::wsp::report::criteria_table(&Criteria::default());
    assert!(
        criteria.contains("| air consumption (free air) | <= 214.1 | l |"),
        "{criteria}"
    );
    let wheelsets = hils::wsp::report::wheelset_table(&v);
    assert!(wheelsets.contains("| - | - | 0.50 s | - |"), "{wheelsets}");
    assert!(!wheelsets.contains("Some("), "{wheelsets}");
}
