//! `hils rig run --programme FILE`: a WSP test programme run on the rig, one run after
//! another, each recorded as a run log (`# run: NAME`), with a JSON summary and a report.
//!
//! # The programme
//!
//! The format of `hils wsp-test --programme` (issue 13, `programmes/*.toml`): `[[run]]`
//! entries with `name`, `speed_kmh`, `demand` (`emergency` or `service:<m/s^2>`), `track`
//! (a `[tracks.X]` name) and an optional `vehicle`; `[criteria]` and `[vehicles]` are read
//! by `wsp-test`. This module reads only what the board can run, tolerating the rest, until
//! the two branches are merged and it takes `crate::wsp::programme::Programme` instead (one
//! parser of the format).
//!
//! # What the board can run
//!
//! `RIG_COMMAND`'s start carries a rail (`wet` or `dry`), the friction model and the initial
//! speed (0-655.34 km/h); the board's plant has the default vehicle. A run whose track is a
//! uniform `wet` or `dry` surface with the default vehicle runs on the board; any other
//! (low-adhesion surfaces, zones, vehicle variants, demands other than `emergency` and
//! `service:<m/s^2>`) is listed as *not run on the rig* with the reason, not approximated.
//!
//! # A run
//!
//! `brake release`, `--settle-s` (3 s: the controller vents the last run's brake), `start`
//! (rig mode), the run's brake demand, then frames until the board
//! leaves `running` (or `--max-run-s`, then `stop`). Each run's log is judged by
//! `hils wsp-test --programme FILE --log LOG` (its `# run:` names the run); the summary here
//! has stopping time and distance from the brake command, mean deceleration and each
//! wheelset's lowest wheel/vehicle speed ratio. A lost board, a bus-off, a stuck alive
//! counter or a rejected command ends the programme: the runs so far, the partial log and the
//! summary are written, and the exit code is non-zero.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, anyhow, bail};
use clap::Args;
use hils_plant::{Params, Rail};
use hils_rig_core::can::{BrakeCommand, Command, RigMode, RigState};
use serde::{Deserialize, Serialize};

use super::commands::{Flow, Session, state_name};
use super::monitor::Seen;
use super::record::{Recorder, RunMeta};
use super::transport::Transport;
use super::{FrictionArg, RigArgs, Stop, open};

/// Arguments of `hils rig run`.
#[derive(Args, Debug, Clone)]
pub struct RunArgs {
    /// The programme (the `hils wsp-test --programme` format).
    #[arg(long)]
    pub programme: PathBuf,
    /// Write the summary JSON here.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Write report.md and each run's log (NAME.csv) into this directory (default: the
    /// current directory for the logs, no report).
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Friction model of the board's plant for every run.
    #[arg(long, value_enum, default_value_t = FrictionArg::Variable)]
    pub friction: FrictionArg,
    /// Longest a run may take (board time, s: 1-3600); then it is stopped.
    #[arg(long, default_value_t = 180.0, value_parser = crate::cli::rig_max_run_s)]
    pub max_run_s: f64,
    /// Wait after releasing the brake before each start, s (the controller under test
    /// vents its cylinders; nothing in `hils.dbc` shows their pressure): 0.1-600 s.
    #[arg(long, default_value_t = 3.0, value_parser = crate::cli::rig_settle_s)]
    pub settle_s: f64,
    /// Only the runs whose name contains this.
    #[arg(long)]
    pub only: Option<String>,
}

#[derive(Deserialize, Debug, Clone)]
struct TrackSpec {
    base: String,
    #[serde(default)]
    zone: Vec<toml::Value>,
}

#[derive(Deserialize, Debug, Clone)]
struct RunSpec {
    name: String,
    speed_kmh: f64,
    demand: String,
    track: String,
    #[serde(default)]
    vehicle: Option<String>,
}

/// The part of a programme file the rig reads (other tables are `wsp-test`'s).
#[derive(Deserialize, Debug, Clone)]
struct ProgrammeFile {
    #[serde(default)]
    tracks: BTreeMap<String, TrackSpec>,
    run: Vec<RunSpec>,
}

