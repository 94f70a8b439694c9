//! gms-tune's integration tests in one binary: each file below is a module, `support`
//! shared by them (`cargo test -p gms-tune --test all -- MODULE::` runs one file's tests).

mod cli;
mod commission;
mod frf;
mod identify;
mod learn;
mod support;
mod window;
