//! `hils simulate`: the paper's emergency brake in software-in-the-loop, with its figures.

use std::path::{Path, PathBuf};

use anyhow::{Result, bail};
use clap::{Args, ValueEnum};
use hils_plant::contact::Polach;
use hils_plant::{FrictionModel, Params, Rail};
use hils_sil::{KMH_PER_MPS, ParamFile};

use crate::figures::list_text;
use crate::outputs::OutDir;
use crate::params_file::params_or_default;
use crate::plots::{Chart, Series, Style};
use crate::runlog::{Format, write_run_log_as};
use crate::scenario::{EbOptions, Run, Summary, run_eb};

#[derive(Clone, Copy, Debug, ValueEnum, PartialEq, Eq)]
pub enum FrictionArg {
    Variable,
    Constant,
}

impl From<FrictionArg> for FrictionModel {
    fn from(f: FrictionArg) -> Self {
        match f {
            FrictionArg::Variable => FrictionModel::Variable,
            FrictionArg::Constant => FrictionModel::Constant,
        }
    }
}

#[derive(Clone, Copy, Debug, ValueEnum, PartialEq, Eq)]
pub enum RailArg {
    Wet,
    Dry,
}

impl From<RailArg> for Rail {
    fn from(r: RailArg) -> Self {
        match r {
            RailArg::Wet => Rail::Wet,
            RailArg::Dry => Rail::Dry,
        }
    }
}

#[derive(Clone, Copy, Debug, ValueEnum, PartialEq, Eq)]
pub enum ScenarioArg {
    /// The paper's emergency brake from 150 km/h on a wet rail (EB at t = 0).
    PaperEb,
}

#[derive(Clone, Copy, Debug, ValueEnum, PartialEq, Eq)]
pub enum PrecisionArg {
    F32,
    F64,
}

/// Arguments of `hils simulate`.
#[derive(Args, Debug, Clone)]
pub struct SimulateArgs {
    /// Scenario to run.
    #[arg(long, value_enum, default_value = "paper-eb")]
    pub scenario: ScenarioArg,
    /// Disc-pad friction: Eq (2) (`variable`) or mu_d0 (`constant`). Default: the
    /// parameter file's `friction.model`.
    #[arg(long, value_enum)]
    pub friction: Option<FrictionArg>,
    /// Parameter file (reference-parameters.toml or a variant); default: built-in values.
    #[arg(long)]
    pub params: Option<PathBuf>,
    /// Rail condition (default: the scenario's).
    #[arg(long, value_enum)]
    pub rail: Option<RailArg>,
    /// Initial speed, km/h (default: the scenario's).
    #[arg(long, value_parser = crate::flags::speed_kmh)]
    pub speed_kmh: Option<f64>,
    /// Output directory (created).
    #[arg(long)]
    pub out: PathBuf,
    /// Sample rate of run.csv, Hz (a divisor of the plant rate).
    #[arg(long, default_value_t = 1000.0, value_parser = crate::flags::sample_rate_hz)]
    pub sample_rate_hz: f64,
    /// Plant precision (f32 is what the target runs).
    #[arg(long, value_enum, default_value = "f32")]
    pub precision: PrecisionArg,
    /// Skip the figures (and the overlay run they need).
    #[arg(long)]
    pub no_plots: bool,
    /// Run-log format: `csv` (run.csv, spec/measured-data.md) or `mf4` (run.mf4, ASAM MDF
    /// 4.10: the same columns and names, with units, comments and the run's metadata).
    #[arg(long, value_enum, default_value = "csv")]
    pub format: Format,
}

/// Builds the parameters and options of a run from the arguments.
pub fn setup(args: &SimulateArgs) -> Result<(ParamFile, EbOptions)> {
    let mut params = params_or_default(args.params.as_deref())?;
    if let Some(f) = args.friction {
        params.plant.friction.model = f.into();
    }
    let mut opts = EbOptions::paper(&params);
    if let Some(r) = args.rail {
        opts.rail = r.into();
    }
    if let Some(v) = args.speed_kmh {
        if !(v > 0.0 && v <= 400.0) {
            bail!("--speed-kmh {v}: must be in (0, 400] km/h");
        }
        opts.initial_speed_mps = v / KMH_PER_MPS;
    }
    let dt = params.scenario.paper_eb.step_s;
    let every = 1.0 / (args.sample_rate_hz * dt);
    if !(every >= 1.0) || (every - every.round()).abs() > 1e-6 {
        bail!(
            "--sample-rate-hz {}: must divide the plant rate {} Hz",
            args.sample_rate_hz,
            1.0 / dt
        );
    }
    opts.record_every = every.round() as u32;
    Ok((params, opts))
}

