//! The Generalized Maxwell-Slip model (paper eqs 1-6, docs/design.md#the-gms-model).

use crate::friction::error::{Field, ParamError, finite};
use crate::friction::model::{FrictionModel, Step, step_velocity};
use crate::friction::stribeck::{Stribeck, StribeckParams};
use crate::math;

/// One elementary Maxwell-slip block. A block with `k = 0` and `alpha = 0` is *unused*: it
/// holds no force (a parameter set of `N` blocks may describe fewer; the used ones come
/// first, see [`GmsParams::blocks_used`]).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct Block {
    /// Stiffness `k_i` [N/m or N·m/rad], `> 0` (0 in an unused block).
    pub k: f32,
    /// Relative weight `alpha_i` [-], `> 0` (0 in an unused block); the weights of a model sum
    /// to 1 ± 0.01.
    pub alpha: f32,
}

/// An unused block: no stiffness, no weight.
pub const UNUSED_BLOCK: Block = Block { k: 0.0, alpha: 0.0 };

impl Block {
    /// The pre-sliding displacement at which the block saturates on the virgin curve,
    /// `D_i = alpha_i Fs / k_i` [m or rad] (paper eq. 3).
    pub fn breakpoint(&self, fs: f32) -> f32 {
        self.alpha * fs / self.k
    }
}

/// Parameters of a GMS model with `N` blocks (editable; validated by [`Gms::try_new`]).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct GmsParams<const N: usize> {
    /// The Stribeck curve, for both directions unless `negative` is set.
    pub stribeck: StribeckParams,
    /// Separate Stribeck parameters for negative velocity (the paper's direction asymmetry).
    pub negative: Option<StribeckParams>,
    /// Viscous coefficient `sigma` [N·s/m or N·m·s/rad], `>= 0`.
    pub sigma: f32,
    /// Attraction parameter `C` of the slip dynamics [N/s or N·m/s], `> 0`.
    pub c: f32,
    /// The blocks.
    #[cfg_attr(feature = "serde", serde(with = "crate::friction::serde_array"))]
    pub blocks: [Block; N],
}

impl<const N: usize> GmsParams<N> {
    /// The static map of the same sliding friction: the Stribeck curve (and its negative side)
    /// and the viscous term, `s(v) + σ v` (what the GMS model tends to at a steady speed).
    pub fn static_params(&self) -> crate::friction::static_map::StaticParams {
        crate::friction::static_map::StaticParams {
            stribeck: self.stribeck,
            negative: self.negative,
            sigma: self.sigma,
        }
    }

    /// The number of blocks in use: those before the first unused one (`k = alpha = 0`).
    /// A valid set uses at least one, and every block after the first unused one is unused.
    pub fn blocks_used(&self) -> usize {
        self.blocks
            .iter()
            .position(|b| *b == UNUSED_BLOCK)
            .unwrap_or(N)
    }

    /// These parameters using the first `n` blocks (`1 <= n <= N`): the blocks past `n`
    /// become unused; those kept are left as they are, and a block that joins (it was unused)
    /// is marked as waiting for its values (`k = 0`, `alpha = -1`), so that the set does not
    /// validate until they are given.
    pub fn with_blocks_used(mut self, n: usize) -> Self {
        for (i, b) in self.blocks.iter_mut().enumerate() {
            if i >= n {
                *b = UNUSED_BLOCK;
            } else if *b == UNUSED_BLOCK {
                *b = Block {
                    k: 0.0,
                    alpha: -1.0,
                };
            }
        }
        self
    }

    /// Checks every rule of the model; the error names the first offending field.
    pub fn validate(&self) -> Result<(), ParamError> {
        Stribeck::try_new(self.stribeck, self.negative)?;
        finite(self.sigma, Field::Sigma)?;
        finite(self.c, Field::C)?;
        if self.sigma < 0.0 {
            return Err(ParamError::SigmaNegative);
        }
        if self.c <= 0.0 {
            return Err(ParamError::CNotPositive);
        }
        let used = self.blocks_used();
        if used == 0 {
            return Err(ParamError::KNotPositive(0));
        }
        if let Some(i) = (used..N).find(|&i| self.blocks[i] != UNUSED_BLOCK) {
            return Err(ParamError::AfterUnused(i));
        }
        let mut sum = 0.0f32;
        for (i, b) in self.blocks.iter().enumerate().take(used) {
            finite(b.k, Field::K(i))?;
            finite(b.alpha, Field::Alpha(i))?;
            if b.k <= 0.0 {
                return Err(ParamError::KNotPositive(i));
            }
            if b.alpha <= 0.0 {
                return Err(ParamError::AlphaNotPositive(i));
            }
            sum += b.alpha;
        }
        if !(0.99..=1.01).contains(&sum) {
            return Err(ParamError::AlphaSum);
        }
        Ok(())
    }
}

