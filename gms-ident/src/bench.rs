//! The paper's experiments written once against an abstract bench: anything that answers the
//! bench protocol — a board over USB, the virtual device over TCP (`gms-tune`'s link), the
//! device core in-process on the simulated plant (`hil-sim`'s `LocalDevice`). An experiment
//! only sends protocol requests and lets device time pass, so it runs alike on all of them.

use crate::Error;
use crate::units::{num4, si};
use gms_core::device::StatusReply;

/// A device speaking the bench protocol.
pub trait Bench {
    /// Sends one request line; returns the lines before its `ok` and the text after `ok`, or
    /// the device's `err` line as [`Error::Device`].
    fn request(&mut self, line: &str) -> Result<(Vec<String>, String), Error>;
    /// Lets at least `seconds` of device time pass; fails when the run must stop (the link
    /// is lost, the user interrupted it).
    fn wait(&mut self, seconds: f64) -> Result<(), Error>;
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
        b.wait(step)?;
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
    b.wait(samples as f64 * step_s)?;
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

/// The encoder of a firmware older than `enc.counts_per_rev` \[rad/count\]: the paper's
/// 3.8 µrad, then a constant of the device.
pub const PAPER_RAD_PER_COUNT: f64 = 3.8e-6;

/// The device's encoder resolution \[rad/count\]: 2π / `enc.counts_per_rev`, for figures in
/// counts (the device's own, never an assumed encoder; [`PAPER_RAD_PER_COUNT`] on a firmware
/// that predates the parameter).
pub fn rad_per_count(b: &mut impl Bench) -> Result<f64, Error> {
    let counts = match get_param(b, "enc.counts_per_rev") {
        Ok(c) => c,
        // A firmware from before the resolution was a parameter ran the paper's encoder.
        Err(Error::Device(e)) if e.contains("unknown parameter") => {
            return Ok(PAPER_RAD_PER_COUNT);
        }
        Err(e) => return Err(e),
    };
    if !(counts.is_finite() && counts > 0.0) {
        return Err(Error::Device(format!(
            "enc.counts_per_rev: {counts} is not a resolution"
        )));
    }
    Ok(std::f64::consts::TAU / counts)
}

/// The velocity mode's ramp [rad/s²] (the device's `velocity` ramps at `MOVE_AMAX`).
const VELOCITY_ACC: f64 = gms_core::reference::MOVE_AMAX as f64;

/// What the experiments need to know of the device, read with `get` (SI).
#[derive(Debug, Clone, Copy)]
pub struct DeviceInfo {
    /// Torque constant k_M [N·m/A].
    pub k_m: f64,
    /// Position-loop rate \\[Hz\\].
    pub pos_hz: f64,
    /// Current limit \\[A\\].
    pub i_max: f64,
    /// The compensator's static friction, the expected breakaway torque [N·m].
    pub fs: f64,
    /// The compensator's Stribeck velocity [rad/s].
    pub vs: f64,
    /// The encoder's resolution \\[rad/count\\].
    pub rad_per_count: f64,
}

impl DeviceInfo {
    /// Reads the parameters from the device.
    pub fn read(b: &mut impl Bench) -> Result<DeviceInfo, Error> {
        let info = DeviceInfo {
            k_m: get_param(b, "motor.k_m")?,
            pos_hz: get_param(b, "rate.pos_hz")?,
            i_max: get_param(b, "lim.i_max")?,
            fs: get_param(b, "gms.fs")?,
            vs: get_param(b, "gms.vs")?,
            rad_per_count: rad_per_count(b)?,
        };
        let ok = |v: f64| v.is_finite() && v > 0.0;
        if !(ok(info.k_m) && ok(info.pos_hz) && ok(info.i_max) && ok(info.fs) && ok(info.vs)) {
            return Err(Error::Device(format!(
                "the device's parameters cannot plan an experiment: {info:?}"
            )));
        }
        Ok(info)
    }

    /// One position step \\[s\\].
    pub fn dt(&self) -> f64 {
        1.0 / self.pos_hz
    }
}

/// The device's answer to a bench tool that is about to measure: an error when it runs on
/// its built-in defaults (its status says `configured=0`: the encoder's resolution and the
/// sense's scale are the paper's rig's, which no user's axis is), naming what to set.
pub fn check_configured(b: &mut impl Bench) -> Result<(), Error> {
    if !status(b)?.configured {
        return Err(Error::Device(
            "the device runs on its built-in defaults (never configured): set \
             enc.counts_per_rev and sense.v_per_a for this axis, then save (docs/bring-up.md)"
                .into(),
        ));
    }
    Ok(())
}

/// The device's encoder and current sense as one line for a report: counts per revolution,
/// radians per count, volts per ampere.
pub fn scales_line(b: &mut impl Bench) -> Result<String, Error> {
    let counts = get_param(b, "enc.counts_per_rev")?;
    let rpc = rad_per_count(b)?;
    let v_per_a = get_param(b, "sense.v_per_a")?;
    Ok(format!(
        "encoder: {counts} counts/rev ({}/count); current sense: {} V/A",
        si(rpc, "rad"),
        crate::units::num4(v_per_a)
    ))
}

/// The device's `status`, read ([`StatusReply::parse`]: the device core's own format).
pub fn status(b: &mut impl Bench) -> Result<StatusReply, Error> {
    let (_, text) = b.request("status")?;
    StatusReply::parse(&text).map_err(|e| Error::Device(format!("{e}: {text}")))
}

/// The device's latched faults, as an error naming them, if any.
pub fn check_faults(b: &mut impl Bench) -> Result<(), Error> {
    let faults = status(b)?.faults;
    if faults.is_empty() {
        return Ok(());
    }
    let mut names = String::new();
    let _ = faults.write_names(&mut names);
    Err(Error::Device(format!(
        "the device latched a fault ({names})"
    )))
}

/// Runs `f`; if it fails, switches the bridge off (best effort: the link may be gone) and
/// passes the error on.
pub fn guarded<B: Bench, T>(
    b: &mut B,
    f: impl FnOnce(&mut B) -> Result<T, Error>,
) -> Result<T, Error> {
    match f(b) {
        Ok(v) => Ok(v),
        Err(e) => {
            // A latched fault is the reason a later request failed: say which.
            let e = match check_faults(b) {
                Err(Error::Device(fault))
                    if fault.starts_with("the device latched")
                        && !e.to_string().starts_with("the device latched") =>
                {
                    Error::Device(format!("{fault}: {e}"))
                }
                _ => e,
            };
            let _ = b.request("disable");
            Err(e)
        }
    }
}

/// A request of a bench primitive, with a clear error when the device does not know it (a
/// firmware older than the primitives).
fn primitive(b: &mut impl Bench, line: &str) -> Result<(), Error> {
    match b.request(line) {
        Ok(_) => Ok(()),
        // An older parser: the command unknown, or its new argument extra.
        Err(Error::Device(e))
            if e.contains("unknown command") || e.contains("too many arguments") =>
        {
            Err(Error::Device(format!(
                "the device does not know `{}` ({e}): its firmware predates the bench experiments; \
             update it",
                line.split_whitespace().next().unwrap_or(line)
            )))
        }
        Err(e) => Err(e),
    }
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
    /// The shortest averaging window (position steps).
    pub samples: u32,
    /// The stroke averaged over at least \\[rad\\]: at low speeds the window grows to cover
    /// it (the loop's hunting and the encoder counts average out).
    pub window_stroke: f64,
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
            window_stroke: 5e-3,
        }
    }

    /// The plan for an encoder of `rad_per_count` \\[rad\\]: the averaging window covers at
    /// least 50 counts (on the paper's encoder the 5 mrad of [`SlidingPlan::log_spaced`] are
    /// 1300; on a gear motor's 2000 counts/rev 5 mrad would be under two counts, and the
    /// speed read over it a count's worth off).
    pub fn for_encoder(mut self, rad_per_count: f64) -> SlidingPlan {
        self.window_stroke = self.window_stroke.max(200.0 * rad_per_count);
        self
    }

    /// The settling time at speed `v` \\[s\\].
    fn settle(&self, v: f64) -> f64 {
        (self.settle_stroke / v.abs()).max(self.settle_min)
    }

    /// The averaging window at speed `v` \\[s\\].
    fn window(&self, v: f64, dt: f64) -> f64 {
        (self.window_stroke / v.abs()).max(self.samples as f64 * dt)
    }

    /// The device time the run takes, about \\[s\\] (the ramps between speeds and the
    /// exchanges not counted).
    pub fn duration(&self, dt: f64) -> f64 {
        2.0 * self
            .speeds
            .iter()
            .map(|&v| self.settle(v) + self.window(v, dt))
            .sum::<f64>()
    }

    /// The farthest the axis goes from where a speed's run starts \\[rad\\] (each run goes one
    /// way from rest, the next the other way back): the run and its ramps, with 20 % to spare.
    pub fn stroke(&self, dt: f64) -> f64 {
        self.speeds
            .iter()
            .map(|&v| {
                let v = v.abs();
                1.2 * (v * (self.settle(v) + self.window(v, dt) + 0.02) + v * v / VELOCITY_ACC)
            })
            .fold(0.0, f64::max)
    }
}

/// A timed velocity run from rest, captured whole (`fields`, beginning with `t`): `velocity V
/// 0 1 1 SECONDS` — no swing, then a ramp to rest the device makes by itself, so the stroke
/// never depends on the link's timing (a late stop over a slow link, or on a virtual device
/// faster than real time, would overrun the window). Waits for it and its ramps, checks the
/// faults, holds; the rows are then read with [`capture_rows`].
fn timed_run(b: &mut impl Bench, v: f64, seconds: f64, fields: &str, dt: f64) -> Result<(), Error> {
    let t_acc = v.abs() / VELOCITY_ACC;
    let steps = ((seconds + 2.0 * t_acc + 0.01) / dt).ceil();
    // The fields per sample within the 8192 values of the buffer.
    let nf = fields.split(',').count() as f64;
    let every = (steps * nf / 8100.0).ceil().max(1.0);
    let n = (steps / every).ceil() as u32;
    b.request(&format!("capture {fields} {every} {n} next"))?;
    primitive(b, &format!("velocity {v} 0 1 1 {seconds}"))?;
    b.wait(n as f64 * every * dt)?;
    capture_wait(b, 0.01, 200)?;
    check_faults(b)?;
    b.request("hold")?;
    Ok(())
}

