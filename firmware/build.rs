//! Writes the linker's memory map for the board being built, `board-memory.x` in this build's
//! output directory, from the board's `gms-core/src/boards/<board>/memory.rs`, and adds defmt's linker
//! script for this binary only (the workspace's other thumb binaries do not use defmt).
//!
//! cortex-m-rt's `link.x` does `INCLUDE memory.x`, and the linker looks in its working
//! directory — cargo runs it in the workspace root — before its search path: a `memory.x`
//! with a `MEMORY` block at the root would be the one every board links with. The root's
//! `memory.x` therefore holds no map, only `INCLUDE board-memory.x`, which each thumb binary's
//! build script writes into its own output directory (this one; `target-bench`'s for QEMU).
//! The build fails if the root file ever holds a `MEMORY` block again. The map defines
//! `__gms_app_end`, `__gms_ram_end` and `__gms_store_start`, which `cargo xtask check-elf`
//! reads back from the linked image against the board's numbers, and asserts at link time that
//! the firmware's flash ends at or before the parameter store.
use std::{env, fs, path::PathBuf};

#[path = "../gms-core/src/boards/f405/memory.rs"]
#[allow(dead_code)]
mod f405;
#[path = "../gms-core/src/boards/nucleo_f446/memory.rs"]
#[allow(dead_code)]
mod nucleo_f446;

/// The `MEMORY` lines of a board: the firmware's flash from 0x08000000, the main SRAM.
fn memory_lines(app_len: u32, ram_len: u32) -> [String; 2] {
    [
        format!("FLASH : ORIGIN = 0x08000000, LENGTH = {}K", app_len / 1024),
        format!("RAM : ORIGIN = 0x20000000, LENGTH = {}K", ram_len / 1024),
    ]
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
    let top = dir.join("../memory.x");
    let root = fs::read_to_string(&top).expect("read the top-level memory.x");
    let code: String = root
        .split("*/")
        .map(|part| part.split("/*").next().unwrap_or(""))
        .collect();
    assert!(
        !code.contains("MEMORY") && code.contains("INCLUDE board-memory.x"),
        "the top-level memory.x must hold no MEMORY block, only `INCLUDE board-memory.x`: a map \
         there would be found before every board's own (see firmware/build.rs)"
    );
    println!("cargo:rerun-if-changed={}", top.display());
    let text = format!(
        "/* Board {name}: written by firmware/build.rs from gms-core/src/boards/{name}/memory.rs. The \
         parameter store\n * (0x{store0:08X}..0x{store1:08X}) lies beyond FLASH. */\nMEMORY\n{{\n  {}\n  {}\n}}\n\
         /* Read back from the image by `cargo xtask check-elf`. */\n\
         __gms_app_end = ORIGIN(FLASH) + LENGTH(FLASH);\n\
         __gms_ram_end = ORIGIN(RAM) + LENGTH(RAM);\n\
         __gms_store_start = 0x{store0:08X};\n\
         ASSERT(__gms_app_end <= __gms_store_start, \"board {name}: the firmware's flash reaches the parameter store\");\n",
        lines[0],
        lines[1],
        store0 = 0x0800_0000 + store.0,
        store1 = 0x0800_0000 + store.1,
    );
    // The control interrupt's code in SRAM; the F405's capture and learning table in its CCM.
    let mut text = text + RAM_CODE;
    if name == "f405" {
        text += F405_CCM;
    }
    fs::write(out.join("board-memory.x"), text).expect("write board-memory.x");
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rerun-if-changed=../gms-core/src/boards/f405/memory.rs");
    println!("cargo:rerun-if-changed=../gms-core/src/boards/nucleo_f446/memory.rs");
    println!("cargo:rustc-link-arg-bins=-Tdefmt.x");
}

/// The control interrupt's code in `.ramcode`, loaded in flash after the vector table and run
/// from SRAM1 remapped at 0 (SYSCFG_MEMRMP.MEM_MODE = 11, RM0090 §9.2.1: SRAM1 at
/// 0x0000_0000, fetched through the I-bus without the flash's wait states), where the firmware
/// copies it at start-up (`board::init`, `f4_regs::remap`). SRAM1 starts at
/// 0x2000_0000, so the code's bytes there are kept out of RAM's use by `.ramcode.room`, the
/// first section in RAM. The functions are picked by their sections' names (`.text.NAME`,
/// one per function): the control interrupt (all it inlines) and the out-of-line gms-core
/// functions it calls, as `rehost check --profile` lists them (not compiler-builtins' `memcpy`
/// and kin, which the start-up calls before the remap: there, on the chip, address 0 is still
/// the flash); gms-core stays free of
/// link-section attributes (its `forbid(unsafe_code)`). `.text` of cortex-m-rt's `link.x`
/// takes every `.text.*` it meets first, so `.ramcode` comes before it, and `_stext` (where
/// `.text` starts) after `.ramcode`'s load image.
const RAM_CODE: &str = "
MEMORY
{
  RAMCODE : ORIGIN = 0x00000000, LENGTH = 112K
}
SECTIONS
{
  .ramcode : ALIGN(8)
  {
    __sramcode = .;
    *(.text.DMA2_STREAM0 .text.DMA2_STREAM0.*)
    *(.text._ZN8gms_core4math14stribeck_decay*)
    *(.text.*ControlLoop14reference_side*)
    *(.text.*ControlLoop12table_sample*)
    *(.text.*ControlLoop12table_record*)
    *(.text.*ControlLoop4take17h*)
    *(.text.*ControlLoop10take_table*)
    *(.text.*ControlLoop8stop_frf*)
    *(.text.*MapCursor6sample*)
    *(.text.*Gms*FrictionModel*7advance*)
    *(.text.*Gms*15take_state_from*)
    *(.text.*Shaping15take_state_from*)
    *(.text.*Player4take17h*)
    *(.text.*Player11report_into*)
    *(.text.*VelocityProfile4next*)
    *(.text.*ControlLoop9hold_here*)
    . = ALIGN(8);
    __eramcode = .;
  } > RAMCODE AT > FLASH
  __siramcode = LOADADDR(.ramcode);
  _stext = ALIGN(LOADADDR(.ramcode) + SIZEOF(.ramcode), 16);
}
INSERT AFTER .vector_table;
SECTIONS
{
  .ramcode.room (NOLOAD) : ALIGN(8)
  {
    . = . + SIZEOF(.ramcode);
  } > RAM
}
INSERT BEFORE .data;
ASSERT(ADDR(.ramcode.room) == ORIGIN(RAM), \".ramcode.room must be RAM's first section (SRAM1's start holds the code)\");
";

/// The F405's 64 KiB of core-coupled memory (RM0090 §2.3.1: on the D-bus only, so neither
/// code nor DMA; 0x1000_0000): the statics placed in `.ccm` (the capture buffer and the
/// learning table, which only the core reads and writes), not loaded, zeroed at start-up
/// before they are taken (`board::init`); the SRAM they leave holds the code run from it.
/// After `.got`, the last section of cortex-m-rt's `link.x`: after `.bss` it moved `__ebss`
/// (assigned after that section) into the CCM, and the start-up zeroed on into unmapped
/// memory.
const F405_CCM: &str = "
MEMORY
{
  CCM : ORIGIN = 0x10000000, LENGTH = 64K
}
SECTIONS
{
  .ccm (NOLOAD) : ALIGN(4)
  {
    __sccm = .;
    *(.ccm .ccm.*);
    . = ALIGN(4);
    __eccm = .;
  } > CCM
}
INSERT AFTER .got;
";
