//! The boards, described once: the power stage every board carries ([`power_stage`]) and each
//! board's chip limits, clock tree, memory map and probe ([`f405`], [`nucleo_f446`]). Plain
//! numbers, used by everything that needs a board: the firmware (which picks one by its cargo
//! feature and drives it), the virtual device ([`f405::BOARD`] with the simulator's few
//! differences, `hil-sim`'s `device::board`), the instruction-count benchmarks, the host tests
//! (`tests/tests/board_*.rs` check each description against its chip), and the build scripts
//! that write the linker's memory map from `*/memory.rs` (kept free of dependencies for that).

pub mod f405;
pub mod hw;
pub mod nucleo_f446;
pub mod power_stage;
