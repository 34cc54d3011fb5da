//! `hils-fmu-check bench FMU`: plant steps per second through the FMU's C API (a direct
//! import, one step per `fmi3DoStep` and 100) and of the plant itself (`hils bench`'s
//! timing of `Plant::step`), on the same inputs: the cylinder pressures of the paper's EB
//! (`hils::bench::recorded_inputs`).

use std::hint::black_box;
use std::path::Path;
use std::time::Instant;

use anyhow::{Result, bail};
use hils::bench::{recorded_inputs, time_plant};
use hils::figures::round_sig;
use hils_fmu_check::direct::{Fmu, OK};
use hils_sil::ParamFile;

/// Plant steps per timed run (the paper's EB takes 0.30 M).
const STEPS: usize = 300_000;

/// Plant steps per second through the FMU with `per_call` plant steps per `fmi3DoStep`
/// (the inputs set before each call), the best of `repeat` runs.
fn time_fmu(
    fmu: &Fmu,
    inputs: &[[f32; 4]],
    per_call: usize,
    dt: f64,
    repeat: usize,
) -> Result<f64> {
    let vrs: Vec<u32> = (1..=4)
        .map(|j| fmu.vr(&format!("p_cyl{j}_pa")))
        .collect::<Result<_>>()?;
    let h = per_call as f64 * dt;
    let mut best = f64::INFINITY;
    for _ in 0..repeat {
        let mut inst = fmu.instantiate("bench")?;
        inst.initialize()?;
        let mut t = 0.0;
        let calls = inputs.len() / per_call;
        let start = Instant::now();
        for chunk in inputs.chunks_exact(per_call) {
            let p = chunk[0].map(f64::from);
            let s = inst.set_f64(&vrs, black_box(&p));
            let s2 = inst.step(t, h);
            if s != OK || s2 != OK {
                bail!("the FMU refused a step: {}", inst.last_message());
            }
            t += h;
        }
        best = best.min(start.elapsed().as_secs_f64());
        black_box(calls);
    }
    Ok((inputs.len() / per_call * per_call) as f64 / best)
}

pub fn run(path: &Path, json: bool, repeat: usize) -> Result<()> {
    let file = ParamFile::default();
    let dt = file.scenario.paper_eb.step_s;
    let inputs = recorded_inputs(&file, STEPS)?;
    let fmu = Fmu::open(path)?;
    let plant = time_plant::<f32>(&file, &inputs, repeat)?;
    let one = time_fmu(&fmu, &inputs, 1, dt, repeat)?;
    let hundred = time_fmu(&fmu, &inputs, 100, dt, repeat)?;
    let call_ns = (1.0 / one - 1.0 / plant) * 1e9;
    if json {
        println!(
            "{}",
            serde_json::json!({
                "plant_steps_per_s": round_sig(plant, 3),
                "fmu_direct_steps_per_s_1_per_call": round_sig(one, 3),
                "fmu_direct_steps_per_s_100_per_call": round_sig(hundred, 3),
                "fmi_call_ns": round_sig(call_ns, 2),
                "steps": STEPS,
                "repeat": repeat,
            })
        );
    } else {
        println!(
            "plant steps per second (f32, one core, the paper's EB inputs, best of {repeat}):"
        );
        println!(
            "  plant alone (hils bench's timing)           {:>12}",
            round_sig(plant, 3)
        );
        println!(
            "  FMU, direct import, 1 step per fmi3DoStep   {:>12}",
            round_sig(one, 3)
        );
        println!(
            "  FMU, direct import, 100 steps per doStep    {:>12}",
            round_sig(hundred, 3)
        );
        println!(
            "  FMI call (fmi3SetFloat64 of 4 inputs + fmi3DoStep) over the plant step: {} ns",
            round_sig(call_ns, 2)
        );
    }
    Ok(())
}
