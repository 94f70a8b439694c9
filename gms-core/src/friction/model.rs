//! The interface shared by every friction model.

/// A friction model driven by the relative motion of the two surfaces.
///
/// Units are SI and consistent: displacement in m (or rad), time in s, force in N (or N·m).
/// The motion between two calls is taken at constant velocity `dx / dt`.
pub trait FrictionModel {
    /// Advances the model by the displacement `dx` [m or rad] done at constant velocity over
    /// `dt` \[s\] and returns the friction force after it [N or N·m].
    ///
    /// `dx = 0` holds the state (zero velocity). `dt = 0` with `dx != 0` is an instantaneous
    /// displacement (the limit of infinite velocity: no time for relaxation, no viscous force).
    /// Non-finite `dx` or `dt`, or `dt < 0`, leave the model unchanged.
    fn advance(&mut self, dx: f32, dt: f32) -> f32;

    /// The friction force after the last [`advance`](Self::advance) [N or N·m], opposing
    /// nothing by itself: positive for friction resisting positive motion.
    fn force(&self) -> f32;

    /// Returns to the virgin state at rest (zero internal state, zero force).
    fn reset(&mut self);

    /// The internal state: each Maxwell-slip block's force [N or N·m] for GMS, the bristle
    /// deflection z [m or rad] for LuGre, nothing for a static map.
    fn state(&self) -> &[f32] {
        &[]
    }
}

/// The step's velocity [m/s] and direction, or `None` when the step is ignored or holds.
///
/// Returns `Some((v, sign))` with `sign = ±1` for a moving step; `v` is infinite for `dt = 0`.
#[inline]
pub(crate) fn step_velocity(dx: f32, dt: f32) -> Step {
    // On the bits: dx finite (exponent not all ones); dt a finite number >= 0 (or -0).
    let (dxb, dtb) = (dx.to_bits() & 0x7fff_ffff, dt.to_bits());
    if dxb >= 0x7f80_0000 || (dtb >= 0x7f80_0000 && dtb != 0x8000_0000) {
        return Step::Ignore;
    }
    if dxb == 0 {
        return Step::Hold;
    }
    // ±1 with the sign of dx, from its sign bit.
    let sign = f32::from_bits(0x3f80_0000 | (dx.to_bits() & 0x8000_0000));
    Step::Move { v: dx / dt, sign }
}

/// What one `advance` call does.
pub(crate) enum Step {
    /// Invalid input: nothing changes.
    Ignore,
    /// No motion: the state holds, velocity zero.
    Hold,
    /// Motion at velocity `v` (infinite for `dt = 0`) in direction `sign` (±1).
    Move { v: f32, sign: f32 },
}
