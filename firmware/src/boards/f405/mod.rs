//! The F405 board (feature `board-f405`, the default): its description and the pins that
//! differ between boards.

pub use gms_core::boards::f405::*;

/// The board's LEDs (run, fault) from the peripherals `$p`: PB0 and PB1, each to an LED and
/// 1 k to GND.
macro_rules! led_pins {
    ($p:ident) => {
        ($p.PB0, $p.PB1)
    };
}
pub(crate) use led_pins;
