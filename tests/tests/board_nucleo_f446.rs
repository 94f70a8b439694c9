//! The nucleo_f446 board's description (gms-core's `boards::nucleo_f446`, the one the firmware links) checked
//! (`support/board_checks.rs`).

use crate::checks;
use gms_core::boards::nucleo_f446 as desc;
use gms_core::boards::nucleo_f446::memory;
use gms_core::boards::power_stage;

#[test]
fn the_description_holds_together() {
    checks::all(&checks::Desc {
        name: desc::NAME,
        clocks: desc::CLOCKS,
        part: desc::PART,
        memory: desc::MEMORY,
        timing: desc::SENSE_TIMING,
        board: desc::BOARD,
        chip: memory::PROBE_RS_CHIP,
        encoder_max_rate: power_stage::ENCODER_MAX_RATE,
        watchdog_us: power_stage::WATCHDOG_US,
        sense_v_per_a: power_stage::SENSE_V_PER_A,
    });
}
