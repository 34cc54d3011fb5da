//! The safe state on every fault path, the reset after it, and what a debugger halt does.
//!
//! A panic, a HardFault, an NMI (the clock security system saw the crystal stop) or an
//! unexpected interrupt all end here: interrupts off, then at once
//!
//! * pulse outputs silent: the four pulse timers stopped, their channel forced inactive
//!   (OC1M = force inactive) and the pins PA8/PB6/PC6/PB2 switched to GPIO outputs driven
//!   low, so no timer state can drive them;
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
//! A debugger halt freezes the step timer, the pulse timers, the time driver and the
//! watchdog (DBGMCU): the trains stop where they are instead of running on with the last
//! speed, and the board does not reset under the debugger.

use core::mem::MaybeUninit;
use core::ptr::addr_of_mut;
use core::sync::atomic::{AtomicBool, Ordering};

use cortex_m_rt::{ExceptionFrame, exception};
use embassy_stm32::pac;
use embassy_stm32::pac::gpio::vals::Moder;
use embassy_stm32::pac::timer::vals::Ocm;

use crate::pulse::PULSE_PINS;

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

/// Pulse outputs silent and FDCAN off the bus. Register writes only: callable from any
/// fault handler, with any peripheral state (writes to an unclocked peripheral are ignored).
pub fn enter_safe_state() {
    for tim in [pac::TIM1, pac::TIM8, pac::TIM20] {
        tim.cr1().modify(|w| w.set_cen(false));
        tim.ccmr_output(0)
            .modify(|w| w.set_ocm(0, Ocm::FORCE_INACTIVE));
    }
    pac::TIM4.cr1().modify(|w| w.set_cen(false));
    pac::TIM4
        .ccmr_output(0)
        .modify(|w| w.set_ocm(0, Ocm::FORCE_INACTIVE));
    for (port, pin) in PULSE_PINS {
        port.bsrr().write(|w| w.set_br(pin, true));
        port.moder().modify(|w| w.set_moder(pin, Moder::OUTPUT));
    }
    pac::FDCAN1.cccr().modify(|w| w.set_init(true));
    // PA12 = FDCAN1_TX: high first, then output, so the pin never drives dominant.
    pac::GPIOA.bsrr().write(|w| w.set_bs(CAN_TX_PIN, true));
    pac::GPIOA
        .moder()
        .modify(|w| w.set_moder(CAN_TX_PIN, Moder::OUTPUT));
}

/// PA12, FDCAN1_TX (app.rs).
const CAN_TX_PIN: usize = 12;

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

#[exception]
unsafe fn HardFault(ef: &ExceptionFrame) -> ! {
    if begin() {
        // SAFETY: read-only access to the system control block's fault status.
        let cfsr = unsafe { (*cortex_m::peripheral::SCB::PTR).cfsr.read() };
        record(FaultKind::HardFault, ef.pc(), ef.lr(), cfsr);
        defmt::error!(
            "HardFault at pc {=u32:#010x} lr {=u32:#010x} CFSR {=u32:#010x} - safe state, reset",
            ef.pc(),
            ef.lr(),
            cfsr
        );
    }
    wait_then_reset()
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

/// DBGMCU: on a debugger halt, stop the step timer (TIM3), the pulse timers (TIM1, TIM4,
/// TIM8, TIM20), the time driver (TIM2) and the independent watchdog.
pub fn freeze_on_debug_halt() {
    pac::DBGMCU.apb1lfzr().modify(|w| {
        w.set_tim2(true);
        w.set_tim3(true);
        w.set_tim4(true);
        w.set_iwdg(true);
    });
    pac::DBGMCU.apb2fzr().modify(|w| {
        w.set_tim1(true);
        w.set_tim8(true);
        w.set_tim20(true);
    });
}
