//! The paper's experiments on a bench: the sliding sweep, the pre-sliding staircase with its
//! erase, the frictional-lag run, their plans sized for the device's encoder, and their data
//! as CSV.

use crate::Error;
use crate::client::{
    Bench, DeviceInfo, VELOCITY_ACC, capture_now, capture_rows, capture_wait, check_faults,
    guarded, move_to, narrow_limits, position, primitive, timed_run,
};
use crate::client::{capture_status, get_param_if_known, velocity};
use crate::commission::slide;
use crate::settings::restoring;
use gms_core::drive::Faults;
use gms_core::protocol::Command;
use gms_core::protocol::ParamId;

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

/// The sliding experiment (paper §3): at each speed, in both directions, a timed velocity run
/// from rest (the device ends it by itself, so the stroke never depends on the link's
/// timing), captured whole; after the ramp and the settling stroke, the mean friction
/// torque (current × k_M, the loop's own torque constant, at constant speed the whole of the
/// motor torque) and the measured speed (the encoder over the window). Pushes `(v, f)` pairs
/// as `hil-sim experiment sliding` writes them onto `out` as they are measured (so that a run
/// cut short keeps them). Runs in the measuring loop
/// ([`gms_ident::gains::measuring_loop`]: the tracking loop's speed ripple reads the friction
/// high at low speed) and ends with the device's settings put back and the bridge off. Fails
/// (the bridge off) when the axis does not follow the speed (measured below half of it, or
/// the other way) or the device latches a fault.
pub fn sliding(
    b: &mut impl Bench,
    plan: &SlidingPlan,
    out: &mut Vec<(f64, f64)>,
) -> Result<(), Error> {
    measuring(b, |b| sweep(b, plan, out))
}

/// Runs `f` with the position loop set to the measuring loop
/// ([`gms_ident::gains::measuring_loop`]: the device's `pos.kd` kept, `pos.kp`, `pos.ki` and
/// `pos.d_filter_hz` softened for an overdamped velocity loop on its `ff.inertia`; the loop
/// as it is where none can be built on it) with a plain integral (`pos.ki_fric` 0: the
/// experiments measure the friction the compensator's model is fitted to, and an integral
/// that turns over with the old model would carry that model into the data), the device's
/// settings put back after (and the bridge off), however `f` ended.
pub(crate) fn measuring<B: Bench, T>(
    b: &mut B,
    f: impl FnOnce(&mut B) -> Result<T, Error>,
) -> Result<T, Error> {
    restoring(b, |b| {
        // A firmware that does not know one of them (an older one): the loop as it is.
        let mut read = |p: ParamId| get_param_if_known(b, p);
        let figures = [
            read(ParamId::PosKp)?,
            read(ParamId::PosKd)?,
            read(ParamId::PosDFilterHz)?,
            read(ParamId::FfInertia)?,
            read(ParamId::RatePosHz)?,
        ];
        let m = match figures {
            [Some(kp), Some(kd), Some(f), Some(j), Some(hz)] => {
                gms_ident::gains::measuring_loop(kp, kd, f, j, hz)
            }
            _ => None,
        };
        if let Some(m) = m {
            b.set(ParamId::PosKp, m.kp)?;
            b.set(ParamId::PosKi, m.ki)?;
            b.set(ParamId::PosDFilterHz, m.d_filter_hz)?;
        }
        if get_param_if_known(b, ParamId::PosKiFric)?.is_some() {
            b.set(ParamId::PosKiFric, 0.0)?;
        }
        f(b)
    })
}

