//! Reference trajectories for the position loop: holds, steps, staircases, sinusoids with
//! velocity reversals, and jerk-limited point-to-point moves, played one after the other.
//!
//! Positions are kept as fixed-point encoder counts ([`SubCounts`], 1/65536 count) so that a
//! long stroke loses nothing to f32 rounding; each segment's shape is computed in f32 relative
//! to the segment's start.

use crate::math;

/// Fractional bits of [`SubCounts`].
pub const SUB_BITS: u32 = 16;
/// One encoder count in [`SubCounts`].
pub const SUB_PER_COUNT: f32 = (1u32 << SUB_BITS) as f32;

/// A position in 1/65536 of an encoder count (fixed point, i64).
pub type SubCounts = i64;

/// `count` encoder counts in [`SubCounts`], saturating: `count.saturating_mul(1 << SUB_BITS)`
/// by a shift and two compares (the M4F has no 64-bit multiply with an overflow flag: the
/// multiply took 22 instructions in every position step).
#[inline]
pub fn sub_counts(count: i64) -> SubCounts {
    const HI: i64 = i64::MAX >> SUB_BITS;
    const LO: i64 = i64::MIN >> SUB_BITS;
    if count > HI {
        i64::MAX
    } else if count < LO {
        i64::MIN
    } else {
        count << SUB_BITS
    }
}

/// One piece of a reference trajectory. Distances in rad (at the encoder), times in s.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Segment {
    /// Stay where the previous segment ended for `duration` \[s\].
    Hold {
        /// Duration \[s\].
        duration: f32,
    },
    /// An instantaneous step of `distance` \[rad\], then `dwell` \[s\] at rest.
    Step {
        /// Step size \[rad\].
        distance: f32,
        /// Time at rest after the step \[s\].
        dwell: f32,
    },
    /// `count` steps of `distance` \[rad\], each followed by `dwell` \[s\].
    Staircase {
        /// Step size \[rad\].
        distance: f32,
        /// Number of steps.
        count: u32,
        /// Time at rest after each step \[s\].
        dwell: f32,
    },
    /// `x = A (1 - cos(2 pi f t))` for `cycles` periods: starts and ends at rest, reverses
    /// at 0 and 2A.
    Sine {
        /// Amplitude A \[rad\].
        amplitude: f32,
        /// Frequency f \[Hz\].
        freq: f32,
        /// Number of periods.
        cycles: f32,
    },
    /// A jerk-limited point-to-point move of `distance` \[rad\] (quintic minimum-jerk profile,
    /// its duration the shortest that keeps speed, acceleration and jerk within the limits),
    /// then `dwell` \[s\] at rest.
    Move {
        /// Distance \[rad\].
        distance: f32,
        /// Speed limit [rad/s].
        vmax: f32,
        /// Acceleration limit [rad/s^2].
        amax: f32,
        /// Jerk limit [rad/s^3].
        jmax: f32,
        /// Time at rest after the move \[s\].
        dwell: f32,
    },
}

/// Why a segment is invalid.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum SegmentError {
    /// A value is NaN or infinite (segment index).
    NonFinite(usize),
    /// A duration, dwell, frequency, cycle count or limit is not positive where it must be.
    NotPositive(usize),
}

impl core::fmt::Display for SegmentError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            SegmentError::NonFinite(i) => write!(f, "reference segment {i}: value not finite"),
            SegmentError::NotPositive(i) => {
                write!(
                    f,
                    "reference segment {i}: durations, frequency and limits must be > 0"
                )
            }
        }
    }
}

impl Segment {
    /// Checks the segment (index `i` names it in the error).
    pub fn validate(&self, i: usize) -> Result<(), SegmentError> {
        let (vals, pos): (&[f32], &[f32]) = match self {
            Segment::Hold { duration } => (&[*duration], &[*duration]),
            Segment::Step { distance, dwell } => (&[*distance, *dwell], &[*dwell]),
            Segment::Staircase {
                distance, dwell, ..
            } => (&[*distance, *dwell], &[*dwell]),
            Segment::Sine {
                amplitude,
                freq,
                cycles,
            } => (&[*amplitude, *freq, *cycles], &[*freq, *cycles]),
            Segment::Move {
                distance,
                vmax,
                amax,
                jmax,
                dwell,
            } => (
                &[*distance, *vmax, *amax, *jmax, *dwell],
                &[*vmax, *amax, *jmax],
            ),
        };
        if vals.iter().any(|v| !v.is_finite()) {
            return Err(SegmentError::NonFinite(i));
        }
        if pos.iter().any(|v| *v <= 0.0) {
            return Err(SegmentError::NotPositive(i));
        }
        Ok(())
    }

