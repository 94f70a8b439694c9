//! hil-sim's integration tests in one binary: each file below is a module, `common` and
//! `suite` shared by them (`cargo test -p hil-sim --test all -- MODULE::` runs one file's tests).

mod bench_ident;
mod bench_stage;
mod bridge;
mod coarse;
mod common;
mod conformance;
mod frf;
mod friction_cli;
mod identify_cli;
mod learn;
mod posmap;
mod schedule;
mod serve;
mod settings;
mod sim_cli;
mod stage;
mod suite;
mod truth;
mod tune;