fn run(params: &ParamFile, opts: &EbOptions, precision: PrecisionArg) -> Result<Run> {
    match precision {
        PrecisionArg::F32 => run_eb::<f32>(params, opts),
        PrecisionArg::F64 => run_eb::<f64>(params, opts),
    }
}

/// `hils simulate`.
pub fn main(args: SimulateArgs) -> Result<()> {
    let (params, mut opts) = setup(&args)?;
    let out = OutDir::check(&args.out, "--out")?;
    opts.progress = true;
    let main_run = run(&params, &opts, args.precision)?;
    let friction = match params.plant.friction.model {
        FrictionModel::Variable => "variable",
        FrictionModel::Constant => "constant",
    };
    let rail = match opts.rail {
        Rail::Wet => "wet",
        Rail::Dry => "dry",
    };
    let metadata = vec![
        (
            "source",
            "hils simulate (software-in-the-loop: plant + simulated brake unit)".to_string(),
        ),
        ("scenario", "paper-eb".to_string()),
        ("rail", rail.to_string()),
        (
            "initial_speed_kmh",
            format!("{}", opts.initial_speed_mps * KMH_PER_MPS),
        ),
        ("eb_command_s", "0".to_string()),
        ("friction", friction.to_string()),
        ("sample_rate_hz", format!("{}", args.sample_rate_hz)),
        ("plant_step_s", format!("{}", main_run.dt)),
        (
            "precision",
            match args.precision {
                PrecisionArg::F32 => "f32",
                PrecisionArg::F64 => "f64",
            }
            .to_string(),
        ),
        ("math", hils_plant::math::IMPLEMENTATION.to_string()),
        (
            "params",
            args.params
                .as_ref()
                .map(|p| p.display().to_string())
                .unwrap_or("built-in".into()),
        ),
    ];
    let run_name = format!("run.{}", args.format.extension());
    let csv_path = out.write_with(&run_name, |w| {
        write_run_log_as(args.format, w, &metadata, &main_run.samples)
    })?;
    let summary = main_run.summary.rounded();
    let summary_path = out.write_json("summary.json", &summary)?;
    print_summary(
        &summary,
        friction,
        rail,
        opts.initial_speed_mps,
        opts.max_time_s,
    );

    if !args.no_plots {
        // The paper overlays the other friction model (Figs 10, 11).
        let mut other_params = params;
        other_params.plant.friction.model = match params.plant.friction.model {
            FrictionModel::Variable => FrictionModel::Constant,
            FrictionModel::Constant => FrictionModel::Variable,
        };
        let other = run(&other_params, &opts, args.precision)?;
        let files = draw_figures(&out, &params.plant, &main_run, &other)?;
        for f in files {
            println!("  figure {}", f.display());
        }
    }
    println!(
        "  wrote {} and {}",
        csv_path.display(),
        summary_path.display()
    );
    Ok(())
}

/// The run's summary for people (figures rounded, no debug forms).
fn print_summary(s: &Summary, friction: &str, rail: &str, speed_mps: f64, max_time_s: f64) {
    println!(
        "{friction} friction, {rail} rail, {:.0} km/h:",
        speed_mps * KMH_PER_MPS
    );
    match (s.stop_time_s, s.stopping_distance_m) {
        (Some(t), Some(d)) => println!("  stop after {t:.2} s and {d:.1} m"),
        _ => println!("  no stop within {max_time_s} s"),
    }
    let vents: Vec<String> = (0..4)
        .filter_map(|j| s.slide_onset_s[j].map(|t| format!("{t:.3} s (wheelset {})", j + 1)))
        .collect();
    if vents.is_empty() {
        println!("  WSP acted on no wheelset");
    } else {
        println!(
            "  WSP acted on wheelsets {}; first vents {}",
            list_text(&s.slides),
            vents.join(", ")
        );
    }
    let at = |k: &str| match s.mu_d_at_s.get(k).copied().flatten() {
        Some(mu) => format!("{mu:.4} at {k} s"),
        None => format!("{k} s not reached"),
    };
    println!(
        "  mu_d: {}, {}, {}, min {:.4}, {:.4} at the stop; EB pressure {:.0} Pa",
        at("0"),
        at("10"),
        at("20"),
        s.mu_d_min,
        s.mu_d_end,
        s.eb_pressure_pa
    );
    println!("  {} steps in {:.2} s", s.steps, s.wall_s);
}

