//! Cycles per plant step on the Cortex-M4F, estimated from the instruction mix QEMU
//! executes (QEMU counts instructions, not cycles).
//!
//! Stage: run the emulator binary with QEMU's execution trace (`-d in_asm,exec,nochain`,
//! read from a pipe, never stored) until [`PROFILE_STEPS`] calls of `Plant::step` have
//! run (the start of the variable friction run), count how often each instruction of the
//! step and of the functions it calls executes, and weight each with the CPI model below.
//!
//! # CPI model (stated; Cortex-M4 TRM r0p1 section 3.3 and its FPU chapter)
//!
//! Zero wait states (code in CCM SRAM on the I-bus, data in SRAM on the S-bus):
//! VDIV.F32, VSQRT.F32 14 | VMLA/VMLS/VNMLA/VNMLS/VFMA.F32 3 | VLDR, VSTR 2 | other FP
//! data processing 1 | LDR/STR 2 | LDRD/STRD 3 | PUSH/POP/LDM/STM and VPUSH/VPOP
//! 1 + registers | unconditional branch, call, return 3 (1 + 2 refill) | conditional
//! branch 1, + 2 when taken (taken = executed minus the executions of the next
//! instruction) | other integer 1.
//!
//! Flash at 170 MHz ([`FLASH_WAIT_STATES`] = 4, a 64-bit line per fetch), assuming the
//! 1 KiB instruction cache never holds the step (its code is several KiB): every taken
//! branch waits the full latency (+4 cycles); in straight code the prefetch of the next
//! 64-bit line overlaps execution, so a line costs max(0, 5 - cycles spent executing it)
//! extra cycles; a load from flash (literal pool, `[pc, ...]`) waits +4. This is the
//! upper estimate; a cache that always hits gives the zero-wait figure.

use std::collections::HashMap;
use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Command, Stdio};

use anyhow::{Context, Result, anyhow, bail};
use serde::Serialize;

/// `Plant::step` calls profiled (the emulator runs every step twice: in the closed loop
/// and as a replay, so this is half as many plant steps).
pub const PROFILE_STEPS: u64 = 4000;
/// Flash wait states of the STM32G474 at 170 MHz (RM0440, 3.3.3: 4 WS above 136 MHz).
pub const FLASH_WAIT_STATES: u64 = 4;
/// Core clock of the board, Hz.
pub const CORE_CLOCK_HZ: f64 = 170e6;

/// The functions whose instructions count as the plant step's: the step and its callees.
const STEP_FUNCTIONS: [&str; 4] = [
    "Plant$LT$F$GT$::step",
    "libm::math::atanf",
    "libm::math::logf",
    "expf::exp_outside",
];

/// Estimated cycles per plant step.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct CycleEstimate {
    pub steps_profiled: u64,
    /// Instructions per step in the profiled steps (the start of the run).
    pub profile_instructions_per_step: f64,
    /// Cycles per instruction with zero wait states (CCM SRAM).
    pub cpi_ccm: f64,
    /// Cycles per instruction from flash, no cache hits.
    pub cpi_flash: f64,
    /// `cpi_ccm` times the mean instructions of the whole run.
    pub cycles_per_step_ccm: f64,
    /// `cpi_flash` times the mean instructions of the whole run.
    pub cycles_per_step_flash: f64,
    /// `cycles_per_step_ccm` at 170 MHz, microseconds.
    pub us_per_step_ccm: f64,
    pub us_per_step_flash: f64,
    /// Instructions and zero-wait cycles per step by instruction class.
    pub classes: Vec<(String, f64, f64)>,
    pub model: &'static str,
}

/// One-line statement of the model (report and JSON).
pub const MODEL: &str = "Cortex-M4 TRM timings: VDIV/VSQRT 14, VMLA-family 3, VLDR/VSTR 2, \
     LDR/STR 2, LDRD/STRD 3, PUSH/POP 1+regs, branch taken +2 (unconditional 3), rest 1; \
     flash: 4 WS, no cache hits, +4 per taken branch and literal load, 64-bit prefetch \
     overlapping execution";

