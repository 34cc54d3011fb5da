//! `hils rig run --programme FILE`: a WSP test programme run on the rig, one run after
//! another, each recorded as a run log (`# run: NAME`), judged by `hils wsp-test`'s
//! metrics and criteria beside the SIL run of the same programme run.
//!
//! # The programme
//!
//! The `hils wsp-test --programme` format, read by its parser
//! ([`crate::wsp::programme::Programme`]: one parser of the format): `[criteria]`,
//! `[tracks]`, `[vehicles]` and `[[run]]`.
//!
//! # What the board can run
//!
//! Each run's track goes to the board in `TrackZone` / `Track` commit frames and its
//! vehicle variant in `Vehicle` frames ([`super::track`]); the start frame carries the
//! friction model and the initial speed (0-655.34 km/h), the brake frame `emergency`,
//! `service:<m/s^2 <= 10>` or `step:<n>`. A run the frames cannot carry exactly (own
//! contact sets, zone bounds off the 0.1 m grid, a parameter file other than the default,
//! degraded adhesion on, faster starts) is listed as *not run on the rig* with the reason,
//! not approximated.
//!
//! # A run
//!
//! `brake release`, `--settle-s` (3 s: the controller vents the last run's brake), the
//! vehicle and track frames, `arm` (the board's outputs to the controller go live for the
//! run; only with `--arm`, the operator's explicit arming, announced on the terminal:
//! without it nothing is sent or written; the board disarms at every stop, fault and
//! reset, so each run arms again),
//! `start` (rig mode, on the track), the run's brake demand, then frames until the board
//! leaves `running` (or `--max-run-s`, then `stop`).
//!
//! # Judging
//!
//! Each run's log (`NAME.csv`, the spec's run-log schema with `# run`, `# track`,
//! `# demand` and `# speed_resolution_kmh`) is judged by the one path of
//! `hils wsp-test --programme FILE --log NAME.csv` ([`crate::wsp::judge_log`]): the same
//! recording gets the same verdict from both. The board reads the controller's dump and
//! hold valve coils on its valve inputs (`hils_rig_core::valves`); the wheel-speed frames
//! carry them every 1 ms and the log has them as `wsp1..4` (dump) and `hold1..4`
//! ([`super::record`]): air and WSP timer actions are judged from them as a SIL run's from
//! the simulated unit's valves (`crate::wsp::log`: the dump valve acts one pneumatic dead
//! time after its coil). An input the rig's configuration says is not wired gives empty
//! cells: the judge then estimates the vents from the pressure falls or says "not
//! measured" (`crate::wsp::log`), the criterion not judged and the run not passed. Every run of the programme is also simulated in SIL
//! ([`crate::wsp::run_one`]). `--json` holds one entry per run: the rig verdict's keys
//! (those of `hils wsp-test --json`) with `on_rig` and `end`, or for a run not judged its
//! `name`, `passed: false`, `on_rig` and `end` (why). `--report DIR` writes `report.md`
//! (rig and SIL rows side by side, the rig against SIL ([`super::agreement`]: also printed,
//! and `against_sil` in each judged run's JSON entry), the `wsp-test` sections and plots of both:
//! `NAME-rig-*.svg`, `NAME-sil-*.svg`) and the logs. A lost board, a bus-off, a stuck alive
//! counter or a rejected command ends the programme: the runs so far, the partial log and
//! the summary are written, and the exit code is non-zero.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{Result, anyhow, bail};
use clap::Args;
use hils_brake_unit::BrakeDemand;
use hils_plant::Rail;
use hils_rig_core::can::{
    BrakeCommand, Command, ConfigItem, RigMode, RigState, StartCommand, WHEEL_SPEED_MAX_KMH,
    command,
};
use hils_rig_core::controller_io::IoConfig;

use super::commands::{Flow, Session};
use super::monitor::Seen;
use super::monitor::state_name;
use super::record::{Recorder, RunMeta};
use super::track;
use super::transport::Transport;
use super::{FrictionArg, RigArgs, Stop, open};
use crate::outputs::OutDir;
use crate::wsp::log::{VENT_FALL_PA_PER_S, VENT_WINDOW_S};
use crate::wsp::metrics::Verdict;
use crate::wsp::programme::{Criteria, Programme, Run, demand_text, track_layout};
use crate::wsp::{judge_log, report};

