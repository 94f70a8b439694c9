//! The workspace's cross-crate tests in one binary: each file below is a module
//! (`cargo test -p gms-tests --test all -- MODULE::` runs one file's tests).

// The checks every board's description must pass (`support/board_checks.rs`).
#[path = "support/board_checks.rs"]
mod checks;

mod board_f405;
mod board_nucleo_f446;
mod closed_loop;
mod docs;
mod identification;
mod paper_reference;
