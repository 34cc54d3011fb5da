#!/usr/bin/env python3
"""Independent checks of the project's MDF4 reading and writing with asammdf (ASAM MDF's
reference Python implementation). Called by scripts/mdf4-asammdf.sh; subcommands:

  canape CSV OUT_STEM [--unsorted] [--compression N]
      A spec run-log CSV as a measurement tool writes it (Vector CANape-like): foreign
      channel names, km/h, bar, kN, degC; wheel speeds, valves, command and clamp forces in
      the fast group (the CSV's own rows), radar and cylinder pressures in a slow group
      (every 4th row), disc temperatures in a 10 Hz-like group (every 20th row); integers
      with linear, value-to-value and value-to-text conversions; dropouts as invalidation
      bits. Writes OUT_STEM.mf4, OUT_STEM.map.toml (the channel map) and OUT_STEM.csv: the
      spec CSV of the same data as asammdf reads it back from OUT_STEM.mf4, converted to SI
      here (empty cells where a slow channel has no sample).
  unsort IN OUT      rewrites a sorted file (one channel group per data group) as one
                     unsorted data group with record ids; asammdf must read it equal.
  written MF4 CSV    a file the project wrote (hils simulate --format mf4, decode, record)
                     read by asammdf: every column of the CSV with equal name, unit and
                     samples; the metadata in the header's properties.
  same-diagnosis A.json B.json [--rel R]
                     two diagnosis JSONs agree: discrepancy, causes, confounded; fitted
                     parameters and gains within R (relative) or their CI half-width.
  fixtures DIR       the small fixtures the Rust tests read without Python
                     (tools/tests/data/mdf4/): sorted, unsorted, compressed, with the spec
                     CSV asammdf decodes them to.
  vlsd DUMP [N]      VLSD text channels (UTF-8, Latin-1, UTF-16 LE/BE) beside numbers, N
                     records: MDF 4.10 and 4.20, uncompressed (also unsorted, and as an
                     MDF 4.2 VLSD channel group), DZ, DZ transposed; every sample the
                     project's reader gives (DUMP: `cargo build -p hils --example mdf4_dump
                     --features mdf4-dump`, target/debug/examples/mdf4_dump) equals asammdf's.
                     Not run by CI.
  friction CSV OUT_STEM [--slow-temp] [--compression N]
                     a spec friction-test CSV (`hils bench --reader X.csv
                     --write-friction-points N`) as a dynamometer logger writes it:
                     Speed in km/h, DiscTemp in degC, Mu, at 10 kHz (the CSV's `t_s`, else
                     the row index times 0.1 ms); --slow-temp: DiscTemp in a second group at
                     every 10th row. Writes OUT_STEM.mf4 and OUT_STEM.map.toml (for
                     fit-friction's memory figures, docs/mdf4.md). Not run by CI.
"""
import argparse
import json
import math
import struct
import sys

import numpy as np
from asammdf import MDF, Signal

WHEEL_RADIUS_M = 0.43  # spec/reference-parameters.toml `wheel_radius`
KMH = 1 / 3.6


def read_spec_csv(path):
    """Metadata pairs, header, columns (float arrays, or lists of texts for cmd/unknown texts)."""
    meta, lines = [], open(path, encoding="utf-8-sig").read().splitlines()
    i = 0
    while lines[i].startswith("#") or not lines[i].strip():
        body = lines[i].lstrip("#").strip()
        if ":" in body:
            k, v = body.split(":", 1)
            meta.append((k.strip(), v.strip()))
        i += 1
    header = [h.strip() for h in lines[i].split(",")]
    rows = [l.split(",") for l in lines[i + 1:] if l.strip()]
    cols = {}
    for j, h in enumerate(header):
        cells = [r[j].strip() for r in rows]
        try:
            cols[h] = np.array([float(c) if c else math.nan for c in cells])
        except ValueError:
            cols[h] = cells
    return meta, header, cols


