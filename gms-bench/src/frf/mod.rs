//! Frequency response on a device: a stepped-sine sweep of the device's own measurement
//! (`frf`: a sine injected and demodulated on the device over whole periods), the transfer
//! functions made from its phasors, the stability margins of a loop gain, and the pre-sliding
//! stiffness seen at low frequency.
//!
//! Which transfer function each loop is, from the four phasors the device demodulates (the sine
//! injected `in`, the current commanded after it `cmd`, the current measured `cur`, the position
//! relative to the reference without the sine `pos`):
//!
//! - `plant`: `pos / cmd` \[rad/A\] (the sine at the current command; in closed loop, divided by
//!   the current actually commanded, so the controller's own reaction does not enter);
//! - `open`: the loop gain `in / cmd − 1` (the command is `u + d`, the controller's part
//!   `u = −L · cmd`), dimensionless, the loop-shaping filters included;
//! - `closed`: `pos / in` (the sine at the position reference).

mod files;

mod notch;

pub use files::*;

pub use notch::*;

use crate::Error;
use gms_core::control::frf::{FrfState, Injection};
use gms_core::protocol::ParamId;
use gms_core::protocol::{self, Command, FrfCmd};
use num_complex::Complex64;

pub use gms_ident::margins::{Extremum, Margins, db, extrema, margins, refinement};

use crate::client::{Bench, status};

/// Which transfer function a sweep measures.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Loop {
    /// Position per current commanded \[rad/A\].
    Plant,
    /// The loop gain [-].
    Open,
    /// Position per position reference [-].
    Closed,
}

impl Loop {
    /// The name on the command line: `plant`, `open` or `closed`.
    pub fn name(self) -> &'static str {
        match self {
            Loop::Plant => "plant",
            Loop::Open => "open",
            Loop::Closed => "closed",
        }
    }

    /// The loop with this name.
    pub fn from_name(s: &str) -> Option<Loop> {
        match s {
            "plant" => Some(Loop::Plant),
            "open" => Some(Loop::Open),
            "closed" => Some(Loop::Closed),
            _ => None,
        }
    }

    /// Where the sine goes for this loop.
    pub fn injection(self) -> Injection {
        match self {
            Loop::Plant | Loop::Open => Injection::Current,
            Loop::Closed => Injection::Position,
        }
    }
}

/// The device's `frf` reply.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Reply {
    /// Where the measurement stands.
    pub state: FrfState,
    /// Where the sine went (`None` before any measurement).
    pub injection: Option<Injection>,
    /// The frequency run \[Hz\].
    pub f_hz: f64,
    /// The amplitude injected \[A or rad\].
    pub amp: f64,
    /// Groups of whole periods summed so far.
    pub groups: u32,
    /// Groups to be summed.
    pub total: u32,
    /// The phasors `in`, `cmd`, `cur`, `pos` \[A, A, A, rad\] (`re` in phase with the sine).
    pub phasors: [Complex64; 4],
    /// Their coherences over the groups \[0, 1\] (NaN before two groups).
    pub coherence: [f64; 4],
}

impl From<protocol::FrfStatus> for Reply {
    fn from(st: protocol::FrfStatus) -> Reply {
        let nan = Complex64::new(f64::NAN, f64::NAN);
        match st.measure {
            None => Reply {
                state: st.state,
                injection: None,
                f_hz: f64::NAN,
                amp: f64::NAN,
                groups: 0,
                total: 0,
                phasors: [nan; 4],
                coherence: [f64::NAN; 4],
            },
            Some(m) => Reply {
                state: st.state,
                injection: Some(m.injection),
                f_hz: f64::from(m.f_hz),
                amp: f64::from(m.amp),
                groups: m.groups_done,
                total: m.groups,
                phasors: m
                    .phasors
                    .map(|[re, im]| Complex64::new(f64::from(re), f64::from(im))),
                coherence: m.coherence.map(f64::from),
            },
        }
    }
}

