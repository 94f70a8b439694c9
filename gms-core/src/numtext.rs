//! Decimal text to f32 and back, without a panicking path (core's float parsing and
//! formatting contain panics the optimiser cannot remove, so a target build that must be
//! proven panic-free cannot use them).
//!
//! - [`parse_f32`] accepts what `str::parse::<f32>` accepts for finite numbers: an optional
//!   sign, digits with an optional decimal point (at least one digit), an optional exponent
//!   `e`/`E` with an optional sign and at least one digit. The result is correctly rounded
//!   (round half to even), the same bits as core's parser; values that round to infinity,
//!   `inf`, `NaN` and anything else give `None`. Values too small for f32 give ±0.
//! - [`write_f32`] writes what `{}` (Display) writes: the shortest decimal that reads back as
//!   the same f32, without an exponent (`0.0001`, `1000000`, `-0`).
//!
//! Both compute exactly with a small fixed-size big integer (no allocation); neither is fast
//! (a few microseconds on a Cortex-M4), neither belongs in a control step.

use core::cmp::Ordering;
use core::fmt::{self, Write};

/// 32-bit words of the big integer: 768 bits, enough for every intermediate value (the
/// largest is below 2^660).
const WORDS: usize = 24;

/// Significant digits kept exactly. More digits only matter as "something non-zero follows",
/// which is exact for f32: every halfway point between two f32 has at most 113 significant
/// digits, so a value cut after 125 digits lies on the same side of it.
const MAX_DIGITS: usize = 125;

/// Unsigned big integer, little-endian 32-bit words.
#[derive(Clone, Copy, PartialEq, Eq)]
struct Big([u32; WORDS]);

impl Big {
    const ZERO: Big = Big([0; WORDS]);

    fn from_u64(x: u64) -> Big {
        let mut b = Big::ZERO;
        let mut it = b.0.iter_mut();
        if let Some(w) = it.next() {
            *w = x as u32;
        }
        if let Some(w) = it.next() {
            *w = (x >> 32) as u32;
        }
        b
    }

    fn is_zero(&self) -> bool {
        self.0.iter().all(|&w| w == 0)
    }

    /// self = self * m + a (bits carried out of the top are lost; callers stay below it).
    fn mul_add_small(&mut self, m: u32, a: u32) {
        let mut carry = a as u64;
        for w in self.0.iter_mut() {
            let t = (*w as u64) * (m as u64) + carry;
            *w = t as u32;
            carry = t >> 32;
        }
    }

    fn mul_pow(&mut self, base: u32, mut n: u32) {
        // base^k fits in u32 for k <= 9 (base 10) and k <= 13 (base 5).
        let (chunk, chunk_pow) = if base == 5 {
            (13, 1_220_703_125u32)
        } else {
            (9, 1_000_000_000u32)
        };
        while n >= chunk {
            self.mul_add_small(chunk_pow, 0);
            n -= chunk;
        }
        let mut p = 1u32;
        for _ in 0..n {
            p = p.wrapping_mul(base);
        }
        self.mul_add_small(p, 0);
    }

    fn bit_len(&self) -> u32 {
        for (i, &w) in self.0.iter().enumerate().rev() {
            if w != 0 {
                return i as u32 * 32 + (32 - w.leading_zeros());
            }
        }
        0
    }

    fn word(&self, i: usize) -> u32 {
        self.0.get(i).copied().unwrap_or(0)
    }

    /// self << n (bits shifted out of the top are lost).
    fn shl(&self, n: u32) -> Big {
        let ws = (n / 32) as usize;
        let bs = n % 32;
        let mut out = Big::ZERO;
        for (i, w) in out.0.iter_mut().enumerate() {
            let Some(src) = i.checked_sub(ws) else {
                continue;
            };
            let hi = self.word(src) << bs;
            let lo = match (bs, src.checked_sub(1)) {
                (0, _) | (_, None) => 0,
                (_, Some(j)) => self.word(j) >> (32 - bs),
            };
            *w = hi | lo;
        }
        out
    }

    fn cmp(&self, o: &Big) -> Ordering {
        for (a, b) in self.0.iter().zip(o.0.iter()).rev() {
            match a.cmp(b) {
                Ordering::Equal => {}
                other => return other,
            }
        }
        Ordering::Equal
    }

