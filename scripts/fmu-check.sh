#!/usr/bin/env bash
# The packed FMU checked by importers outside its own code (CI: .ci/run; docs/fmu.md).
#   1. `cargo fmu` builds target/fmu/hils_plant.fmu;
#   2. FMPy: `fmpy validate` (the model description against the FMI 3.0 schema), then
#      scripts/fmu_check.py: the paper's EB through fmpy.simulate_fmu and the plant driven by
#      the run's pressures at 0.1 ms, both bit-identical to `hils simulate` at every
#      communication point; a bad step size refused with the FMU's message;
#   3. a direct Rust import (dlopen) and rust-fmi's importer (the `fmi` crate):
#      `hils-fmu-check direct` / `rust-fmi` (bit identity, two instances with different
#      parameter files side by side, bad use).
# Needs FMPy (pip install fmpy==0.3.32) and libclang for rust-fmi's bindgen (Debian:
# libclang-dev); .ci/run installs both. Usage: scripts/fmu-check.sh [WORK_DIR]
set -euo pipefail
cd "$(dirname "$0")/.."
work=${1:-target/fmu-check}
fmu=target/fmu/hils_plant.fmu

python3 -c "import fmpy" 2>/dev/null || { echo "FMPy missing: pip install fmpy==0.3.32" >&2; exit 1; }

echo "-- cargo fmu"
cargo fmu
echo "-- fmpy validate $fmu"
fmpy validate "$fmu"
echo "-- the importers' checks (hils-fmu-check with rust-fmi's importer)"
cargo build --release -q -p hils-fmu-check --features rust-fmi
check=target/release/hils-fmu-check
"$check" reference "$work"
python3 scripts/fmu_check.py "$fmu" "$work"
"$check" direct "$fmu"
"$check" rust-fmi "$fmu"
rm -f "$work/reference.f32"
