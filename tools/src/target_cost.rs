//! `hils target-cost`: the plant on the emulated Cortex-M4F.
//!
//! Builds the emulator binary (`firmware/qemu`, `cargo qemu`) unless `--elf` names one,
//! runs it in QEMU (`-machine mps2-an386 -cpu cortex-m4 -icount shift=0`, semihosting),
//! and reads what it prints (see `firmware/qemu/src/main.rs`): the SysTick calibration,
//! instructions per plant step (mean, maximum, percentiles; per part) and the trajectory of
//! the paper's EB for both disc-pad friction models, every f32 as its bit pattern. The same
//! scenario then runs on the host in f32 ([`host_trace`]) and every recorded value is
//! compared bit for bit ([`compare`]); the host run is also checked against what
//! `hils simulate` records ([`check_against_simulate`]). Finally the f32 run is compared
//! with the f64 reference ([`fidelity`]): the math comparison of docs/target.md.
//!
//! The math implementation is the one `hils_plant::math` was compiled with; the emulator is
//! built with the same one, so `cargo run -p hils --features hils-plant/math-libm --
//! target-cost` measures the libm variant, and so on.

use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::{Context, Result, anyhow, bail};
use clap::Args;
use hils_plant::{FrictionModel, Params, WHEELSETS};
use hils_qemu::{EbScenario, RECORD_EVERY, SCALAR_COLUMNS, TraceRow, WHEELSET_COLUMNS};
use serde::Serialize;

use crate::scenario::{EbOptions, Run, run_eb};

/// Targets of the issue: instructions per full plant step.
pub const TARGET_MEAN: f64 = 2500.0;
pub const TARGET_MAX: u32 = 3000;

/// Arguments of `hils target-cost`.
#[derive(Args, Debug, Clone)]
pub struct TargetCostArgs {
    /// Print one JSON object instead of the report.
    #[arg(long)]
    pub json: bool,
    /// Emulator binary to run (default: build it with cargo, `cargo qemu`).
    #[arg(long)]
    pub elf: Option<PathBuf>,
    /// QEMU system emulator for Arm.
    #[arg(long, default_value = "qemu-system-arm")]
    pub qemu: String,
    /// Give up on the emulator after this many seconds.
    #[arg(long, default_value_t = 900)]
    pub timeout_s: u64,
    /// Also save the emulator's raw output (trajectory lines included) to this file.
    #[arg(long)]
    pub save_output: Option<PathBuf>,
}

/// Distribution of one part's instructions per step over a run.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct PartCost {
    /// Steps measured.
    pub n: u64,
    pub mean: f64,
    pub max: u32,
    /// Step (1-based) at which the maximum occurred.
    pub max_step: u32,
    /// Median and 99th percentile (upper edge of an 8-instruction bin).
    pub p50: u32,
    pub p99: u32,
}

/// One friction model's run on the emulator.
#[derive(Clone, Debug, Default)]
pub struct TargetRun {
    pub friction: String,
    pub rows: Vec<TraceRow>,
    /// Costs in the order of [`PARTS`].
    pub parts: Vec<(String, PartCost)>,
    pub steps: u32,
    pub stop_step: Option<u32>,
    /// The instructions of the harness around a sub-model call (subtracted).
    pub harness_baseline: u32,
}

impl TargetRun {
    /// The cost of part `name`.
    pub fn part(&self, name: &str) -> Option<&PartCost> {
        self.parts.iter().find(|(n, _)| n == name).map(|(_, c)| c)
    }
}

/// A calibration check: a loop of exactly `expected` instructions, as measured.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct CalibrationPoint {
    pub expected: u32,
    pub measured: u32,
}

/// Instructions per call of a math function over an argument range.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct FunctionCost {
    pub name: String,
    pub calls: u64,
    pub mean: f64,
    pub max: u32,
}

/// Everything the emulator printed, parsed.
#[derive(Clone, Debug, Default)]
pub struct EmulatorOutput {
    pub math: String,
    pub instructions_per_tick: u32,
    pub timer_overhead: u32,
    pub calibration: Vec<CalibrationPoint>,
    pub functions: Vec<FunctionCost>,
    pub runs: Vec<TargetRun>,
}

impl EmulatorOutput {
    pub fn run(&self, friction: &str) -> Option<&TargetRun> {
        self.runs.iter().find(|r| r.friction == friction)
    }
}

