//! A receive ring filled by circular DMA, checked for laps: whether the bytes a reader has
//! not yet read are still the ones received, from the stream's position and its half- and
//! full-transfer flags (a UART's reception on a board, `f4_regs::uart_rx`).
//!
//! The stream writes the ring round and round without ever waiting for the reader: a reader
//! that falls a lap behind reads bytes overwritten by newer ones, and the position alone cannot
//! tell (it is the same after a lap). The stream's half-transfer flag (set as the position
//! reaches the ring's middle) and transfer-complete flag (as it wraps to 0), taken and cleared
//! at each look, say which of the two boundaries it passed since the last look. A lap passes
//! both; a path of at most half the ring from the last look's position passes at most one.
//! So at each look the ring is taken as lapped when the unread bytes are more than half the
//! ring (less a margin: see [`RING_MARGIN`]), or when a flag is set for a boundary the path
//! since the last look did not pass. Every lap is found; a ring more than half full is
//! reported too, which a host that waits for each reply (a request is at most 121 bytes)
//! never fills.

/// Bytes by which the path since the last look is extended backwards \[bytes\]: the position
/// and the flags are not read in the same instant, so a boundary passed between the two reads
/// of one look shows its flag only at the next. One byte at 921,600 Bd takes 10.9 µs, the
/// reads a few hundred nanoseconds: two bytes cover it.
pub const RING_MARGIN: u16 = 2;

/// The reader's memory of the stream's position between looks.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct RingWatch {
    /// The stream's write position at the last look.
    last: u16,
}

impl RingWatch {
    /// A watch of a stream started at position 0, its flags cleared.
    pub const fn new() -> Self {
        RingWatch { last: 0 }
    }

    /// The stream's write position at the last look.
    pub const fn last(&self) -> u16 {
        self.last
    }

    /// One look at a ring of `len` bytes: the reader is at `at`, the stream writes next at
    /// `to` (both in `0..len`), and since the last look it set the half-transfer flag (`half`:
    /// it reached position `len / 2`) and the transfer-complete flag (`full`: it reached
    /// `len`, wrapping to 0). True when the unread bytes are intact; false when the ring lapped
    /// (the caller drops what it has not read). The look's position is kept for the next.
    pub fn intact(&mut self, len: u16, at: u16, to: u16, half: bool, full: bool) -> bool {
        let from = self.last;
        self.last = to;
        if len < 4 * RING_MARGIN || at >= len || to >= len || from >= len {
            return false;
        }
        let ahead = |a: u16, b: u16| (b as u32 + len as u32 - a as u32) % len as u32;
        let unread = ahead(at, to);
        if unread > (len / 2 - RING_MARGIN) as u32 {
            return false;
        }
        let start = (from as u32 + len as u32 - RING_MARGIN as u32) % len as u32;
        let path = ahead(start as u16, to);
        // A boundary `b` was passed on the path when it lies in (start, to].
        let passed = |b: u16| {
            let d = ahead(start as u16, b % len);
            d != 0 && d <= path
        };
        // Each flag set must be for a boundary the path passed.
        (!half || passed(len / 2)) && (!full || passed(0))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A stream that writes `n` bytes at a time into a ring of `len`, its flags set as the
    /// hardware sets them (RM0090 §10.3.10: HTIF at half the count, TCIF at the end).
    struct Stream {
        len: u16,
        pos: u32,
        half: bool,
        full: bool,
    }

    impl Stream {
        fn write(&mut self, n: u32) {
            for _ in 0..n {
                self.pos = (self.pos + 1) % self.len as u32;
                if self.pos == (self.len / 2) as u32 {
                    self.half = true;
                }
                if self.pos == 0 {
                    self.full = true;
                }
            }
        }
        fn take(&mut self) -> (bool, bool) {
            let f = (self.half, self.full);
            (self.half, self.full) = (false, false);
            f
        }
    }

    /// Writes of every length, looked at after each: a lap is always found, no write that
    /// keeps the unread bytes within half the ring is ever taken for one.
    #[test]
    fn every_lap_is_found_and_nothing_else() {
        let len = 64u16;
        for first in 0..len as u32 {
            for n in 0..3 * len as u32 {
                let mut s = Stream {
                    len,
                    pos: 0,
                    half: false,
                    full: false,
                };
                let mut w = RingWatch::new();
                // The reader keeps up, byte by byte, to `first`; then the stream writes `n`
                // more before the next look.
                for _ in 0..first {
                    s.write(1);
                    let (h, f) = s.take();
                    assert!(w.intact(len, s.pos as u16 - 1, s.pos as u16, h, f));
                }
                let at = s.pos as u16;
                s.write(n);
                let (h, f) = s.take();
                let ok = w.intact(len, at, s.pos as u16, h, f);
                if n >= len as u32 {
                    assert!(!ok, "a lap of {n} bytes from {first} not found");
                } else if n <= (len / 2 - RING_MARGIN) as u32 {
                    assert!(ok, "{n} bytes from {first} taken for a lap");
                } else {
                    assert!(!ok, "{n} unread bytes from {first}: over half the ring");
                }
            }
        }
    }

    /// A boundary passed between a look's reading of the flags and of the position shows its
    /// flag at the next look: not a lap.
    #[test]
    fn a_flag_seen_one_look_late_is_not_a_lap() {
        let len = 64u16;
        let mut w = RingWatch::new();
        // First look: the flags read clear, then the stream reached 32, then the position
        // read 32.
        assert!(w.intact(len, 30, 32, false, false));
        // Next look: the half flag, set before the last look's position was read.
        assert!(w.intact(len, 32, 35, true, false));
        // A full-transfer flag with no wrap anywhere near: a lap.
        assert!(!w.intact(len, 35, 36, false, true));
    }

    #[test]
    fn positions_outside_the_ring_are_not_intact() {
        let mut w = RingWatch::new();
        assert!(!w.intact(64, 64, 0, false, false));
        assert!(!w.intact(64, 0, 70, false, false));
        assert!(!w.intact(4, 0, 1, false, false));
    }
}
