//! Transcendental functions for the friction models, identical on host and target.
//!
//! The models need `exp`, `ln` and a real power. The inherent `f32::exp`/`f32::powf` exist on
//! the host only (through std) and micromath 2.1's `ln`/`powf` are badly wrong below 1 (its
//! `ln(0.9)` gives -0.182), which is exactly where the Stribeck power `(|v|/Vs)^delta` lives.
//! So these are written here from plain IEEE-754 `f32` arithmetic (add, multiply, divide and
//! bit manipulation), which every conforming FPU rounds identically: the Cortex-M4F and the
//! host give the same bits.
//!
//! Accuracy (measured against `f64` in the tests): `exp` within 3e-7 relative over its whole
//! range of normal results, `ln` within 2e-7 absolute for arguments near 1 and 2e-7 relative
//! elsewhere, `powf` within 2e-6 relative for exponent·ln(base) in [-40, 40].

/// ln 2 split in a high part with trailing zero bits (so that `n * LN2_HI` is exact for
/// |n| < 512) and the rest.
const LN2_HI: f32 = 0.693_145_75;
/// The low part of ln 2: `LN2_HI + LN2_LO` is ln 2 to about 1e-14.
const LN2_LO: f32 = 1.428_606_8e-6;
/// log2(e).
const LOG2_E: f32 = core::f32::consts::LOG2_E;

/// Coefficients of `P` in `e^r = 1 + r + r^2 P(r)` on |r| <= ln(2)/2, fitted for least maximum
/// relative error (1.05e-7 before rounding); fitted in `tools/fit_exp.py`.
const EXP_P: [f32; 4] = [0.499_992_3, 0.166_671_14, 0.041_890_114, 0.008_312_525];

/// Coefficients of `Q` in `2^f = 1 + f Q(f)` on |f| <= 1/2, fitted for least maximum
/// relative error (1.1e-7 with these f32 coefficients); `tools/fit_exp.py`.
#[allow(clippy::approx_constant)] // a fitted coefficient, not ln 2
const EXP2_P: [f32; 5] = [
    0.693_147,
    0.240_222_42,
    0.055_507_336,
    0.009_671_513,
    0.001_326_472_7,
];

/// Largest argument with a finite `e^x` in f32.
const EXP_MAX: f32 = 88.722_83;
/// Below this `e^x` is smaller than half the smallest subnormal f32 and rounds to zero.
const EXP_MIN: f32 = -103.972_08;

/// 1.5 × 2^23: adding it to |t| < 2^22 rounds t to an integer held in the low mantissa bits.
const ROUND_MAGIC: f32 = 12_582_912.0;

/// e^x for any `f32`: +inf above 88.72, 0 below -103.97, NaN for NaN.
#[inline]
pub fn exp(x: f32) -> f32 {
    // |x| < 87: one integer comparison on the bits; everything else (NaN, infinities, large
    // arguments, subnormal results) takes the careful path.
    if x.to_bits() & 0x7fff_ffff >= 0x42ae_0000 {
        return exp_edge(x);
    }
    exp_core(x)
}

/// e^x for EXP_MIN < x <= EXP_MAX.
#[inline(always)]
fn exp_core(x: f32) -> f32 {
    // x = n ln2 + r, |r| <= ln2/2 (plus rounding); Cody-Waite reduction keeps r exact enough.
    // n = round(x log2 e) by the magic-number addition (round to nearest even).
    let shifted = x * LOG2_E + ROUND_MAGIC;
    let n = shifted.to_bits() as i32 - ROUND_MAGIC.to_bits() as i32;
    let nf = shifted - ROUND_MAGIC;
    let r = (x - nf * LN2_HI) - nf * LN2_LO;
    let p = EXP_P[0] + r * (EXP_P[1] + r * (EXP_P[2] + r * EXP_P[3]));
    let er = 1.0 + (r + r * r * p);
    scale_pow2(er, n)
}