fn label(run: &Run) -> &'static str {
    match run.friction {
        FrictionModel::Variable => "variable mu_d",
        FrictionModel::Constant => "constant mu_d0",
    }
}

/// Draws the paper's Figs 8A, 8B, 9, 10, 11 for `main` with `other` overlaid.
pub fn draw_figures(
    dir: &OutDir,
    params: &Params,
    main: &Run,
    other: &Run,
) -> Result<Vec<PathBuf>> {
    let (var, con) = match main.friction {
        FrictionModel::Variable => (main, other),
        FrictionModel::Constant => (other, main),
    };
    let files: Vec<PathBuf> = [
        "fig8a_wheel_speeds.svg",
        "fig8b_axle_loads.svg",
        "fig9_mu_d.svg",
        "fig10_brake_force_ws4.svg",
        "fig11_adhesion_creepage.svg",
    ]
    .iter()
    .map(|f| dir.file(f))
    .collect::<Result<_>>()?;
    fig8a(&files[0], params.vehicle.wheel_radius, main)?;
    fig8b(&files[1], main)?;
    fig9(&files[2], params, var)?;
    fig10(&files[3], var, con)?;
    // Fig 11: adhesion coefficient vs creepage at ~3 s, with the anti-skid limits.
    fig11(&files[4], params, main.rail, var, con)?;
    Ok(files)
}

/// A quantity of every sample of `run` against time.
fn series_of(run: &Run, f: &dyn Fn(&crate::scenario::Sample) -> f64) -> Vec<(f64, f64)> {
    run.samples.iter().map(|s| (s.t_s, f(s))).collect()
}

/// Fig 8A: circumferential wheel speeds (`r`: wheel radius, m).
fn fig8a(path: &Path, r: f64, main: &Run) -> Result<()> {
    let mut chart = Chart::new(
        &format!("Fig 8A: wheel speeds during EB ({})", label(main)),
        "time, s",
        "speed, km/h",
    );
    chart.series.push(Series::new(
        "vehicle",
        series_of(main, &|s| s.v_ref_mps * KMH_PER_MPS),
        Style::Dashed,
        7,
    ));
    for j in 0..4 {
        chart.series.push(Series::new(
            format!("wheelset {}", j + 1),
            series_of(main, &|s| s.omega_radps[j] * r * KMH_PER_MPS),
            Style::Solid,
            j,
        ));
    }
    chart.save_svg(path)
}

/// Fig 8B: axle loads.
fn fig8b(path: &Path, main: &Run) -> Result<()> {
    let mut chart = Chart::new(
        &format!("Fig 8B: axle loads during EB ({})", label(main)),
        "time, s",
        "axle load, kN",
    );
    for j in 0..4 {
        chart.series.push(Series::new(
            format!("wheelset {}", j + 1),
            series_of(main, &|s| s.q_n[j] / 1e3),
            Style::Solid,
            j,
        ));
    }
    chart.save_svg(path)
}

/// Fig 9: friction coefficient of the variable run up to its stop, and mu_d0.
fn fig9(path: &Path, params: &Params, var: &Run) -> Result<()> {
    let stop = var.summary.stop_time_s.unwrap_or(f64::INFINITY);
    let mut chart = Chart::new("Fig 9: disc-pad friction during EB", "time, s", "mu_d");
    chart.series.push(Series::new(
        "variable mu_d (Eq 2), mean of wheelsets",
        var.samples
            .iter()
            .filter(|s| s.t_s <= stop)
            .map(|s| (s.t_s, s.mean_mu_d()))
            .collect(),
        Style::Solid,
        0,
    ));
    let t_end = var.samples.last().map(|s| s.t_s).unwrap_or(30.0).min(stop);
    chart.series.push(Series::new(
        "constant mu_d0",
        vec![(0.0, params.friction.mu_d0), (t_end, params.friction.mu_d0)],
        Style::Dotted,
        2,
    ));
    chart.save_svg(path)
}

