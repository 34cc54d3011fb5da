#!/usr/bin/env bash
# Runs every fuzz target for SECONDS each (default 30; CI) or RUNS executions each
# (`fuzz/run.sh --runs 1000000`), starting from the committed seeds (fuzz/seeds/<target>,
# found crashes included as regression inputs). Needs cargo-fuzz (`cargo install
# cargo-fuzz`); on the stable toolchain RUSTC_BOOTSTRAP=1 lets it pass its flags.
# Prints the executions per target; exits non-zero on the first failing target and leaves
# the failing input in fuzz/artifacts/<target>/.
set -euo pipefail
cd "$(dirname "$0")/.."
limit="-max_total_time=${1:-30}"
if [ "${1:-}" = "--runs" ]; then limit="-runs=${2:?--runs N}"; fi
targets=(reader mdf4 params can_rig decode plant)
command -v cargo-fuzz >/dev/null || cargo install --locked cargo-fuzz
export RUSTC_BOOTSTRAP=1
# No sanitizer (safe Rust); debug assertions and overflow checks on (-a).
cargo fuzz build -s none -a --fuzz-dir fuzz
for t in "${targets[@]}"; do
    corpus="fuzz/corpus/$t"
    mkdir -p "$corpus" "fuzz/artifacts/$t"
    log="fuzz/artifacts/$t/last-run.log"
    # Seeds are read (and run) first; new inputs go to the working corpus.
    if ! cargo fuzz run -s none -a --fuzz-dir fuzz "$t" "$corpus" "fuzz/seeds/$t" -- \
        "$limit" -max_len=4096 -timeout=10 -rss_limit_mb=2048 -print_final_stats=1 \
        >"$log" 2>&1; then
        tail -40 "$log"
        echo "fuzz target $t FAILED (input in fuzz/artifacts/$t/)"
        exit 1
    fi
    execs=$(grep -o 'stat::number_of_executed_units: *[0-9]*' "$log" | grep -o '[0-9]*$' || echo '?')
    echo "fuzz $t: $execs executions, no failure"
done
