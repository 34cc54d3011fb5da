//! `hils bench`: host steps per second of the full plant (17 DOF, four contacts, Eq 2
//! friction, disc heat) in f32 and f64, and the real-time factor at 10 kHz.
//!
//! The plant runs the paper's EB (150 km/h, wet): the brake inputs are the cylinder
//! pressures of a closed-loop run recorded beforehand, so the timed loop is the plant
//! alone (slides and WSP included); a second figure times plant + simulated brake unit
//! (`steps_per_s_closed_loop`), and a third whole paper-scenario runs (EB from 150 km/h to
//! standstill, plant + unit, as `hils simulate` runs it) on every core (`runs_per_s`).

use std::hint::black_box;
use std::time::Instant;

use anyhow::{Result, anyhow};
use clap::Args;
use hils_brake_unit::BrakeDemand;
use hils_plant::{BrakeInput, Plant, Real};
use hils_sil::{ClosedLoop, EbScenario, KMH_PER_MPS, ParamFile};
use rayon::prelude::*;

/// Initial speed of the benchmark run: the paper's 150 km/h, m/s.
const PAPER_SPEED_MPS: f64 = 150.0 / KMH_PER_MPS;
use serde::Serialize;

#[derive(Args, Debug, Clone)]
pub struct BenchArgs {
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
    /// Plant steps per timed repetition.
    #[arg(long, default_value_t = 300_000, value_parser = crate::flags::steps)]
    pub steps: usize,
    /// Repetitions (the best is reported).
    #[arg(long, default_value_t = 5, value_parser = crate::flags::repeat)]
    pub repeat: usize,
    /// Instead of the plant: time and peak memory of reading this measured file.
    #[arg(long)]
    pub reader: Option<std::path::PathBuf>,
    /// With --reader: the channel map to read the file with.
    #[arg(long, requires = "reader", value_name = "FILE")]
    pub map: Option<std::path::PathBuf>,
    /// With --reader: first write a synthetic run log of about this many MB to the file
    /// (MDF4 when the file name ends in `.mf4`, else CSV).
    #[arg(long, requires = "reader", value_parser = crate::flags::log_mb)]
    pub write_log_mb: Option<f64>,
    /// With --reader: first write a synthetic friction test of this many points (Eq 2 of
    /// the reference parameters plus noise, labelled synthetic) to the file.
    #[arg(long, requires = "reader", conflicts_with = "write_log_mb", value_parser = crate::flags::friction_points)]
    pub write_friction_points: Option<u64>,
}

/// Figures printed by `hils bench --json`.
#[derive(Debug, Serialize, Clone, PartialEq)]
pub struct BenchFigures {
    pub steps_per_s_f32: f64,
    pub steps_per_s_f64: f64,
    pub realtime_factor_f32: f64,
    pub realtime_factor_f64: f64,
    /// Plant + simulated brake unit, f32, one core (the same figure as
    /// `steps_per_s_closed_loop`, kept under its first name).
    pub closed_loop_steps_per_s_f32: f64,
    /// Plant + simulated brake unit, f32, steps per second on one core.
    pub steps_per_s_closed_loop: f64,
    /// Whole paper-scenario runs (EB 150 km/h to standstill, closed loop, f32) per second
    /// on all `threads` cores.
    pub runs_per_s: f64,
    /// Plant steps of one paper-scenario run.
    pub steps_per_run: u32,
    pub ns_per_step_f32: f64,
    pub plant_rate_hz: f64,
    pub steps: usize,
    pub repeat: usize,
    pub math: &'static str,
    /// The host instruction set the plant was compiled for (`.cargo/config.toml`).
    pub host_isa: &'static str,
    pub threads: usize,
}

/// Cylinder pressures of the paper's EB, one per step (closed loop, f32).
pub fn recorded_inputs(params: &ParamFile, steps: usize) -> Result<Vec<[f32; 4]>> {
    let rail = params.scenario.paper_eb.rail;
    let mut sim = ClosedLoop::<f32>::from_file(params, rail, PAPER_SPEED_MPS as f32)
        .map_err(|e| anyhow!("{e}"))?;
    sim.set_demand(BrakeDemand::Emergency);
    Ok((0..steps)
        .map(|_| {
            sim.step();
            sim.unit_outputs().cylinder_pressure_pa
        })
        .collect())
}