/// Arguments of `hils rig run`.
#[derive(Args, Debug, Clone)]
pub struct RunArgs {
    /// The programme (the `hils wsp-test --programme` format).
    #[arg(long)]
    pub programme: PathBuf,
    /// `--json FILE` and `--report DIR` (what they hold: `hils rig run --help`).
    #[command(flatten)]
    pub out: crate::outputs::Outputs,
    /// Friction model of the board's plant (and of the SIL runs) for every run.
    #[arg(long, value_enum, default_value_t = FrictionArg::Variable)]
    pub friction: FrictionArg,
    /// Longest a run may take (board time, s: 1-3600); then it is stopped.
    #[arg(long, default_value_t = 180.0, value_parser = crate::flags::rig_max_run_s)]
    pub max_run_s: f64,
    /// Wait after releasing the brake before each start, s (the controller under test
    /// vents its cylinders; nothing in `hils.dbc` shows their pressure): 0.1-600 s.
    #[arg(long, default_value_t = 3.0, value_parser = crate::flags::rig_settle_s)]
    pub settle_s: f64,
    /// Only the runs whose name contains this.
    #[arg(long)]
    pub only: Option<String>,
    /// Arm the board before each run's start (required on a CAN interface): the runs drive
    /// the controller under test (pulse trains, wheel speeds); the board disarms at every
    /// stop, fault and reset, so each run is armed again. `--interface sim` arms without it:
    /// its controller is the simulated one in this process, no real controller is driven.
    #[arg(long)]
    pub arm: bool,
    /// The rig's controller I/O configuration, sent before the first run (`hils rig
    /// configure io FILE`; format: docs/rig.md, "Controller I/O"). Without it the board
    /// keeps what it has (the simulated board: every valve input wired).
    #[arg(long)]
    pub io: Option<PathBuf>,
}

/// What the board is sent for a run: the vehicle and track frames, then the brake command
/// after the start.
#[derive(Clone, Debug)]
pub struct Plan {
    /// `Vehicle` frames, then `TrackZone` frames and the `Track` commit.
    pub setup: Vec<Command>,
    pub demand: BrakeCommand,
}

/// A run of the programme as the board can (or cannot) run it.
#[derive(Clone, Debug)]
pub struct BoardRun {
    pub run: Run,
    /// What the board is sent, or why the run cannot be run on the board.
    pub plan: Result<Plan, String>,
}

/// What the board runs of a programme run, or why not (module doc).
fn board_plan(vehicle: Option<&str>, run: &Run) -> Result<Plan, String> {
    let mut setup = Vec::new();
    let why = |e: anyhow::Error| format!("{e:#}");
    track::check_params(&run.file).map_err(why)?;
    setup.extend(
        track::vehicle_commands(&run.file.plant.vehicle)
            .map_err(|e| format!("vehicle `{}`: {e:#}", vehicle.unwrap_or("default")))?,
    );
    setup.extend(track::track_commands(&run.track, &run.sets).map_err(why)?);
    let speed_kmh = run.speed_mps * hils_sil::KMH_PER_MPS;
    if speed_kmh > WHEEL_SPEED_MAX_KMH as f64 {
        return Err(format!(
            "{speed_kmh:.1} km/h: the start frame carries up to {WHEEL_SPEED_MAX_KMH:.2} km/h"
        ));
    }
    on_frame_grid(
        "speed",
        speed_kmh,
        command::START_SPEED.scale as f64,
        "km/h",
        "start",
    )?;
    let demand = match run.demand {
        BrakeDemand::Emergency => BrakeCommand::Emergency,
        BrakeDemand::Service { deceleration_mps2 } if deceleration_mps2 <= 10.0 => {
            BrakeCommand::Service { deceleration_mps2 }
        }
        BrakeDemand::ServiceStep { step } if step > 0 => BrakeCommand::ServiceStep { step },
        other => {
            return Err(format!(
                "demand `{}`: the brake frame carries emergency, service 0-10 m/s^2 or a step 1-255",
                demand_text(other)
            ));
        }
    };
    if let BrakeCommand::Service { deceleration_mps2 } = demand {
        on_frame_grid(
            "service deceleration",
            deceleration_mps2 as f64,
            command::SERVICE_DECELERATION.scale as f64,
            "m/s^2",
            "brake",
        )?;
    }
    Ok(Plan { setup, demand })
}

