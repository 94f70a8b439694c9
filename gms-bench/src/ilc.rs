//! Iterative learning control's law: after each period of a repeated motion, the feedforward
//! correction is updated from the period's error,
//!
//! `u_{k+1} = Q [ u_k + L e_k ]`,
//!
//! a standard robust ILC. The learning filter `L` ([`LearningFilter`]) is a gain γ, a lead λ
//! that matches the loop's delay from the correction to the position (the error a correction
//! at `t` shows up in is the one `λ` later: `e(t + λ)`), and optionally a shape `F(f)`: with
//! the inverse of the process sensitivity as `F` — the loop's own controller `C` plus the
//! plant's `1/P` (`C + J s²` for a rigid axis) — a correction `γ F e` changes the next
//! period's error by `−γ e`, so every frequency is learned at the same rate `1 − γ` (with `C`
//! alone, by `−γ T e`: `T` the loop's complementary sensitivity, near 1 over its bandwidth
//! only). Q is a zero-phase low-pass
//! (a second-order Butterworth run forwards and backwards over the periodic signal) that keeps
//! the learning from building up noise and the high frequencies where the loop's phase makes
//! it diverge. The signals are periodic: shifts and filters wrap around the period, and `L`
//! acts on the period's spectrum (`rustfft`).
//!
//! [`Learner`] keeps the iterations' figures, the best correction, and stops on divergence (the
//! error's RMS, averaged over a set number of iterations, risen 25 % above its lowest: the
//! period's RMS scatters by several per cent from one period to the next on a real axis, so
//! no single rise stops it, and a true divergence grows without bound).

use biquad::{Biquad, Coefficients, DirectForm2Transposed, ToHertz, Type};
use rustfft::FftPlanner;
use rustfft::num_complex::Complex;

/// The learning filter `L` over one period of `n` samples: a complex gain per harmonic of the
/// period, conjugate-symmetric so that a real error gives a real correction.
#[derive(Debug, Clone)]
pub struct LearningFilter {
    gains: Vec<Complex<f64>>,
    /// A gain per sample on the error with the lead alone (a time-varying part), if any.
    pointwise: Option<Vec<f64>>,
    /// The lead alone, per harmonic (for the pointwise part).
    lead: Vec<Complex<f64>>,
}

impl LearningFilter {
    /// `γ e(t + lead)`: a gain and a lead \[samples, fractional allowed\] over `n` samples.
    pub fn p_type(n: usize, gain: f64, lead: f64) -> LearningFilter {
        LearningFilter::shaped(n, 1.0, gain, lead, |_| Complex::new(1.0, 0.0))
    }

    /// `γ F(f) e^{j2πfλ}` over `n` samples at `rate_hz` \[samples/s\]: the gain `gain`, the
    /// lead `lead_s` \[s\] and the shape `shape` at each harmonic's frequency \[Hz\] (the
    /// steady part, 0 Hz, is left alone: its gain 0).
    pub fn shaped(
        n: usize,
        rate_hz: f64,
        gain: f64,
        lead_s: f64,
        shape: impl Fn(f64) -> Complex<f64>,
    ) -> LearningFilter {
        let mut gains = vec![Complex::new(0.0, 0.0); n];
        let mut lead = vec![Complex::new(1.0, 0.0); n];
        for k in 1..=n / 2 {
            let f = k as f64 * rate_hz / n as f64;
            let w = std::f64::consts::TAU * f * lead_s;
            let ld = Complex::new(w.cos(), w.sin());
            lead[k] = ld;
            lead[n - k] = ld.conj();
            if 2 * k == n {
                lead[k] = Complex::new(ld.re, 0.0);
            }
            let g = gain * shape(f) * ld;
            let g = if !g.re.is_finite() || !g.im.is_finite() {
                Complex::new(0.0, 0.0)
            } else {
                g
            };
            gains[k] = g;
            gains[n - k] = g.conj();
            if 2 * k == n {
                // The Nyquist harmonic is real.
                gains[k] = Complex::new(g.re, 0.0);
            }
        }
        LearningFilter {
            gains,
            pointwise: None,
            lead,
        }
    }

