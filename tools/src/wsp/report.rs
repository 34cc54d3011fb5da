//! The WSP bench report: the summary table (Markdown, also printed on the terminal), the
//! criteria with their limits, units and sources, per run the criteria, the per-wheelset
//! figures and plots: wheel speeds with the surface under wheelset 1 shaded (with its key),
//! cylinder pressures and valve states (SVG, the project's plotting).

use std::fmt::Write as _;
use std::path::PathBuf;

use anyhow::Result;
use hils_plant::Surface;
use hils_sil::KMH_PER_MPS;

use super::Outcome;
use super::metrics::{Criterion, Verdict};
use super::programme::Criteria;
use crate::outputs::OutDir;
use crate::plots::{Chart, Series, Style};

/// `x` with `decimals` decimals, `-` when absent.
fn opt(x: Option<f64>, decimals: usize) -> String {
    x.map_or("-".into(), |x| format!("{x:.decimals$}"))
}

/// A criterion's short name for people (the JSON names it by its metric key).
fn label(c: &Criterion) -> &'static str {
    let key = c.criterion.split_whitespace().next().unwrap_or("");
    match key {
        "stops" => "no stop",
        "distance_ratio" => "distance ratio",
        "max_lock_s" => "lock",
        "wsp_timer_actions" => "WSP timer",
        "air_consumption_l" => "air",
        "adhesion" => "adhesion reference",
        _ => "criterion",
    }
}

/// The verdict of a run for the table: `pass`, or `FAIL:` and the criteria that failed
/// (`not measured` where the metric was not measured, so the criterion was not judged).
pub fn verdict_cell(v: &Verdict) -> String {
    if v.passed {
        return "pass".into();
    }
    let failed: Vec<String> = v
        .criteria
        .iter()
        .filter(|c| !c.passed)
        .map(|c| {
            if c.criterion.contains("not measured") {
                format!("{} not measured", label(c))
            } else {
                label(c).to_string()
            }
        })
        .collect();
    format!("FAIL: {}", failed.join(", "))
}