/// Whether `value` is a whole number of the frame signal's `step` (to 1 % of a step: the
/// f32 rounding of a value written on the grid), else why not: the board would run another
/// value than the programme's (a service deceleration of 0.0004 m/s^2 is 0 in the frame).
fn on_frame_grid(what: &str, value: f64, step: f64, unit: &str, frame: &str) -> Result<(), String> {
    let steps = value / step;
    if (steps - steps.round()).abs() > 0.01 {
        return Err(format!(
            "{what} {} {unit} is not on the {frame} frame's {} {unit} grid (the board would run {} {unit})",
            crate::figures::round_sig(value, 6),
            crate::figures::round_sig(step, 3),
            crate::figures::round_sig(steps.round() * step, 6)
        ));
    }
    Ok(())
}

/// Reads a programme with `hils wsp-test`'s parser: its criteria and runs (on the default
/// parameters with the friction model `friction`), each with the board's plan or why not.
pub fn load(path: &Path, friction: FrictionArg) -> Result<(Criteria, Vec<BoardRun>)> {
    let programme = Programme::load(path)?;
    let mut file = crate::params_file::params_or_default(None)?;
    file.plant.friction.model = friction.model();
    let runs = programme.runs(&file)?;
    let runs = programme
        .run
        .iter()
        .zip(runs)
        .map(|(spec, run)| BoardRun {
            plan: board_plan(spec.vehicle.as_deref(), &run),
            run,
        })
        .collect();
    Ok((programme.criteria, runs))
}

/// The rig's side of one run: how it ended, its verdict (its log and plots are written).
pub struct RigRun {
    pub name: String,
    pub on_rig: bool,
    /// `finished`, `stopped`, `fault`, or why the run did not run or ended early.
    pub end: String,
    pub verdict: Option<Verdict>,
}

impl RigRun {
    /// The JSON entry (module doc), with `against_sil` ([`super::agreement::Agreement`]) when
    /// the rig run was judged.
    fn json(&self, sil: &Verdict) -> serde_json::Value {
        let mut v = match &self.verdict {
            Some(verdict) => serde_json::to_value(verdict).unwrap_or_default(),
            None => serde_json::json!({ "name": self.name, "passed": false }),
        };
        if let Some(m) = v.as_object_mut() {
            m.insert("on_rig".into(), self.on_rig.into());
            m.insert("end".into(), self.end.clone().into());
            if let Some(rig) = &self.verdict {
                let a = super::agreement::agreement(rig, sil);
                m.insert(
                    "against_sil".into(),
                    serde_json::to_value(a).unwrap_or_default(),
                );
            }
        }
        v
    }
}

