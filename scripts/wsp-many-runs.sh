#!/usr/bin/env bash
# The memory figure of issue 24 item 8: `hils wsp-test` on a programme of N runs (default
# 10,000) keeps only the verdicts, so its peak memory does not grow with N.
#   scripts/wsp-many-runs.sh [N] [OUT_DIR] [SPEED_KMH]
# Writes OUT_DIR/programme.toml (N runs cycling over the default programme's tracks and
# demands, 40-120 km/h, or all from SPEED_KMH: short runs for a quick check), runs `hils wsp-test --json OUT_DIR/verdicts.json` under
# /usr/bin/time -v (Debian package `time`) when it is there, and prints the summary line
# (runs passed, programme time, peak memory) and time's wall time and peak RSS.
set -euo pipefail
cd "$(dirname "$0")/.."
n="${1:-10000}"
out="${2:-target/wsp-many-runs}"
speed="${3:-}"
mkdir -p "$out"
p="$out/programme.toml"
{
    sed -n '/^\[criteria\]/,/^\[\[run\]\]/p' programmes/wsp-low-adhesion.toml | sed '$d'
    tracks=(low very_low low_dry_low wet_low low)
    demands=(emergency emergency emergency emergency "service:0.8")
    for ((k = 0; k < n; k++)); do
        i=$((k % 5))
        v="${speed:-$((40 + (k % 9) * 10))}"
        printf '[[run]]\nname = "run-%05d"\nspeed_kmh = %s\ndemand = "%s"\ntrack = "%s"\n' \
            "$k" "$v" "${demands[$i]}" "${tracks[$i]}"
    done
} >"$p"
cargo build --release -p hils
hils=target/release/hils
if [ -x /usr/bin/time ]; then
    /usr/bin/time -v "$hils" wsp-test --programme "$p" --json "$out/verdicts.json" \
        >"$out/stdout.txt" 2>"$out/time.txt"
    grep -E 'runs passed' "$out/stdout.txt"
    grep -E 'Elapsed \(wall clock\)|Maximum resident set size' "$out/time.txt"
else
    "$hils" wsp-test --programme "$p" --json "$out/verdicts.json" >"$out/stdout.txt"
    grep -E 'runs passed' "$out/stdout.txt"
fi
