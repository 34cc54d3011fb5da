// The link arguments of the STM32 binaries (`firmware/board`, `firmware/rig-fixture`),
// included by their build scripts (`link_stm32()`): cortex-m-rt's `link.x` with the workspace root's
// `memory.x` (STM32G474RE; the linker looks there first) and defmt's table, for their
// binaries only (the emulator binary, firmware/qemu, has its own memory map).

fn link_stm32() {
    println!("cargo:rustc-link-arg-bins=--nmagic");
    println!("cargo:rustc-link-arg-bins=-Tlink.x");
    println!("cargo:rustc-link-arg-bins=-Tdefmt.x");
    println!("cargo:rerun-if-changed=../../memory.x");
    println!("cargo:rerun-if-changed=../link-stm32.rs");
    println!("cargo:rerun-if-changed=build.rs");
}