/// Plant steps per second on `inputs` (one per step), the best of `repeat` runs.
pub fn time_plant<F: Real>(params: &ParamFile, inputs: &[[f32; 4]], repeat: usize) -> Result<f64> {
    let inputs: Vec<[BrakeInput<F>; 4]> = inputs
        .iter()
        .map(|p| p.map(|x| BrakeInput::CylinderPressure(F::of(x as f64))))
        .collect();
    let mut best = f64::INFINITY;
    for _ in 0..repeat {
        let sc = &params.scenario.paper_eb;
        let mut plant =
            Plant::<F>::with_step(&params.plant, sc.rail, F::of(PAPER_SPEED_MPS), sc.step_s)
                .map_err(|e| anyhow!("{e}"))?;
        let start = Instant::now();
        for input in &inputs {
            black_box(plant.step(black_box(input)));
        }
        best = best.min(start.elapsed().as_secs_f64());
        black_box(plant.outputs());
    }
    Ok(inputs.len() as f64 / best)
}

fn time_closed_loop(params: &ParamFile, steps: usize, repeat: usize) -> Result<f64> {
    let mut best = f64::INFINITY;
    for _ in 0..repeat {
        let rail = params.scenario.paper_eb.rail;
        let mut sim = ClosedLoop::<f32>::from_file(params, rail, PAPER_SPEED_MPS as f32)
            .map_err(|e| anyhow!("{e}"))?;
        sim.set_demand(BrakeDemand::Emergency);
        let start = Instant::now();
        for _ in 0..steps {
            black_box(sim.step());
        }
        best = best.min(start.elapsed().as_secs_f64());
    }
    Ok(steps as f64 / best)
}

/// One paper-scenario run to its end (stop rule of `hils simulate`); returns its steps.
fn paper_run(params: &ParamFile) -> Result<u32> {
    let mut sc = EbScenario::<f32>::new(params, u32::MAX).map_err(|e| anyhow!("{e}"))?;
    while !sc
        .advance(|sim| {
            black_box(sim.step());
        })
        .done
    {}
    Ok(sc.steps())
}

/// Paper-scenario runs per second on all cores (`threads` runs at a time, `repeat` rounds;
/// the best round counts) and the steps of one run.
fn time_runs(params: &ParamFile, threads: usize, repeat: usize) -> Result<(f64, u32)> {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()?;
    let mut best = f64::INFINITY;
    let mut steps = 0;
    for _ in 0..repeat.min(2) {
        let start = Instant::now();
        let runs: Vec<u32> = pool.install(|| {
            (0..threads)
                .into_par_iter()
                .map(|_| paper_run(params))
                .collect::<Result<_>>()
        })?;
        best = best.min(start.elapsed().as_secs_f64());
        steps = runs[0];
    }
    Ok((threads as f64 / best, steps))
}

/// Measures the figures (single thread, then `runs_per_s` on every core).
pub fn measure(params: &ParamFile, steps: usize, repeat: usize) -> Result<BenchFigures> {
    let inputs = recorded_inputs(params, steps)?;
    let rate = 1.0 / params.scenario.paper_eb.step_s;
    let f32_rate = time_plant::<f32>(params, &inputs, repeat)?;
    let f64_rate = time_plant::<f64>(params, &inputs, repeat)?;
    let closed = time_closed_loop(params, steps, repeat)?;
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    let (runs_per_s, steps_per_run) = time_runs(params, threads, repeat)?;
    Ok(BenchFigures {
        steps_per_s_f32: f32_rate,
        steps_per_s_f64: f64_rate,
        realtime_factor_f32: f32_rate / rate,
        realtime_factor_f64: f64_rate / rate,
        closed_loop_steps_per_s_f32: closed,
        steps_per_s_closed_loop: closed,
        runs_per_s,
        steps_per_run,
        ns_per_step_f32: 1e9 / f32_rate,
        plant_rate_hz: rate,
        steps,
        repeat,
        math: hils_plant::math::IMPLEMENTATION,
        host_isa: HOST_ISA,
        threads,
    })
}

/// The instruction set this build targets: x86-64-v3 (AVX2, FMA; `.cargo/config.toml`) or
/// the baseline. FMA being available changes no result: Rust never fuses a*b+c on its own.
const HOST_ISA: &str = if cfg!(all(target_feature = "avx2", target_feature = "fma")) {
    "x86-64-v3 (avx2, fma)"
} else if cfg!(target_arch = "x86_64") {
    "x86-64 baseline (sse2)"
} else {
    std::env::consts::ARCH
};

