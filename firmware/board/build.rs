//! Link arguments of the board binary only (the workspace also builds another thumbv7em
//! binary, firmware/qemu, with its own memory map). `memory.x` (STM32G474RE) is the one at
//! the workspace root, where the linker looks first.

include!("../link-stm32.rs");
