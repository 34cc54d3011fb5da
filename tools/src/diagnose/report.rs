//! The human report of `hils diagnose`: where and when the baseline's error grows, what it
//! goes with, the slides, measured vs baseline vs extended plots, and one paragraph naming
//! the cause.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use hils_plant::WHEELSETS;
use hils_sil::KMH_PER_MPS;

use super::analysis::{RunAnalysis, UNITS, VARIABLES};
use super::json::{Report, Tried};
use super::outcome::Outcome;
use super::replay::{Group, Prepared, Quantity, Replay};
use crate::figures::list_text;
use crate::plots::{Chart, Series, Style};

fn words_for(a: &RunAnalysis) -> String {
    let mut s = String::new();
    if a.points.is_empty() {
        return "No braking interval without slides was long enough to relate the error to the \
                operating point."
            .into();
    }
    let pct = a.mean_relative_decel_error * 100.0;
    let _ = write!(
        s,
        "While braking, the baseline decelerates {:.1} % {} than measured on average. ",
        pct.abs(),
        if pct < 0.0 { "less" } else { "more" }
    );
    if let Some(t) = a.first_exceed_s {
        let _ = write!(
            s,
            "Its speed error exceeds three times the noise from {t:.2} s; "
        );
    }
    let _ = write!(
        s,
        "the largest speed error is {:.3} m/s at {:.2} s. ",
        a.max_error.1, a.max_error.0
    );
    let strong: Vec<String> = a
        .correlations
        .iter()
        .filter(|(_, r)| r.abs() >= 0.5)
        .take(3)
        .map(|(name, r)| {
            // Relative deceleration error < 0: the model brakes too weakly. A negative
            // correlation with x: the shortfall grows as x rises.
            let dir = if *r < 0.0 { "rises" } else { "falls" };
            format!("the braking shortfall grows as the {name} {dir} (r = {r:.2})")
        })
        .collect();
    let strong: Vec<String> = strong
        .into_iter()
        .enumerate()
        .map(|(i, t)| if i == 0 { format!("T{}", &t[1..]) } else { t })
        .collect();
    if strong.is_empty() {
        s += "The deceleration error goes with none of friction speed, disc temperature, vehicle speed, \
              clamp force, time or creepage (all |r| < 0.5).";
    } else {
        s += &strong.join("; ");
        s += ".";
    }
    s
}

/// The paragraph that names the cause.
pub fn cause_paragraph(out: &Outcome) -> String {
    let r = &out.report;
    if !r.discrepancy {
        return format!(
            "No discrepancy: the baseline replays the measured runs within their noise \
             (validation error {:.2} times the noise level, {:.4} m/s on the speeds), so no cause is named.",
            r.gain.baseline, r.gain.speed_rms_mps["baseline"]
        );
    }
    if r.causes.is_empty() {
        return format!(
            "The baseline does not explain the data (validation error {:.1} times the noise), and none of \
             the listed effects, alone or combined, explains it: {:.0} % of the error stays unexplained. \
             No cause is claimed;{} the plots below show where and when the error grows.",
            r.gain.baseline,
            r.unexplained_share * 100.0,
            wheelset_differences(r)
        );
    }
    let mut s = String::from("The cause: ");
    let parts: Vec<String> = out
        .result
        .effects
        .iter()
        .zip(&out.result.x)
        .map(|(e, x)| {
            let keys: Vec<&str> = e
                .params(&out.baseline_params, out.runs[0].rail)
                .into_iter()
                .map(|(k, _)| k)
                .collect();
            let values: Vec<String> = keys
                .iter()
                .zip(x)
                .map(|(k, v)| format!("{k} = {v:.4}"))
                .collect();
            format!("{} — {} ({})", e.name(), e.describe(), values.join(", "))
        })
        .collect();
    s += &parts.join("; and ");
    let _ = write!(
        s,
        ". With {} the replay error on validation data falls from {:.2} to {:.2} times the noise \
         ({:.4} to {:.4} m/s on the speeds), a reduction of {:.1} %; {:.1} % of the baseline's excess \
         error stays unexplained.",
        if r.causes.len() > 1 {
            "these effects"
        } else {
            "this effect"
        },
        r.gain.baseline,
        r.gain.extended,
        r.gain.speed_rms_mps["baseline"],
        r.gain.speed_rms_mps["extended"],
        r.gain.reduction * 100.0,
        r.unexplained_share * 100.0
    );
    let missed: Vec<usize> = r
        .slides
        .measured
        .iter()
        .copied()
        .filter(|j| !r.slides.baseline.contains(j))
        .collect();
    if !missed.is_empty() {
        let _ = write!(
            s,
            " The baseline misses the wheel slide of wheelset(s) {}; the extended model {}.",
            list_text(&missed),
            if missed.iter().all(|j| r.slides.extended.contains(j)) {
                "reproduces it".to_string()
            } else {
                format!("shows slides on {}", list_text(&r.slides.extended))
            }
        );
    }
    for g in &r.confounded {
        let _ = write!(
            s,
            " The data cannot tell {} apart: treat them as alternatives.",
            g.join(" and ")
        );
    }
    s
}