    /// self -= o (requires self >= o).
    fn sub(&mut self, o: &Big) {
        let mut borrow = 0u64;
        for (a, &b) in self.0.iter_mut().zip(o.0.iter()) {
            let t = (*a as u64).wrapping_sub(b as u64).wrapping_sub(borrow);
            *a = t as u32;
            borrow = (t >> 63) & 1;
        }
    }
}

/// A decimal number `0.d1 d2 … dn × 10^point` (`digits` without leading zeros), plus whether
/// non-zero digits were cut after the stored ones.
struct Decimal {
    digits: [u8; MAX_DIGITS],
    len: usize,
    /// Value = D × 10^exp10, D the integer of the stored digits.
    exp10: i64,
    truncated: bool,
}

impl Decimal {
    fn new() -> Decimal {
        Decimal {
            digits: [0; MAX_DIGITS],
            len: 0,
            exp10: 0,
            truncated: false,
        }
    }

    fn digits(&self) -> &[u8] {
        self.digits.get(..self.len).unwrap_or(&[])
    }

    /// Appends a significant digit; returns false when there is no room (the caller then
    /// treats it as cut).
    fn push(&mut self, d: u8) -> bool {
        match self.digits.get_mut(self.len) {
            Some(slot) => {
                *slot = d;
                self.len += 1;
                true
            }
            None => false,
        }
    }

    /// The f32 nearest to the value (ties to even); `None` if it rounds beyond f32::MAX.
    fn to_f32(&self, negative: bool) -> Option<f32> {
        let sign = if negative { 0x8000_0000u32 } else { 0 };
        let k = self.len as i64;
        if k == 0 {
            return Some(f32::from_bits(sign));
        }
        // The value lies in [10^(k-1+e), 10^(k+e)).
        if k - 1 + self.exp10 > 38 {
            return None;
        }
        if k + self.exp10 < -46 {
            // Below 1e-46, less than half the smallest subnormal (1.4e-45).
            return Some(f32::from_bits(sign));
        }
        let mut n = Big::ZERO;
        for &d in self.digits() {
            n.mul_add_small(10, d as u32);
        }
        let mut den = Big::from_u64(1);
        if self.exp10 >= 0 {
            n.mul_pow(10, self.exp10 as u32);
        } else {
            den.mul_pow(10, (-self.exp10) as u32);
        }
        // Binary exponent E with 2^E <= n/den < 2^(E+1).
        let diff = n.bit_len() as i64 - den.bit_len() as i64;
        let at_least = if diff >= 0 {
            n.cmp(&den.shl(diff as u32)) != Ordering::Less
        } else {
            n.shl((-diff) as u32).cmp(&den) != Ordering::Less
        };
        let e = if at_least { diff } else { diff - 1 };
        // Weight of the mantissa's last bit, then one guard bit below it.
        let lsb = (e - 23).max(-149);
        let shift = 1 - lsb;
        let (mut num, den) = if shift >= 0 {
            (n.shl(shift as u32), den)
        } else {
            (n, den.shl((-shift) as u32))
        };
        // q = floor(num / den) < 2^25: restoring division, one bit at a time.
        let mut q = 0u32;
        for b in (0..26u32).rev() {
            let t = den.shl(b);
            if num.cmp(&t) != Ordering::Less {
                num.sub(&t);
                q |= 1 << b;
            }
        }
        let sticky = !num.is_zero() || self.truncated;
        let guard = q & 1;
        let mut mant = q >> 1;
        let mut lsb = lsb;
        if guard == 1 && (sticky || mant & 1 == 1) {
            mant += 1;
            if mant == 1 << 24 {
                mant = 1 << 23;
                lsb += 1;
            }
        }
        if mant >= 1 << 23 {
            let biased = lsb + 150;
            if biased >= 255 {
                return None;
            }
            Some(f32::from_bits(
                sign | ((biased as u32) << 23) | (mant & 0x7f_ffff),
            ))
        } else {
            // Subnormal (lsb = -149); a carry into bit 23 above made it the smallest normal.
            Some(f32::from_bits(sign | mant))
        }
    }
}

