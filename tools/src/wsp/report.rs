//! The WSP bench report: a summary table (Markdown) and, per run, wheel speeds with the
//! adhesion zones shaded, cylinder pressures and valve states (SVG, the project's plotting).

use std::fmt::Write as _;
use std::path::Path;

use anyhow::{Context, Result};
use hils_plant::Surface;
use hils_sil::KMH_PER_MPS;

use super::Outcome;
use super::metrics::Verdict;
use super::programme::Criteria;
use crate::plots::{Chart, Series, Style};

fn opt(x: Option<f64>, decimals: usize) -> String {
    x.map_or("-".into(), |x| format!("{x:.decimals$}"))
}

/// The summary table (Markdown); `-`: not measured (or no stop).
pub fn table(verdicts: &[&Verdict]) -> String {
    let mut s = String::from(
        "| run | passed | stop m | allowed m | ratio | utilisation | air l | max lock s | locks | timer |\n\
         |---|---|---|---|---|---|---|---|---|---|\n",
    );
    for v in verdicts {
        let lock = v.max_lock_s.iter().copied().fold(0.0, f64::max);
        let _ = writeln!(
            s,
            "| {} | {} | {} | {:.1} | {} | {:.2} | {} | {:.2} | {} | {} |",
            v.name,
            if v.passed { "yes" } else { "NO" },
            opt(v.stopping_distance_m, 1),
            v.allowed_distance_m,
            opt(v.distance_ratio, 2),
            v.adhesion_utilisation,
            opt(v.air_consumption_l, 1),
            lock,
            v.lock_count.iter().sum::<u32>(),
            v.wsp_timer_actions
                .map_or("-".to_string(), |t| t.to_string())
        );
    }
    s
}

/// Time intervals during which the leading wheelset runs on each surface other than the
/// most common one (shaded; palette index per surface).
fn zone_shades(o: &Outcome) -> Vec<(f64, f64, usize)> {
    let t = &o.trace.t_s;
    let mut shades = Vec::new();
    let mut start = 0;
    for k in 1..=t.len() {
        let changed = k == t.len() || o.surfaces[k][0] != o.surfaces[start][0];
        if changed {
            let s = o.surfaces[start][0];
            let color = match s {
                Surface::Dry => 2,
                Surface::Wet => 0,
                Surface::Low => 3,
                Surface::VeryLow => 1,
            };
            shades.push((t[start], t[k - 1], color));
            start = k;
        }
    }
    shades
}

fn per_wheelset(name: &str, t: &[f64], y: &[Vec<f64>; 4], scale: f64) -> Vec<Series> {
    (0..4)
        .filter(|&j| y[j].len() == t.len())
        .map(|j| {
            let pts = t.iter().zip(&y[j]).map(|(&t, &v)| (t, v * scale)).collect();
            Series::new(format!("{name} {}", j + 1), pts, Style::Solid, j + 1)
        })
        .collect()
}

fn run_plots(dir: &Path, o: &Outcome) -> Result<()> {
    let t = &o.trace.t_s;
    let mut speeds = Chart::new(
        &format!(
            "{}: wheel speeds (shaded: surface under wheelset 1)",
            o.run.name
        ),
        "t, s",
        "speed, km/h",
    );
    speeds.shades = zone_shades(o);
    let v = t
        .iter()
        .zip(&o.trace.v_mps)
        .map(|(&t, &v)| (t, v * KMH_PER_MPS))
        .collect();
    speeds
        .series
        .push(Series::new("vehicle", v, Style::Dashed, 7));
    speeds
        .series
        .extend(per_wheelset("wheelset", t, &o.trace.wheel_mps, KMH_PER_MPS));
    speeds.save_svg(&dir.join(format!("{}-speeds.svg", o.run.name)))?;

    let mut pressures = Chart::new(
        &format!("{}: cylinder pressures", o.run.name),
        "t, s",
        "p, kPa",
    );
    pressures.series = per_wheelset("cylinder", t, &o.trace.p_cyl_pa, 1e-3);
    pressures.save_svg(&dir.join(format!("{}-pressures.svg", o.run.name)))?;

    let mut valves = Chart::new(
        &format!("{}: WSP valve commands (wheelset j at level j)", o.run.name),
        "t, s",
        "wheelset (+0.3 hold, +0.6 vent)",
    );
    let states: [Vec<f64>; 4] = std::array::from_fn(|j| {
        (0..o.trace.venting[j].len())
            .map(|k| {
                let hold = o.trace.holding[j].get(k).copied().unwrap_or(false);
                let raise = if o.trace.venting[j][k] {
                    0.6
                } else if hold {
                    0.3
                } else {
                    0.0
                };
                j as f64 + 1.0 + raise
            })
            .collect()
    });
    valves.series = per_wheelset("valve", t, &states, 1.0);
    valves.y_range = Some((0.5, 5.0));
    valves.save_svg(&dir.join(format!("{}-valves.svg", o.run.name)))?;
    Ok(())
}

/// Writes `report.md` and the plots of every run into `dir`.
pub fn write(dir: &Path, outcomes: &[Outcome], criteria: &Criteria) -> Result<()> {
    let verdicts: Vec<&Verdict> = outcomes.iter().map(|o| &o.verdict).collect();
    write_with(
        dir,
        "# WSP test report\n\n",
        &table(&verdicts),
        outcomes,
        criteria,
    )
}

/// Writes `report.md` (`heading`, the criteria, `summary`, then a section per outcome) and
/// the plots of every outcome (files named after `run.name`) into `dir`.
pub fn write_with(
    dir: &Path,
    heading: &str,
    summary: &str,
    outcomes: &[Outcome],
    criteria: &Criteria,
) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let mut md = String::from(heading);
    let _ = writeln!(md, "Criteria: {criteria:?}\n");
    md.push_str(summary);
    for o in outcomes {
        run_plots(dir, o)?;
        let v = &o.verdict;
        let _ = writeln!(md, "\n## {}\n", o.run.name);
        for c in &v.criteria {
            let verdict = if c.passed { "pass" } else { "FAIL" };
            let _ = writeln!(md, "- {}: {verdict}", c.criterion);
        }
        let _ = writeln!(
            md,
            "- slide onsets s: {:?}; max lock s: {:?}; locks: {:?}\n",
            v.slide_onset_s
                .map(|x| x.map(|x| (x * 1000.0).round() / 1000.0)),
            v.max_lock_s.map(|x| (x * 1000.0).round() / 1000.0),
            v.lock_count
        );
        for kind in ["speeds", "pressures", "valves"] {
            let _ = writeln!(md, "![{kind}]({}-{kind}.svg)", o.run.name);
        }
    }
    crate::outputs::write_file(&dir.join("report.md"), md)
}
