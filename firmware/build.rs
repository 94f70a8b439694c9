//! Puts the root `memory.x` where the linker finds it (cortex-m-rt's `link.x` includes it) and
//! adds defmt's linker script for this binary only (the workspace's other thumb binaries do
//! not use defmt).
use std::{env, fs, path::PathBuf};

fn main() {
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    let memory = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../memory.x");
    fs::copy(&memory, out.join("memory.x")).expect("copy memory.x");
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rerun-if-changed={}", memory.display());
    println!("cargo:rustc-link-arg-bins=-Tdefmt.x");
}