/// Fig 10: tangential brake force on the disc of wheelset 4.
fn fig10(path: &Path, var: &Run, con: &Run) -> Result<()> {
    let mut chart = Chart::new(
        "Fig 10: brake force on the disc, wheelset 4",
        "time, s",
        "brake force, kN",
    );
    chart.series.push(Series::new(
        "variable mu_d",
        series_of(var, &|s| s.f_brake_n[3] / 1e3),
        Style::Solid,
        0,
    ));
    chart.series.push(Series::new(
        "constant mu_d0",
        series_of(con, &|s| s.f_brake_n[3] / 1e3),
        Style::Dotted,
        2,
    ));
    chart.save_svg(path)
}

/// The adhesion a wheelset needs not to slide (the paper's "anti-skid limit") at sample
/// `s`, wheelset `j`: the rail force that makes the wheelset decelerate with the vehicle,
/// (T_b - I_w a / r) / r (Eq 7 with omega' = a / r), over the axle load (Eq 13).
pub fn required_adhesion(params: &Params, s: &crate::scenario::Sample, j: usize) -> f64 {
    let v = &params.vehicle;
    let torque = s.f_brake_n[j] * params.brake.friction_radius;
    let spin_torque = v.wheelset_spin_inertia * s.a_x_mps2 / v.wheel_radius;
    (torque + spin_torque) / v.wheel_radius / s.q_n[j]
}

fn fig11(path: &Path, params: &Params, rail: Rail, var: &Run, con: &Run) -> Result<()> {
    let at = |run: &Run| {
        let i = run
            .samples
            .partition_point(|s| s.t_s < 3.0)
            .min(run.samples.len() - 1);
        run.samples[i]
    };
    let (sv, sc) = (at(var), at(con));
    let polach = Polach::<f64>::new(&params.contact, rail);
    let curve: Vec<(f64, f64)> = (0..=400)
        .map(|i| {
            let s = 0.25 * i as f64 / 400.0;
            (s, polach.adhesion_coefficient(s, sv.v_ref_mps, sv.q_n[3]))
        })
        .collect();
    let limit_v = required_adhesion(params, &sv, 3);
    let limit_c = required_adhesion(params, &sc, 3);
    let mut chart = Chart::new(
        &format!(
            "Fig 11: adhesion vs creepage at 3 s ({:.0} km/h), wheelset 4",
            sv.v_ref_mps * KMH_PER_MPS
        ),
        "creepage s",
        "adhesion coefficient F/Q",
    );
    chart
        .series
        .push(Series::new("Polach (Eqs 9-12)", curve, Style::Solid, 0));
    chart.series.push(Series::new(
        format!("anti-skid limit, variable mu_d ({limit_v:.4})"),
        vec![(0.0, limit_v), (0.25, limit_v)],
        Style::Dashed,
        1,
    ));
    chart.series.push(Series::new(
        format!("anti-skid limit, constant mu_d0 ({limit_c:.4})"),
        vec![(0.0, limit_c), (0.25, limit_c)],
        Style::Dotted,
        2,
    ));
    // Operating points of wheelset 4 during the first 8 s of each run.
    let path_of = |run: &Run| -> Vec<(f64, f64)> {
        run.samples
            .iter()
            .filter(|s| s.t_s <= 8.0 && s.creepage[3] <= 0.25)
            .map(|s| (s.creepage[3], s.adhesion[3]))
            .collect()
    };
    chart.series.push(Series::new(
        "wheelset 4, variable (0-8 s)",
        path_of(var),
        Style::Points,
        3,
    ));
    chart.series.push(Series::new(
        "wheelset 4, constant (0-8 s)",
        path_of(con),
        Style::Points,
        4,
    ));
    chart.x_range = Some((0.0, 0.25));
    chart.save_svg(path)
}