    /// This filter plus a time-varying part: `gains[i] e(t_i + λ)` (one gain per sample, the
    /// same lead), e.g. the friction's local stiffness along the path.
    pub fn with_pointwise(mut self, gains: Vec<f64>) -> LearningFilter {
        if gains.len() == self.gains.len() {
            self.pointwise = Some(gains);
        }
        self
    }

    /// `L e` for one period `e` (its length the filter's; otherwise zeros).
    pub fn apply(&self, e: &[f64]) -> Vec<f64> {
        let n = self.gains.len();
        if e.len() != n || n == 0 {
            return vec![0.0; e.len()];
        }
        let mut planner = FftPlanner::<f64>::new();
        let mut spectrum: Vec<Complex<f64>> = e.iter().map(|v| Complex::new(*v, 0.0)).collect();
        planner.plan_fft_forward(n).process(&mut spectrum);
        let inverse = planner.plan_fft_inverse(n);
        let through = |g: &[Complex<f64>]| -> Vec<f64> {
            let mut x: Vec<Complex<f64>> = spectrum.iter().zip(g).map(|(v, g)| v * g).collect();
            inverse.process(&mut x);
            x.iter().map(|v| v.re / n as f64).collect()
        };
        let mut out = through(&self.gains);
        if let Some(pw) = &self.pointwise {
            let led = through(&self.lead);
            for ((o, k), v) in out.iter_mut().zip(pw).zip(&led) {
                *o += k * v;
            }
        }
        out
    }
}

/// The zero-phase low-pass Q: a second-order Butterworth at `corner_hz` for signals sampled at
/// `rate_hz`, run forwards then backwards (the phases cancel, the gain is squared: −6 dB at
/// the corner).
#[derive(Debug, Clone, Copy)]
pub struct QFilter {
    coeffs: Option<Coefficients<f64>>,
}

impl QFilter {
    /// The filter; a corner at or above 0.45 × the rate, or not positive, is no filter.
    pub fn new(corner_hz: f64, rate_hz: f64) -> QFilter {
        let coeffs = (corner_hz > 0.0 && corner_hz < 0.45 * rate_hz)
            .then(|| {
                Coefficients::<f64>::from_params(
                    Type::LowPass,
                    rate_hz.hz(),
                    corner_hz.hz(),
                    core::f64::consts::FRAC_1_SQRT_2,
                )
                .ok()
            })
            .flatten();
        QFilter { coeffs }
    }

    /// `x` (one period of a periodic signal) filtered with zero phase: forwards over three
    /// periods (the first two settle the filter on the periodic signal), the last kept, then
    /// backwards the same way.
    pub fn apply(&self, x: &[f64]) -> Vec<f64> {
        let Some(c) = self.coeffs else {
            return x.to_vec();
        };
        let n = x.len();
        if n == 0 {
            return Vec::new();
        }
        let pass = |input: &[f64]| -> Vec<f64> {
            let mut f = DirectForm2Transposed::<f64>::new(c);
            let mut out = vec![0.0; n];
            for round in 0..3 {
                for (i, v) in input.iter().enumerate() {
                    let y = f.run(*v);
                    if round == 2 {
                        out[i] = y;
                    }
                }
            }
            out
        };
        let fwd = pass(x);
        let rev: Vec<f64> = fwd.iter().rev().copied().collect();
        let mut back = pass(&rev);
        back.reverse();
        back
    }
}

/// One update of the correction `u` from the period's error `e` (the same length): `Q[u + L
/// e]`.
pub fn update(u: &[f64], e: &[f64], l: &LearningFilter, q: &QFilter) -> Vec<f64> {
    let le = l.apply(e);
    let raw: Vec<f64> = u.iter().zip(&le).map(|(a, b)| a + b).collect();
    q.apply(&raw)
}

/// What one iteration gave.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Iteration {
    /// Its number, from 0 (the first pass, no correction learned yet).
    pub n: usize,
    /// The error's RMS over the period.
    pub rms: f64,
    /// The error's largest magnitude over the period.
    pub peak: f64,
}

/// How far the RMS's moving average may rise above its lowest before the learning stops
/// (25 %).
pub const DIVERGED: f64 = 0.25;

