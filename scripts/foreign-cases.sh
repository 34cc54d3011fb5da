#!/usr/bin/env bash
# Runs `hils diagnose` / `hils fit-friction` on the independent cases of
# ../shared/foreign-cases (runs and friction tests of another simulator of the same vehicle,
# logged like rigs and field tests) and scores them with their own scorer: one line per case
# (ok / FAIL with reasons, wall time s, exit code), then `N/M right`; exits 0 only when every
# case is right. The recipe is the one of ../shared/foreign-cases/README.md.
#   bash scripts/foreign-cases.sh [OUT_DIR]          (needs: cargo build --release -p hils)
set -uo pipefail
cd "$(dirname "$0")/.."
cases="${FOREIGN_CASES:-../shared/foreign-cases}"
spec="$(dirname "$cases")/spec"
hils="${CARGO_TARGET_DIR:-target}/release/hils"
out="${1:-$(mktemp -d)}"
mkdir -p "$out"
[ -x "$hils" ] || { echo "no $hils: run cargo build --release -p hils" >&2; exit 2; }
sed 's/^model = "variable"/model = "constant"/' "$spec/reference-parameters.toml" > "$out/baseline.toml"
python3 -c 'import json,sys
for c,a in sorted(json.load(open(sys.argv[1]))["cases"].items()): print(c, a["kind"], *a["files"])' \
    "$cases/answers.json" | while read -r c kind files; do
    args=(); for f in $files; do args+=("$cases/$f"); done
    start=$(date +%s.%N)
    if [ "$kind" = friction-test ]; then
        "$hils" fit-friction --json "$out/$c.json" "${args[@]}"
    else
        "$hils" diagnose --baseline "$out/baseline.toml" --json "$out/$c.json" "${args[@]}"
    fi > "$out/$c.log" 2>&1 < /dev/null
    rc=$?
    python3 -c "import sys; print(f'{float(sys.argv[2]) - float(sys.argv[1]):.1f} {sys.argv[3]}')" \
        "$start" "$(date +%s.%N)" "$rc" > "$out/$c.wall"
done
python3 "$cases/score.py" "$cases/answers.json" "$out"