    /// Duration of the move part of a `Move` \[s\].
    fn move_time(distance: f32, vmax: f32, amax: f32, jmax: f32) -> f32 {
        let d = abs(distance);
        // Quintic x = D(10u^3 - 15u^4 + 6u^5): peak v = 1.875 D/T, a = 5.7735 D/T^2,
        // jerk = 60 D/T^3.
        let tv = 1.875 * d / vmax;
        let ta = sqrt(5.773_503 * d / amax);
        let tj = cbrt(60.0 * d / jmax);
        tv.max(ta).max(tj).max(1e-6)
    }

    /// Total duration \[s\].
    pub fn duration(&self) -> f32 {
        match *self {
            Segment::Hold { duration } => duration,
            Segment::Step { dwell, .. } => dwell,
            Segment::Staircase { count, dwell, .. } => count as f32 * dwell,
            Segment::Sine { freq, cycles, .. } => cycles / freq,
            Segment::Move {
                distance,
                vmax,
                amax,
                jmax,
                dwell,
            } => Self::move_time(distance, vmax, amax, jmax) + dwell,
        }
    }

    /// Offset from the segment's start \[rad\], velocity [rad/s] and acceleration [rad/s^2] at
    /// time `t` \[s\] into the segment (t in [0, duration]).
    fn eval(&self, t: f32) -> (f32, f32, f32) {
        match *self {
            Segment::Hold { .. } => (0.0, 0.0, 0.0),
            Segment::Step { distance, .. } => (distance, 0.0, 0.0),
            Segment::Staircase {
                distance,
                count,
                dwell,
            } => {
                let k = ((t / dwell) as u32 + 1).min(count);
                (distance * k as f32, 0.0, 0.0)
            }
            Segment::Sine {
                amplitude, freq, ..
            } => {
                let w = 2.0 * core::f32::consts::PI * freq;
                let (s, c) = sin_cos(w * t);
                (
                    amplitude * (1.0 - c),
                    amplitude * w * s,
                    amplitude * w * w * c,
                )
            }
            Segment::Move {
                distance,
                vmax,
                amax,
                jmax,
                ..
            } => {
                let tm = Self::move_time(distance, vmax, amax, jmax);
                if t >= tm {
                    return (distance, 0.0, 0.0);
                }
                let u = t / tm;
                let u2 = u * u;
                let x = distance * u2 * u * (10.0 - 15.0 * u + 6.0 * u2);
                let v = distance / tm * 30.0 * u2 * (1.0 - 2.0 * u + u2);
                let a = distance / (tm * tm) * 60.0 * u * (1.0 - 3.0 * u + 2.0 * u2);
                (x, v, a)
            }
        }
    }
}

/// One sample of the reference: position (fixed-point counts), velocity, acceleration.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RefSample {
    /// Position [1/65536 count].
    pub pos: SubCounts,
    /// Velocity [rad/s].
    pub vel: f32,
    /// Acceleration [rad/s^2].
    pub acc: f32,
}

/// Plays up to `S` segments one after the other, sampled at a fixed period.
#[derive(Debug, Clone)]
pub struct Reference<const S: usize> {
    segs: [Segment; S],
    len: usize,
    rad_per_count: f32,
    idx: usize,
    t: f32,
    start: SubCounts,
    last: RefSample,
}

impl<const S: usize> Reference<S> {
    /// A reference starting at `start` [1/65536 count] with the segments `segs` (at most
    /// `S`), for an encoder of `rad_per_count` \[rad\]. Errors name the first bad segment.
    pub fn try_new(
        segs: &[Segment],
        rad_per_count: f32,
        start: SubCounts,
    ) -> Result<Self, SegmentError> {
        if segs.len() > S {
            return Err(SegmentError::NotPositive(S));
        }
        let mut arr = [Segment::Hold { duration: 0.0 }; S];
        for (i, (slot, s)) in arr.iter_mut().zip(segs).enumerate() {
            s.validate(i)?;
            *slot = *s;
        }
        Ok(Reference {
            segs: arr,
            len: segs.len(),
            rad_per_count,
            idx: 0,
            t: 0.0,
            start,
            last: RefSample {
                pos: start,
                vel: 0.0,
                acc: 0.0,
            },
        })
    }