# Spec column -> (foreign name, group, unit, encoder). Groups: fast (every row), slow
# (every 4th), thermal (every 20th).
def plan(col):
    j = col[-1] if col[:-1] in ("wsp",) else None
    for stem, name, group, unit in [
        ("omega", "WheelSpeed_Axle{}", "fast", "km/h"),
        ("p_cyl", "BC_Pressure_{}", "slow", "bar"),
        ("f_clamp", "ClampForce_{}", "fast", "kN"),
        ("f_brake", "BrakeForce_{}", "fast", "kN"),
        ("t_disc", "DiscTemp_{}", "thermal", "degC"),
        ("q", "AxleLoad_{}", "slow", "kN"),
    ]:
        if col.startswith(stem) and len(col) > len(stem) and col[len(stem)].isdigit():
            return name.format(col[len(stem)]), group, unit
    return {
        "v_ref_mps": ("Radar_Speed", "slow", "km/h"),
        "a_x_mps2": ("LongAccel", "fast", "m/s^2"),
        "cmd": ("BrakeCmd", "fast", ""),
    }.get(col, (f"WSP_Valve_{j}", "fast", "") if j else None)


def to_unit(col, si):
    """SI values of a spec column in the foreign unit."""
    if col.startswith("omega"):
        return si * WHEEL_RADIUS_M / KMH
    if col == "v_ref_mps":
        return si / KMH
    if col.startswith("p_cyl"):
        return si / 1e5
    if col.startswith(("f_clamp", "f_brake", "q")):
        return si / 1e3
    return si


def to_si(col, x):
    if col.startswith("omega"):
        return x * KMH / WHEEL_RADIUS_M
    if col == "v_ref_mps":
        return x * KMH
    if col.startswith("p_cyl"):
        return x * 1e5
    if col.startswith(("f_clamp", "f_brake", "q")):
        return x * 1e3
    return x


def signal(col, name, unit, t, si, vlsd=False):
    """A signal as a logger stores it: integers with conversions where loggers use them
    (`vlsd`: the command as a variable-length UTF-8 string, as asammdf stores texts)."""
    nan = np.isnan(si) if not isinstance(si, list) else None
    if col == "cmd" and vlsd:
        return Signal(np.array([c.encode() for c in si]), t, name=name, encoding="utf-8",
                      comment="brake command")
    if col == "cmd":
        codes = {"REL": 0, "EB": 1, "SB": 2}
        raw = np.array([codes.get(c, 3) for c in si], dtype=np.uint8)
        conv = {"val_0": 0, "text_0": b"REL", "val_1": 1, "text_1": b"EB",
                "val_2": 2, "text_2": b"SB", "val_3": 3, "text_3": b"", "default": b""}
        return Signal(raw, t, name=name, conversion=conv, comment="brake command")
    x = to_unit(col, si)
    inval = nan if nan is not None and nan.any() else None
    x = np.where(np.isnan(x), 0.0, x)
    if col.startswith("p_cyl"):
        # int16, 0.0002 bar per bit (linear conversion)
        raw = np.round(x / 0.0002).astype(np.int16)
        return Signal(raw, t, name=name, unit=unit, conversion={"a": 0.0002, "b": 0.0},
                      invalidation_bits=inval, comment="brake cylinder pressure")
    if col == "v_ref_mps":
        # uint16, 0.01 km/h per bit (linear conversion)
        raw = np.round(np.clip(x, 0, None) / 0.01).astype(np.uint16)
        return Signal(raw, t, name=name, unit=unit, conversion={"a": 0.01, "b": 0.0},
                      invalidation_bits=inval, comment="radar ground speed")
    if col.startswith("t_disc"):
        # 12-bit ADC through a value-to-value table with interpolation: 0..4095 -> -50..1000 degC
        raw = np.round((x + 50.0) / 1050.0 * 4095.0).astype(np.uint16)
        conv = {"raw_0": 0.0, "phys_0": -50.0, "raw_1": 4095.0, "phys_1": 1000.0}
        return Signal(raw, t, name=name, unit=unit, conversion=conv,
                      invalidation_bits=inval, comment="disc temperature rise")
    if col.startswith("wsp"):
        return Signal(x.astype(np.uint8), t, name=name, invalidation_bits=inval,
                      comment="WSP vent valve")
    return Signal(x.astype(np.float32), t, name=name, unit=unit, invalidation_bits=inval)


def header_xml(pairs):
    props = "".join(f'<e name="{k}">{v}</e>' for k, v in pairs)
    return f"<HDcomment><TX>CANape-like recording</TX><common_properties>{props}</common_properties></HDcomment>"


