//! Puts the repository's root `memory.x` (the STM32F407VG's memory map) on
//! the linker's search path, where cortex-m-rt's `link.x` looks for it, and
//! adds `ccmram.x` (the `.ccmram` section in the core-coupled memory) to the
//! firmware's link.

use std::path::PathBuf;
use std::{env, fs};

fn main() {
    let manifest = PathBuf::from(env::var_os("CARGO_MANIFEST_DIR").expect("set by cargo"));
    let memory = manifest.join("..").join("memory.x");
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("set by cargo"));
    fs::copy(&memory, out.join("memory.x")).unwrap_or_else(|e| panic!("copying {}: {e}", memory.display()));
    let ccm = manifest.join("ccmram.x");
    fs::copy(&ccm, out.join("ccmram.x")).unwrap_or_else(|e| panic!("copying {}: {e}", ccm.display()));
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rustc-link-arg-bins=-Tccmram.x");
    println!("cargo:rerun-if-changed={}", memory.display());
    println!("cargo:rerun-if-changed={}", ccm.display());
    println!("cargo:rerun-if-changed=build.rs");
}
