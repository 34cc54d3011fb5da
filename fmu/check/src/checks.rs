//! The checks of `hils-fmu-check direct` and the reference data of `reference`.

use std::io::Write;
use std::path::Path;

use anyhow::{Context, Result, bail};
use hils_fmu_check::direct::{ERROR, Fmu, Instance, OK, Outputs, expect_refusal};
use hils_fmu_check::{UNIT_OUTPUTS, columns, first_difference, names, paper_run, values};
use hils_plant::FrictionModel;
use hils_sil::{ParamFile, RunRecord};

/// The closed loop's communication step, s.
const LOOP_STEP_S: f64 = 1e-3;

/// Steps of the closed loop (or of the plant alone) and compares every output at every
/// communication point with the run's records.
struct Compared<'a> {
    inst: Instance<'a>,
    outputs: &'a Outputs,
    names: Vec<String>,
    columns: Vec<usize>,
    buffer: Vec<f64>,
    t: f64,
    skip: &'static [&'static str],
}

impl<'a> Compared<'a> {
    fn new(fmu: &'a Fmu, outputs: &'a Outputs, name: &str, closed_loop: bool) -> Result<Self> {
        let names = outputs.names();
        let mut inst = fmu.instantiate(name)?;
        if closed_loop {
            // brake_input = brake_unit, cmd = EB
            let s = inst.set_i64("brake_input", 2)?;
            check(&inst, s)?;
            let s = inst.set_i64("cmd", 1)?;
            check(&inst, s)?;
        }
        Ok(Compared {
            inst,
            outputs,
            columns: columns(&names)?,
            names,
            buffer: Vec::new(),
            t: 0.0,
            skip: if closed_loop { &[] } else { &UNIT_OUTPUTS },
        })
    }

    /// One communication step of `h` s, then the comparison with `record` (step `k`).
    fn step(&mut self, h: f64, record: &RunRecord, k: usize) -> Result<()> {
        let status = self.inst.step(self.t, h);
        check(&self.inst, status)?;
        self.t += h;
        self.outputs.read(&mut self.inst, &mut self.buffer)?;
        if let Some(d) = first_difference(
            record,
            &self.names,
            &self.columns,
            &self.buffer,
            self.skip,
            k,
        ) {
            bail!("{d}");
        }
        Ok(())
    }

    fn output(&self, name: &str) -> f64 {
        self.names
            .iter()
            .position(|n| n == name)
            .map_or(f64::NAN, |i| self.buffer[i])
    }
}

fn check(inst: &Instance<'_>, status: i32) -> Result<()> {
    if status != OK {
        bail!("status {status}: {}", inst.last_message());
    }
    Ok(())
}

/// `hils-fmu-check direct FMU`.
pub fn direct(path: &Path) -> Result<()> {
    let fmu = Fmu::open(path)?;
    let outputs = Outputs::of(&fmu);
    let file = ParamFile::default();
    let run = paper_run(&file)?;
    let every = (LOOP_STEP_S / file.scenario.paper_eb.step_s).round() as usize;

    let mut sim = Compared::new(&fmu, &outputs, "closed-loop", true)?;
    sim.inst.initialize()?;
    let mut points = 0;
    for (k, s) in run.samples.iter().enumerate().step_by(every).skip(1) {
        sim.step(LOOP_STEP_S, s, k)?;
        points += 1;
    }
    println!(
        "direct import: closed loop (brake_input = brake_unit, cmd = EB) at 1 ms: {points} communication points x {} outputs bit-identical to hils simulate (stop {:.2} s, {:.1} m)",
        outputs.names().len(),
        run.summary.stop_time_s.unwrap_or(f64::NAN),
        run.summary.stopping_distance_m.unwrap_or(f64::NAN)
    );

    plant_at_every_step(&fmu, &outputs, &run)?;
    two_instances(&fmu, &outputs, &file, &run)?;
    bad_use(&fmu)?;
    Ok(())
}

/// The plant alone, driven by the run's cylinder pressures at the plant step.
fn plant_at_every_step(fmu: &Fmu, outputs: &Outputs, run: &hils::scenario::Run) -> Result<()> {
    let mut sim = Compared::new(fmu, outputs, "plant", false)?;
    let inputs: Vec<u32> = (1..=4)
        .map(|j| fmu.vr(&format!("p_cyl{j}_pa")))
        .collect::<Result<_>>()?;
    sim.inst.initialize()?;
    for (k, s) in run.samples.iter().enumerate().skip(1) {
        let status = sim.inst.set_f64(&inputs, &s.p_cyl_pa);
        check(&sim.inst, status)?;
        sim.step(run.dt, s, k)?;
    }
    println!(
        "direct import: plant driven by the run's p_cyl1..4_pa at {} s: {} communication points bit-identical",
        run.dt,
        run.samples.len() - 1
    );
    Ok(())
}