/// Why learning stopped, if it did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stop {
    /// The error's RMS averaged over the last `patience` iterations rose more than
    /// [`DIVERGED`] above its lowest such average, at this iteration: diverging.
    Diverging(usize),
}

/// The learning over iterations: the correction, the figures, the best correction so far.
#[derive(Debug, Clone)]
pub struct Learner {
    /// The learning filter L.
    pub l: LearningFilter,
    /// The Q filter.
    pub q: QFilter,
    /// Iterations the RMS is averaged over for the stop.
    pub patience: usize,
    u: Vec<f64>,
    best: (f64, Vec<f64>),
    history: Vec<Iteration>,
    /// The lowest moving average of the RMS so far.
    floor: f64,
}

impl Learner {
    /// A learner for periods of `samples` samples (the learning filter's), starting from no
    /// correction.
    pub fn new(l: LearningFilter, q: QFilter, patience: usize) -> Learner {
        let samples = l.gains.len();
        Learner {
            l,
            q,
            patience: patience.max(1),
            u: vec![0.0; samples],
            best: (f64::INFINITY, vec![0.0; samples]),
            history: Vec::new(),
            floor: f64::INFINITY,
        }
    }

    /// The correction to play in the next period.
    pub fn correction(&self) -> &[f64] {
        &self.u
    }

    /// The correction of the least RMS so far (the one to keep when learning stops).
    pub fn best(&self) -> &[f64] {
        &self.best.1
    }

    /// The iterations so far.
    pub fn history(&self) -> &[Iteration] {
        &self.history
    }

    /// Takes the period's error `e` (played with [`Learner::correction`]): records its figures,
    /// keeps the best correction, updates the correction; `Err` when the RMS's average over the
    /// last `patience` iterations has risen more than [`DIVERGED`] above its lowest (the
    /// correction is then the best one).
    pub fn learn(&mut self, e: &[f64]) -> Result<Iteration, Stop> {
        let n = e.len().max(1) as f64;
        let rms = (e.iter().map(|x| x * x).sum::<f64>() / n).sqrt();
        let peak = e.iter().fold(0.0f64, |a, x| a.max(x.abs()));
        self.learn_measured(e, rms, peak)
    }

    /// As [`Learner::learn`], with the period's RMS and peak as measured elsewhere (the
    /// device's, over every step rather than the period's samples).
    pub fn learn_measured(&mut self, e: &[f64], rms: f64, peak: f64) -> Result<Iteration, Stop> {
        let it = Iteration {
            n: self.history.len(),
            rms,
            peak,
        };
        self.history.push(it);
        if rms < self.best.0 {
            self.best = (rms, self.u.clone());
        }
        if self.history.len() >= self.patience {
            let last = &self.history[self.history.len() - self.patience..];
            let mean = last.iter().map(|i| i.rms).sum::<f64>() / self.patience as f64;
            self.floor = self.floor.min(mean);
            if mean > (1.0 + DIVERGED) * self.floor {
                self.u = self.best.1.clone();
                return Err(Stop::Diverging(it.n));
            }
        }
        self.u = update(&self.u, e, &self.l, &self.q);
        Ok(it)
    }
}

