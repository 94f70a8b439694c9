//! Parameter validation errors.

use core::fmt;

/// Which branch of a direction-dependent Stribeck curve a parameter belongs to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Side {
    /// The curve for positive velocity (and for both directions when symmetric).
    Positive,
    /// The optional separate curve for negative velocity (`[friction.negative]`).
    Negative,
}

/// A parameter of a friction model, named as in the parameter file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Field {
    /// Static (breakaway) friction `fs` [N or N·m].
    Fs(Side),
    /// Coulomb friction `fc` [N or N·m].
    Fc(Side),
    /// Stribeck velocity `vs` [m/s or rad/s].
    Vs(Side),
    /// Stribeck shape factor `delta` [-].
    Delta(Side),
    /// Viscous coefficient `sigma` [N·s/m or N·m·s/rad].
    Sigma,
    /// GMS attraction parameter `c` [N/s or N·m/s].
    C,
    /// Stiffness `k` of a GMS block (0-based index) [N/m or N·m/rad].
    K(usize),
    /// Weight `alpha` of a GMS block (0-based index) [-].
    Alpha(usize),
    /// The sum of the GMS block weights [-].
    AlphaSum,
    /// LuGre bristle stiffness `sigma0` [N/m or N·m/rad].
    Sigma0,
    /// LuGre bristle damping `sigma1` [N·s/m or N·m·s/rad].
    Sigma1,
}

impl fmt::Display for Field {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let neg = |side: &Side| match side {
            Side::Positive => "",
            Side::Negative => "negative.",
        };
        match self {
            Field::Fs(s) => write!(f, "{}fs", neg(s)),
            Field::Fc(s) => write!(f, "{}fc", neg(s)),
            Field::Vs(s) => write!(f, "{}vs", neg(s)),
            Field::Delta(s) => write!(f, "{}delta", neg(s)),
            Field::Sigma => f.write_str("sigma"),
            Field::C => f.write_str("c"),
            Field::K(i) => write!(f, "blocks[{i}].k"),
            Field::Alpha(i) => write!(f, "blocks[{i}].alpha"),
            Field::AlphaSum => f.write_str("sum of blocks[].alpha"),
            Field::Sigma0 => f.write_str("sigma0"),
            Field::Sigma1 => f.write_str("sigma1"),
        }
    }
}

/// Why a parameter set was rejected; every variant names the offending field.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ParamError {
    /// A value is NaN or infinite.
    NonFinite(Field),
    /// A block stiffness `k` is zero or negative (block index, 0-based).
    KNotPositive(usize),
    /// A block weight `alpha` is zero or negative (block index, 0-based).
    AlphaNotPositive(usize),
    /// The block weights do not sum to 1 within ±0.01.
    AlphaSum,
    /// Static friction below Coulomb friction (`fs < fc`).
    FsBelowFc(Side),
    /// Negative Coulomb friction.
    FcNegative(Side),
    /// Stribeck velocity zero or negative.
    VsNotPositive(Side),
    /// Stribeck shape factor zero or negative.
    DeltaNotPositive(Side),
    /// Negative viscous coefficient.
    SigmaNegative,
    /// GMS attraction parameter `c` zero or negative.
    CNotPositive,
    /// LuGre bristle stiffness zero or negative.
    Sigma0NotPositive,
    /// A GMS block in use after an unused one (`k = alpha = 0`): the used blocks come first
    /// (block index, 0-based).
    AfterUnused(usize),
    /// Negative LuGre bristle damping.
    Sigma1Negative,
}

impl ParamError {
    /// The parameter that made the set invalid.
    pub fn field(&self) -> Field {
        match *self {
            ParamError::NonFinite(f) => f,
            ParamError::KNotPositive(i) => Field::K(i),
            ParamError::AlphaNotPositive(i) => Field::Alpha(i),
            ParamError::AlphaSum => Field::AlphaSum,
            ParamError::FsBelowFc(s) => Field::Fs(s),
            ParamError::FcNegative(s) => Field::Fc(s),
            ParamError::VsNotPositive(s) => Field::Vs(s),
            ParamError::DeltaNotPositive(s) => Field::Delta(s),
            ParamError::SigmaNegative => Field::Sigma,
            ParamError::CNotPositive => Field::C,
            ParamError::Sigma0NotPositive => Field::Sigma0,
            ParamError::Sigma1Negative => Field::Sigma1,
            ParamError::AfterUnused(i) => Field::K(i),
        }
    }
}

impl fmt::Display for ParamError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let field = self.field();
        match self {
            ParamError::NonFinite(_) => write!(f, "{field} is not a finite number"),
            ParamError::AfterUnused(i) => write!(
                f,
                "blocks[{i}] follows an unused block (k = alpha = 0): the used blocks come first"
            ),
            ParamError::AlphaSum => write!(f, "{field} must be 1 within ±0.01"),
            ParamError::FsBelowFc(Side::Positive) => write!(f, "{field} must be >= fc"),
            ParamError::FsBelowFc(Side::Negative) => write!(f, "{field} must be >= negative.fc"),
            ParamError::FcNegative(_) | ParamError::SigmaNegative | ParamError::Sigma1Negative => {
                write!(f, "{field} must be >= 0")
            }
            _ => write!(f, "{field} must be > 0"),
        }
    }
}

impl core::error::Error for ParamError {}

/// Checks that `x` is finite, naming `field` if not.
pub(crate) fn finite(x: f32, field: Field) -> Result<f32, ParamError> {
    if x.is_finite() {
        Ok(x)
    } else {
        Err(ParamError::NonFinite(field))
    }
}
