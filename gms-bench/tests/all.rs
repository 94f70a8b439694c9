//! gms-bench's integration tests in one binary: each file below is a module
//! (`cargo test -p gms-bench --test all -- MODULE::` runs one file's tests).

mod configured;
mod paramfile;
mod tune_ff;