pub fn main(args: BenchArgs) -> Result<()> {
    if let Some(path) = &args.reader {
        if let Some(mb) = args.write_log_mb {
            crate::outputs::OutFile::check_file(
                path,
                "--reader",
                "the synthetic log is written to a file and then read",
            )?;
            write_log(path, mb)?;
        }
        if let Some(n) = args.write_friction_points {
            crate::outputs::OutFile::check_file(
                path,
                "--reader",
                "the synthetic friction test is written to a file and then read",
            )?;
            crate::outputs::write_atomic(path, |w| write_friction_test(w, n))?;
        }
        return bench_reader_with(path, args.map.as_deref(), args.json);
    }
    let params = ParamFile::default();
    let f = measure(&params, args.steps.max(1), args.repeat.max(1))?;
    if args.json {
        println!("{}", serde_json::to_string(&f)?);
    } else {
        println!(
            "plant (17 DOF, 4 contacts, Eq 2, heat), paper EB inputs, one core, best of {}, \
             compiled for {}:",
            f.repeat, f.host_isa
        );
        println!(
            "  f32: {:>10.0} steps/s  ({:.0} ns/step)  real-time factor at {:.0} Hz: {:.0}x",
            f.steps_per_s_f32, f.ns_per_step_f32, f.plant_rate_hz, f.realtime_factor_f32
        );
        println!(
            "  f64: {:>10.0} steps/s  real-time factor: {:.0}x",
            f.steps_per_s_f64, f.realtime_factor_f64
        );
        println!(
            "  plant + simulated brake unit (f32): {:.0} steps/s; math: {}",
            f.closed_loop_steps_per_s_f32, f.math
        );
        println!(
            "  paper scenario (EB 150 km/h to standstill, {} steps, closed loop, f32): \
             {:.2} runs/s on {} cores",
            f.steps_per_run, f.runs_per_s, f.threads
        );
        println!("  target: >= 1,000x real time (10 M steps/s) for f32 on one core");
    }
    Ok(())
}

/// Writes a synthetic braking run log of about `mb` MB (the spec's columns, values
/// formatted like `hils decode`'s f32 cells): CSV streaming (small memory), or MDF4 when
/// the file name ends in `.mf4` (through the one run-log writer).
pub fn write_log(path: &std::path::Path, mb: f64) -> Result<()> {
    crate::outputs::write_atomic(path, |w| write_log_to(w, path, mb))
}

/// Noise of the synthetic friction test's mu (one standard deviation).
pub const FRICTION_NOISE: f64 = 0.005;

/// Writes a synthetic friction test of `n` points (spec section 2: `v_friction_mps`,
/// `t_disc_c`, `mu`), labelled synthetic in its metadata: Eq (2) of the reference
/// parameters (the plant's `DiscPadFriction`) at friction speeds 1-45 m/s and disc
/// temperature rises 0-320 degC (uniform), plus Gaussian noise of [`FRICTION_NOISE`]
/// (Box-Muller on a seeded xorshift: the same `n` gives the same file). Streams: any size.
pub fn write_friction_test(w: &mut dyn std::io::Write, n: u64) -> Result<()> {
    let p = hils_plant::Params::default().friction;
    let eq2 =
        hils_plant::friction::DiscPadFriction::<f64>::new(&hils_plant::params::FrictionParams {
            model: hils_plant::FrictionModel::Variable,
            ..p
        });
    writeln!(
        w,
        "# source: SYNTHETIC friction test, not measured: `hils bench --reader FILE \
         --write-friction-points {n}`\n# notes: Eq (2) of the reference parameters \
         (mu_d0 {}, n_v {}, m_v {}, n_t {}, m_t {}, c {}) plus Gaussian noise, sigma \
         {FRICTION_NOISE}; speeds 1-45 m/s, temperature rises 0-320 degC, uniform, seeded\n\
         v_friction_mps,t_disc_c,mu",
        p.mu_d0, p.n_v, p.m_v, p.n_t, p.m_t, p.correction_c
    )?;
    let mut state = 0x2545_F491_4F6C_DD1Du64;
    let mut uniform = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    for _ in 0..n {
        let v = 1.0 + 44.0 * uniform();
        let t = 320.0 * uniform();
        let (u1, u2) = (uniform().max(1e-300), uniform());
        let noise = (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos();
        let mu = eq2.mu_d(v, t, 0.0) + FRICTION_NOISE * noise;
        writeln!(w, "{v:.3},{t:.2},{mu:.5}")?;
    }
    Ok(())
}

/// The synthetic run log of [`write_log`], in the format of `path`'s extension.
fn write_log_to(w: &mut dyn std::io::Write, path: &std::path::Path, mb: f64) -> Result<()> {
    let meta = vec![
        ("source", format!("hils bench --write-log-mb {mb}")),
        ("rail", "dry".to_string()),
    ];
    let header = synthetic_header();
    let target = (mb * 1e6) as u64;
    let format = crate::runlog::Format::of_path(path);
    if format == crate::runlog::Format::Mf4 {
        // Bytes per record: 8 per number, 4 for the command's code.
        let per_row = 8 * (header.len() as u64 - 1) + 4;
        let rows = (0..target.div_ceil(per_row)).map(synthetic_row);
        return crate::runlog::write_table_as(format, w, &meta, &header, rows);
    }
    for (k, v) in &meta {
        writeln!(w, "# {k}: {v}")?;
    }
    writeln!(w, "{}", header.join(","))?;
    let (mut written, mut k) = (0u64, 0u64);
    while written < target {
        let line = synthetic_row(k).join(",") + "\n";
        w.write_all(line.as_bytes())?;
        written += line.len() as u64;
        k += 1;
    }
    Ok(())
}

/// The columns of the synthetic log.
fn synthetic_header() -> Vec<String> {
    use hils_sil::record::run_log::{
        A_X, CMD, F_BRAKE, F_CLAMP, OMEGA, P_CYL, T, T_DISC, V_REF, WSP,
    };
    crate::runlog::column_names(&[
        T, V_REF, OMEGA, P_CYL, F_CLAMP, F_BRAKE, T_DISC, WSP, A_X, CMD,
    ])
}

/// Row `k` of the synthetic log (10 kHz).
fn synthetic_row(k: u64) -> Vec<String> {
    let t = k as f64 * 1e-4;
    let v = (41.7 - 1.39 * (t % 30.0)) as f32;
    let mut row = vec![format!("{t}"), format!("{v}")];
    for j in 0..4 {
        let slip = 0.01 * ((k + j) % 17) as f32;
        row.push(format!("{}", (v - slip) / 0.43));
    }
    for x in [
        250_000.0f32,
        20_000.0,
        7_600.0,
        20.0 + (t % 30.0) as f32 * 3.3,
    ] {
        for j in 0..4 {
            row.push(format!("{}", x * (1.0 + 0.001 * ((k + j) % 7) as f32)));
        }
    }
    for j in 0..4 {
        row.push(format!("{}", (k / 500 + j) % 2));
    }
    row.push(format!("{}", -1.39f32 + 0.001 * (k % 11) as f32));
    row.push("EB".to_string());
    row
}

/// The process's peak resident memory, bytes (Linux `VmHWM`; 0 where unknown).
pub fn peak_rss_bytes() -> u64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmHWM:"))
                .and_then(|l| l.split_whitespace().nth(1)?.parse::<u64>().ok())
        })
        .map_or(0, |kb| kb * 1024)
}