/// A validated GMS model with `N` blocks and its state.
///
/// Numerics (docs/design.md#numerics): a sticking block follows the position increment, `F_i += k_i dx`; a
/// block that would pass `alpha_i |s(v)|` is clamped onto it; a slipping block relaxes
/// exactly, `F_i = W + (F_i - W) exp(-C dt / |s(v)|)` with `W = alpha_i s(v)`; a block whose
/// force points against the motion (just after a reversal) sticks. The result is exact for
/// motion at constant velocity within a step, whatever the step size, up to f32 rounding.
#[derive(Debug, Clone)]
pub struct Gms<const N: usize> {
    params: GmsParams<N>,
    stribeck: Stribeck,
    k: [f32; N],
    alpha: [f32; N],
    f: [f32; N],
    /// Rounding error of each `f` not yet added (Kahan compensation of the elastic sums).
    comp: [f32; N],
    /// alpha_i Fc for positive and negative motion: the least alpha_i |s(v)| can be; +inf for
    /// an unused block, so that it never leaves the fast path (its force stays 0 on both).
    alpha_fc: [[f32; N]; 2],
    /// Each block's force limit for a hand-over, `alpha_i` times the larger breakaway level
    /// (computed when built: [`Gms::take_state_from`] runs in a control step).
    hand_over_lim: [f32; N],
    viscous: f32,
    force: f32,
}

impl<const N: usize> Gms<N> {
    /// Validates `params` into a model in the virgin state (all block forces zero).
    pub fn try_new(params: GmsParams<N>) -> Result<Self, ParamError> {
        params.validate()?;
        let stribeck = Stribeck::try_new(params.stribeck, params.negative)?;
        let afc = |i: usize, dir: f32| {
            if params.blocks[i] == UNUSED_BLOCK {
                f32::INFINITY
            } else {
                params.blocks[i].alpha * stribeck.coulomb(dir)
            }
        };
        let fs = stribeck.max_magnitude();
        Ok(Gms {
            params,
            stribeck,
            hand_over_lim: core::array::from_fn(|i| params.blocks[i].alpha * fs),
            k: core::array::from_fn(|i| params.blocks[i].k),
            alpha: core::array::from_fn(|i| params.blocks[i].alpha),
            f: [0.0; N],
            comp: [0.0; N],
            alpha_fc: [
                core::array::from_fn(|i| afc(i, 1.0)),
                core::array::from_fn(|i| afc(i, -1.0)),
            ],
            viscous: 0.0,
            force: 0.0,
        })
    }

    /// The validated parameters.
    pub fn params(&self) -> &GmsParams<N> {
        &self.params
    }

    /// The validated Stribeck curve.
    pub fn stribeck(&self) -> &Stribeck {
        &self.stribeck
    }

    /// The force of each block `F_i` [N or N·m].
    pub fn block_forces(&self) -> &[f32; N] {
        &self.f
    }

    /// The viscous part `sigma v` of the last step's force [N or N·m].
    pub fn viscous_force(&self) -> f32 {
        self.viscous
    }

    /// Live tuning: this model (new, of other parameters) takes over the state of `old`:
    /// each block keeps its
    /// force, clamped into its new limit `alpha_i` times the larger breakaway level (`Fs`, or
    /// the larger of both directions' with `negative`); the viscous part of the last step is
    /// rescaled to the new `sigma` (zero if the old `sigma` was 0). A few dozen operations: fit
    /// for a control step.
    pub fn take_state_from(&mut self, old: &Gms<N>) {
        // Usually every block is within its new limit: the state copied as it is, and one
        // comparison a block (the limits computed when this model was built). Beyond (or
        // NaN), the force clamped and its rounding error dropped.
        self.f = old.f;
        self.comp = old.comp;
        let mut sum = 0.0f32;
        let mut within = true;
        for (&f, &lim) in self.f.iter().zip(&self.hand_over_lim) {
            within &= f.abs() <= lim;
            sum += f;
        }
        if !within {
            // Only the blocks beyond their limit are touched, then the sum taken again.
            for ((f, c), &lim) in self
                .f
                .iter_mut()
                .zip(&mut self.comp)
                .zip(&self.hand_over_lim)
            {
                let inside = f.abs() <= lim;
                if !inside {
                    *f = math::clamp(*f, lim);
                    *c = 0.0;
                }
            }
            sum = self.f.iter().sum();
        }
        let old_sigma = old.params.sigma;
        let viscous = if old_sigma > 0.0 {
            old.viscous * (self.params.sigma / old_sigma)
        } else {
            0.0
        };
        self.viscous = if viscous.is_finite() { viscous } else { 0.0 };
        self.force = sum + self.viscous;
    }
}