/// A run of the programme as the board can (or cannot) run it.
#[derive(Clone, Debug, PartialEq)]
pub struct BoardRun {
    pub name: String,
    pub speed_kmh: f32,
    pub demand_text: String,
    /// The board's rail and brake command, or why the run cannot be run on the board.
    pub plan: Result<(Rail, BrakeCommand), String>,
}

/// The brake command of a programme demand: `emergency` or `service:<m/s^2>`.
pub fn parse_demand(text: &str) -> Result<BrakeCommand> {
    if text == "emergency" {
        return Ok(BrakeCommand::Emergency);
    }
    text.strip_prefix("service:")
        .and_then(|d| d.trim().parse::<f32>().ok())
        .filter(|d| d.is_finite() && *d > 0.0 && *d <= 10.0)
        .map(|deceleration_mps2| BrakeCommand::Service { deceleration_mps2 })
        .ok_or_else(|| anyhow!("demand `{text}`: `emergency` or `service:<0-10 m/s^2>`"))
}

/// Reads a programme: the runs, each with the board's rail or why not.
pub fn load(path: &Path) -> Result<Vec<BoardRun>> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("cannot read programme {}", path.display()))?;
    let p: ProgrammeFile =
        toml::from_str(&text).with_context(|| format!("programme {}", path.display()))?;
    if p.run.is_empty() {
        bail!("programme {}: no [[run]]", path.display());
    }
    p.run
        .iter()
        .map(|r| {
            let track = p.tracks.get(&r.track).ok_or_else(|| {
                anyhow!(
                    "programme {}: run `{}`: no track `{}`",
                    path.display(),
                    r.name,
                    r.track
                )
            })?;
            let rail = match (track.base.as_str(), track.zone.len(), &r.vehicle) {
                (_, _, Some(v)) => Err(format!(
                    "vehicle `{v}`: the board's plant has the default vehicle"
                )),
                (_, n, _) if n > 0 => Err(format!(
                    "track `{}` has {n} zone(s): the board runs one rail condition",
                    r.track
                )),
                ("wet", ..) => Ok(Rail::Wet),
                ("dry", ..) => Ok(Rail::Dry),
                (other, ..) => Err(format!(
                    "surface `{other}`: the start frame carries rail wet or dry only"
                )),
            };
            if !(r.speed_kmh.is_finite() && r.speed_kmh > 0.0) {
                bail!("run `{}`: speed_kmh must be > 0", r.name);
            }
            let demand = parse_demand(&r.demand).map_err(|e| format!("{e}"));
            Ok(BoardRun {
                name: r.name.clone(),
                speed_kmh: r.speed_kmh as f32,
                demand_text: r.demand.clone(),
                plan: rail.and_then(|rail| demand.map(|d| (rail, d))),
            })
        })
        .collect()
}

/// The summary of one run.
#[derive(Clone, Debug, Default, Serialize, PartialEq)]
pub struct RunSummary {
    pub name: String,
    pub speed_kmh: f64,
    pub demand: String,
    pub rail: Option<String>,
    /// `finished`, `stopped`, `fault`, or why the run did not run or ended early.
    pub end: String,
    pub on_rig: bool,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub log: Option<PathBuf>,
    /// From the brake command to standstill, s (None: no standstill).
    pub stop_time_s: Option<f64>,
    /// Distance from the brake command to standstill (or the end), m.
    pub stop_distance_m: Option<f64>,
    pub mean_deceleration_mps2: Option<f64>,
    /// Lowest wheel speed over vehicle speed of each wheelset above 1.4 m/s.
    pub min_wheel_speed_ratio: Option<[f64; 4]>,
}

/// Speed below which the WSP is inhibited and ratios are not taken, m/s (as `wsp-test`).
const MIN_SPEED_MPS: f64 = 1.4;

