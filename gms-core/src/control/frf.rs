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
//! the `n` samples (no drift however long it runs); each sample's sine and cosine come from a
//! rotation by the phase step (computed once), started afresh at `(0, 1)` with every
//! group, so that every group is the same sequence and a step costs no transcendental function
//! (the rounding over a group of n samples stays near n × 1e-7: 1e-4 for a 10 Hz sine at
//! 10 kHz).
//!
//! Sums run in f32 within a period and are added once per period into totals kept as
//! compensated f32 pairs ([`Sum2`]: the sum and its rounding error), so a long measurement
//! keeps about twice f32's precision without f64, which a board's FPU does
//! not have (nine soft-float additions in one control step cost ~1,000 instructions on the
//! M4F and overran the 40 kHz step).
//!
//! quartiq's `idsp` has a lock-in (`idsp::Lockin`), but it demodulates with a low-pass filter
//! (its output settles and ripples at 2f), in fixed point, for a free-running local
//! oscillator; a whole-period correlation is exact for a periodic excitation and is a few
//! lines, so it is written here.

/// The channels demodulated at once: on the device the current commanded, the current
/// measured and the position ([`Channel`]); the sine injected is known exactly (its
/// amplitude, in phase) and not summed.
pub const CHANNELS: usize = 3;

/// The channels a device demodulates, in [`LockIn`] order.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Channel {
    /// The current command after the injection \[A\].
    Command = 0,
    /// The current measured \[A\].
    Current = 1,
    /// The position measured, relative to the reference without the injection \[rad\].
    Position = 2,
}

/// Why a frequency-response measurement cannot be set up.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FrfError {
    /// The frequency is not in (0, 0.45 × rate): above it the samples of a period no longer
    /// tell its phase (the Nyquist frequency, with a margin).
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
            FrfError::Frequency => "the frequency must be above 0 and below 0.45 × the loop rate",
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
    /// This sample's `(sin, cos)`: rotated by `step` each sample (two multiplications and an
    /// addition each, no transcendental function in a step), set back to `(0, 1)` at the start
    /// of each group, so that every group is the same sequence.
    sc: (f32, f32),
    /// `(sin, cos)` of one sample's phase step, 2π k / n.
    step: (f32, f32),
}

impl Sine {
    /// The sine closest to `freq_hz` \[Hz\] at a sample rate of `rate_hz` \[Hz\], of amplitude
    /// `amp`: `k` whole periods in `n` samples, with `k` the smallest number of periods that
    /// puts the frequency within 0.1 % of the one asked (at most 64).
    pub fn new(freq_hz: f32, rate_hz: f32, amp: f32) -> Result<Sine, FrfError> {
        if !(freq_hz > 0.0 && rate_hz > 0.0 && freq_hz < 0.45 * rate_hz) {
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
        // The step's sine and cosine in f32 (the crate's own, as the reference generator's:
        // no f64 trigonometry in the firmware for this).
        let (sin, cos) = crate::control::reference::sin_cos(
            (core::f64::consts::TAU * best.0 as f64 / best.1 as f64) as f32,
        );
        Ok(Sine {
            n: best.1,
            k: best.0,
            amp,
            i: 0,
            sc: (0.0, 1.0),
            step: (sin, cos),
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
        self.sc
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
            self.sc = (0.0, 1.0);
            true
        } else {
            // sin(θ + δ) = sin θ cos δ + cos θ sin δ; cos(θ + δ) = cos θ cos δ − sin θ sin δ.
            let ((s, c), (ds, dc)) = (self.sc, self.step);
            self.sc = (s * dc + c * ds, c * dc - s * ds);
            false
        }
    }
}

/// A running sum kept as an f32 pair, a "float-float": the rounded sum and what it leaves
/// out, renormalised at every addition so that the second is within half an ulp of the
/// first (Knuth's two-sum, exact in IEEE arithmetic, then Dekker's fast two-sum: nine f32
/// operations an addition, about 44 bits). Without the renormalisation the error term grows
/// with the sum's own drift and loses what it was to keep.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Sum2 {
    hi: f32,
    lo: f32,
}

impl Sum2 {
    /// No sum yet.
    pub const ZERO: Sum2 = Sum2 { hi: 0.0, lo: 0.0 };