fn kv<'a>(line: &'a str, key: &str) -> Result<&'a str> {
    line.split(' ')
        .find_map(|f| f.strip_prefix(key).and_then(|r| r.strip_prefix('=')))
        .ok_or_else(|| anyhow!("emulator line lacks `{key}=`: {line}"))
}

fn num<T: std::str::FromStr>(line: &str, key: &str) -> Result<T> {
    let v = kv(line, key)?;
    v.parse()
        .map_err(|_| anyhow!("emulator line: `{key}={v}` is not a number: {line}"))
}

/// Parses the emulator's output (see `firmware/qemu/src/main.rs` for the line kinds).
/// An `X` line (an error the target reported), a malformed line, a run without its end
/// line or a trajectory row outside a run is an error.
pub fn parse_output(text: &str) -> Result<EmulatorOutput> {
    let mut out = EmulatorOutput::default();
    let mut current: Option<TargetRun> = None;
    let mut header = false;
    for (i, line) in text.lines().enumerate() {
        let at = || format!("emulator output line {}", i + 1);
        let kind = line.split(' ').next().unwrap_or("");
        match kind {
            "H" => {
                out.math = kv(line, "math")?.to_string();
                out.instructions_per_tick = num(line, "instructions_per_tick")?;
                out.timer_overhead = num(line, "overhead")?;
                header = true;
            }
            "K" => out.calibration.push(CalibrationPoint {
                expected: num(line, "n")?,
                measured: num(line, "instructions")?,
            }),
            "F" => {
                let calls: u64 = num(line, "n")?;
                let sum: u64 = num(line, "sum")?;
                out.functions.push(FunctionCost {
                    name: kv(line, "fn")?.to_string(),
                    calls,
                    mean: sum as f64 / calls.max(1) as f64,
                    max: num(line, "max")?,
                });
            }
            "B" => {
                if current.is_some() {
                    bail!("{}: a run starts before the previous one ended", at());
                }
                current = Some(TargetRun {
                    friction: kv(line, "friction")?.to_string(),
                    harness_baseline: num(line, "harness_baseline")?,
                    ..TargetRun::default()
                });
            }
            "R" => {
                let run = current
                    .as_mut()
                    .ok_or_else(|| anyhow!("{}: a row outside a run", at()))?;
                let row = TraceRow::decode(line)
                    .ok_or_else(|| anyhow!("{}: malformed trajectory row", at()))?;
                run.rows.push(row);
            }
            "C" => {
                let run = current
                    .as_mut()
                    .ok_or_else(|| anyhow!("{}: costs outside a run", at()))?;
                let n: u64 = num(line, "n")?;
                let sum: u64 = num(line, "sum")?;
                run.parts.push((
                    kv(line, "part")?.to_string(),
                    PartCost {
                        n,
                        mean: sum as f64 / n.max(1) as f64,
                        max: num(line, "max")?,
                        max_step: num(line, "max_step")?,
                        p50: num(line, "p50")?,
                        p99: num(line, "p99")?,
                    },
                ));
            }
            "E" => {
                let mut run = current
                    .take()
                    .ok_or_else(|| anyhow!("{}: a run ends that never started", at()))?;
                run.steps = num(line, "steps")?;
                run.stop_step = match kv(line, "stop_step")? {
                    "none" => None,
                    s => Some(s.parse().map_err(|_| anyhow!("{}: bad stop_step", at()))?),
                };
                let rows: usize = num(line, "rows")?;
                if rows != run.rows.len() {
                    bail!(
                        "{}: the target sent {rows} rows but {} arrived intact",
                        at(),
                        run.rows.len()
                    );
                }
                out.runs.push(run);
            }
            "X" => bail!(
                "the emulated target reported an error: {}",
                &line[1..].trim()
            ),
            "" => {}
            _ => bail!("{}: unexpected line: {line}", at()),
        }
    }
    if let Some(run) = current {
        bail!(
            "the emulator's {} friction run did not end (output cut short?)",
            run.friction
        );
    }
    if !header {
        bail!("the emulator printed no header line (not the hils-qemu binary?)");
    }
    Ok(out)
}

