//! Writes the linker's `memory.x` for the board being built (cortex-m-rt's `link.x` includes
//! it) from the board's `src/boards/<board>/memory.rs`, and adds defmt's linker script for this
//! binary only (the workspace's other thumb binaries do not use defmt). The workspace's
//! top-level `memory.x` is the default board's (the F405): it must say the same, and the build
//! fails if it does not.
use std::{env, fs, path::PathBuf};

#[path = "src/boards/f405/memory.rs"]
#[allow(dead_code)]
mod f405;
#[path = "src/boards/nucleo_f446/memory.rs"]
#[allow(dead_code)]
mod nucleo_f446;

/// The `MEMORY` lines of a board: the firmware's flash from 0x08000000, the main SRAM.
fn memory_lines(app_len: u32, ram_len: u32) -> [String; 2] {
    [
        format!("FLASH : ORIGIN = 0x08000000, LENGTH = {}K", app_len / 1024),
        format!("RAM : ORIGIN = 0x20000000, LENGTH = {}K", ram_len / 1024),
    ]
}

fn squash(line: &str) -> String {
    line.split_whitespace().collect::<Vec<_>>().join(" ")
}

fn main() {
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let f446 = env::var_os("CARGO_FEATURE_BOARD_NUCLEO_F446").is_some();
    // With no board or two, the crate's own compile_error! says so; write the default here.
    let (name, app, ram, store) = if f446 && env::var_os("CARGO_FEATURE_BOARD_F405").is_none() {
        (
            "nucleo_f446",
            nucleo_f446::APP_LEN,
            nucleo_f446::RAM_LEN,
            (nucleo_f446::STORE_START, nucleo_f446::STORE_END),
        )
    } else {
        (
            "f405",
            f405::APP_LEN,
            f405::RAM_LEN,
            (f405::STORE_START, f405::STORE_END),
        )
    };
    let lines = memory_lines(app, ram);
    if name == "f405" {
        let top = dir.join("../memory.x");
        let text = fs::read_to_string(&top).expect("read the top-level memory.x");
        let have: Vec<String> = text.lines().map(squash).collect();
        for l in &lines {
            assert!(
                have.iter().any(|h| h == l),
                "memory.x (top level) does not say `{l}` as src/boards/f405/memory.rs does"
            );
        }
        println!("cargo:rerun-if-changed={}", top.display());
    }
    let text = format!(
        "/* Board {name}: written by firmware/build.rs from src/boards/{name}/memory.rs. The \
         parameter store\n * (0x{:08X}..0x{:08X}) lies beyond FLASH. */\nMEMORY\n{{\n  {}\n  {}\n}}\n",
        0x0800_0000 + store.0,
        0x0800_0000 + store.1,
        lines[0],
        lines[1]
    );
    fs::write(out.join("memory.x"), text).expect("write memory.x");
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rerun-if-changed=src/boards/f405/memory.rs");
    println!("cargo:rerun-if-changed=src/boards/nucleo_f446/memory.rs");
    println!("cargo:rustc-link-arg-bins=-Tdefmt.x");
}