def canape(args):
    meta, header, cols = read_spec_csv(args.csv)
    t = cols["t_s"]
    rows = {"fast": np.arange(len(t)), "slow": np.arange(0, len(t), 4),
            "thermal": np.arange(0, len(t), 20)}
    groups = {"fast": [], "slow": [], "thermal": []}
    mapping = {}
    for col in header:
        p = plan(col)
        if col == "t_s" or p is None:
            continue
        name, group, unit = p
        r = rows[group]
        si = cols[col]
        si = [si[i] for i in r] if isinstance(si, list) else si[r]
        groups[group].append(signal(col, name, unit, t[r], si, getattr(args, "vlsd", False)))
        mapping[col] = name
    mdf = MDF(version="4.10")
    for g in ("fast", "slow", "thermal"):
        if groups[g]:
            mdf.append(groups[g], comment=f"{g} rate")
    meta_d = dict(meta)
    in_file = [(k, meta_d[k]) for k in ("source", "initial_speed_kmh") if k in meta_d]
    mdf.header.comment = header_xml(in_file)
    mdf.save(args.out_stem + ".mf4", overwrite=True, compression=args.compression)
    if args.unsorted:
        unsort_file(args.out_stem + ".mf4", args.out_stem + ".mf4")
    with open(args.out_stem + ".map.toml", "w") as f:
        f.write("# Channel map of a CANape-like recording (scripts/mdf4_asammdf.py canape)\n")
        f.write(f"wheel_radius_m = {WHEEL_RADIUS_M}\n\n[metadata]\n")
        for k in ("rail", "eb_command_s"):
            if k in meta_d:
                f.write(f'{k} = "{meta_d[k]}"\n')
        for col, name in mapping.items():
            f.write(f'\n[channels.{col}]\nfrom = "{name}"\n')
    equivalent_csv(args.out_stem + ".mf4", args.out_stem + ".csv", mapping, meta, t)


def equivalent_csv(mf4, out, mapping, meta, t):
    """The spec CSV of what asammdf reads from `mf4` (SI; empty where not sampled)."""
    m = MDF(mf4)
    index = {round(x, 9): i for i, x in enumerate(t)}
    cols = {}
    for col, name in mapping.items():
        s = m.get(name)
        cells = [""] * len(t)
        for ti, v, bad in zip(s.timestamps, s.samples,
                              s.invalidation_bits if s.invalidation_bits is not None
                              else [False] * len(s.samples)):
            i = index[round(float(ti), 9)]
            if bad:
                continue
            if isinstance(v, bytes):
                cells[i] = v.decode()
            else:
                cells[i] = repr(float(to_si(col, float(v))))
        cols[col] = cells
    with open(out, "w") as f:
        for k, v in meta:
            f.write(f"# {k}: {v}\n")
        f.write(",".join(["t_s"] + list(cols)) + "\n")
        for i, ti in enumerate(t):
            f.write(",".join([repr(float(ti))] + [cols[c][i] for c in cols]) + "\n")


def blocks_of(b, addr, kind):
    assert b[addr:addr + 4] == b"##" + kind, (addr, b[addr:addr + 4])
    length, nlinks = struct.unpack_from("<QQ", b, addr + 8)
    links = list(struct.unpack_from(f"<{nlinks}Q", b, addr + 24))
    return length, links


def data_bytes(b, addr):
    """The bytes of a data group's DT block or DL list of DT blocks (or of SD blocks)."""
    kind = b[addr + 2:addr + 4]
    length, links = blocks_of(b, addr, kind)
    if kind in (b"DT", b"SD"):
        return bytes(b[addr + 24:addr + length])
    assert kind == b"DL", kind
    out = b""
    while True:
        for a in links[1:]:
            out += data_bytes(b, a)
        if links[0] == 0:
            return out
        length, links = blocks_of(b, links[0], b"DL")


def append_block(b, kind, links, data):
    """Appends a block (at an 8-byte boundary) to the file's bytes `b`; its address."""
    while len(b) % 8:
        b.append(0)
    addr = len(b)
    b += b"##" + kind + bytes(4) + struct.pack("<QQ", 24 + 8 * len(links) + len(data), len(links))
    b += struct.pack(f"<{len(links)}Q", *links) + data
    return addr


