//! Puts the repository's `memory.x` (STM32F405 memory map) on the linker search path,
//! where cortex-m-rt's `link.x` includes it, and derives the build's two switches from its
//! features (docs/firmware.md, "Features"):
//! * `emulated`: feature `qemu` without `board`: HSI clocks, semihosting console and run
//!   modes;
//! * `semihosting_log`: feature `log-semihosting` without `log-rtt`: the defmt logger of
//!   `src/log.rs`.
use std::{env, fs, path::PathBuf};

fn feature(name: &str) -> bool {
    env::var_os(format!("CARGO_FEATURE_{name}")).is_some()
}

fn main() {
    let out = PathBuf::from(env::var_os("OUT_DIR").unwrap());
    let manifest = PathBuf::from(env::var_os("CARGO_MANIFEST_DIR").unwrap());
    let memory = manifest.join("..").join("memory.x");
    fs::copy(&memory, out.join("memory.x")).expect("copy memory.x");
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rerun-if-changed={}", memory.display());
    println!("cargo:rerun-if-changed=build.rs");

    println!("cargo::rustc-check-cfg=cfg(emulated)");
    println!("cargo::rustc-check-cfg=cfg(semihosting_log)");
    if feature("QEMU") && !feature("BOARD") {
        println!("cargo:rustc-cfg=emulated");
    }
    if feature("LOG_SEMIHOSTING") && !feature("LOG_RTT") {
        println!("cargo:rustc-cfg=semihosting_log");
    }
}
