//! The F405 board (feature `board-f405`, the default): its description and the pins that
//! differ between boards.

pub mod desc;
pub mod memory;

// For `desc.rs`, which names its siblings through `super` (so that the host tests can compile
// it with `memory.rs` and `power_stage.rs` as its siblings).
use super::power_stage;

pub use desc::*;

/// The board's LEDs (run, fault) from the peripherals `$p`: PB0 and PB1, each to an LED and
/// 1 k to GND.
macro_rules! led_pins {
    ($p:ident) => {
        ($p.PB0, $p.PB1)
    };
}
pub(crate) use led_pins;
