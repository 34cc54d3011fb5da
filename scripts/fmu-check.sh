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
# Needs FMPy (pip install fmpy==0.3.32); with --rust-fmi also libclang for rust-fmi's
# bindgen (Debian: libclang-dev). CI (.ci/run) runs FMPy and the direct import; rust-fmi's
# importer (a bindgen build of several minutes on 2 cores) runs with --rust-fmi.
# Usage: scripts/fmu-check.sh [--rust-fmi] [WORK_DIR]
set -euo pipefail
cd "$(dirname "$0")/.."
rust_fmi=0
if [ "${1:-}" = "--rust-fmi" ]; then rust_fmi=1; shift; fi
work=${1:-target/fmu-check}
fmu=target/fmu/hils_plant.fmu

python3 -c "import fmpy" 2>/dev/null || { echo "FMPy missing: pip install fmpy==0.3.32" >&2; exit 1; }

echo "-- cargo fmu"
cargo fmu
echo "-- fmpy validate $fmu"
fmpy validate "$fmu"
if [ "$rust_fmi" = 1 ]; then
    echo "-- the importers' checks (hils-fmu-check with rust-fmi's importer)"
    cargo build --release -q -p hils-fmu-check --features rust-fmi
else
    echo "-- the importers' checks (hils-fmu-check; rust-fmi's importer not run: --rust-fmi runs it)"
    cargo build --release -q -p hils-fmu-check
fi
check=target/release/hils-fmu-check
"$check" reference "$work"
python3 scripts/fmu_check.py "$fmu" "$work"
"$check" direct "$fmu"
if [ "$rust_fmi" = 1 ]; then "$check" rust-fmi "$fmu"; fi
rm -f "$work/reference.f32"
