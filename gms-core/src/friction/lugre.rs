//! The LuGre model (Canudas de Wit, Olsson, Åström & Lischinsky 1995), for comparison.
//!
//! `dz/dt = v - sigma0 |v| z / g(v)`, `F = sigma0 z + sigma1 dz/dt + sigma v`, with
//! `g(v) = |s(v)|` the Stribeck magnitude (the original uses delta = 2).

use crate::friction::error::{Field, ParamError, finite};
use crate::friction::model::{FrictionModel, Step, step_velocity};
use crate::friction::stribeck::{Stribeck, StribeckParams};
use crate::math;

/// Parameters of the LuGre model.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct LugreParams {
    /// The Stribeck curve g(v), for both directions unless `negative` is set.
    pub stribeck: StribeckParams,
    /// Separate Stribeck parameters for negative velocity.
    pub negative: Option<StribeckParams>,
    /// Bristle stiffness `sigma0` [N/m or N·m/rad], `> 0`.
    pub sigma0: f32,
    /// Bristle damping `sigma1` [N·s/m or N·m·s/rad], `>= 0`.
    pub sigma1: f32,
    /// Viscous coefficient `sigma` (sigma2 in the original) [N·s/m or N·m·s/rad], `>= 0`.
    pub sigma: f32,
}

impl LugreParams {
    /// Checks every rule; the error names the first offending field.
    pub fn validate(&self) -> Result<(), ParamError> {
        Stribeck::try_new(self.stribeck, self.negative)?;
        finite(self.sigma0, Field::Sigma0)?;
        finite(self.sigma1, Field::Sigma1)?;
        finite(self.sigma, Field::Sigma)?;
        if self.sigma0 <= 0.0 {
            return Err(ParamError::Sigma0NotPositive);
        }
        if self.sigma1 < 0.0 {
            return Err(ParamError::Sigma1Negative);
        }
        if self.sigma < 0.0 {
            return Err(ParamError::SigmaNegative);
        }
        Ok(())
    }
}

/// A validated LuGre model and its bristle state.
///
/// Numerics: for a step of constant velocity the bristle deflection relaxes exactly,
/// `z = z_ss + (z - z_ss) exp(-sigma0 |dx| / g(v))` with `z_ss = sgn(v) g(v) / sigma0`, so the
/// result does not depend on the step size.
#[derive(Debug, Clone)]
pub struct LuGre {
    params: LugreParams,
    stribeck: Stribeck,
    z: f32,
    force: f32,
}

impl LuGre {
    /// Validates `params` into a model at rest with no bristle deflection.
    pub fn try_new(params: LugreParams) -> Result<Self, ParamError> {
        params.validate()?;
        let stribeck = Stribeck::try_new(params.stribeck, params.negative)?;
        Ok(LuGre {
            params,
            stribeck,
            z: 0.0,
            force: 0.0,
        })
    }

    /// The validated parameters.
    pub fn params(&self) -> &LugreParams {
        &self.params
    }

    /// The mean bristle deflection `z` [m or rad].
    pub fn deflection(&self) -> f32 {
        self.z
    }
}

impl FrictionModel for LuGre {
    fn advance(&mut self, dx: f32, dt: f32) -> f32 {
        let p = &self.params;
        let (v, sign) = match step_velocity(dx, dt) {
            Step::Ignore => return self.force,
            Step::Hold => {
                self.force = p.sigma0 * self.z;
                return self.force;
            }
            Step::Move { v, sign } => (v, sign),
        };
        let g = if v.is_finite() {
            self.stribeck.magnitude(v)
        } else {
            self.stribeck.coulomb(sign)
        };
        let z_ss = sign * g / p.sigma0;
        let dist = if dx < 0.0 { -dx } else { dx };
        // g = 0 gives exp(-inf) = 0: the bristles follow z_ss = 0 at once.
        self.z = z_ss + (self.z - z_ss) * math::exp(-p.sigma0 * dist / g);
        let (zdot, viscous) = if v.is_finite() && g > 0.0 {
            let speed = v * sign;
            // Bounded factor first (|sigma0 (z_ss - z) / g| <= 2), so that 0 * inf never occurs.
            (speed * (p.sigma0 * (z_ss - self.z) / g), p.sigma * v)
        } else {
            (0.0, 0.0)
        };
        self.force = p.sigma0 * self.z + p.sigma1 * zdot + viscous;
        self.force
    }

    fn force(&self) -> f32 {
        self.force
    }

    fn reset(&mut self) {
        self.z = 0.0;
        self.force = 0.0;
    }

    fn state(&self) -> &[f32] {
        core::slice::from_ref(&self.z)
    }
}
