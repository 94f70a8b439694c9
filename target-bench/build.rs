//! Writes the linker's memory map for QEMU's `netduinoplus2` (an STM32F405RG): the F405
//! board's numbers (`gms-core/src/boards/f405/memory.rs`), as `board-memory.x` in this
//! build's output directory, which the workspace root's `memory.x` includes (see
//! `firmware/build.rs` for why the root holds no map of its own).
use std::{env, fs, path::PathBuf};

#[path = "../gms-core/src/boards/f405/memory.rs"]
#[allow(dead_code)]
mod f405;

fn main() {
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    let text = format!(
        "/* QEMU netduinoplus2 (STM32F405RG): written by target-bench/build.rs. */\nMEMORY\n{{\n  \
         FLASH : ORIGIN = 0x08000000, LENGTH = {}K\n  RAM : ORIGIN = 0x20000000, LENGTH = {}K\n}}\n",
        f405::APP_LEN / 1024,
        f405::RAM_LEN / 1024
    );
    fs::write(out.join("board-memory.x"), text).expect("write board-memory.x");
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rerun-if-changed=../gms-core/src/boards/f405/memory.rs");
}
