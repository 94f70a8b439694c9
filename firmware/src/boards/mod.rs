//! The boards the firmware builds for, chosen by one cargo feature of the firmware package:
//! `board-f405` (the default) or `board-nucleo-f446`. Each board's description (chip limits,
//! clock tree, memory map and parameter sectors, probe-rs chip name) and the power stage they
//! share are gms-core's `boards` (one description for the firmware, the virtual device, the
//! benchmarks and the tests; `build.rs` turns its `memory.rs` into the linker's `memory.x`);
//! here only what embassy needs as code: the LED pins. `board.rs` drives the power stage.

pub use gms_core::boards::power_stage;

#[cfg(all(feature = "board-f405", feature = "board-nucleo-f446"))]
compile_error!("choose one board: `board-f405` or `board-nucleo-f446`, not both");
#[cfg(not(any(feature = "board-f405", feature = "board-nucleo-f446")))]
compile_error!("choose a board: `--features board-f405` or `--features board-nucleo-f446`");

#[cfg(feature = "board-f405")]
mod f405;
#[cfg(feature = "board-f405")]
pub use f405::*;

#[cfg(feature = "board-nucleo-f446")]
mod nucleo_f446;
#[cfg(feature = "board-nucleo-f446")]
pub use nucleo_f446::*;
