//! The encoder: a wrapping hardware counter extended to i64, and the timer input filter for its signals.

/// Extends a wrapping hardware counter of `bits` bits (1 to 32) to an i64 count.
///
/// Correct as long as the counter moves by less than half its range between two updates
/// (32 767 counts for a 16-bit timer; 2^31 for a 32-bit one).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CountExtender {
    bits: u32,
    last: u32,
    count: i64,
}

/// The signed difference `raw - last` of a `bits`-bit wrapping counter \[counts\], taken as the
/// shortest way round (in `-2^(bits-1) .. 2^(bits-1)`). `bits` is clamped to 1..=32.
pub fn wrapping_delta(last: u32, raw: u32, bits: u32) -> i64 {
    let bits = bits.clamp(1, 32);
    let shift = 32 - bits;
    // Move the counter into the top bits so that u32 wrapping is the counter's wrapping.
    let d = (raw << shift).wrapping_sub(last << shift) as i32;
    (d >> shift) as i64
}

impl CountExtender {
    /// An extender for a `bits`-bit counter (clamped to 1..=32) that reads `raw` now; the
    /// extended count starts at 0.
    pub fn new(bits: u32, raw: u32) -> Self {
        CountExtender {
            bits: bits.clamp(1, 32),
            last: raw,
            count: 0,
        }
    }

    /// Takes `raw` as the counter's reading now without counting anything (after the reading's
    /// meaning changed, e.g. its direction): the extended count goes on from where it is.
    pub fn rebase(&mut self, raw: u32) {
        self.last = raw;
    }

    /// Takes a new raw reading; returns the increment since the last one \[counts\].
    pub fn update(&mut self, raw: u32) -> i64 {
        let d = wrapping_delta(self.last, raw, self.bits);
        self.last = raw;
        self.count = self.count.saturating_add(d);
        d
    }

    /// The extended count \[counts\].
    pub fn count(&self) -> i64 {
        self.count
    }
}

/// STM32 timer input filters (TIMx_CCMRx ICxF, RM0090 §18.4.7): for each code 0..=15, the
/// sampling clock's divider of f_DTS (0: f_CK_INT) and the samples N an input must keep its
/// new level before the edge is taken. Code 0 is no filter.
pub const INPUT_FILTERS: [(u32, u32); 16] = [
    (1, 1),
    (1, 2),
    (1, 4),
    (1, 8),
    (2, 6),
    (2, 8),
    (4, 6),
    (4, 8),
    (8, 6),
    (8, 8),
    (16, 5),
    (16, 6),
    (16, 8),
    (32, 5),
    (32, 6),
    (32, 8),
];

/// The strongest timer input filter for a quadrature encoder counted on both edges of both
/// channels up to `max_count_rate` [counts/s], on a timer clocked at `timer_hz` \[Hz\] (f_DTS =
/// f_CK_INT): the filter's window (N samples) stays at most half of the shortest time between
/// two edges (1 / `max_count_rate`), so edges at the highest rate pass with a factor 2 for
/// phase error and duty spread, while glitches shorter than the window are rejected. Returns
/// the ICxF code and the window \[s\]; code 0 (no filter, window 0) when even the lightest
/// filter would be too slow or the arguments are not positive.
pub fn encoder_filter(timer_hz: u32, max_count_rate: f32) -> (u8, f32) {
    if timer_hz == 0 || !max_count_rate.is_finite() || max_count_rate <= 0.0 {
        return (0, 0.0);
    }
    let limit = 0.5 / max_count_rate as f64;
    let mut best = (0u8, 0.0f32);
    let mut longest = 0.0f64;
    for (code, &(div, n)) in INPUT_FILTERS.iter().enumerate().skip(1) {
        let window = n as f64 * div as f64 / timer_hz as f64;
        if window <= limit && window > longest {
            longest = window;
            best = (code as u8, window as f32);
        }
    }
    best
}