    /// Adds `x`.
    pub fn add(&mut self, x: f32) {
        let s = self.hi + x;
        let bp = s - self.hi;
        let err = (self.hi - (s - bp)) + (x - bp);
        let t = err + self.lo;
        let h = s + t;
        self.lo = t - (h - s);
        self.hi = h;
    }

    /// The sum.
    pub fn value(&self) -> f64 {
        self.hi as f64 + self.lo as f64
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
    sum_s: [Sum2; CHANNELS],
    /// Σ x cos over the completed groups.
    sum_c: [Sum2; CHANNELS],
    /// Σ over the completed groups of each group's |Σ x sin + j Σ x cos|².
    sum_sq: [Sum2; CHANNELS],
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
        libm::hypot(self.re, self.im)
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

impl LockIn {
    /// A lock-in with nothing summed.
    pub const fn new() -> LockIn {
        LockIn {
            part_s: [0.0; CHANNELS],
            part_c: [0.0; CHANNELS],
            sum_s: [Sum2::ZERO; CHANNELS],
            sum_c: [Sum2::ZERO; CHANNELS],
            sum_sq: [Sum2::ZERO; CHANNELS],
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
                sum.add(*part);
            }
            for (sum, part) in self.sum_c.iter_mut().zip(&self.part_c) {
                sum.add(*part);
            }
            for ((sq, ps), pc) in self.sum_sq.iter_mut().zip(&self.part_s).zip(&self.part_c) {
                sq.add(ps * ps + pc * pc);
            }
            self.part_s = [0.0; CHANNELS];
            self.part_c = [0.0; CHANNELS];
            self.samples += n as u64;
            self.groups = self.groups.saturating_add(1);
        }
    }

    /// Channel `ch`'s sums copied from `src` (nothing for a channel out of range).
    fn copy_channel(&mut self, src: &LockIn, ch: usize) {
        if ch < CHANNELS {
            self.part_s[ch] = src.part_s[ch];
            self.part_c[ch] = src.part_c[ch];
            self.sum_s[ch] = src.sum_s[ch];
            self.sum_c[ch] = src.sum_c[ch];
            self.sum_sq[ch] = src.sum_sq[ch];
        }
    }

    /// Completed groups of whole periods.
    pub fn groups(&self) -> u32 {
        self.groups
    }

    /// Channel `ch`'s coherence over the completed groups \[0, 1\]: the power of the mean
    /// phasor over the mean power of the groups' phasors, `|Σ P_g|² / (G Σ |P_g|²)` (1 when
    /// every group gave the same response; noise and drift lower it). `None` before the
    /// second group (one group is always coherent with itself) or for a channel that is 0.
    pub fn coherence(&self, ch: usize) -> Option<f64> {
        let (s, c, sq) = (
            self.sum_s.get(ch)?.value(),
            self.sum_c.get(ch)?.value(),
            self.sum_sq.get(ch)?.value(),
        );
        if self.groups < 2 || sq.partial_cmp(&0.0) != Some(core::cmp::Ordering::Greater) {
            return None;
        }
        Some(((s * s + c * c) / (self.groups as f64 * sq)).min(1.0))
    }

    /// Channel `ch`'s phasor over the completed groups (`None` before the first).
    pub fn phasor(&self, ch: usize) -> Option<Phasor> {
        if self.samples == 0 || ch >= CHANNELS {
            return None;
        }
        let k = 2.0 / self.samples as f64;
        Some(Phasor {
            re: k * self.sum_s[ch].value(),
            im: k * self.sum_c[ch].value(),
        })
    }
}

/// Where a device injects its sine.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Injection {
    /// Added to the current command after the position loop and its filters \[A\]: the plant
    /// (position per current) and the open loop (the loop gain) are measured from it.
    Current,
    /// Added to the position reference \[rad\] (with its velocity and acceleration): the
    /// closed loop (position per reference).
    Position,
}

impl Injection {
    /// The protocol's name: `current` or `position`.
    pub fn name(self) -> &'static str {
        match self {
            Injection::Current => "current",
            Injection::Position => "position",
        }
    }

