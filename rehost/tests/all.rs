//! rehost's tests against a firmware image in one binary: each file below is a module,
//! `support` and hil-sim's `suite` shared by them (`cargo test -p rehost --test all -- MODULE::`).

mod bench;
mod conformance;
mod faults;
#[path = "../../hil-sim/tests/suite/mod.rs"]
mod suite;
mod support;
