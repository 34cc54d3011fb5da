#!/usr/bin/env bash
# Prints the flash and RAM of a board image and checks the budgets: half the chip,
# <= 256 KiB flash and <= 64 KiB RAM (issue 22) counting the stack with the statics, for the
# rig image (`cargo board`) and the bring-up image (`cargo board --features bringup`) alike;
# the CCM SRAM code fits its 32 KiB; the stack (its size set once, `_stack_size` in stack.x)
# is at the bottom of SRAM. Needs llvm-size (Debian package llvm).
#   bash firmware/board/size.sh [ELF]     (default: the image last built by `cargo board ...`)
set -euo pipefail
elf="${1:-${CARGO_TARGET_DIR:-target}/thumbv7em-none-eabihf/firmware/board}"
size_tool="$(command -v llvm-size || command -v rust-size || command -v arm-none-eabi-size || true)"
if [ -z "$size_tool" ]; then
    echo "size.sh: no llvm-size (apt-get install llvm)" >&2
    exit 2
fi
"$size_tool" -A "$elf"
# Flash: everything loaded from flash (vector table, code, read-only data, the load images
# of .data and of the step code that runs from CCM SRAM).
# RAM: .data + .bss + .uninit (the statics) + .stack (below them): the budget is for all.
# CCM SRAM: the step code copied there at reset (ccm.x; 32 KiB).
"$size_tool" -A "$elf" | awk -v elf="$elf" '
    $1 == ".vector_table" || $1 == ".text" || $1 == ".text.rig_core_cold" || $1 == ".rodata" || $1 == ".gnu.sgstubs" { flash += $2 }
    $1 == ".ccmram_text" { flash += $2; ccm += $2 }
    $1 == ".data" { flash += $2; ram += $2 }
    $1 == ".bss" || $1 == ".uninit" { ram += $2 }
    $1 == ".stack" { stack = $2; stack_at = $3 }
    END {
        printf "board image %s\n", elf
        printf "  flash      %6d B = %5.1f KiB (budget 256 KiB)\n", flash, flash / 1024
        printf "  RAM        %6d B = %5.1f KiB (budget 64 KiB): statics %d B + stack %d B\n", ram + stack, (ram + stack) / 1024, ram, stack
        printf "  CCM code   %6d B = %5.1f KiB (CCM SRAM 32 KiB; in flash too, as its load image)\n", ccm, ccm / 1024
        printf "  stack      %6d B = %5.1f KiB at %#x (stack.x: bottom of SRAM, guard below)\n", stack, stack / 1024, stack_at
        if (flash > 256 * 1024 || ram + stack > 64 * 1024 || ccm > 32 * 1024) { print "  OVER BUDGET"; exit 1 }
        if (stack == 0 || stack_at != 536870912) { print "  STACK NOT AT THE BOTTOM OF SRAM (stack.x)"; exit 1 }
        print "  within budget"
    }'

# Step placement (ccm.x): the step interrupt runs from CCM SRAM, masks no interrupt
# globally (no CPSID in CCM code: its critical sections are BASEPRI ceilings), and leaves
# CCM only for cold paths (panics, defmt, the construction of a run, the commands:
# Rig::command on a command tick, IoConfig::set, KeptSetup::apply; a Start's setup_digest
# and a Calibrate frame's decode_calibration).
objdump_tool="$(command -v llvm-objdump || command -v arm-none-eabi-objdump || true)"
nm_tool="$(command -v llvm-nm || command -v arm-none-eabi-nm || true)"
if [ -n "$objdump_tool" ] && [ -n "$nm_tool" ]; then
    tim3="$("$nm_tool" "$elf" | awk '$3 == "TIM3" { print $1 }')"
    cpsid="$("$objdump_tool" -d --no-show-raw-insn "$elf" | grep -ciE '^ *10[0-9a-f]{6}:.*cpsid' || true)"
    hot_exits="$("$nm_tool" "$elf" | awk '$1 ~ /^10/ && $3 ~ /LongThunk/ { print $3 }' \
        | grep -vE 'panic|defmt|slice_index_fail|with_step|with_config|brake_unit4unit.*3new|reset_state|exp_outside|IoConfig3set|KeptSetup5apply|setup_digest|decode_calibration|div_u64_wide|u64_of_wide|Rig.LT.S.GT.7command17h' || true)"
    printf "  step placement: TIM3 at 0x%s, CPSID in CCM code: %s, calls from CCM to hot flash code: %s\n" \
        "$tim3" "$cpsid" "$(printf '%s' "$hot_exits" | grep -c . || true)"
    if [ "${tim3:0:2}" != "10" ] || [ "$cpsid" != "0" ] || [ -n "$hot_exits" ]; then
        printf '%s\n' "$hot_exits"
        echo "  STEP PLACEMENT BROKEN (see firmware/board/ccm.x)"
        exit 1
    fi
