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

/// A numeric parameter of the device (`get PATH`).
pub fn get_param(b: &mut impl Bench, path: &str) -> Result<f64, Error> {
    let (_, v) = b.request(&format!("get {path}"))?;
    v.trim()
        .parse()
        .map_err(|_| Error::Device(format!("{path}: not a number: {v}")))
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
    let k_m = get_param(b, "motor.k_m")?;
    let dt = 1.0 / get_param(b, "rate.pos_hz")?;
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

/// The pre-sliding experiment's settings.
#[derive(Debug, Clone)]
pub struct PreslidingPlan {
    /// The current step \\[A\\] (the torque step is this × k_M): small, so that no step
    /// overshoots past breakaway.
    pub step: f64,
    /// The most steps before giving up \\[-\\].
    pub max_steps: u32,
    /// The wait after each step before measuring \\[s\\].
    pub dwell: f64,
    /// Samples averaged per step (position steps).
    pub samples: u32,
    /// The stroke the run may use from its start \\[rad\\]: beyond it the axis has broken
    /// away (or never holds) and the run ends.
    pub window: f64,
    /// The creep speed that counts as breakaway \\[rad/s\\]: an axis still moving this fast
    /// after the dwell (over the averaged samples) slides; the run ends there.
    pub creep: f64,
}

impl PreslidingPlan {
    /// Steps of `step` \\[A\\], 20 ms of dwell, 100 samples, up to `max_steps`, a stroke window
    /// of 20 mrad, breakaway above 30 mrad/s of creep.
    pub fn new(step: f64, max_steps: u32) -> PreslidingPlan {
        PreslidingPlan {
            step,
            max_steps,
            dwell: 0.02,
            samples: 100,
            window: 0.02,
            creep: 0.03,
        }
    }
}

/// What a settled dwell gives.
struct Settled {
    /// Mean position, absolute (from the capture's origin) \\[rad\\].
    x: f64,
    /// Mean current \\[A\\].
    i: f64,
    /// Speed over the samples (second half's mean position against the first's) \\[rad/s\\].
    creep: f64,
}

/// The means of a `samples`-step capture taken now.
fn settled(b: &mut impl Bench, samples: u32, dt: f64) -> Result<Settled, Error> {
    let rows = capture_now(b, "pos,current", samples.max(2), dt)?;
    let (_, text) = b.request("capture")?;
    let origin: f64 = text
        .split_whitespace()
        .find_map(|w| w.strip_prefix("origin="))
        .and_then(|v| v.parse().ok())
        .ok_or_else(|| Error::Device(format!("no capture origin in: {text}")))?;
    let mean =
        |r: &[Vec<f64>], c: usize| r.iter().map(|r| r[c]).sum::<f64>() / r.len().max(1) as f64;
    let half = rows.len() / 2;
    let (first, second) = rows.split_at(half);
    let creep = (mean(second, 0) - mean(first, 0)) / (half.max(1) as f64 * dt);
    Ok(Settled {
        x: origin + mean(&rows, 0),
        i: mean(&rows, 1),
        creep,
    })
}

/// The pre-sliding experiment (paper §3, the torque staircase): from rest (a virgin friction
/// state: right after power-up), the current held in current mode is raised by `plan.step`
/// at a time (in ten sub-steps, quasi-statically); after each dwell, the mean position and
/// torque (k_M × the measured current) are recorded, relative to the start, until the axis
/// slides (it creeps faster than `plan.creep` or leaves `plan.window`: that step is not
/// recorded) or `max_steps` were taken. Returns `(x, f)` pairs as `hil-sim experiment
/// presliding` writes them (one direction: only the power-up state is virgin), and ends holding
/// where the axis is.
pub fn presliding(b: &mut impl Bench, plan: &PreslidingPlan) -> Result<Vec<(f64, f64)>, Error> {
    let k_m = get_param(b, "motor.k_m")?;
    let dt = 1.0 / get_param(b, "rate.pos_hz")?;
    b.request("enable")?;
    b.request("current 0")?;
    b.wait(plan.dwell);
    // The start (no torque): the origin of the displacements, not a point of the curve.
    let x0 = settled(b, plan.samples, dt)?.x;
    let mut out = Vec::new();
    for k in 1..=plan.max_steps {
        // Raised in ten small increments, not one: a torque step rings the axis on its
        // pre-sliding stiffness, and the overshoot slips blocks that then hold less than the
        // virgin curve (the paper loads quasi-statically).
        for j in 1..=10 {
            let amps = plan.step * ((k - 1) as f64 + j as f64 / 10.0);
            b.request(&format!("current {amps}"))?;
            b.wait(plan.dwell / 10.0);
        }
        let s = settled(b, plan.samples, dt)?;
        if (s.x - x0).abs() > plan.window || s.creep.abs() > plan.creep {
            break;
        }
        out.push((s.x - x0, k_m * s.i));
    }
    b.request("hold")?;
    Ok(out)
}

/// The frictional-lag run's settings: the speed swings `mean ± amp` [rad/s] at a frequency
/// rising linearly from `f0` to `f1` \\[Hz\\] over `seconds`, recorded every `every` position
/// steps.
#[derive(Debug, Clone)]
pub struct LagPlan {
    /// Mean speed [rad/s] (in sliding: above the Stribeck velocity).
    pub mean: f64,
    /// Swing [rad/s] (below `mean`, so that the axis keeps sliding one way).
    pub amp: f64,
    /// Start frequency \\[Hz\\].
    pub f0: f64,
    /// End frequency \\[Hz\\].
    pub f1: f64,
    /// Duration \\[s\\].
    pub seconds: f64,
    /// Position steps per recorded sample.
    pub every: u32,
}

/// The frictional-lag run (paper §3): a velocity run at `plan.mean`, then the sweep, recorded
/// (position and the loop's friction estimate, k_M × current − J × reference acceleration)
/// from its start. Returns `(t, x, f)` as `hil-sim experiment lag` writes them (t from the
/// sweep's start \\[s\\], x from there \\[rad\\], f [N·m]), and ends holding.
#[allow(clippy::type_complexity)]
pub fn lag(b: &mut impl Bench, plan: &LagPlan) -> Result<(Vec<f64>, Vec<f64>, Vec<f64>), Error> {
    let dt = 1.0 / get_param(b, "rate.pos_hz")?;
    let every = plan.every.max(1);
    let samples = (plan.seconds / (dt * every as f64)).floor() as u32;
    b.request("enable")?;
    b.request(&format!("velocity {}", plan.mean))?;
    b.wait(1.0);
    b.request(&format!("capture pos,friction {every} {samples} next"))?;
    b.request(&format!(
        "velocity {} {} {} {} {}",
        plan.mean, plan.amp, plan.f0, plan.f1, plan.seconds
    ))?;
    b.wait(plan.seconds);
    capture_wait(b, 0.05, 400)?;
    let rows = capture_rows(b)?;
    b.request("hold")?;
    let t = (0..rows.len())
        .map(|k| k as f64 * every as f64 * dt)
        .collect();
    let x = rows.iter().map(|r| r[0]).collect();
    let f = rows.iter().map(|r| r[1]).collect();
    Ok((t, x, f))
}

/// The pre-sliding CSV (`x,f,dir`, as `hil-sim experiment presliding` writes it) of a
/// staircase in the positive direction.
pub fn presliding_csv(data: &[(f64, f64)]) -> String {
    let mut text = String::from("x,f,dir\n");
    for (x, f) in data {
        let dir = if *f < 0.0 { -1 } else { 1 };
        text += &format!("{x},{f},{dir}\n");
    }
    text
}

/// The sliding CSV (`v,f`).
pub fn sliding_csv(data: &[(f64, f64)]) -> String {
    let mut text = String::from("v,f\n");
    for (v, f) in data {
        text += &format!("{v},{f}\n");
    }
    text
}

/// The frictional-lag CSV (`t,x,f`).
pub fn lag_csv(t: &[f64], x: &[f64], f: &[f64]) -> String {
    let mut text = String::from("t,x,f\n");
    for ((t, x), f) in t.iter().zip(x).zip(f) {
        text += &format!("{t},{x},{f}\n");
    }
    text
}