impl Reply {
    /// Reads the text after `ok` of an `frf` reply ([`protocol::FrfStatus::parse`]: the device
    /// core's own format); without a measurement, the figures are NaN and the counts 0.
    pub fn parse(text: &str) -> Result<Reply, String> {
        let st = protocol::FrfStatus::parse(text).map_err(|e| format!("{e}: {text}"))?;
        Ok(st.into())
    }

    /// The transfer function of `lp` from these phasors, and its coherence (the lower of the
    /// coherences of the signals it is made of).
    pub fn transfer(&self, lp: Loop) -> (Complex64, f64) {
        let [d, cmd, _, pos] = self.phasors;
        // NaN (a signal that is exactly 0, or a single group) is no evidence of a response.
        let [_, c_cmd, _, c_pos] = self.coherence.map(|c| if c.is_nan() { 0.0 } else { c });
        match lp {
            Loop::Plant => (pos / cmd, c_pos.min(c_cmd)),
            // The loop gain is made of the position's response too: an encoder that does not
            // see the motion leaves the command equal to the sine (L = 0, "coherent").
            Loop::Open => (d / cmd - 1.0, c_cmd.min(c_pos)),
            Loop::Closed => (pos / d, c_pos),
        }
    }
}

/// One point of a frequency response.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Point {
    /// Frequency \[Hz\].
    pub f_hz: f64,
    /// The transfer function's value (rad/A for the plant, dimensionless otherwise).
    pub value: Complex64,
    /// Its coherence \[0, 1\].
    pub coherence: f64,
    /// The device's reply it came from.
    pub reply: Reply,
}

impl Point {
    /// Gain \[dB\].
    pub fn gain_db(&self) -> f64 {
        db(self.value)
    }

    /// Phase \[deg\], in (−180, 180].
    pub fn phase_deg(&self) -> f64 {
        self.value.arg().to_degrees()
    }
}

/// A stepped-sine sweep.
#[derive(Debug, Clone, PartialEq)]
pub struct Plan {
    /// What is measured.
    pub lp: Loop,
    /// Lowest frequency \[Hz\].
    pub from_hz: f64,
    /// Highest frequency \[Hz\].
    pub to_hz: f64,
    /// Frequencies, spaced evenly on a log scale (at least 2).
    pub points: usize,
    /// The sine's amplitude: \[A\] for `plant` and `open`, \[rad\] for `closed`.
    pub amplitude: f64,
    /// Measure while the axis runs at this speed \[rad/s\] (sliding friction), `None` at rest.
    pub velocity: Option<f64>,
    /// Periods summed per point, at least.
    pub periods: u32,
    /// Time summed per point, at least \[s\] (more periods at high frequencies).
    pub seconds: f64,
    /// Points measured again in each interval where a loop gain's margins are decided (the
    /// open loop: 3 by default; 0: none).
    pub refine: usize,
}

impl Plan {
    /// A sweep of `lp` with the bench's defaults: 10 Hz to 5 kHz (a quarter of the default
    /// 20 kHz position rate: the default loop's phase crosses −180° near 3.4 kHz), 40 points,
    /// 8 periods or 0.1 s a point, whichever is longer.
    pub fn new(lp: Loop, amplitude: f64) -> Plan {
        Plan {
            lp,
            from_hz: 10.0,
            to_hz: 5000.0,
            points: 40,
            amplitude,
            velocity: None,
            periods: 8,
            seconds: 0.1,
            refine: if lp == Loop::Open { 3 } else { 0 },
        }
    }

    /// The frequencies asked \[Hz\].
    pub fn frequencies(&self) -> Vec<f64> {
        let n = self.points.max(2);
        let (a, b) = (self.from_hz.ln(), self.to_hz.ln());
        (0..n)
            .map(|i| (a + (b - a) * i as f64 / (n - 1) as f64).exp())
            .collect()
    }

    /// Periods summed and let settle at `f_hz` \[Hz\]: `periods` or `seconds`' worth, and two
    /// periods or 20 ms of settling (the loop's transient), whichever is longer.
    pub fn periods_at(&self, f_hz: f64) -> (u32, u32) {
        let sum = (self.periods as f64).max((self.seconds * f_hz).ceil());
        let settle = 2f64.max((0.02 * f_hz).ceil());
        (sum.min(1e6) as u32, settle.min(1e6) as u32)
    }