/// Runs one run on the board; records into `log`.
fn run_one<T: Transport>(
    s: &mut Session<T>,
    run: &Run,
    plan: &Plan,
    args: &RunArgs,
    log: &Path,
) -> (String, Option<Stop>) {
    s.recorder = Some(Recorder::default());
    let start = Command::Start(StartCommand {
        mode: RigMode::Rig,
        rail: Rail::Wet,
        friction: args.friction.model(),
        emergency: false,
        initial_speed_kmh: (run.speed_mps * hils_sil::KMH_PER_MPS) as f32,
        track: true,
        // Stamped below from the setup sent before it.
        setup_digest: 0,
    });
    let demand = plan.demand;
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
        for c in &plan.setup {
            send(s, *c)?;
        }
        send(s, Command::Arm)?;
        // The run's demand is in force from its first step (t = 0), as a SIL run's: the
        // board drives the brake command in force from the start (EB loop, service PWM).
        send(s, Command::Brake(demand))?;
        send(s, super::track::with_setup_digest(&plan.setup, start)?)?;
        let mut running = true;
        s.run_for(args.max_run_s, |_, seen| match seen {
            Seen::Status(st) if st.state != RigState::Running => {
                running = false;
                Flow::Done
            }
            _ => Flow::Continue,
        })?;
        if !running {
            // The board's standstill: the frames after it (speeds 0.00 km/h, the next status)
            // close the log at standstill, as the judge needs.
            s.run_for(0.05, |_, _| Flow::Continue)?;
        } else {
            let o = s.command(Command::Stop)?;
            return Ok(format!("not at standstill after {} s: {o}", args.max_run_s));
        }
        Ok(s.board
            .status()
            .map_or("unknown", |st| state_name(st.state))
            .to_string())
    };
    let mut end = match steps() {
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
        end: end.clone(),
        wheel_radius_m: Some(run.file.plant.vehicle.wheel_radius),
        track: Some(track_layout(&run.track)),
        demand: Some(demand_text(run.demand)),
    };
    if let Err(e) = rec.write(log, &meta) {
        end = format!("{end}; log: {e:#}");
    }
    (end, stop)
}

/// Runs a programme in a session, recording each run's log into `dir` and judging it (its
/// plots written into `dir` as it is judged: only the verdict is kept); what ended it early.
pub fn run_programme<T: Transport>(
    s: &mut Session<T>,
    runs: &[BoardRun],
    criteria: &Criteria,
    args: &RunArgs,
    dir: &OutDir,
) -> (Vec<RigRun>, Option<Stop>) {
    let mut out = Vec::new();
    let mut stopped: Option<Stop> = None;
    if runs.iter().any(|r| r.plan.is_ok()) {
        crate::say!(
            "arming the board before each run: its pulse trains and wheel speeds drive the controller on {} during the runs (docs/rig.md, Arming)",
            s.link.describe()
        );
    }
    for BoardRun { run, plan } in runs {
        let mut rig = RigRun {
            name: run.name.clone(),
            on_rig: false,
            end: String::new(),
            verdict: None,
        };
        match (&stopped, plan) {
            (Some(e), _) => rig.end = format!("not run: the programme ended ({e})"),
            (None, Err(why)) => rig.end = format!("not run on the rig: {why}"),
            (None, Ok(plan)) => {
                let log = match dir.file(&format!("{}.csv", run.name)) {
                    Ok(log) => log,
                    Err(e) => {
                        rig.end = format!("not run: {e:#}");
                        out.push(rig);
                        continue;
                    }
                };
                let (end, stop) = run_one(s, run, plan, args, &log);
                rig.on_rig = true;
                rig.end = end;
                stopped = stop;
                let judged = judge_log(&log, run, criteria).and_then(|o| {
                    report::write_run_plots(dir, &format!("{}-rig", run.name), &o)?;
                    Ok(o.verdict)
                });
                match judged {
                    Ok(verdict) => rig.verdict = Some(verdict),
                    Err(e) => rig.end = format!("{}; not judged: {e:#}", rig.end),
                }
            }
        }
        crate::say!("{}: {}", rig.name, rig.end);
        out.push(rig);
    }
    (out, stopped)
}

