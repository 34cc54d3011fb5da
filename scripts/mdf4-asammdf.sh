#!/usr/bin/env bash
# MDF4 in and out checked by an independent implementation, asammdf (issue 23; .ci/run
# calls it; needs `cargo build --release -p hils` and Python 3; installs asammdf with pip
# when missing). Prints one line per check and exits non-zero on the first that fails:
#   1. files the project writes (`hils simulate --format mf4`, `hils decode -o X.mf4`,
#      `hils rig record --out X.mf4`) read by asammdf: every channel, unit and sample equal
#      to the CSV the same command writes, the metadata in the header's properties;
#   2. a foreign case (../shared/foreign-cases/fc03.csv: 200 Hz, jittered, dropouts) written
#      by asammdf as a CANape-like recording (foreign names, km/h, bar, kN; two rates;
#      integer channels with conversions; sorted, unsorted and DZ-compressed) plus its
#      channel map: `hils diagnose` gives the diagnosis of the spec CSV of the same data
#      (equal), and of the original CSV within the noise of the slower radar and pressures;
#   3. reading speed and peak memory of the MDF4 and CSV files (`hils bench --reader`).
#   bash scripts/mdf4-asammdf.sh [OUT_DIR]
set -euo pipefail
cd "$(dirname "$0")/.."
out="${1:-$(mktemp -d)}"
mkdir -p "$out"
hils="${CARGO_TARGET_DIR:-target}/release/hils"
[ -x "$hils" ] || { echo "no $hils: run cargo build --release -p hils" >&2; exit 2; }
python3 -c 'import asammdf' 2>/dev/null || python3 -m pip install -q asammdf
py="python3 scripts/mdf4_asammdf.py"
cases="${FOREIGN_CASES:-../shared/foreign-cases}"
spec="$(dirname "$cases")/spec"

echo "== files the project writes, read by asammdf $(python3 -c 'import asammdf; print(asammdf.__version__)')"
"$hils" simulate --no-plots --out "$out/sim-csv" > /dev/null
"$hils" simulate --no-plots --out "$out/sim-mf4" --format mf4 > /dev/null
$py written "$out/sim-mf4/run.mf4" "$out/sim-csv/run.csv"
fixture=firmware/rig-fixture/fixture
"$hils" decode "$fixture/telemetry.defmt" --elf "$fixture/rig-fixture.elf" --run 1 -o "$out/decoded.csv" > /dev/null
"$hils" decode "$fixture/telemetry.defmt" --elf "$fixture/rig-fixture.elf" --run 1 -o "$out/decoded.mf4" > /dev/null
$py written "$out/decoded.mf4" "$out/decoded.csv"
for ext in csv mf4; do
    printf 'record --out %s\nstart --arm --speed-kmh 60 --rail wet --friction variable\nbrake eb\nwait --until-end\n' \
        "$out/recorded.$ext" > "$out/session-$ext.txt"
    "$hils" rig --interface sim session "$out/session-$ext.txt" > /dev/null
done
# Two sessions: the step times of the simulated board are the host's (they vary).
$py written "$out/recorded.mf4" "$out/recorded.csv" --vary step_max_us,step_mean_us

echo "== a CANape-like recording by asammdf + channel map: the diagnosis of its spec CSV"
sed 's/^model = "variable"/model = "constant"/' "$spec/reference-parameters.toml" > "$out/baseline.toml"
$py canape "$cases/fc03.csv" "$out/fc03-sorted"
$py canape "$cases/fc03.csv" "$out/fc03-unsorted" --unsorted
$py canape "$cases/fc03.csv" "$out/fc03-dz" --compression 2
diagnose() { "$hils" diagnose --baseline "$out/baseline.toml" --json "$@" > /dev/null; }
diagnose "$out/fc03-csv.json" "$cases/fc03.csv"
diagnose "$out/fc03-equivalent.json" "$out/fc03-sorted.csv"
for layout in sorted unsorted dz; do
    diagnose "$out/fc03-$layout.json" --map "$out/fc03-$layout.map.toml" "$out/fc03-$layout.mf4"
done
$py same-diagnosis "$out/fc03-equivalent.json" "$out/fc03-sorted.json" --rel 1e-6 --noise-units
$py same-diagnosis "$out/fc03-sorted.json" "$out/fc03-unsorted.json" --rel 1e-9 --noise-units
$py same-diagnosis "$out/fc03-sorted.json" "$out/fc03-dz.json" --rel 1e-9 --noise-units
# Radar at 50 Hz in 0.01 km/h steps and pressures at 50 Hz, against the CSV's 200 Hz: the
# speed errors within 5 % or 5 mm/s (a quarter of the radar's noise), the causes equal.
$py same-diagnosis "$out/fc03-csv.json" "$out/fc03-sorted.json" --rel 0.05 --abs-mps 0.005

echo "== reading speed and peak memory (hils bench --reader)"
"$hils" bench --reader "$out/sim-csv/run.csv"
"$hils" bench --reader "$out/sim-mf4/run.mf4"
echo "mdf4-asammdf: all checks passed"