    /// Device time the sweep takes \[s\] (the measurements alone).
    pub fn device_seconds(&self) -> f64 {
        self.frequencies()
            .iter()
            .map(|f| {
                let (a, b) = self.periods_at(*f);
                (a + b) as f64 / f
            })
            .sum()
    }

    /// Checks the plan against the device's position rate \[Hz\] and current limit \[A\].
    pub fn check(&self, pos_hz: f64, i_max: f64) -> Result<(), Error> {
        let bad = |m: String| Err(Error::Params(m));
        if !(self.from_hz > 0.0 && self.from_hz < self.to_hz) {
            return bad(format!(
                "--from {} and --to {}: need 0 < from < to",
                self.from_hz, self.to_hz
            ));
        }
        let nyq = 0.45 * pos_hz;
        if self.to_hz.is_nan() || self.to_hz >= nyq {
            return bad(format!(
                "--to {} Hz is above the position loop's Nyquist limit ({nyq:.0} Hz = 0.45 × rate.pos_hz)",
                self.to_hz
            ));
        }
        if !(2..=1000).contains(&self.points) {
            return bad(format!("--points {}: from 2 to 1000", self.points));
        }
        if !(self.amplitude.is_finite() && self.amplitude > 0.0) {
            return bad(format!("--amplitude {}: must be > 0", self.amplitude));
        }
        if self.lp != Loop::Closed && self.amplitude > i_max {
            return bad(format!(
                "--amplitude {} A is beyond the current limit lim.i_max = {i_max} A",
                self.amplitude
            ));
        }
        if let Some(v) = self.velocity
            && !(v.is_finite() && v != 0.0 && v.abs() <= 20.0)
        {
            return bad(format!(
                "--velocity {v}: must be non-zero, at most 20 rad/s"
            ));
        }
        Ok(())
    }
}

/// Runs one measurement at `f_hz` and waits for its result.
pub fn measure(
    b: &mut impl Bench,
    injection: Injection,
    f_hz: f64,
    amp: f64,
    (periods, settle): (u32, u32),
) -> Result<Reply, Error> {
    b.send(Command::Frf(FrfCmd::Start {
        injection,
        f_hz: f_hz as f32,
        amp: amp as f32,
        periods,
        settle,
    }))?;
    // The device fits the frequency to its rate and rounds to whole groups: a little more
    // than the periods asked.
    let expect = (periods + settle) as f64 / f_hz;
    b.wait(expect)?;
    for _ in 0..200 {
        let (_, text) = b.send(Command::Frf(FrfCmd::Status))?;
        let r = Reply::parse(&text).map_err(Error::Device)?;
        match r.state {
            FrfState::Done => return Ok(r),
            FrfState::Settling | FrfState::Measuring => b.wait(0.05_f64.max(0.1 * expect))?,
            FrfState::Stopped | FrfState::Idle => {
                let st = status(b)?;
                return Err(if !st.faults.is_empty() {
                    Error::Faulted {
                        faults: st.faults,
                        during: Some(format!("the measurement at {f_hz:.1} Hz")),
                    }
                } else {
                    Error::Device(format!(
                        "the measurement at {f_hz:.1} Hz stopped (bridge {})",
                        if st.enabled { "on" } else { "off" }
                    ))
                });
            }
        }
    }
    Err(Error::Device(format!(
        "the measurement at {f_hz:.1} Hz did not end"
    )))
}

