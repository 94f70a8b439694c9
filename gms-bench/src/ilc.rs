//! Iterative learning control (issue 30, the host's learning law; the device's table motion is
//! still to come): after each period of a repeated motion, the feedforward correction is
//! updated from the period's error,
//!
//! `u_{k+1}(t) = Q [ u_k(t) + γ e_k(t + λ) ]`,
//!
//! a standard robust ILC. γ is the learning gain [A/rad or N·m/rad]; λ the lead \[samples\]
//! that matches the loop's delay from the correction to the position (the error a correction
//! at `t` shows up in is the one `λ` samples later); Q a zero-phase low-pass (a second-order
//! Butterworth run forwards and backwards over the periodic signal) that keeps the learning
//! from building up noise and the high frequencies where the loop's phase makes it diverge.
//! The signals are periodic: shifts and filters wrap around the period.
//!
//! [`Learner`] keeps the iterations' figures, the best correction, and stops on divergence (the
//! error's RMS growing for a set number of iterations).

use biquad::{Biquad, Coefficients, DirectForm2Transposed, ToHertz, Type};

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

/// One update of the correction `u` from the period's error `e` (the same length): `Q[u + γ
/// e(t + lead)]`, the shift wrapping around the period.
pub fn update(u: &[f64], e: &[f64], gain: f64, lead: usize, q: &QFilter) -> Vec<f64> {
    let n = u.len().min(e.len());
    let raw: Vec<f64> = (0..n)
        .map(|i| u[i] + gain * e[(i + lead) % n.max(1)])
        .collect();
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

/// Why learning stopped, if it did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stop {
    /// The error's RMS grew (by more than 1 % each) over this many iterations in a row:
    /// diverging.
    Diverging(usize),
}

/// The learning over iterations: the correction, the figures, the best correction so far.
#[derive(Debug, Clone)]
pub struct Learner {
    /// The learning gain γ.
    pub gain: f64,
    /// The lead λ \[samples\].
    pub lead: usize,
    /// The Q filter.
    pub q: QFilter,
    /// Iterations of growing RMS that stop it.
    pub patience: usize,
    u: Vec<f64>,
    best: (f64, Vec<f64>),
    history: Vec<Iteration>,
    growing: usize,
}

impl Learner {
    /// A learner for periods of `samples` samples, starting from no correction.
    pub fn new(samples: usize, gain: f64, lead: usize, q: QFilter, patience: usize) -> Learner {
        Learner {
            gain,
            lead,
            q,
            patience: patience.max(1),
            u: vec![0.0; samples],
            best: (f64::INFINITY, vec![0.0; samples]),
            history: Vec::new(),
            growing: 0,
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
    /// keeps the best correction, updates the correction; `Err` when it has been diverging for
    /// `patience` iterations (the correction is then the best one).
    pub fn learn(&mut self, e: &[f64]) -> Result<Iteration, Stop> {
        let n = e.len().max(1) as f64;
        let rms = (e.iter().map(|x| x * x).sum::<f64>() / n).sqrt();
        let peak = e.iter().fold(0.0f64, |a, x| a.max(x.abs()));
        let it = Iteration {
            n: self.history.len(),
            rms,
            peak,
        };
        if let Some(last) = self.history.last() {
            // Growing: up by more than 1 % (a converged learning wanders by less at its floor).
            self.growing = if rms > 1.01 * last.rms {
                self.growing + 1
            } else {
                0
            };
        }
        self.history.push(it);
        if rms < self.best.0 {
            self.best = (rms, self.u.clone());
        }
        if self.growing >= self.patience {
            self.u = self.best.1.clone();
            return Err(Stop::Diverging(self.growing));
        }
        self.u = update(&self.u, e, self.gain, self.lead, &self.q);
        Ok(it)
    }
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
        let mut l = Learner::new(n, 0.8, delay, QFilter::new(40.0, 1000.0), 3);
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
        // The wrong sign: diverges, stops, keeps the best (the first pass's zero correction).
        let mut bad = Learner::new(n, -0.8, delay, QFilter::new(40.0, 1000.0), 3);
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
}