/// Splits periods of an error (each the same length, at least two) into the part that
/// repeats and the part that does not: `(rms, repeating, not_repeating)`. With `m` the mean
/// over the `P` periods at each step and `s²` the unbiased variance about it pooled over the
/// steps, `not_repeating = s` and `repeating² = mean(m²) − s²/P` (the mean of `P` periods
/// still carries `s²/P` of the scatter), so that a repeating signal plus independent noise
/// of standard deviation σ gives back the signal's RMS and σ; and `repeating² +
/// not_repeating² = rms²` exactly (unless the noise's share leaves `repeating²` below 0,
/// where it is 0).
pub fn decompose(periods: &[Vec<f64>]) -> Option<(f64, f64, f64)> {
    let p = periods.len();
    let n = periods.first()?.len();
    if p < 2 || n == 0 || periods.iter().any(|e| e.len() != n) {
        return None;
    }
    let (mut ms, mut mean_sq, mut var) = (0.0, 0.0, 0.0);
    for k in 0..n {
        let m = periods.iter().map(|e| e[k]).sum::<f64>() / p as f64;
        mean_sq += m * m;
        for e in periods {
            ms += e[k] * e[k];
            var += (e[k] - m).powi(2);
        }
    }
    let ms = ms / (n * p) as f64;
    let s2 = var / (n * (p - 1)) as f64;
    let rep2 = mean_sq / n as f64 - s2 / p as f64;
    Some((ms.sqrt(), rep2.max(0.0).sqrt(), s2.sqrt()))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A sine below the corner passes with its phase (zero-phase filtering) and the squared
    /// gain of the filter's transfer function; one above it is cut by that squared gain.
    #[test]
    fn q_is_zero_phase_with_the_squared_butterworth_gain() {
        let rate = 1000.0;
        let n = 1000; // one second: whole periods of 5 and 200 Hz
        let q = QFilter::new(50.0, rate);
        // |H(e^{jω})|² of the biquad's own coefficients: what one pass forwards and one
        // backwards must give.
        let c = q.coeffs.unwrap();
        let h2 = |f: f64| {
            let w = std::f64::consts::TAU * f / rate;
            let num = (
                c.b0 + c.b1 * w.cos() + c.b2 * (2.0 * w).cos(),
                -c.b1 * w.sin() - c.b2 * (2.0 * w).sin(),
            );
            let den = (
                1.0 + c.a1 * w.cos() + c.a2 * (2.0 * w).cos(),
                -c.a1 * w.sin() - c.a2 * (2.0 * w).sin(),
            );
            (num.0 * num.0 + num.1 * num.1) / (den.0 * den.0 + den.1 * den.1)
        };
        // Near the analog Butterworth's at 5 Hz, far below it at 200 Hz (the bilinear
        // transform's warping towards the Nyquist frequency).
        assert!((h2(5.0) * (1.0 + (5.0f64 / 50.0).powi(4)) - 1.0).abs() < 1e-3);
        for (f, expect) in [(5.0, h2(5.0)), (200.0, h2(200.0))] {
            let x: Vec<f64> = (0..n)
                .map(|i| (std::f64::consts::TAU * f * i as f64 / rate).sin())
                .collect();
            let y = q.apply(&x);
            // In-phase and quadrature parts of the output against the input's sine.
            let (mut s, mut c) = (0.0, 0.0);
            for (i, v) in y.iter().enumerate() {
                let w = std::f64::consts::TAU * f * i as f64 / rate;
                s += v * w.sin();
                c += v * w.cos();
            }
            let (s, c) = (2.0 * s / n as f64, 2.0 * c / n as f64);
            assert!(
                (s / expect - 1.0).abs() < 1e-3,
                "{f} Hz: {s} against {expect}"
            );
            assert!(c.abs() < 1e-3 * expect.max(1e-3), "{f} Hz: phase {c}");
        }
    }

    /// A plant with a delay and a first-order lag in closed loop under a repeating
    /// disturbance: the learning with the lead matched to the delay takes the error down
    /// iteration by iteration, to under 2 % of the first pass's in 30 iterations; with the
    /// wrong sign it diverges and stops with the best correction kept.
    #[test]
    fn learning_removes_a_repeating_error_and_stops_when_it_diverges() {
        let n = 500;
        let delay = 3;
        let disturbance: Vec<f64> = (0..n)
            .map(|i| {
                let w = std::f64::consts::TAU * i as f64 / n as f64;
                w.sin() + 0.3 * (3.0 * w).sin()
            })
            .collect();
        // One period of the loop: y[t] = a y[t−1] + (1 − a) (u[t − delay] + d[t]), the
        // error −y; periodic, so run three periods and keep the last.
        let period = |u: &[f64]| -> Vec<f64> {
            let a = 0.9;
            let mut y = vec![0.0; n];
            let mut prev = 0.0;
            for round in 0..3 {
                for t in 0..n {
                    let ud = u[(t + n - delay) % n];
                    prev = a * prev + (1.0 - a) * (ud + disturbance[t]);
                    if round == 2 {
                        y[t] = prev;
                    }
                }
            }
            y.iter().map(|v| -v).collect()
        };
        let p = |g: f64| LearningFilter::p_type(n, g, delay as f64);
        let mut l = Learner::new(p(0.8), QFilter::new(40.0, 1000.0), 3);
        let first = l.learn(&period(l.correction())).unwrap().rms;
        for _ in 0..30 {
            let e = period(l.correction());
            l.learn(&e).unwrap();
        }
        let last = l.history().last().unwrap().rms;
        assert!(last < 0.02 * first, "{first} → {last}");
        // Never up by more than 1 % (at its floor the Q filter's leak wanders by 0.2 %).
        let h = l.history();
        assert!(h.windows(2).all(|w| w[1].rms <= w[0].rms * 1.01));
        // Noise on the error (a tenth of the disturbance, a new draw each period) makes the
        // RMS scatter but does not stop 50 iterations; the error still ends far below the
        // first pass's.
        let mut noisy = Learner::new(p(0.5), QFilter::new(40.0, 1000.0), 3);
        let mut seed = 12345u64;
        let mut noise = || {
            // xorshift, uniform in ±0.17 (0.1 RMS)
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            ((seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 0.346
        };
        for _ in 0..50 {
            let e: Vec<f64> = period(noisy.correction())
                .iter()
                .map(|v| v + noise())
                .collect();
            noisy.learn(&e).unwrap();
        }
        let tail = &noisy.history()[40..];
        let tail_rms = tail.iter().map(|i| i.rms).sum::<f64>() / tail.len() as f64;
        assert!(tail_rms < 0.25 * first, "{first} → {tail_rms}");
        // The wrong sign: diverges, stops, keeps the best (the first pass's zero correction).
        let mut bad = Learner::new(p(-0.8), QFilter::new(40.0, 1000.0), 3);
        let mut stopped = false;
        for _ in 0..50 {
            let e = period(bad.correction());
            if bad.learn(&e).is_err() {
                stopped = true;
                break;
            }
        }
        assert!(stopped);
        assert!(bad.correction().iter().all(|v| *v == 0.0));
    }

    /// A repeating signal plus independent noise of a known standard deviation comes back
    /// apart: the signal's RMS and the noise's σ, and the parts' squares add up to the
    /// whole's less the share the mean carries.
    #[test]
    fn a_repeating_signal_and_noise_come_apart() {
        // A 64-bit LCG's uniform noise in [−0.5, 0.5): σ = 1/√12.
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let mut uniform = || {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        let n = 20_000;
        let signal: Vec<f64> = (0..n)
            .map(|k| 0.7 * (std::f64::consts::TAU * k as f64 / n as f64).sin())
            .collect();
        let periods: Vec<Vec<f64>> = (0..5)
            .map(|_| signal.iter().map(|s| s + uniform()).collect())
            .collect();
        let (rms, rep, nonrep) = decompose(&periods).unwrap();
        let sigma = 1.0 / 12f64.sqrt();
        let signal_rms = 0.7 / 2f64.sqrt();
        assert!(
            (nonrep / sigma - 1.0).abs() < 0.01,
            "{nonrep} against {sigma}"
        );
        assert!(
            (rep / signal_rms - 1.0).abs() < 0.01,
            "{rep} against {signal_rms}"
        );
        let whole = (signal_rms.powi(2) + sigma.powi(2)).sqrt();
        assert!((rms / whole - 1.0).abs() < 0.01, "{rms} against {whole}");
        assert!((rep * rep + nonrep * nonrep - rms * rms).abs() < 1e-12 * rms * rms);
        // Noise alone: nothing repeats (to the estimate's own scatter).
        let noise: Vec<Vec<f64>> = (0..5)
            .map(|_| (0..n).map(|_| uniform()).collect())
            .collect();
        let (_, rep, nonrep) = decompose(&noise).unwrap();
        assert!(rep < 0.1 * nonrep, "{rep} of {nonrep}");
        // Too few periods, or periods of unequal length: none.
        assert!(decompose(&periods[..1]).is_none());
        assert!(decompose(&[vec![1.0, 2.0], vec![1.0]]).is_none());
    }
}
