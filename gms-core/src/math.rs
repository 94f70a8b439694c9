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

/// Largest argument with a finite `e^x` in f32.
const EXP_MAX: f32 = 88.722_83;
/// Below this `e^x` is smaller than half the smallest subnormal f32 and rounds to zero.
const EXP_MIN: f32 = -103.972_08;

/// e^x for any `f32`: +inf above 88.72, 0 below -103.97, NaN for NaN.
#[inline]
pub fn exp(x: f32) -> f32 {
    if x > EXP_MAX {
        return f32::INFINITY;
    }
    if x.is_nan() {
        return x;
    }
    if x < EXP_MIN {
        return 0.0;
    }
    // x = n ln2 + r, |r| <= ln2/2 (plus rounding); Cody-Waite reduction keeps r exact enough.
    let t = x * LOG2_E;
    let n = if t >= 0.0 {
        (t + 0.5) as i32
    } else {
        (t - 0.5) as i32
    };
    let nf = n as f32;
    let r = (x - nf * LN2_HI) - nf * LN2_LO;
    let p = EXP_P[0] + r * (EXP_P[1] + r * (EXP_P[2] + r * EXP_P[3]));
    let er = 1.0 + (r + r * r * p);
    scale_pow2(er, n)
}

/// `x * 2^n` for x in [0.5, 2] and n in [-151, 128], exact unless the result is subnormal.
#[inline]
fn scale_pow2(x: f32, n: i32) -> f32 {
    if n >= -126 {
        if n <= 127 {
            x * pow2(n)
        } else {
            x * pow2(127) * 2.0
        }
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

/// `base^p` for `base >= 0`: `exp(p ln base)`, with 0^p = 0 for p > 0 and +inf^p = +inf.
///
/// Only the non-negative bases that the Stribeck curve needs are supported; a negative base
/// gives NaN.
#[inline]
pub fn powf(base: f32, p: f32) -> f32 {
    exp(p * ln(base))
}