    /// Total duration of all segments \[s\].
    pub fn duration(&self) -> f32 {
        let segs = self.segs.get(..self.len).unwrap_or(&[]);
        segs.iter().map(Segment::duration).sum()
    }

    /// True once every segment has been played.
    pub fn done(&self) -> bool {
        self.idx >= self.len
    }

    /// The last sample returned (the start position before the first call).
    pub fn last(&self) -> RefSample {
        self.last
    }

    /// Index of the segment being played (== number of segments when done).
    pub fn segment_index(&self) -> usize {
        self.idx
    }

    /// Returns the sample at the current time, then advances the time by `dt` \[s\]. The first
    /// call returns the start (t = 0). After the last segment the reference holds its final
    /// position.
    pub fn next(&mut self, dt: f32) -> RefSample {
        while let Some(&seg) = self.segs.get(self.idx).filter(|_| self.idx < self.len) {
            let d = seg.duration();
            if self.t < d {
                let (x, v, a) = seg.eval(self.t);
                self.last = RefSample {
                    pos: self.start + self.to_sub(x),
                    vel: v,
                    acc: a,
                };
                self.t += dt;
                return self.last;
            }
            // Segment finished: its end becomes the next start.
            let (x, _, _) = seg.eval(d);
            self.start += self.to_sub(x);
            self.t -= d;
            self.idx += 1;
        }
        self.t += dt;
        self.last = RefSample {
            pos: self.start,
            vel: 0.0,
            acc: 0.0,
        };
        self.last
    }

    fn to_sub(&self, rad: f32) -> SubCounts {
        let c = rad / self.rad_per_count * SUB_PER_COUNT;
        // Round to nearest; saturating conversion for absurd values.
        crate::math::round_to_i64(c)
    }
}

/// The fastest reference of the protocol's `velocity` (mean plus sweep amplitude) [rad/s].
pub const VELOCITY_MAX: f32 = 20.0;

/// A sweep around the mean speed of a [`VelocityProfile`] (the frictional-lag experiment):
/// `amp sin(2π (f0 t + (f1 - f0) t² / 2 T))`, its frequency going linearly from `f0` to `f1`
/// over `seconds` (T).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sweep {
    /// Amplitude [rad/s], `>= 0`.
    pub amp: f32,
    /// Start frequency \[Hz\], `> 0`.
    pub f0: f32,
    /// End frequency \[Hz\], `> 0`.
    pub f1: f32,
    /// Duration \[s\], `> 0`; after it the speed ramps to rest and stays there.
    pub seconds: f32,
}

/// The reference of the protocol's `velocity`: from the reference's own speed, the speed ramps
/// to `vel` at up to `amax`; then, with a [`Sweep`], it oscillates around `vel` for the sweep's
/// duration (starting at phase 0, so the speed is continuous), then ramps to rest and stays
/// there (a run that ends on the device: with an amplitude of 0, a timed constant speed). The
/// position is the speed's integral (trapezoid per step) in fixed point, so that a long run
/// does not drift and no control step does double arithmetic in software: the step's mean
/// speed as an exact multiple of 2^-40 rad/s, times the step's length in sub-counts per rad/s
/// (computed once per step length, in f64), accumulated in integer sub-counts with a 32-bit
/// fraction carried.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VelocityProfile {
    /// Position \[sub-counts\] and its fraction \[2^-32 sub-count\].
    pos: SubCounts,
    frac: u32,
    /// The step length `dt` \[s\] prepared (0: none yet), and it in sub-counts per rad/s
    /// \[2^-32 sub-count per rad/s\]: see [`VelocityProfile::next`].
    per_speed: (f32, i64),
    v: f32,
    vel: f32,
    amax: f32,
    sweep: Option<Sweep>,
    t_sweep: f32,
    ramped: bool,
    sub_per_rad: f64,
}