/// e^x for |x| >= 87 or NaN.
#[cold]
fn exp_edge(x: f32) -> f32 {
    if x.is_nan() {
        x
    } else if x > EXP_MAX {
        f32::INFINITY
    } else if x <= EXP_MIN {
        0.0
    } else {
        exp_core(x)
    }
}

/// `x * 2^n` for x in [0.5, 2] and n in [-151, 128], exact unless the result is subnormal.
#[inline]
fn scale_pow2(x: f32, n: i32) -> f32 {
    // n in [-126, 127]: one unsigned comparison.
    if ((n + 126) as u32) <= 253 {
        x * pow2(n)
    } else {
        scale_pow2_edge(x, n)
    }
}

#[cold]
fn scale_pow2_edge(x: f32, n: i32) -> f32 {
    if n > 127 {
        x * pow2(127) * 2.0
    } else {
        // Two steps so that each factor is a normal number; the last multiply rounds once.
        x * pow2(n + 64) * pow2(-64)
    }
}

/// 2^n for n in [-126, 127], built from the exponent bits.
#[inline]
fn pow2(n: i32) -> f32 {
    f32::from_bits(((n + 127) as u32) << 23)
}

/// Natural logarithm for any `f32`: -inf for 0, NaN for negative or NaN, +inf for +inf.
#[inline]
pub fn ln(x: f32) -> f32 {
    if x.is_nan() || x < 0.0 {
        return f32::NAN;
    }
    if x == 0.0 {
        return f32::NEG_INFINITY;
    }
    if x == f32::INFINITY {
        return x;
    }
    let mut bits = x.to_bits();
    let mut e: i32 = 0;
    if bits < 0x0080_0000 {
        // Subnormal: scale into the normal range first (exact).
        bits = (x * 33_554_432.0).to_bits(); // 2^25
        e = -25;
    }
    // Write x = 2^e m with m in [sqrt(1/2), sqrt(2)): shift the mantissa so that the exponent
    // field rolls over exactly at sqrt(2), then put the mantissa back in place.
    const SQRT_HALF_BITS: u32 = 0x3f35_04f3;
    let shifted = bits + (0x3f80_0000 - SQRT_HALF_BITS);
    e += (shifted >> 23) as i32 - 127;
    let m = f32::from_bits((shifted & 0x007f_ffff) + SQRT_HALF_BITS);
    // ln m = 2 atanh(f), f = (m-1)/(m+1), |f| <= 0.1716: the odd series to f^7 is within 1e-7.
    let f = (m - 1.0) / (m + 1.0);
    let z = f * f;
    let series = z * (2.0 / 3.0 + z * (2.0 / 5.0 + z * (2.0 / 7.0)));
    let ln_m = 2.0 * f + f * series;
    let ef = e as f32;
    ef * LN2_HI + (ef * LN2_LO + ln_m)
}

/// 1 / ln 2.
const INV_LN2: f32 = core::f32::consts::LOG2_E;

/// Base-2 logarithm for any `f32`: -inf for 0, NaN for negative or NaN, +inf for +inf.
///
/// The same reduction as [`ln`] without the split of ln 2: `e + log2(m)`.
#[inline]
pub fn log2(x: f32) -> f32 {
    let bits = x.to_bits();
    // Positive normal numbers in one unsigned comparison; the rest elsewhere.
    if bits.wrapping_sub(0x0080_0000) >= 0x7f00_0000 {
        return log2_edge(x);
    }
    log2_normal(bits, 0)
}

/// log2 of 0, subnormals, negatives, infinities and NaN.
#[cold]
fn log2_edge(x: f32) -> f32 {
    if x.is_nan() || x < 0.0 {
        f32::NAN
    } else if x == 0.0 {
        f32::NEG_INFINITY
    } else if x == f32::INFINITY {
        x
    } else {
        // Subnormal: scale into the normal range first (exact).
        log2_normal((x * 33_554_432.0).to_bits(), -25)
    }
}

