//! A closed-loop run's trace, simulated or recorded on a device, and its figures: the same
//! rows and the same metrics for `hil-sim run` and `gms-tune step-test`.

use std::fmt::Write as _;

use gms_core::control::reference::Segment;
use serde::Serialize;

/// One row of the trace, at the position-loop rate.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct TraceRow {
    /// Time \[s\].
    pub t: f64,
    /// Reference position \[rad\].
    pub reference: f64,
    /// Measured position (encoder) \[rad\].
    pub position: f64,
    /// Position error, reference - measured \[rad\].
    pub error: f64,
    /// True motor current \[A\].
    pub current: f64,
    /// Current command \[A\].
    pub current_cmd: f64,
    /// Voltage applied by the bridge \[V\].
    pub voltage: f64,
    /// True friction torque, actuator + reflected guideway [N·m].
    pub friction: f64,
    /// Friction feedforward torque [N·m].
    pub feedforward: f64,
    /// Scale on the friction feedforward (the adaptation's estimate; 1 unless gms-adaptive) [-].
    pub ff_scale: f64,
    /// True friction level relative to the nominal (the plant's drift factor) [-].
    pub drift: f64,
    /// Reference velocity [rad/s].
    pub ref_velocity: f64,
    /// Index of the reference segment.
    pub segment: usize,
}

/// The figures of one run (SI units: rad, s).
#[derive(Debug, Clone, Copy, Default, Serialize, PartialEq)]
pub struct Metrics {
    /// RMS position error over the whole run \[rad\].
    pub rms_error: f64,
    /// Largest |error| \[rad\].
    pub max_error: f64,
    /// Largest |error| within 50 ms after a velocity reversal of the reference \[rad\].
    pub reversal_error: f64,
    /// RMS error over the sine segments only \[rad\].
    pub sine_rms_error: f64,
    /// Longest time, after a step's reference has come to rest at its target, until the
    /// error stays within the step's settle band, excursions shorter than [`SPIKE`] ignored
    /// (the rest of the dwell when it never does) \[s\]. See [`settle_band`].
    pub settle_time: f64,
    /// Largest mean |error| over the last 20 % of a step's dwell \[rad\].
    pub steady_state_error: f64,
    /// Steps that did not settle within their band before their dwell ended.
    pub unsettled_steps: f64,
    /// Crossings of the mean (±1 count of hysteresis) by a sustained oscillation of the
    /// error in the second half of step dwells: a hunting limit cycle (more than one count
    /// RMS, periodic); 0 when the error only dithers or is noisy, however it crosses.
    pub hunting_crossings: f64,
    /// The widest settle band of the steps, ± \[rad\] ([`settle_band`]).
    pub settle_band: f64,
}

/// Excursions beyond the settle band shorter than this are spikes of noise, not a departure
/// from the target \[s\].
pub const SPIKE: f64 = 2e-3;

/// The settle band of a step, ± \[rad\]: one encoder count (the encoder cannot tell closer)
/// plus twice the standard deviation of the error about its mean over the last 20 % of the
/// dwell (the noise the axis dithers with at rest), that deviation taken at most one count
/// (more is not noise but motion: a limit cycle must not widen its own band), with 1 %
/// allowance for a target between counts.
pub fn settle_band(tail: &[f64], rad_per_count: f64) -> f64 {
    let n = tail.len().max(1) as f64;
    let mean = tail.iter().sum::<f64>() / n;
    let sd = (tail.iter().map(|e| (e - mean).powi(2)).sum::<f64>() / n).sqrt();
    (rad_per_count + 2.0 * sd.min(rad_per_count)) * 1.01
}

/// `(settle time, settled)`: the time from `rows[0]` after which `(t, error)` stays within
/// ±`band` but for excursions shorter than [`SPIKE`]; not settled when the last excursion
/// lasts to the end.
fn settle(rows: &[(f64, f64)], band: f64) -> (f64, bool) {
    let t0 = rows.first().map_or(0.0, |r| r.0);
    let t_end = rows.last().map_or(0.0, |r| r.0);
    // Walk back from the end: the last excursion that lasts at least SPIKE.
    let mut i = rows.len();
    while i > 0 {
        i -= 1;
        if rows[i].1.abs() <= band {
            continue;
        }
        // An excursion ends at i; find where it starts.
        let end = i;
        while i > 0 && rows[i - 1].1.abs() > band {
            i -= 1;
        }
        let lasts = rows[end].0 - rows[i].0;
        if end + 1 == rows.len() {
            return (t_end - t0, false);
        }
        if lasts + 1e-12 >= SPIKE || i == 0 {
            return (rows[end + 1].0 - t0, true);
        }
    }
    (0.0, true)
}

