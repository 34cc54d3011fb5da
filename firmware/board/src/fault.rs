//! The safe state on every fault path and at every start, the reset after a fault, the
//! count of fault resets in a row, the stack guard, and what a debugger halt does.
//!
//! A panic, a HardFault (a stack overflow included), an NMI (the clock security system saw
//! the crystal stop) or an unexpected interrupt all end here: interrupts off, then at once
//!
//! * pulse outputs silent: the four pulse timers stopped, their channel forced inactive
//!   (OC1M = force inactive, MOE cleared) and the pins PA8/PB14/PC6/PB2 switched to GPIO
//!   outputs driven low, so no timer state can drive them; the output enable (PC8) low, so
//!   the interface stage opens the sensor loops;
//! * FDCAN1 off the bus: CCCR.INIT set (RM0440 FDCAN: message transfer stops, FDCAN_TX
//!   recessive), and PA12 (FDCAN1_TX) switched to a GPIO output driven high (recessive):
//!   the FDCAN kernel clock is the HSE, so after a crystal failure the controller may not
//!   act on INIT and could hold the bus dominant;
//!
//! then a record of the fault in RAM that survives the reset (`.uninit`, reported at the
//! next start), a defmt line if the logger is free, ~50 ms for the host to read it (the
//! watchdog is fed every ms of the actual SYSCLK, HSI16 after a clock failure) and a
//! system reset. An NMI is classified from its sources (RCC_CIFR.CSSF clock security,
//! FLASH_ECCR.ECCD double ECC error, SYSCFG_CFGR2.SPF SRAM parity). The independent watchdog (10 ms, fed by
//! the step) is the backstop for everything that does not reach these handlers: a stuck
//! step, a lockup, interrupts masked too long.
//!
//! **At every start**: the reset handler's first instructions (`__pre_init`, `ccm.rs`,
//! before the CCM copy and RAM initialisation) drive the pulse pins and the output enable
//! low and PA12 high, within a microsecond of the reset instead of floating until the
//! application configures them; `main` does the same again ([`safe_pins_at_start`]) before
//! the crystal's up to 100 ms start.
//! Before that (the reset itself and the boot ROM) only the external pull resistors decide
//! (docs/rig.md, "Lines in reset").
//!
//! **Fault resets in a row** are counted in `.uninit` (`hils_rig_core::reset_loop`): after
//! three the board holds the safe state ([`hold`]) until power-cycled or reset by its button.
//!
//! **Stack guard** ([`guard_stack`]): the stack is at the bottom of SRAM (`stack.x`), and
//! an MPU region forbids the 32 KiB below it; an overflow is a MemManage fault escalated to
//! HardFault, whose handler ([`HardFault`] in assembly) first moves to its own stack.
//!
//! **Lockup** (a fault inside a fault handler; a Cortex-M4 lockup does not reset the
//! STM32G4 until the watchdog does): SYSCFG_CFGR2.CLL connects it to the break input of
//! the four pulse timers (TIM1/8/20/15, `crate::pulse`), which clear MOE and drive the
//! outputs to their idle level (low) in hardware.
//!
//! A debugger halt freezes the step timer, the pulse timers, the time driver and the
//! watchdog (DBGMCU): the trains stop where they are instead of running on with the last
//! speed, and the board does not reset under the debugger.

use core::mem::MaybeUninit;
use core::ptr::addr_of_mut;
use core::sync::atomic::{AtomicBool, Ordering};

use cortex_m_rt::exception;
use embassy_stm32::pac;
use embassy_stm32::pac::gpio::vals::Moder;
use embassy_stm32::pac::timer::vals::Ocm;
use hils_rig_core::reset_loop::{Boot, ResetCause, ResetLoopRecord};

use crate::pulse::{CAN_TX_PIN_ID, OUTPUT_ENABLE_PIN, PULSE_PINS, PULSE_TIMERS};

/// What ended the last run (an unknown stored code reads as `UnexpectedInterrupt`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, defmt::Format, num_enum::FromPrimitive)]
#[repr(u32)]
pub enum FaultKind {
    Panic = 1,
    HardFault = 2,
    ClockFailure = 3,
    #[num_enum(default)]
    UnexpectedInterrupt = 4,
    /// NMI from a flash double ECC error (FLASH_ECCR.ECCD).
    FlashEcc = 5,
    /// NMI from an SRAM parity error (SYSCFG_CFGR2.SPF).
    SramParity = 6,
    /// NMI with none of its known sources flagged.
    UnknownNmi = 7,
    /// HardFault from a stack overflow (the guard below the stack).
    StackOverflow = 8,
}