/// The workspace root (the emulator crate is `firmware/qemu` below it).
pub fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// Cargo features of the emulator that select the math implementation this program was
/// built with, so that host and target compute with the same functions.
pub fn emulator_features() -> &'static [&'static str] {
    match hils_plant::math::IMPLEMENTATION {
        "micromath" => &["--features", "math-micromath"],
        "libm" => &["--features", "math-libm"],
        _ => &[],
    }
}

/// Builds the emulator binary (release, thumbv7em-none-eabihf, the host's math) with
/// cargo and returns the ELF's path (as cargo reports it).
pub fn build_elf() -> Result<PathBuf> {
    let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
    let output = Command::new(&cargo)
        .current_dir(workspace_root())
        .args([
            "build",
            "--release",
            "-p",
            "hils-qemu",
            "--target",
            "thumbv7em-none-eabihf",
        ])
        .args(emulator_features())
        .args(["--message-format", "json-render-diagnostics"])
        .stderr(Stdio::inherit())
        .output()
        .with_context(|| format!("cannot run {}", Path::new(&cargo).display()))?;
    if !output.status.success() {
        bail!(
            "building the emulator binary failed ({}); it needs the thumbv7em-none-eabihf \
             target: `rustup target add thumbv7em-none-eabihf`",
            output.status
        );
    }
    let stdout = String::from_utf8_lossy(&output.stdout);
    for line in stdout.lines() {
        let Ok(msg) = serde_json::from_str::<serde_json::Value>(line) else {
            continue;
        };
        if msg["reason"] == "compiler-artifact"
            && msg["target"]["name"] == "hils-qemu"
            && let Some(exe) = msg["executable"].as_str()
        {
            return Ok(PathBuf::from(exe));
        }
    }
    bail!("cargo built no hils-qemu executable")
}

/// Runs the emulator binary in QEMU and returns its standard output. Fails if QEMU is
/// missing, exits with failure (the target's own checks failed) or takes longer than
/// `timeout`.
pub fn run_emulator(qemu: &str, elf: &Path, timeout: Duration) -> Result<String> {
    let mut child = Command::new(qemu)
        .args(["-machine", "mps2-an386", "-cpu", "cortex-m4"])
        .args(["-nographic", "-monitor", "none", "-serial", "none"])
        .args(["-semihosting-config", "enable=on,target=native"])
        .args(["-icount", "shift=0"])
        .arg("-kernel")
        .arg(elf)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .with_context(|| {
            format!("cannot start {qemu} (Debian/Ubuntu: `apt-get install qemu-system-arm`)")
        })?;
    let mut stdout = child.stdout.take().ok_or_else(|| anyhow!("no stdout"))?;
    let mut stderr = child.stderr.take().ok_or_else(|| anyhow!("no stderr"))?;
    let reader = std::thread::spawn(move || {
        let mut s = String::new();
        stdout.read_to_string(&mut s).map(|_| s)
    });
    let err_reader = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = stderr.read_to_string(&mut s);
        s
    });
    let started = Instant::now();
    let status = loop {
        if let Some(status) = child.try_wait()? {
            break status;
        }
        if started.elapsed() > timeout {
            let _ = child.kill();
            let _ = child.wait();
            bail!("the emulator did not finish within {} s", timeout.as_secs());
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    let text = reader
        .join()
        .map_err(|_| anyhow!("reader thread failed"))??;
    let errors = err_reader.join().unwrap_or_default();
    if !status.success() {
        let last = text.lines().rfind(|l| !l.starts_with('R')).unwrap_or("");
        bail!(
            "the emulator exited with {status}; last line: {last}; stderr: {}",
            errors.trim()
        );
    }
    Ok(text)
}

/// The trajectory of the emulator's scenario computed on the host in f32, with the same
/// driver and row format, and the host run's step count and stop step.
pub fn host_trace(friction: FrictionModel) -> Result<(Vec<TraceRow>, u32, Option<u32>)> {
    let mut sc = EbScenario::<f32>::paper(friction).map_err(|e| anyhow!("{e}"))?;
    let mut rows = vec![TraceRow::of(&sc.sim)];
    loop {
        let adv = sc.advance(|sim| {
            sim.step();
        });
        if adv.record {
            rows.push(TraceRow::of(&sc.sim));
        }
        if adv.done {
            break;
        }
    }
    Ok((rows, sc.steps(), sc.stop_step()))
}

/// Names of the values of a [`TraceRow`]: `step`, `flags`, `valves`, then the columns.
pub fn column_names() -> Vec<String> {
    let mut names = vec!["step".to_string(), "flags".into(), "valves".into()];
    names.extend(SCALAR_COLUMNS.iter().map(|s| s.to_string()));
    for j in 1..=WHEELSETS {
        names.extend(WHEELSET_COLUMNS.iter().map(|c| format!("{c}{j}")));
    }
    names
}

/// The first difference between two trajectories.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Mismatch {
    pub row: usize,
    pub step: u32,
    pub column: String,
    pub target_bits: u32,
    pub host_bits: u32,
}