/// One disassembled instruction.
struct Insn {
    op: String,
    operands: String,
    size: u64,
}

/// Zero-wait cycles and class of an instruction (conditional branches: not taken).
fn base_cycles(op: &str, operands: &str) -> (u64, &'static str) {
    let regs = || operands.split(',').count() as u64;
    let op = op.split('.').next().unwrap_or(op);
    match op {
        "vdiv" | "vsqrt" => (14, "divide/sqrt"),
        "vmla" | "vmls" | "vnmla" | "vnmls" | "vfma" | "vfms" | "vfnma" | "vfnms" => {
            (3, "multiply-accumulate")
        }
        _ if op.starts_with("vldr") || op.starts_with("vstr") => (2, "FP load/store"),
        "vpush" | "vpop" => (1 + 2 * operands.matches('d').count() as u64, "push/pop"),
        "push" | "pop" => (1 + regs(), "push/pop"),
        _ if op.starts_with("ldm") || op.starts_with("stm") => (1 + regs(), "push/pop"),
        _ if op.starts_with("ldrd") || op.starts_with("strd") => (3, "integer load/store"),
        _ if op.starts_with("ldr") || op.starts_with("str") => (2, "integer load/store"),
        "b" | "bl" | "blx" | "bx" => (3, "branch"),
        _ if is_conditional_branch(op) => (1, "branch"),
        _ if op.starts_with('v') => (1, "FP other"),
        _ => (1, "integer other"),
    }
}

fn is_conditional_branch(op: &str) -> bool {
    const CONDS: [&str; 14] = [
        "eq", "ne", "gt", "lt", "ge", "le", "hi", "ls", "mi", "pl", "hs", "lo", "cs", "cc",
    ];
    op.starts_with("cb") || (op.len() == 3 && op.starts_with('b') && CONDS.contains(&&op[1..]))
}

/// Address, mnemonic and operands of an llvm-objdump line
/// (`"    ae0:      \tpush\t{r4, r5, r7, lr}"`; comments after `@` dropped).
fn parse_insn(line: &str) -> Option<(u64, String, String)> {
    let (addr, rest) = line.trim_start().split_once(':')?;
    let addr = u64::from_str_radix(addr, 16).ok()?;
    let rest = rest.trim_start();
    let (op, operands) = rest.split_once('\t').unwrap_or((rest, ""));
    let operands = operands.split(" @").next().unwrap_or("").trim();
    Some((addr, op.trim().to_string(), operands.to_string()))
}

/// The step's instructions (address -> instruction) and the entry of `Plant::step`.
fn disassemble(elf: &Path) -> Result<(HashMap<u64, Insn>, u64)> {
    let out = Command::new("llvm-objdump")
        .args(["-d", "--demangle", "--no-show-raw-insn"])
        .arg(elf)
        .output()
        .context("cannot run llvm-objdump (Debian: apt-get install llvm)")?;
    let text = String::from_utf8_lossy(&out.stdout);
    let (mut insns, mut entry, mut inside) = (HashMap::new(), None, false);
    let mut last: Option<u64> = None;
    for line in text.lines() {
        if let Some(name) = line.strip_suffix(">:").and_then(|l| l.split_once(" <")) {
            if !name.1.starts_with('$') {
                inside = STEP_FUNCTIONS.iter().any(|f| name.1.contains(f));
                if inside && name.1.contains("::step") && entry.is_none() {
                    entry = u64::from_str_radix(name.0, 16).ok();
                }
            }
            continue;
        }
        let Some((addr, op, operands)) = parse_insn(line) else {
            continue;
        };
        if let Some(prev) = last.take() {
            if let Some(i) = insns.get_mut(&prev) {
                let i: &mut Insn = i;
                i.size = addr.saturating_sub(prev).min(4);
            }
        }
        if !inside {
            continue;
        }
        insns.insert(
            addr,
            Insn {
                op,
                operands,
                size: 2,
            },
        );
        last = Some(addr);
    }
    let entry = entry.ok_or_else(|| anyhow!("no Plant::step in {}", elf.display()))?;
    Ok((insns, entry))
}