/// Runs the sweep of `plan` on a device that holds its position (enabled): each point is
/// added to `out` (kept in frequency order) as it comes and passed to `on_point` (a running
/// count, the point), so that a sweep that fails keeps what it measured. With
/// `plan.velocity` the axis runs at that speed during each measurement, turning round before
/// a soft limit; with `plan.refine` the open loop is measured again between the points where
/// its margins are decided ([`refinement`]). The caller switches the bridge off on failure
/// ([`crate::client::guarded`]) and restores the settings.
pub fn sweep<B: Bench>(
    b: &mut B,
    plan: &Plan,
    out: &mut Vec<Point>,
    mut on_point: impl FnMut(usize, &Point),
) -> Result<(), Error> {
    let mut dir = 1.0;
    // The speed asked last [rad/s] (the sweep starts holding).
    let mut running = 0.0;
    let mut count = 0;
    let mut one = |b: &mut B, f: f64, out: &mut Vec<Point>| -> Result<(), Error> {
        let per = plan.periods_at(f);
        if let Some(v) = plan.velocity {
            // Run at the speed, turning round where the next point would pass a limit.
            let (lo, hi) = crate::client::soft_limits(b)?;
            let x = crate::client::position(b)?;
            let span = v.abs() * ((per.0 + per.1) as f64 / f + 0.5);
            if x + span > hi && x - span < lo {
                return Err(Error::Params(format!(
                    "--velocity {v}: the stroke between the soft limits is too short for a point at {f:.1} Hz"
                )));
            }
            if (dir > 0.0 && x + span > hi) || (dir < 0.0 && x - span < lo) {
                dir = -dir;
            }
            let want = dir * v.abs();
            if running != want {
                b.send(crate::client::velocity(want, None))?;
                // The ramp to the speed (50 rad/s², from the reference's own) and a settling
                // time of the loop.
                b.wait((want - running).abs() / 50.0 + 0.05)?;
                running = want;
            }
        }
        let r = measure(b, plan.lp.injection(), f, plan.amplitude, per)?;
        let (value, coherence) = r.transfer(plan.lp);
        let p = Point {
            f_hz: r.f_hz,
            value,
            coherence,
            reply: r,
        };
        on_point(count, &p);
        count += 1;
        let at = out.partition_point(|q| q.f_hz < p.f_hz);
        out.insert(at, p);
        Ok(())
    };
    for f in plan.frequencies() {
        one(b, f, out)?;
    }
    // Twice: the second pass narrows what the first found (a sharp sensitivity peak).
    for _ in 0..if plan.refine > 0 { 2 } else { 0 } {
        let l: Vec<(f64, Complex64)> = out.iter().map(|p| (p.f_hz, p.value)).collect();
        for f in refinement(&l, plan.refine) {
            one(b, f, out)?;
        }
    }
    if plan.velocity.is_some() {
        b.hold()?;
    }
    Ok(())
}

/// The pre-sliding spring and the inertia from a plant response measured at rest: below the
/// spring's resonance the mechanics are `k_m / (K − J ω² + j b ω)`, so `Re(k_m / P)` is a line
/// in ω² whose intercept is the stiffness `K` \[N·m/rad\] and whose slope is `−J`
/// \[kg·m²\]. Fitted by least squares over the points below half the frequency where the
/// plant's phase first passes −90° (the resonance), from the position per current measured
/// (the current loop's own lag left out). `None` with fewer than three such points.
pub fn presliding(points: &[Point], k_m: f64) -> Option<(f64, f64)> {
    let mech: Vec<(f64, Complex64)> = points
        .iter()
        .map(|p| (p.f_hz, p.reply.phasors[3] / p.reply.phasors[2]))
        .collect();
    let f_res = mech
        .iter()
        .find(|(_, z)| z.arg().to_degrees() < -90.0)
        .map(|(f, _)| *f)?;
    let xy: Vec<(f64, f64)> = mech
        .iter()
        .filter(|(f, _)| *f <= 0.5 * f_res)
        .map(|(f, z)| {
            let w = std::f64::consts::TAU * f;
            (w * w, (k_m / z).re)
        })
        .collect();
    if xy.len() < 3 {
        return None;
    }
    let n = xy.len() as f64;
    let (sx, sy) = xy.iter().fold((0.0, 0.0), |a, (x, y)| (a.0 + x, a.1 + y));
    let (mx, my) = (sx / n, sy / n);
    let (sxx, sxy) = xy.iter().fold((0.0, 0.0), |a, (x, y)| {
        (a.0 + (x - mx) * (x - mx), a.1 + (x - mx) * (y - my))
    });
    let slope = sxy / sxx;
    Some((my - slope * mx, -slope))
}

