//! The NUCLEO-F446RE board's memory map and probe, plain numbers (read by `build.rs` to write
//! the linker's `memory.x`, by the firmware and by the host tests).

/// probe-rs's name of the chip.
pub const PROBE_RS_CHIP: &str = "STM32F446RETx";
/// Flash (bytes): 512 KiB.
pub const FLASH_LEN: u32 = 512 * 1024;
/// The firmware's flash from the start (bytes): sectors 0-5 (4 × 16 + 64 + 128 KiB).
pub const APP_LEN: u32 = 256 * 1024;
/// Main SRAM (bytes) (SRAM1 + SRAM2).
pub const RAM_LEN: u32 = 128 * 1024;
/// The parameter store: the last two 128 KiB sectors, 6 and 7 (RM0390 table 4), as offsets
/// from the flash start (bytes).
pub const STORE_START: u32 = 0x0004_0000;
/// End of the store (bytes).
pub const STORE_END: u32 = 0x0008_0000;
/// The store's sector size (bytes).
pub const STORE_SECTOR: u32 = 128 * 1024;
