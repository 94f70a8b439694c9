//! NUCLEO-F446RE carrying the same power stage on the same pins (`power_stage.rs`: PC6/PC7,
//! PC0, PA0/PA1 are on its morpho headers, PA11/PA12 to a USB breakout), flashed through its
//! on-board ST-LINK. Plain numbers, checked on the host.

use crate::boards::hw::{F4Clocks, F4Limits, F446_LIMITS, MemoryMap};
use crate::device::Board;
use crate::drive::SenseTiming;

use super::power_stage;

pub mod memory;

/// The board's name (its cargo feature is `board-nucleo-f446`).
pub const NAME: &str = "nucleo-f446";

/// Clocks: the ST-LINK's 8 MHz MCO into OSC_IN as HSE in bypass (the board's default solder
/// bridges; there is no crystal on X3), PLL to 168 MHz like the F405 board — below the
/// F446's 180 MHz, where the PLL could not also give USB its 48 MHz — so that every timing
/// is the same.
pub const CLOCKS: F4Clocks = F4Clocks {
    hse_hz: 8_000_000,
    hse_bypass: true,
    pll_m: 4,
    pll_n: 168,
    pll_p: 2,
    pll_q: 7,
    ahb_div: 1,
    apb1_div: 4,
    apb2_div: 2,
};

/// What to check when the HSE does not start (the first log lines say it).
pub const HSE_HINT: &str = "the ST-LINK's 8 MHz MCO does not reach PH0: a NUCLEO-64 of revision \
                            MB1136 C-01 ships with HSE not used (UM1724 section 6.7.1 and 7.2); \
                            for 'MCO from ST-LINK' close SB16 and SB50 and SB54, open SB55, R35 \
                            and R37 removed (or fit an 8 MHz crystal at X3)";

/// The part's limits.
pub const PART: F4Limits = F446_LIMITS;

/// The memory map.
pub const MEMORY: MemoryMap = MemoryMap {
    flash_len: memory::FLASH_LEN,
    app_len: memory::APP_LEN,
    ram_len: memory::RAM_LEN,
    store: memory::STORE_START..memory::STORE_END,
    store_sector: memory::STORE_SECTOR,
};

/// How the current is sampled.
pub const SENSE_TIMING: SenseTiming = power_stage::sense_timing(&CLOCKS);

/// The board as the device core sees it: the power stage's, with a capture buffer of
/// [`CAPTURE_VALUES_F446`].
pub const BOARD: Board = Board {
    capture_values: CAPTURE_VALUES_F446,
    ..power_stage::board(&CLOCKS)
};

/// The Nucleo's capture buffer (values): 16 KiB, half the F405's. The F446 has no CCM, and its
/// 128 KiB of SRAM hold the control interrupt's code (25 KiB, run from SRAM1 remapped at 0),
/// the statics, the stack guard (8 KiB, aligned to its size) and a stack of at least 16 KiB
/// (17 KiB used): with the F405's 32 KiB the guard found no room. 4096 samples of one field,
/// 1024 of four; the bench tools size their captures from the capacity the device reports.
pub const CAPTURE_VALUES_F446: u32 = 4096;