    /// The injection with this name.
    pub fn from_name(name: &str) -> Option<Injection> {
        match name {
            "current" => Some(Injection::Current),
            "position" => Some(Injection::Position),
            _ => None,
        }
    }
}

/// Where a measurement stands.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum FrfState {
    /// None asked since start.
    #[default]
    Idle,
    /// Injecting, the response not yet steady: not summed.
    Settling,
    /// Injecting and summing.
    Measuring,
    /// Every group summed: the result stands, the injection is over.
    Done,
    /// Ended before its groups were summed (the bridge went off, a fault, `frf off`, another
    /// measurement): what was summed stands.
    Stopped,
}

impl FrfState {
    /// The protocol's name.
    pub fn name(self) -> &'static str {
        match self {
            FrfState::Idle => "idle",
            FrfState::Settling => "settling",
            FrfState::Measuring => "measuring",
            FrfState::Done => "done",
            FrfState::Stopped => "stopped",
        }
    }

    /// True while the sine is injected.
    pub fn running(self) -> bool {
        matches!(self, FrfState::Settling | FrfState::Measuring)
    }
}

/// A measurement as asked: the sine, where it goes, and how many groups of whole periods
/// settle and are then summed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrfSpec {
    /// Where the sine is injected.
    pub injection: Injection,
    /// The sine (its amplitude in A or rad).
    pub sine: Sine,
    /// Groups injected before the summing starts (the response's transient).
    pub settle_groups: u32,
    /// Groups summed.
    pub groups: u32,
}

impl FrfSpec {
    /// The measurement closest to `periods` periods of `freq_hz` \[Hz\] after `settle`
    /// periods, at `rate_hz` \[Hz\] (whole groups, at least one of each), amplitude `amp`.
    pub fn new(
        injection: Injection,
        freq_hz: f32,
        amp: f32,
        periods: u32,
        settle: u32,
        rate_hz: f32,
    ) -> Result<FrfSpec, FrfError> {
        let sine = Sine::new(freq_hz, rate_hz, amp)?;
        let k = sine.periods();
        let whole = |p: u32| if k == 0 { p } else { p.div_ceil(k) }.max(1);
        let (groups, settle_groups) = (whole(periods), whole(settle));
        if (groups as u64 + settle_groups as u64) * sine.samples() as u64 > u32::MAX as u64 {
            return Err(FrfError::TooLong);
        }
        Ok(FrfSpec {
            injection,
            sine,
            settle_groups,
            groups,
        })
    }

    /// Position steps the whole measurement takes (settling and summing).
    pub fn steps(&self) -> u64 {
        (self.settle_groups as u64 + self.groups as u64) * self.sine.samples() as u64
    }
}

/// A measurement under way on the device, and its result.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Frf {
    spec: FrfSpec,
    state: FrfState,
    /// Groups completed (settling included).
    groups_done: u32,
    lock: LockIn,
    /// The rate \[Hz\] the frequency was last computed for, and it \[Hz\] (in f64, once: not
    /// in every report).
    freq: (f32, f64),
}

/// What a device shows of its measurement (published at the end of each group).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct FrfReport {
    /// Where it stands.
    pub state: FrfState,
    /// Where the sine went (`None` before the first measurement).
    pub injection: Option<Injection>,
    /// The frequency run \[Hz\] (the one asked, fitted to the rate).
    pub freq_hz: f64,
    /// The amplitude injected (A or rad).
    pub amp: f32,
    /// The sums.
    pub lock: LockIn,
    /// Groups to be summed in all.
    pub groups: u32,
}

