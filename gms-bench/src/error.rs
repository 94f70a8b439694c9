//! A bench step's error: the identification's kinds ([`crate::Error`]), the link's
//! ([`gms_link::Error`]) and the device's own (a fault latched, a motion that did not do
//! what was asked).

use core::fmt;

use gms_core::drive::Faults;
use gms_core::protocol::ErrorCode;
use gms_link::Refusal;

/// What went wrong in a bench step (or in the identification or analysis it ran). `Display` gives the
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

impl From<gms_ident::Error> for Error {
    fn from(e: gms_ident::Error) -> Error {
        match e {
            gms_ident::Error::Data(m) => Error::Data(m),
            gms_ident::Error::Params(m) => Error::Params(m),
            gms_ident::Error::Io(m) => Error::Io(m),
        }
    }
}

impl From<gms_link::Error> for Error {
    fn from(e: gms_link::Error) -> Error {
        match e {
            gms_link::Error::Refused(r) => Error::Refused(r),
            gms_link::Error::Lost(m) => Error::Link(m),
            gms_link::Error::Reply(m) => Error::Device(m),
        }
    }
}

impl From<gms_ident::paramfile::FileError> for Error {
    fn from(e: gms_ident::paramfile::FileError) -> Error {
        Error::Params(e.to_string())
    }
}
