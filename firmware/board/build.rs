//! Link arguments of the board binary only (the workspace also builds other thumbv7em
//! binaries, firmware/qemu and firmware/rig-fixture, with their own maps). `memory.x`
//! (STM32G474RE) is the one at the workspace root, where the linker looks first; `ccm.x`
//! (beside this file) places the step's code in CCM SRAM, which only this binary copies there
//! at reset (`__pre_init`, src/ccm.rs); `stack.x` puts the stack at the bottom of SRAM, below
//! the statics (src/fault.rs: the guard under it).

fn link_board_ccm() {
    let dir = std::env::var("CARGO_MANIFEST_DIR").unwrap();
    println!("cargo:rustc-link-search={dir}");
    println!("cargo:rustc-link-arg-bins=-Tccm.x");
    println!("cargo:rustc-link-arg-bins=-Tstack.x");
    println!("cargo:rerun-if-changed=ccm.x");
    println!("cargo:rerun-if-changed=stack.x");
}

include!("../link-stm32.rs");

fn main() {
    // Before link.x: its PROVIDE(_stext) then yields to ccm.x's _stext.
    link_board_ccm();
    link_stm32();
}