/// Consumes an optional `+` or `-`; true for `-`.
fn take_sign(bytes: &mut core::iter::Peekable<impl Iterator<Item = u8>>) -> bool {
    match bytes.peek() {
        Some(b'-') => {
            bytes.next();
            true
        }
        Some(b'+') => {
            bytes.next();
            false
        }
        _ => false,
    }
}

/// A finite f32 from decimal text (see the module doc), or `None`.
pub fn parse_f32(s: &str) -> Option<f32> {
    let mut bytes = s.as_bytes().iter().copied().peekable();
    let negative = take_sign(&mut bytes);
    let mut dec = Decimal::new();
    let mut any_digit = false;
    let mut after_point = false;
    let mut scale: i64 = 0;
    loop {
        match bytes.peek().copied() {
            Some(c @ b'0'..=b'9') => {
                bytes.next();
                any_digit = true;
                let d = c - b'0';
                if dec.len == 0 && d == 0 {
                    // A leading zero: only moves the point.
                    if after_point {
                        scale -= 1;
                    }
                } else if dec.push(d) {
                    if after_point {
                        scale -= 1;
                    }
                } else {
                    dec.truncated |= d != 0;
                    if !after_point {
                        scale += 1;
                    }
                }
            }
            Some(b'.') if !after_point => {
                bytes.next();
                after_point = true;
            }
            _ => break,
        }
    }
    if !any_digit {
        return None;
    }
    let mut exp: i64 = 0;
    if let Some(b'e' | b'E') = bytes.peek() {
        bytes.next();
        let neg_exp = take_sign(&mut bytes);
        let mut any = false;
        while let Some(c @ b'0'..=b'9') = bytes.peek().copied() {
            bytes.next();
            any = true;
            // Saturate far beyond any f32 exponent.
            exp = (exp * 10 + (c - b'0') as i64).min(1_000_000_000);
        }
        if !any {
            return None;
        }
        if neg_exp {
            exp = -exp;
        }
    }
    if bytes.next().is_some() {
        return None;
    }
    dec.exp10 = scale + exp;
    dec.to_f32(negative)
}

/// Drops trailing zero digits into the exponent.
fn trim(mut d: Decimal) -> Decimal {
    while d.len > 1 && d.digits.get(d.len - 1) == Some(&0) {
        d.len -= 1;
        d.exp10 += 1;
    }
    d
}

/// The shortest decimal that reads back as `x` (the nearest one among the shortest): Ryū's
/// digits (the `ryu` crate; Adams, "Ryū: fast float-to-string conversion", PLDI 2018), laid
/// out here without an exponent. A few hundred instructions a value, where the search over
/// the exact digits it replaced (rounding to 1…9 digits, each parsed back) took some
/// 100,000 on the M4: a `status` reply cost 1.6 M instructions of the board's thread time.
fn shortest(x: f32) -> Option<Decimal> {
    if !x.is_finite() || x == 0.0 {
        return None;
    }
    let mut buf = ryu::Buffer::new();
    let text = buf.format_finite(x.abs());
    let (mant, exp) = match text.split_once('e') {
        Some((m, e)) => (m, small_int(e)?),
        None => (text, 0),
    };
    let mut d = Decimal::new();
    let mut frac_len = 0i64;
    let mut point = false;
    for b in mant.bytes() {
        match b {
            b'.' => point = true,
            b'0'..=b'9' => {
                if point {
                    frac_len += 1;
                }
                let v = b - b'0';
                if d.len == 0 && v == 0 {
                    continue;
                }
                if !d.push(v) {
                    return None;
                }
            }
            _ => return None,
        }
    }
    d.exp10 = exp - frac_len;
    let d = trim(d);
    Some(tie_up(x, d))
}

