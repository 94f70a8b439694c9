//! Frequency response on the device: a sine injected at a chosen frequency and amplitude, and
//! the responses demodulated over whole periods at the control rate, so that a measurement
//! does not depend on the link's speed.
//!
//! The frequency is adjusted to fit the sample rate: `k` whole periods in exactly `n` samples
//! (`f = k · fs / n`, `n` the nearest whole number of samples to `k` periods of the frequency
//! asked), so that the sine repeats bit for bit every `n` samples and the demodulation is a
//! single bin of a discrete Fourier transform over whole periods: a lock-in whose low-pass is
//! the exact average over the periods, with no ripple at twice the frequency and no leakage
//! from the other harmonics of the response. The excitation's phase is an integer index into
//! the `n` samples (no drift however long it runs); each sample's sine and cosine come from
//! [`crate::reference::sin_cos`] on an angle within one turn.
//!
//! Sums run in f32 within a period and are added into f64 totals once per period (a board's
//! FPU has no f64; one f64 addition per channel and period costs little), so a long
//! measurement keeps its precision.
//!
//! quartiq's `idsp` has a lock-in (`idsp::Lockin`), but it demodulates with a low-pass filter
//! (its output settles and ripples at 2f), in fixed point, for a free-running local
//! oscillator; a whole-period correlation is exact for a periodic excitation and is a few
//! lines, so it is written here.

use crate::reference::sin_cos;

/// The channels demodulated at once (e.g. the injected signal, the current commanded, the
/// position).
pub const CHANNELS: usize = 3;

/// Why a frequency-response measurement cannot be set up.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FrfError {
    /// The frequency is not in (0, rate / 4): a sine needs four samples a period to be
    /// measured with its phase.
    Frequency,
    /// The amplitude is not finite and positive.
    Amplitude,
    /// The measurement would need more samples per group of periods than the counter holds.
    TooLong,
}

impl FrfError {
    /// The one-line reason.
    pub fn reason(self) -> &'static str {
        match self {
            FrfError::Frequency => "the frequency must be above 0 and below a quarter of the rate",
            FrfError::Amplitude => "the amplitude must be a positive number",
            FrfError::TooLong => "too many samples per period at this rate",
        }
    }
}

/// A sine of `k` periods every `n` samples, with its demodulation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sine {
    /// Samples per group of whole periods.
    n: u32,
    /// Periods per group.
    k: u32,
    /// Amplitude (the injected signal's unit).
    amp: f32,
    /// Sample index within the group, 0 … n-1.
    i: u32,
}

impl Sine {
    /// The sine closest to `freq_hz` \[Hz\] at a sample rate of `rate_hz` \[Hz\], of amplitude
    /// `amp`: `k` whole periods in `n` samples, with `k` the smallest number of periods that
    /// puts the frequency within 0.1 % of the one asked (at most 64).
    pub fn new(freq_hz: f32, rate_hz: f32, amp: f32) -> Result<Sine, FrfError> {
        if !(freq_hz > 0.0 && rate_hz > 0.0 && freq_hz < rate_hz / 4.0) {
            return Err(FrfError::Frequency);
        }
        if !(amp > 0.0 && amp.is_finite()) {
            return Err(FrfError::Amplitude);
        }
        let per = rate_hz as f64 / freq_hz as f64;
        let mut best = (1u32, 0u32, f64::INFINITY);
        for k in 1..=64u32 {
            let n = (per * k as f64 + 0.5) as u64;
            if n > u32::MAX as u64 / 2 {
                return Err(FrfError::TooLong);
            }
            let f = k as f64 * rate_hz as f64 / n as f64;
            let err = (f / freq_hz as f64 - 1.0).abs();
            if err < best.2 {
                best = (k, n as u32, err);
            }
            if err <= 1e-3 {
                break;
            }
        }
        Ok(Sine {
            n: best.1,
            k: best.0,
            amp,
            i: 0,
        })
    }

    /// The frequency it runs at \[Hz\] at `rate_hz` \[Hz\].
    pub fn freq_hz(&self, rate_hz: f32) -> f64 {
        self.k as f64 * rate_hz as f64 / self.n as f64
    }

    /// Samples per group of whole periods.
    pub fn samples(&self) -> u32 {
        self.n
    }

    /// Periods per group.
    pub fn periods(&self) -> u32 {
        self.k
    }

    /// The amplitude.
    pub fn amplitude(&self) -> f32 {
        self.amp
    }

