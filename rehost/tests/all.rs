//! rehost's tests against a firmware image in one binary: each file below is a module,
//! `support` and hil-sim's `suite` shared by them (`cargo test -p rehost --test all -- MODULE::`).

mod bench;
mod conformance;
mod faults;
#[path = "../../hil-sim/tests/suite/mod.rs"]
mod suite;
mod support;
mod usb;

/// The virtual device, when this binary is started as one (`hil_sim::harness::Server::child`
/// runs it again with the filter `serve_child --exact`: this test's name at the crate root).
#[test]
#[ignore = "the virtual device of the bench test"]
fn serve_child() {
    hil_sim::harness::serve_child();
}
