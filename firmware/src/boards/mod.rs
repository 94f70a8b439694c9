//! The boards the firmware builds for, one module each, chosen by one cargo feature of the
//! firmware package: `board-f405` (the default) or `board-nucleo-f446`. A board module carries
//! its chip's limits, clock tree, memory map and parameter sectors (`memory.rs`, which
//! `build.rs` turns into the linker's `memory.x`), probe-rs chip name and LED pins; the power
//! stage and its pins are common (`power_stage.rs`), driven by `board.rs`. The descriptions are
//! plain numbers that `tests/tests/boards.rs` checks on the host.

pub mod power_stage;

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
