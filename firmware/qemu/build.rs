//! Links the emulator binary with the MPS2-AN386 memory map.
//!
//! The usual cortex-m-rt set-up (`-Tlink.x`, which does `INCLUDE memory.x`) cannot work in
//! this workspace: the linker resolves `INCLUDE memory.x` in its current directory first,
//! which is the workspace root, where the board's STM32G474RE `memory.x` lives (flash at
//! 0x0800_0000, unmapped on mps2-an386). So the binary gets its own complete script,
//! `mps2-an386.x` (cortex-m-rt's link.x with the memory map inlined), passed by absolute
//! path and only to this package's binaries: nothing global, the board build is untouched.

use std::env;
use std::path::PathBuf;

fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rerun-if-changed=mps2-an386.x");
    // The optimisation level this image is built at, for its `H` line (`hils target-cost`
    // checks it against the board image's, Cargo.toml).
    let opt_level = env::var("OPT_LEVEL").unwrap_or_default();
    println!("cargo:rustc-env=HILS_QEMU_OPT_LEVEL={opt_level}");
    let target = env::var("TARGET").unwrap_or_default();
    if !(target.starts_with("thumbv7em-") && target.ends_with("-eabihf")) {
        // Host build: the binary is a stub, nothing to link specially.
        return;
    }
    let manifest_dir = PathBuf::from(env::var_os("CARGO_MANIFEST_DIR").expect("cargo sets it"));
    let script = manifest_dir.join("mps2-an386.x");
    println!("cargo:rustc-link-arg-bins=-T{}", script.display());
}
