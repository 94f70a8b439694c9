//! The Stribeck curve `s(v) = sgn(v) [Fc + (Fs - Fc) exp(-(|v|/Vs)^delta)]` (paper eq. 1 with
//! the shape factor delta of its Table 1), optionally with separate parameters for v < 0.

use crate::friction::error::{Field, ParamError, Side, finite};
use crate::math;

/// Parameters of one branch of the Stribeck curve.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct StribeckParams {
    /// Static (breakaway) friction `Fs` [N or N·m], `>= fc`.
    pub fs: f32,
    /// Coulomb (kinetic) friction `Fc` [N or N·m], `>= 0`.
    pub fc: f32,
    /// Stribeck velocity `Vs` [m/s or rad/s], `> 0`.
    pub vs: f32,
    /// Shape factor `delta` [-], `> 0` (1 in the paper's eq. 1, 0.9 in its Table 1).
    pub delta: f32,
}

impl StribeckParams {
    /// Checks this branch; `side` names it in the error.
    pub fn validate(&self, side: Side) -> Result<(), ParamError> {
        finite(self.fs, Field::Fs(side))?;
        finite(self.fc, Field::Fc(side))?;
        finite(self.vs, Field::Vs(side))?;
        finite(self.delta, Field::Delta(side))?;
        if self.fc < 0.0 {
            return Err(ParamError::FcNegative(side));
        }
        if self.fs < self.fc {
            return Err(ParamError::FsBelowFc(side));
        }
        if self.vs <= 0.0 {
            return Err(ParamError::VsNotPositive(side));
        }
        if self.delta <= 0.0 {
            return Err(ParamError::DeltaNotPositive(side));
        }
        Ok(())
    }
}

/// One validated branch, stored in the form the evaluation uses.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Branch {
    fc: f32,
    dfs: f32,
    vs: f32,
    delta: f32,
    delta_is_one: bool,
}

impl Branch {
    fn new(p: &StribeckParams) -> Self {
        Branch {
            fc: p.fc,
            dfs: p.fs - p.fc,
            vs: p.vs,
            delta: p.delta,
            delta_is_one: p.delta == 1.0,
        }
    }

    /// |s(v)| for a speed `speed = |v|` >= 0 (may be +inf).
    #[inline(always)]
    fn magnitude(&self, speed: f32) -> f32 {
        let r = speed / self.vs;
        let decay = if self.delta_is_one {
            math::exp(-r)
        } else {
            math::stribeck_decay(r, self.delta)
        };
        self.fc + self.dfs * decay
    }
}

/// A validated Stribeck curve, symmetric or with its own branch for negative velocity.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Stribeck {
    pos: Branch,
    neg: Branch,
    pos_params: StribeckParams,
    neg_params: Option<StribeckParams>,
}

impl Stribeck {
    /// Validates `positive` (used for both directions) and the optional `negative` branch.
    pub fn try_new(
        positive: StribeckParams,
        negative: Option<StribeckParams>,
    ) -> Result<Self, ParamError> {
        positive.validate(Side::Positive)?;
        if let Some(n) = &negative {
            n.validate(Side::Negative)?;
        }
        Ok(Stribeck {
            pos: Branch::new(&positive),
            neg: Branch::new(negative.as_ref().unwrap_or(&positive)),
            pos_params: positive,
            neg_params: negative,
        })
    }

    /// The positive-velocity (or symmetric) parameters.
    pub fn positive(&self) -> &StribeckParams {
        &self.pos_params
    }

    /// The separate negative-velocity parameters, if any.
    pub fn negative(&self) -> Option<&StribeckParams> {
        self.neg_params.as_ref()
    }

    /// |s(v)| [N or N·m] on the branch of `v`'s sign; `v` may be infinite (then Fc).
    /// At `v = 0` this is Fs of the positive branch.
    #[inline]
    pub fn magnitude(&self, v: f32) -> f32 {
        let (branch, speed) = if v < 0.0 {
            (&self.neg, -v)
        } else {
            (&self.pos, v)
        };
        branch.magnitude(speed)
    }

    /// |s(v)| for a finite `v` whose direction is already known (`neg` = v < 0).
    #[inline(always)]
    pub(crate) fn magnitude_dir(&self, v: f32, neg: bool) -> f32 {
        let speed = f32::from_bits(v.to_bits() & 0x7fff_ffff);
        if neg {
            self.neg.magnitude(speed)
        } else {
            self.pos.magnitude(speed)
        }
    }

    /// The signed Stribeck force s(v) [N or N·m]; 0 at v = 0.
    #[inline]
    pub fn value(&self, v: f32) -> f32 {
        if v > 0.0 {
            self.pos.magnitude(v)
        } else if v < 0.0 {
            -self.neg.magnitude(-v)
        } else {
            0.0
        }
    }

    /// Coulomb friction of the branch in direction `sign` (> 0: positive) [N or N·m]: the
    /// limit of |s(v)| for |v| → ∞.
    #[inline]
    pub(crate) fn coulomb(&self, sign: f32) -> f32 {
        if sign < 0.0 { self.neg.fc } else { self.pos.fc }
    }

    /// The largest |s(v)| over both directions, max(Fs, Fc) [N or N·m].
    pub fn max_magnitude(&self) -> f32 {
        let p = self.pos.fc + self.pos.dfs;
        let n = self.neg.fc + self.neg.dfs;
        if p > n { p } else { n }
    }
}