fi

# Indirect calls from CCM code (review C1: they need no long-branch thunk, so the check
# above cannot see them). The only ones allowed are waker calls through a RawWakerVTable
# (`ldr rN, [rM, #4]; blx rN`, the load within the 4 instructions before the call and
# rN not written in between: a StepChannel send waking a task), and their targets, the
# executor's waker functions, must be in CCM SRAM too (ccm.x).
if [ -n "$objdump_tool" ] && [ -n "$nm_tool" ]; then
    indirect="$("$objdump_tool" -d --no-show-raw-insn "$elf" | awk '
        /^ *10[0-9a-f][0-9a-f][0-9a-f][0-9a-f][0-9a-f][0-9a-f]:/ {
            if ($0 ~ /\tblx\tr[0-9]+/) {
                reg = $0; sub(/.*blx\t/, "", reg); sub(/[^a-z0-9].*/, "", reg)
                n++
                ok = 0
                for (k = 1; k <= 4; k++) {
                    if (prev[k] ~ ("\tldr\t" reg ", \\[r[0-9]+, #4\\]")) { ok = 1; break }
                    if (prev[k] ~ ("\t[a-z.]+\t" reg "(,|$)")) break
                }
                if (!ok) { bad++; print "  not a waker call: " $0 > "/dev/stderr" }
            }
            for (k = 4; k > 1; k--) prev[k] = prev[k - 1]
            prev[1] = $0
        }
        END { printf "%d %d\n", n, bad }')"
    set -- $indirect
    waker_in_flash="$("$nm_tool" "$elf" | awk '$3 ~ /16embassy_executor3raw5waker(4wake|5clone|4drop)/ && $1 !~ /^10/ && $3 !~ /LongThunk/' | grep -c . || true)"
    printf "  indirect calls from CCM code: %s (waker wake through the executor's vtable; waker functions in flash: %s)\n" "$1" "$waker_in_flash"
    if [ "$2" != "0" ] || { [ "$1" != "0" ] && [ "$waker_in_flash" != "0" ]; }; then
        echo "  INDIRECT CALL FROM CCM TO FLASH (see firmware/board/ccm.x)"
        exit 1
    fi
fi

# defmt::flush would busy-wait while the host has set the RTT channel blocking, even with
# `disable-blocking-mode` (defmt-rtt 1.3.1 channel.rs; review C9): never linked.
if [ -n "$nm_tool" ] && "$nm_tool" "$elf" | grep -q '_defmt_flush'; then
    echo "  defmt::flush is linked: it can block the logging task (review C9)"
    exit 1
fi

# Stack frames of the step's own functions (prologue: pushes and `sub sp`), against a
# budget: a value of the size of the simulation (~6 KiB) moved through the step would
# show here as a frame of that size (review of issue 11).
STEP_FRAME_BUDGET=1024
if [ -n "$objdump_tool" ] && [ -n "$nm_tool" ]; then
    # By address (objdump may label a function with another symbol at the same address,
    # e.g. __sccm_text for the first function in CCM).
    step_fns="$("$nm_tool" "$elf" | awk '$3 == "TIM3" || $3 ~ /4step9step_tick|4step8rig_step/ { if ($3 !~ /LongThunk/) printf "%s=%s ", $1, $3 }')"
    "$objdump_tool" -d --no-show-raw-insn "$elf" | awk -v budget="$STEP_FRAME_BUDGET" -v fns="$step_fns" '
        BEGIN { k = split(fns, f, " "); for (i = 1; i <= k; i++) { split(f[i], p, "="); want[p[1]] = p[2] } }
        /^[0-9a-f]+ <[^$][^>]*>:$/ {
            if (name != "") report()
            name = ""; n = 0; frame = 0
            if ($1 in want) { name = want[$1]; delete want[$1] }
            next
        }
        name != "" && n < 16 {
            n++
            line = $0
            if (line ~ /\tv?push(\.w)?\t\{/) {
                regs = line; sub(/.*\{/, "", regs); sub(/\}.*/, "", regs)
                k = split(regs, r, ",")
                frame += (line ~ /vpush/ ? 8 : 4) * k
            } else if (line ~ /\tsub(\.w)?\tsp, (sp, )?#[0-9]+/) {
                imm = line; sub(/.*#/, "", imm); sub(/[^0-9].*/, "", imm)
                frame += imm
            }
        }
        function report() {
            printf "  step frame: %s %d B (budget %d B)\n", name, frame, budget
            if (frame > budget) over = 1
        }
        END {
            if (name != "") report()
            if (over) { print "  STEP FRAME OVER BUDGET"; exit 1 }
        }'
fi