/// The figures of a run from its log (as the reader reads it).
fn figures(s: &mut RunSummary, log_path: &Path) -> Result<()> {
    let log = crate::measured::read_run_log(log_path).map_err(|e| anyhow!("{e}"))?;
    let t_eb: f64 = log
        .metadata
        .get("brake_command_s")
        .and_then(|v| v.parse().ok())
        .unwrap_or(0.0);
    let r_w = Params::default().vehicle.wheel_radius;
    let mut x = 0.0;
    let mut stop = None;
    let mut ratio = [f64::INFINITY; 4];
    let mut v0 = None;
    for k in 0..log.len() {
        let (t, v) = (log.t_s[k], log.v_ref_mps[k]);
        if t < t_eb {
            continue;
        }
        v0.get_or_insert(v);
        if k > 0 && log.t_s[k - 1] >= t_eb {
            x += 0.5 * (v + log.v_ref_mps[k - 1]) * (t - log.t_s[k - 1]);
        }
        if v >= MIN_SPEED_MPS {
            for (j, r) in ratio.iter_mut().enumerate() {
                *r = r.min(log.omega_radps[j][k] * r_w / v);
            }
        }
        if v < 0.05 && stop.is_none() {
            stop = Some(t - t_eb);
            break;
        }
    }
    s.stop_time_s = stop;
    s.stop_distance_m = Some(x);
    s.mean_deceleration_mps2 = stop.zip(v0).map(|(t, v0)| v0 / t.max(1e-9));
    s.min_wheel_speed_ratio = ratio.iter().all(|r| r.is_finite()).then_some(ratio);
    Ok(())
}

/// Runs one run on the board; records into `log`.
fn run_one<T: Transport>(
    s: &mut Session<T>,
    run: &BoardRun,
    (rail, demand): (Rail, BrakeCommand),
    args: &RunArgs,
    log: &Path,
) -> (RunSummary, Option<Stop>) {
    let mut summary = RunSummary {
        name: run.name.clone(),
        speed_kmh: run.speed_kmh as f64,
        demand: run.demand_text.clone(),
        rail: Some(format!("{rail:?}").to_lowercase()),
        on_rig: true,
        log: Some(log.to_path_buf()),
        ..Default::default()
    };
    s.recorder = Some(Recorder::default());
    let start = Command::Start {
        mode: RigMode::Rig,
        rail,
        friction: args.friction.model(),
        emergency: false,
        initial_speed_kmh: run.speed_kmh,
    };
    let mut stop = None;
    let mut steps = || -> Result<String, Stop> {
        let send = |s: &mut Session<T>, c: Command| -> Result<(), Stop> {
            let o = s.command(c)?;
            if o.accepted {
                Ok(())
            } else {
                Err(Stop::Rejected(o))
            }
        };
        // The controller vents the last run's brake before the next run starts.
        send(s, Command::Brake(BrakeCommand::Release))?;
        s.run_for(args.settle_s, |_, _| Flow::Continue)?;
        send(s, start)?;
        send(s, Command::Brake(demand))?;
        let mut running = true;
        s.run_for(args.max_run_s, |_, seen| match seen {
            Seen::Status(st) if st.state != RigState::Running => {
                running = false;
                Flow::Done
            }
            _ => Flow::Continue,
        })?;
        if running {
            let o = s.command(Command::Stop)?;
            return Ok(format!("not at standstill after {} s: {o}", args.max_run_s));
        }
        Ok(s.board
            .status()
            .map_or("unknown", |st| state_name(st.state))
            .to_string())
    };
    summary.end = match steps() {
        Ok(end) => end,
        Err(e) => {
            let end = format!("ended early: {e}");
            stop = Some(e);
            end
        }
    };
    let rec = s.recorder.take().unwrap_or_default();
    let meta = RunMeta {
        source: format!("hils rig run over {}", s.link.describe()),
        run: Some(run.name.clone()),
        start: s.last_start,
        end: summary.end.clone(),
    };
    match rec
        .write(log, &meta)
        .and_then(|_| figures(&mut summary, log))
    {
        Ok(()) => {}
        Err(e) => summary.end = format!("{}; log: {e:#}", summary.end),
    }
    (summary, stop)
}