impl VelocityProfile {
    /// The profile from the reference sample `from` to the speed `vel` [rad/s] (with a
    /// `sweep`), speed changes at up to `amax` [rad/s²], for an encoder of `rad_per_count`
    /// \[rad\]. Errors: a value not finite, a limit or a sweep figure not positive, or
    /// |vel| + amp above [`VELOCITY_MAX`].
    pub fn new(
        from: RefSample,
        vel: f32,
        sweep: Option<Sweep>,
        amax: f32,
        rad_per_count: f32,
    ) -> Result<Self, SegmentError> {
        let amp = sweep.map_or(0.0, |s| s.amp);
        let finite = [vel, amax, rad_per_count, amp, from.vel]
            .iter()
            .all(|x| x.is_finite());
        if !finite {
            return Err(SegmentError::NonFinite(0));
        }
        if let Some(s) = sweep
            && !(s.f0.is_finite() && s.f1.is_finite() && s.seconds.is_finite())
        {
            return Err(SegmentError::NonFinite(0));
        }
        let bad_sweep =
            sweep.is_some_and(|s| s.amp < 0.0 || s.f0 <= 0.0 || s.f1 <= 0.0 || s.seconds <= 0.0);
        if amax <= 0.0 || rad_per_count <= 0.0 || bad_sweep || abs(vel) + amp > VELOCITY_MAX {
            return Err(SegmentError::NotPositive(0));
        }
        Ok(VelocityProfile {
            pos: from.pos,
            frac: 0,
            per_speed: (0.0, 0),
            v: from.vel,
            vel,
            amax,
            sweep,
            t_sweep: 0.0,
            ramped: false,
            sub_per_rad: SUB_PER_COUNT as f64 / rad_per_count as f64,
        })
    }

    /// The mean speed [rad/s].
    pub fn speed(&self) -> f32 {
        self.vel
    }

    /// This profile prepared for steps of `dt` \[s\] (the position loop's period): the
    /// step's factor for the position computed here, in f64, so that no control step does
    /// it (a step of another length computes it when first used).
    pub fn for_step(mut self, dt: f32) -> Self {
        let k = dt as f64 * self.sub_per_rad * 4_294_967_296.0;
        // Within ±2^63 up to steps of 0.25 s with a 3.8 µrad encoder.
        self.per_speed = (dt, k.clamp(-9.2e18, 9.2e18) as i64);
        self
    }

    /// The reference for the next step of `dt` \[s\].
    pub fn next(&mut self, dt: f32) -> RefSample {
        let v0 = self.v;
        let acc;
        if !self.ramped {
            let dv = self.vel - self.v;
            let step = self.amax * dt;
            if abs(dv) <= step {
                self.v = self.vel;
                self.ramped = true;
            } else {
                self.v += if dv > 0.0 { step } else { -step };
            }
            acc = if dt > 0.0 { (self.v - v0) / dt } else { 0.0 };
        } else if let Some(s) = self.sweep
            && self.t_sweep < s.seconds
        {
            self.t_sweep += dt;
            let t = math::min(self.t_sweep, s.seconds);
            let tau = core::f32::consts::TAU;
            let phase = tau * (s.f0 * t + (s.f1 - s.f0) * t * t / (2.0 * s.seconds));
            let f = s.f0 + (s.f1 - s.f0) * t / s.seconds;
            let (sin, cos) = sin_cos(phase);
            if self.t_sweep >= s.seconds {
                // The run is over: the speed ramps to rest (and stays there), so a timed run
                // ends on the device whatever the link does.
                self.v = self.vel;
                self.vel = 0.0;
                self.ramped = false;
                acc = 0.0;
            } else {
                self.v = self.vel + s.amp * sin;
                acc = s.amp * cos * tau * f;
            }
        } else {
            self.v = self.vel;
            acc = 0.0;
        }
        // The trapezoid: the mean of the two speeds (their f32 mean, as the profile has always
        // integrated it) in 2^-40 rad/s, exact, times `k`, dt in 2^-32 sub-counts per rad/s
        // (computed once per step length in f64: 52 bits at 20 kHz with the paper's encoder,
        // rounded by less than 1e-15), shifted right by 40.
        if self.per_speed.0 != dt {
            // Not prepared for this step (`for_step`): computed here, once.
            *self = self.for_step(dt);
        }
        let k = self.per_speed.1;
        let mean_fx = speed_fx(0.5 * (v0 + self.v));
        let inc = (mean_fx as i128 * k as i128) >> 40;
        // inc = whole · 2^32 + low (whole floored), the carry from the fraction added.
        let low = self.frac as i128 + (inc & 0xFFFF_FFFF);
        self.frac = low as u32;
        let whole = (inc >> 32) + (low >> 32);
        self.pos = self
            .pos
            .saturating_add(whole.clamp(i64::MIN as i128, i64::MAX as i128) as i64);
        RefSample {
            pos: self.pos,
            vel: self.v,
            acc,
        }
    }
}