/// The summary table: each run's rig row beside its SIL row, then the runs not judged.
pub fn summary_table(rig: &[RigRun], sil: &[Verdict]) -> String {
    let mut rows: Vec<Verdict> = Vec::new();
    let mut not_judged = String::new();
    for (r, s) in rig.iter().zip(sil) {
        match &r.verdict {
            Some(v) => {
                rows.push(Verdict {
                    name: format!("{} (rig)", r.name),
                    ..v.clone()
                });
                if !v.estimated_from_cylinder_pressure.is_empty() {
                    let _ = writeln!(
                        not_judged,
                        "- {} (rig): estimated from the measured cylinder pressure falls (a fall faster than {} bar/s over {} ms counts as venting): {}",
                        r.name,
                        VENT_FALL_PA_PER_S / 1e5,
                        VENT_WINDOW_S * 1e3,
                        v.estimated_from_cylinder_pressure.join(", ")
                    );
                }
                if !v.not_measured.is_empty() {
                    let _ = writeln!(
                        not_judged,
                        "- {} (rig): not measured, not judged (a valve input or a cylinder pressure the log lacks: not wired, or no probe capture): {}",
                        r.name,
                        v.not_measured.join(", ")
                    );
                }
            }
            None => {
                let _ = writeln!(not_judged, "- {} (rig): {}", r.name, r.end);
            }
        }
        rows.push(Verdict {
            name: format!("{} (SIL)", s.name),
            ..s.clone()
        });
    }
    let refs: Vec<&Verdict> = rows.iter().collect();
    let mut t = report::table(&refs);
    if !not_judged.is_empty() {
        let _ = write!(
            t,
            "\nNot judged or not measured on the rig:\n\n{not_judged}"
        );
    }
    t
}

/// Telemetry divider of a programme: a record every 10 plant steps (1 kHz), so the
/// cylinder pressures the air is judged from are logged at the valves' pace (at the
/// default 100 Hz the pressure falls between records are interpolated and the air comes
/// out 2-3 % low; docs/rig.md, "Controller I/O").
pub const PROGRAMME_TELEMETRY_DIVIDER: u16 = 10;

/// Before the runs: the controller I/O of `--io` (if given) and the programme's telemetry
/// rate, each command accepted or an error.
fn configure_board<T: Transport>(s: &mut Session<T>, io: Option<&IoConfig>) -> Result<()> {
    let mut commands = io.map(super::io_config::commands).unwrap_or_default();
    commands.push(Command::Configure(ConfigItem::TelemetryDivider(
        PROGRAMME_TELEMETRY_DIVIDER,
    )));
    for c in commands {
        let o = s.command(c).map_err(anyhow::Error::from)?;
        if !o.accepted {
            return Err(anyhow!("the board refused the configuration: {o}"));
        }
    }
    Ok(())
}

