"""Plant steps per second through FMPy (scripts/fmu-bench.sh): the FMU driven by the paper
run's cylinder pressures with FMPy's FMU3Slave, one plant step (0.1 ms) per doStep with the
inputs set each step, and 100 plant steps (10 ms) per doStep.

usage: fmu_bench.py FMU REFERENCE_DIR
"""

import json
import sys
import time

import numpy as np
from fmpy import extract, read_model_description
from fmpy.fmi3 import FMU3Slave


def run(fmu, md, unzipdir, pressures, per_call, h):
    vr = {v.name: v.valueReference for v in md.modelVariables}
    inputs = [vr[f"p_cyl{j}_pa"] for j in range(1, 5)]
    slave = FMU3Slave(guid=md.guid, unzipDirectory=unzipdir,
                      modelIdentifier=md.coSimulation.modelIdentifier, instanceName="bench")
    slave.instantiate()
    slave.enterInitializationMode(startTime=0.0)
    slave.exitInitializationMode()
    calls = len(pressures) // per_call
    t = 0.0
    started = time.perf_counter()
    for k in range(calls):
        slave.setFloat64(inputs, list(pressures[k * per_call]))
        slave.doStep(t, per_call * h)
        t = (k + 1) * per_call * h
    wall = time.perf_counter() - started
    slave.terminate()
    slave.freeInstance()
    return calls * per_call / wall


def main():
    fmu, reference = sys.argv[1], sys.argv[2]
    with open(f"{reference}/reference.json") as f:
        meta = json.load(f)
    data = np.fromfile(f"{reference}/reference.f32", dtype="<f4").reshape(meta["rows"], len(meta["columns"]))
    pressures = data[1:, :4].astype(np.float64)
    md = read_model_description(fmu)
    unzipdir = extract(fmu)
    h = meta["step_s"]
    one = run(fmu, md, unzipdir, pressures[:100_000], 1, h)
    hundred = run(fmu, md, unzipdir, pressures, 100, h)
    print(f"  FMPy, 1 step per doStep (setFloat64 of 4 inputs + doStep): {one:,.0f} steps/s "
          f"({1e6 / one:.1f} us per call)")
    print(f"  FMPy, 100 steps per doStep:                                {hundred:,.0f} steps/s")


if __name__ == "__main__":
    main()