/// `v` \[rad/s\] in 2^-40 rad/s, exactly for |v| from 2^-17 to 2^15 rad/s (an f32's 24 bits
/// fit), without a soft 64-bit conversion: the whole 2^-16 steps and the rest, each through
/// the FPU's conversion to i32 (`x - hi` is exact: both share x's exponent range).
fn speed_fx(v: f32) -> i64 {
    let x = v * 65_536.0;
    let within = x.abs() < 2_147_483_520.0;
    if !within {
        // Beyond any speed a profile takes (or NaN: 0): saturated.
        return if x.is_nan() {
            0
        } else if x > 0.0 {
            1 << 62
        } else {
            -(1 << 62)
        };
    }
    let hi = x as i32;
    let lo = ((x - hi as f32) * 16_777_216.0) as i32;
    ((hi as i64) << 24) + lo as i64
}

/// Speed limit of the protocol's `move` when none is given [rad/s].
pub const MOVE_VMAX: f32 = 0.5;
/// Acceleration limit of the protocol's `move` [rad/s^2].
pub const MOVE_AMAX: f32 = 50.0;
/// Jerk limit of the protocol's `move` [rad/s^3].
pub const MOVE_JMAX: f32 = 1e4;

/// A point-to-point move that starts from any state of the reference (position, velocity,
/// acceleration) and ends at rest on the target. A start with an acceleration first brings it
/// to zero at the jerk limit (a cubic piece: the speed changes by `a0² / 2 jmax`); from there a
/// quintic polynomial matches both ends' position, velocity and acceleration, with the
/// shortest duration (searched in steps of 5 % from the minimum-jerk time of the distance)
/// whose sampled speed, acceleration and jerk stay within the limits, or within the start's
/// own speed where that is higher. From rest it is the [`Segment::Move`] profile. A new move
/// planned from the reference of a move under way therefore continues it without a jump in
/// position, velocity or acceleration.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MovePlan {
    start: SubCounts,
    target: SubCounts,
    rad_per_count: f32,
    /// The start's velocity [rad/s] and acceleration [rad/s^2].
    v0: f32,
    a0: f32,
    /// The jerk of the first piece [rad/s^3] and its duration \[s\].
    jr: f32,
    tr: f32,
    /// Offset \[rad\] and velocity [rad/s] at the end of the first piece.
    x1: f32,
    v1: f32,
    c3: f32,
    c4: f32,
    c5: f32,
    /// Duration of the quintic \[s\].
    dur: f32,
    t: f32,
}

/// Time at rest after a move before it counts as finished \[s\].
const MOVE_DWELL: f32 = 1e-3;

