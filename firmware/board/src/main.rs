//! Rig interface board firmware (NUCLEO-G474RE, STM32G474RE at 170 MHz from the 24 MHz
//! crystal).
//!
//! A thin HAL shell over `hils-rig-core`: all logic (frame codec, sensor scaling and
//! plausibility, pulse timing, telemetry, commands, the run state machine and the safe
//! state, CAN bit timing, transmit freshness, the handoff protocol, the bring-up rules)
//! lives there and is tested on the host. The shell, one concern a module:
//!
//! * [`clock`]: HSE 24 MHz -> PLL -> 170 MHz, boost, flash accelerator, clock security.
//! * [`ceiling`]: interrupt priorities; the step's queues locked by BASEPRI, not PRIMASK.
//! * [`ccm`]: the step's code copied to CCM SRAM at reset, then write-protected.
//! * [`step`]: TIM3's 10 kHz update interrupt running `Rig::step`, the watchdog feed.
//! * [`can_io`]: FDCAN1 timing, FIFO transmit with stale frames dropped, filter, bus state.
//! * [`telemetry`]: defmt-rtt logging with dropped records counted.
//! * [`pulse`]: the four pulse-train timers (break on lockup) and the output enable.
//! * [`fault`]: panic / HardFault / NMI -> safe state -> reset; the safe pins at every
//!   start, fault resets in a row (hold after three), the stack guard; debugger-halt freeze.
//! * [`app`]: the rig application (also run by the bring-up image for its step check);
//!   `bringup` (feature): the first-flash self-test.
#![no_std]
#![no_main]
// A binary: `missing_docs` (denied by the workspace) is for the no_std library crates.
#![allow(missing_docs)]

mod app;
mod can_io;
mod ccm;
mod ceiling;
mod clock;
mod fault;
mod handoff;
mod pulse;
mod shared;
mod sim_store;
mod step;
mod telemetry;

#[cfg(feature = "bringup")]
mod bringup;

use defmt::{error, info, warn};
use defmt_rtt as _;
use embassy_executor::Spawner;
use embassy_stm32::{bind_interrupts, can, dma, peripherals};
use hils_rig_core::reset_loop::Boot;

bind_interrupts!(pub struct Irqs {
    // Called in this order: ours first (it must see IR.BO before embassy's handler
    // acknowledges it), the RX FIFO 0 drain last (after embassy's handler clears RF0N).
    FDCAN1_IT0 => can_io::It0, can::IT0InterruptHandler<peripherals::FDCAN1>, can_io::It0Drain;
    FDCAN1_IT1 => can::IT1InterruptHandler<peripherals::FDCAN1>;
    DMA1_CHANNEL1 => dma::InterruptHandler<peripherals::DMA1_CH1>;
});

#[embassy_executor::main]
async fn main(spawner: Spawner) {
    // The safe pins again (`__pre_init` drove them first, ccm.rs), before the crystal's
    // start (up to 100 ms); the stack guarded before anything deep runs.
    fault::safe_pins_at_start();
    fault::guard_stack();
    let reset = clock::take_reset_cause();
    let last_fault = fault::take_last_fault();
    if let Some(f) = last_fault {
        warn!("the previous run ended in a fault: {}", f);
    }
    if !embassy_stm32::pac::FLASH.optr().read().dbank() {
        warn!(
            "FLASH_OPTR.DBANK = 0 (single bank): the image is built for the factory dual-bank layout (embassy-stm32 feature dual-bank)"
        );
    }
    let boot = fault::note_boot(reset.for_reset_loop(last_fault.is_some()));
    if let Boot::Hold { fault_resets } = boot {
        fault::hold(fault_resets);
    }
    if clock::start_hse().is_err() {
        // Only the safe pins are configured (pulses low, output enable off, PA12 high =
        // CAN recessive). Stay so.
        error!(
            "HSE 24 MHz did not start within 100 ms: crystal X3 missing or its solder bridges open (UM2505, HSE); the board stays in reset state"
        );
        loop {
            cortex_m::asm::wfi();
        }
    }
    let p = embassy_stm32::init(clock::config());
    ceiling::set_interrupt_priorities();
    clock::enable_flash_accelerator();
    clock::enable_css();
    ccm::write_protect();
    fault::break_on_lockup();
    fault::freeze_on_debug_halt();

    let (ccm_at, ccm_len) = ccm::code_span();
    info!(
        "rig interface board: STM32G474RE at {=u32} Hz from HSE {=u32} Hz; reset: {} ({=u32} fault resets in a row); step code {=u32} B in CCM SRAM at {=u32:#x}",
        clock::SYSCLK_HZ,
        clock::HSE_HZ,
        reset,
        boot.fault_resets(),
        ccm_len,
        ccm_at
    );
    // The step must not run code that differs from what was linked (a failed copy).
    defmt::assert!(
        ccm::matches_load_image(),
        "CCM step code differs from its flash image at {=u32:#x}",
        ccm::load_address()
    );

    // DWT cycle counter for step timing.
    let mut cp = defmt::unwrap!(cortex_m::Peripherals::take());
    cp.DCB.enable_trace();
    cp.DWT.enable_cycle_counter();

    #[cfg(feature = "bringup")]
    bringup::run(spawner, p).await;
    #[cfg(not(feature = "bringup"))]
    app::run(spawner, p, app::Image::Rig).await;
}