/// The sweep of [`sliding`], in the loop set by it.
fn sweep(b: &mut impl Bench, plan: &SlidingPlan, out: &mut Vec<(f64, f64)>) -> Result<(), Error> {
    guarded(b, |b| {
        let dev = DeviceInfo::read(b)?;
        let dt = dev.dt();
        b.enable()?;
        for &v in &plan.speeds {
            for dir in [1.0, -1.0] {
                let v = dir * v;
                // A timed run (`velocity V 0 1 1 SECONDS`: no swing, then a ramp to rest that
                // the device makes by itself, so the stroke never depends on the link's
                // timing: a late stop over a slow link, or on a virtual device faster than
                // real time, would overrun the window), captured whole — the current as the
                // mean over each decimated sample's steps (`current_mean`): the loop's current
                // ripples at the encoder's count rate, and single steps every N alias it into
                // the window's mean (up to ±2 % of the friction at 20 kHz).
                let t_acc = v.abs() / VELOCITY_ACC;
                timed_run(
                    b,
                    v,
                    plan.settle(v) + plan.window(v, dt) + 0.02,
                    "t,pos,current_mean",
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
        b.hold()?;
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
pub(crate) struct Settled {
    /// Mean position, absolute (from the capture's origin) \\[rad\\].
    x: f64,
    /// Mean current \\[A\\].
    i: f64,
    /// Speed over the samples (second half's mean position against the first's) \\[rad/s\\].
    creep: f64,
}

/// The means of a `samples`-step capture taken now.
pub(crate) fn settled(b: &mut impl Bench, samples: u32, dt: f64) -> Result<Settled, Error> {
    let most = crate::client::capture_capacity(b)?.div_euclid(2).max(2);
    let rows = capture_now(b, "pos,current", samples.clamp(2, most), dt)?;
    let origin = capture_status(b)?.origin;
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
    // The device's own guard: its stroke limits narrowed around the start, put back after
    // (with the measuring loop's gains, which the erase moves in).
    measuring(b, |b| {
        narrow_limits(b, plan.guard)?;
        guarded(b, |b| staircase(b, plan, out))
    })
}

/// Whether the device's only latched fault is `position_limit` (a guard reached).
pub(crate) fn only_position_limit(b: &mut impl Bench) -> bool {
    matches!(check_faults(b), Err(e) if e.faults() == Some(Faults::POSITION_LIMIT))
}

/// The staircase of [`presliding`], within the guard set by it.
pub(crate) fn staircase(
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
    primitive(b, Command::Enable { current: true })?;
    b.wait(plan.dwell)?;
    // The start (no torque): the origin of the displacements, not a point of the curve.
    let x0 = settled(b, plan.samples, dt)?.x;
    // A thousandth of the window (20 µrad by default, five counts of a 3.8 µrad
    // encoder), and never under two counts: beyond noise and quantisation (on a coarse
    // encoder the settled mean flickers by a fraction of a count as the axis creeps between
    // two of them: 0.13 of a 3.14 mrad count seen under the first 2.6 mA step).
    let against = (plan.window / 1000.0).max(2.0 * dev.rad_per_count);
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
                b.current(amps)?;
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
                b.clear()?;
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
            // Held where the axis is, then given the time to stop: a hold that lands just
            // inside the guard with the axis still running (a host slow against the device's
            // clock) brakes it past the guard, which latches after the hold was accepted
            // (seen in CI on the image on emulated silicon: the next experiment refused).
            let held = b
                .hold()
                .and_then(|()| b.wait(HOLD_SETTLE))
                .and_then(|()| check_faults(b));
            return match held {
                Ok(()) => Ok(()),
                // Broken away, it ran on to the guard before the hold came, or braked past
                // it after (a host slow against the device's clock: seen in CI against
                // `--speed 20`): the same end as the guard's during a step, the bridge off.
                Err(_) if only_position_limit(b) => b.clear(),
                Err(e) => Err(e),
            };
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

/// The time a hold after breakaway is given to stop the axis before the staircase checks
/// that the guard was not reached \\[s\\]: the measuring loop brakes the axis in a few
/// milliseconds.
pub(crate) const HOLD_SETTLE: f64 = 0.1;

/// The ratio of one erase swing to the one before \\[-\\]: each block is left within
/// ±(1 − r)/(1 + r) of its slip deflection of zero (±2.6 % at 0.95).
pub(crate) const ERASE_RATIO: f64 = 0.95;

/// The erase's speed, a fraction of the compensator's Stribeck velocity \\[-\\].
pub(crate) const ERASE_SPEED: f64 = 0.25;

/// The friction's memory erased about where the axis is: position-loop swings each way,
/// from `plan.window` down by [`ERASE_RATIO`] per swing to below `plan.erase_min`, slowly (at
/// a quarter of the compensator's Vs, near the Stribeck curve's static end: a block that slips
/// faster saturates lower, and its residual grows; at Vs the virgin curves of the property
/// test came out up to 6.1 % of Fs off instead of 4.6 %), then back to the start. A block of
/// the model is an elasto-slip element: a swing beyond its slip deflection resets it, the
/// smaller swings after leave it near zero. About 35 s of device time with the defaults.
pub(crate) fn erase(
    b: &mut impl Bench,
    plan: &PreslidingPlan,
    dev: &DeviceInfo,
) -> Result<(), Error> {
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
        // The plan's decimation, or more if the buffer (two fields) needs it.
        let room = crate::client::capture_capacity(b)? as f64;
        let every = plan
            .every
            .max(crate::client::decimation(plan.seconds / dt, 2, room));
        let samples = (plan.seconds / (dt * every as f64)).floor() as u32;
        b.enable()?;
        primitive(b, velocity(plan.mean, None))?;
        b.wait(1.0)?;
        b.capture("pos,friction", every, samples, true)?;
        b.send(velocity(
            plan.mean,
            Some((plan.amp, plan.f0, plan.f1, plan.seconds)),
        ))?;
        b.wait(plan.seconds)?;
        capture_wait(b, 0.05, 400)?;
        check_faults(b)?;
        let rows = capture_rows(b)?;
        b.hold()?;
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
    // The staircase loads one way, positive: its direction is the command's, not the
    // measured load's sign (the first steps' mean current is within the sense's noise of
    // zero, and a point read below it would be taken as the other direction's).
    let mut text = String::from("x,f,dir\n");
    for (x, f) in data {
        text += &format!("{x},{f},1\n");
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

/// The experiments' ranges as a user gives them; `None`: derived from the device's
/// parameters (its compensator's Fs and Vs). The same options on every command that runs the
/// experiments (`gms-tune identify`, `hil-sim experiment`), so that an error can name them.
#[derive(Debug, Clone, Default, clap::Args)]
pub struct Ranges {
    /// The staircase's torque step [N·m] (default: the device's gms.fs / 100).
    #[arg(long)]
    pub torque_step: Option<f64>,
    /// The slowest sliding speed [rad/s] (default: the device's gms.vs / 10).
    #[arg(long)]
    pub v_min: Option<f64>,
    /// The fastest sliding speed [rad/s] (default: 30 × the device's gms.vs).
    #[arg(long)]
    pub v_max: Option<f64>,
    /// The number of sliding speeds, log-spaced (4 to 50; default 10).
    #[arg(long)]
    pub speeds: Option<usize>,
    /// The stroke window around the start, each way \[rad\] (default 5): the device's stroke
    /// limits are narrowed to it while the experiments run.
    #[arg(long)]
    pub window: Option<f64>,
    /// Skip the erase of the friction's memory before the staircase (right after power-up
    /// the state is virgin already; the erase takes about 35 s).
    #[arg(long)]
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
    /// The stroke the sweep's fastest run needs \\[rad\\] ([`Plans::check_sliding`]).
    pub sliding_stroke: f64,
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
        let step_t = pos(
            "--torque-step",
            ranges.torque_step.unwrap_or(dev.fs / 100.0),
        )?;
        let steps_to_fs = dev.fs / step_t;
        if !(10.0..=1000.0).contains(&steps_to_fs) {
            return Err(Error::Params(format!(
                "--torque-step {step_t:.3e} N·m: the staircase would take {steps_to_fs:.0} steps \
                 to the expected Fs {:.3e} N·m (10 to 1000)",
                dev.fs
            )));
        }
        let v_min = pos("--v-min", ranges.v_min.unwrap_or(dev.vs / 10.0))?;
        let v_max = pos("--v-max", ranges.v_max.unwrap_or(30.0 * dev.vs))?;
        if v_min >= v_max || v_max > 20.0 {
            return Err(Error::Params(format!(
                "--v-min {v_min} and --v-max {v_max} rad/s: the slowest speed must be below the \
                 fastest, the fastest at most 20 rad/s"
            )));
        }
        let n = ranges.speeds.unwrap_or(10);
        if !(4..=50).contains(&n) {
            return Err(Error::Params(format!("--speeds {n}: 4 to 50")));
        }
        let window = pos("--window", ranges.window.unwrap_or(5.0))?;
        let mut presliding =
            PreslidingPlan::new(step_t / dev.k_m, 0).for_encoder(dev.rad_per_count, dev.dt());
        // Up to three times the expected breakaway: an axis that holds more is blocked.
        presliding.max_steps = (3.0 * steps_to_fs).ceil() as u32;
        presliding.erase = !ranges.no_erase;
        presliding.window = presliding.window.min(window);
        let sliding = SlidingPlan::log_spaced(v_min, v_max, n).for_encoder(dev.rad_per_count);
        let sliding_stroke = sliding.stroke(dev.dt());
        Ok(Plans {
            presliding,
            sliding,
            window,
            sliding_stroke,
        })
    }

    /// Refuses a sliding sweep whose fastest run needs more stroke than the window, naming
    /// the options that change it (`--v-max`, `--window`). The sweep's callers check it
    /// before anything moves (`gms-tune identify`, `hil-sim experiment sliding`); the
    /// staircase alone (`hil-sim experiment presliding`) does not need it.
    pub fn check_sliding(&self) -> Result<(), Error> {
        let need = self.sliding_stroke;
        if need > self.window {
            let v_max = self
                .sliding
                .speeds
                .iter()
                .fold(0.0, |a: f64, v| a.max(v.abs()));
            // Rounded: the log-spaced speeds end at the asked one within a rounding.
            let v_max = (v_max * 1e6).round() / 1e6;
            return Err(Error::Params(format!(
                "the sliding run at {v_max} rad/s needs {need:.2} rad of stroke, more than the \
                 window {} rad: lower --v-max or widen --window",
                self.window
            )));
        }
        Ok(())
    }
}