/// Runs a programme in a session; every run's summary, and what ended it early.
pub fn run_programme<T: Transport>(
    s: &mut Session<T>,
    runs: &[BoardRun],
    args: &RunArgs,
    log_dir: &Path,
) -> (Vec<RunSummary>, Option<Stop>) {
    let mut out = Vec::new();
    let mut stopped: Option<Stop> = None;
    for run in runs {
        let not_run = |end: String| RunSummary {
            name: run.name.clone(),
            speed_kmh: run.speed_kmh as f64,
            demand: run.demand_text.clone(),
            end,
            ..Default::default()
        };
        if let Some(e) = &stopped {
            out.push(not_run(format!("not run: the programme ended ({e})")));
            continue;
        }
        match &run.plan {
            Err(why) => out.push(not_run(format!("not run on the rig: {why}"))),
            Ok(plan) => {
                let log = log_dir.join(format!("{}.csv", run.name));
                let (summary, stop) = run_one(s, run, *plan, args, &log);
                println!("{}: {}", summary.name, summary.end);
                out.push(summary);
                stopped = stop;
            }
        }
    }
    (out, stopped)
}

fn cell(x: Option<f64>, d: usize) -> String {
    x.map_or("-".into(), |x| format!("{x:.d$}"))
}

/// report.md of the runs.
pub fn report_text(programme: &Path, source: &str, runs: &[RunSummary]) -> String {
    let mut r = String::new();
    let _ = writeln!(r, "# Rig runs of {}\n", programme.display());
    let _ = writeln!(r, "Interface: {source}\n");
    r.push_str("| run | rail | speed km/h | demand | end | stop s | distance m | mean decel m/s2 | lowest wheel/vehicle speed 1-4 |\n|---|---|---|---|---|---|---|---|---|\n");
    for s in runs {
        let ratios = s.min_wheel_speed_ratio.map_or("-".into(), |r| {
            r.iter()
                .map(|x| format!("{x:.2}"))
                .collect::<Vec<_>>()
                .join(" ")
        });
        let _ = writeln!(
            r,
            "| {} | {} | {:.1} | {} | {} | {} | {} | {} | {} |",
            s.name,
            s.rail.as_deref().unwrap_or("-"),
            s.speed_kmh,
            s.demand,
            s.end,
            cell(s.stop_time_s, 2),
            cell(s.stop_distance_m, 1),
            cell(s.mean_deceleration_mps2, 3),
            ratios
        );
    }
    let _ = writeln!(
        r,
        "\nEach run's log is `NAME.csv` here (spec run-log schema, `# run: NAME`); judge it against the programme's criteria with `hils wsp-test --programme {} --log NAME.csv`.",
        programme.display()
    );
    r
}

/// `hils rig run`.
pub fn main(rig: &RigArgs, args: &RunArgs) -> Result<()> {
    let mut runs = load(&args.programme)?;
    if let Some(only) = &args.only {
        runs.retain(|r| r.name.contains(only.as_str()));
    }
    let log_dir = args.report.clone().unwrap_or_else(|| PathBuf::from("."));
    std::fs::create_dir_all(&log_dir)
        .with_context(|| format!("cannot create {}", log_dir.display()))?;
    let mut s = Session::new(open(rig)?, rig.lost_after_s);
    let (summaries, stopped) = run_programme(&mut s, &runs, args, &log_dir);
    let on_rig = summaries.iter().filter(|r| r.on_rig).count();
    println!("{on_rig}/{} runs on the rig", summaries.len());
    if let Some(out) = &args.json {
        std::fs::write(out, serde_json::to_string_pretty(&summaries)?)
            .with_context(|| format!("cannot write {}", out.display()))?;
    }
    if let Some(dir) = &args.report {
        let path = dir.join("report.md");
        std::fs::write(
            &path,
            report_text(&args.programme, &s.link.describe(), &summaries),
        )
        .with_context(|| format!("cannot write {}", path.display()))?;
        println!("report: {}", path.display());
    }
    match stopped {
        Some(e) => Err(anyhow!("programme ended early: {e}")),
        None => Ok(()),
    }
}