/// Figures of `hils bench --reader FILE`.
#[derive(Debug, Serialize, Clone, PartialEq)]
pub struct ReaderFigures {
    pub file_bytes: u64,
    pub rows: usize,
    pub read_s: f64,
    pub mb_per_s: f64,
    /// Peak resident memory of the process before reading, bytes.
    pub peak_rss_before_bytes: u64,
    /// Peak resident memory of the process after reading (the whole log held), bytes.
    pub peak_rss_bytes: u64,
    /// peak_rss_bytes / file_bytes.
    pub peak_rss_per_file_byte: f64,
}

/// Times reading a measured file and prints the peak memory against its size.
pub fn bench_reader(path: &std::path::Path, json: bool) -> Result<()> {
    bench_reader_with(path, None, json)
}

/// [`bench_reader`] of a file (CSV or MDF4) read through a channel map.
pub fn bench_reader_with(
    path: &std::path::Path,
    map: Option<&std::path::Path>,
    json: bool,
) -> Result<()> {
    let file_bytes = std::fs::metadata(path)?.len();
    let map = crate::measured::load_map(map)?;
    let before = peak_rss_bytes();
    let started = Instant::now();
    let m = crate::measured::read_with(path, map.as_ref())?;
    let read_s = started.elapsed().as_secs_f64();
    let rows = match &m {
        crate::measured::Measured::Run(r) => r.len(),
        crate::measured::Measured::Friction(f) => f.mu.len(),
    };
    let peak = peak_rss_bytes();
    black_box(&m);
    let f = ReaderFigures {
        file_bytes,
        rows,
        read_s,
        mb_per_s: file_bytes as f64 / 1e6 / read_s,
        peak_rss_before_bytes: before,
        peak_rss_bytes: peak,
        peak_rss_per_file_byte: peak as f64 / file_bytes.max(1) as f64,
    };
    if json {
        println!("{}", serde_json::to_string(&f)?);
    } else {
        println!(
            "reader: {} ({:.1} MB, {} rows) in {:.2} s ({:.0} MB/s); peak RSS {:.1} MB \
             ({:.2}x the file; {:.1} MB before reading)",
            path.display(),
            file_bytes as f64 / 1e6,
            rows,
            read_s,
            f.mb_per_s,
            peak as f64 / 1e6,
            f.peak_rss_per_file_byte,
            before as f64 / 1e6
        );
    }
    Ok(())
}
