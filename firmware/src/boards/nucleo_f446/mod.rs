//! NUCLEO-F446RE (feature `board-nucleo-f446`): its description and the pins that differ
//! between boards.

pub use gms_core::boards::nucleo_f446::*;

/// The board's LEDs (run, fault) from the peripherals `$p`: the green user LED LD2 on PA5 and
/// an LED with 1 k to GND on PB1 (morpho CN10).
macro_rules! led_pins {
    ($p:ident) => {
        ($p.PA5, $p.PB1)
    };
}
pub(crate) use led_pins;