/// Executions per instruction address over the first [`PROFILE_STEPS`] step calls.
fn profile(qemu: &str, elf: &Path, entry: u64) -> Result<(HashMap<u64, u64>, u64)> {
    let mut child = super::emulator::qemu_command(qemu, elf)
        .args(["-d", "in_asm,exec,nochain"])
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .with_context(|| format!("cannot start {qemu}"))?;
    let log = child.stderr.take().ok_or_else(|| anyhow!("no stderr"))?;
    let mut blocks: HashMap<u64, Vec<u64>> = HashMap::new();
    let mut block_runs: HashMap<u64, u64> = HashMap::new();
    let mut current: Option<Vec<u64>> = None;
    let mut steps = 0;
    for line in BufReader::new(log).lines() {
        let line = line?;
        if line.starts_with("IN:") {
            current = Some(Vec::new());
            continue;
        }
        if let Some(block) = current.as_mut() {
            let addr = line
                .strip_prefix("0x")
                .and_then(|l| l.split(':').next())
                .and_then(|a| u64::from_str_radix(a, 16).ok());
            match addr {
                Some(a) => {
                    block.push(a);
                    continue;
                }
                None => {
                    if let Some(b) = current.take().filter(|b| !b.is_empty()) {
                        blocks.insert(b[0], b);
                    }
                }
            }
        }
        // "Trace 0: 0x... [00000000/000005e0/...] symbol"
        if line.starts_with("Trace") {
            let pc = line
                .split('[')
                .nth(1)
                .and_then(|f| f.split('/').nth(1))
                .and_then(|a| u64::from_str_radix(a, 16).ok());
            if let Some(pc) = pc {
                *block_runs.entry(pc).or_default() += 1;
                if pc == entry {
                    steps += 1;
                    if steps >= PROFILE_STEPS {
                        break;
                    }
                }
            }
        }
    }
    let _ = child.kill();
    let _ = child.wait();
    if steps == 0 {
        bail!("no plant step ran under the execution trace");
    }
    let mut counts: HashMap<u64, u64> = HashMap::new();
    for (start, n) in block_runs {
        for a in blocks.get(&start).into_iter().flatten() {
            *counts.entry(*a).or_default() += n;
        }
    }
    Ok((counts, steps))
}

/// Cycles of the profiled instructions: (class -> (instructions, zero-wait cycles)) and
/// the flash penalty, from the execution counts.
fn weigh(
    insns: &HashMap<u64, Insn>,
    counts: &HashMap<u64, u64>,
) -> (HashMap<&'static str, (u64, u64)>, u64) {
    let mut classes: HashMap<&'static str, (u64, u64)> = HashMap::new();
    let mut penalty = 0;
    // 64-bit flash lines: executions (of their busiest instruction) and cycles inside.
    let mut lines: HashMap<u64, (u64, u64)> = HashMap::new();
    for (addr, insn) in insns {
        let n = counts.get(addr).copied().unwrap_or(0);
        if n == 0 {
            continue;
        }
        let (c, class) = base_cycles(&insn.op, &insn.operands);
        let head = insn.op.split('.').next().unwrap_or("");
        let taken = if is_conditional_branch(head) {
            let next = counts.get(&(addr + insn.size)).copied().unwrap_or(0);
            n.saturating_sub(next)
        } else if matches!(head, "b" | "bl" | "blx" | "bx")
            || (head == "pop" && insn.operands.contains("pc"))
        {
            n
        } else {
            0
        };
        // A taken conditional branch refills the pipeline (+2); unconditional ones are
        // counted at 3 already.
        let c = c * n + if c == 1 { 2 * taken } else { 0 };
        let e = classes.entry(class).or_default();
        e.0 += n;
        e.1 += c;
        penalty += FLASH_WAIT_STATES * taken;
        if insn.operands.contains("[pc") {
            penalty += FLASH_WAIT_STATES * n;
        }
        let line = lines.entry(addr / 8).or_default();
        line.0 = line.0.max(n);
        line.1 += c;
    }
    for (runs, cycles) in lines.values() {
        let per_run = cycles / runs.max(&1);
        penalty += runs * (FLASH_WAIT_STATES + 1).saturating_sub(per_run);
    }
    (classes, penalty)
}