def unsort_file(src, dst):
    b = bytearray(open(src, "rb").read())
    _, hd = blocks_of(b, 64, b"HD")
    dg, groups = hd[0], []
    while dg:
        _, dgl = blocks_of(b, dg, b"DG")
        assert b[dg + 24 + 8 * len(dgl)] == 0, "already unsorted"
        cg = dgl[1]
        _, cgl = blocks_of(b, cg, b"CG")
        assert cgl[0] == 0, "one channel group per data group"
        cg_data = cg + 24 + 8 * len(cgl)
        cycles, = struct.unpack_from("<Q", b, cg_data + 8)
        size = sum(struct.unpack_from("<II", b, cg_data + 24))
        recs = data_bytes(b, dgl[2])
        assert len(recs) == cycles * size
        # the master is float64 at byte 0 in asammdf's layout
        times = [struct.unpack_from("<d", recs, k * size)[0] for k in range(cycles)]
        groups.append((cg, cgl, cg_data, size, recs, times))
        dg = dgl[0]
    merged = []
    for rid, (cg, cgl, cg_data, size, recs, times) in enumerate(groups, start=1):
        struct.pack_into("<Q", b, cg_data, rid)
        for k, tk in enumerate(times):
            merged.append((tk, rid, recs[k * size:(k + 1) * size]))
    for (cg, *_), nxt in zip(groups, groups[1:] + [None]):
        struct.pack_into("<Q", b, cg + 24, nxt[0] if nxt else 0)
    merged.sort(key=lambda r: (r[0], r[1]))
    payload = b"".join(bytes([rid]) + rec for _, rid, rec in merged)
    dt = append_block(b, b"DT", (), payload)
    new_dg = append_block(b, b"DG", (0, groups[0][0], dt, 0), bytes([1]) + bytes(7))
    struct.pack_into("<Q", b, 64 + 24, new_dg)
    open(dst, "wb").write(b)


def unsort(args):
    before = MDF(args.src)
    unsort_file(args.src, args.dst)
    after = MDF(args.dst)
    for g in range(len(before.groups)):
        for c in before.groups[g].channels:
            x, y = before.get(c.name, group=g), after.get(c.name, group=g)
            assert np.array_equal(x.samples, y.samples), c.name
            assert np.array_equal(x.timestamps, y.timestamps), c.name
    print(f"unsort: {args.dst}: {len(after.groups)} groups, asammdf reads it equal")


def written(args):
    m = MDF(args.mf4)
    meta, header, cols = read_spec_csv(args.csv)
    props = dict(m.header._common_properties) if hasattr(m.header, "_common_properties") else {}
    bad = []
    for k, v in meta:
        if str(props.get(k, "")).strip() != v:
            bad.append(f"metadata {k}: {props.get(k)!r} != {v!r}")
    names = [c.name for g in m.groups for c in g.channels]
    if names != header:
        bad.append(f"channels {names} != columns {header}")
    for col in header:
        if col == "t_s":
            x, unit = m.get_master(0), m.groups[0].channels[0].unit
        else:
            s = m.get(col)
            x, unit = s.samples, s.unit
        y = cols[col]
        if isinstance(y, list):
            x = [v.decode() if isinstance(v, bytes) else str(v) for v in x]
            same = x == y
        else:
            same = np.array_equal(np.asarray(x, dtype=float), y, equal_nan=True)
        if not same and col not in args.vary.split(","):
            bad.append(f"{col}: samples differ")
        want = {"_s": "s", "_mps": "m/s", "_radps": "rad/s", "_pa": "Pa", "_n": "N",
                "_c": "degC", "_m": "m", "_mps2": "m/s^2", "_us": "us"}
        expect = next((u for suf, u in sorted(want.items(), key=lambda p: -len(p[0]))
                       if col.endswith(suf)), "")
        if col.startswith(("wsp", "mu_d", "creepage", "adhesion", "cmd", "state", "faults",
                           "sensor_faults", "overruns", "missed_ticks", "surface", "mu_avail")):
            expect = ""
        if unit != expect:
            bad.append(f"{col}: unit {unit!r}, expected {expect!r}")
    rows = len(cols["t_s"])
    print(f"asammdf {args.mf4}: {len(header)} channels x {rows} samples, "
          f"{len(meta)} metadata keys: {'EQUAL' if not bad else 'DIFFERENT'}")
    for line in bad[:20]:
        print("  " + line)
    sys.exit(1 if bad else 0)