/// Ryū breaks an exact tie between the two shortest candidates to the even one; core's
/// Display (whose text the protocol has always written) takes the upper one. A tie is an
/// exact value of one significant digit more, ending in 5 (x = m·2^k: a 5^j's or an
/// integer's digits, both within 64 bits where a tie is possible at all: at most 10
/// significant digits); the upper candidate replaces `d` then.
fn tie_up(x: f32, d: Decimal) -> Decimal {
    let bits = x.to_bits() & 0x7fff_ffff;
    let biased = (bits >> 23) as i64;
    let frac = bits & 0x7f_ffff;
    let (mut m, mut k) = if biased == 0 {
        (frac as u64, -149i64)
    } else {
        ((frac | 1 << 23) as u64, biased - 150)
    };
    if m == 0 {
        return d;
    }
    while m & 1 == 0 {
        m >>= 1;
        k += 1;
    }
    // The exact value as N · 10^e.
    let (n, e) = if k < 0 {
        let j = (-k) as u32;
        if j > 14 {
            return d;
        }
        (m * 5u64.pow(j), k)
    } else {
        if k > 100 {
            return d;
        }
        let mut v = (m as u128) << k;
        let mut z = 0i64;
        while v % 10 == 0 {
            v /= 10;
            z += 1;
        }
        if v >= 10_000_000_000 {
            return d;
        }
        (v as u64, z)
    };
    let mut len = 0;
    let mut t = n;
    while t > 0 {
        t /= 10;
        len += 1;
    }
    if n % 10 != 5 || len != d.len + 1 {
        return d;
    }
    let up = n / 10 + 1;
    let mut digits = [0u8; 20];
    let mut at = digits.len();
    let mut t = up;
    while t > 0 && at > 0 {
        at -= 1;
        if let Some(slot) = digits.get_mut(at) {
            *slot = (t % 10) as u8;
        }
        t /= 10;
    }
    let mut out = Decimal::new();
    for &v in digits.get(at..).unwrap_or(&[]) {
        if !out.push(v) {
            return d;
        }
    }
    out.exp10 = e + 1;
    trim(out)
}

/// A small signed decimal integer (Ryū's exponent), `None` past 4 digits or on anything else.
fn small_int(s: &str) -> Option<i64> {
    let (neg, digits) = match s.strip_prefix('-') {
        Some(rest) => (true, rest),
        None => (false, s),
    };
    if digits.is_empty() || digits.len() > 4 {
        return None;
    }
    let mut v = 0i64;
    for b in digits.bytes() {
        if !b.is_ascii_digit() {
            return None;
        }
        v = v * 10 + (b - b'0') as i64;
    }
    Some(if neg { -v } else { v })
}

/// Writes `x` as `{}` (Display) does: shortest round-trip digits, no exponent.
pub fn write_f32(out: &mut dyn Write, x: f32) -> fmt::Result {
    if x.is_nan() {
        return out.write_str("NaN");
    }
    if x.is_sign_negative() {
        out.write_char('-')?;
    }
    if x.is_infinite() {
        return out.write_str("inf");
    }
    let Some(d) = shortest(x) else {
        return out.write_char('0');
    };
    let digits = d.digits();
    // Digits before the point.
    let point = digits.len() as i64 + d.exp10;
    if point <= 0 {
        out.write_str("0.")?;
        for _ in 0..-point {
            out.write_char('0')?;
        }
        for &c in digits {
            out.write_char((b'0' + c) as char)?;
        }
    } else {
        for (i, &c) in digits.iter().enumerate() {
            if i as i64 == point {
                out.write_char('.')?;
            }
            out.write_char((b'0' + c) as char)?;
        }
        for _ in digits.len() as i64..point {
            out.write_char('0')?;
        }
    }
    Ok(())
}

/// `x` formatted by [`write_f32`], for `write!` (`write!(out, "{}", Num(x))`).
#[derive(Debug, Clone, Copy)]
pub struct Num(pub f32);

impl fmt::Display for Num {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write_f32(f, self.0)
    }
}

/// An integer for a reply, written digit by digit (core's 64-bit integer formatting is a
/// large piece of a board's flash).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Int(pub i64);

impl fmt::Display for Int {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let mut digits = [0u8; 20];
        let mut n = self.0.unsigned_abs();
        let mut at = digits.len();
        loop {
            at -= 1;
            if let Some(d) = digits.get_mut(at) {
                *d = b'0' + (n % 10) as u8;
            }
            n /= 10;
            if n == 0 || at == 0 {
                break;
            }
        }
        if self.0 < 0 {
            f.write_str("-")?;
        }
        for d in digits.iter().skip(at) {
            f.write_char(char::from(*d))?;
        }
        Ok(())
    }
}