/// A fault, kept across the reset.
#[derive(Clone, Copy, Debug, defmt::Format)]
pub struct FaultRecord {
    pub kind: FaultKind,
    /// HardFault: the faulting PC; panic: the source line.
    pub pc_or_line: u32,
    /// HardFault: LR; unexpected interrupt: its number.
    pub lr_or_irq: u32,
    /// HardFault: SCB CFSR; NMI: RCC_CIFR (the NMI's FLASH_ECCR is in `pc_or_line`, its
    /// SYSCFG_CFGR2 in `lr_or_irq`).
    pub detail: u32,
}

#[repr(C)]
struct Stored {
    magic: u32,
    kind: u32,
    pc_or_line: u32,
    lr_or_irq: u32,
    detail: u32,
}

const MAGIC: u32 = 0x5AFE_57A7;

/// Not zeroed at start-up (cortex-m-rt `.uninit`): survives a system reset.
#[unsafe(link_section = ".uninit.board_fault")]
static mut LAST_FAULT: MaybeUninit<Stored> = MaybeUninit::uninit();

static IN_FAULT: AtomicBool = AtomicBool::new(false);

/// The fault that ended the previous run, if it was one of ours; forgets it.
pub fn take_last_fault() -> Option<FaultRecord> {
    // SAFETY: read at start-up before any handler can write; plain words, any bit pattern.
    let s = unsafe { core::ptr::read_volatile(addr_of_mut!(LAST_FAULT) as *const Stored) };
    // SAFETY: as above.
    unsafe { core::ptr::write_volatile(addr_of_mut!(LAST_FAULT) as *mut u32, 0) };
    if s.magic != MAGIC {
        return None;
    }
    Some(FaultRecord {
        kind: FaultKind::from(s.kind),
        pc_or_line: s.pc_or_line,
        lr_or_irq: s.lr_or_irq,
        detail: s.detail,
    })
}

/// Pulse outputs silent, the output enable off and FDCAN off the bus. Register writes
/// only: callable from any fault handler and at start, with any peripheral state (writes to
/// an unclocked peripheral are ignored).
pub fn enter_safe_state() {
    for tim in PULSE_TIMERS {
        tim.cr1().modify(|w| w.set_cen(false));
        tim.ccmr_output(0)
            .modify(|w| w.set_ocm(0, Ocm::FORCE_INACTIVE));
        tim.bdtr().modify(|w| w.set_moe(false));
    }
    for (port, pin) in PULSE_PINS.into_iter().chain([OUTPUT_ENABLE_PIN]) {
        crate::pulse::drive_low(port, pin);
    }
    pac::FDCAN1.cccr().modify(|w| w.set_init(true));
    // PA12 = FDCAN1_TX: high first, then output, so the pin never drives dominant.
    pac::GPIOA.bsrr().write(|w| w.set_bs(CAN_TX_PIN, true));
    pac::GPIOA
        .moder()
        .modify(|w| w.set_moder(CAN_TX_PIN, Moder::OUTPUT));
}

/// PA12, FDCAN1_TX (app.rs).
const CAN_TX_PIN: usize = CAN_TX_PIN_ID.1;

/// The first thing at every start: GPIOA-C clocked and the controller-facing pins driven
/// safe (pulse pins and output enable low, PA12 high = CAN recessive), before the crystal
/// starts (up to 100 ms) and before embassy's init (which only enables GPIO clocks, so the
/// states stay until the application takes each pin).
pub fn safe_pins_at_start() {
    pac::RCC.ahb2enr().modify(|w| {
        w.set_gpioaen(true);
        w.set_gpioben(true);
        w.set_gpiocen(true);
    });
    // RCC: two AHB cycles before the enabled port takes writes (RM0440 RCC, "delay after
    // an RCC peripheral clock enabling").
    let _ = pac::RCC.ahb2enr().read();
    cortex_m::asm::dsb();
    enter_safe_state();
}

/// Fault resets in a row before this start (`RIG_HEALTH` `FaultResets`).
pub static FAULT_RESETS: core::sync::atomic::AtomicU32 = core::sync::atomic::AtomicU32::new(0);

