//! gms-tune's integration tests in one binary: each file below is a module, `support`
//! shared by them (`cargo test -p gms-tune --test all -- MODULE::` runs one file's tests).

mod cli;
mod commission;
mod frf;
mod identify;
mod learn;
mod support;
mod window;

/// The virtual device, when this binary is started as one (`hil_sim::harness::Server::child`
/// runs it again with the filter `serve_child --exact`: this test's name at the crate root).
#[test]
#[ignore = "the virtual device of the other tests"]
fn serve_child() {
    hil_sim::harness::serve_child();
}