    /// This sample's `(sin, cos)` of the excitation's phase (unit amplitude).
    pub fn phase(&self) -> (f32, f32) {
        // k i mod n < n: the angle stays within one turn.
        let m = (self.k as u64 * self.i as u64 % self.n as u64) as f32;
        sin_cos(core::f32::consts::TAU * m / self.n as f32)
    }

    /// This sample's value: `amp · sin(phase)`.
    pub fn value(&self) -> f32 {
        self.amp * self.phase().0
    }

    /// On to the next sample; true when a group of whole periods has just been completed.
    pub fn advance(&mut self) -> bool {
        self.i += 1;
        if self.i >= self.n {
            self.i = 0;
            true
        } else {
            false
        }
    }
}

/// The demodulation of [`CHANNELS`] signals against a [`Sine`]'s phase over whole groups of
/// periods.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct LockIn {
    /// Σ x sin over the group under way, per channel.
    part_s: [f32; CHANNELS],
    /// Σ x cos over the group under way, per channel.
    part_c: [f32; CHANNELS],
    /// Σ x sin over the completed groups.
    sum_s: [f64; CHANNELS],
    /// Σ x cos over the completed groups.
    sum_c: [f64; CHANNELS],
    /// Samples in the completed groups.
    samples: u64,
    /// Completed groups.
    groups: u32,
}

/// One channel's complex amplitude: the signal's component at the excitation's frequency,
/// `x(t) ≈ re · sin(θ) + im · cos(θ)` with θ the excitation's phase (the excitation itself
/// reads `(amp, 0)`).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Phasor {
    /// In phase with the excitation's sine.
    pub re: f64,
    /// In quadrature (with its cosine).
    pub im: f64,
}

impl Phasor {
    /// Magnitude.
    pub fn abs(&self) -> f64 {
        libm_hypot(self.re, self.im)
    }

    /// The ratio `self / den` as a complex number `(re, im)`: a transfer function's value.
    pub fn ratio(&self, den: &Phasor) -> (f64, f64) {
        let d = den.re * den.re + den.im * den.im;
        if d == 0.0 || !d.is_finite() {
            return (f64::NAN, f64::NAN);
        }
        (
            (self.re * den.re + self.im * den.im) / d,
            (self.im * den.re - self.re * den.im) / d,
        )
    }
}

fn libm_hypot(a: f64, b: f64) -> f64 {
    let s = a * a + b * b;
    // Newton's square root from a good start (no std on the target).
    if s <= 0.0 || !s.is_finite() {
        return if s == 0.0 { 0.0 } else { f64::NAN };
    }
    let mut r = f64::from_bits((s.to_bits() >> 1) + (1023u64 << 51));
    for _ in 0..6 {
        r = 0.5 * (r + s / r);
    }
    r
}

impl LockIn {
    /// A lock-in with nothing summed.
    pub const fn new() -> LockIn {
        LockIn {
            part_s: [0.0; CHANNELS],
            part_c: [0.0; CHANNELS],
            sum_s: [0.0; CHANNELS],
            sum_c: [0.0; CHANNELS],
            samples: 0,
            groups: 0,
        }
    }

    /// Adds one sample `x` of every channel, taken at the phase `(sin, cos)` of this sample
    /// ([`Sine::phase`]); `group_done`: this sample completed a group of whole periods (what
    /// [`Sine::advance`] returned after it), which moves the group's sums into the totals.
    pub fn add(&mut self, x: &[f32; CHANNELS], (s, c): (f32, f32), group_done: bool, n: u32) {
        for ((ps, pc), x) in self.part_s.iter_mut().zip(&mut self.part_c).zip(x) {
            *ps += x * s;
            *pc += x * c;
        }
        if group_done {
            for (sum, part) in self.sum_s.iter_mut().zip(&self.part_s) {
                *sum += *part as f64;
            }
            for (sum, part) in self.sum_c.iter_mut().zip(&self.part_c) {
                *sum += *part as f64;
            }
            self.part_s = [0.0; CHANNELS];
            self.part_c = [0.0; CHANNELS];
            self.samples += n as u64;
            self.groups = self.groups.saturating_add(1);
        }
    }

    /// Completed groups of whole periods.
    pub fn groups(&self) -> u32 {
        self.groups
    }

    /// Channel `ch`'s phasor over the completed groups (`None` before the first).
    pub fn phasor(&self, ch: usize) -> Option<Phasor> {
        if self.samples == 0 || ch >= CHANNELS {
            return None;
        }
        let k = 2.0 / self.samples as f64;
        Some(Phasor {
            re: k * self.sum_s[ch],
            im: k * self.sum_c[ch],
        })
    }
}