/// Not zeroed at start-up: survives a system reset (`hils_rig_core::reset_loop`).
#[unsafe(link_section = ".uninit.board_reset_loop")]
static mut RESET_LOOP: MaybeUninit<ResetLoopRecord> = MaybeUninit::uninit();

/// Counts this start against the fault resets in a row (`cause` from RCC_CSR and the fault
/// record) and says whether to start or hold.
pub fn note_boot(cause: ResetCause) -> Boot {
    // SAFETY: start-up, before any handler can run; three plain words, any bit pattern.
    let boot = unsafe {
        let r = &mut *(addr_of_mut!(RESET_LOOP) as *mut ResetLoopRecord);
        let mut rec = core::ptr::read_volatile(r);
        let boot = rec.on_boot(cause);
        core::ptr::write_volatile(r, rec);
        boot
    };
    FAULT_RESETS.store(boot.fault_resets(), Ordering::Relaxed);
    boot
}

/// The board ran healthy for `reset_loop::HEALTHY_RUN_TICKS`: the next fault starts a new
/// count (thread mode, once).
pub fn ran_healthy() {
    // SAFETY: a three-word write from thread mode; the fault handlers never write it.
    unsafe {
        let r = addr_of_mut!(RESET_LOOP) as *mut ResetLoopRecord;
        let mut rec = core::ptr::read_volatile(r);
        rec.ran_healthy();
        core::ptr::write_volatile(r, rec);
    }
}

/// Holds the safe state after too many fault resets in a row: no clock change, no CAN, no
/// step, no watchdog; LD2 (PA5) blinks twice a second. Until power-cycled or reset.
pub fn hold(fault_resets: u32) -> ! {
    enter_safe_state();
    defmt::error!(
        "{=u32} fault resets in a row: holding the safe state (outputs silent, CAN off); power-cycle or press reset (B2) to start again",
        fault_resets
    );
    const LED_PIN: usize = 5;
    pac::GPIOA
        .moder()
        .modify(|w| w.set_moder(LED_PIN, Moder::OUTPUT));
    loop {
        for on in [true, false, true, false, false, false, false, false] {
            pac::GPIOA.bsrr().write(|w| {
                if on {
                    w.set_bs(LED_PIN, true)
                } else {
                    w.set_br(LED_PIN, true)
                }
            });
            // 125 ms at HSI16 (the clock was never switched).
            cortex_m::asm::delay(HSI16_HZ / 8);
        }
    }
}

fn record(kind: FaultKind, pc_or_line: u32, lr_or_irq: u32, detail: u32) {
    let s = Stored {
        magic: MAGIC,
        kind: kind as u32,
        pc_or_line,
        lr_or_irq,
        detail,
    };
    // SAFETY: single writer (interrupts are off in every fault path).
    unsafe { core::ptr::write_volatile(addr_of_mut!(LAST_FAULT) as *mut Stored, s) };
}

/// Core cycles per ms of the clock SYSCLK runs from now (RCC_CFGR.SWS): after a crystal
/// failure the clock security system has switched it to HSI16.
fn cycles_per_ms() -> u32 {
    use pac::rcc::vals::Sw;
    match pac::RCC.cfgr().read().sws() {
        Sw::PLL1_R => crate::clock::SYSCLK_HZ / 1000,
        Sw::HSE => crate::clock::HSE_HZ / 1000,
        _ => HSI16_HZ / 1000,
    }
}

/// HSI16, Hz.
const HSI16_HZ: u32 = 16_000_000;

/// Waits ~50 ms for the host to read the log (feeding the watchdog every ms of the actual
/// SYSCLK: a delay counted at 170 MHz would last 10.6 ms at HSI16, past the 10 ms
/// watchdog), then resets.
fn wait_then_reset() -> ! {
    let cycles = cycles_per_ms();
    for _ in 0..50 {
        pac::IWDG
            .kr()
            .write(|w| w.set_key(pac::iwdg::vals::Key::RESET));
        cortex_m::asm::delay(cycles);
    }
    cortex_m::peripheral::SCB::sys_reset()
}

