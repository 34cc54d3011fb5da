//! The step's code in CCM SRAM (see `firmware/board/ccm.x`): copied from its flash load image before
//! anything runs, then write-protected.
//!
//! Why CCM rather than flash with prefetch and the ART caches alone: at 170 MHz flash needs
//! 4 wait states (RM0440 flash latency table, range 1 boost), and the instruction cache
//! holds 1 KiB while the step (rig step, plant, brake unit) is ~16 KiB of straight-line
//! floating point per tick, so most fetches would miss. CCM SRAM is read on the I-bus
//! with no wait state at 170 MHz (RM0440 2.1.1, 2.4), and its data (the rig in SRAM1) is
//! fetched in parallel on the S-bus. Prefetch and both caches are enabled as well
//! (`clock::enable_flash_accelerator`) for everything that stays in flash.

use core::ptr::addr_of;

use embassy_stm32::pac;

unsafe extern "C" {
    static __sccm_text: u32;
    static __eccm_text: u32;
    static __siccm_text: u32;
}

// cortex-m-rt's Reset calls `__pre_init` before it initialises RAM (cortex-m-rt 0.7.7
// lib.rs: `bl __pre_init`), and asks for it in assembly: no Rust code, no memcpy (which
// may itself live in CCM), runs before the copy. Word copy; the section is 8-byte aligned
// and padded (ccm.x), so every word of it is written before it is fetched (CCM SRAM
// parity, when enabled by the SRAM_PE option bit, is computed on write).
// A core-only reset (a debugger's VECTRESET) keeps SYSCFG_SWPR, which only a system reset
// clears: the pages are write-protected and hold the image already, so the copy is skipped
// (it would fault on them before RAM is initialised). After a system reset SYSCFG is not
// clocked and SWPR reads 0.
// First of all, the safe pins (`crate::pulse::SAFE_PIN_WRITES`; docs/rig.md "Lines in
// reset"): GPIOA-C clocked (RCC_AHB2ENR, RM0440: 0x4002_104C, GPIOAEN..GPIOCEN bits 0-2,
// read back so the clock is on before the ports are written), then per port (GPIOA
// 0x4800_0000, GPIOB +0x400, GPIOC +0x800) BSRR (+0x18) first, then MODER (+0x00) to
// general-purpose output: the pin never drives a level other than the safe one.
core::arch::global_asm!(
    ".section .text.__pre_init, \"ax\"",
    ".global __pre_init",
    ".type __pre_init, %function",
    ".thumb_func",
    "__pre_init:",
    "    ldr r0, =0x4002104C",
    "    ldr r1, [r0]",
    "    orr r1, r1, #7",
    "    str r1, [r0]",
    "    ldr r1, [r0]",
    "    dsb",
    "    ldr r0, =0x48000000",
    "    ldr r1, ={bsrr_a}",
    "    str r1, [r0, #0x18]",
    "    ldr r1, [r0]",
    "    ldr r2, ={mask_a}",
    "    bic r1, r1, r2",
    "    ldr r2, ={value_a}",
    "    orr r1, r1, r2",
    "    str r1, [r0]",
    "    ldr r0, =0x48000400",
    "    ldr r1, ={bsrr_b}",
    "    str r1, [r0, #0x18]",
    "    ldr r1, [r0]",
    "    ldr r2, ={mask_b}",
    "    bic r1, r1, r2",
    "    ldr r2, ={value_b}",
    "    orr r1, r1, r2",
    "    str r1, [r0]",
    "    ldr r0, =0x48000800",
    "    ldr r1, ={bsrr_c}",
    "    str r1, [r0, #0x18]",
    "    ldr r1, [r0]",
    "    ldr r2, ={mask_c}",
    "    bic r1, r1, r2",
    "    ldr r2, ={value_c}",
    "    orr r1, r1, r2",
    "    str r1, [r0]",
    "    ldr r0, =0x40010020", // SYSCFG_SWPR (RM0440: SYSCFG base 0x4001_0000 + 0x20)
    "    ldr r0, [r0]",
    "    cbnz r0, 1f",
    "    ldr r0, =__sccm_text",
    "    ldr r1, =__eccm_text",
    "    ldr r2, =__siccm_text",
    "0:  cmp r1, r0",
    "    beq 1f",
    "    ldm r2!, {{r3}}",
    "    stm r0!, {{r3}}",
    "    b 0b",
    "1:  bx lr",
    ".ltorg",
    mask_a = const crate::pulse::SAFE_PIN_WRITES[0].0,
    value_a = const crate::pulse::SAFE_PIN_WRITES[0].1,
    bsrr_a = const crate::pulse::SAFE_PIN_WRITES[0].2,
    mask_b = const crate::pulse::SAFE_PIN_WRITES[1].0,
    value_b = const crate::pulse::SAFE_PIN_WRITES[1].1,
    bsrr_b = const crate::pulse::SAFE_PIN_WRITES[1].2,
    mask_c = const crate::pulse::SAFE_PIN_WRITES[2].0,
    value_c = const crate::pulse::SAFE_PIN_WRITES[2].1,
    bsrr_c = const crate::pulse::SAFE_PIN_WRITES[2].2,
);

/// CCM SRAM pages are 1 KiB (SYSCFG_SWPR: one write-protection bit per page, 32 pages).
const PAGE_BYTES: u32 = 1024;
const CCM_BASE: u32 = 0x1000_0000;

/// The CCM code section: start address and length in bytes.
pub fn code_span() -> (u32, u32) {
    // Linker symbols: only their addresses are used.
    let (start, end) = (addr_of!(__sccm_text) as u32, addr_of!(__eccm_text) as u32);
    (start, end - start)
}

/// The flash address of the CCM code's load image.
pub fn load_address() -> u32 {
    // Linker symbol: only its address is used.
    addr_of!(__siccm_text) as u32
}

/// Pages of CCM SRAM holding code (bit per page).
pub fn code_pages() -> u32 {
    let (start, len) = code_span();
    if len == 0 {
        return 0;
    }
    let first = (start - CCM_BASE) / PAGE_BYTES;
    let last = (start - CCM_BASE + len - 1) / PAGE_BYTES;
    let mut mask = 0u32;
    for p in first..=last.min(31) {
        mask |= 1 << p;
    }
    mask
}

/// Write-protects the pages holding code: a stray write into them is a bus fault
/// (HardFault -> safe state) instead of corrupted step code. SYSCFG_SWPR bits are cleared
/// only by a system reset, so this is done after embassy's init (which resets SYSCFG).
pub fn write_protect() {
    let pages = code_pages();
    pac::SYSCFG.swpr().modify(|w| w.0 |= pages);
}

/// Whether the CCM code equals its flash image (word compare).
pub fn matches_load_image() -> bool {
    let (start, len) = code_span();
    let src = load_address();
    (0..len / 4).all(|k| {
        // SAFETY: both ranges are inside the linked sections (CCM code, its flash image).
        unsafe {
            core::ptr::read_volatile((start + 4 * k) as *const u32)
                == core::ptr::read_volatile((src + 4 * k) as *const u32)
        }
    })
}