/// The sliding experiment (paper §3): at each speed, in both directions, a timed velocity run
/// from rest (the device ends it by itself, so the stroke never depends on the link's
/// timing), captured whole; after the ramp and the settling stroke, the mean friction
/// torque (current × k_M, the loop's own torque constant, at constant speed the whole of the
/// motor torque) and the measured speed (the encoder over the window). Pushes `(v, f)` pairs
/// as `hil-sim experiment sliding` writes them onto `out` as they are measured (so that a run
/// cut short keeps them), and ends holding. Fails (the bridge off) when the axis does not
/// follow the speed (measured below half of it, or the other way) or the device latches a
/// fault.
pub fn sliding(
    b: &mut impl Bench,
    plan: &SlidingPlan,
    out: &mut Vec<(f64, f64)>,
) -> Result<(), Error> {
    guarded(b, |b| {
        let dev = DeviceInfo::read(b)?;
        let dt = dev.dt();
        b.request("enable")?;
        for &v in &plan.speeds {
            for dir in [1.0, -1.0] {
                let v = dir * v;
                // A timed run (`velocity V 0 1 1 SECONDS`: no swing, then a ramp to rest that
                // the device makes by itself, so the stroke never depends on the link's
                // timing: a late stop over a slow link, or on a virtual device faster than
                // real time, would overrun the window), captured whole.
                let t_acc = v.abs() / VELOCITY_ACC;
                timed_run(
                    b,
                    v,
                    plan.settle(v) + plan.window(v, dt) + 0.02,
                    "t,pos,current",
                    dt,
                )?;
                let all = capture_rows(b)?;
                // The averaging window: after the ramp and the settling stroke.
                let (from, to) = (
                    t_acc + plan.settle(v),
                    t_acc + plan.settle(v) + plan.window(v, dt),
                );
                let rows: Vec<Vec<f64>> = all
                    .into_iter()
                    .filter(|r| r[0] >= from && r[0] <= to)
                    .collect();
                let (Some(first), Some(last)) = (rows.first(), rows.last()) else {
                    return Err(Error::Device("an empty capture".into()));
                };
                let span = last[0] - first[0];
                if span <= 0.0 {
                    return Err(Error::Device("a capture without time".into()));
                }
                let v_meas = (last[1] - first[1]) / span;
                if v_meas * v < 0.0 {
                    return Err(Error::Device(format!(
                        "commanded {v} rad/s, the encoder counts {v_meas:.4} rad/s: it counts \
                         against the motor (swap its A and B channels, or the motor leads)"
                    )));
                }
                if v_meas.abs() < 0.5 * v.abs() {
                    return Err(Error::Device(format!(
                        "commanded {v} rad/s, the axis moves at {v_meas:.4} rad/s: it does not \
                         follow (blocked, the motor not connected, or the current limit too low)"
                    )));
                }
                let i_mean = rows.iter().map(|r| r[2]).sum::<f64>() / rows.len() as f64;
                out.push((v_meas, dev.k_m * i_mean));
            }
        }
        b.request("hold")?;
        Ok(())
    })
}

/// The pre-sliding experiment's settings.
#[derive(Debug, Clone)]
pub struct PreslidingPlan {
    /// The current step \\[A\\] (the torque step is this × k_M): small, so that no step
    /// overshoots past breakaway.
    pub step: f64,
    /// The most steps before giving up \\[-\\]: the axis that has not broken away by then does
    /// not move (blocked, or the motor not connected).
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
    /// The stroke from the start beyond which the device itself ends the run \\[rad\\]: its
    /// position limits, narrowed to this for the staircase, switch the bridge off. After
    /// breakaway the current is still held until the host has seen it; over a slow link (or
    /// on a virtual device faster than real time on a loaded host) that is long enough for the
    /// axis to run far. Reaching the guard counts as breakaway (that step is not recorded).
    pub guard: f64,
    /// Erase the friction's memory first \\[-\\]: the position loop swings the axis about its
    /// start, from `window` each way (every block slides) down by 5 % per swing to below
    /// `erase_min`, so that the staircase starts from a near-virgin state even after earlier
    /// motion (commissioning, a previous run), as a decaying alternating field demagnetises.
    pub erase: bool,
    /// The smallest swing of the erase \\[rad\\]: a couple of encoder counts.
    pub erase_min: f64,
}

impl PreslidingPlan {
    /// Steps of `step` \\[A\\], 20 ms of dwell, 100 samples, up to `max_steps`, a stroke window
    /// of 20 mrad, breakaway above 30 mrad/s of creep, the device's guard at 0.5 rad, the
    /// friction's memory erased first down to 4 µrad swings (about a count of the default
    /// encoder).
    pub fn new(step: f64, max_steps: u32) -> PreslidingPlan {
        PreslidingPlan {
            step,
            max_steps,
            dwell: 0.02,
            samples: 100,
            window: 0.02,
            creep: 0.03,
            guard: 0.5,
            erase: true,
            erase_min: 4e-6,
        }
    }

    /// The plan for an encoder of `rad_per_count` \\[rad\\] sampled every `dt` \\[s\\]: on a
    /// coarse one the window holds at least 40 counts, the creep that counts as breakaway is
    /// above 2.5 counts between the halves of the averaged samples (a count's flicker is not a
    /// slide) and the erase ends at two counts. On the paper's encoder nothing changes.
    pub fn for_encoder(mut self, rad_per_count: f64, dt: f64) -> PreslidingPlan {
        let half = (self.samples / 2).max(1) as f64 * dt;
        self.window = self.window.max(40.0 * rad_per_count);
        self.creep = self.creep.max(2.5 * rad_per_count / half);
        self.erase_min = self.erase_min.max(2.0 * rad_per_count);
        self
    }