/// Result of the bit-for-bit comparison of one friction model's trajectories.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Comparison {
    pub friction: String,
    pub identical: bool,
    pub rows_target: usize,
    pub rows_host: usize,
    /// Values compared (rows x words).
    pub values_compared: usize,
    /// Values that differ.
    pub values_different: usize,
    pub first_mismatch: Option<Mismatch>,
}

/// Compares every word (step, flags, valves, every f32 bit pattern) of every row. The
/// trajectories are identical only if they also have the same number of rows.
pub fn compare(friction: &str, target: &[TraceRow], host: &[TraceRow]) -> Comparison {
    let names = column_names();
    let words = |r: &TraceRow| {
        let mut w = vec![r.step, r.flags, r.valves];
        w.extend_from_slice(&r.values);
        w
    };
    let mut values_compared = 0;
    let mut values_different = 0;
    let mut first_mismatch = None;
    for (i, (t, h)) in target.iter().zip(host).enumerate() {
        for (k, (a, b)) in words(t).into_iter().zip(words(h)).enumerate() {
            values_compared += 1;
            if a != b {
                values_different += 1;
                first_mismatch.get_or_insert(Mismatch {
                    row: i,
                    step: h.step,
                    column: names[k].clone(),
                    target_bits: a,
                    host_bits: b,
                });
            }
        }
    }
    Comparison {
        friction: friction.to_string(),
        identical: values_different == 0 && target.len() == host.len() && !host.is_empty(),
        rows_target: target.len(),
        rows_host: host.len(),
        values_compared,
        values_different,
        first_mismatch,
    }
}

/// Checks the host trajectory against what `hils simulate` records for the same run
/// (`run_eb::<f32>` sampled every [`RECORD_EVERY`] steps): the same samples, every
/// shared value equal (f32 to f64 and back is exact). Returns the number of values checked.
pub fn check_against_simulate(friction: FrictionModel, rows: &[TraceRow]) -> Result<usize> {
    let mut params = Params::default();
    params.friction.model = friction;
    let mut opts = EbOptions::paper(&params);
    opts.record_every = RECORD_EVERY;
    let run = run_eb::<f32>(&params, &opts)?;
    if run.samples.len() != rows.len() {
        bail!(
            "hils simulate records {} samples, the emulator scenario {}",
            run.samples.len(),
            rows.len()
        );
    }
    let col = |name: &str| SCALAR_COLUMNS.iter().position(|c| *c == name);
    let wcol = |name: &str| WHEELSET_COLUMNS.iter().position(|c| *c == name);
    let mut checked = 0;
    for (i, (s, r)) in run.samples.iter().zip(rows).enumerate() {
        let mut same = |what: &str, sim: f64, row: f32| -> Result<()> {
            checked += 1;
            if sim as f32 != row || (sim.is_nan() != row.is_nan()) {
                bail!("sample {i}: {what} is {sim} in hils simulate but {row} in the trace");
            }
            Ok(())
        };
        let scalar = |name: &str| r.value(col(name).unwrap_or(usize::MAX));
        same("t", s.t, scalar("t_s"))?;
        same("v_ref", s.v_ref, scalar("vehicle_speed_mps"))?;
        same("distance", s.distance, scalar("distance_m"))?;
        same("a_x", s.a_x, scalar("carbody_accel_mps2"))?;
        same(
            "v_ref_estimate",
            s.v_ref_estimate,
            scalar("reference_speed_mps"),
        )?;
        for j in 0..WHEELSETS {
            let w = |name: &str| r.wheelset_value(j, wcol(name).unwrap_or(usize::MAX));
            same("omega", s.omega[j], w("omega_radps"))?;
            same("p_cyl", s.p_cyl[j], w("cylinder_pressure_pa"))?;
            same("f_clamp", s.f_clamp[j], w("clamp_force_n"))?;
            same("f_brake", s.f_brake[j], w("brake_force_n"))?;
            same("t_disc", s.t_disc[j], w("disc_temp_c"))?;
            same("q", s.q[j], w("axle_load_n"))?;
            same("mu_d", s.mu_d[j], w("mu_d"))?;
            same("creepage", s.creepage[j], w("creepage"))?;
            same("adhesion", s.adhesion[j], w("adhesion"))?;
            same("wsp", s.wsp[j] as u8 as f64, r.venting(j) as u8 as f32)?;
        }
    }
    Ok(checked)
}

