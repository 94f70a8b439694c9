//! `cargo xtask check-elf --board NAME ELF`: static checks of a linked firmware image against
//! its board's own numbers (`gms-core/src/boards/<board>/memory.rs`), read from the ELF, not
//! from the linker script that made it:
//!
//! - the memory map it was linked with is the board's (`__gms_app_end`, `__gms_ram_end`,
//!   `__gms_store_start`, which `firmware/build.rs` writes into the board's map), so no other
//!   `memory.x` can have masked it;
//! - every loadable segment in flash ends at or before the parameter store, every one in RAM
//!   within the board's RAM;
//! - the vector table's entries for the interrupts the firmware uses point at their handlers
//!   (the symbol of the interrupt's name), not at `DefaultHandler`.

use object::read::elf::ProgramHeader;
use object::{Object, ObjectSection, ObjectSymbol};

/// A board as the check sees it.
pub struct BoardMap {
    /// `--board` name.
    pub name: &'static str,
    /// The firmware's flash from 0x08000000 \[bytes\].
    pub app_len: u32,
    /// Main SRAM from 0x20000000 \[bytes\].
    pub ram_len: u32,
    /// The parameter store's first byte, from the flash start \[bytes\].
    pub store_start: u32,
    /// The interrupts the firmware handles on this board: (name, position in the vector table
    /// after the 16 system exceptions; stm32-metapac 21's `Interrupt` for the part, RM0090
    /// table 61, RM0390 table 38).
    pub irqs: &'static [(&'static str, u32)],
}

const FLASH: u64 = 0x0800_0000;
const RAM: u64 = 0x2000_0000;

/// Runs the checks; one line per check on stdout, `Err` with every failure.
pub fn check(board: &BoardMap, bytes: &[u8]) -> Result<Vec<String>, String> {
    let file = object::File::parse(bytes).map_err(|e| format!("not an ELF file: {e}"))?;
    let sym = |name: &str| -> Option<u64> {
        file.symbols()
            .find(|s| s.name() == Ok(name))
            .map(|s| s.address())
    };
    let mut ok = Vec::new();
    let mut bad = Vec::new();
    // The map.
    for (name, want) in [
        ("__gms_app_end", FLASH + board.app_len as u64),
        ("__gms_ram_end", RAM + board.ram_len as u64),
        ("__gms_store_start", FLASH + board.store_start as u64),
    ] {
        match sym(name) {
            Some(v) if v == want => ok.push(format!("{name} = {v:#010x}: the board's")),
            Some(v) => bad.push(format!(
                "{name} = {v:#010x}, the board {} says {want:#010x}: linked with another map",
                board.name
            )),
            None => bad.push(format!(
                "no {name}: not linked with a map written by firmware/build.rs"
            )),
        }
    }
    // The loadable segments: what goes into flash (at its load address, .data's initial
    // values included) and what occupies RAM (at its run address).
    let elf = object::read::elf::ElfFile32::<object::LittleEndian>::parse(bytes)
        .map_err(|e| format!("not a 32-bit little-endian ELF: {e}"))?;
    let e = elf.endian();
    let app_end = FLASH + board.app_len as u64;
    let ram_end = RAM + board.ram_len as u64;
    let (mut flash_top, mut ram_top) = (FLASH, RAM);
    for ph in elf.elf_program_headers() {
        if ph.p_type(e) != object::elf::PT_LOAD {
            continue;
        }
        let (paddr, filesz) = (ph.p_paddr(e) as u64, ph.p_filesz(e) as u64);
        let (vaddr, memsz) = (ph.p_vaddr(e) as u64, ph.p_memsz(e) as u64);
        if filesz > 0 && (FLASH..FLASH + 0x0100_0000).contains(&paddr) {
            flash_top = flash_top.max(paddr + filesz);
        }
        if memsz > 0 && (RAM..RAM + 0x0100_0000).contains(&vaddr) {
            ram_top = ram_top.max(vaddr + memsz);
        }
    }
    if flash_top <= app_end {
        ok.push(format!(
            "flash image ends at {flash_top:#010x}, at or before the store at {app_end:#010x} \
             ({} KiB free)",
            (app_end - flash_top) / 1024
        ));
    } else {
        bad.push(format!(
            "flash image ends at {flash_top:#010x}, past the store at {app_end:#010x}"
        ));
    }
    if ram_top <= ram_end {
        ok.push(format!(
            "RAM used up to {ram_top:#010x} (ends {ram_end:#010x})"
        ));
    } else {
        bad.push(format!(
            "RAM used up to {ram_top:#010x}, past {ram_end:#010x}"
        ));
    }
    // The vector table.
    let table = file
        .section_by_name(".vector_table")
        .ok_or("no .vector_table section")?;
    let data = table
        .data()
        .map_err(|e| format!(".vector_table unreadable: {e}"))?;
    let default = sym("DefaultHandler").ok_or("no DefaultHandler symbol")? & !1;
    // The core's fault handlers (the stack guard's, `f4_regs::mpu`) at their vector positions
    // (ARMv7-M ARM B1.5.3: HardFault 3, MemManage 4), then the interrupts after the 16 system
    // exceptions.
    let vectors = [("HardFault", 3usize), ("MemoryManagement", 4)]
        .into_iter()
        .map(|(name, i)| (name, i, format!("exception {i}")))
        .chain(
            board
                .irqs
                .iter()
                .map(|&(irq, n)| (irq, 16 + n as usize, format!("irq {n}"))),
        );
    for (irq, index, n) in vectors {
        let at = index * 4;
        let Some(word) = data.get(at..at + 4) else {
            bad.push(format!("vector {irq} ({n}) beyond the table"));
            continue;
        };
        let entry = u32::from_le_bytes([word[0], word[1], word[2], word[3]]) as u64 & !1;
        let handler = sym(irq).map(|a| a & !1);
        if entry == default {
            bad.push(format!("vector {irq} ({n}) is DefaultHandler"));
        } else if handler != Some(entry) {
            bad.push(format!(
                "vector {irq} ({n}) at {entry:#010x}, not its handler {handler:x?}"
            ));
        } else {
            ok.push(format!("vector {irq} ({n}) -> {irq} at {entry:#010x}"));
        }
    }
    if bad.is_empty() {
        Ok(ok)
    } else {
        Err(bad.join("\n"))
    }
}
