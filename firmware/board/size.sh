#!/usr/bin/env bash
# Prints the flash and static RAM of the board image and checks the budgets
# (issue 5: <= 96 KiB flash, <= 32 KiB static RAM). Needs llvm-size (Debian package llvm).
#   bash firmware/board/size.sh [ELF]     (default: the image `cargo board` builds)
set -euo pipefail
elf="${1:-${CARGO_TARGET_DIR:-target}/thumbv7em-none-eabihf/release/board}"
size_tool="$(command -v llvm-size || command -v rust-size || command -v arm-none-eabi-size || true)"
if [ -z "$size_tool" ]; then
    echo "size.sh: no llvm-size (apt-get install llvm)" >&2
    exit 2
fi
"$size_tool" -A "$elf"
# Flash: everything loaded from flash (vector table, code, read-only data, .data's image).
# Static RAM: .data + .bss + .uninit (the stack is the rest of the 96 KiB SRAM1+2).
"$size_tool" -A "$elf" | awk -v elf="$elf" '
    $1 == ".vector_table" || $1 == ".text" || $1 == ".rodata" || $1 == ".gnu.sgstubs" { flash += $2 }
    $1 == ".data" { flash += $2; ram += $2 }
    $1 == ".bss" || $1 == ".uninit" { ram += $2 }
    END {
        printf "board image %s\n", elf
        printf "  flash      %6d B = %5.1f KiB (budget 96 KiB)\n", flash, flash / 1024
        printf "  static RAM %6d B = %5.1f KiB (budget 32 KiB)\n", ram, ram / 1024
        if (flash > 96 * 1024 || ram > 32 * 1024) { print "  OVER BUDGET"; exit 1 }
        print "  within budget"
    }'