impl<const N: usize> FrictionModel for Gms<N> {
    fn advance(&mut self, dx: f32, dt: f32) -> f32 {
        let (v, sign) = match step_velocity(dx, dt) {
            Step::Ignore => return self.force,
            Step::Hold => {
                self.viscous = 0.0;
                self.force = self.f.iter().sum();
                return self.force;
            }
            Step::Move { v, sign } => (v, sign),
        };
        let v_finite = v.is_finite();
        let viscous = if v_finite { self.params.sigma * v } else { 0.0 };
        // Fast path: when every block sticks and stays below alpha_i Fc, the least that
        // alpha_i |s(v)| can be, the Stribeck curve is not needed (the common case in fine
        // positioning). The result is bit for bit that of the full path below.
        let neg = sign < 0.0;
        let afc = &self.alpha_fc[neg as usize];
        let mut trial = [0.0f32; N];
        let mut fast = true;
        for i in 0..N {
            let fi = self.f[i];
            // A block at or above alpha_i Fc may slip: leave at once (while sliding, the first
            // block already is). No NaN can occur here: forces and increments are finite or
            // infinite, never NaN.
            if fi * sign >= afc[i] {
                fast = false;
                break;
            }
            let g = fi + (self.k[i] * dx - self.comp[i]);
            if g * sign > afc[i] {
                fast = false;
                break;
            }
            trial[i] = g;
        }
        if fast {
            let mut sum = 0.0f32;
            let state = self.f.iter_mut().zip(&mut self.comp);
            for ((f, comp), (&k, &g)) in state.zip(self.k.iter().zip(&trial)) {
                let inc = k * dx - *comp;
                *comp = (g - *f) - inc;
                *f = g;
                sum += g;
            }
            self.viscous = viscous;
            self.force = sum + viscous;
            return self.force;
        }
        // |s(v)| and the argument of the slip relaxation.
        let (s_abs, relax_arg) = if v_finite {
            let s_abs = self.stribeck.magnitude_dir(v, neg);
            // dt > 0 here; s_abs = 0 (Fs = Fc = 0) gives +inf, i.e. immediate relaxation.
            (s_abs, self.params.c * dt / s_abs)
        } else {
            // dt = 0: the infinite-velocity limit, no time to relax, no viscous force.
            (self.stribeck.coulomb(sign), 0.0)
        };
        // Slipping: F = W + (F - W) r = F r + alpha_i (s(v) (1 - r)) with r = exp(-C dt/|s|),
        // W = alpha_i s(v): exact relaxation towards W for a step of constant velocity.
        let relax = math::exp(-relax_arg);
        let pull = s_abs * sign * (1.0 - relax);
        let mut sum = 0.0f32;
        let blocks = self.f.iter_mut().zip(&mut self.comp);
        for ((f, comp), (&k, &alpha)) in blocks.zip(self.k.iter().zip(&self.alpha)) {
            let fi = *f;
            let w_abs = alpha * s_abs;
            let new = if fi * sign < w_abs {
                // Sticking (or against the motion, just after a reversal): elastic. The sum
                // is compensated (Kahan) so that thousands of tiny increments per cycle do
                // not accumulate f32 rounding into a drift of the pre-sliding state.
                let inc = k * dx - *comp;
                let g = fi + inc;
                if g * sign > w_abs {
                    w_abs * sign
                } else {
                    *comp = (g - fi) - inc;
                    g
                }
            } else {
                fi * relax + alpha * pull
            };
            *f = new;
            sum += new;
        }
        self.viscous = viscous;
        self.force = sum + viscous;
        self.force
    }

    fn force(&self) -> f32 {
        self.force
    }

    fn reset(&mut self) {
        self.f = [0.0; N];
        self.comp = [0.0; N];
        self.viscous = 0.0;
        self.force = 0.0;
    }

    /// The forces of the blocks in use.
    fn state(&self) -> &[f32] {
        self.f.get(..self.params.blocks_used()).unwrap_or(&self.f)
    }
}
