//! Link arguments of the board binary only (the workspace also builds another thumbv7em
//! binary, firmware/qemu, with its own memory map). `memory.x` (STM32G474RE) is the one at
//! the workspace root, where the linker looks first.

fn main() {
    println!("cargo:rustc-link-arg-bins=--nmagic");
    println!("cargo:rustc-link-arg-bins=-Tlink.x");
    println!("cargo:rustc-link-arg-bins=-Tdefmt.x");
    println!("cargo:rerun-if-changed=../../memory.x");
    println!("cargo:rerun-if-changed=build.rs");
}
