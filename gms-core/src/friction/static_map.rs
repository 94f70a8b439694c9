//! The static friction map `F = s(v) + sigma v` (Stribeck + Coulomb + viscous), no state.

use crate::friction::error::{Field, ParamError, finite};
use crate::friction::model::{FrictionModel, Step, step_velocity};
use crate::friction::stribeck::{Stribeck, StribeckParams};

/// Parameters of the static map.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct StaticParams {
    /// The Stribeck curve, for both directions unless `negative` is set.
    pub stribeck: StribeckParams,
    /// Separate Stribeck parameters for negative velocity.
    pub negative: Option<StribeckParams>,
    /// Viscous coefficient `sigma` [N·s/m or N·m·s/rad], `>= 0`.
    pub sigma: f32,
}

impl StaticParams {
    /// Checks every rule; the error names the first offending field.
    pub fn validate(&self) -> Result<(), ParamError> {
        Stribeck::try_new(self.stribeck, self.negative)?;
        finite(self.sigma, Field::Sigma)?;
        if self.sigma < 0.0 {
            return Err(ParamError::SigmaNegative);
        }
        Ok(())
    }
}

/// The validated static map. At zero velocity it gives zero force (the map has no memory of
/// which way the surfaces were loaded).
#[derive(Debug, Clone)]
pub struct StaticMap {
    params: StaticParams,
    stribeck: Stribeck,
    force: f32,
}

impl StaticMap {
    /// Validates `params` into a map.
    pub fn try_new(params: StaticParams) -> Result<Self, ParamError> {
        params.validate()?;
        let stribeck = Stribeck::try_new(params.stribeck, params.negative)?;
        Ok(StaticMap {
            params,
            stribeck,
            force: 0.0,
        })
    }

    /// The validated parameters.
    pub fn params(&self) -> &StaticParams {
        &self.params
    }

    /// The map's force at velocity `v` [m/s or rad/s]: `s(v) + sigma v` [N or N·m], 0 at v = 0.
    #[inline]
    pub fn force_at(&self, v: f32) -> f32 {
        self.stribeck.value(v) + self.params.sigma * v
    }
}

impl FrictionModel for StaticMap {
    fn advance(&mut self, dx: f32, dt: f32) -> f32 {
        self.force = match step_velocity(dx, dt) {
            Step::Ignore => return self.force,
            Step::Hold => 0.0,
            Step::Move { v, sign } if !v.is_finite() => sign * self.stribeck.coulomb(sign),
            Step::Move { v, .. } => self.force_at(v),
        };
        self.force
    }

    fn force(&self) -> f32 {
        self.force
    }

    fn reset(&mut self) {
        self.force = 0.0;
    }
}
