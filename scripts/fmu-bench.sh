#!/usr/bin/env bash
# Plant steps per second through the FMU, against the plant's own (docs/fmu.md, "Speed"):
#   hils bench                  the plant alone (f32, one core, the paper's EB inputs);
#   hils-fmu-check bench        a direct Rust import of the packed FMU: one plant step per
#                               fmi3DoStep (4 inputs set each call) and 100 per call, and the
#                               plant alone timed the same way in the same process;
#   scripts/fmu_bench.py        the same through FMPy (FMU3Slave, Python).
# Run it on an idle machine: the figures are wall-clock times.
set -euo pipefail
cd "$(dirname "$0")/.."
work=${1:-target/fmu-bench}
cargo fmu >/dev/null
cargo build --release -q -p hils -p hils-fmu-check
mkdir -p "$work"
echo "== hils bench (plant alone)"
target/release/hils bench --json --repeat 3 > "$work/hils-bench.json"
python3 -c 'import json,sys; b=json.load(open(sys.argv[1])); print("  plant alone: {:,.0f} steps/s (f32, {})".format(b["steps_per_s_f32"], b["host_isa"]))' "$work/hils-bench.json"
echo "== direct Rust import of target/fmu/hils_plant.fmu"
target/release/hils-fmu-check bench target/fmu/hils_plant.fmu
echo "== FMPy"
target/release/hils-fmu-check reference "$work" >/dev/null
python3 scripts/fmu_bench.py target/fmu/hils_plant.fmu "$work"
rm -f "$work/reference.f32"
