"""FMPy's checks of the packed FMU (run by scripts/fmu-check.sh).

1. FMPy's validation of the FMU (the model description against the FMI 3.0 schema, names,
   units, model structure).
2. The paper's emergency brake simulated by fmpy.simulate_fmu (closed loop: brake_input =
   brake_unit, cmd = EB, 1 ms): every output at every communication point equals hils
   simulate's run bit for bit (reference written by `hils-fmu-check reference`).
3. The plant alone driven by FMPy with the run's cylinder pressures at the plant step
   (0.1 ms): every output at every communication point, bit for bit.
4. A communication step that is not a multiple of 0.1 ms: refused, with the FMU's message
   in FMPy's logger.

usage: fmu_check.py FMU REFERENCE_DIR
"""

import ctypes
import json
import sys
import time

import numpy as np
from fmpy import extract, read_model_description, simulate_fmu
from fmpy.fmi3 import FMU3Slave, fmi3Boolean, fmi3Float64, fmi3ValueReference
from fmpy.validation import validate_fmu

# Outputs the plant alone does not model (the simulated brake unit's).
UNIT_OUTPUTS = ("p_cyl_unit", "wsp", "v_ref_est")


def wheelset_list(numbers):
    """Wheelset numbers as people write them: "2 and 4", "1, 2 and 3", "none"."""
    names = [str(n) for n in numbers]
    if not names:
        return "none"
    return names[0] if len(names) == 1 else ", ".join(names[:-1]) + " and " + names[-1]


def load_reference(directory):
    with open(f"{directory}/reference.json") as f:
        meta = json.load(f)
    data = np.fromfile(f"{directory}/reference.f32", dtype="<f4")
    data = data.reshape(meta["rows"], len(meta["columns"])).astype(np.float64)
    return meta, {name: data[:, i] for i, name in enumerate(meta["columns"])}


def outputs_of(md):
    return [v for v in md.modelVariables if v.causality == "output" and v.type in ("Float64", "Boolean")]


def compare(name, got, want, times):
    """Bit-for-bit equality of two float64 columns; the first difference as a message."""
    bad = np.flatnonzero(got.view(np.uint64) != want.view(np.uint64))
    if bad.size:
        i = bad[0]
        return f"{name} at t = {times[i]:.4f} s: FMU {got[i]!r}, hils simulate {want[i]!r}"
    return None


def check_validate(fmu):
    problems = validate_fmu(fmu)
    if problems:
        sys.exit("FMPy validate: " + "; ".join(problems))
    print("FMPy validate_fmu: no problems (schema, names, units, model structure)")


def check_paper_eb(fmu, md, meta, ref):
    rows = meta["rows"]
    every = int(round(1e-3 / meta["step_s"]))
    idx = np.arange(0, rows, every)
    names = [v.name for v in outputs_of(md)]
    started = time.perf_counter()
    result = simulate_fmu(fmu, stop_time=(len(idx) - 1) * 1e-3, output_interval=1e-3,
                          start_values={"brake_input": 2, "cmd": 1}, output=names)
    wall = time.perf_counter() - started
    if len(result) != len(idx):
        sys.exit(f"FMPy paper EB: {len(result)} communication points, expected {len(idx)}")
    for name in names:
        message = compare(name, result[name].astype(np.float64), ref[name][idx], result["time"])
        if message:
            sys.exit(f"FMPy paper EB (closed loop): {message}")
    v = result["v_ref_mps"]
    i = int(np.argmax(v <= 0.01))
    slides = [j for j in range(1, 5) if result[f"wsp{j}"].any()]
    if slides != meta["slides"]:
        sys.exit(f"FMPy paper EB: WSP acted on wheelsets {wheelset_list(slides)}, "
                 f"hils simulate on {wheelset_list(meta['slides'])}")
    print(f"FMPy simulate_fmu, paper EB in closed loop at 1 ms: {len(idx)} communication points x "
          f"{len(names)} outputs bit-identical to hils simulate; stop {result['time'][i]:.2f} s, "
          f"{result['x_m'][i]:.1f} m; WSP on wheelsets {wheelset_list(slides)} ({wall:.1f} s)")


