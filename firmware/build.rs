//! Puts the repository's root `memory.x` (the STM32F407VG's memory map;
//! under the `qemu` feature, with QEMU's 192 KB of SRAM) on the linker's
//! search path, where cortex-m-rt's `link.x` looks for it, and
//! adds `ccmram.x` (the `.ccmram` section in the core-coupled memory) to the
//! firmware's link.

use std::path::PathBuf;
use std::{env, fs};

fn main() {
    let manifest = PathBuf::from(env::var_os("CARGO_MANIFEST_DIR").expect("set by cargo"));
    let memory = manifest.join("..").join("memory.x");
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("set by cargo"));
    let map = fs::read_to_string(&memory).unwrap_or_else(|e| panic!("reading {}: {e}", memory.display()));
    // QEMU's netduinoplus2 maps the STM32F405's 192 KB of SRAM contiguously
    // at 0x2000_0000 and has no CCM: the `qemu` build puts the CCM's
    // buffers in that extra SRAM (src/mem.rs).
    let map = if env::var_os("CARGO_FEATURE_QEMU").is_some() {
        let board = "RAM   : ORIGIN = 0x20000000, LENGTH = 128K";
        assert!(map.contains(board), "memory.x has no line `{board}`");
        map.replace(board, "RAM   : ORIGIN = 0x20000000, LENGTH = 192K")
    } else {
        map
    };
    fs::write(out.join("memory.x"), map).unwrap_or_else(|e| panic!("writing memory.x: {e}"));
    let ccm = manifest.join("ccmram.x");
    fs::copy(&ccm, out.join("ccmram.x")).unwrap_or_else(|e| panic!("copying {}: {e}", ccm.display()));
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rustc-link-arg-bins=-Tccmram.x");
    println!("cargo:rerun-if-changed={}", memory.display());
    println!("cargo:rerun-if-changed={}", ccm.display());
    println!("cargo:rerun-if-changed=build.rs");
}
