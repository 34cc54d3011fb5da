#!/usr/bin/env bash
# Runs `hils diagnose` / `hils fit-friction` on the independent cases of
# ../shared/foreign-cases and ../shared/foreign-cases-2 (runs and friction tests of another
# simulator of the same vehicle, logged like rigs and field tests) and scores each set with
# its own scorer: one line per case (ok / FAIL with reasons, wall time s, exit code), then
# `N/M right`, then the wall and CPU (user + system) time of every case; exits 0 only when
# every case of every set is right. The recipe is the one of the sets' README.md.
#   bash scripts/foreign-cases.sh [OUT_DIR]          (needs: cargo build --release -p hils)
# FOREIGN_CASES=DIR runs that one set only; HILS_SHARED_DIR=DIR is the shared material
# (default ../shared). Each set's outputs go to OUT_DIR/<set>/.
set -uo pipefail
cd "$(dirname "$0")/.."
shared="${HILS_SHARED_DIR:-../shared}"
if [ -n "${FOREIGN_CASES:-}" ]; then
    sets=("$FOREIGN_CASES")
else
    sets=("$shared/foreign-cases" "$shared/foreign-cases-2")
fi
hils="${CARGO_TARGET_DIR:-target}/release/hils"
out_root="${1:-$(mktemp -d)}"
[ -x "$hils" ] || { echo "no $hils: run cargo build --release -p hils" >&2; exit 2; }

# Runs one command, writing its output to $1 and "WALL_S RC CPU_S" to $2.
timed() {
    python3 - "$@" <<'EOF'
import resource, subprocess, sys, time
log, stamp, cmd = sys.argv[1], sys.argv[2], sys.argv[3:]
start = time.monotonic()
with open(log, "w") as out:
    rc = subprocess.run(cmd, stdout=out, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL).returncode
wall = time.monotonic() - start
ru = resource.getrusage(resource.RUSAGE_CHILDREN)
open(stamp, "w").write(f"{wall:.1f} {rc} {ru.ru_utime + ru.ru_stime:.1f}\n")
EOF
}

status=0
for cases in "${sets[@]}"; do
    [ -f "$cases/answers.json" ] || { echo "no $cases/answers.json" >&2; status=2; continue; }
    out="$out_root/$(basename "$cases")"
    mkdir -p "$out"
    spec="$(dirname "$cases")/spec"
    sed 's/^model = "variable"/model = "constant"/' "$spec/reference-parameters.toml" > "$out/baseline.toml"
    echo "== $(basename "$cases")"
    python3 -c 'import json,sys
for c,a in sorted(json.load(open(sys.argv[1]))["cases"].items()): print(c, a["kind"], *a["files"])' \
        "$cases/answers.json" | while read -r c kind files; do
        args=(); for f in $files; do args+=("$cases/$f"); done
        if [ "$kind" = friction-test ]; then
            timed "$out/$c.log" "$out/$c.wall" "$hils" fit-friction --json "$out/$c.json" "${args[@]}"
        else
            timed "$out/$c.log" "$out/$c.wall" "$hils" diagnose --baseline "$out/baseline.toml" \
                --json "$out/$c.json" "${args[@]}"
        fi
    done
    python3 "$cases/score.py" "$cases/answers.json" "$out" || status=1
    python3 - "$out" <<'EOF'
import glob, os, sys
rows = []
for w in sorted(glob.glob(os.path.join(sys.argv[1], "*.wall"))):
    f = open(w).read().split()
    if len(f) >= 3:
        rows.append((os.path.basename(w)[:-5], float(f[0]), float(f[2])))
if rows:
    print("time per case (wall s / cpu s): " + ", ".join(f"{c} {w:.1f}/{u:.1f}" for c, w, u in rows))
    print(f"largest: wall {max(r[1] for r in rows):.1f} s, cpu {max(r[2] for r in rows):.1f} s")
EOF
done
exit $status
