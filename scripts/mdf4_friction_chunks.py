#!/usr/bin/env python3
"""Friction tests as MDF4 written by asammdf, stressing fit-friction's row chunks of 65,536
records, each with the CSV asammdf reads back and a channel map (docs/mdf4.md,
"fit-friction and MDF4"). Not run by CI; scripts/mdf4_friction_chunks.sh runs and compares.
  mdf4_friction_chunks.py BASE.csv OUTDIR [CASE...]  -> OUTDIR/CASE.mf4, .csv, .map.toml"""
import math
import os
import sys

import numpy as np
from asammdf import MDF, Signal

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from mdf4_asammdf import unsort_file  # noqa: E402

base_csv, out = sys.argv[1], sys.argv[2]
only = sys.argv[3:] if len(sys.argv) > 3 else None
os.makedirs(out, exist_ok=True)
import pandas as pd  # noqa: E402

B = pd.read_csv(base_csv, comment="#")
NB = len(B)
V = B["v_friction_mps"].to_numpy() * 3.6  # km/h
T = B["t_disc_c"].to_numpy()
MU = B["mu"].to_numpy()


def case(name, n, version="4.10", comp=0, unsorted=False, conv=None, invalid=(), back_at=None,
         nan_at=None, extra=False, forces=False, frag=None, v2t=False,
         dup_t=None, hot_at=None, inv_ch=0):
    if only and name not in only:
        return
    idx = np.arange(n) % NB
    t = np.arange(n) * 1e-4
    if back_at is not None:
        t[back_at] = t[back_at - 1] - 0.05
    if dup_t is not None:
        t[dup_t] = t[dup_t - 1]
    v, tt, mu = V[idx].copy(), T[idx].copy(), MU[idx].copy()
    if nan_at is not None:
        v[nan_at] = math.nan
    if hot_at is not None:
        tt[hot_at] = 5000.0
    inv = np.zeros(n, dtype=bool)
    for r in invalid:
        inv[r] = True
    sigs = []
    if conv == "linear":
        raw = np.round(v / 0.01).astype(np.uint16)
        sigs.append(Signal(raw, t, name="Speed", unit="km/h",
                           conversion={"a": 0.01, "b": 0.0}))
        rawT = np.round((tt + 40.0) / 0.1).astype(np.int32)
        sigs.append(Signal(rawT, t, name="DiscTemp", unit="degC",
                           conversion={"a": 0.1, "b": -40.0}))
    elif conv == "rational":
        raw = np.round(v * 100).astype(np.int32)
        # phys = (0*x^2 + 1*x + 0)/(0*x^2 + 0*x + 100)
        sigs.append(Signal(raw, t, name="Speed", unit="km/h",
                           conversion={"P1": 0.0, "P2": 1.0, "P3": 0.0, "P4": 0.0, "P5": 0.0,
                                       "P6": 100.0}))
        sigs.append(Signal(tt, t, name="DiscTemp", unit="degC"))
    else:
        sigs.append(Signal(v, t, name="Speed", unit="km/h"))
        sigs.append(Signal(tt, t, name="DiscTemp", unit="degC"))
    if forces:
        clamp = np.full(n, 20000.0) + (np.arange(n) % 13)
        clamp[np.arange(n) % 7 == 0] = 10.0
        sigs.append(Signal(clamp, t, name="Clamp", unit="N"))
        sigs.append(Signal(mu * clamp, t, name="Friction", unit="N"))
    else:
        sigs.append(Signal(mu.astype(np.float32), t, name="Mu", unit="-"))
    if v2t:
        mode = (np.arange(n) % 3).astype(np.uint8)
        sigs.append(Signal(mode, t, name="Mode", unit="",
                           conversion={"val_0": 0, "text_0": b"off", "val_1": 1,
                                       "text_1": b"on", "default": b"?"}))
    if len(invalid):
        s0 = sigs[inv_ch]
        sigs[inv_ch] = Signal(s0.samples, t, name=s0.name, unit=s0.unit,
                              conversion=s0.conversion, invalidation_bits=inv)
    mdf = MDF(version=version)
    if frag:
        mdf.configure(write_fragment_size=frag)
    if extra:
        # other groups first: a slow housekeeping group and one at another rate
        ts = np.arange(n // 7 + 1) * 7e-4
        mdf.append([Signal(np.sin(ts), ts, name="Ambient", unit="degC"),
                    Signal(np.cos(ts), ts, name="Humidity", unit="%")], comment="house")
    mdf.append(sigs, comment="dyno")
    if extra:
        ts = np.arange(n // 3 + 2) * 3e-4 + 1e-5
        mdf.append([Signal(ts * 2, ts, name="Load", unit="kN")], comment="load")
    path = f"{out}/{name}.mf4"
    tmp = path + ".s.mf4"
    mdf.save(tmp if unsorted else path, overwrite=True, compression=comp)
    if unsorted:
        unsort_file(tmp, path)
        os.remove(tmp)
    # read back with asammdf: the CSV of the used channels (foreign names, file units)
    back = MDF(path)
    used = ["Speed", "DiscTemp"] + (["Clamp", "Friction"] if forces else ["Mu"])
    cols, times = {}, None
    for u in used:
        gi = next(i for i, g in enumerate(back.groups) if any(c.name == u for c in g.channels))
        s = back.get(u, group=gi, ignore_invalidation_bits=True)
        ib = s.invalidation_bits
        vals = [repr(float(x)) for x in np.asarray(s.samples, dtype=np.float64)]
        if ib is not None:
            vals = ["" if b else x for x, b in zip(vals, np.asarray(ib))]
        cols[u] = vals
        if times is None:
            times = s.timestamps
    with open(f"{out}/{name}.csv", "w") as f:
        f.write("# source: review\n")
        f.write(",".join(["t_s"] + used) + "\n")
        n_csv = min(len(times), *(len(c) for c in cols.values()))
        for i in range(n_csv):
            f.write(",".join([repr(float(times[i]))] + [cols[u][i] for u in used]) + "\n")
    spec = {"v_friction_mps": ("Speed", "km/h"), "t_disc_c": ("DiscTemp", "degC")}
    if forces:
        spec.update(f_clamp_n=("Clamp", "N"), f_friction_n=("Friction", "N"))
    else:
        spec["mu"] = ("Mu", "-")
    with open(f"{out}/{name}.map.toml", "w") as f:
        for col, (nm, unit) in spec.items():
            f.write(f'[channels.{col}]\nfrom = "{nm}"\nunit = "{unit}"\n')
    print(name, n, os.path.getsize(path), flush=True)


C = 65536
case("n65535", C - 1)
case("n65536", C)
case("n65537", C + 1)
case("n131073", 2 * C + 1)
case("n131072_forces", 2 * C, forces=True)
case("n131073_forces_dz", 2 * C + 1, forces=True, comp=1)
case("dz_frag", 2 * C + 1, comp=1, frag=100_003)
case("dzt_frag", 2 * C + 1, comp=2, frag=77_777)
case("dzt_lin", C + 1, comp=2, conv="linear", frag=333_333)
case("v400", C + 1, version="4.00")
case("v420", C + 1, version="4.20")
case("v420_dzt", 2 * C + 1, version="4.20", comp=2, frag=123_457)
case("unsorted", C + 1, unsorted=True, extra=True)
case("unsorted_dup", C + 1, unsorted=True)
case("linear", C + 5, conv="linear")
case("rational", C + 5, conv="rational")
case("v2t_unused", C + 5, v2t=True)
case("invalid", 2 * C + 1, invalid=[3, C - 1, C, C + 1, 2 * C])
case("invalid_dzt", 2 * C + 1, invalid=[3, C, 2 * C], comp=2, frag=99_991)
case("back_c2", 2 * C + 1, back_at=C + 10)
case("back_at_boundary", 2 * C + 1, back_at=C)
case("dup_at_boundary", 2 * C + 1, dup_t=C)
case("nan_c2", 2 * C + 1, nan_at=C + 7)
case("nan_at_boundary", 2 * C + 1, nan_at=C)
case("extra", 2 * C + 1, extra=True)
case("extra_dz", 2 * C + 1, extra=True, comp=2)
case("small", 50)
case("hot_lin_c2", 2 * C + 1, conv="linear", hot_at=C + 3)
case("hot_last", 2 * C + 1, hot_at=2 * C)
case("forces_inv", 2 * C + 1, forces=True, invalid=[C - 1, C, 2 * C], inv_ch=2, comp=2, frag=50_001)
case("unsorted_big", 2 * C + 1, unsorted=True, extra=True, invalid=[C])
case("v400_dz", 2 * C + 1, version="4.00", comp=1)
# Memory flat with rows: only when named (hundreds of MB).
if only:
    case("big1m", 1_000_003, comp=0)
    case("big3m", 3_000_017, comp=0)
    case("big3m_dzt", 3_000_017, comp=2)