/// One friction model's f32 run (the compiled-in math) against the f64 reference.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Fidelity {
    pub friction: String,
    pub stop_time_f32_s: Option<f64>,
    pub stop_time_f64_s: Option<f64>,
    pub stopping_distance_f32_m: Option<f64>,
    pub stopping_distance_f64_m: Option<f64>,
    /// (f32 - f64) / f64, percent.
    pub stopping_distance_error_pct: Option<f64>,
    pub slides_f32: Vec<usize>,
    pub slides_f64: Vec<usize>,
    /// First WSP vent per wheelset, s.
    pub slide_onsets_f32_s: [Option<f64>; 4],
    pub slide_onsets_f64_s: [Option<f64>; 4],
    /// Largest |onset f32 - onset f64| over wheelsets that slide in both, ms.
    pub slide_onset_max_diff_ms: Option<f64>,
    /// Largest |mu_d f32 - mu_d f64| over the 1 kHz samples and wheelsets while moving.
    pub mu_d_max_abs_diff: f64,
    /// Mean over wheelsets of the same, RMS over time.
    pub mu_d_rms_diff: f64,
}

/// The f32 run against the f64 run of the paper's EB (`hils simulate`'s runs, 1 kHz).
pub fn fidelity(friction: FrictionModel) -> Result<Fidelity> {
    let mut params = Params::default();
    params.friction.model = friction;
    let opts = EbOptions::paper(&params);
    let a = run_eb::<f32>(&params, &opts)?;
    let b = run_eb::<f64>(&params, &opts)?;
    Ok(compare_runs(friction, &a, &b))
}

fn compare_runs(friction: FrictionModel, a: &Run, b: &Run) -> Fidelity {
    let (sa, sb) = (&a.summary, &b.summary);
    let onsets_diff = (0..4)
        .filter_map(|j| Some((sa.slide_onset_s[j]? - sb.slide_onset_s[j]?).abs() * 1e3))
        .fold(None, |m: Option<f64>, d| Some(m.map_or(d, |m| m.max(d))));
    let mut max_diff = 0.0f64;
    let (mut sq, mut n) = (0.0f64, 0usize);
    let end = sb.stop_time_s.unwrap_or(f64::INFINITY);
    for (x, y) in a.samples.iter().zip(&b.samples) {
        if y.t > end {
            break;
        }
        for j in 0..4 {
            let d = (x.mu_d[j] - y.mu_d[j]).abs();
            max_diff = max_diff.max(d);
            sq += d * d;
            n += 1;
        }
    }
    let err = match (sa.stopping_distance_m, sb.stopping_distance_m) {
        (Some(x), Some(y)) => Some((x - y) / y * 100.0),
        _ => None,
    };
    Fidelity {
        friction: friction_name(friction).to_string(),
        stop_time_f32_s: sa.stop_time_s,
        stop_time_f64_s: sb.stop_time_s,
        stopping_distance_f32_m: sa.stopping_distance_m,
        stopping_distance_f64_m: sb.stopping_distance_m,
        stopping_distance_error_pct: err,
        slides_f32: sa.slides.clone(),
        slides_f64: sb.slides.clone(),
        slide_onsets_f32_s: sa.slide_onset_s,
        slide_onsets_f64_s: sb.slide_onset_s,
        slide_onset_max_diff_ms: onsets_diff,
        mu_d_max_abs_diff: max_diff,
        mu_d_rms_diff: (sq / n.max(1) as f64).sqrt(),
    }
}

fn friction_name(f: FrictionModel) -> &'static str {
    match f {
        FrictionModel::Variable => "variable",
        FrictionModel::Constant => "constant",
    }
}