/// log2 of the positive normal number with bits `bits`, plus `e`.
#[inline]
fn log2_normal(bits: u32, mut e: i32) -> f32 {
    const SQRT_HALF_BITS: u32 = 0x3f35_04f3;
    let shifted = bits + (0x3f80_0000 - SQRT_HALF_BITS);
    e += (shifted >> 23) as i32 - 127;
    let m = f32::from_bits((shifted & 0x007f_ffff) + SQRT_HALF_BITS);
    let f = (m - 1.0) / (m + 1.0);
    let z = f * f;
    // log2 m = (2/ln 2) atanh(f): the odd series to f^7, scaled.
    let series = z * (2.0 / 3.0 + z * (2.0 / 5.0 + z * (2.0 / 7.0)));
    let log2_m = (2.0 * INV_LN2) * f + (INV_LN2 * f) * series;
    e as f32 + log2_m
}

/// 2^y for any `f32`: +inf above 128, 0 below -150, NaN for NaN.
#[inline]
pub fn exp2(y: f32) -> f32 {
    // |y| < 126 by one integer comparison; the rest takes the careful path.
    if y.to_bits() & 0x7fff_ffff >= 0x42fc_0000 {
        return exp2_edge(y);
    }
    exp2_core(y)
}

/// 2^y for -150 < y < 128.
#[inline(always)]
fn exp2_core(y: f32) -> f32 {
    let shifted = y + ROUND_MAGIC;
    let n = shifted.to_bits() as i32 - ROUND_MAGIC.to_bits() as i32;
    // y - n is exact, |y - n| <= 0.5; 2^f by its own polynomial in f.
    let f = y - (shifted - ROUND_MAGIC);
    let q = EXP2_P[3] + f * EXP2_P[4];
    let q = EXP2_P[0] + f * (EXP2_P[1] + f * (EXP2_P[2] + f * q));
    scale_pow2(1.0 + f * q, n)
}

/// 2^y for |y| >= 126 or NaN.
#[cold]
fn exp2_edge(y: f32) -> f32 {
    if y.is_nan() {
        y
    } else if y >= 128.0 {
        f32::INFINITY
    } else if y <= -150.0 {
        0.0
    } else {
        exp2_core(y)
    }
}

/// `exp(-(r^delta))` for `r >= 0` (including 0 and +inf) and `delta > 0`: the decay of the
/// Stribeck curve, with one log2 and two exp2.
#[inline]
pub fn stribeck_decay(r: f32, delta: f32) -> f32 {
    // exp(-p) as 2^(-p log2 e): for p > 1 the product's rounding costs p·6e-8 of relative
    // accuracy, which matters only where exp(-p) is already negligible beside Fc.
    exp2(-exp2(delta * log2(r)) * LOG2_E)
}

/// `base^p` for `base >= 0`: `exp(p ln base)`, with 0^p = 0 for p > 0 and +inf^p = +inf.
///
/// Only the non-negative bases that the Stribeck curve needs are supported; a negative base
/// gives NaN.
#[inline]
pub fn powf(base: f32, p: f32) -> f32 {
    exp(p * ln(base))
}

/// `x` as the nearest `f32`, as `x as f32`: through the FPU's one-instruction conversion when
/// `x` fits in an `i32` (the same integer, so the same rounding), by the soft 64-bit one
/// (`__aeabi_l2f`, about 25 instructions on the M4F) only beyond. The control step's
/// differences of fixed-point positions (an error, a step's increment) always fit.
#[inline]
pub(crate) fn i64_to_f32(x: i64) -> f32 {
    match i32::try_from(x) {
        Ok(v) => v as f32,
        Err(_) => i64_to_f32_wide(x),
    }
}

/// The soft conversion, out of line: inlined, LLVM computes it on every call and selects.
#[cold]
#[inline(never)]
fn i64_to_f32_wide(x: i64) -> f32 {
    x as f32
}

