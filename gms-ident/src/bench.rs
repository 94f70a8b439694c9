//! The paper's experiments written once against an abstract bench: anything that answers the
//! bench protocol — a board over USB, the virtual device over TCP (`gms-tune`'s link), the
//! device core in-process on the simulated plant (`hil-sim`'s `LocalDevice`). An experiment
//! only sends protocol requests and lets device time pass, so it runs alike on all of them.

use crate::Error;

/// A device speaking the bench protocol.
pub trait Bench {
    /// Sends one request line; returns the lines before its `ok` and the text after `ok`, or
    /// the device's `err` line as [`Error::Device`].
    fn request(&mut self, line: &str) -> Result<(Vec<String>, String), Error>;
    /// Lets at least `seconds` of device time pass.
    fn wait(&mut self, seconds: f64);
}

/// A capture's state as `capture` reports it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CaptureStatus {
    /// `idle`, `armed`, `recording` or `done`.
    pub state: String,
    /// Samples recorded.
    pub samples: u32,
    /// The buffer's size (values).
    pub capacity: u32,
}

/// The capture's state.
pub fn capture_status(b: &mut impl Bench) -> Result<CaptureStatus, Error> {
    let (_, text) = b.request("capture")?;
    let get = |k: &str| {
        text.split_whitespace()
            .find_map(|w| w.strip_prefix(k)?.strip_prefix('='))
            .map(String::from)
    };
    let num = |k: &str| get(k).and_then(|v| v.parse().ok());
    match (get("state"), num("samples"), num("capacity")) {
        (Some(state), Some(samples), Some(capacity)) => Ok(CaptureStatus {
            state,
            samples,
            capacity,
        }),
        _ => Err(Error::Device(format!("unexpected capture reply: {text}"))),
    }
}

/// Waits until the capture is `done`, letting `step` seconds of device time pass between
/// looks, at most `tries` looks.
pub fn capture_wait(b: &mut impl Bench, step: f64, tries: u32) -> Result<CaptureStatus, Error> {
    for _ in 0..tries {
        let st = capture_status(b)?;
        if st.state == "done" {
            return Ok(st);
        }
        b.wait(step);
    }
    Err(Error::Device("the capture did not finish".into()))
}

/// Every sample of a finished capture, as rows of its fields (SI), read 64 at a time.
pub fn capture_rows(b: &mut impl Bench) -> Result<Vec<Vec<f64>>, Error> {
    let st = capture_status(b)?;
    if st.state != "done" {
        return Err(Error::Device(format!(
            "no finished capture (state {})",
            st.state
        )));
    }
    let mut rows = Vec::with_capacity(st.samples as usize);
    let mut start = 0;
    while start < st.samples {
        let (lines, _) = b.request(&format!("capture read {start} 64"))?;
        if lines.is_empty() {
            return Err(Error::Device(format!("capture read {start}: no samples")));
        }
        for l in &lines {
            let row: Result<Vec<f64>, _> = l.split(',').map(str::parse).collect();
            rows.push(row.map_err(|_| Error::Device(format!("bad capture line: {l}")))?);
        }
        start += lines.len() as u32;
    }
    Ok(rows)
}

/// Records `fields` every position step for `samples` steps from now and returns the rows.
pub fn capture_now(
    b: &mut impl Bench,
    fields: &str,
    samples: u32,
    step_s: f64,
) -> Result<Vec<Vec<f64>>, Error> {
    b.request(&format!("capture {fields} 1 {samples}"))?;
    b.wait(samples as f64 * step_s);
    capture_wait(b, 0.01, 200)?;
    capture_rows(b)
}

/// The sliding experiment's settings.
#[derive(Debug, Clone)]
pub struct SlidingPlan {
    /// The speeds [rad/s], each run in both directions.
    pub speeds: Vec<f64>,
    /// The stroke to cover before measuring \\[rad\\] (several pre-sliding ranges, so that every
    /// block slips).
    pub settle_stroke: f64,
    /// The shortest settling time \\[s\\] (the loop and the slip time constants).
    pub settle_min: f64,
    /// Samples averaged per speed (position steps).
    pub samples: u32,
}

impl SlidingPlan {
    /// `n` speeds spaced logarithmically from `v_min` to `v_max` [rad/s].
    pub fn log_spaced(v_min: f64, v_max: f64, n: usize) -> SlidingPlan {
        let n = n.max(2);
        let speeds = (0..n)
            .map(|i| v_min * (v_max / v_min).powf(i as f64 / (n - 1) as f64))
            .collect();
        SlidingPlan {
            speeds,
            settle_stroke: 0.05,
            settle_min: 0.3,
            samples: 200,
        }
    }
}

/// The sliding experiment (paper §3): at each speed, in both directions, a velocity run; once
/// settled, the mean friction torque (current × k_M, the loop's own torque constant, at
/// constant speed the whole of the motor torque) and the measured speed (the encoder over the
/// window). Returns `(v, f)` pairs as `hil-sim experiment sliding` writes them, and ends holding.
pub fn sliding(b: &mut impl Bench, plan: &SlidingPlan) -> Result<Vec<(f64, f64)>, Error> {
    let (_, k_m) = b.request("get motor.k_m")?;
    let k_m: f64 = k_m
        .trim()
        .parse()
        .map_err(|_| Error::Device(format!("motor.k_m: {k_m}")))?;
    let (_, rate) = b.request("get rate.pos_hz")?;
    let rate: f64 = rate
        .trim()
        .parse()
        .map_err(|_| Error::Device(format!("rate.pos_hz: {rate}")))?;
    let dt = 1.0 / rate;
    b.request("enable")?;
    let mut out = Vec::new();
    for &v in &plan.speeds {
        for dir in [1.0, -1.0] {
            let v = dir * v;
            b.request(&format!("velocity {v}"))?;
            b.wait((plan.settle_stroke / v.abs()).max(plan.settle_min));
            let rows = capture_now(b, "t,pos,current", plan.samples, dt)?;
            let (Some(first), Some(last)) = (rows.first(), rows.last()) else {
                return Err(Error::Device("an empty capture".into()));
            };
            let span = last[0] - first[0];
            if span <= 0.0 {
                return Err(Error::Device("a capture without time".into()));
            }
            let v_meas = (last[1] - first[1]) / span;
            let i_mean = rows.iter().map(|r| r[2]).sum::<f64>() / rows.len() as f64;
            out.push((v_meas, k_m * i_mean));
        }
    }
    b.request("hold")?;
    Ok(out)
}