def same_diagnosis(args):
    a, b = (json.load(open(p)) for p in (args.a, args.b))
    bad = []
    for key in ("discrepancy", "causes", "confounded"):
        if a.get(key) != b.get(key):
            bad.append(f"{key}: {a.get(key)} vs {b.get(key)}")
    fa = {f["effect"]: f for f in a.get("findings", [])}
    fb = {f["effect"]: f for f in b.get("findings", [])}
    worst = 0.0
    for eff in fa.keys() & fb.keys():
        for k, x in fa[eff]["params"].items():
            y = fb[eff]["params"].get(k)
            lo, hi = fa[eff].get("ci95", {}).get(k, [x, x])
            tol = max(args.rel * abs(x), 0.5 * (hi - lo))
            d = abs(x - y) if y is not None else math.inf
            worst = max(worst, d / tol if tol > 0 else 0.0)
            if d > tol:
                bad.append(f"{eff}.{k}: {x} vs {y} (tolerance {tol:.4g})")
    ga, gb = a["gain"], b["gain"]
    # Physical figures: the speed errors (m/s) within rel or abs_mps, the reduction within
    # rel (absolute). The figures in noise units only with --noise-units: a channel
    # recorded slower or coarser has another noise level, so they move with the layout.
    for k in ("baseline", "extended"):
        x, y = ga["speed_rms_mps"][k], gb["speed_rms_mps"][k]
        if abs(x - y) > max(args.rel * abs(x), args.abs_mps):
            bad.append(f"gain.speed_rms_mps.{k}: {x} vs {y}")
        if args.noise_units and abs(ga[k] - gb[k]) > args.rel * max(abs(ga[k]), 1.0):
            bad.append(f"gain.{k}: {ga[k]} vs {gb[k]}")
    if abs(ga["reduction"] - gb["reduction"]) > args.rel:
        bad.append(f"gain.reduction: {ga['reduction']} vs {gb['reduction']}")
    r = lambda x: f"{x:.4g}"
    print(f"diagnosis {args.a} vs {args.b}: causes {a.get('causes')} / {b.get('causes')}; "
          f"speed rms baseline {r(ga['speed_rms_mps']['baseline'])} / "
          f"{r(gb['speed_rms_mps']['baseline'])} m/s, extended "
          f"{r(ga['speed_rms_mps']['extended'])} / {r(gb['speed_rms_mps']['extended'])} m/s; "
          f"reduction {r(ga['reduction'])} / {r(gb['reduction'])}; x noise {r(ga['baseline'])} / "
          f"{r(gb['baseline'])}; largest parameter difference {worst:.2f} x tolerance: "
          f"{'SAME' if not bad else 'DIFFERENT'}")
    for line in bad:
        print("  " + line)
    sys.exit(1 if bad else 0)


