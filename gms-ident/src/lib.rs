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

use gms_core::drive::Faults;
use gms_core::protocol::ErrorCode;

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

/// What went wrong in an identification, an analysis or a bench step. `Display` gives the
/// one-line message the tools print; the variant says what kind of failure it is, so callers
/// decide on the variant, never on the text.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Error {
    /// The data cannot be fitted as given: too few points, non-finite values, a curve of the
    /// wrong shape, a fit that does not converge.
    Data(String),
    /// A parameter file or parameter set is invalid.
    Params(String),
    /// A file could not be read or written.
    Io(String),
    /// The device refused a request: its `err` reply.
    Refused(Refusal),
    /// The device latched faults; `during`: what failed because of them, if anything did.
    Faulted {
        /// The latched faults.
        faults: Faults,
        /// The failure the faults explain (its message), if any.
        during: Option<String>,
    },
    /// The link to the device failed (lost, timed out) or the run was stopped (Ctrl-C, the
    /// window's Stop): the message says which.
    Link(String),
    /// A device did not do what an experiment asked (an unexpected reply, a motion that did
    /// not end, a measurement out of its range).
    Device(String),
}

/// A device's `err CODE REASON` reply.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Refusal {
    /// The protocol's error code.
    pub code: ErrorCode,
    /// The reason the device gave.
    pub reason: String,
}

impl Refusal {
    /// Reads an `err CODE REASON` line ([`gms_core::protocol::Reply`]); `None` when the line
    /// is not one.
    pub fn parse(line: &str) -> Option<Refusal> {
        match gms_core::protocol::Reply::parse(line.trim()) {
            Ok(Some(gms_core::protocol::Reply::Err(code, reason))) => Some(Refusal {
                code,
                reason: reason.to_string(),
            }),
            _ => None,
        }
    }

    /// True when the device refused with `code`.
    pub fn is(&self, code: ErrorCode) -> bool {
        self.code == code
    }
}

impl fmt::Display for Refusal {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let line = gms_core::protocol::Reply::Err(self.code, &self.reason);
        write!(f, "device answered: {line}")
    }
}

/// The names of `faults`, comma-separated (`none` when empty).
pub fn fault_names(faults: Faults) -> String {
    let mut names = String::new();
    let _ = faults.write_names(&mut names);
    names
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Error::Data(m)
            | Error::Params(m)
            | Error::Io(m)
            | Error::Link(m)
            | Error::Device(m) => f.write_str(m),
            Error::Refused(r) => r.fmt(f),
            Error::Faulted { faults, during } => {
                write!(f, "the device latched a fault ({})", fault_names(*faults))?;
                match during {
                    Some(e) => write!(f, ": {e}"),
                    None => Ok(()),
                }
            }
        }
    }
}

impl Error {
    /// True when the device refused the request with `code`.
    pub fn refused_with(&self, code: ErrorCode) -> bool {
        matches!(self, Error::Refused(r) if r.is(code))
    }

    /// The error with `note` added to its message (after `; `), its kind kept (a refusal
    /// becomes [`Error::Device`]: its code no longer describes the whole).
    pub fn with_note(self, note: &str) -> Error {
        match self {
            Error::Data(m) => Error::Data(format!("{m}; {note}")),
            Error::Params(m) => Error::Params(format!("{m}; {note}")),
            Error::Io(m) => Error::Io(format!("{m}; {note}")),
            Error::Link(m) => Error::Link(format!("{m}; {note}")),
            Error::Device(m) => Error::Device(format!("{m}; {note}")),
            Error::Faulted { faults, during } => Error::Faulted {
                faults,
                during: Some(match during {
                    Some(d) => format!("{d}; {note}"),
                    None => note.to_string(),
                }),
            },
            e @ Error::Refused(_) => Error::Device(format!("{e}; {note}")),
        }
    }

    /// The latched faults this error reports, if it is about them.
    pub fn faults(&self) -> Option<Faults> {
        match self {
            Error::Faulted { faults, .. } => Some(*faults),
            _ => None,
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
