//! Link arguments of this binary only. It uses the workspace root's `memory.x`
//! (STM32G474RE map: flash 0x0800_0000, RAM 0x2000_0000), which also fits QEMU's
//! netduinoplus2 machine (STM32F405: 1 MiB flash at 0x0800_0000, 128 KiB SRAM).

include!("../link-stm32.rs");

fn main() {
    link_stm32();
}