/// The figures of `hils target-cost --json`.
#[derive(Clone, Debug, Serialize)]
pub struct TargetCost {
    /// Mean instructions per full plant step (`Plant::step`): the larger of the two
    /// friction models' means over the scenario.
    pub instructions_mean: f64,
    /// Largest instructions of one plant step over both runs.
    pub instructions_max: u32,
    /// Host f32 and emulated target trajectories equal bit for bit, both frictions.
    pub bit_identical: bool,
    pub target_mean: f64,
    pub target_max: u32,
    pub within_targets: bool,
    pub math: String,
    pub machine: &'static str,
    pub instructions_per_systick_tick: u32,
    /// Largest |measured - known| over the calibration loops, instructions.
    pub calibration_max_error: u32,
    pub frictions: Vec<FrictionCost>,
    pub functions: Vec<FunctionCost>,
    pub fidelity: Vec<Fidelity>,
    pub emulator_wall_s: f64,
}

/// One friction model's figures.
#[derive(Clone, Debug, Serialize)]
pub struct FrictionCost {
    pub friction: String,
    pub steps: u32,
    pub stop_step: Option<u32>,
    /// Per part, in the order of `hils_qemu::PARTS`.
    pub parts: std::collections::BTreeMap<String, PartCost>,
    pub comparison: Comparison,
    /// Values checked against `hils simulate`'s samples of the same run.
    pub simulate_values_checked: usize,
}

/// Runs everything: build (or take) the ELF, emulate, compare with the host, fidelity.
pub fn measure(args: &TargetCostArgs) -> Result<TargetCost> {
    let elf = match &args.elf {
        Some(p) => p.clone(),
        None => build_elf()?,
    };
    let started = Instant::now();
    let text = run_emulator(&args.qemu, &elf, Duration::from_secs(args.timeout_s))?;
    let wall = started.elapsed().as_secs_f64();
    if let Some(path) = &args.save_output {
        std::fs::write(path, &text).with_context(|| format!("cannot write {}", path.display()))?;
    }
    evaluate(&text, wall)
}

/// The figures from the emulator's output (host comparison and fidelity included).
pub fn evaluate(text: &str, emulator_wall_s: f64) -> Result<TargetCost> {
    let out = parse_output(text)?;
    if out.math != hils_plant::math::IMPLEMENTATION {
        bail!(
            "the emulator computes with `{}` but this program with `{}`: build both alike",
            out.math,
            hils_plant::math::IMPLEMENTATION
        );
    }
    let mut frictions = Vec::new();
    let mut fid = Vec::new();
    for friction in [FrictionModel::Variable, FrictionModel::Constant] {
        let name = friction_name(friction);
        let run = out
            .run(name)
            .ok_or_else(|| anyhow!("the emulator output has no {name} friction run"))?;
        let (host_rows, _, _) = host_trace(friction)?;
        let comparison = compare(name, &run.rows, &host_rows);
        let simulate_values_checked = check_against_simulate(friction, &host_rows)?;
        let parts = run.parts.iter().cloned().collect();
        frictions.push(FrictionCost {
            friction: name.to_string(),
            steps: run.steps,
            stop_step: run.stop_step,
            parts,
            comparison,
            simulate_values_checked,
        });
        fid.push(fidelity(friction)?);
    }
    let step_costs: Vec<PartCost> = out
        .runs
        .iter()
        .map(|r| {
            r.part("step")
                .copied()
                .ok_or_else(|| anyhow!("no `step` cost line"))
        })
        .collect::<Result<_>>()?;
    let instructions_mean = step_costs.iter().map(|c| c.mean).fold(0.0, f64::max);
    let instructions_max = step_costs.iter().map(|c| c.max).max().unwrap_or(0);
    let bit_identical = frictions.iter().all(|f| f.comparison.identical);
    let calibration_max_error = out
        .calibration
        .iter()
        .map(|c| c.measured.abs_diff(c.expected))
        .max()
        .unwrap_or(0);
    Ok(TargetCost {
        instructions_mean,
        instructions_max,
        bit_identical,
        target_mean: TARGET_MEAN,
        target_max: TARGET_MAX,
        within_targets: instructions_mean <= TARGET_MEAN && instructions_max <= TARGET_MAX,
        math: out.math.clone(),
        machine: "QEMU mps2-an386 (Cortex-M4F), -icount shift=0",
        instructions_per_systick_tick: out.instructions_per_tick,
        calibration_max_error,
        frictions,
        functions: out.functions.clone(),
        fidelity: fid,
        emulator_wall_s,
    })
}