/// `c` rounded half away from zero to an `i64`, saturating (NaN gives 0), as
/// `(c ± 0.5) as i64`: through the FPU's conversion to `i32` when the result fits, the soft
/// 64-bit one (`__aeabi_f2lz`) only beyond.
#[inline]
pub(crate) fn round_to_i64(c: f32) -> i64 {
    let r = if c >= 0.0 { c + 0.5 } else { c - 0.5 };
    // 2^31 is exact in f32; every f32 strictly inside (-2^31, 2^31) truncates into an i32.
    if r > -2_147_483_648.0 && r < 2_147_483_648.0 {
        r as i32 as i64
    } else {
        f32_to_i64_wide(r)
    }
}

/// The soft conversion, out of line (see [`i64_to_f32_wide`]).
#[cold]
#[inline(never)]
fn f32_to_i64_wide(r: f32) -> i64 {
    r as i64
}

/// The lesser of `a` and `b`, as [`f32::min`] (a NaN gives the other), by comparisons: on the
/// M4F, whose FPU has no VMINNM, `f32::min` is a call of libm's `fminf` (about 20 cycles).
#[inline]
pub fn min(a: f32, b: f32) -> f32 {
    if a <= b || b.is_nan() { a } else { b }
}

/// The greater of `a` and `b`, as [`f32::max`] (a NaN gives the other), by comparisons (see
/// [`min`]).
#[inline]
pub fn max(a: f32, b: f32) -> f32 {
    if a >= b || b.is_nan() { a } else { b }
}

/// `x` clamped into `[-lim, lim]` (`lim >= 0`; a NaN `x` stays NaN).
pub(crate) fn clamp(x: f32, lim: f32) -> f32 {
    if x > lim {
        lim
    } else if x < -lim {
        -lim
    } else {
        x
    }
}

/// The square root of `x` (`x >= 0`; NaN below, +inf stays) by Newton's iteration from the
/// exponent halved: within 2 ulp (tests/math_accuracy.rs), small in flash (for figures
/// computed once a period, not in every step).
pub fn sqrt(x: f32) -> f32 {
    if x.is_nan() || x < 0.0 {
        return f32::NAN;
    }
    if x == 0.0 || x == f32::INFINITY {
        return x;
    }
    // The exponent halved: within a factor of 1.5 of the root.
    let mut y = f32::from_bits((x.to_bits() >> 1) + 0x1fc0_0000);
    for _ in 0..4 {
        y = 0.5 * (y + x / y);
    }
    y
}

#[cfg(test)]
mod conversions {
    use super::{i64_to_f32, round_to_i64};
    use proptest::prelude::*;

    /// The values where the fast paths hand over to the soft ones.
    const EDGES: [i64; 8] = [
        0,
        i32::MAX as i64,
        i32::MAX as i64 + 1,
        i32::MIN as i64,
        i32::MIN as i64 - 1,
        i64::MAX,
        i64::MIN,
        16_777_217,
    ];

    #[test]
    fn the_fast_conversions_are_the_plain_ones_at_their_edges() {
        for x in EDGES {
            assert_eq!(i64_to_f32(x).to_bits(), (x as f32).to_bits(), "{x}");
        }
        for c in [
            0.0f32,
            -0.0,
            0.5,
            -0.5,
            2_147_483_520.0,
            2_147_483_648.0,
            -2_147_483_648.0,
            -2_147_483_904.0,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NAN,
            f32::MAX,
        ] {
            let plain = (if c >= 0.0 { c + 0.5 } else { c - 0.5 }) as i64;
            assert_eq!(round_to_i64(c), plain, "{c}");
        }
    }

    proptest! {
        #[test]
        fn i64_to_f32_is_as_f32(x in any::<i64>(), small in any::<i32>()) {
            prop_assert_eq!(i64_to_f32(x).to_bits(), (x as f32).to_bits());
            prop_assert_eq!(i64_to_f32(small as i64).to_bits(), (small as i64 as f32).to_bits());
        }

        #[test]
        fn round_to_i64_is_the_plain_rounding(bits in any::<u32>(), c in -3e9f32..3e9) {
            for c in [f32::from_bits(bits), c] {
                let plain = (if c >= 0.0 { c + 0.5 } else { c - 0.5 }) as i64;
                prop_assert_eq!(round_to_i64(c), plain);
            }
        }
    }
}