/// The differences of single wheelsets the localisation found, in words (empty if none).
fn wheelset_differences(r: &Report) -> String {
    let found: Vec<String> = r
        .localisation
        .iter()
        .filter(|l| !l.explained && l.wheelset.is_some())
        .filter_map(|l| l.note.split_once(": no listed effect explains it: "))
        .map(|(_, size)| size.to_string())
        .collect();
    if found.is_empty() {
        String::new()
    } else {
        format!(" where it sits: {};", found.join("; "))
    }
}

fn t_series(run: &Prepared, y: &[f64], scale: f64) -> Vec<(f64, f64)> {
    run.bin_time
        .iter()
        .zip(y)
        .filter(|(_, v)| v.is_finite())
        .map(|(t, v)| (*t, v * scale))
        .collect()
}

/// The localisation list as the report's lead: one line per link of the signal chain.
/// Adds a measured channel and the baseline's and the extended model's replays of it, in
/// that order (palette 7, 1, 2; the baseline dashed, the extended model in `extended`).
fn add_measured_and_models(c: &mut Chart, points: [Vec<(f64, f64)>; 3], extended: Style) {
    let looks = [
        ("measured", Style::Solid, 7),
        ("baseline", Style::Dashed, 1),
        ("extended", extended, 2),
    ];
    for ((name, style, color), p) in looks.into_iter().zip(points) {
        c.series.push(Series::new(name, p, style, color));
    }
}

/// Saves a chart as `path`, links it in the report with `alt` text and `caption` after it,
/// and lists the file.
fn embed_chart(
    c: &Chart,
    path: PathBuf,
    alt: &str,
    caption: &str,
    md: &mut String,
    files: &mut Vec<PathBuf>,
) -> Result<()> {
    c.save_svg(&path)?;
    let name = path.file_name().unwrap().to_string_lossy();
    let _ = writeln!(md, "![{alt}]({name}){caption}\n");
    files.push(path);
    Ok(())
}

fn localisation_table(links: &[super::links::LinkCheck]) -> String {
    let mut md = String::from(
        "## Where along the signal chain\n\n| link | channels | baseline error (x noise) | extended error | explained | note |\n|---|---|---|---|---|---|\n",
    );
    for l in links {
        let name = match l.wheelset {
            Some(w) => format!("{} (wheelset {w})", l.link),
            None => l.link.clone(),
        };
        let _ = writeln!(
            md,
            "| {name} | {} | {:.2} | {:.2} | {} | {} |",
            l.channels.join(", "),
            l.baseline_error,
            l.extended_error,
            if l.explained { "yes" } else { "**no**" },
            l.note
        );
    }
    md + "\n"
}

/// One run's part of the report being written: the run, its analysis and replays, the
/// directory and the file-name prefix of its plots.
struct RunPage<'a> {
    dir: &'a Path,
    tag: String,
    run: &'a Prepared,
    a: &'a RunAnalysis,
    base: &'a Replay,
    ext: &'a Replay,
}

impl RunPage<'_> {
    /// Saves chart `c` as `{tag}{file}` and embeds it in `md`.
    fn embed(
        &self,
        c: &Chart,
        file: &str,
        alt: &str,
        caption: &str,
        md: &mut String,
        files: &mut Vec<PathBuf>,
    ) -> Result<()> {
        let f = self.dir.join(format!("{}{file}", self.tag));
        embed_chart(c, f, alt, caption, md, files)
    }
}