fn opt(x: Option<f64>, digits: usize) -> String {
    x.map_or("-".to_string(), |v| format!("{v:.digits$}"))
}

/// The text report.
pub fn report(c: &TargetCost) -> String {
    use std::fmt::Write;
    let mut s = String::new();
    let _ = writeln!(s, "Plant on the emulated Cortex-M4F: {}", c.machine);
    let _ = writeln!(
        s,
        "  math: {}; 1 SysTick tick = {} instructions; timer checked against known loops \
         within {} instructions",
        c.math, c.instructions_per_systick_tick, c.calibration_max_error
    );
    let _ = writeln!(
        s,
        "Instructions per step, paper EB (150 km/h, wet), every step of the run:"
    );
    let _ = writeln!(
        s,
        "  {:<38} {:>27} {:>27}",
        "", "variable friction", "constant friction"
    );
    let label = |p: &str| match p {
        "step" => "full plant step (Plant::step)",
        "contact" => "  contact, 4 wheelsets (Eqs 9-12)",
        "friction" => "  friction, 4 wheelsets (Eq 2)",
        "thermal" => "  thermal, 4 wheelsets (Eqs 3-6)",
        "suspension" => "  suspension, bodies, spin (the rest)",
        "loop" => "closed loop (brake unit + plant)",
        "unit" => "  brake unit + wiring",
        _ => "?",
    };
    for part in [
        "step",
        "contact",
        "friction",
        "thermal",
        "suspension",
        "loop",
        "unit",
    ] {
        let cell = |f: &FrictionCost| {
            f.parts.get(part).map_or("-".to_string(), |p| {
                format!("mean {:6.0} max {:5} p99 {:5}", p.mean, p.max, p.p99)
            })
        };
        let _ = writeln!(
            s,
            "  {:<38} {:>27} {:>27}",
            label(part),
            c.frictions.first().map(cell).unwrap_or_default(),
            c.frictions.get(1).map(cell).unwrap_or_default()
        );
    }
    let _ = writeln!(
        s,
        "  targets: mean <= {} ({:.0}: {}), max <= {} ({}: {})",
        c.target_mean,
        c.instructions_mean,
        if c.instructions_mean <= c.target_mean {
            "met"
        } else {
            "NOT MET"
        },
        c.target_max,
        c.instructions_max,
        if c.instructions_max <= c.target_max {
            "met"
        } else {
            "NOT MET"
        }
    );
    let _ = writeln!(s, "Math functions (instructions per call):");
    for f in &c.functions {
        let _ = writeln!(
            s,
            "  {:<6} mean {:5.1} max {:4} ({} arguments)",
            f.name, f.mean, f.max, f.calls
        );
    }
    let _ = writeln!(s, "Host f32 vs emulated target, bit for bit:");
    for f in &c.frictions {
        let cmp = &f.comparison;
        let verdict = if cmp.identical {
            format!(
                "IDENTICAL: {} rows x {} values ({} values; {} also equal to hils simulate's samples)",
                cmp.rows_target,
                column_names().len(),
                cmp.values_compared,
                f.simulate_values_checked
            )
        } else {
            format!(
                "DIFFERENT: {} of {} values, rows {} (target) vs {} (host); first: {:?}",
                cmp.values_different,
                cmp.values_compared,
                cmp.rows_target,
                cmp.rows_host,
                cmp.first_mismatch
            )
        };
        let _ = writeln!(s, "  {:<9} {verdict}", f.friction);
    }
    let _ = writeln!(
        s,
        "Fidelity of the f32 run ({}) against the f64 reference (libm):",
        c.math
    );
    for f in &c.fidelity {
        let _ = writeln!(
            s,
            "  {:<9} stop {} s vs {} s, distance {} m vs {} m ({} %); slides {:?} vs {:?}, \
             onsets differ by <= {} ms; mu_d max |diff| {:.2e}, rms {:.2e}",
            f.friction,
            opt(f.stop_time_f32_s, 4),
            opt(f.stop_time_f64_s, 4),
            opt(f.stopping_distance_f32_m, 2),
            opt(f.stopping_distance_f64_m, 2),
            opt(f.stopping_distance_error_pct, 4),
            f.slides_f32,
            f.slides_f64,
            opt(f.slide_onset_max_diff_ms, 1),
            f.mu_d_max_abs_diff,
            f.mu_d_rms_diff
        );
    }
    let _ = writeln!(s, "  (emulator wall time {:.1} s)", c.emulator_wall_s);
    s
}