    /// The device time of `steps` steps and of the erase before them (for a compensator's
    /// Stribeck velocity `vs` [rad/s]), about \\[s\\].
    pub fn duration(&self, steps: u32, dt: f64, vs: f64) -> f64 {
        let staircase = steps as f64 * (self.dwell + self.samples as f64 * dt);
        if !self.erase {
            return staircase;
        }
        // Each swing from one side to the other, then back to the start; a move takes about
        // twice its travel at the cruise speed.
        let (mut travel, mut amp) = (self.window, self.window);
        while amp > self.erase_min {
            travel += amp * (1.0 + ERASE_RATIO);
            amp *= ERASE_RATIO;
        }
        staircase + 2.0 * travel / (ERASE_SPEED * vs)
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
/// recorded). The device's stroke limits are narrowed to `plan.guard` around the start for
/// the run (and put back after): an axis that has broken away stops there with the bridge off
/// however late the host sees it. Pushes `(x, f)` pairs as `hil-sim experiment presliding`
/// writes them (one direction: only the power-up state is virgin) onto `out` as they come,
/// and ends holding where the axis is (or, at the guard, with the bridge off). Fails (the bridge off) when the current does not flow (below half the
/// command: the motor not connected), when the axis moves against the torque (the encoder
/// reversed), when it has not broken away after `max_steps`, or on a fault.
pub fn presliding(
    b: &mut impl Bench,
    plan: &PreslidingPlan,
    out: &mut Vec<(f64, f64)>,
) -> Result<(), Error> {
    // The device's own guard: its stroke limits narrowed around the start.
    let limits = narrow_limits(b, plan.guard)?;
    let result = guarded(b, |b| staircase(b, plan, out));
    restore_limits(b, limits);
    result
}

/// Whether the device's only latched fault is `position_limit` (a guard reached).
fn only_position_limit(b: &mut impl Bench) -> bool {
    matches!(check_faults(b), Err(Error::Device(e)) if e.ends_with("(position_limit)"))
}

/// The staircase of [`presliding`], within the guard set by it.
fn staircase(
    b: &mut impl Bench,
    plan: &PreslidingPlan,
    out: &mut Vec<(f64, f64)>,
) -> Result<(), Error> {
    let dev = DeviceInfo::read(b)?;
    let dt = dev.dt();
    if plan.erase {
        // The encoder's direction first, in current mode: a position loop on a reversed
        // encoder would run away at once.
        if slide(b, &dev, dt)?.moved < 0.0 {
            return Err(Error::Device(
                "the axis moved backwards under a positive current: the encoder counts \
                 against the motor (swap its A and B channels, or the motor leads; or set \
                 enc.dir -1: `gms-tune commission` finds it)"
                    .into(),
            ));
        }
        erase(b, plan, &dev)?;
    }
    // Into current mode, at 0 A.
    primitive(b, "enable current")?;
    b.wait(plan.dwell)?;
    // The start (no torque): the origin of the displacements, not a point of the curve.
    let x0 = settled(b, plan.samples, dt)?.x;
    // A thousandth of the window (20 µrad by default, five counts of a 3.8 µrad
    // encoder): beyond noise and quantisation.
    let against = plan.window / 1000.0;
    for k in 1..=plan.max_steps {
        let amps = plan.step * k as f64;
        if amps > dev.i_max {
            return Err(Error::Device(format!(
                "the axis did not break away below the current limit ({} A, {:.3e} N·m): \
                 blocked, or the motor not connected?",
                dev.i_max,
                dev.k_m * dev.i_max
            )));
        }
        let step = (|| {
            // Raised in ten small increments, not one: a torque step rings the axis on its
            // pre-sliding stiffness, and the overshoot slips blocks that then hold less than
            // the virgin curve (the paper loads quasi-statically).
            for j in 1..=10 {
                let amps = plan.step * ((k - 1) as f64 + j as f64 / 10.0);
                b.request(&format!("current {amps}"))?;
                b.wait(plan.dwell / 10.0)?;
            }
            let s = settled(b, plan.samples, dt)?;
            check_faults(b)?;
            Ok(s)
        })();
        let s = match step {
            Ok(s) => s,
            // The axis reached the guard (it broke away, and ran on until the device
            // stopped it): the end of the staircase, the bridge off.
            Err(_) if only_position_limit(b) => {
                b.request("clear")?;
                return Ok(());
            }
            Err(e) => return Err(e),
        };
        let dx = s.x - x0;
        if k >= 10 && s.i < 0.5 * amps {
            return Err(Error::Device(format!(
                "commanded {amps:.4e} A, measured {:.4e} A: no current flows (the motor \
                 not connected?)",
                s.i
            )));
        }
        if dx < -against {
            return Err(Error::Device(format!(
                "the axis moved {dx:.3e} rad under +{amps:.3e} A: the encoder counts \
                 against the motor (swap its A and B channels, or the motor leads)"
            )));
        }
        if dx.abs() > plan.window || s.creep.abs() > plan.creep {
            b.request("hold")?;
            return Ok(());
        }
        out.push((dx, dev.k_m * s.i));
    }
    Err(Error::Device(format!(
        "the axis did not break away after {} steps ({:.3e} N·m, {:.1} × the expected Fs \
         {:.3e} N·m): blocked, or the motor not connected?",
        plan.max_steps,
        dev.k_m * plan.step * plan.max_steps as f64,
        dev.k_m * plan.step * plan.max_steps as f64 / dev.fs,
        dev.fs
    )))
}

/// The ratio of one erase swing to the one before \\[-\\]: each block is left within
/// ±(1 − r)/(1 + r) of its slip deflection of zero (±2.6 % at 0.95).
const ERASE_RATIO: f64 = 0.95;

/// The erase's speed, a fraction of the compensator's Stribeck velocity \\[-\\].
const ERASE_SPEED: f64 = 0.25;

/// The friction's memory erased about where the axis is: position-loop swings each way,
/// from `plan.window` down by [`ERASE_RATIO`] per swing to below `plan.erase_min`, slowly (at
/// a quarter of the compensator's Vs, near the Stribeck curve's static end: a block that slips
/// faster saturates lower, and its residual grows; at Vs the virgin curves of the property
/// test came out up to 6.1 % of Fs off instead of 4.6 %), then back to the start. A block of
/// the model is an elasto-slip element: a swing beyond its slip deflection resets it, the
/// smaller swings after leave it near zero. About 35 s of device time with the defaults.
fn erase(b: &mut impl Bench, plan: &PreslidingPlan, dev: &DeviceInfo) -> Result<(), Error> {
    let x0 = position(b)?;
    let vel = ERASE_SPEED * dev.vs;
    let mut amp = plan.window;
    let mut side = -1.0;
    while amp > plan.erase_min {
        move_to(b, x0 + side * amp, vel)?;
        amp *= ERASE_RATIO;
        side = -side;
    }
    move_to(b, x0, vel)
}

/// Moves the axis to `x` \\[rad\\] (the protocol's position) in the position loop at up to `vel`
/// [rad/s] and waits until the move has ended; fails (the bridge off) on a fault or when it
/// has not ended in four times the time at `vel`.
pub fn move_to(b: &mut impl Bench, x: f64, vel: f64) -> Result<(), Error> {
    guarded(b, |b| {
        b.request("enable")?;
        let from = position(b)?;
        b.request(&format!("move {x} {vel}"))?;
        // A quintic from rest to rest peaks at 1.875 × its mean speed: about twice the time
        // at `vel`; then up to twice that again.
        let t = 2.0 * (x - from).abs() / vel + 0.02;
        b.wait(t)?;
        for _ in 0..100 {
            if !status(b)?.moving {
                return check_faults(b);
            }
            b.wait(t / 50.0)?;
        }
        check_faults(b)?;
        Err(Error::Device(format!("the move to {x} rad did not end")))
    })
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

/// The fewest counts the lag run's position swing must span at its top frequency for the
/// record to show the lag (it shows where the swing is smallest).
pub const LAG_MIN_SWING_COUNTS: f64 = 20.0;

impl LagPlan {
    /// The position swing at the sweep's top frequency, in counts of an encoder of
    /// `rad_per_count` \\[rad\\]: amp / (2π f1) (the paper's encoder: 2500 counts for Vs
    /// 0.2 rad/s; a 2000 counts/rev gear motor: 3 for Vs 1 rad/s).
    pub fn swing_counts(&self, rad_per_count: f64) -> f64 {
        self.amp / (2.0 * std::f64::consts::PI * self.f1) / rad_per_count
    }

    /// The paper's run for a Stribeck velocity `vs` [rad/s]: around 1.5 Vs, ± 1.2 Vs, 0.2 to
    /// 20 Hz over 4 s, recorded at 1 kHz for a position loop at `pos_hz` \\[Hz\\].
    pub fn for_vs(vs: f64, pos_hz: f64) -> LagPlan {
        LagPlan {
            mean: 1.5 * vs,
            amp: 1.2 * vs,
            f0: 0.2,
            f1: 20.0,
            seconds: 4.0,
            every: (pos_hz / 1000.0).round().max(1.0) as u32,
        }
    }

    /// The device time the run takes, about \\[s\\] (1 s at the mean speed first).
    pub fn duration(&self) -> f64 {
        1.0 + self.seconds
    }

    /// The stroke it covers \\[rad\\] (one way).
    pub fn stroke(&self) -> f64 {
        self.mean * self.duration()
    }
}

/// The frictional-lag run (paper §3): a velocity run at `plan.mean`, then the sweep, recorded
/// (position and the loop's friction estimate, k_M × current − J × reference acceleration)
/// from its start. Returns `(t, x, f)` as `hil-sim experiment lag` writes them (t from the
/// sweep's start \\[s\\], x from there \\[rad\\], f [N·m]), and ends holding.
#[allow(clippy::type_complexity)]
pub fn lag(b: &mut impl Bench, plan: &LagPlan) -> Result<(Vec<f64>, Vec<f64>, Vec<f64>), Error> {
    guarded(b, |b| {
        let dt = DeviceInfo::read(b)?.dt();
        let every = plan.every.max(1);
        let samples = (plan.seconds / (dt * every as f64)).floor() as u32;
        b.request("enable")?;
        primitive(b, &format!("velocity {}", plan.mean))?;
        b.wait(1.0)?;
        b.request(&format!("capture pos,friction {every} {samples} next"))?;
        b.request(&format!(
            "velocity {} {} {} {} {}",
            plan.mean, plan.amp, plan.f0, plan.f1, plan.seconds
        ))?;
        b.wait(plan.seconds)?;
        capture_wait(b, 0.05, 400)?;
        check_faults(b)?;
        let rows = capture_rows(b)?;
        b.request("hold")?;
        let t = (0..rows.len())
            .map(|k| k as f64 * every as f64 * dt)
            .collect();
        let x = rows.iter().map(|r| r[0]).collect();
        let f = rows.iter().map(|r| r[1]).collect();
        Ok((t, x, f))
    })
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

/// The axis's position from `status` \\[rad\\] (from the power-up position, as the stroke
/// limits `lim.pos_min`/`lim.pos_max` are).
pub fn position(b: &mut impl Bench) -> Result<f64, Error> {
    Ok(status(b)?.pos)
}

/// The experiments' ranges as a user gives them; `None`: derived from the device's
/// parameters (its compensator's Fs and Vs).
#[derive(Debug, Clone, Default)]
pub struct Ranges {
    /// The staircase's torque step [N·m] (default: the device's Fs / 100).
    pub torque_step: Option<f64>,
    /// The slowest sliding speed [rad/s] (default: the device's Vs / 10).
    pub v_min: Option<f64>,
    /// The fastest sliding speed [rad/s] (default: 30 × the device's Vs).
    pub v_max: Option<f64>,
    /// The number of sliding speeds (default 10).
    pub speeds: Option<usize>,
    /// The stroke window around the start, each way \\[rad\\] (default 5): the device's stroke
    /// limits are narrowed to it while the experiments run.
    pub window: Option<f64>,
    /// Skip the erase of the friction's memory before the staircase (right after power-up
    /// the state is virgin already; the erase takes about 35 s).
    pub no_erase: bool,
}

/// The three experiments planned for a device.
#[derive(Debug, Clone)]
pub struct Plans {
    /// The torque staircase.
    pub presliding: PreslidingPlan,
    /// The velocity sweep.
    pub sliding: SlidingPlan,
    /// The stroke window each way \\[rad\\].
    pub window: f64,
}

impl Plans {
    /// Plans from `ranges` and the device's parameters; refuses ranges that are not positive
    /// and finite, a torque step the staircase would take over 1000 steps or under 10 to
    /// climb to the expected Fs, speeds the window cannot hold, or speeds above the device's
    /// velocity mode (20 rad/s).
    pub fn new(dev: &DeviceInfo, ranges: &Ranges) -> Result<Plans, Error> {
        let bad = |what: &str, v: f64| {
            Error::Params(format!("{what} = {v}: not a positive finite number"))
        };
        let pos = |what: &str, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(v)
            } else {
                Err(bad(what, v))
            }
        };
        let step_t = pos("torque step", ranges.torque_step.unwrap_or(dev.fs / 100.0))?;
        let steps_to_fs = dev.fs / step_t;
        if !(10.0..=1000.0).contains(&steps_to_fs) {
            return Err(Error::Params(format!(
                "torque step {step_t:.3e} N·m: the staircase would take {steps_to_fs:.0} steps to \
                 the expected Fs {:.3e} N·m (10 to 1000)",
                dev.fs
            )));
        }
        let v_min = pos("slowest speed", ranges.v_min.unwrap_or(dev.vs / 10.0))?;
        let v_max = pos("fastest speed", ranges.v_max.unwrap_or(30.0 * dev.vs))?;
        if v_min >= v_max || v_max > 20.0 {
            return Err(Error::Params(format!(
                "speeds {v_min} to {v_max} rad/s: the slowest must be below the fastest, the \
                 fastest at most 20 rad/s"
            )));
        }
        let n = ranges.speeds.unwrap_or(10);
        if !(4..=50).contains(&n) {
            return Err(Error::Params(format!("{n} speeds: 4 to 50")));
        }
        let window = pos("stroke window", ranges.window.unwrap_or(5.0))?;
        let mut presliding =
            PreslidingPlan::new(step_t / dev.k_m, 0).for_encoder(dev.rad_per_count, dev.dt());
        // Up to three times the expected breakaway: an axis that holds more is blocked.
        presliding.max_steps = (3.0 * steps_to_fs).ceil() as u32;
        presliding.erase = !ranges.no_erase;
        presliding.window = presliding.window.min(window);
        let sliding = SlidingPlan::log_spaced(v_min, v_max, n).for_encoder(dev.rad_per_count);
        let need = sliding.stroke(dev.dt());
        if need > window {
            return Err(Error::Params(format!(
                "the sliding run at {v_max} rad/s needs {need:.2} rad of stroke, more than the \
                 window {window} rad: lower the fastest speed or widen the window"
            )));
        }
        Ok(Plans {
            presliding,
            sliding,
            window,
        })
    }
}

/// A sine test with reversals: the axis swings `amp` \\[rad\\] to and fro from where it is
/// (velocity mode, a sweep of one frequency `freq` \\[Hz\\] around zero speed) for `seconds`;
/// the position error is captured and its RMS \\[rad\\] returned, leaving out the first period.
/// The same test on the same device gives the same reference: compensations compare on it.
/// Ends holding.
pub fn sine_test(b: &mut impl Bench, amp: f64, freq: f64, seconds: f64) -> Result<f64, Error> {
    if !(amp > 0.0 && amp.is_finite() && freq > 0.0 && freq.is_finite() && seconds * freq >= 2.0) {
        return Err(Error::Params(format!(
            "sine test: amplitude {amp} rad, {freq} Hz, {seconds} s: positive, and at least two \
             periods"
        )));
    }
    guarded(b, |b| {
        let dev = DeviceInfo::read(b)?;
        let every = (seconds * dev.pos_hz / 8000.0).ceil().max(1.0) as u32;
        let samples = (seconds * dev.pos_hz / every as f64).floor() as u32;
        let v_amp = amp * 2.0 * std::f64::consts::PI * freq;
        b.request("enable")?;
        b.request(&format!("capture error {every} {samples} next"))?;
        primitive(b, &format!("velocity 0 {v_amp} {freq} {freq} {seconds}"))?;
        b.wait(seconds)?;
        capture_wait(b, 0.05, 400)?;
        check_faults(b)?;
        b.request("hold")?;
        let rows = capture_rows(b)?;
        let skip = ((dev.pos_hz / freq) / every as f64).ceil() as usize;
        let e: Vec<f64> = rows.iter().skip(skip).map(|r| r[0]).collect();
        if e.is_empty() {
            return Err(Error::Device("the sine test recorded nothing".into()));
        }
        Ok((e.iter().map(|v| v * v).sum::<f64>() / e.len() as f64).sqrt())
    })
}

/// The device's stroke limits narrowed to `window` each way around where the axis is;
/// returns the previous ones.
pub fn narrow_limits(b: &mut impl Bench, window: f64) -> Result<(f64, f64), Error> {
    let (lo, hi) = (get_param(b, "lim.pos_min")?, get_param(b, "lim.pos_max")?);
    let x = position(b)?;
    let (nlo, nhi) = ((x - window).max(lo), (x + window).min(hi));
    // Narrowing each side keeps pos_min < pos_max after each set.
    b.request(&format!("set lim.pos_min {nlo}"))?;
    b.request(&format!("set lim.pos_max {nhi}"))?;
    Ok((lo, hi))
}

/// The stroke limits `(pos_min, pos_max)` \\[rad\\] that [`narrow_limits`] returned put back,
/// widening each side (best effort: the link may be gone).
pub fn restore_limits(b: &mut impl Bench, (lo, hi): (f64, f64)) {
    let _ = b.request(&format!("set lim.pos_min {lo}"));
    let _ = b.request(&format!("set lim.pos_max {hi}"));
}

/// What a bench identification gathered.
#[derive(Debug, Clone, Default)]
pub struct Gathered {
    /// Pre-sliding `(x, f)` points.
    pub presliding: Vec<(f64, f64)>,
    /// Sliding `(v, f)` points.
    pub sliding: Vec<(f64, f64)>,
    /// The lag run `(t, x, f)`, once done.
    pub lag: Option<(Vec<f64>, Vec<f64>, Vec<f64>)>,
}

/// The whole bench identification: the stroke limits narrowed to the plans' window, the
/// pre-sliding staircase, a move back to the start, the sliding sweep, the lag run around the Vs just measured; then,
/// whatever happened, the bridge off, the limits back and the data written to `dir`
/// (`presliding.csv`, `sliding.csv`, `lag.csv`: what `hil-sim identify` reads), and on
/// success the identification of those files (`blocks`, `asymmetric` as `hil-sim identify`
/// takes them). `stage(b, name, seconds)` is called as each experiment starts, with its
/// expected device time (for progress). A failure says how much data was kept, and where.
pub fn identify_on<B: Bench>(
    b: &mut B,
    plans: &Plans,
    dir: &std::path::Path,
    blocks: usize,
    asymmetric: bool,
    stage: &mut dyn FnMut(&mut B, &str, f64),
) -> Result<(Gathered, crate::identify::Identified), Error> {
    let mut g = Gathered::default();
    let dev = DeviceInfo::read(b)?;
    let dt = dev.dt();
    let limits = narrow_limits(b, plans.window);
    let mut lag_skipped: Option<f64> = None;
    let result = limits.clone().map(|_| ()).and_then(|_| {
        let steps = (dev.fs / (dev.k_m * plans.presliding.step)).ceil() as u32;
        stage(
            b,
            "pre-sliding",
            plans.presliding.duration(steps, dt, dev.vs),
        );
        let x_start = position(b)?;
        presliding(b, &plans.presliding, &mut g.presliding)?;
        // Back to the start, so that the sliding runs have their planned stroke each way.
        move_to(b, x_start, 1.0)?;
        stage(b, "sliding", plans.sliding.duration(dt));
        sliding(b, &plans.sliding, &mut g.sliding)?;
        // The lag run around the Vs just measured.
        let (v, f): (Vec<f64>, Vec<f64>) =
            g.sliding.iter().map(|(v, f)| (v.abs(), f.abs())).unzip();
        let vs = crate::identify::fit_stribeck(&v, &f)
            .map_err(|e| Error::Data(format!("the sliding data do not fit: {e}")))?
            .vs;
        let plan = LagPlan::for_vs(vs, dev.pos_hz);
        let swing = plan.swing_counts(dev.rad_per_count);
        if swing < LAG_MIN_SWING_COUNTS {
            // The lag shows at the sweep's top, where the encoder cannot see it: no run.
            lag_skipped = Some(swing);
            return Ok(());
        }
        if plan.stroke() > plans.window {
            return Err(Error::Params(format!(
                "the lag run needs {:.2} rad of stroke, more than the window {} rad: widen it",
                plan.stroke(),
                plans.window
            )));
        }
        stage(b, "lag", plan.duration());
        g.lag = Some(lag(b, &plan)?);
        Ok(())
    });
    // Whatever happened: the bridge off, the limits back (best effort: the link may be gone).
    let _ = b.request("disable");
    if let Ok(l) = limits {
        restore_limits(b, l);
    }
    let written = (|| {
        std::fs::create_dir_all(dir)
            .map_err(|e| format!("{}: cannot create: {e}", dir.display()))?;
        let w = |name: &str, text: &str| {
            let p = dir.join(name);
            crate::io::write_atomic(&p, text.as_bytes()).map(|_| p)
        };
        let pre = w("presliding.csv", &presliding_csv(&g.presliding))?;
        let slide = w("sliding.csv", &sliding_csv(&g.sliding))?;
        let lag = match &g.lag {
            Some((t, x, f)) => Some(w("lag.csv", &lag_csv(t, x, f))?),
            None => None,
        };
        Ok::<_, String>((pre, slide, lag))
    })();
    let kept = || {
        format!(
            "the bridge is off; the data so far ({} pre-sliding points, {} sliding points) is in {}",
            g.presliding.len(),
            g.sliding.len(),
            dir.display()
        )
    };
    if let Err(e) = result {
        let kept = match &written {
            Ok(_) => kept(),
            Err(w) => format!("the bridge is off; the data could not be written: {w}"),
        };
        return Err(match e {
            Error::Device(m) => Error::Device(format!("{m}; {kept}")),
            Error::Params(m) => Error::Params(format!("{m}; {kept}")),
            Error::Data(m) => Error::Data(format!("{m}; {kept}")),
            Error::Io(m) => Error::Io(format!("{m}; {kept}")),
        });
    }
    let (pre, slide, lag) = written.map_err(Error::Io)?;
    let mut id = crate::identify::identify_from(&crate::identify::Inputs {
        presliding: Some(&pre),
        sliding: Some(&slide),
        lag: lag.as_deref(),
        blocks,
        asymmetric,
    })?;
    if let Some(swing) = lag_skipped {
        id.report.push(format!(
            "frictional lag: not measured: the sweep's swing at its top frequency would be \
             {swing:.1} counts of this encoder (fewer than {LAG_MIN_SWING_COUNTS}), too few to \
             show the lag; C by the paper's rule"
        ));
    }
    Ok((g, id))
}

/// Sends a parameter file to the device: its `[friction]` (a GMS model of 1 to 6 blocks, the
/// compensator's) as `gms.*` (with `gms.blocks` when fewer than 6), its `[device]` table by protocol path, staged and committed as
/// one set (weights that must sum to 1 cannot change one `set` at a time), so the device
/// takes all or nothing. A firmware without staging gets one `set` at a time, retried while
/// that makes progress. Returns the number of parameters sent.
pub fn load_params(b: &mut impl Bench, pf: &crate::paramfile::ParamFile) -> Result<usize, Error> {
    use crate::paramfile::ModelKind;
    let f = &pf.friction;
    let n = f.blocks.as_ref().map_or(0, Vec::len);
    if f.negative.is_some() {
        return Err(Error::Params(
            "[friction.negative]: the device's compensator has one Stribeck curve for both \
             directions; nothing loaded (fit without --asymmetric, or remove the table)"
                .into(),
        ));
    }
    if f.model != ModelKind::Gms || !(1..=6).contains(&n) {
        return Err(Error::Params(format!(
            "[friction] must be a gms model of 1 to 6 blocks for the device's compensator \
             (it is {} with {n} blocks)",
            f.model
        )));
    }
    f.gms_params::<6>()
        .map_err(|e| e.to_string())
        .and_then(|p| p.validate().map_err(|e| e.to_string()))
        .map_err(|e| Error::Params(format!("[friction] {e}")))?;
    let mut sets: Vec<(String, String)> = Vec::new();
    if n < 6 {
        // First: the blocks past n become unused, then the n blocks are set.
        sets.push(("gms.blocks".into(), format!("{n}")));
    }
    for (k, v) in [
        ("fs", f.fs),
        ("fc", f.fc),
        ("vs", f.vs),
        ("delta", f.delta.or(Some(1.0))),
        ("sigma", f.sigma.or(Some(0.0))),
        ("c", f.c),
    ] {
        if let Some(v) = v {
            sets.push((format!("gms.{k}"), format!("{v}")));
        }
    }
    for (i, blk) in f.blocks.iter().flatten().enumerate() {
        sets.push((format!("gms.k{}", i + 1), format!("{}", blk.k)));
        sets.push((format!("gms.a{}", i + 1), format!("{}", blk.alpha)));
    }
    for (k, v) in pf.device.iter().flatten() {
        let v = match v {
            toml::Value::Float(x) => format!("{x}"),
            toml::Value::Integer(x) => format!("{x}"),
            toml::Value::String(s) => s.clone(),
            _ => return Err(Error::Params(format!("[device] `{k}` is not a value"))),
        };
        sets.push((k.clone(), v));
    }
    let n = sets.len();
    match b.request("discard") {
        Ok(_) => {
            for (k, v) in &sets {
                if let Err(e) = b.request(&format!("stage {k} {v}")) {
                    let _ = b.request("discard");
                    return Err(Error::Device(format!(
                        "stage {k} {v}: {e} (nothing changed)"
                    )));
                }
            }
            b.request("commit")
                .map_err(|e| Error::Device(format!("commit: {e} (nothing changed)")))?;
            return Ok(n);
        }
        // A firmware without staging: one `set` at a time.
        Err(Error::Device(e)) if e.contains("err 1 ") => {}
        Err(e) => return Err(e),
    }
    // A set may be refused while others are pending (fs below the old fc, say): retry until
    // no progress.
    let mut last_err = String::new();
    while !sets.is_empty() {
        let before = sets.len();
        let mut rest = Vec::new();
        for (k, v) in sets {
            match b.request(&format!("set {k} {v}")) {
                Ok(_) => {}
                Err(Error::Device(e)) => {
                    last_err = format!("set {k} {v}: {e}");
                    rest.push((k, v));
                }
                Err(e) => return Err(e),
            }
        }
        if rest.len() == before {
            return Err(Error::Device(last_err));
        }
        sets = rest;
    }
    Ok(n)
}

/// The feedforward-gain tuning's settings: the sine test (amplitude \\[rad\\], frequency
/// \\[Hz\\], duration \\[s\\]); a coarse sweep of `steps` gains from `from` to `to` \\[-\\] (widened
/// when its lowest point is at an edge); then a refinement of `fine_steps` gains around the
/// coarse optimum, each tested `repeats` times.
#[derive(Debug, Clone, PartialEq)]
pub struct TuneFfPlan {
    /// Sine amplitude \\[rad\\].
    pub amp: f64,
    /// Sine frequency \\[Hz\\].
    pub freq: f64,
    /// Each test's duration \\[s\\].
    pub seconds: f64,
    /// The coarse sweep's lowest gain \\[-\\].
    pub from: f64,
    /// The coarse sweep's highest gain \\[-\\].
    pub to: f64,
    /// The coarse sweep's gains, evenly spaced (≥ 4).
    pub steps: usize,
    /// The refinement's gains (≥ 4).
    pub fine_steps: usize,
    /// Tests at each of the refinement's gains (≥ 1).
    pub repeats: usize,
}

impl Default for TuneFfPlan {
    /// 2 mrad at 1 Hz for 3 s; 0.5 to 1.3 in 9 gains; 9 gains twice around the optimum.
    fn default() -> Self {
        TuneFfPlan {
            amp: 2e-3,
            freq: 1.0,
            seconds: 3.0,
            from: 0.5,
            to: 1.3,
            steps: 9,
            fine_steps: 9,
            repeats: 2,
        }
    }
}

/// How far the coarse range may be widened, each time by half its span.
pub const TUNE_FF_WIDENINGS: usize = 3;

/// The standard error of the optimum above which the curve is too flat to choose \\[-\\].
pub const TUNE_FF_FLAT_SE: f64 = 0.05;

impl TuneFfPlan {
    /// Checks the plan: a valid sine test, 0 ≤ from < to ≤ 2 (the protocol's range of
    /// `ff.gain`), 4 to 101 coarse and fine gains, 1 to 10 repeats.
    pub fn check(&self) -> Result<(), Error> {
        let sine_ok = self.amp > 0.0
            && self.amp.is_finite()
            && self.freq > 0.0
            && self.freq.is_finite()
            && self.seconds * self.freq >= 2.0
            && self.seconds <= 60.0;
        if !sine_ok {
            return Err(Error::Params(format!(
                "sine test {} rad, {} Hz, {} s: positive, at least two periods, at most 60 s",
                self.amp, self.freq, self.seconds
            )));
        }
        let range_ok = 0.0 <= self.from && self.from < self.to && self.to <= 2.0;
        if !(range_ok && (4..=101).contains(&self.steps)) {
            return Err(Error::Params(format!(
                "gains {} to {} in {} steps: 0 <= from < to <= 2, 4 to 101 steps",
                self.from, self.to, self.steps
            )));
        }
        if !((4..=101).contains(&self.fine_steps) && (1..=10).contains(&self.repeats)) {
            return Err(Error::Params(format!(
                "refinement of {} gains × {} repeats: 4 to 101 gains, 1 to 10 repeats",
                self.fine_steps, self.repeats
            )));
        }
        Ok(())
    }

    /// The coarse sweep's gains.
    pub fn gains(&self) -> Vec<f64> {
        spaced(self.from, self.to, self.steps)
    }

    /// The sine tests of a tuning without widening, and the device time they take (each test
    /// plus about 0.3 s of set-up) \\[s\\].
    pub fn tests(&self) -> (usize, f64) {
        let n = self.steps + self.fine_steps * self.repeats;
        (n, n as f64 * (self.seconds + 0.3))
    }
}

/// `n` evenly spaced values from `a` to `b`.
fn spaced(a: f64, b: f64, n: usize) -> Vec<f64> {
    (0..n)
        .map(|i| a + (b - a) * i as f64 / (n.max(2) - 1) as f64)
        .collect()
}

/// What the tuning found.
#[derive(Debug, Clone, PartialEq)]
pub struct TuneFf {
    /// `(gain, RMS error [rad])` of every test, in the order run (coarse, then refinement).
    pub curve: Vec<(f64, f64)>,
    /// The coarse sweep's range after any widening \\[-\\].
    pub range: (f64, f64),
    /// The refinement's window \\[-\\].
    pub window: (f64, f64),
    /// The optimum fitted to the refinement (mean-square parabola, its vertex and standard
    /// error: [`crate::optimum::fit_minimum`]); `None` when the curve has no minimum there.
    pub optimum: Option<crate::optimum::Optimum>,
    /// Whether the optimum is clear enough to choose: it exists, lies within the refinement's
    /// window, and its standard error is below [`TUNE_FF_FLAT_SE`].
    pub decided: bool,
    /// The gain to use \\[-\\]: the optimum when decided, else the device's gain as it was.
    pub chosen: f64,
    /// The gain the device had before \\[-\\].
    pub before: f64,
    /// What the tuning did or found beyond the plan, a sentence each (widening, flatness).
    pub notes: Vec<String>,
    /// The device's encoder resolution \[rad/count\] (for errors in counts).
    pub rad_per_count: f64,
}

/// The feedforward gain by experiment. The same sine test with reversals at each gain; a
/// coarse sweep, widened by half its span on the side of its lowest point while that point
/// is at an edge (at most [`TUNE_FF_WIDENINGS`] times, within 0..2); then a refinement
/// around the coarse optimum, over the window where the fitted mean square rises to about
/// twice its minimum, every gain tested `repeats` times (alternately up and down the
/// window); the optimum is the vertex of the mean-square parabola fitted to the refinement,
/// with its standard error ([`crate::optimum`]). Leaves the device at `before` (the caller
/// applies `chosen` if asked), holding; on a failure the gain goes back and the bridge off.
/// `progress(test, gain, rms)` after each test.
pub fn tune_ff(
    b: &mut impl Bench,
    plan: &TuneFfPlan,
    mut progress: impl FnMut(usize, f64, f64),
) -> Result<TuneFf, Error> {
    use crate::optimum::fit_minimum;
    plan.check()?;
    let before = get_param(b, "ff.gain")?;
    let rpc = rad_per_count(b)?;
    let r = guarded(b, |b| {
        let mut curve: Vec<(f64, f64)> = Vec::new();
        let mut notes = Vec::new();
        let mut test = |b: &mut _, g: f64, curve: &mut Vec<(f64, f64)>| -> Result<(), Error> {
            b_set_gain(b, g)?;
            let rms = sine_test(b, plan.amp, plan.freq, plan.seconds)?;
            progress(curve.len(), g, rms);
            curve.push((g, rms));
            Ok(())
        };
        // The coarse sweep, widened while its lowest point sits at an edge.
        let (mut lo, mut hi) = (plan.from, plan.to);
        let step = (plan.to - plan.from) / (plan.steps - 1) as f64;
        for g in plan.gains() {
            test(b, g, &mut curve)?;
        }
        for _ in 0..TUNE_FF_WIDENINGS {
            let Some(&(g_min, _)) = curve.iter().min_by(|a, b| a.1.total_cmp(&b.1)) else {
                break;
            };
            let half = 0.5 * (hi - lo);
            let n_new = ((half / step).round() as usize).max(1);
            let new: Vec<f64> = if g_min <= lo + 1e-9 && lo > 0.0 {
                let from = (lo - n_new as f64 * step).max(0.0);
                let gs: Vec<f64> = (1..=n_new)
                    .map(|i| lo - i as f64 * step)
                    .filter(|g| *g >= from - 1e-9)
                    .collect();
                notes.push(format!(
                    "the lowest error was at the range's low end ({lo:.3}): widened down to {:.3}",
                    from.max(0.0)
                ));
                lo = from.max(0.0);
                gs
            } else if g_min >= hi - 1e-9 && hi < 2.0 {
                let to = (hi + n_new as f64 * step).min(2.0);
                let gs: Vec<f64> = (1..=n_new)
                    .map(|i| hi + i as f64 * step)
                    .filter(|g| *g <= to + 1e-9)
                    .collect();
                notes.push(format!(
                    "the lowest error was at the range's high end ({hi:.3}): widened up to {to:.3}"
                ));
                hi = to;
                gs
            } else {
                break;
            };
            for g in new {
                test(b, g.clamp(0.0, 2.0), &mut curve)?;
            }
        }
        // The refinement: where the coarse parabola rises to about twice its minimum.
        let coarse = fit_minimum(&curve);
        let best = curve
            .iter()
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .map_or(before, |p| p.0);
        let (centre, half) = match coarse {
            Some(o) if o.at >= lo && o.at <= hi => {
                (o.at, (o.min / o.curvature).sqrt().clamp(0.1, 0.4))
            }
            _ => (best, 0.2),
        };
        let (w_lo, w_hi) = ((centre - half).max(0.0), (centre + half).min(2.0));
        let fine = spaced(w_lo, w_hi, plan.fine_steps);
        let start = curve.len();
        for r in 0..plan.repeats {
            let order: Vec<f64> = if r % 2 == 0 {
                fine.clone()
            } else {
                fine.iter().rev().copied().collect()
            };
            for g in order {
                test(b, g, &mut curve)?;
            }
        }
        let optimum = fit_minimum(&curve[start..]);
        Ok((curve, (lo, hi), (w_lo, w_hi), optimum, notes))
    });
    // The gain as it was, whatever happened (best effort after a failure).
    let restored = b.request(&format!("set ff.gain {before}"));
    let (curve, range, window, optimum, mut notes) = r?;
    restored?;
    let (decided, note) = decide(optimum, window);
    notes.extend(note);
    let chosen = match optimum {
        Some(o) if decided => o.at,
        _ => before,
    };
    Ok(TuneFf {
        curve,
        range,
        window,
        optimum,
        decided,
        chosen,
        before,
        notes,
        rad_per_count: rpc,
    })
}

/// Whether a fitted optimum is clear enough to choose: it exists, lies within the
/// refinement's `window`, and its standard error is at most [`TUNE_FF_FLAT_SE`]; otherwise
/// the note that says why not.
pub fn decide(
    optimum: Option<crate::optimum::Optimum>,
    window: (f64, f64),
) -> (bool, Option<String>) {
    match optimum {
        None => (
            false,
            Some(
                "the refinement's errors have no minimum (the curve is flat or falls): no gain \
                 chosen"
                    .into(),
            ),
        ),
        Some(o) if o.at < window.0 || o.at > window.1 => (
            false,
            Some(format!(
                "the fitted optimum {:.3} lies outside the refinement's window {:.3} to {:.3}: \
                 no gain chosen (try a range around it)",
                o.at, window.0, window.1
            )),
        ),
        Some(o) if o.se > TUNE_FF_FLAT_SE => (
            false,
            Some(format!(
                "the curve is too flat to choose: the optimum {:.3} has a standard error of \
                 {:.3} (over {TUNE_FF_FLAT_SE})",
                o.at, o.se
            )),
        ),
        Some(_) => (true, None),
    }
}

/// `set ff.gain G`.
fn b_set_gain(b: &mut impl Bench, g: f64) -> Result<(), Error> {
    b.request(&format!("set ff.gain {g}")).map(|_| ())
}

/// What commissioning measured and decided.
#[derive(Debug, Clone, Default)]
pub struct Commissioned {
    /// The current sense's residual offset at rest, bridge off \\[A\\] (after the start-up zero).
    pub sense_offset: f64,
    /// Its noise at rest, one standard deviation per position step \\[A\\].
    pub sense_noise: f64,
    /// The current-sense polarity found (`sense.dir`) \\[-\\].
    pub sense_dir: f64,
    /// The encoder direction found (`enc.dir`) \\[-\\].
    pub enc_dir: f64,
    /// Winding resistance \\[ohm\\].
    pub r: f64,
    /// Back-EMF constant [V·s/rad] (= k_M in SI).
    pub k_e: f64,
    /// Reflected inertia [kg·m²].
    pub inertia: f64,
    /// Winding inductance \\[H\\].
    pub inductance: f64,
    /// The current of the pulse that first slid the axis \\[A\\] (an upper bound of the
    /// breakaway current within a quarter of it; × k_M: the breakaway torque).
    pub breakaway_a: f64,
    /// The device's friction model scaled to the measured breakaway, when the axis broke away
    /// at more than 1.5 × (or less than 1/1.5 of) what the model expects: `gms.fs`, `gms.fc`,
    /// `gms.sigma`, `gms.c` and the block stiffnesses times one factor (the shape stays the
    /// model's until `identify`; the experiments that plan from the model then fit the axis).
    pub friction_scaled: Vec<(&'static str, f64)>,
    /// Current-loop PI from the bandwidth (`cur.kp` [V/A], `cur.ki` [V/(A·s)]).
    pub cur_pi: (f64, f64),
    /// The position loop's gains and their bounds (once that step has run).
    pub pos: Option<crate::gains::PositionGains>,
    /// What was done, a line per step.
    pub lines: Vec<String>,
}

impl Commissioned {
    /// The `[device]` settings by protocol path.
    pub fn settings(&self) -> Vec<(&'static str, f64)> {
        vec![
            ("sense.dir", self.sense_dir),
            ("enc.dir", self.enc_dir),
            ("motor.r", self.r),
            ("motor.k_e", self.k_e),
            ("motor.k_m", self.k_e),
            ("ff.inertia", self.inertia),
            ("cur.kp", self.cur_pi.0),
            ("cur.ki", self.cur_pi.1),
        ]
        .into_iter()
        .chain(
            self.pos
                .iter()
                .flat_map(|g| [("pos.kp", g.kp), ("pos.ki", g.ki), ("pos.kd", g.kd)]),
        )
        .chain(self.friction_scaled.iter().copied())
        .collect()
    }
}

/// The means of the columns of `rows`.
fn means(rows: &[Vec<f64>]) -> Vec<f64> {
    let n = rows.len().max(1) as f64;
    let w = rows.first().map_or(0, Vec::len);
    (0..w)
        .map(|c| rows.iter().map(|r| r[c]).sum::<f64>() / n)
        .collect()
}

/// What [`slide`] found: which way the encoder counts when the motor pushes, and the pulse
/// that broke the axis away.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Slide {
    /// The signed slide \\[rad\\] (negative: the encoder counts against the motor).
    pub moved: f64,
    /// The current of the pulse that moved the axis \\[A\\] (the one before it held): an
    /// upper bound of the breakaway current, within a quarter of it.
    pub amps: f64,
}

/// How far a pulse must move the axis to count as a slide \\[rad\\]: 2 mrad (beyond the
/// pre-sliding range, which a stiff or blocked axis travels too) or eight counts of the
/// encoder, whichever is more.
pub fn slide_threshold(rad_per_count: f64) -> f64 {
    (8.0 * rad_per_count).max(2e-3)
}

/// Which way the encoder counts when the motor pushes, and at what current the axis breaks
/// away: in current mode, pulses of current that the device ends by itself after 10 ms (so a
/// slow link cannot hold the current on a sliding axis), from half the expected breakaway
/// (the device's `gms.fs`) up by a quarter of it each to three times it, then on by a
/// quarter of the last each (an axis whose friction the device's model underestimates),
/// within 60 % of the current limit (a step to it overshoots in the current loop, and the
/// trip is at 1.5 × the limit or below), until the axis has slid ([`slide_threshold`]). Fails when
/// no current flows (a current friction holds, measured) or the axis does not slide.
pub fn slide(b: &mut impl Bench, dev: &DeviceInfo, dt: f64) -> Result<Slide, Error> {
    let i_fs = dev.fs / dev.k_m;
    let threshold = slide_threshold(rad_per_count(b)?);
    primitive(b, "enable current")?;
    b.request("current 0")?;
    b.wait(0.05)?;
    let x0 = position(b)?;
    let mut moved = 0.0;
    let mut amps = 0.5 * i_fs;
    let mut last = 0.0;
    while amps <= 0.6 * dev.i_max {
        primitive(b, &format!("current {amps} 0.01"))?;
        b.wait(0.05)?;
        moved = position(b)? - x0;
        last = amps;
        if moved.abs() > threshold {
            break;
        }
        amps += 0.25 * if amps < 3.0 * i_fs { i_fs } else { amps };
    }
    b.request("current 0")?;
    b.wait(0.2)?;
    check_faults(b)?;
    if moved.abs() <= threshold {
        // Which of the two: a current friction holds (40 % of the expected breakaway).
        let (i, _, _) = hold_current(b, 0.4 * i_fs, 0.1, dt)?;
        b.request("current 0")?;
        if i < 0.2 * i_fs {
            return Err(Error::Device(format!(
                "commanded {:.4e} A, measured {i:.4e} A: no current flows (the motor not \
                 connected?)",
                0.4 * i_fs
            )));
        }
        return Err(Error::Device(format!(
            "the axis did not move with current pulses up to {} ({} N·m, 60 % of lim.i_max): \
             blocked?",
            si(last, "A"),
            num4(last * dev.k_m)
        )));
    }
    Ok(Slide { moved, amps: last })
}

/// Holds `amps` in current mode for `seconds` and returns the mean current \\[A\\] and voltage
/// \\[V\\] over its second half, and the position change \\[rad\\] over the whole.
fn hold_current(
    b: &mut impl Bench,
    amps: f64,
    seconds: f64,
    dt: f64,
) -> Result<(f64, f64, f64), Error> {
    let x0 = position(b)?;
    b.request(&format!("current {amps}"))?;
    b.wait(seconds / 2.0)?;
    let n = ((seconds / 2.0) / dt).ceil().clamp(2.0, 2700.0) as u32;
    let rows = capture_now(b, "current,volts", n, dt)?;
    check_faults(b)?;
    let m = means(&rows);
    Ok((m[0], m[1], position(b)? - x0))
}

/// Commissioning a motor on the bench: the current sense at rest (offset, noise); its
/// polarity (a reversed sense makes the current loop run away at once: `over_current`, then
/// `sense.dir` flipped and tried again); the encoder's direction (current steps of a quarter
/// of the expected Fs until the axis slides 2 mrad, which way the counts say; flipped by
/// `enc.dir`; each step a pulse of 10 ms the device ends by itself); the winding resistance (current mode at ±40 % of the expected breakaway, the
/// axis held by friction: R from the voltage and current differences, offsets cancelled); the
/// back-EMF constant (timed velocity runs at 1, 2 and 3 × `speed` each way: the voltage less
/// R × current against the speed, the slope); the reflected inertia (timed current pulses and
/// the coasts after them); the inductance (the current loop's step response). The device's
/// stroke limits are narrowed around the start for the run (the farthest speed run each way
/// and 0.5 rad more). The direction settings it changes to go on, and the limits, are put back
/// at the end (and on failure, with the bridge off): the caller applies the result.
pub fn commission(b: &mut impl Bench, speed: f64) -> Result<Commissioned, Error> {
    if !(speed > 0.0 && speed * 3.0 <= VELOCITY_MAX_BENCH) {
        return Err(Error::Params(format!(
            "speed {speed} rad/s: positive, three times it at most {VELOCITY_MAX_BENCH} rad/s"
        )));
    }
    check_configured(b)?;
    let scales = scales_line(b)?;
    let dev = DeviceInfo::read(b)?;
    let dt = dev.dt();
    check_faults(b)?;
    let dirs0 = (get_param(b, "sense.dir")?, get_param(b, "enc.dir")?);
    // The device's own stroke guard around the start: the farthest speed run each way, and
    // half a radian for the rest; an axis that runs away stops there with the bridge off.
    let v = 3.0 * speed;
    let window = 1.2 * (v * KE_RUN + v * v / VELOCITY_ACC) + 0.5;
    let limits = narrow_limits(b, window)?;
    let gains0 = (
        get_param(b, "pos.kp")?,
        get_param(b, "pos.ki")?,
        get_param(b, "pos.kd")?,
    );
    let r = guarded(b, |b| commission_steps(b, &dev, dt, dirs0, gains0, speed)).map(|mut c| {
        c.lines.insert(0, scales);
        c
    });
    // The position gains as they were (the back-EMF runs soften them).
    let _ = b.request(&format!("set pos.kp {}", gains0.0));
    let _ = b.request(&format!("set pos.ki {}", gains0.1));
    let _ = b.request(&format!("set pos.kd {}", gains0.2));
    // The directions and the limits as they were (the caller applies what was found).
    let _ = b.request("disable");
    let _ = b.request(&format!("set sense.dir {}", dirs0.0));
    let _ = b.request(&format!("set enc.dir {}", dirs0.1));
    restore_limits(b, limits);
    r
}

/// The length of each back-EMF run at constant speed \\[s\\] (0.1 s settling, 0.1 s averaged).
const KE_RUN: f64 = 0.2;

pub use crate::gains::CURRENT_BW_FRACTION;

/// The fastest speed commissioning uses [rad/s] (the velocity mode allows 20).
const VELOCITY_MAX_BENCH: f64 = 20.0;

fn commission_steps(
    b: &mut impl Bench,
    dev: &DeviceInfo,
    dt: f64,
    (sense0, enc0): (f64, f64),
    (kp, ki, kd): (f64, f64, f64),
    speed: f64,
) -> Result<Commissioned, Error> {
    let mut c = Commissioned {
        sense_dir: sense0,
        enc_dir: enc0,
        ..Commissioned::default()
    };
    let i_fs = dev.fs / dev.k_m;
    // 1. The sense at rest, bridge off.
    b.request("disable")?;
    let rows = capture_now(b, "current", 2000, dt)?;
    let m = means(&rows)[0];
    let var = rows.iter().map(|r| (r[0] - m).powi(2)).sum::<f64>() / rows.len().max(1) as f64;
    (c.sense_offset, c.sense_noise) = (m, var.sqrt());
    c.lines.push(format!(
        "current sense at rest: offset {}, noise {} rms",
        si(c.sense_offset, "A"),
        si(c.sense_noise, "A")
    ));
    // 2. Its polarity: a small current in current mode.
    let mut polarity_ok = false;
    for attempt in 0..2 {
        let tried = (|| {
            primitive(b, "enable current")?;
            b.request(&format!("current {}", 0.4 * i_fs))?;
            b.wait(0.02)
        })();
        // The runaway may trip while `enable current` is still being answered: the latched
        // fault says what happened either way.
        let faults = check_faults(b);
        match (tried, faults) {
            (Ok(()), Ok(())) => {
                polarity_ok = true;
                break;
            }
            (_, Err(e)) if attempt == 0 && e.to_string().contains("over_current") => {
                c.sense_dir = -c.sense_dir;
                b.request("clear")?;
                b.request(&format!("set sense.dir {}", c.sense_dir))?;
                c.lines.push(
                    "current sense: reversed (the current loop ran away: over_current); sense.dir flipped"
                        .into(),
                );
            }
            (Err(e), _) | (_, Err(e)) => return Err(e),
        }
    }
    if !polarity_ok {
        return Err(Error::Device(
            "the current loop runs away either way".into(),
        ));
    }
    if c.sense_dir == sense0 {
        c.lines.push(format!(
            "current sense: polarity right (sense.dir {})",
            c.sense_dir
        ));
    }
    // 3. The encoder's direction.
    let sl = slide(b, dev, dt)?;
    let moved = sl.moved;
    // The experiments below need the breakaway current (the sense's polarity above only a
    // small current): the device's friction model's when the axis agrees with it, else the
    // pulse that moved it (a user's motor whose friction the model, Table 1 by default, is far
    // from).
    let expected = i_fs;
    let off = sl.amps > 1.5 * expected || sl.amps < expected / 1.5;
    let i_fs = if sl.amps > 1.5 * expected {
        c.lines.push(format!(
            "breakaway: the axis slid under a pulse of {}, {:.1} times what the device's \
             friction model expects (gms.fs {} N·m over motor.k_m {} N·m/A): the experiments \
             use the pulse's current",
            si(sl.amps, "A"),
            sl.amps / expected,
            num4(dev.fs),
            num4(dev.k_m)
        ));
        sl.amps
    } else {
        expected
    };
    c.breakaway_a = sl.amps;
    if moved < 0.0 {
        c.enc_dir = -c.enc_dir;
        // The bridge goes off with the change; back into current mode.
        b.request(&format!("set enc.dir {}", c.enc_dir))?;
        primitive(b, "enable current")?;
        c.lines.push(format!(
            "encoder: counted {} under a positive current: reversed; enc.dir flipped",
            si(moved, "rad")
        ));
    } else {
        c.lines.push(format!(
            "encoder: direction right ({} under a positive current)",
            si(moved, "rad")
        ));
    }
    // 4. R at standstill: ±40 % of the expected breakaway, friction holds the axis.
    let (ip, vp, _) = hold_current(b, 0.4 * i_fs, 0.2, dt)?;
    let (in_, vn, _) = hold_current(b, -0.4 * i_fs, 0.2, dt)?;
    b.request("current 0")?;
    if (ip - in_).abs() < 0.2 * i_fs {
        return Err(Error::Device(format!(
            "commanded ±{:.3e} A, measured {ip:.3e} and {in_:.3e} A: no current flows (the motor \
             not connected?)",
            0.4 * i_fs
        )));
    }
    c.r = (vp - vn) / (ip - in_);
    c.lines.push(format!(
        "winding resistance: {} ({} at {}, {} at {})",
        si(c.r, "Ω"),
        si(vp, "V"),
        si(ip, "A"),
        si(vn, "V"),
        si(in_, "A")
    ));
    // 5. k_e from timed runs both ways: V - R i against the speed. The motor's inertia is
    //    not known yet, and a loop tuned for a heavier one may be unstable on it: the runs
    //    use a softer position loop (kp / 4, ki / 8, kd / 2; `commission` puts the gains
    //    back), which tracks a constant speed well enough.
    b.request(&format!("set pos.kd {}", kd / 2.0))?;
    b.request(&format!("set pos.kp {}", kp / 4.0))?;
    b.request(&format!("set pos.ki {}", ki / 8.0))?;
    b.request("hold")?;
    let mut pts = Vec::new();
    for k in 1..=3 {
        for dir in [1.0, -1.0] {
            let v = dir * speed * k as f64;
            let t_acc = v.abs() / VELOCITY_ACC;
            let run = KE_RUN;
            timed_run(b, v, run, "t,pos,current,volts", dt)?;
            let rows: Vec<Vec<f64>> = capture_rows(b)?
                .into_iter()
                .filter(|r| r[0] >= t_acc + 0.1 && r[0] <= t_acc + run)
                .collect();
            if rows.len() < 2 {
                return Err(Error::Device("an empty capture".into()));
            }
            // The speed: the least-squares slope of the position (every sample, so that a
            // coarse encoder's counts average out rather than only the two ends').
            let m = means(&rows);
            let (mut stt, mut stx) = (0.0, 0.0);
            for r in &rows {
                stt += (r[0] - m[0]).powi(2);
                stx += (r[0] - m[0]) * (r[1] - m[1]);
            }
            let w = stx / stt.max(dt * dt);
            pts.push((w, m[3] - c.r * m[2]));
        }
    }
    let n = pts.len() as f64;
    let (mw, me) = (
        pts.iter().map(|p| p.0).sum::<f64>() / n,
        pts.iter().map(|p| p.1).sum::<f64>() / n,
    );
    let sww = pts.iter().map(|p| (p.0 - mw).powi(2)).sum::<f64>();
    let swe = pts.iter().map(|p| (p.0 - mw) * (p.1 - me)).sum::<f64>();
    if sww <= 0.0 {
        return Err(Error::Device("the speed runs did not move the axis".into()));
    }
    c.k_e = swe / sww;
    c.lines.push(format!(
        "back-EMF constant: {} from {} runs up to {} rad/s (k_M = k_e in SI)",
        si(c.k_e, "V·s/rad"),
        pts.len(),
        3.0 * speed
    ));
    // 6. The inertia: current pulses that the device ends by itself, and the coast after.
    c.inertia = inertia(b, &mut c, dev, dt, i_fs)?;
    // 7. The inductance: the current loop's step response at standstill.
    c.inductance = inductance(b, &mut c, dt, i_fs)?;
    // 8. The current loop's PI for a bandwidth of CURRENT_BW_FRACTION of its rate: kp = ω L,
    //    ki = ω R (the PI's zero on the winding's pole: a first-order loop of bandwidth ω).
    let cur_hz = get_param(b, "rate.cur_hz")?;
    c.cur_pi = crate::gains::current_pi(c.r, c.inductance, cur_hz);
    // The loop's delay: the sample, the computation and the update, about 1.5 periods.
    let margin = 90.0 - 360.0 * CURRENT_BW_FRACTION * 1.5;
    c.lines.push(format!(
        "current loop: bandwidth {:.0} Hz ({} of its rate): cur.kp {} V/A, cur.ki {} V/(A·s); \
         phase margin about {margin:.0}° (1.5 periods of delay)",
        CURRENT_BW_FRACTION * cur_hz,
        CURRENT_BW_FRACTION,
        num4(c.cur_pi.0),
        num4(c.cur_pi.1)
    ));
    // 9. A friction model far from the axis scaled to its breakaway (the level measured, the
    //    shape the model's), for the gains below and for the caller to apply.
    let ratio = if off { sl.amps * c.k_e / dev.fs } else { 1.0 };
    if off {
        let mut paths = vec!["gms.fs", "gms.fc", "gms.sigma", "gms.c"];
        paths.extend(["gms.k1", "gms.k2", "gms.k3", "gms.k4", "gms.k5", "gms.k6"]);
        for p in paths {
            let v = get_param(b, p)?;
            c.friction_scaled.push((p, v * ratio));
        }
        c.lines.push(format!(
            "friction level: the device's model scaled ×{ratio:.3} to the measured breakaway \
             ({} N·m: the pulse's current × k_M; its shape stays the model's until \
             `gms-tune identify`)",
            num4(sl.amps * c.k_e)
        ));
    }
    // 10. The position loop's gains for this motor and loop, kd between the device's
    //    friction model's Stribeck slope and the loops' stability limit.
    c.pos = Some(position_gains_for(b, &mut c, cur_hz, ratio)?);
    b.request("disable")?;
    Ok(c)
}

/// The position loop's gains for the motor `c` measured, the current loop at `cur_hz` with
/// its new PI, the device's position rate, derivative filter, supply and friction model (its
/// level times `scale`).
fn position_gains_for(
    b: &mut impl Bench,
    c: &mut Commissioned,
    cur_hz: f64,
    scale: f64,
) -> Result<crate::gains::PositionGains, Error> {
    use crate::gains::{Axis, Stribeck, position_gains};
    let mut k0 = 0.0;
    for i in 1..=6 {
        k0 += scale * get_param(b, &format!("gms.k{i}"))?;
    }
    let axis = Axis {
        r: c.r,
        l: c.inductance,
        k_m: c.k_e,
        inertia: c.inertia,
        cur_pi: c.cur_pi,
        cur_hz,
        pos_hz: get_param(b, "rate.pos_hz")?,
        d_filter_hz: get_param(b, "pos.d_filter_hz")?,
        v_supply: get_param(b, "lim.v_supply")?,
        k_presliding: k0,
        rad_per_count: rad_per_count(b)?,
        i_max: get_param(b, "lim.i_max")?,
    };
    let s = Stribeck {
        fs: scale * get_param(b, "gms.fs")?,
        fc: scale * get_param(b, "gms.fc")?,
        vs: get_param(b, "gms.vs")?,
        delta: get_param(b, "gms.delta")?,
        sigma: scale * get_param(b, "gms.sigma")?,
    };
    let g = position_gains(&axis, &s).ok_or_else(|| {
        Error::Device(format!(
            "no position-loop gains for the measured motor ({axis:?}): the loop model does not \
             settle"
        ))
    })?;
    c.lines.push(format!(
        "position loop: pos.kp {} N·m/rad, pos.ki {} N·m/(rad·s), pos.kd {} N·m·s/rad \
         (natural frequency {:.0} Hz)",
        num4(g.kp),
        num4(g.ki),
        num4(g.kd),
        (g.kp / c.inertia).sqrt() / (2.0 * std::f64::consts::PI)
    ));
    if g.count_limited {
        c.lines.push(format!(
            "  limited by the encoder's count ({}): one count of error asks at most {:.0} % \
             of lim.i_max through kp, a one-count step {:.0} % through kd",
            si(axis.rad_per_count, "rad"),
            100.0 * crate::gains::COUNT_SHARE.0,
            100.0 * crate::gains::COUNT_SHARE.1
        ));
    }
    c.lines.push(format!(
        "  kd above the friction's negative damping {} (the device's Stribeck curve at Vs: \
         Fs {}, Fc {}, Vs {}) by ×{:.2}; below the stability limit {} by ×{:.2}",
        num4(g.kd_min),
        si(s.fs, "N·m"),
        si(s.fc, "N·m"),
        si(s.vs, "rad/s"),
        g.margin_low(),
        num4(g.kd_max),
        g.margin_high()
    ));
    if g.kd_max <= g.kd_min {
        c.lines.push(
            "  warning: no kd is both above the friction's negative damping and stable: kd is \
             set for stability, the axis may hunt at low speed (a faster current loop or more \
             inertia widens the window)"
                .into(),
        );
    }
    Ok(g)
}

/// The reflected inertia from current pulses, timed on the device, each way twice, and the
/// coast that follows: at the same speed the friction is the same in both, so
/// J = k_M × i / (a_pulse − a_coast), the accelerations from local parabolas through the
/// captured positions, compared at 30-80 % of the top speed. The pulses and the parabolas are
/// sized for the encoder ([`InertiaPlan::for_encoder`]): 3 × the breakaway current for 2 ms and
/// 7-sample parabolas on a fine one; on a coarse one (a count above 20 µrad) 1.5 × for 20 ms,
/// parabolas over 6 ms, so that quantisation averages out.
fn inertia(
    b: &mut impl Bench,
    c: &mut Commissioned,
    dev: &DeviceInfo,
    dt: f64,
    i_fs: f64,
) -> Result<f64, Error> {
    let k_m = c.k_e;
    let plan = InertiaPlan::for_encoder(rad_per_count(b)?, dt);
    let amps = (plan.breakaways * i_fs).min(0.8 * dev.i_max);
    let pulse = plan.pulse;
    let mut js = Vec::new();
    primitive(b, "enable current")?;
    b.wait(0.05)?;
    for dir in [1.0, -1.0, 1.0, -1.0] {
        let n = (plan.record / dt).ceil() as u32;
        b.request(&format!("capture t,pos,current 1 {n} next"))?;
        primitive(b, &format!("current {} {pulse}", dir * amps))?;
        b.wait(n as f64 * dt)?;
        capture_wait(b, 0.01, 200)?;
        check_faults(b)?;
        let rows = capture_rows(b)?;
        b.wait(0.05)?;
        // Local parabolas over 2h + 1 samples: speed and acceleration at each sample.
        let h = plan.half_window;
        let mut va = Vec::new();
        for k in h..rows.len().saturating_sub(h) {
            let (mut s0, mut s1, mut s2, mut s3, mut s4) = (0.0, 0.0, 0.0, 0.0, 0.0);
            let (mut y0, mut y1, mut y2) = (0.0, 0.0, 0.0);
            for j in k - h..=k + h {
                let u = rows[j][0] - rows[k][0];
                let y = dir * rows[j][1];
                s0 += 1.0;
                s1 += u;
                s2 += u * u;
                s3 += u * u * u;
                s4 += u * u * u * u;
                y0 += y;
                y1 += u * y;
                y2 += u * u * y;
            }
            // Normal equations of y = p0 + p1 u + p2 u² (symmetric window: s1 = s3 = 0).
            let det =
                s2 * (s0 * s4 - s2 * s2) - s1 * (s1 * s4 - s2 * s3) + s3 * (s1 * s3 - s2 * s2);
            if det.abs() < 1e-300 {
                continue;
            }
            let p1 = (y1 - s1 * y0 / s0) / (s2 - s1 * s1 / s0);
            let p2 = (s0 * y2 - s2 * y0) / (s0 * s4 - s2 * s2);
            va.push((rows[k][0], p1, 2.0 * p2, dir * rows[k][2]));
        }
        let top = va.iter().map(|p| p.1).fold(0.0, f64::max);
        if top <= 0.0 {
            return Err(Error::Device(
                "the current pulses did not move the axis".into(),
            ));
        }
        let band = |p: &&(f64, f64, f64, f64)| p.1 > 0.3 * top && p.1 < 0.8 * top;
        // The pulse's samples after the current has settled (0.4 ms), the coast's after it.
        let push: Vec<_> = va
            .iter()
            .filter(|p| p.0 > 0.0004 + plan.edge && p.0 < pulse - 0.0002 - plan.edge)
            .filter(band)
            .collect();
        let coast: Vec<_> = va
            .iter()
            .filter(|p| p.0 > pulse + 0.0004 + plan.edge)
            .filter(band)
            .collect();
        if push.is_empty() || coast.is_empty() {
            return Err(Error::Device(
                "the current pulses were too short to measure the inertia".into(),
            ));
        }
        let mean = |v: &[&(f64, f64, f64, f64)], f: fn(&(f64, f64, f64, f64)) -> f64| {
            v.iter().map(|p| f(p)).sum::<f64>() / v.len() as f64
        };
        let (a_p, i_p) = (mean(&push, |p| p.2), mean(&push, |p| p.3));
        let (a_c, i_c) = (mean(&coast, |p| p.2), mean(&coast, |p| p.3));
        if a_p - a_c <= 0.0 {
            return Err(Error::Device(
                "the current pulses gave no acceleration".into(),
            ));
        }
        js.push(k_m * (i_p - i_c) / (a_p - a_c));
    }
    b.request("current 0")?;
    let j = js.iter().sum::<f64>() / js.len() as f64;
    c.lines.push(format!(
        "reflected inertia: {} kg·m² from four current pulses of {} for {} ms and the coasts \
         after (each {} … {})",
        num4(j),
        si(amps, "A"),
        pulse * 1e3,
        num4(js.iter().cloned().fold(f64::INFINITY, f64::min)),
        num4(js.iter().cloned().fold(f64::NEG_INFINITY, f64::max))
    ));
    Ok(j)
}

/// How `inertia` pulses the axis for an encoder.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct InertiaPlan {
    /// The pulse's current in breakaway currents \\[-\\].
    pub breakaways: f64,
    /// The pulse's length \\[s\\].
    pub pulse: f64,
    /// The record from the pulse's start \\[s\\] (the pulse and the coast).
    pub record: f64,
    /// The local parabolas' half width \\[samples\\].
    pub half_window: usize,
    /// How far from the pulse's ends a parabola's centre keeps \\[s\\] (its half width on a
    /// coarse encoder, so that none straddles the switch; 0 on a fine one).
    pub edge: f64,
}

impl InertiaPlan {
    /// The plan for an encoder of `rad_per_count` \\[rad\\] sampled every `dt` \\[s\\]: on the
    /// paper's (3.8 µrad) or any finer than 20 µrad, 3 × the breakaway for 2 ms, recorded 30
    /// ms, 7-sample parabolas; on a coarser one, 1.5 × for 20 ms (about 50 counts of a 3 mrad
    /// count on a motor that its breakaway accelerates at 1500 rad/s²), recorded 60 ms,
    /// parabolas over 6 ms.
    pub fn for_encoder(rad_per_count: f64, dt: f64) -> InertiaPlan {
        if rad_per_count <= 20e-6 {
            InertiaPlan {
                breakaways: 3.0,
                pulse: 0.002,
                record: 0.03,
                half_window: 3,
                edge: 0.0,
            }
        } else {
            let h = ((0.003 / dt).round() as usize).max(3);
            InertiaPlan {
                breakaways: 1.5,
                pulse: 0.02,
                record: 0.06,
                half_window: h,
                edge: h as f64 * dt,
            }
        }
    }
}

/// The winding inductance from the current loop's response to current steps at standstill
/// (between −40 % and +40 % of the expected breakaway current: friction holds the axis, no
/// back-EMF), sixteen steps each way in turn, averaged (the loop is linear, so a step of 2A
/// from −A is twice the response to A from rest), against the device's own current loop
/// (`gms_core`'s controller with the device's gains, rates, supply and feedforward R) driving
/// an R-L winding whose voltage is applied one current period late, as the bridge does: the L
/// whose simulated response is closest (least squares over the first 2 ms, golden-section
/// search over ln L). A winding much faster than the current period settles within it and
/// shows little of its L: below L/R = a sixth of the period the result is flagged.
fn inductance(b: &mut impl Bench, c: &mut Commissioned, dt: f64, i_fs: f64) -> Result<f64, Error> {
    let amps = 0.4 * i_fs;
    let n = 20u32;
    let steps = 16;
    let mut avg = vec![0.0f64; n as usize];
    primitive(b, "enable current")?;
    b.request(&format!("current {}", -amps))?;
    b.wait(0.01)?;
    for k in 0..steps {
        let dir = if k % 2 == 0 { 1.0 } else { -1.0 };
        b.request(&format!("capture current 1 {n} next"))?;
        b.request(&format!("current {}", dir * amps))?;
        b.wait(n as f64 * dt)?;
        capture_wait(b, 0.01, 200)?;
        check_faults(b)?;
        for (a, r) in avg.iter_mut().zip(capture_rows(b)?) {
            *a += (dir * r[0] + amps) / 2.0 / steps as f64;
        }
        b.wait(0.002)?;
    }
    b.request("current 0")?;
    // The device's current loop, as it runs.
    let mut p = gms_core::device::default_settings();
    p.current.kp = get_param(b, "cur.kp")? as f32;
    p.current.ki = get_param(b, "cur.ki")? as f32;
    p.cur_rate_hz = get_param(b, "rate.cur_hz")? as f32;
    p.pos_rate_hz = get_param(b, "rate.pos_hz")? as f32;
    p.v_supply = get_param(b, "lim.v_supply")? as f32;
    p.motor.r = get_param(b, "motor.r")? as f32;
    let r = c.r;
    let ratio = (p.cur_rate_hz / p.pos_rate_hz).round().max(1.0) as usize;
    let h = 1.0 / p.cur_rate_hz as f64;
    let model = |l: f64| -> Option<f64> {
        let mut ctrl = gms_core::controller::Controller::try_new(p).ok()?;
        ctrl.hold_current(amps as f32);
        let (mut i, mut v_prev) = (0.0f64, 0.0f64);
        let mut sse = 0.0;
        for k in 0..(n as usize * ratio) {
            if k % ratio == 0 {
                sse += (i - avg[k / ratio]).powi(2);
            }
            let v = ctrl.current_step(i as f32).voltage as f64;
            // The voltage computed now drives the next period.
            let e = (-r * h / l).exp();
            let i_ss = v_prev / r;
            i = i_ss + (i - i_ss) * e;
            v_prev = v;
        }
        Some(sse)
    };
    // Golden-section search over ln L in [1 µH, 1 H].
    let (mut lo, mut hi) = (1e-6f64.ln(), 1.0f64.ln());
    let g = 0.5 * (5f64.sqrt() - 1.0);
    let f = |x: f64| model(x.exp()).unwrap_or(f64::INFINITY);
    let (mut x1, mut x2) = (hi - g * (hi - lo), lo + g * (hi - lo));
    let (mut f1, mut f2) = (f(x1), f(x2));
    for _ in 0..80 {
        if f1 < f2 {
            hi = x2;
            (x2, f2) = (x1, f1);
            x1 = hi - g * (hi - lo);
            f1 = f(x1);
        } else {
            lo = x1;
            (x1, f1) = (x2, f2);
            x2 = lo + g * (hi - lo);
            f2 = f(x2);
        }
    }
    let l = (0.5 * (lo + hi)).exp();
    if !l.is_finite() || f1.is_infinite() {
        return Err(Error::Device(
            "the current steps could not be fitted".into(),
        ));
    }
    c.lines.push(format!(
        "winding inductance: {} from the current loop's response to {steps} steps of {} \
         (L/R {:.1} µs)",
        si(l, "H"),
        si(2.0 * amps, "A"),
        l / r * 1e6
    ));
    if l / r < h / 6.0 {
        c.lines.push(format!(
            "  warning: L/R is below a sixth of the current period ({:.1} µs): the winding \
             settles within a period, so L is poorly resolved (cur.kp = ωL matters little there)",
            h / 6.0 * 1e6
        ));
    }
    Ok(l)
}