/// Common entry: interrupts off, safe state; `true` for the first fault only (a fault
/// inside a fault handler goes straight to the reset).
fn begin() -> bool {
    cortex_m::interrupt::disable();
    enter_safe_state();
    !IN_FAULT.swap(true, Ordering::Relaxed)
}

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    if begin() {
        let line = info.location().map_or(0, |l| l.line());
        record(FaultKind::Panic, line, 0, 0);
        defmt::error!("panic: {} - safe state, reset", defmt::Display2Format(info));
    }
    wait_then_reset()
}

/// The HardFault handler's own stack: a stack overflow leaves MSP below SRAM, where no push
/// can go (the MPU guard), so the handler moves here before any Rust code runs.
const FAULT_STACK_BYTES: usize = 2048;
/// FPCCR, the floating-point context control register (bit 0: LSPACT).
const FPCCR_ADDR: u32 = 0xE000_EF34;
#[repr(C, align(8))]
struct FaultStack([u8; FAULT_STACK_BYTES]);
static mut FAULT_STACK: FaultStack = FaultStack([0; FAULT_STACK_BYTES]);

// HardFault, in place of cortex-m-rt's trampoline (which would run the handler on the
// faulting stack): r0 = MSP as the fault left it (the exception frame, if it could be
// pushed), FPCCR.LSPACT cleared, MSP = the top of FAULT_STACK, then the handler.
// LSPACT: a fault taken with an active FP context and lazy stacking (FPCCR.LSPEN, the
// reset value) leaves the FP registers' slot reserved in the faulting frame, at FPCAR, and
// the first FP instruction of the handler would push them there: below the stack after an
// overflow, a MemManage fault inside HardFault, i.e. a lockup. Clearing LSPACT drops that
// pending push (ARMv7-M ARM B3.2.21, FPCCR; the faulting context never resumes).
core::arch::global_asm!(
    ".section .HardFaultTrampoline, \"ax\"",
    ".global HardFault",
    ".type HardFault, %function",
    ".thumb_func",
    "HardFault:",
    "    mrs r0, MSP",
    "    ldr r1, ={fpccr}",
    "    ldr r2, [r1]",
    "    bic r2, r2, #1",
    "    str r2, [r1]",
    "    dsb",
    "    isb",
    "    ldr r1, ={stack}",
    "    add.w r1, r1, #{size}",
    "    msr MSP, r1",
    "    b {handler}",
    ".ltorg",
    fpccr = const FPCCR_ADDR,
    stack = sym FAULT_STACK,
    size = const FAULT_STACK_BYTES,
    handler = sym hard_fault_on_own_stack,
);

unsafe extern "C" {
    static _stack_end: u32;
    static _stack_start: u32;
}

/// The stack's size, bytes: `stack.x`'s `_stack_size`, the one place it is set.
#[inline(always)]
pub fn stack_bytes() -> u32 {
    let (bottom, top) = stack_span();
    top - bottom
}

/// The stack's bottom (lowest address) and top, from `stack.x`.
#[inline(always)]
pub fn stack_span() -> (u32, u32) {
    // Linker symbols: only their addresses are used.
    (
        core::ptr::addr_of!(_stack_end) as u32,
        core::ptr::addr_of!(_stack_start) as u32,
    )
}

/// The HardFault handler, on its own stack; `sp`: MSP when the fault was taken.
unsafe extern "C" fn hard_fault_on_own_stack(sp: u32) -> ! {
    if begin() {
        // SAFETY: read-only access to the system control block's fault status.
        let (cfsr, mmfar) = unsafe {
            let scb = &*cortex_m::peripheral::SCB::PTR;
            (scb.cfsr.read(), scb.mmfar.read())
        };
        let (bottom, top) = stack_span();
        // The frame's PC and LR, only where the frame could be pushed.
        let frame_ok = sp >= bottom && sp + 32 <= top;
        // SAFETY: inside the stack (checked); words 5 and 6 of the exception frame.
        let (lr, pc) = if frame_ok {
            unsafe {
                (
                    core::ptr::read_volatile((sp + 20) as *const u32),
                    core::ptr::read_volatile((sp + 24) as *const u32),
                )
            }
        } else {
            (0, 0)
        };
        let overflow = hils_rig_core::stack::is_overflow(sp, bottom, cfsr, mmfar);
        let kind = if overflow {
            FaultKind::StackOverflow
        } else {
            FaultKind::HardFault
        };
        record(kind, pc, lr, cfsr);
        defmt::error!(
            "HardFault{=str} at pc {=u32:#010x} lr {=u32:#010x} sp {=u32:#010x} CFSR {=u32:#010x} - safe state, reset",
            if overflow { " (stack overflow)" } else { "" },
            pc,
            lr,
            sp,
            cfsr
        );
    }
    wait_then_reset()
}

