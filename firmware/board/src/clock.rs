//! The clock tree: HSE 24 MHz (NUCLEO-G474RE crystal X3) -> PLL -> 170 MHz, range 1 boost,
//! 4 flash wait states, prefetch and caches on; the FDCAN kernel clock straight from HSE.
//!
//! * PLL: 24 MHz / M 6 = 4 MHz (PLL input 2.66..16 MHz), x N 85 = 340 MHz VCO
//!   (96..344 MHz), / R 2 = 170 MHz (embassy-stm32 0.6 rcc/g4.rs `max` ranges, from the
//!   STM32G474 datasheet). ST's own NUCLEO-G474RE clock setup (stm32duino variant, PR 2186
//!   by ST) uses the same HSE / 6 x 85 / 2.
//! * Boost (PWR_CR5.R1MODE = 0) is needed above 150 MHz. RM0440 (range 1 normal -> boost):
//!   AHB / 2 before switching to the higher frequency, R1MODE = 0, wait states, switch to
//!   the new clock, wait >= 1 us, then AHB / 1. embassy-stm32 0.6 `rcc/g4.rs` sets AHB / 2,
//!   R1MODE and the 4 wait states (HCLK <= 170 MHz in boost: RM0440 flash latency table; ST
//!   LL utils agree), waits 16 cycles, and then writes SW = PLL and HPRE = /1 in one
//!   write: the core goes from HSI16 straight to 170 MHz HCLK, without the 1 us at 85 MHz
//!   that the sequence puts in to soften the load step on the regulator. Not patched:
//!   embassy's recorded clock frequencies (time driver, timers, FDCAN, ADC) come from the
//!   same configuration, so a switch at AHB / 2 with our own HPRE write afterwards would
//!   leave them wrong. Documented in docs/rig.md ("Clocks"); the bring-up self-test reads
//!   the clock tree back.
//! * FDCAN kernel clock = HSE, not PCLK1: 24 MHz is 8 x 3 MHz, so every standard rate from
//!   125 kbit/s to 1 Mbit/s is a whole number of quanta that is a multiple of 8 with
//!   prescaler 1 (192/96/48/24 quanta: 87.5 % exactly), and the CAN timing does not depend
//!   on the PLL settings. ST's rule fdcan_tq_ck <= fdcan_pclk holds (24 <= 170 MHz).
//! * Timers (PCLK1/2 = 170 MHz, APB prescaler 1) and the ADC (SYSCLK / 4) also follow the
//!   crystal: the 10 kHz step and every pulse frequency are as exact as X3.

use embassy_stm32::pac;
use embassy_stm32::time::Hertz;

/// Crystal X3, Hz.
pub const HSE_HZ: u32 = hils_rig_core::bringup::HSE_HZ;
/// SYSCLK = HCLK = PCLK1 = PCLK2 = timer clocks, Hz.
pub const SYSCLK_HZ: u32 = hils_rig_core::bringup::SYSCLK_HZ;

/// How long the crystal may take to start (datasheet: ~2 ms typ.), ms.
const HSE_START_TIMEOUT_MS: u32 = 100;
/// Core cycles per ms before the PLL runs (HSI16 after reset).
const RESET_CYCLES_PER_MS: u32 = 16_000;

/// embassy's configuration for this clock tree.
pub fn config() -> embassy_stm32::Config {
    use embassy_stm32::rcc::*;
    let mut config = embassy_stm32::Config::default();
    config.rcc.hsi = false;
    config.rcc.hsi48 = None;
    config.rcc.hse = Some(Hse {
        freq: Hertz(HSE_HZ),
        mode: HseMode::Oscillator,
    });
    config.rcc.pll = Some(Pll {
        source: PllSource::HSE,
        prediv: PllPreDiv::DIV6,
        mul: PllMul::MUL85,
        divp: None,
        divq: None,
        divr: Some(PllRDiv::DIV2),
    });
    config.rcc.sys = Sysclk::PLL1_R;
    config.rcc.boost = true;
    config.rcc.mux.fdcansel = mux::Fdcansel::HSE;
    config.rcc.mux.adc12sel = mux::Adcsel::SYS;
    // embassy enables every DMA channel interrupt at this priority (default P0, above the
    // step): below the step instead.
    config.bdma_interrupt_priority = crate::ceiling::BACKGROUND_PRIORITY;
    config
}

