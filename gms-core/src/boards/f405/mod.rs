//! The F405 board: a bare STM32F405RG board with an 8 MHz crystal and USB on PA11/PA12 (e.g.
//! Olimex STM32-H405) carrying the power stage (`power_stage.rs`). Plain numbers, checked on
//! the host.

use crate::boards::hw::{F4Clocks, F4Limits, F405_LIMITS, MemoryMap};
use crate::device::Board;
use crate::drive::SenseTiming;

use super::power_stage;

pub mod memory;

/// The board's name (its cargo feature is `board-f405`).
pub const NAME: &str = "f405";

/// Clocks: 8 MHz crystal, PLL to 168 MHz (8 / 4 × 168 / 2), 48 MHz for USB (336 / 7); APB1
/// 42 MHz (timers 84), APB2 84 MHz (timers 168).
pub const CLOCKS: F4Clocks = F4Clocks {
    hse_hz: 8_000_000,
    hse_bypass: false,
    pll_m: 4,
    pll_n: 168,
    pll_p: 2,
    pll_q: 7,
    ahb_div: 1,
    apb1_div: 4,
    apb2_div: 2,
};

/// What to check when the HSE does not start (the first log lines say it).
pub const HSE_HINT: &str = "check the 8 MHz crystal and its two load capacitors on OSC_IN/OSC_OUT \
                            (PH0/PH1)";

/// The part's limits.
pub const PART: F4Limits = F405_LIMITS;

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

/// The board as the device core sees it.
pub const BOARD: Board = power_stage::board(&CLOCKS);
