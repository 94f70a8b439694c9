//! On-line adaptation of the friction feedforward's level: the paper's outlook (friction
//! varies by ±15 % from run to run and along the stroke).
//!
//! The estimator learns the level `scale` of the friction relative to the GMS model F̂, and
//! the controller applies `gain · scale · F̂` (`gain` being the feedforward gain the user
//! tuned, see below). With a true friction `F = θ F̂`, the loop's feedback `u_fb` settles where
//! `u_fb + gain · scale · F̂ ≈ θ F̂`, so the residual
//!
//! ```text
//! r = u_fb + applied - scale · F̂  ≈ (θ - scale) F̂
//! ```
//!
//! is what the estimated level misses. The gradient of `r²/2` in `scale` gives the update
//!
//! ```text
//! scale += rate · dt · dz(r) · F̂ / F_n²
//! ```
//!
//! with `F_n` the nominal friction level (so that `rate` is in 1/s whatever the units), `dz` a
//! dead zone against sensor noise and quantisation (`dz(r) = 0` for `|r| <= deadzone`, else
//! `r ∓ deadzone`), and a projection onto `[min, max]`. The update is frozen while the
//! reference is slower than `v_min` (the axis at rest or in pre-sliding, where the feedback
//! carries stiction and position noise rather than a friction level) and while the current
//! command is saturated (the feedback then says nothing about friction). Cost: a handful of
//! f32 operations per position step, no branches on data beyond the gates.
//!
//! Why the residual and not the feedback alone: the best feedforward gain of a stiff loop is
//! below 1 (the model follows the reference, the axis lags it by a few counts, so a full
//! feedforward turns over at a reversal before the real friction does; hil-sim's default
//! scenario is best near 0.94). Adapting on the feedback alone would drive
//! `gain · scale` to 1 and undo that tuning; on the residual, `scale` tracks the friction
//! level and the applied feedforward keeps the tuned ratio to it.

/// Tuning of the adaptation.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(deny_unknown_fields))]
pub struct AdaptiveParams {
    /// Adaptation rate [1/s], in [0, 1e4]: the inverse time constant of the scale's
    /// convergence while the model output equals the nominal level (0 freezes it).
    pub gain: f32,
    /// Lower bound of the scale [-], in [0, max].
    pub min: f32,
    /// Upper bound of the scale [-], in [min, 10].
    pub max: f32,
    /// Dead zone on the residual torque `r` [N·m], `>= 0`: a smaller residual does not adapt.
    pub deadzone: f32,
    /// Slowest reference speed that adapts [rad/s], `>= 0`.
    pub v_min: f32,
}

impl Default for AdaptiveParams {
    /// Rate 100/s (a 10 ms time constant at the nominal level: hil-sim's drift scenarios
    /// are best between 100 and 200/s, and at rest or on stationary friction it does no harm),
    /// bounds 0.5-1.5 (the paper's ±15 % with a wide margin), dead zone 2 uN·m (about one
    /// count of position error under the default gains), adapting above 0.02 rad/s (Vs/10 of
    /// Table 1).
    fn default() -> Self {
        AdaptiveParams {
            gain: 100.0,
            min: 0.5,
            max: 1.5,
            deadzone: 2e-6,
            v_min: 0.02,
        }
    }
}

impl AdaptiveParams {
    /// Checks the ranges (the settings table, [`crate::settings::SPECS`]) and that
    /// `min <= max`; the error names the field by its protocol path.
    pub fn validate(&self) -> Result<(), &'static str> {
        use crate::settings::ParamId;
        let ok = |v: f32, (lo, hi): (f32, f32)| v.is_finite() && v >= lo && v <= hi;
        if !ok(self.gain, const { ParamId::FfAdaptGain.range() }) {
            return Err("ff.adapt.gain");
        }
        if !ok(self.min, const { ParamId::FfAdaptMin.range() }) || self.min > self.max {
            return Err("ff.adapt.min");
        }
        if !ok(self.max, const { ParamId::FfAdaptMax.range() }) {
            return Err("ff.adapt.max");
        }
        if !ok(self.deadzone, const { ParamId::FfAdaptDeadzone.range() }) {
            return Err("ff.adapt.deadzone");
        }
        if !ok(self.v_min, const { ParamId::FfAdaptVmin.range() }) {
            return Err("ff.adapt.vmin");
        }
        Ok(())
    }
}

/// What the loop saw in one position step, as the estimator needs it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AdaptInput {
    /// Feedback torque of the position loop (P + I + D) [N·m].
    pub feedback: f32,
    /// The friction feedforward applied in this step [N·m] (`gain · scale · model`).
    pub applied: f32,
    /// The unscaled friction model F̂ [N·m].
    pub model: f32,
    /// Reference speed [rad/s].
    pub v_ref: f32,
    /// Whether the current command was saturated.
    pub saturated: bool,
}

/// The estimator's state: the scale on the feedforward.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Adaptive {
    scale: f32,
    inv_norm2: f32,
}

impl Adaptive {
    /// An estimator starting at scale 1 (the nominal friction), for a nominal friction
    /// level `f_norm` [N·m] (`> 0`; a non-positive or non-finite level gives a frozen
    /// estimator).
    pub fn new(f_norm: f32) -> Self {
        let inv_norm2 = if f_norm.is_finite() && f_norm > 0.0 {
            let v = 1.0 / (f_norm * f_norm);
            if v.is_finite() { v } else { 0.0 }
        } else {
            0.0
        };
        Adaptive {
            scale: 1.0,
            inv_norm2,
        }
    }

    /// The current scale [-].
    pub fn scale(&self) -> f32 {
        self.scale
    }

    /// Back to scale 1, clamped into the bounds of `p`.
    pub fn reset(&mut self, p: &AdaptiveParams) {
        self.set_scale(1.0, p);
    }

    /// Sets the scale, clamped into the bounds of `p`; a non-finite value means 1.
    pub fn set_scale(&mut self, scale: f32, p: &AdaptiveParams) {
        let s = if scale.is_finite() { scale } else { 1.0 };
        self.scale = if s < p.min {
            p.min
        } else if s > p.max {
            p.max
        } else {
            s
        };
    }

    /// One update over `dt` \[s\]; returns the new scale. Non-finite inputs change nothing.
    pub fn update(&mut self, p: &AdaptiveParams, x: &AdaptInput, dt: f32) -> f32 {
        let speed = if x.v_ref < 0.0 { -x.v_ref } else { x.v_ref };
        let active = !x.saturated && speed >= p.v_min && speed.is_finite();
        // What the loop supplies against friction beyond the estimated level.
        let u = x.feedback + x.applied - self.scale * x.model;
        let excess = if u > p.deadzone {
            u - p.deadzone
        } else if u < -p.deadzone {
            u + p.deadzone
        } else {
            0.0
        };
        let step = p.gain * dt * excess * x.model * self.inv_norm2;
        if active && step.is_finite() {
            self.set_scale(self.scale + step, p);
        }
        self.scale
    }
}