/// The resonances and anti-resonances of the mechanics in a plant sweep: the extrema of
/// `|pos / cur| (2πf)²`, the position per current *measured* (the motor's torque; the current
/// loop's own roll-off left out) relative to the rigid-body line (a free mass's falls as
/// 1/ω²), strongest first.
pub fn plant_extrema(points: &[Point]) -> Vec<Extremum> {
    let f: Vec<f64> = points.iter().map(|p| p.f_hz).collect();
    let l: Vec<f64> = points
        .iter()
        .map(|p| {
            let mech = p.reply.phasors[3] / p.reply.phasors[2];
            db(mech) + 40.0 * (std::f64::consts::TAU * p.f_hz).log10()
        })
        .collect();
    extrema(&f, &l)
}

/// What a sweep gave.
#[derive(Debug, Clone, PartialEq)]
pub struct Sweep {
    /// The plan it ran.
    pub plan: Plan,
    /// The points, in frequency order.
    pub points: Vec<Point>,
    /// The margins (the open loop).
    pub margins: Option<Margins>,
    /// The pre-sliding stiffness \[N·m/rad\] and inertia \[kg·m²\] (the plant at rest).
    pub presliding: Option<(f64, f64)>,
    /// The device's torque constant \[N·m/A\].
    pub k_m: f64,
    /// The device's compensator's initial stiffness, the sum of its GMS blocks' k (`gms.k1` …
    /// `gms.k6`, the actuator's) \[N·m/rad\].
    pub model_stiffness: f64,
}

/// The least coherence of a point that counts as a response (below it the excitation is
/// lost in the noise).
pub const MIN_COHERENCE: f64 = 0.9;

/// Runs `plan` on the device: checks it against the device's rate and current limit (nothing
/// moves on a bad plan), enables, sweeps, and puts the settings back with the bridge off
/// however it ends ([`crate::settings::restoring`]). The points measured are in `out` even
/// when it fails (a fault, a lost link, Ctrl-C); a sweep in which no point stands above the
/// noise is an error: the axis does not respond.
pub fn run<B: Bench>(
    b: &mut B,
    plan: &Plan,
    out: &mut Vec<Point>,
    on_point: impl FnMut(usize, &Point),
) -> Result<Sweep, Error> {
    let pos_hz = crate::client::get_param(b, ParamId::RatePosHz)?;
    let i_max = crate::client::get_param(b, ParamId::LimIMax)?;
    let k_m = crate::client::get_param(b, ParamId::MotorKM)?;
    plan.check(pos_hz, i_max)?;
    let dev = crate::settings::read(b)?;
    // The GMS model the protocol shows (`gms.k1` … `gms.k6`: the actuator's).
    let model_stiffness: f64 = dev.ff.actuator.blocks.iter().map(|bl| bl.k as f64).sum();
    crate::settings::restoring(b, |b| {
        crate::client::guarded(b, |b| {
            b.enable()?;
            b.wait(0.2)?;
            sweep(b, plan, out, on_point)?;
            b.disable()
        })
    })?;
    let responding = out.iter().filter(|p| p.coherence >= MIN_COHERENCE).count();
    if responding == 0 {
        return Err(Error::Device(format!(
            "the axis does not respond: no point of {} stands above the noise (coherence \
             under {MIN_COHERENCE}; is the motor connected, the bridge powered, the amplitude \
             large enough?)",
            out.len()
        )));
    }
    let pairs: Vec<(f64, Complex64)> = out.iter().map(|p| (p.f_hz, p.value)).collect();
    Ok(Sweep {
        plan: plan.clone(),
        points: out.clone(),
        margins: (plan.lp == Loop::Open).then(|| margins(&pairs)),
        presliding: (plan.lp == Loop::Plant && plan.velocity.is_none())
            .then(|| presliding(out, k_m))
            .flatten(),
        k_m,
        model_stiffness,
    })
}
