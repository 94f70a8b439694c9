//! The F405 board's memory map and probe, plain numbers (read by `build.rs` to write the
//! linker's `memory.x`, by the firmware and by the host tests).

/// probe-rs's name of the chip.
pub const PROBE_RS_CHIP: &str = "STM32F405RGTx";
/// Flash (bytes): 1 MiB.
pub const FLASH_LEN: u32 = 1024 * 1024;
/// The firmware's flash from the start (bytes): sectors 0-9.
pub const APP_LEN: u32 = 768 * 1024;
/// Main SRAM (bytes) (SRAM1 + SRAM2; the 64 KiB CCM is not used).
pub const RAM_LEN: u32 = 128 * 1024;
/// The parameter store: the last two 128 KiB sectors, 10 and 11 (RM0090 table 5), as offsets
/// from the flash start (bytes).
pub const STORE_START: u32 = 0x000C_0000;
/// End of the store (bytes).
pub const STORE_END: u32 = 0x0010_0000;
/// The store's sector size (bytes).
pub const STORE_SECTOR: u32 = 128 * 1024;