/// Starts the crystal before embassy's init, which waits for HSERDY without a limit (rcc/g4.rs):
/// a board without X3 (or with its solder bridges open) would hang silently. `Err` if
/// HSERDY does not come within 100 ms.
pub fn start_hse() -> Result<(), ()> {
    pac::RCC.cr().modify(|w| {
        w.set_hsebyp(false);
        w.set_hseon(true);
    });
    for _ in 0..HSE_START_TIMEOUT_MS {
        if pac::RCC.cr().read().hserdy() {
            return Ok(());
        }
        cortex_m::asm::delay(RESET_CYCLES_PER_MS);
    }
    pac::RCC.cr().read().hserdy().then_some(()).ok_or(())
}

/// Prefetch and both ART caches on (FLASH_ACR PRFTEN, ICEN, DCEN) for the code that stays
/// in flash; embassy sets only the latency.
pub fn enable_flash_accelerator() {
    pac::FLASH.acr().modify(|w| {
        w.set_prften(true);
        w.set_icen(true);
        w.set_dcen(true);
    });
}

/// Clock security system on HSE (RCC_CR.CSSON): if the crystal stops, the hardware
/// switches SYSCLK to HSI16 and raises an NMI, which puts the board in its safe state
/// (`fault.rs`): the CAN timing and the pulse frequencies would be wrong from then on.
pub fn enable_css() {
    pac::RCC.cr().modify(|w| w.set_csson(true));
}

/// Why the last reset happened (RCC_CSR flags), then clears them (RMVF).
#[derive(Clone, Copy, Debug, defmt::Format)]
pub enum ResetCause {
    PowerOnOrBrownOut,
    Pin,
    Software,
    IndependentWatchdog,
    WindowWatchdog,
    LowPower,
    OptionByteLoad,
    Unknown,
}

impl ResetCause {
    /// The cause as the count of fault resets in a row sees it (`hils_rig_core::reset_loop`):
    /// a software reset is a fault handler's when it recorded a fault, else a debugger's.
    pub fn for_reset_loop(self, fault_recorded: bool) -> hils_rig_core::reset_loop::ResetCause {
        use hils_rig_core::reset_loop::ResetCause as Loop;
        match self {
            ResetCause::IndependentWatchdog | ResetCause::WindowWatchdog => Loop::Watchdog,
            ResetCause::Software if fault_recorded => Loop::FaultHandler,
            ResetCause::Software | ResetCause::Unknown => Loop::Debugger,
            ResetCause::Pin => Loop::Pin,
            ResetCause::PowerOnOrBrownOut | ResetCause::LowPower | ResetCause::OptionByteLoad => {
                Loop::PowerOn
            }
        }
    }
}

pub fn take_reset_cause() -> ResetCause {
    let csr = pac::RCC.csr().read();
    // In priority order: a watchdog or software reset also pulls the reset pin.
    let flags = [
        (csr.iwdgrstf(), ResetCause::IndependentWatchdog),
        (csr.wwdgrstf(), ResetCause::WindowWatchdog),
        (csr.sftrstf(), ResetCause::Software),
        (csr.borrstf(), ResetCause::PowerOnOrBrownOut),
        (csr.lpwrrstf(), ResetCause::LowPower),
        (csr.oblrstf(), ResetCause::OptionByteLoad),
        (csr.pinrstf(), ResetCause::Pin),
    ];
    let cause = flags
        .into_iter()
        .find_map(|(set, cause)| set.then_some(cause))
        .unwrap_or(ResetCause::Unknown);
    pac::RCC.csr().modify(|w| w.set_rmvf(true));
    cause
}
