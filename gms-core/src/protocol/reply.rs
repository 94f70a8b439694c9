//! The envelope of every reply: its last line, `ok[ TEXT]` or `err CODE REASON`, written and
//! read by one type.

use core::fmt;

use super::ErrorCode;

/// A reply's last line: the device's answer to one request.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Reply<'a> {
    /// `ok`, or `ok TEXT` (the text of a `get`, `status`, …; empty for a bare `ok`).
    Ok(&'a str),
    /// `err CODE REASON`: the request refused, nothing changed.
    Err(ErrorCode, &'a str),
}

/// A line that starts like a reply's end but does not read as one (`err` without a code the
/// protocol knows).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BadReply;

impl fmt::Display for BadReply {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("an `err` line without a known error code")
    }
}

impl<'a> Reply<'a> {
    /// Reads one line of a reply: `Ok(Some(..))` for its end (`ok…`, `err…`), `Ok(None)` for a
    /// line of its body, `Err` for an `err` line whose code is missing or unknown (still the
    /// reply's end: the caller stops reading there).
    pub fn parse(line: &'a str) -> Result<Option<Reply<'a>>, BadReply> {
        let line = line.trim_end_matches(['\r', '\n']);
        if line == "ok" {
            return Ok(Some(Reply::Ok("")));
        }
        if let Some(text) = line.strip_prefix("ok ") {
            return Ok(Some(Reply::Ok(text)));
        }
        if line == "err" || line.starts_with("err ") {
            let rest = line.get(4..).unwrap_or("");
            let (code, reason) = rest.split_once(' ').unwrap_or((rest, ""));
            let code = code
                .parse::<u8>()
                .ok()
                .and_then(ErrorCode::from_code)
                .ok_or(BadReply)?;
            return Ok(Some(Reply::Err(code, reason)));
        }
        Ok(None)
    }
}

impl fmt::Display for Reply<'_> {
    /// The line without its newline.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Reply::Ok("") => f.write_str("ok"),
            Reply::Ok(text) => write!(f, "ok {text}"),
            Reply::Err(code, reason) => write!(f, "err {} {reason}", *code as u8),
        }
    }
}

impl ErrorCode {
    /// Every code, in number order.
    pub const ALL: [ErrorCode; 9] = [
        ErrorCode::UnknownCommand,
        ErrorCode::BadArgument,
        ErrorCode::LineTooLong,
        ErrorCode::NotText,
        ErrorCode::UnknownPath,
        ErrorCode::OutOfRange,
        ErrorCode::InvalidSet,
        ErrorCode::Refused,
        ErrorCode::LinkError,
    ];

    /// The code of its number on the wire; `None` for a number the protocol does not use.
    pub fn from_code(n: u8) -> Option<ErrorCode> {
        ErrorCode::ALL.into_iter().find(|c| *c as u8 == n)
    }
}
