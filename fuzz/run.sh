#!/usr/bin/env bash
# Runs every fuzz target for SECONDS each (default 30) or RUNS executions each
# (`fuzz/run.sh --runs 1000000`), starting from the committed seeds (fuzz/seeds/<target>,
# found crashes included as regression inputs). Prints the executions per target; exits
# non-zero on the first failing target and leaves the failing input in fuzz/artifacts/<target>/.
#
# Builds the targets with plain cargo on the stable toolchain, with the flags cargo-fuzz 0.13
# passes for `cargo fuzz build -s none -a` (SanitizerCoverage instrumentation for libFuzzer,
# `--cfg fuzzing`, debug assertions and overflow checks; no sanitizer: safe Rust), so CI
# needs no cargo-fuzz install. `cargo fuzz run -s none -a --fuzz-dir fuzz <target>` builds
# the same binaries.
set -euo pipefail
cd "$(dirname "$0")/.."
limit="-max_total_time=${1:-30}"
if [ "${1:-}" = "--runs" ]; then limit="-runs=${2:?--runs N}"; fi
targets=(reader mdf4 params can_rig decode plant)
host=$(rustc -vV | sed -n 's/^host: //p')
flags=(
    -Cpasses=sancov-module
    -Cllvm-args=-sanitizer-coverage-level=4
    -Cllvm-args=-sanitizer-coverage-inline-8bit-counters
    -Cllvm-args=-sanitizer-coverage-pc-table
    -Cllvm-args=-sanitizer-coverage-trace-compares
    -Cllvm-args=-simplifycfg-branch-fold-threshold=0
    -Cllvm-args=-sanitizer-coverage-stack-depth
    --cfg fuzzing
    -Cdebug-assertions
    -Coverflow-checks
)
# An explicit --target keeps these flags off build scripts and proc macros (as cargo-fuzz does).
RUSTFLAGS="${flags[*]}" cargo build --release --manifest-path fuzz/Cargo.toml \
    --target "$host" --bins
bin_dir="fuzz/target/$host/release"
for t in "${targets[@]}"; do
    corpus="fuzz/corpus/$t"
    mkdir -p "$corpus" "fuzz/artifacts/$t"
    log="fuzz/artifacts/$t/last-run.log"
    # Seeds are read (and run) first; new inputs go to the working corpus.
    if ! "$bin_dir/$t" -artifact_prefix="fuzz/artifacts/$t/" "$corpus" "fuzz/seeds/$t" \
        "$limit" -max_len=4096 -timeout=10 -rss_limit_mb=2048 -print_final_stats=1 \
        >"$log" 2>&1; then
        tail -40 "$log"
        echo "fuzz target $t FAILED (input in fuzz/artifacts/$t/)"
        exit 1
    fi
    execs=$(grep -o 'stat::number_of_executed_units: *[0-9]*' "$log" | grep -o '[0-9]*$' || echo '?')
    echo "fuzz $t: $execs executions, no failure"
done
