//! A closed-loop run's trace, simulated or recorded on a device, and its figures: the same
//! rows and the same metrics for `hil-sim run` and `gms-tune step-test`.

use std::fmt::Write as _;

use gms_core::reference::Segment;
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
    /// Longest time, after a step's reference has come to rest at its target, until |error|
    /// stays within 1 count (the rest of the dwell when it never does) \[s\].
    pub settle_time: f64,
    /// Largest mean |error| over the last 20 % of a step's dwell \[rad\].
    pub steady_state_error: f64,
    /// Steps that did not settle within ±1 count before their dwell ended.
    pub unsettled_steps: f64,
    /// Sign changes of the error beyond ±1 count in the second half of step dwells (a hunting
    /// limit cycle shows as many).
    pub hunting_crossings: f64,
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
    // ±1 count, with 1 % allowance for a target that is not exactly on a count boundary.
    let band = rad_per_count * 1.01;
    for (idx, seg) in segments.iter().enumerate() {
        // Time from the segment's start until the reference is at rest at its target.
        let motion = match *seg {
            Segment::Step { .. } | Segment::Staircase { .. } => 0.0,
            Segment::Move { dwell, .. } => (seg.duration() - dwell) as f64,
            _ => continue,
        };
        let rows: Vec<&TraceRow> = trace
            .iter()
            .filter(|r| r.segment == idx)
            .skip_while(|r| r.t < trace_start(trace, idx) + motion)
            .collect();
        if rows.is_empty() {
            continue;
        }
        let t0 = rows[0].t;
        let t_end = rows[rows.len() - 1].t;
        let last_out = rows.iter().rposition(|r| r.error.abs() > band);
        let settle = match last_out {
            None => 0.0,
            Some(i) if i + 1 < rows.len() => rows[i + 1].t - t0,
            Some(_) => {
                m.unsettled_steps += 1.0;
                t_end - t0
            }
        };
        m.settle_time = m.settle_time.max(settle);
        let tail: Vec<f64> = rows[rows.len() * 4 / 5..]
            .iter()
            .map(|r| r.error.abs())
            .collect();
        let mean_tail = tail.iter().sum::<f64>() / tail.len().max(1) as f64;
        m.steady_state_error = m.steady_state_error.max(mean_tail);
        let mut prev = 0.0f64;
        for r in &rows[rows.len() / 2..] {
            if r.error.abs() > band {
                let s = r.error.signum();
                if prev != 0.0 && s != prev {
                    m.hunting_crossings += 1.0;
                }
                prev = s;
            }
        }
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
