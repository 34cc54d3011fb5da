#!/usr/bin/env bash
# Makes the telemetry fixture of `hils decode`: builds firmware/rig-fixture for
# thumbv7em-none-eabihf, strips its debug info (the defmt table and symbols stay), runs it in
# QEMU (netduinoplus2, Cortex-M4F) and keeps its raw defmt output.
#   bash firmware/rig-fixture/make-fixture.sh [OUT_DIR]    (default: firmware/rig-fixture/fixture)
# Needs: the thumbv7em-none-eabihf target, qemu-system-arm, llvm-objcopy (Debian llvm).
set -euo pipefail
cd "$(dirname "$0")/../.."
out="${1:-firmware/rig-fixture/fixture}"
mkdir -p "$out"
cargo rig-fixture
elf="${CARGO_TARGET_DIR:-target}/thumbv7em-none-eabihf/firmware/rig-fixture"
objcopy="$(command -v llvm-objcopy || command -v rust-objcopy)"
"$objcopy" --strip-debug "$elf" "$out/rig-fixture.elf"
timeout 300 qemu-system-arm -M netduinoplus2 -nographic -monitor none -serial none \
    -semihosting-config enable=on,target=native \
    -kernel "$out/rig-fixture.elf" > "$out/telemetry.defmt"
echo "fixture: $out/rig-fixture.elf ($(stat -c %s "$out/rig-fixture.elf") B), $out/telemetry.defmt ($(stat -c %s "$out/telemetry.defmt") B)"
