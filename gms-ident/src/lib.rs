//! # gms-ident
//!
//! Friction identification and trace analysis on data, for the host: the paper's fits (the
//! virgin curve of pre-sliding, the Stribeck curve of sliding, the frictional lag) on arrays,
//! the parameter file they produce, a run's figures and plots. Used by the simulator
//! (`hil-sim`) and by the bench tool (`gms-tune`), so that a simulated and a measured
//! experiment go through the same code.
#![forbid(unsafe_code)]
#![deny(missing_docs)]

use core::fmt;

pub mod gains;
pub mod identify;
pub mod io;
pub mod linear;
pub mod margins;
pub mod optimum;
pub mod paramfile;
pub mod plot;
pub mod trace;
pub mod units;

/// What went wrong in an identification or an analysis. `Display` gives the one-line message
/// the tools print; the variant says what kind of failure it is, so callers decide on the
/// variant, never on the text. (A bench step's error, with the device's refusals and faults,
/// is `gms_bench::Error`.)
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Error {
    /// The data cannot be fitted as given: too few points, non-finite values, a curve of the
    /// wrong shape, a fit that does not converge.
    Data(String),
    /// A parameter file or parameter set is invalid.
    Params(String),
    /// A file could not be read or written.
    Io(String),
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Error::Data(m) | Error::Params(m) | Error::Io(m) => f.write_str(m),
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

impl From<paramfile::FileError> for Error {
    fn from(e: paramfile::FileError) -> Error {
        Error::Params(e.to_string())
    }
}
