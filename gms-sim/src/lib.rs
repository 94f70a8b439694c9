//! # gms-sim
//!
//! The simulated axis: the plant (motor, gearhead, lead screw, guideways, sensors), scenarios,
//! closed-loop runs of gms-core's controller against it, the paper's experiments on it, and
//! the virtual device (gms-core's device core on the plant, `hil-sim serve`; a
//! [`gms_link::DeviceLink`] in-process). The fits and the parameter file are `gms-ident`'s;
//! the bench's workflows (`gms-bench`) are not used here: the `hil-sim` command runs them on
//! this crate's virtual device.
#![forbid(unsafe_code)]
#![deny(missing_docs)]

use core::fmt;

pub mod commands;
pub mod device;
pub mod experiment;
pub mod friction_cmd;
pub mod harness;
pub mod plant;
pub mod scenario;
pub mod sim;
pub mod study;

/// What went wrong in the simulator. `Display` gives the one-line message the CLI prints; the
/// variant says what kind of failure it is.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Error {
    /// A scenario (or the plant it describes) is invalid.
    Scenario(String),
    /// A run, an experiment or the friction command failed (bad input files, invalid
    /// parameters, nothing written).
    Run(String),
    /// The virtual device could not start (its store, its endpoint, its parameters).
    Device(String),
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Error::Scenario(m) | Error::Run(m) | Error::Device(m) => f.write_str(m),
        }
    }
}

impl std::error::Error for Error {}

/// The message, for callers that report errors as text.
impl From<Error> for String {
    fn from(e: Error) -> String {
        e.to_string()
    }
}