/// Writes report.md with its SVG plots into `dir`; returns the files written.
pub fn write(dir: &Path, out: &Outcome) -> Result<Vec<PathBuf>> {
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let mut files = Vec::new();
    let r = &out.report;
    let mut md = String::from("# Diagnosis\n\n");
    let _ = writeln!(
        md,
        "Baseline `{}`; runs: {}.\n",
        r.baseline,
        r.files.join(", ")
    );
    md += &localisation_table(&r.localisation);
    md += &cause_paragraph(out);
    md += &result_section(r);
    md += "## What is wrong: where and when the baseline's error grows\n\n";
    for (i, (run, a)) in out.runs.iter().zip(&out.analysis.runs).enumerate() {
        let page = RunPage {
            dir,
            tag: if out.runs.len() > 1 {
                format!("run{}_", i + 1)
            } else {
                String::new()
            },
            run,
            a,
            base: &out.baseline_replays[i],
            ext: &out.extended_replays[i],
        };
        run_section(&page, &mut md, &mut files)?;
    }
    if !r.notes.is_empty() {
        md += "## Notes (skipped, repaired, unused)\n\n";
        for n in &r.notes {
            let _ = writeln!(md, "- {n}");
        }
        md += "\n";
    }
    let f = dir.join("report.md");
    crate::outputs::write_file(&f, md)?;
    files.push(f);
    Ok(files)
}

/// The result list, the findings table and every effect tried.
fn result_section(r: &Report) -> String {
    let mut md = String::from("\n\n## Result\n\n");
    let _ = writeln!(
        md,
        "- discrepancy: **{}**\n- causes: {}\n- confounded: {}\n- unexplained share: {:.3}\n- gain ({}): baseline {:.3}, extended {:.3}, reduction {:.3}\n- speeds alone: baseline {:.4} m/s, extended {:.4} m/s\n- slides: measured {}, baseline {}, extended {}\n",
        r.discrepancy,
        if r.causes.is_empty() {
            "none".into()
        } else {
            r.causes.join(", ")
        },
        if r.confounded.is_empty() {
            "none".to_string()
        } else {
            r.confounded
                .iter()
                .map(|g| g.join(" / "))
                .collect::<Vec<_>>()
                .join("; ")
        },
        r.unexplained_share,
        r.gain.metric,
        r.gain.baseline,
        r.gain.extended,
        r.gain.reduction,
        r.gain.speed_rms_mps["baseline"],
        r.gain.speed_rms_mps["extended"],
        list_text(&r.slides.measured),
        list_text(&r.slides.baseline),
        list_text(&r.slides.extended)
    );
    if !r.findings.is_empty() {
        md += "| effect | parameter | value | 95 % CI | gain alone |\n|---|---|---|---|---|\n";
        for f in &r.findings {
            for (k, v) in &f.params {
                let [lo, hi] = f.ci95[k];
                let _ = writeln!(
                    md,
                    "| {} | {k} | {v:.5} | [{lo:.5}, {hi:.5}] | {:.3} |",
                    f.effect, f.gain
                );
            }
        }
        md += "\n";
    }
    md += &tried_table(&r.tried);
    md
}

/// Every effect fitted alone, on validation data.
fn tried_table(tried: &[Tried]) -> String {
    let mut md = String::new();
    if !tried.is_empty() {
        md += "## Every effect fitted alone (validation data)\n\n| effect | parameters | validation error (x noise) | gain |\n|---|---|---|---|\n";
        for t in tried {
            let p: Vec<String> = t
                .params
                .iter()
                .map(|(k, v)| format!("{k} = {v:.4}"))
                .collect();
            let _ = writeln!(
                md,
                "| {} | {} | {:.3} | {:.3} |",
                t.effect,
                p.join(", "),
                t.validation_rms,
                t.gain
            );
        }
        md += "\n";
    }
    md
}