/// `hils rig run`: `--report DIR` is required (each run's log is written there, with the
/// report: nothing is written into the current folder unasked).
pub fn main(rig: &RigArgs, args: &RunArgs) -> Result<()> {
    // The arming rule protects a real controller: `--interface sim` has none on its bus.
    if !args.arm && rig.interface != "sim" {
        return Err(anyhow!(
            "hils rig run --programme drives the controller under test from each run's start: add --arm to arm the board before each run (docs/rig.md, Arming)"
        ));
    }
    let mut inputs = vec![("--programme", args.programme.as_path())];
    inputs.extend(args.io.as_deref().map(|p| ("--io", p)));
    let out = args.out.check()?.not_over(&inputs)?;
    let Some(dir) = out.report.clone() else {
        bail!(
            "hils rig run records each run's log (NAME.csv) and writes its report into \
             --report DIR: give one (nothing was run)"
        );
    };
    let (criteria, mut runs) = load(&args.programme, args.friction)?;
    if let Some(only) = &args.only {
        runs.retain(|r| r.run.name.contains(only.as_str()));
        if runs.is_empty() {
            bail!(
                "--only {only}: no run of {} has a name containing it (nothing was run)",
                args.programme.display()
            );
        }
    }
    if let Some(json) = out.json.as_ref().and_then(|j| j.path()) {
        let written = runs.iter().map(|r| format!("{}.csv", r.run.name));
        if let Some(name) = written
            .chain(["report.md".to_string()])
            .find(|name| dir.holds(json, name))
        {
            bail!(
                "--json {}: is {name} of --report {}, which this command writes there; name another file",
                json.display(),
                dir.path().display()
            );
        }
    }
    let io = args.io.as_deref().map(super::io_config::load).transpose()?;
    dir.create()?;
    let mut s = Session::new(open(rig)?, rig.lost_after_s);
    configure_board(&mut s, io.as_ref())?;
    let (rig_runs, stopped) = run_programme(&mut s, &runs, &criteria, args, &dir);
    let sil = crate::wsp::judge_runs(
        runs.iter().map(|r| r.run.clone()).collect(),
        &criteria,
        Some((&dir, "sil")),
    )?;
    let pairs: Vec<(&Verdict, &Verdict)> = rig_runs
        .iter()
        .zip(&sil)
        .filter_map(|(r, s)| r.verdict.as_ref().map(|v| (v, s)))
        .collect();
    let table = format!(
        "{}\n{}",
        summary_table(&rig_runs, &sil),
        super::agreement::table(&pairs)
    );
    crate::say!("{table}");
    let on_rig = rig_runs.iter().filter(|r| r.on_rig).count();
    let passed = rig_runs
        .iter()
        .filter(|r| r.verdict.as_ref().is_some_and(|v| v.passed))
        .count();
    crate::say!(
        "{on_rig}/{} runs on the rig, {passed} passed",
        rig_runs.len()
    );
    let json: Vec<serde_json::Value> = rig_runs.iter().zip(&sil).map(|(r, s)| r.json(s)).collect();
    out.write_json(&json)?;
    out.write_report(|dir| {
        let heading = format!(
            "# Rig runs of {}\n\nInterface: {}. Each run's log is `NAME.csv` here (spec run-log schema, `# run: NAME`), judged from its brake command as `hils wsp-test --programme {} --log NAME.csv` judges it; `(SIL)` rows: the same run simulated with the simulated brake unit.\n\n",
            args.programme.display(),
            s.link.describe(),
            args.programme.display()
        );
        let stems: Vec<(String, &Verdict)> = rig_runs
            .iter()
            .zip(&sil)
            .flat_map(|(r, v)| {
                let rig = r.verdict.as_ref().map(|x| (format!("{}-rig", r.name), x));
                rig.into_iter().chain([(format!("{}-sil", v.name), v)])
            })
            .collect();
        let sections: Vec<(&str, &Verdict)> = stems.iter().map(|(s, v)| (s.as_str(), *v)).collect();
        Ok(vec![report::write_with(
            dir, &heading, &table, &sections, &criteria,
        )?])
    })?;
    match stopped {
        Some(e) => Err(anyhow!("programme ended early: {e}")),
        None => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The board's plan of each run of a programme of `runs` (`[[run]]` bodies on a wet
    /// track), or why not.
    fn plans(runs: &[&str]) -> Vec<Result<Plan, String>> {
        let mut text = String::from("[tracks.wet]\nbase = \"wet\"\n");
        for (i, r) in runs.iter().enumerate() {
            text += &format!("[[run]]\nname = \"r{i}\"\ntrack = \"wet\"\n{r}\n");
        }
        let path = std::env::temp_dir().join(format!("hils-rig-plan-{}.toml", std::process::id()));
        std::fs::write(&path, text).unwrap();
        let (_, runs) = load(&path, FrictionArg::Variable).unwrap();
        std::fs::remove_file(&path).unwrap();
        runs.into_iter().map(|r| r.plan).collect()
    }

    #[test]
    fn a_speed_or_deceleration_the_frames_cannot_carry_is_not_run_on_the_rig() {
        let p = plans(&[
            "speed_kmh = 60.0\ndemand = \"service:0.8\"",
            "speed_kmh = 123.45\ndemand = \"service:1.234\"",
            "speed_kmh = 60.004\ndemand = \"emergency\"",
            "speed_kmh = 60.0\ndemand = \"service:0.0004\"",
            "speed_kmh = 60.0\ndemand = \"service:0.8005\"",
        ]);
        assert!(p[0].is_ok() && p[1].is_ok(), "{:?} {:?}", p[0], p[1]);
        let why = |k: usize| p[k].as_ref().map(|_| ()).unwrap_err().clone();
        assert!(
            why(2).contains("speed 60.004") && why(2).contains("0.01"),
            "{}",
            why(2)
        );
        // 0.0004 m/s^2 is 0 in the frame: the board would run no brake at all.
        assert!(why(3).contains("would run 0 m/s^2"), "{}", why(3));
        assert!(why(4).contains("service deceleration"), "{}", why(4));
    }
}
