//! # gms-link
//!
//! A gms device as the host sees it: anything that answers the bench protocol — a board over
//! USB or UART, the virtual device over TCP (`gms-tune`'s link), the device core in-process on
//! the simulated plant (`hil-sim`'s `LocalDevice`). [`DeviceLink`] is the one trait they implement
//! and every workflow is written against (`gms-bench`'s), below both the simulator and the
//! bench crate; [`Error`] is what a request can end in short of `ok`.
#![forbid(unsafe_code)]
#![deny(missing_docs)]

use core::fmt;

use gms_core::protocol::{Command, ErrorCode, Reply};

/// One line of a reply, read as every host reads it ([`Reply::parse`]): `Ok(None)` a line of
/// its body, `Ok(Some(text))` its `ok` end with the text after `ok`, [`Error::Refused`] its
/// `err` end, [`Error::Reply`] an `err` line whose code the protocol does not have (still the
/// reply's end).
pub fn reply_line(line: &str) -> Result<Option<&str>, Error> {
    match Reply::parse(line) {
        Ok(None) => Ok(None),
        Ok(Some(Reply::Ok(text))) => Ok(Some(text)),
        Ok(Some(Reply::Err(code, reason))) => Err(Error::Refused(Refusal::new(code, reason))),
        Err(e) => Err(Error::Reply(format!("{e}: {line}"))),
    }
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
    /// The refusal `err CODE REASON`.
    pub fn new(code: ErrorCode, reason: &str) -> Refusal {
        Refusal {
            code,
            reason: reason.to_string(),
        }
    }

    /// Reads an `err CODE REASON` line ([`gms_core::protocol::Reply`]); `None` when the line
    /// is not one.
    pub fn parse(line: &str) -> Option<Refusal> {
        match Reply::parse(line.trim()) {
            Ok(Some(Reply::Err(code, reason))) => Some(Refusal::new(code, reason)),
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

/// Why a request got no `ok`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Error {
    /// The device refused it: its `err` reply (nothing changed on the device).
    Refused(Refusal),
    /// The link failed (lost, timed out) or the run was stopped (Ctrl-C, the window's Stop):
    /// the message says which.
    Lost(String),
    /// The device answered something that is not a reply of the protocol.
    Reply(String),
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Error::Refused(r) => r.fmt(f),
            Error::Lost(m) | Error::Reply(m) => f.write_str(m),
        }
    }
}

impl std::error::Error for Error {}

/// A link to a device speaking the bench protocol: what a board's port, the virtual device's
/// socket and the in-process device core each implement. The workflows' conveniences (`set`,
/// `enable`, `capture`, …) are `gms_bench::Bench`'s, on top of it.
pub trait DeviceLink {
    /// Sends a typed request (`gms_core::protocol::Command`: its line is the one the device's
    /// parser reads back as the same command); returns the lines before its `ok` and the
    /// text after `ok`, or the device's `err` as [`Error::Refused`].
    fn request(&mut self, c: Command<'_>) -> Result<(Vec<String>, String), Error>;
    /// Lets at least `seconds` of device time pass; fails when the run must stop (the link
    /// is lost, the user interrupted it).
    fn pass(&mut self, seconds: f64) -> Result<(), Error>;
    /// Sends a request that ends a run safely (the bridge off, the settings put back): unlike
    /// [`DeviceLink::request`] it goes out even after the run was stopped. By default the
    /// same.
    fn request_to_end(&mut self, c: Command<'_>) -> Result<(Vec<String>, String), Error> {
        self.request(c)
    }
}