/// One run: its text and table, then its plots.
fn run_section(p: &RunPage, md: &mut String, files: &mut Vec<PathBuf>) -> Result<()> {
    let rb = super::replay::channel_rms(p.run, p.base);
    *md += &run_text(p, &rb);
    speed_charts(p, md, files)?;
    wheel_charts(p, md, files)?;
    residual_charts(p, md, files)?;
    mu_d_chart(p, md, files)?;
    group_charts(p, &rb, md, files)
}

/// A run's conditions, what its error goes with, its slides and its channel errors.
fn run_text(p: &RunPage, rb: &[(Quantity, f64, f64)]) -> String {
    let (run, a) = (p.run, p.a);
    let mut md = String::new();
    let _ = writeln!(md, "### {}\n", run.name);
    let _ = writeln!(
        md,
        "Initial speed {:.2} km/h (measured), rail {}{}, {} samples over {:.2} s, replay step {} ms, comparison bins of {} ms (every third 0.2 s block is validation data).\n",
        run.v0 * KMH_PER_MPS,
        super::replay::rail_name(run.rail),
        if run.rail_from_metadata {
            " (metadata)"
        } else {
            " (baseline scenario: no `rail` metadata)"
        },
        run.t.len(),
        run.duration,
        run.dt * 1e3,
        run.bin_s * 1e3
    );
    md += &words_for(a);
    md += "\n\n";
    if !a.measured_slides.is_empty() {
        md += "Measured slides (wheel speed deficit beyond max(0.5 m/s, 5 %)):\n\n| wheelset | from s | to s |\n|---|---|---|\n";
        for (j, s, e) in &a.measured_slides {
            let _ = writeln!(md, "| {j} | {s:.2} | {e:.2} |");
        }
        md += "\n";
    }
    md += "| quantity | baseline rms | extended rms | noise (sample) |\n|---|---|---|---|\n";
    let re = super::replay::channel_rms(run, p.ext);
    for ((q, b, noise), (_, e, _)) in rb.iter().zip(&re) {
        let _ = writeln!(
            md,
            "| {} ({}) | {b:.4} | {e:.4} | {noise:.4} |",
            q.label(),
            q.unit()
        );
    }
    md += "\n";
    md
}

/// Vehicle speed, and the speed errors of both models.
fn speed_charts(p: &RunPage, md: &mut String, files: &mut Vec<PathBuf>) -> Result<()> {
    let (run, base, ext) = (p.run, p.base, p.ext);
    let mut c = Chart::new(
        &format!("{}: vehicle speed", run.name),
        "time, s",
        "v_ref, km/h",
    );
    let kmh = |y: &[f64]| t_series(run, y, KMH_PER_MPS);
    add_measured_and_models(
        &mut c,
        [kmh(&run.v_bin), kmh(&base.v_bin), kmh(&ext.v_bin)],
        Style::Dotted,
    );
    p.embed(&c, "v_ref.svg", "vehicle speed", "", md, files)?;

    let mut c = Chart::new(
        &format!("{}: speed error, model - measured", run.name),
        "time, s",
        "error, m/s",
    );
    let err = |m: &[f64]| -> Vec<(f64, f64)> {
        (0..run.n_bins)
            .filter(|&b| m[b].is_finite() && run.v_bin[b].is_finite())
            .map(|b| (run.bin_time[b], m[b] - run.v_bin[b]))
            .collect()
    };
    c.series.push(Series::new(
        "v_ref, baseline",
        err(&base.v_bin),
        Style::Solid,
        1,
    ));
    c.series.push(Series::new(
        "v_ref, extended",
        err(&ext.v_bin),
        Style::Solid,
        2,
    ));
    p.embed(&c, "speed_error.svg", "speed error", "", md, files)
}

/// Wheel speeds (slides), one chart per wheelset.
fn wheel_charts(p: &RunPage, md: &mut String, files: &mut Vec<PathBuf>) -> Result<()> {
    let (run, base, ext) = (p.run, p.base, p.ext);
    let kmh = |y: &[f64]| t_series(run, y, KMH_PER_MPS);
    for j in 0..WHEELSETS {
        let mut c = Chart::new(
            &format!("{}: wheelset {} circumferential speed", run.name, j + 1),
            "time, s",
            "speed, km/h",
        );
        c.series.push(Series::new(
            "v_ref measured",
            t_series(run, &run.v_bin, KMH_PER_MPS),
            Style::Dotted,
            6,
        ));
        add_measured_and_models(
            &mut c,
            [
                kmh(&run.wheel_bin[j]),
                kmh(&base.wheel_bin[j]),
                kmh(&ext.wheel_bin[j]),
            ],
            Style::Solid,
        );
        let alt = format!("wheelset {}", j + 1);
        p.embed(&c, &format!("wheel{}.svg", j + 1), &alt, "", md, files)?;
    }
    Ok(())
}