def check_plant(fmu, md, meta, ref):
    """The plant driven by FMPy at 0.1 ms: FMU3Slave, one doStep per plant step."""
    rows = meta["rows"]
    h = meta["step_s"]
    outs = [v for v in outputs_of(md) if v.type == "Float64" and not v.name.startswith(UNIT_OUTPUTS)]
    vr = {v.name: v.valueReference for v in md.modelVariables}
    unzipdir = extract(fmu)
    slave = FMU3Slave(guid=md.guid, unzipDirectory=unzipdir,
                      modelIdentifier=md.coSimulation.modelIdentifier, instanceName="fmpy-plant")
    slave.instantiate()
    slave.enterInitializationMode(startTime=0.0)
    slave.exitInitializationMode()
    in_vrs = (fmi3ValueReference * 4)(*[vr[f"p_cyl{j}_pa"] for j in range(1, 5)])
    out_vrs = (fmi3ValueReference * len(outs))(*[v.valueReference for v in outs])
    got = np.empty((rows, len(outs)))
    pressures = np.ascontiguousarray(np.stack([ref[f"p_cyl{j}_pa"] for j in range(1, 5)], axis=1))
    flags = [fmi3Boolean() for _ in range(3)]
    last = fmi3Float64()
    row_bytes = 8 * len(outs)
    out_base = got.ctypes.data
    in_base = pressures.ctypes.data
    p_double = ctypes.POINTER(ctypes.c_double)
    slave.fmi3GetFloat64(slave.component, out_vrs, len(outs),
                         ctypes.cast(out_base, p_double), len(outs))
    started = time.perf_counter()
    t = 0.0
    for k in range(1, rows):
        slave.fmi3SetFloat64(slave.component, in_vrs, 4, ctypes.cast(in_base + 32 * k, p_double), 4)
        slave.fmi3DoStep(slave.component, t, h, True, ctypes.byref(flags[0]), ctypes.byref(flags[1]),
                         ctypes.byref(flags[2]), ctypes.byref(last))
        t = k * h
        slave.fmi3GetFloat64(slave.component, out_vrs, len(outs),
                             ctypes.cast(out_base + row_bytes * k, p_double), len(outs))
    wall = time.perf_counter() - started
    slave.terminate()
    slave.freeInstance()
    times = np.arange(rows) * h
    for i, v in enumerate(outs):
        message = compare(v.name, got[:, i], ref[v.name], times)
        if message:
            sys.exit(f"FMPy plant at {h} s: {message}")
    print(f"FMPy FMU3Slave, plant driven by the run's p_cyl1..4_pa at {h} s: {rows - 1} communication "
          f"points x {len(outs)} outputs bit-identical to hils simulate ({wall:.1f} s, "
          f"{(rows - 1) / wall:.0f} steps/s through FMPy)")


def check_bad_step(fmu):
    messages = []

    def logger(env, status, category, message):
        messages.append(message.decode())

    try:
        simulate_fmu(fmu, stop_time=0.01, output_interval=1.5e-4, logger=logger)
    except Exception as e:
        refused = str(e)
    else:
        sys.exit("FMPy: a 0.15 ms communication step was accepted")
    if not any("not a multiple" in m for m in messages):
        sys.exit(f"FMPy: the 0.15 ms step was refused ({refused}) without the FMU's message: {messages}")
    print(f"FMPy: a 0.15 ms communication step refused ({refused}); the FMU logged: "
          f"{[m for m in messages if 'not a multiple' in m][0]}")


def main():
    fmu, reference = sys.argv[1], sys.argv[2]
    md = read_model_description(fmu)
    meta, ref = load_reference(reference)
    check_validate(fmu)
    check_paper_eb(fmu, md, meta, ref)
    check_plant(fmu, md, meta, ref)
    check_bad_step(fmu)


if __name__ == "__main__":
    main()