/// Hunting in `(t, error)`: a sustained oscillation about the error's mean — its RMS about
/// the mean above one count (more than the encoder's quantisation dither) and periodic (the
/// normalised autocorrelation, after its first negative lobe, comes back to 0.5 or more at a
/// lag up to 0.25 s). Returns the crossings of the mean with ±1 count of hysteresis when it
/// hunts, 0 when it does not (dither and noise are not hunting, however they cross).
fn hunting(rows: &[(f64, f64)], rad_per_count: f64) -> usize {
    let n = rows.len();
    if n < 8 {
        return 0;
    }
    let mean = rows.iter().map(|r| r.1).sum::<f64>() / n as f64;
    let x: Vec<f64> = rows.iter().map(|r| r.1 - mean).collect();
    let var: f64 = x.iter().map(|v| v * v).sum();
    if (var / n as f64).sqrt() <= rad_per_count || var <= 0.0 {
        return 0;
    }
    let dt = (rows[n - 1].0 - rows[0].0) / (n - 1) as f64;
    let max_lag = ((0.25 / dt.max(1e-9)) as usize).min(n / 2);
    let r = |k: usize| x.iter().zip(&x[k..]).map(|(a, b)| a * b).sum::<f64>() / var;
    let mut lobe = false;
    let mut periodic = false;
    for k in 1..=max_lag {
        let v = r(k);
        if v < -0.2 {
            lobe = true;
        } else if lobe && v >= 0.5 {
            periodic = true;
            break;
        }
    }
    if !periodic {
        return 0;
    }
    let mut count = 0;
    let mut side = 0.0f64;
    for v in &x {
        let s = if *v > rad_per_count {
            1.0
        } else if *v < -rad_per_count {
            -1.0
        } else {
            continue;
        };
        if side != 0.0 && s != side {
            count += 1;
        }
        side = s;
    }
    count
}

/// Time of the first trace row of segment `idx`.
fn trace_start(trace: &[TraceRow], idx: usize) -> f64 {
    trace.iter().find(|r| r.segment == idx).map_or(0.0, |r| r.t)
}

/// Computes the run's figures from its trace.
pub fn metrics(trace: &[TraceRow], segments: &[Segment], rad_per_count: f64) -> Metrics {
    let mut m = Metrics::default();
    if trace.is_empty() {
        return m;
    }
    let n = trace.len() as f64;
    m.rms_error = (trace.iter().map(|r| r.error * r.error).sum::<f64>() / n).sqrt();
    m.max_error = trace.iter().map(|r| r.error.abs()).fold(0.0, f64::max);
    let sine: Vec<f64> = trace
        .iter()
        .filter(|r| matches!(segments.get(r.segment), Some(Segment::Sine { .. })))
        .map(|r| r.error)
        .collect();
    if !sine.is_empty() {
        m.sine_rms_error = (sine.iter().map(|e| e * e).sum::<f64>() / sine.len() as f64).sqrt();
    }
    // Reversals: the reference velocity changes sign (ignoring exact zeros).
    let mut last_sign = 0.0f64;
    let mut window_end = f64::NEG_INFINITY;
    for r in trace {
        let s = if r.ref_velocity > 0.0 {
            1.0
        } else if r.ref_velocity < 0.0 {
            -1.0
        } else {
            0.0
        };
        if s != 0.0 {
            if last_sign != 0.0 && s != last_sign {
                window_end = r.t + 0.05;
            }
            last_sign = s;
        }
        if r.t <= window_end {
            m.reversal_error = m.reversal_error.max(r.error.abs());
        }
    }
    // Steps: per step segment, settling and steady state.
    for (idx, seg) in segments.iter().enumerate() {
        // Time from the segment's start until the reference is at rest at its target.
        let motion = match *seg {
            Segment::Step { .. } | Segment::Staircase { .. } => 0.0,
            Segment::Move { dwell, .. } => (seg.duration() - dwell) as f64,
            _ => continue,
        };
        let rows: Vec<(f64, f64)> = trace
            .iter()
            .filter(|r| r.segment == idx)
            .skip_while(|r| r.t < trace_start(trace, idx) + motion)
            .map(|r| (r.t, r.error))
            .collect();
        if rows.is_empty() {
            continue;
        }
        let tail: Vec<f64> = rows[rows.len() * 4 / 5..].iter().map(|r| r.1).collect();
        let band = settle_band(&tail, rad_per_count);
        m.settle_band = m.settle_band.max(band);
        let (t_settle, settled) = settle(&rows, band);
        if !settled {
            m.unsettled_steps += 1.0;
        }
        m.settle_time = m.settle_time.max(t_settle);
        let mean_tail = tail.iter().map(|e| e.abs()).sum::<f64>() / tail.len().max(1) as f64;
        m.steady_state_error = m.steady_state_error.max(mean_tail);
        m.hunting_crossings += hunting(&rows[rows.len() / 2..], rad_per_count) as f64;
    }
    m
}