/// The baseline's relative deceleration error against each variable.
fn residual_charts(p: &RunPage, md: &mut String, files: &mut Vec<PathBuf>) -> Result<()> {
    let (run, a) = (p.run, p.a);
    if a.points.is_empty() {
        return Ok(());
    }
    for (i, name) in VARIABLES.iter().enumerate() {
        let mut c = Chart::new(
            &format!(
                "{}: baseline's relative deceleration error vs {name}",
                run.name
            ),
            &format!(
                "{name}{}",
                if UNITS[i].is_empty() {
                    String::new()
                } else {
                    format!(", {}", UNITS[i])
                }
            ),
            "model decel / measured - 1",
        );
        c.series.push(Series::new(
            "baseline (braking, no slide)",
            a.points.iter().map(|p| (p[i], p[6])).collect(),
            Style::Points,
            1,
        ));
        let file = format!("residual_vs_{}.svg", name.replace(' ', "_"));
        let r = a
            .correlations
            .iter()
            .find(|(n, _)| n == name)
            .map(|x| x.1)
            .unwrap_or(f64::NAN);
        let (alt, caption) = (format!("vs {name}"), format!(" (r = {r:.2})"));
        p.embed(&c, &file, &alt, &caption, md, files)?;
    }
    Ok(())
}

/// Disc-pad friction of the models.
fn mu_d_chart(p: &RunPage, md: &mut String, files: &mut Vec<PathBuf>) -> Result<()> {
    let run = p.run;
    let mut c = Chart::new(
        &format!("{}: disc-pad friction mu_d (model)", run.name),
        "time, s",
        "mu_d",
    );
    for (name, rep, color) in [("baseline", p.base, 1usize), ("extended", p.ext, 2)] {
        let mean: Vec<f64> = (0..run.n_bins)
            .map(|b| rep.mu_d_bin.iter().map(|m| m[b]).sum::<f64>() / 4.0)
            .collect();
        c.series.push(Series::new(
            format!("{name}, mean of wheelsets"),
            t_series(run, &mean, 1.0),
            Style::Solid,
            color,
        ));
    }
    p.embed(&c, "mu_d.svg", "mu_d", "", md, files)
}

/// Other logged quantities: the channel of each group with the largest baseline error.
fn group_charts(
    p: &RunPage,
    rb: &[(Quantity, f64, f64)],
    md: &mut String,
    files: &mut Vec<PathBuf>,
) -> Result<()> {
    let run = p.run;
    for group in [
        Group::BrakeForces,
        Group::AxleLoads,
        Group::PadForces,
        Group::DiscTemps,
        Group::Accel,
    ] {
        let best = run
            .channels
            .iter()
            .enumerate()
            .filter(|(_, c)| c.quantity.group() == group)
            .max_by(|(i, _), (k, _)| rb[*i].1.total_cmp(&rb[*k].1));
        let Some((ci, ch)) = best else { continue };
        let mut c = Chart::new(
            &format!("{}: {}", run.name, ch.quantity.label()),
            "time, s",
            &format!("{} ({})", ch.quantity.label(), ch.quantity.unit()),
        );
        let pts = |v: &[f64]| -> Vec<(f64, f64)> {
            ch.times.iter().zip(v).map(|(t, y)| (*t, *y)).collect()
        };
        add_measured_and_models(
            &mut c,
            [
                pts(&ch.measured),
                pts(&p.base.predicted[ci]),
                pts(&p.ext.predicted[ci]),
            ],
            Style::Solid,
        );
        let file = format!("{}.svg", ch.quantity.label().replace([' ', '*'], "_"));
        p.embed(&c, &file, &ch.quantity.label(), "", md, files)?;
    }
    Ok(())
}