def fixtures(args):
    """Small fixtures: 0.2 s of a braking run at 1 kHz / 250 Hz / 50 Hz."""
    import os
    os.makedirs(args.dir, exist_ok=True)
    t = np.round(np.arange(0.0, 0.2, 0.001), 6)
    v = 30.0 - 1.2 * t
    lines = ["# source: scripts/mdf4_asammdf.py fixtures", "# rail: wet",
             "# initial_speed_kmh: 108", "# eb_command_s: 0",
             "t_s,v_ref_mps," + ",".join(f"omega{j}_radps" for j in range(1, 5)) + ","
             + ",".join(f"p_cyl{j}_pa" for j in range(1, 5)) + ","
             + ",".join(f"t_disc{j}_c" for j in range(1, 5)) + ","
             + ",".join(f"wsp{j}" for j in range(1, 5)) + ",cmd"]
    for i, ti in enumerate(t):
        row = [repr(float(ti)), repr(float(v[i]))]
        row += [repr(float((v[i] - 0.01 * j) / WHEEL_RADIUS_M)) for j in range(4)]
        row += [repr(float(min(ti * 2e6, 350000.0) + 1000 * j)) if not (j == 2 and 40 <= i < 60) else ""
                for j in range(4)]
        row += [repr(float(5.0 + 40 * ti + j)) for j in range(4)]
        row += [str(int((i // 50 + j) % 2)) for j in range(4)]
        row += ["EB" if ti > 0.01 else "REL"]
        lines.append(",".join(row))
    src = os.path.join(args.dir, "source.csv")
    open(src, "w").write("\n".join(lines) + "\n")
    for stem, unsorted, comp, vlsd in (("canape_sorted", False, 0, False),
                                       ("canape_unsorted", True, 0, False),
                                       ("canape_dz", False, 2, False),
                                       ("canape_vlsd", False, 2, True)):
        ns = argparse.Namespace(csv=src, out_stem=os.path.join(args.dir, stem),
                                unsorted=unsorted, compression=comp, vlsd=vlsd)
        canape(ns)
        raw = open(ns.out_stem + ".mf4", "rb").read()
        print(f"fixture {stem}.mf4: {len(raw)} bytes, DZ blocks: {raw.count(b'##DZ')}")
    # `cmd` as a VLSD string: asammdf reads the same CSV and map as from its coded twin.
    vlsd = os.path.join(args.dir, "canape_vlsd")
    for ext in (".csv", ".map.toml"):
        assert open(vlsd + ext).read() == open(os.path.join(args.dir, "canape_dz" + ext)).read()
        os.remove(vlsd + ext)
    os.remove(src)


def fuzz_seeds(args):
    """Seeds of the fuzz target `mdf4` (fuzz/seeds/mdf4): tiny sorted, compressed and
    unsorted files of two rates, without their first 16 bytes (the target adds them)."""
    import os
    os.makedirs(args.dir, exist_ok=True)
    t = np.arange(0, 0.005, 0.001)
    t2 = t[::2]
    fast = [Signal((np.full(len(t), 100.0) - j).astype(np.float32), t,
                   name=f"WheelSpeed_Axle{j}", unit="km/h") for j in range(1, 5)]
    slow = [Signal(np.array([0, 5000, 10000], dtype=np.int16), t2, name=f"BC_Pressure_{j}",
                   unit="bar", conversion={"a": 0.0002, "b": 0.0}) for j in range(1, 5)]
    slow.append(Signal(np.array([2700, 2690, 2680], dtype=np.uint16), t2, name="Radar_Speed",
                       unit="km/h", conversion={"a": 0.01, "b": 0.0}))
    mdf = MDF(version="4.10")
    mdf.append(fast)
    mdf.append(slow)
    path = lambda n: os.path.join(args.dir, n)
    mdf.save(path("sorted.mf4"), overwrite=True)
    mdf.save(path("dz.mf4"), overwrite=True, compression=2)
    unsort_file(path("sorted.mf4"), path("unsorted.mf4"))
    for f in ("sorted.mf4", "dz.mf4", "unsorted.mf4"):
        b = open(path(f), "rb").read()
        open(path(f), "wb").write(b[16:])
        print(f"seed {f}: {len(b) - 16} bytes, DZ blocks: {b.count(b'##DZ')}")


VLSD_WORDS = ["REL", "EB", "SERVICE_3", "Bremsstufe \u00e4", "", "L\u00f6sen \u03a9"]
VLSD_ENC = {"cmd": "utf-8", "state_l1": "latin-1", "s_le": "utf-16-le", "s_be": "utf-16-be"}


def vlsd_file(path, n, ver, comp):
    """A 1 kHz group (numbers, UTF-8 and Latin-1 texts) and a 200 Hz group (a number,
    UTF-16 LE and BE texts), texts as asammdf stores them: VLSD."""
    t = np.round(np.arange(n) * 0.001, 6)

    def texts(k, tt, name):
        enc = VLSD_ENC[name]
        w = [VLSD_WORDS[(i // (7 + k)) % len(VLSD_WORDS)] for i in range(len(tt))]
        w = [x.replace("\u03a9", "O") if enc == "latin-1" else x for x in w]
        return Signal(np.array([x.encode(enc) for x in w]), tt, name=name, encoding=enc)
    t2 = t[::5]
    m = MDF(version=ver)
    m.append([Signal(np.sin(t), t, name="v", unit="m/s"),
              Signal((np.arange(n) % 300).astype(np.int16), t, name="i16"),
              texts(0, t, "cmd"), texts(1, t, "state_l1")])
    m.append([Signal(np.cos(t2), t2, name="p", unit="bar"),
              texts(2, t2, "s_le"), texts(3, t2, "s_be")])
    m.save(path, overwrite=True, compression=comp)


def vlsd_group_file(src, dst, channel="cmd", vlsd_id=9):
    """An unsorted file (1-byte record ids) with `channel`'s signal data (SD blocks, not
    compressed) moved into an MDF 4.2 VLSD channel group: one VLSD record (id `vlsd_id`)
    before each record of the channel's group, carrying that record's entry."""
    b = bytearray(open(src, "rb").read())
    _, hd = blocks_of(b, 64, b"HD")
    _, dgl = blocks_of(b, hd[0], b"DG")
    sizes, cgs, target, cg = {}, [], None, dgl[1]
    while cg:
        _, cgl = blocks_of(b, cg, b"CG")
        rid, = struct.unpack_from("<Q", b, cg + 24 + 8 * len(cgl))
        sizes[rid] = sum(struct.unpack_from("<II", b, cg + 24 + 8 * len(cgl) + 24))
        cgs.append(cg)
        cn = cgl[1]
        while cn:
            _, cnl = blocks_of(b, cn, b"CN")
            tx = cnl[2]
            if bytes(b[tx + 24:tx + 24 + len(channel) + 1]) == channel.encode() + b"\0":
                target = (rid, cn, cnl[5], struct.unpack_from("<I", b, cn + 24 + 64 + 4)[0])
            cn = cnl[0]
        cg = cgl[0]
    rid, cn, sd, at = target
    sdata = data_bytes(b, sd)
    recs = data_bytes(b, dgl[2])
    out, pos, count, total = bytearray(), 0, 0, 0
    while pos < len(recs):
        size = sizes[recs[pos]]
        if recs[pos] == rid:
            off, = struct.unpack_from("<Q", recs, pos + 1 + at)
            ln, = struct.unpack_from("<I", sdata, off)
            out += bytes([vlsd_id]) + sdata[off:off + 4 + ln]
            count, total = count + 1, total + 4 + ln
        out += recs[pos:pos + 1 + size]
        pos += 1 + size
    dt = append_block(b, b"DT", (), bytes(out))
    vcg = append_block(b, b"CG", (0,) * 6, struct.pack(
        "<QQHH4xII", vlsd_id, count, 1, 0, total & 0xFFFFFFFF, total >> 32))
    struct.pack_into("<Q", b, cgs[-1] + 24, vcg)  # after the last channel group
    struct.pack_into("<Q", b, cn + 24 + 8 * 5, vcg)  # the channel's cn_data
    struct.pack_into("<Q", b, hd[0] + 24 + 16, dt)  # the data group's records
    b[8:16] = b"4.20    "
    struct.pack_into("<H", b, 28, 420)
    open(dst, "wb").write(b)


def vlsd_compare(dump, path):
    """Every channel the project's reader gives for `path` equals asammdf's: (channels, samples)."""
    import subprocess
    ref = MDF(path)
    out = subprocess.run([dump, path], capture_output=True, text=True, check=True).stdout
    n_ch = n_s = 0
    for line in out.splitlines():
        d = json.loads(line)
        assert "error" not in d, (path, d.get("error"))
        for name, vals in d["channels"].items():
            s = ref.get(name, group=d["group"])
            assert np.array_equal(np.array(d["t"]), s.timestamps), (path, name)
            if name in VLSD_ENC:
                enc = VLSD_ENC[name]
                # numpy's S dtype drops trailing NULs: pad UTF-16 LE back to whole units
                pad = lambda x: x + b"\0" if enc == "utf-16-le" and len(x) % 2 else x
                exp = [pad(x).decode(enc).split("\0")[0] for x in s.samples.tolist()]
                assert vals == exp, (path, name)
            else:
                assert np.array_equal(np.array(vals, dtype=float), s.samples.astype(float)), name
            n_ch, n_s = n_ch + 1, n_s + len(vals)
    return n_ch, n_s


def vlsd(args):
    import os
    import tempfile
    total = 0
    with tempfile.TemporaryDirectory() as tmp:
        for ver in ("4.10", "4.20"):
            for comp in (0, 1, 2):
                p = os.path.join(tmp, f"vlsd_{ver}_{comp}.mf4")
                vlsd_file(p, args.n, ver, comp)
                files = [p]
                if comp == 0:
                    unsort_file(p, p[:-4] + "_unsorted.mf4")
                    vlsd_group_file(p[:-4] + "_unsorted.mf4", p[:-4] + "_vlsd_group.mf4")
                    files += [p[:-4] + "_unsorted.mf4", p[:-4] + "_vlsd_group.mf4"]
                for f in files:
                    raw = open(f, "rb").read()
                    kinds = ", ".join(f"{k.decode()} {raw.count(b'##' + k)}"
                                      for k in (b"SD", b"DZ", b"DL", b"HL"))
                    n_ch, n_s = vlsd_compare(args.dump, f)
                    total += n_s
                    print(f"{os.path.basename(f)}: {len(raw)} bytes ({kinds}): {n_ch} channels, "
                          f"{n_s} samples EQUAL")
    print(f"vlsd: every sample equal to asammdf's: {total} samples")


def friction(args):
    import pandas as pd
    df = pd.read_csv(args.csv, comment="#")
    n = len(df)
    t = df["t_s"].to_numpy() if "t_s" in df else np.arange(n) * 1e-4
    speed = Signal(df["v_friction_mps"].to_numpy() / KMH, t, name="Speed", unit="km/h")
    temp = Signal(df["t_disc_c"].to_numpy(), t, name="DiscTemp", unit="degC")
    mu = Signal(df["mu"].to_numpy(), t, name="Mu", unit="-")
    del df
    mdf = MDF(version="4.10")
    if args.slow_temp:
        mdf.append([speed, mu], comment="fast")
        mdf.append([Signal(temp.samples[::10], t[::10], name="DiscTemp", unit="degC")],
                   comment="slow")
    else:
        mdf.append([speed, temp, mu], comment="dynamometer")
    mdf.header.comment = header_xml([("source", f"scripts/mdf4_asammdf.py friction {args.csv}")])
    mdf.save(args.out_stem + ".mf4", overwrite=True, compression=args.compression)
    with open(args.out_stem + ".map.toml", "w") as f:
        f.write("# scripts/mdf4_asammdf.py friction\n")
        for col, name in (("v_friction_mps", "Speed"), ("t_disc_c", "DiscTemp"), ("mu", "Mu")):
            f.write(f'[channels.{col}]\nfrom = "{name}"\n')
    print(f"friction: {n} rows -> {args.out_stem}.mf4")


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="cmd", required=True)
    c = sub.add_parser("canape")
    c.add_argument("csv")
    c.add_argument("out_stem")
    c.add_argument("--unsorted", action="store_true")
    c.add_argument("--compression", type=int, default=0)
    c.set_defaults(f=canape)
    u = sub.add_parser("unsort")
    u.add_argument("src")
    u.add_argument("dst")
    u.set_defaults(f=unsort)
    w = sub.add_parser("written")
    w.add_argument("mf4")
    w.add_argument("csv")
    w.add_argument("--vary", default="", help="columns that differ between two runs of the "
                   "command (host timing): their names, units and lengths only")
    w.set_defaults(f=written)
    d = sub.add_parser("same-diagnosis")
    d.add_argument("a")
    d.add_argument("b")
    d.add_argument("--rel", type=float, default=0.02)
    d.add_argument("--abs-mps", type=float, default=0.0)
    d.add_argument("--noise-units", action="store_true")
    d.set_defaults(f=same_diagnosis)
    x = sub.add_parser("fixtures")
    x.add_argument("dir")
    x.set_defaults(f=fixtures)
    z = sub.add_parser("fuzz-seeds")
    z.add_argument("dir")
    z.set_defaults(f=fuzz_seeds)
    v = sub.add_parser("vlsd")
    v.add_argument("dump")
    v.add_argument("n", type=int, nargs="?", default=2000)
    v.set_defaults(f=vlsd)
    f = sub.add_parser("friction")
    f.add_argument("csv")
    f.add_argument("out_stem")
    f.add_argument("--slow-temp", action="store_true")
    f.add_argument("--compression", type=int, default=0)
    f.set_defaults(f=friction)
    a = p.parse_args()
    a.f(a)


if __name__ == "__main__":
    main()