/// `hils target-cost`.
pub fn main(args: TargetCostArgs) -> Result<()> {
    let c = measure(&args)?;
    if args.json {
        println!("{}", serde_json::to_string(&c)?);
    } else {
        print!("{}", report(&c));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(step: u32) -> TraceRow {
        let mut values = [0u32; hils_qemu::VALUES];
        for (k, v) in values.iter_mut().enumerate() {
            *v = (k as f32 * 0.5 + step as f32).to_bits();
        }
        TraceRow {
            step,
            flags: 0,
            valves: 0b10_00_01_00,
            values,
        }
    }

    fn encoded(r: &TraceRow) -> String {
        let mut buf = [0u8; hils_qemu::LINE_LEN];
        r.encode(&mut buf);
        String::from_utf8(buf.to_vec()).expect("ascii")
    }

    fn sample_output(rows: &[TraceRow]) -> String {
        let mut s = String::from(
            "H hils-qemu math=M instructions_per_tick=40 ticks_for_2000000=50001 overhead=0 spin=4\n\
             K n=2000 instructions=2004\nF fn=exp n=10 sum=320 max=32 lo=-20 hi=3\n\
             B friction=variable harness_baseline=32\n",
        );
        for r in rows {
            s += &encoded(r);
        }
        s += "C friction=variable part=step n=4 sum=10000 max=2600 max_step=3 p50=2504 p99=2600\n";
        s += &format!(
            "E friction=variable steps=400 stop_step=300 rows={}\n",
            rows.len()
        );
        s
    }

    #[test]
    fn parses_what_the_emulator_prints() {
        let rows = [row(0), row(100), row(200)];
        let out = parse_output(&sample_output(&rows)).expect("parses");
        assert_eq!(out.math, "M");
        assert_eq!(out.instructions_per_tick, 40);
        assert_eq!(
            out.calibration,
            vec![CalibrationPoint {
                expected: 2000,
                measured: 2004
            }]
        );
        assert_eq!(out.functions[0].mean, 32.0);
        let run = out.run("variable").expect("run");
        assert_eq!(run.rows, rows);
        assert_eq!(run.stop_step, Some(300));
        let step = run.part("step").expect("step");
        assert_eq!((step.mean, step.max, step.max_step), (2500.0, 2600, 3));
    }

    #[test]
    fn rejects_cut_or_corrupt_output() {
        let rows = [row(0), row(100)];
        let good = sample_output(&rows);
        // Cut short: no end line.
        let cut = &good[..good.find("C friction").expect("cost line")];
        assert!(
            parse_output(cut)
                .unwrap_err()
                .to_string()
                .contains("did not end")
        );
        // A corrupted row.
        let bad = good.replacen(" 00000064 ", " 0000z064 ", 1);
        assert!(
            parse_output(&bad)
                .unwrap_err()
                .to_string()
                .contains("malformed")
        );
        // A row lost: the count in the end line no longer matches.
        let lost = good.replacen(&encoded(&rows[1]), "", 1);
        assert!(
            parse_output(&lost)
                .unwrap_err()
                .to_string()
                .contains("arrived intact")
        );
        // The target's own error report.
        let err =
            parse_output("H hils-qemu math=M instructions_per_tick=40 overhead=0\nX panic: boom\n");
        assert!(err.unwrap_err().to_string().contains("boom"));
    }

    #[test]
    fn comparison_finds_a_single_flipped_bit() {
        let host = vec![row(0), row(100), row(200)];
        assert!(compare("variable", &host, &host).identical);
        let mut target = host.clone();
        target[2].values[20] ^= 1;
        let c = compare("variable", &target, &host);
        assert!(!c.identical);
        assert_eq!(c.values_different, 1);
        let m = c.first_mismatch.expect("mismatch");
        assert_eq!((m.row, m.step), (2, 200));
        assert_eq!(m.column, column_names()[3 + 20]);
        // A missing row is a difference too.
        assert!(!compare("variable", &host[..2], &host).identical);
    }
}