/// MPU region 0: no access to the 32 KiB below SRAM (0x1FFF_8000..0x1FFF_FFFF: bank-2
/// system memory and option bytes, which nothing here reads), so a push below the stack is
/// a MemManage fault, whatever the bus would do. PRIVDEFENA: the default map everywhere
/// else; HFNMIENA clear: the MPU is off in the HardFault and NMI handlers.
pub fn guard_stack() {
    const GUARD_BASE: u32 = 0x1FFF_8000;
    // RASR: ENABLE, SIZE = log2(32 KiB) - 1 = 14, AP = 0b000 (no access), XN.
    const RASR: u32 = 1 | (14 << 1) | (1 << 28);
    // SAFETY: the MPU is configured once at start, before anything runs below the guard.
    unsafe {
        let mpu = &*cortex_m::peripheral::MPU::PTR;
        mpu.rnr.write(0);
        mpu.rbar.write(GUARD_BASE);
        mpu.rasr.write(RASR);
        // CTRL: ENABLE | PRIVDEFENA.
        mpu.ctrl.write(1 | (1 << 2));
    }
    cortex_m::asm::dsb();
    cortex_m::asm::isb();
}

/// SYSCFG_CFGR2.CLL: the Cortex-M4 LOCKUP output to the break input of TIM1/8/15/16/17/20
/// (RM0440 "From system errors to timers"; set once, cleared only by a reset). Also keeps
/// SPL and ECCL as they are.
pub fn break_on_lockup() {
    pac::SYSCFG.cfgr2().modify(|w| w.set_cll(true));
}

/// The NMI's cause from its sources on the G474 (RM0440: clock security system, flash
/// double ECC error, SRAM parity error), the first flagged in that order.
fn classify_nmi(cifr: u32, eccr: u32, cfgr2: u32) -> FaultKind {
    if pac::rcc::regs::Cifr(cifr).cssf() {
        FaultKind::ClockFailure
    } else if pac::flash::regs::Eccr(eccr).eccd() {
        FaultKind::FlashEcc
    } else if pac::syscfg::regs::Cfgr2(cfgr2).spf() {
        FaultKind::SramParity
    } else {
        FaultKind::UnknownNmi
    }
}

#[exception]
unsafe fn NonMaskableInt() {
    if begin() {
        let cifr = pac::RCC.cifr().read().0;
        let eccr = pac::FLASH.eccr().read().0;
        let cfgr2 = pac::SYSCFG.cfgr2().read().0;
        // Clear the flags (the handler does not return, but a flag left set would be
        // raised again at once if it ever did).
        pac::RCC.cicr().write(|w| w.set_cssc(true));
        pac::FLASH.eccr().modify(|w| w.set_eccd(true));
        pac::SYSCFG.cfgr2().modify(|w| w.set_spf(true));
        let kind = classify_nmi(cifr, eccr, cfgr2);
        record(kind, eccr, cfgr2, cifr);
        defmt::error!(
            "NMI: {} (RCC_CIFR {=u32:#x}, FLASH_ECCR {=u32:#x}, SYSCFG_CFGR2 {=u32:#x}) - safe state, reset",
            kind,
            cifr,
            eccr,
            cfgr2
        );
    }
    wait_then_reset()
}

#[exception]
unsafe fn DefaultHandler(irqn: i16) {
    if begin() {
        record(FaultKind::UnexpectedInterrupt, 0, irqn as u32, 0);
        defmt::error!("unexpected interrupt {=i16} - safe state, reset", irqn);
    }
    wait_then_reset()
}

/// DBGMCU: on a debugger halt, stop the step timer (TIM3), the pulse timers (TIM1, TIM15,
/// TIM8, TIM20), the time driver (TIM2) and the independent watchdog.
pub fn freeze_on_debug_halt() {
    pac::DBGMCU.apb1lfzr().modify(|w| {
        w.set_tim2(true);
        w.set_tim3(true);
        w.set_iwdg(true);
    });
    pac::DBGMCU.apb2fzr().modify(|w| {
        w.set_tim1(true);
        w.set_tim8(true);
        w.set_tim15(true);
        w.set_tim20(true);
    });
}