impl MovePlan {
    /// A move from the reference sample `from` to `target` \[rad\] with the limits `vmax`
    /// [rad/s], `amax` [rad/s^2], `jmax` [rad/s^3] (all `> 0`), for an encoder of
    /// `rad_per_count` \[rad\]. Planning costs up to a few thousand polynomial evaluations:
    /// plan outside the control step.
    pub fn new(
        from: RefSample,
        target: f32,
        vmax: f32,
        amax: f32,
        jmax: f32,
        rad_per_count: f32,
    ) -> Result<Self, SegmentError> {
        let finite = [target, vmax, amax, jmax, rad_per_count, from.vel, from.acc];
        if finite.iter().any(|v| !v.is_finite()) {
            return Err(SegmentError::NonFinite(0));
        }
        if vmax <= 0.0 || amax <= 0.0 || jmax <= 0.0 || rad_per_count <= 0.0 {
            return Err(SegmentError::NotPositive(0));
        }
        let target_sub = target as f64 / rad_per_count as f64 * SUB_PER_COUNT as f64;
        if target_sub.is_nan() || target_sub.abs() >= 9.0e18 {
            return Err(SegmentError::NonFinite(0));
        }
        let target_sub = if target_sub >= 0.0 {
            (target_sub + 0.5) as i64
        } else {
            (target_sub - 0.5) as i64
        };
        let d = (target_sub.saturating_sub(from.pos)) as f64 / SUB_PER_COUNT as f64
            * rad_per_count as f64;
        let d = d as f32;
        let (v0, a0) = (from.vel, from.acc);
        // First piece: the acceleration to zero at the jerk limit.
        let jr = if a0 > 0.0 { -jmax } else { jmax };
        let tr = abs(a0) / jmax;
        let x1 = tr * (v0 + tr * (0.5 * a0 + tr * jr / 6.0));
        let v1 = v0 + tr * (a0 + 0.5 * tr * jr);
        // Limits with room for f32 rounding (the jerk at the ends is a difference of terms
        // ten times its size).
        let vlim = vmax.max(abs(v0)).max(abs(v1)) * 1.0001;
        let alim = amax.max(abs(a0)) * 1.001;
        let jlim = jmax * 1.01;
        let t0 = Segment::move_time(d - x1, vmax, amax, jmax);
        let mut plan = MovePlan {
            start: from.pos,
            target: target_sub,
            rad_per_count,
            v0,
            a0,
            jr,
            tr,
            x1,
            v1,
            c3: 0.0,
            c4: 0.0,
            c5: 0.0,
            dur: t0,
            t: 0.0,
        };
        // First a plan that never backs up (the speed keeps its sign towards the target);
        // where the distance left is too short to stop in, one that overshoots and returns.
        let dir = if d - x1 < 0.0 { -1.0 } else { 1.0 };
        for monotonic in [true, false] {
            let mut dur = t0;
            for _ in 0..400 {
                plan.set_duration(d - x1, dur);
                if plan.within(vlim, alim, jlim, monotonic.then_some(dir)) {
                    return Ok(plan);
                }
                dur *= 1.05;
            }
        }
        // No duration keeps every limit (a start far beyond them): the last one tried is
        // still continuous.
        Ok(plan)
    }

    fn set_duration(&mut self, d: f32, dur: f32) {
        let v = self.v1;
        let t = dur;
        let (t2, t3) = (t * t, t * t * t);
        self.dur = dur;
        self.c3 = (20.0 * d - 12.0 * v * t) / (2.0 * t3);
        self.c4 = (-30.0 * d + 16.0 * v * t) / (2.0 * t3 * t);
        self.c5 = (12.0 * d - 6.0 * v * t) / (2.0 * t3 * t2);
    }

    /// Offset \[rad\], velocity, acceleration and jerk at `t` \[s\] from the start.
    fn eval(&self, t: f32) -> (f32, f32, f32, f32) {
        if t < self.tr {
            let (a0, jr) = (self.a0, self.jr);
            let x = t * (self.v0 + t * (0.5 * a0 + t * jr / 6.0));
            let v = self.v0 + t * (a0 + 0.5 * t * jr);
            return (x, v, a0 + t * jr, jr);
        }
        let t = t - self.tr;
        let (c3, c4, c5) = (self.c3, self.c4, self.c5);
        let x = self.x1 + t * (self.v1 + t * t * (c3 + t * (c4 + t * c5)));
        let v = self.v1 + t * t * (3.0 * c3 + t * (4.0 * c4 + t * 5.0 * c5));
        let a = t * (6.0 * c3 + t * (12.0 * c4 + t * 20.0 * c5));
        let j = 6.0 * c3 + t * (24.0 * c4 + t * 60.0 * c5);
        (x, v, a, j)
    }

    /// The quintic's sampled speed, acceleration and jerk within the limits, and with `dir`
    /// its velocity never against `dir`.
    fn within(&self, vlim: f32, alim: f32, jlim: f32, dir: Option<f32>) -> bool {
        const N: u32 = 64;
        // f32 rounding at the ends, where the velocity is a difference of larger terms.
        let back = -1e-4 * vlim;
        (0..=N).all(|k| {
            let (_, v, a, j) = self.eval(self.tr + self.dur * k as f32 / N as f32);
            let forward = dir.is_none_or(|d| v * d >= back);
            abs(v) <= vlim && abs(a) <= alim && abs(j) <= jlim && forward
        })
    }

