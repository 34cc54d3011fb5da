//! The telemetry fixture of `hils decode`: runs `hils_rig_core::script` (the self-test
//! paper scenario, 6 s) and logs its telemetry with the board's own code path
//! (`TelemetryEvent::log`, defmt) to semihosting stdout. Run in QEMU:
//!
//! ```text
//! cargo rig-fixture
//! qemu-system-arm -M netduinoplus2 -nographic -monitor none -serial none \
//!   -semihosting-config enable=on,target=native \
//!   -kernel target/thumbv7em-none-eabihf/firmware/rig-fixture > telemetry.defmt
//! ```
//!
//! stdout then holds the raw defmt stream; with this ELF's table, `hils decode` turns it
//! into a run log. `firmware/rig-fixture/make-fixture.sh` does all this.
#![no_std]
#![no_main]
// A binary: `missing_docs` (denied by the workspace) is for the no_std library crates.
#![allow(missing_docs)]

use cortex_m_rt::entry;
use cortex_m_semihosting::debug;
use defmt_semihosting as _;

#[panic_handler]
fn panic(_: &core::panic::PanicInfo) -> ! {
    debug::exit(debug::EXIT_FAILURE);
    loop {}
}

#[entry]
fn main() -> ! {
    let frames = hils_rig_core::script::run(|event| event.log());
    defmt::println!("fixture done: {=u32} CAN frames queued", frames);
    debug::exit(debug::EXIT_SUCCESS);
    loop {}
}