/// Two instances, different parameter files (the reference file and one with the constant
/// mu_d0), stepped in turn in one process: each equals its own `hils simulate` run, and
/// they differ (only the variable friction slides).
fn two_instances(
    fmu: &Fmu,
    outputs: &Outputs,
    file: &ParamFile,
    run: &hils::scenario::Run,
) -> Result<()> {
    let mut constant = *file;
    constant.plant.friction.model = FrictionModel::Constant;
    let other_run = paper_run(&constant)?;
    let dir = tempfile::tempdir()?;
    let other_file = dir.path().join("constant-friction.toml");
    let text = std::fs::read_to_string(Path::new(&resources_of(fmu)?).join("parameters.toml"))?;
    let replaced = text.replace("model = \"variable\"", "model = \"constant\"");
    if replaced == text {
        bail!("the resource has no friction.model = \"variable\" to change");
    }
    std::fs::write(&other_file, replaced)?;

    let mut a = Compared::new(fmu, outputs, "reference-file", true)?;
    let mut b = Compared::new(fmu, outputs, "constant-friction-file", true)?;
    let status = b
        .inst
        .set_string("params_file", &other_file.display().to_string())?;
    check(&b.inst, status)?;
    a.inst.initialize()?;
    b.inst.initialize()?;
    let every = (LOOP_STEP_S / run.dt).round() as usize;
    let (mut vents_a, mut vents_b) = (0, 0);
    let points = run.samples.len().min(other_run.samples.len());
    for k in (every..points).step_by(every) {
        a.step(LOOP_STEP_S, &run.samples[k], k)?;
        b.step(LOOP_STEP_S, &other_run.samples[k], k)?;
        vents_a += (1..=4)
            .filter(|j| a.output(&format!("wsp{j}")) > 0.0)
            .count();
        vents_b += (1..=4)
            .filter(|j| b.output(&format!("wsp{j}")) > 0.0)
            .count();
    }
    if vents_a == 0 || vents_b != 0 {
        bail!(
            "two instances: WSP vent samples {vents_a} (reference file) and {vents_b} (constant friction): expected some and none"
        );
    }
    println!(
        "direct import: two instances side by side (reference file; params_file with friction.model = constant), stepped in turn: each bit-identical to its own hils simulate run; WSP vents {vents_a} and {vents_b} samples"
    );
    Ok(())
}

/// The unpacked resources folder of the FMU (beside its model description).
fn resources_of(fmu: &Fmu) -> Result<String> {
    fmu.resources_dir().context("no resources folder")
}

/// Bad use through the C API: refused with `fmi3Error` and a logged message, the instance
/// still usable.
fn bad_use(fmu: &Fmu) -> Result<()> {
    let mut inst = fmu.instantiate("bad-use")?;
    let early = inst.step(0.0, 1e-3);
    expect_refusal(
        &inst,
        "doStep before initialisation",
        early,
        "not allowed in Instantiated",
    )?;
    let s = inst.set_by_name("vehicle.carbody_mass", -1.0)?;
    expect_refusal(
        &inst,
        "a parameter out of its range",
        s,
        "vehicle.carbody_mass",
    )?;
    let s = inst.set_string("params_file", "/nonexistent/params.toml")?;
    expect_refusal(
        &inst,
        "a missing parameter file",
        s,
        "cannot read parameter file",
    )?;
    inst.initialize()?;
    let s = inst.set_by_name("p_cyl2_pa", f64::NAN)?;
    expect_refusal(&inst, "a NaN input", s, "p_cyl2_pa")?;
    let s = inst.step(0.0, 1.5e-4);
    expect_refusal(
        &inst,
        "a step not a multiple of 0.1 ms",
        s,
        "not a multiple",
    )?;
    let s = inst.set_by_name("brake.supply_pressure", 4e5)?;
    expect_refusal(
        &inst,
        "a parameter set in Step Mode",
        s,
        "cannot be set in Step Mode",
    )?;
    // Still usable after the refusals.
    let status = inst.step(0.0, 1e-3);
    check(&inst, status)?;
    let s = inst.enter_initialization();
    expect_refusal(&inst, "initialisation twice", s, "not allowed in Step Mode")?;
    let status = inst.terminate();
    check(&inst, status)?;
    if inst.step(1e-3, 1e-3) != ERROR {
        bail!("doStep after terminate was not refused");
    }
    println!(
        "direct import: bad use refused with fmi3Error and a logged message (doStep before init, a parameter out of range, a missing parameter file, a NaN input, a 0.15 ms step, a parameter in Step Mode, init twice, doStep after terminate); the instance stays usable"
    );
    Ok(())
}

/// `hils-fmu-check reference DIR`: the paper run at every plant step, for FMPy:
/// `reference.json` (columns, rows, step) and `reference.f32` (rows of f32, little-endian;
/// every value of the run is an f32 widened).
pub fn reference(dir: &Path) -> Result<()> {
    let file = ParamFile::default();
    let run = paper_run(&file)?;
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let mut columns: Vec<String> = (1..=4).map(|j| format!("p_cyl{j}_pa")).collect();
    columns.extend(names());
    let data = dir.join("reference.f32");
    let mut out = std::io::BufWriter::new(std::fs::File::create(&data)?);
    for s in &run.samples {
        for x in s.p_cyl_pa.iter().chain(values(s).iter()) {
            let y = *x as f32;
            if f64::from(y).to_bits() != x.to_bits() {
                bail!("a value of the run is not an f32 ({x}): the reference would round it");
            }
            out.write_all(&y.to_le_bytes())?;
        }
    }
    out.flush()?;
    let meta = serde_json::json!({
        "columns": columns,
        "rows": run.samples.len(),
        "step_s": run.dt,
        "stop_time_s": run.summary.stop_time_s,
        "stopping_distance_m": run.summary.stopping_distance_m,
        "slides": run.summary.slides,
    });
    std::fs::write(
        dir.join("reference.json"),
        serde_json::to_string_pretty(&meta)? + "\n",
    )?;
    println!(
        "{}: the paper run of hils simulate, {} rows x {} columns",
        data.display(),
        run.samples.len(),
        columns.len()
    );
    Ok(())
}