impl FrfReport {
    /// The parts [`FrfReport::copy_part`] copies a report in.
    pub const PARTS: usize = 1 + CHANNELS;

    /// Part `part` of `src` copied into `self`: 0 the state, injection, frequency, amplitude
    /// and counts; `1 + k` channel k's sums; nothing past [`FrfReport::PARTS`]. Each part is
    /// at most 32 bytes, where the whole report is 136: a shell whose critical sections
    /// hold a control loop off copies a report a part at a time (the device front does,
    /// checking that no report was published in between).
    pub fn copy_part(&mut self, src: &FrfReport, part: usize) {
        match part.checked_sub(1) {
            None => {
                self.state = src.state;
                self.injection = src.injection;
                self.freq_hz = src.freq_hz;
                self.amp = src.amp;
                self.groups = src.groups;
                self.lock.samples = src.lock.samples;
                self.lock.groups = src.lock.groups;
            }
            Some(ch) => self.lock.copy_channel(&src.lock, ch),
        }
    }
}

impl Frf {
    /// A measurement starting now.
    pub fn start(spec: FrfSpec) -> Frf {
        Frf {
            spec,
            state: FrfState::Settling,
            groups_done: 0,
            lock: LockIn::new(),
            freq: (0.0, f64::NAN),
        }
    }

    /// Where it stands.
    pub fn state(&self) -> FrfState {
        self.state
    }

    /// Where the sine goes.
    pub fn injection(&self) -> Injection {
        self.spec.injection
    }

    /// This sample's injected value (0 once it is over), with the excitation's phase.
    pub fn value(&self) -> (f32, (f32, f32)) {
        if !self.state.running() {
            return (0.0, (0.0, 1.0));
        }
        let ph = self.spec.sine.phase();
        (self.spec.sine.amplitude() * ph.0, ph)
    }

    /// The amplitude injected (A or rad).
    pub fn amplitude(&self) -> f32 {
        self.spec.sine.amplitude()
    }

    /// The sine's angular frequency ω \[rad/s\] at `rate_hz` \[Hz\].
    pub fn omega(&self, rate_hz: f32) -> f32 {
        (core::f64::consts::TAU * self.spec.sine.freq_hz(rate_hz)) as f32
    }

    /// Adds this sample's responses `x` (in [`Channel`] order) taken at phase `ph` (from
    /// [`Frf::value`]) and moves on; true when a group was completed (a new report is due).
    pub fn step(&mut self, x: &[f32; CHANNELS], ph: (f32, f32)) -> bool {
        if !self.state.running() {
            return false;
        }
        let n = self.spec.sine.samples();
        let done = self.spec.sine.advance();
        if self.state == FrfState::Measuring {
            self.lock.add(x, ph, done, n);
        }
        if done {
            self.groups_done = self.groups_done.saturating_add(1);
            if self.groups_done >= self.spec.settle_groups {
                self.state = FrfState::Measuring;
            }
            if self.groups_done >= self.spec.settle_groups.saturating_add(self.spec.groups) {
                self.state = FrfState::Done;
            }
        }
        done
    }

    /// Ends it before its time (what was summed stands); true when it was running.
    pub fn stop(&mut self) -> bool {
        let running = self.state.running();
        if running {
            self.state = FrfState::Stopped;
        }
        running
    }

    /// The report of it now, the frequency at `rate_hz` \[Hz\].
    pub fn report(&mut self, rate_hz: f32) -> FrfReport {
        if self.freq.0 != rate_hz {
            self.freq = (rate_hz, self.spec.sine.freq_hz(rate_hz));
        }
        FrfReport {
            state: self.state,
            injection: Some(self.spec.injection),
            freq_hz: self.freq.1,
            amp: self.spec.sine.amplitude(),
            lock: self.lock,
            groups: self.spec.groups,
        }
    }
}
