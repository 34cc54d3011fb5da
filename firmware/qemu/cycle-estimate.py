#!/usr/bin/env python3
"""Estimate Cortex-M4F cycles per plant step from an executed-instruction profile.

QEMU counts instructions, not cycles (docs/target.md). This script turns the instruction
mix that the emulator actually executes in `Plant::step` into an estimate of core cycles
with the instruction timings of the Cortex-M4 Technical Reference Manual (section 3.3) and
of its FPU (Cortex-M4 TRM, FPU chapter), assuming zero-wait-state memory (code and data
in SRAM / CCM SRAM, or a flash cache that always hits):

  VDIV.F32, VSQRT.F32 14 | VMLA/VMLS/VNMLA/VNMLS.F32 3 | VLDR, VSTR 2 (1 when pipelined)
  other FP data processing 1 | LDR/STR 2 | LDRD/STRD 3 | PUSH/POP/LDM/STM 1 + registers
  taken branch 1 + refill (1..3, 2 used) | conditional branch ~2 (half taken) | ALU 1

Usage (stdlib only, needs qemu-system-arm and llvm-objdump):
  cargo qemu
  python3 firmware/qemu/cycle-estimate.py [ELF] [seconds]

It runs the emulator for a few seconds of wall time with `-d in_asm,exec,nochain` (the
first few thousand steps of the variable friction run), counts how often each
instruction of `Plant::step` and of the functions it calls (libm's atanf, the cold path of
expf) executes, and prints instructions and estimated cycles per step by instruction
class. The log is large (~0.5 GB for 15 s); it goes to a temporary directory.
"""

import collections
import os
import re
import subprocess
import sys
import tempfile

ELF = sys.argv[1] if len(sys.argv) > 1 else "target/thumbv7em-none-eabihf/release/hils-qemu"
SECONDS = sys.argv[2] if len(sys.argv) > 2 else "15"
# Functions whose instructions count as the plant step's (the step and its callees).
FUNCTIONS = [r"Plant\$LT\$F\$GT\$::step", r"libm::math::atanf", r"libm::math::logf", r"expf::exp_outside"]


def disassemble(elf):
    out = subprocess.run(
        ["llvm-objdump", "-d", "--demangle", "--no-show-raw-insn", elf],
        capture_output=True, text=True, check=True,
    ).stdout
    insns, symbols = {}, []
    for line in out.splitlines():
        m = re.match(r"([0-9a-f]{8}) <(.*)>:$", line)
        if m and not m.group(2).startswith("$"):
            symbols.append((int(m.group(1), 16), m.group(2)))
        m = re.match(r"\s+([0-9a-f]+):\s+(\S+)\s*(.*)", line)
        if m:
            insns[int(m.group(1), 16)] = (m.group(2), m.group(3))
    symbols.sort()
    ranges, step_entry = [], None
    for i, (addr, name) in enumerate(symbols):
        if any(re.search(f, name) for f in FUNCTIONS) and i + 1 < len(symbols):
            ranges.append((addr, symbols[i + 1][0]))
            if "step" in name:
                step_entry = addr
    return insns, ranges, step_entry


def profile(elf, log):
    cmd = [
        "timeout", SECONDS, "qemu-system-arm", "-machine", "mps2-an386", "-cpu", "cortex-m4",
        "-nographic", "-monitor", "none", "-serial", "none",
        "-semihosting-config", "enable=on,target=native", "-icount", "shift=0",
        "-kernel", elf, "-d", "in_asm,exec,nochain", "-D", log,
    ]
    subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    blocks, executed, current = {}, collections.Counter(), None
    with open(log) as f:
        for line in f:
            if line.startswith("IN:"):
                current = []
                continue
            if current is not None:
                m = re.match(r"0x([0-9a-f]{8}):", line)
                if m:
                    current.append(int(m.group(1), 16))
                    continue
                if current:
                    blocks[current[0]] = current
                current = None
            if line.startswith("Trace"):
                m = re.search(r"\[[0-9a-f]+/([0-9a-f]+)/", line)
                executed[int(m.group(1), 16)] += 1
    counts = collections.Counter()
    for start, n in executed.items():
        for addr in blocks.get(start, []):
            counts[addr] += n
    return counts, executed


def cycles(op, operands):
    if op.startswith(("vdiv", "vsqrt")):
        return 14, "divide/sqrt"
    if re.match(r"v(n)?ml[as]", op):
        return 3, "multiply-accumulate"
    if op.startswith(("vldr", "vstr")):
        return 2, "FP load/store"
    if op.startswith(("vpush", "vpop")):
        return 1 + 2 * len(re.findall(r"d\d+", operands)), "push/pop"
    if op.startswith(("push", "pop", "ldm", "stm")):
        return 1 + len(operands.split(",")), "push/pop"
    if op.startswith(("ldrd", "strd")):
        return 3, "integer load/store"
    if op.startswith(("ldr", "str")):
        return 2, "integer load/store"
    if op in ("b", "b.w", "bl") or op.startswith(("blx", "bx")):
        return 3, "branch"
    if re.match(r"b(eq|ne|gt|lt|ge|le|hi|ls|mi|pl|hs|lo)(\.w)?$", op) or op.startswith("cb"):
        return 2, "branch"
    if op.startswith("v"):
        return 1, "FP other"
    return 1, "integer other"


def main():
    insns, ranges, step_entry = disassemble(ELF)
    with tempfile.TemporaryDirectory() as tmp:
        counts, executed = profile(ELF, os.path.join(tmp, "qemu.log"))
    steps = executed[step_entry]
    if not steps:
        sys.exit("no plant step executed: is this the hils-qemu ELF?")
    by_class = collections.defaultdict(lambda: [0, 0])
    for addr, n in counts.items():
        if not any(lo <= addr < hi for lo, hi in ranges):
            continue
        c, cls = cycles(*insns.get(addr, ("?", "")))
        by_class[cls][0] += n
        by_class[cls][1] += n * c
    total_i = sum(v[0] for v in by_class.values())
    total_c = sum(v[1] for v in by_class.values())
    print(f"{steps} plant steps profiled (start of the variable friction run)")
    print(f"instructions per step {total_i / steps:.0f}, estimated cycles per step "
          f"{total_c / steps:.0f} (CPI {total_c / total_i:.2f}, zero wait states)")
    for cls, (i, c) in sorted(by_class.items(), key=lambda kv: -kv[1][1]):
        print(f"  {cls:<20} {i / steps:6.0f} instructions {c / steps:6.0f} cycles")


if __name__ == "__main__":
    main()