impl Metrics {
    /// The metrics by name, in a fixed order.
    pub fn named(&self) -> [(&'static str, f64); 8] {
        [
            ("rms_error", self.rms_error),
            ("max_error", self.max_error),
            ("reversal_error", self.reversal_error),
            ("sine_rms_error", self.sine_rms_error),
            ("settle_time", self.settle_time),
            ("steady_state_error", self.steady_state_error),
            ("unsettled_steps", self.unsettled_steps),
            ("hunting_crossings", self.hunting_crossings),
        ]
    }
}

/// The trace as CSV text (a header line, then one line per row, SI units).
pub fn trace_csv(trace: &[TraceRow]) -> String {
    let mut s = String::from(
        "t,reference,position,error,current,current_cmd,voltage,friction,feedforward,ref_velocity,segment,ff_scale,drift\n",
    );
    for r in trace {
        let _ = writeln!(
            s,
            "{},{},{},{},{},{},{},{},{},{},{},{},{}",
            r.t,
            r.reference,
            r.position,
            r.error,
            r.current,
            r.current_cmd,
            r.voltage,
            r.friction,
            r.feedforward,
            r.ref_velocity,
            r.segment,
            r.ff_scale,
            r.drift
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    const C: f64 = 3.8e-6;

    /// A deterministic "noise": ±1-count dither (the encoder's quantisation of a position
    /// that wanders by a fraction of a count), with a 2-count spike of one sample every 50 ms.
    fn dither(i: usize) -> f64 {
        let q = ((i as f64 * 0.731).sin() * 1.4).round(); // -1, 0 or 1 counts
        let spike = if i % 500 == 250 { 2.0 } else { 0.0 };
        (q + spike) * C
    }

    /// An error that decays as 100 counts e^(-t/5 ms) onto the dither, at 10 kHz for 1 s:
    /// it settles when the decay is inside the band (the dither and the spikes do not reset
    /// the clock), and nothing hunts.
    #[test]
    fn a_decay_into_dither_settles_when_the_decay_is_inside_the_band() {
        let rows: Vec<(f64, f64)> = (0..10_000)
            .map(|i| {
                let t = i as f64 * 1e-4;
                (t, 100.0 * C * (-t / 5e-3).exp() + dither(i))
            })
            .collect();
        let tail: Vec<f64> = rows[8000..].iter().map(|r| r.1).collect();
        let band = settle_band(&tail, C);
        // The dither's deviation is about 0.7 count: the band 2.4 counts or so, capped at 3.
        assert!(
            band > 1.5 * C && band <= 3.03 * C,
            "band {} counts",
            band / C
        );
        let (t, settled) = settle(&rows, band);
        // With the dither of ±1 count the decay is inside the band for good once it is below
        // band − 1 count, and cannot be before it is below band + 1 count.
        let lo = 5e-3 * (100.0 * C / (band + 1.0 * C)).ln() - 1e-4;
        let hi = 5e-3 * (100.0 * C / (band - 1.0 * C)).ln() + 2e-4;
        assert!(
            settled && t >= lo - 1e-4 && t <= hi,
            "{t} not in [{lo}, {hi}]"
        );
        assert_eq!(hunting(&rows[5000..], C), 0);
    }

    /// A limit cycle: 6 counts at 8 Hz around the target never settles and hunts (two
    /// crossings a period, each excursion lasting tens of ms).
    #[test]
    fn a_limit_cycle_hunts_and_never_settles() {
        let rows: Vec<(f64, f64)> = (0..10_000)
            .map(|i| {
                let t = i as f64 * 1e-4;
                (
                    t,
                    6.0 * C * (2.0 * std::f64::consts::PI * 8.0 * t).sin() + dither(i),
                )
            })
            .collect();
        let tail: Vec<f64> = rows[8000..].iter().map(|r| r.1).collect();
        let band = settle_band(&tail, C);
        assert!(
            band <= 3.03 * C,
            "the cycle widens its own band: {}",
            band / C
        );
        let (_, settled) = settle(&rows, band);
        assert!(!settled || settle(&rows, band).0 > 0.9);
        let n = hunting(&rows[5000..], C);
        // Half a second at 8 Hz: 8 crossings (7 to 9 by phase and the dither).
        assert!((7..=9).contains(&n), "{n}");
    }
}