    /// Duration of the motion, without the final dwell \[s\].
    pub fn duration(&self) -> f32 {
        self.tr + self.dur
    }

    /// The target [1/65536 count].
    pub fn target(&self) -> SubCounts {
        self.target
    }

    /// Moves the plan's clock on by `t` \[s\] (to join it at the step it is taken).
    pub fn skip(&mut self, t: f32) {
        if t.is_finite() && t > 0.0 {
            self.t += t;
        }
    }

    /// True once the motion and the dwell after it have played.
    pub fn done(&self) -> bool {
        self.t >= self.duration() + MOVE_DWELL
    }

    /// The sample at the plan's time, then the time moves on by `dt` \[s\].
    pub fn next(&mut self, dt: f32) -> RefSample {
        let t = self.t;
        self.t += dt;
        if t >= self.duration() {
            return RefSample {
                pos: self.target,
                vel: 0.0,
                acc: 0.0,
            };
        }
        let (x, v, a, _) = self.eval(t);
        let c = x / self.rad_per_count * SUB_PER_COUNT;
        let off = crate::math::round_to_i64(c);
        RefSample {
            pos: self.start.saturating_add(off),
            vel: v,
            acc: a,
        }
    }
}

/// The reference of a device: holding a position, or playing a [`MovePlan`].
#[derive(Debug, Clone)]
pub struct Motion {
    hold: SubCounts,
    moving: Option<MovePlan>,
    velocity: Option<VelocityProfile>,
}

impl Motion {
    /// Holding at `pos` [1/65536 count], no move.
    pub const fn holding(pos: SubCounts) -> Self {
        Motion {
            hold: pos,
            moving: None,
            velocity: None,
        }
    }

    /// The protocol's `move` from the reference sample `from` to `pos` \[rad\] at up to `vel`
    /// [rad/s] ([`MOVE_VMAX`] when `None`), within [`MOVE_AMAX`] and [`MOVE_JMAX`], for an
    /// encoder of `rad_per_count` \[rad\].
    pub fn plan(
        from: RefSample,
        pos: f32,
        vel: Option<f32>,
        rad_per_count: f32,
    ) -> Result<MovePlan, SegmentError> {
        let vmax = vel.unwrap_or(MOVE_VMAX);
        MovePlan::new(from, pos, vmax, MOVE_AMAX, MOVE_JMAX, rad_per_count)
    }

    /// Plays `m` from now on (replacing any move or speed under way).
    pub fn start(&mut self, m: MovePlan) {
        self.moving = Some(m);
        self.velocity = None;
    }

    /// Plays the speed profile `p` from now on (replacing any move under way); it runs
    /// until replaced or stopped.
    pub fn start_velocity(&mut self, p: &VelocityProfile) {
        // Copied once, from the request into place (by value it was copied out of the
        // request first, then into the option: two `memcpy` calls in the control step).
        self.velocity = Some(*p);
        self.moving = None;
    }

    /// The speed profile playing, if any.
    pub fn velocity_mut(&mut self) -> Option<&mut VelocityProfile> {
        self.velocity.as_mut()
    }

    /// True while a speed profile plays.
    pub fn is_velocity(&self) -> bool {
        self.velocity.is_some()
    }

    /// Drops any move under way and holds at `pos`.
    pub fn hold_at(&mut self, pos: SubCounts) {
        self.hold = pos;
        self.moving = None;
        self.velocity = None;
    }

    /// Drops any move or speed under way; the reference holds where it last was.
    pub fn stop(&mut self) {
        self.moving = None;
        self.velocity = None;
    }

    /// The reference position [1/65536 count] of the last step (where a finished move
    /// ended, or the hold position set).
    pub fn hold(&self) -> SubCounts {
        self.hold
    }

    /// True while a move or a speed profile plays.
    pub fn is_moving(&self) -> bool {
        self.moving.is_some() || self.velocity.is_some()
    }

    /// The reference for this step; advances a move by `dt` \[s\]. A finished move becomes
    /// the hold position.
    pub fn next(&mut self, dt: f32) -> RefSample {
        if let Some(p) = &mut self.velocity {
            let r = p.next(dt);
            self.hold = r.pos;
            return r;
        }
        if let Some(m) = &mut self.moving {
            let r = m.next(dt);
            self.hold = r.pos;
            if m.done() {
                self.moving = None;
            }
            return r;
        }
        RefSample {
            pos: self.hold,
            vel: 0.0,
            acc: 0.0,
        }
    }
}