/// The summary table (Markdown); `-`: not measured (or no stop).
pub fn table(verdicts: &[&Verdict]) -> String {
    let mut s = String::from(
        "| run | verdict | stop m | allowed m | ratio | utilisation | air l | max lock s | locks | timer |\n\
         |---|---|---:|---:|---:|---:|---:|---:|---:|---:|\n",
    );
    for v in verdicts {
        let lock = v.max_lock_s.iter().copied().fold(0.0, f64::max);
        let _ = writeln!(
            s,
            "| {} | {} | {} | {:.1} | {} | {:.3} | {} | {:.2} | {} | {} |",
            v.name,
            verdict_cell(v),
            opt(v.stopping_distance_m, 1),
            v.allowed_distance_m,
            opt(v.distance_ratio, 3),
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

/// The criteria and bench constants as a table: name, limit, unit, source ("assumed" where
/// no public text gives the figure; docs/wsp.md says why).
pub fn criteria_table(c: &Criteria) -> String {
    let rows = [
        (
            "distance ratio: stop / a perfect WSP's stop",
            format!("<= {}", c.max_distance_ratio),
            "-",
            "assumed (CEN/TR 17315 judges the stop against the adhesion available; no public limit)",
        ),
        (
            "longest lock of a wheelset",
            format!("<= {}", c.max_lock_s),
            "s",
            "assumed",
        ),
        (
            "WSP timer actions",
            format!("<= {}", c.max_wsp_timer_actions),
            "count",
            "assumed; the timer is EN 15595's, the unit's vent_max",
        ),
        (
            "air consumption (free air)",
            format!("<= {}", c.max_air_consumption_l),
            "l",
            "assumed: the usable air of a 150 l reservoir (docs/wsp.md)",
        ),
        (
            "WSP timer (continuous vent and hold)",
            format!("{}", c.wsp_timer_s),
            "s",
            "the unit under test (EN 15595 WSP timer)",
        ),
        (
            "locked: wheel speed below",
            format!("{}", c.lock_speed_ratio),
            "of the vehicle speed",
            "assumed",
        ),
        (
            "vented volume per wheelset",
            format!("{:.2}", c.channel_volume_l),
            "l",
            "[brake] cylinders, assumed stroke and pipe",
        ),
        (
            "evaluation ends below",
            format!("{}", c.min_speed_mps),
            "m/s",
            "the WSP's inhibit speed",
        ),
    ];
    let mut s = String::from("| criterion | limit | unit | source |\n|---|---:|---|---|\n");
    for (name, limit, unit, source) in rows {
        let _ = writeln!(s, "| {name} | {limit} | {unit} | {source} |");
    }
    s
}

/// A run's per-wheelset figures as a table: slide onset (`-`: never slid), longest lock and
/// lock count.
pub fn wheelset_table(v: &Verdict) -> String {
    let mut s = String::from("| wheelset | 1 | 2 | 3 | 4 |\n|---|---:|---:|---:|---:|\n");
    let onset: Vec<String> = v
        .slide_onset_s
        .iter()
        .map(|o| o.map_or("-".into(), |t| format!("{t:.2} s")))
        .collect();
    let lock: Vec<String> = v.max_lock_s.iter().map(|t| format!("{t:.2} s")).collect();
    let count: Vec<String> = v.lock_count.iter().map(|n| n.to_string()).collect();
    for (name, row) in [
        ("slide onset (creep past the adhesion peak)", onset),
        ("longest lock", lock),
        ("locks", count),
    ] {
        let _ = writeln!(s, "| {name} | {} |", row.join(" | "));
    }
    s
}

/// Palette index and name of each surface's shading.
fn surface_shade(s: Surface) -> (usize, &'static str) {
    match s {
        Surface::Dry => (2, "dry"),
        Surface::Wet => (0, "wet"),
        Surface::Low => (3, "low"),
        Surface::VeryLow => (1, "very low"),
    }
}

/// Time intervals during which the leading wheelset runs on each surface (shaded; palette
/// index per surface).
fn zone_shades(o: &Outcome) -> Vec<(f64, f64, usize)> {
    let t = &o.trace.t_s;
    let mut shades = Vec::new();
    let mut start = 0;
    for k in 1..=t.len() {
        let changed = k == t.len() || o.surfaces[k][0] != o.surfaces[start][0];
        if changed {
            shades.push((t[start], t[k - 1], surface_shade(o.surfaces[start][0]).0));
            start = k;
        }
    }
    shades
}

/// The key of the shading: one entry per surface the leading wheelset ran on.
fn shade_key(o: &Outcome) -> Vec<(String, usize)> {
    let mut key = Vec::new();
    for s in Surface::ALL {
        if o.surfaces.iter().any(|w| w[0] == s) {
            let (color, name) = surface_shade(s);
            key.push((format!("surface: {name}"), color));
        }
    }
    key
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

/// Writes the plots of one run (`STEM-speeds.svg`, `STEM-pressures.svg`,
/// `STEM-valves.svg`) into `dir`: called as each run is judged, so no trace is kept for the
/// report (memory does not grow with the number of runs).
pub fn write_run_plots(dir: &OutDir, stem: &str, o: &Outcome) -> Result<()> {
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
    speeds.shade_key = shade_key(o);
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
    speeds.save_svg(&dir.file(&format!("{stem}-speeds.svg"))?)?;

    let mut pressures = Chart::new(
        &format!("{}: cylinder pressures", o.run.name),
        "t, s",
        "p, kPa",
    );
    pressures.series = per_wheelset("cylinder", t, &o.trace.p_cyl_pa, 1e-3);
    pressures.save_svg(&dir.file(&format!("{stem}-pressures.svg"))?)?;

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
    valves.save_svg(&dir.file(&format!("{stem}-valves.svg"))?)?;
    Ok(())
}

/// Writes `report.md` of the judged runs into `dir` (their plots are written as each run
/// is judged, [`write_run_plots`]).
pub fn write(dir: &OutDir, verdicts: &[Verdict], criteria: &Criteria) -> Result<PathBuf> {
    let refs: Vec<&Verdict> = verdicts.iter().collect();
    let sections: Vec<(&str, &Verdict)> = verdicts.iter().map(|v| (v.name.as_str(), v)).collect();
    write_with(
        dir,
        "# WSP test report\n\n",
        &table(&refs),
        &sections,
        criteria,
    )
}

/// Writes `report.md` (`heading`, the criteria, `summary`, then a section per judged run
/// with the plots of its file stem) into `dir`.
pub fn write_with(
    dir: &OutDir,
    heading: &str,
    summary: &str,
    sections: &[(&str, &Verdict)],
    criteria: &Criteria,
) -> Result<PathBuf> {
    let mut md = String::from(heading);
    let _ = writeln!(md, "## Criteria\n\n{}", criteria_table(criteria));
    let _ = writeln!(md, "## Runs\n\n{summary}");
    for &(stem, v) in sections {
        let _ = writeln!(md, "\n## {stem}\n");
        for c in &v.criteria {
            let verdict = if c.passed { "pass" } else { "FAIL" };
            let _ = writeln!(md, "- {}: {verdict}", c.criterion);
        }
        let _ = writeln!(md, "\n{}", wheelset_table(v));
        for kind in ["speeds", "pressures", "valves"] {
            let _ = writeln!(md, "![{kind}]({stem}-{kind}.svg)");
        }
    }
    dir.write("report.md", md)
}