/// Profiles the emulator binary and scales the CPI to `instructions_mean` (the whole run's
/// mean instructions per step).
pub fn estimate(qemu: &str, elf: &Path, instructions_mean: f64) -> Result<CycleEstimate> {
    let (insns, entry) = disassemble(elf)?;
    let (counts, steps) = profile(qemu, elf, entry)?;
    let (classes, penalty) = weigh(&insns, &counts);
    let instructions: u64 = classes.values().map(|c| c.0).sum();
    let cycles: u64 = classes.values().map(|c| c.1).sum();
    if instructions == 0 {
        bail!("the execution trace holds no instruction of the plant step");
    }
    let cpi_ccm = cycles as f64 / instructions as f64;
    let cpi_flash = (cycles + penalty) as f64 / instructions as f64;
    let mut by_class: Vec<(String, f64, f64)> = classes
        .into_iter()
        .map(|(k, (i, c))| {
            (
                k.to_string(),
                i as f64 / steps as f64,
                c as f64 / steps as f64,
            )
        })
        .collect();
    by_class.sort_by(|a, b| b.2.total_cmp(&a.2));
    let ccm = cpi_ccm * instructions_mean;
    let flash = cpi_flash * instructions_mean;
    Ok(CycleEstimate {
        steps_profiled: steps,
        profile_instructions_per_step: instructions as f64 / steps as f64,
        cpi_ccm,
        cpi_flash,
        cycles_per_step_ccm: ccm,
        cycles_per_step_flash: flash,
        us_per_step_ccm: ccm / CORE_CLOCK_HZ * 1e6,
        us_per_step_flash: flash / CORE_CLOCK_HZ * 1e6,
        classes: by_class,
        model: MODEL,
    })
}

#[cfg(test)]
mod tests {
    use super::{base_cycles, is_conditional_branch, parse_insn};

    #[test]
    fn reads_objdump_lines() {
        let line = "    16ee:      \tbl\t0xc6c8 <libm::math::atanf::atanf::h7e> @ imm = #45014";
        assert_eq!(
            parse_insn(line),
            Some((
                0x16ee,
                "bl".into(),
                "0xc6c8 <libm::math::atanf::atanf::h7e>".into()
            ))
        );
        assert_eq!(parse_insn("Disassembly of section .text:"), None);
        assert_eq!(parse_insn("00000ae0 <hils_plant::plant::step>:"), None);
    }

    #[test]
    fn timings_of_the_model() {
        assert_eq!(base_cycles("vdiv.f32", "s0, s1, s2").0, 14);
        assert_eq!(base_cycles("vmla.f32", "s0, s1, s2").0, 3);
        assert_eq!(base_cycles("vldr", "s0, [r0, #4]").0, 2);
        assert_eq!(base_cycles("vadd.f32", "s0, s1, s2").0, 1);
        assert_eq!(base_cycles("push.w", "{r4, r5, r6, lr}").0, 5);
        assert_eq!(base_cycles("ldrd", "r0, r1, [r2]").0, 3);
        assert!(is_conditional_branch("bgt") && is_conditional_branch("cbz"));
        assert!(!is_conditional_branch("bic") && !is_conditional_branch("bl"));
    }
}
