//! The f405 board's description (gms-core's `boards::f405`, the one the firmware links) checked
//! (`support/board_checks.rs`).

use crate::checks;
use gms_core::boards::f405 as desc;
use gms_core::boards::f405::memory;
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

#[test]
fn the_simulator_store_image_is_this_board_s() {
    assert_eq!(desc::MEMORY.store, gms_core::device::store::STORE_RANGE);
}

#[test]
fn cargo_run_flashes_this_chip() {
    // `.cargo/config.toml`'s runner is for the default board.
    let cfg = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../.cargo/config.toml"
    ))
    .unwrap();
    let runner = cfg.lines().find(|l| l.starts_with("runner")).unwrap();
    assert!(
        runner.contains(&format!("--chip {}", memory::PROBE_RS_CHIP)),
        "{runner}"
    );
}