fn abs(x: f32) -> f32 {
    if x < 0.0 { -x } else { x }
}

/// sqrt by exp/ln (accurate to ~1e-6 relative; only used for segment timing).
fn sqrt(x: f32) -> f32 {
    if x <= 0.0 {
        0.0
    } else {
        math::exp(0.5 * math::ln(x))
    }
}

/// Cube root of x >= 0.
fn cbrt(x: f32) -> f32 {
    if x <= 0.0 {
        0.0
    } else {
        math::exp(math::ln(x) / 3.0)
    }
}

/// sin and cos of `x` \[rad\]: reduction to [-pi/4, pi/4] and Taylor polynomials (error below
/// 1e-7 there; the reduction keeps ~1e-7 relative phase accuracy for |x| up to ~1e3).
pub fn sin_cos(x: f32) -> (f32, f32) {
    const FRAC_2_PI: f32 = core::f32::consts::FRAC_2_PI;
    const PIO2_HI: f32 = 1.570_796_4;
    const PIO2_LO: f32 = -4.371_139e-8;
    let q = x * FRAC_2_PI;
    let n = if q >= 0.0 {
        (q + 0.5) as i32
    } else {
        (q - 0.5) as i32
    };
    let nf = n as f32;
    let r = (x - nf * PIO2_HI) - nf * PIO2_LO;
    let r2 = r * r;
    let s = r * (1.0 + r2 * (-1.0 / 6.0 + r2 * (1.0 / 120.0 + r2 * (-1.0 / 5040.0))));
    let c = 1.0 + r2 * (-0.5 + r2 * (1.0 / 24.0 + r2 * (-1.0 / 720.0 + r2 / 40320.0)));
    match n & 3 {
        0 => (s, c),
        1 => (c, -s),
        2 => (-s, -c),
        _ => (-c, s),
    }
}

#[cfg(test)]
mod sub_counts_by_shift {
    use super::{SUB_PER_COUNT, sub_counts};
    use proptest::prelude::*;

    /// What the shift replaces: the saturating multiply.
    fn by_multiply(c: i64) -> i64 {
        c.saturating_mul(SUB_PER_COUNT as i64)
    }

    proptest! {
        /// The shift agrees with the saturating multiply over the whole range.
        #[test]
        fn sub_counts_saturate_as_the_multiply(c in any::<i64>()) {
            prop_assert_eq!(sub_counts(c), by_multiply(c));
        }
    }

    #[test]
    fn sub_counts_at_the_edges_of_the_range() {
        let hi = i64::MAX >> 16;
        let lo = i64::MIN >> 16;
        for c in [
            0,
            1,
            -1,
            hi,
            hi + 1,
            hi - 1,
            lo,
            lo - 1,
            lo + 1,
            i64::MAX,
            i64::MIN,
        ] {
            assert_eq!(sub_counts(c), by_multiply(c), "{c}");
        }
        assert_eq!(sub_counts(lo), i64::MIN);
        assert_eq!(sub_counts(hi + 1), i64::MAX);
    }
}

#[cfg(test)]
mod speed_fixed_point {
    use super::speed_fx;
    use proptest::prelude::*;

    proptest! {
        /// A speed in 2^-40 rad/s is exact over the speeds a profile takes.
        #[test]
        fn speed_fx_is_exact(v in -40.0f32..40.0) {
            prop_assume!(v.abs() >= 2f32.powi(-17));
            prop_assert_eq!(speed_fx(v), (v as f64 * 2f64.powi(40)) as i64);
        }
    }

    #[test]
    fn speed_fx_at_its_edges() {
        for v in [0.0f32, -0.0, 0.5, -0.5, 20.0, -20.0, 2f32.powi(-17), 1e-30] {
            assert_eq!(speed_fx(v), (v as f64 * 2f64.powi(40)) as i64, "{v}");
        }
        assert_eq!(speed_fx(f32::NAN), 0);
        assert!(speed_fx(f32::INFINITY) > 0 && speed_fx(f32::NEG_INFINITY) < 0);
    }
}
