//! The line reader: bytes in, complete request lines out, without allocation; over-long and non-ASCII lines are reported, not passed on.

/// The longest request line \[bytes\], without its line ending.
pub const MAX_LINE: usize = 120;

/// CAN (ASCII 0x18): a host's session starts. The line received so far is dropped, with no
/// reply, and the previous host's stream and experiment end as when a USB host goes away
/// ([`Line::Cancel`]). A host starts with CAN LF, so that a half request an earlier host left
/// (a link cut mid-line, which a UART cannot tell) is dropped rather than completed by the
/// newline and run: `move 0.25` cut after `move 0.2` must not move the axis to 0.2.
pub const CANCEL: u8 = 0x18;

/// Accumulates received bytes into request lines.
#[derive(Debug, Clone)]
pub struct LineReader {
    buf: [u8; MAX_LINE],
    len: usize,
    too_long: bool,
    not_text: bool,
    damaged: bool,
    skipping: bool,
}

impl Default for LineReader {
    fn default() -> Self {
        LineReader {
            buf: [0; MAX_LINE],
            len: 0,
            too_long: false,
            not_text: false,
            damaged: false,
            skipping: false,
        }
    }
}

/// A complete request line, or why it cannot be one.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Line<'a> {
    /// A line of printable ASCII (trailing CR removed).
    Text(&'a str),
    /// The line was longer than [`MAX_LINE`] (the rest was discarded).
    TooLong,
    /// The line held other bytes than printable ASCII and tab.
    NotText,
    /// [`CANCEL`]: the line so far dropped, a new host's session.
    Cancel,
    /// Bytes of the line were damaged or lost on the link ([`LineReader::damage`]): it is
    /// not run.
    Damaged,
}

impl LineReader {
    /// The link lost or damaged bytes of the line in progress (the next byte pushed belongs
    /// to it too): it ends as [`Line::Damaged`] at its LF, or is dropped by a [`CANCEL`].
    pub fn damage(&mut self) {
        self.damaged = true;
    }

    /// The line in progress was lost on the link and has been answered already: what came of
    /// it is dropped, and when `rest` the bytes still to come of it, up to and with its LF,
    /// are dropped too, without a line (a [`CANCEL`] ends that).
    pub fn drop_line(&mut self, rest: bool) {
        self.len = 0;
        self.too_long = false;
        self.not_text = false;
        self.damaged = false;
        self.skipping = rest;
    }

    /// Feeds one byte; returns a line when `byte` ends one (LF), and [`Line::Cancel`] for
    /// [`CANCEL`] (the line so far dropped).
    pub fn push(&mut self, byte: u8) -> Option<Line<'_>> {
        if byte == CANCEL {
            self.len = 0;
            self.too_long = false;
            self.not_text = false;
            self.damaged = false;
            self.skipping = false;
            return Some(Line::Cancel);
        }
        if self.skipping {
            self.skipping = byte != b'\n';
            return None;
        }
        if byte == b'\n' {
            let (too_long, not_text, len) = (self.too_long, self.not_text, self.len);
            let damaged = self.damaged;
            self.len = 0;
            self.too_long = false;
            self.not_text = false;
            self.damaged = false;
            if damaged {
                return Some(Line::Damaged);
            }
            if too_long {
                return Some(Line::TooLong);
            }
            if not_text {
                return Some(Line::NotText);
            }
            let mut end = len;
            if end > 0 && self.buf.get(end - 1) == Some(&b'\r') {
                end -= 1;
            }
            let bytes = self.buf.get(..end).unwrap_or(&[]);
            return Some(match core::str::from_utf8(bytes) {
                Ok(s) => Line::Text(s),
                Err(_) => Line::NotText,
            });
        }
        let printable = byte == b'\t' || byte == b'\r' || (0x20..0x7f).contains(&byte);
        if !printable {
            self.not_text = true;
        }
        match self.buf.get_mut(self.len) {
            Some(slot) if !self.too_long => {
                *slot = byte;
                self.len += 1;
            }
            _ => self.too_long = true,
        }
        None
    }
}
