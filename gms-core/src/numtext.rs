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

    /// Divides by `d` (> 0) in place; returns the remainder.
    fn div_small(&mut self, d: u32) -> u32 {
        let d = d.max(1) as u64;
        let mut rem = 0u64;
        for w in self.0.iter_mut().rev() {
            let cur = (rem << 32) | *w as u64;
            *w = (cur / d) as u32;
            rem = cur % d;
        }
        rem as u32
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

/// Digits of |x| = D × 10^exp10, exactly; `None` for zero, infinities and NaN.
fn exact_digits(x: f32) -> Option<Decimal> {
    let bits = x.to_bits();
    let biased = ((bits >> 23) & 0xff) as i32;
    let frac = bits & 0x7f_ffff;
    if biased == 255 || (biased == 0 && frac == 0) {
        return None;
    }
    let (m, e2) = if biased == 0 {
        (frac, -149)
    } else {
        (frac | 0x80_0000, biased - 150)
    };
    let mut big = Big::from_u64(m as u64);
    let exp10 = if e2 >= 0 {
        big = big.shl(e2 as u32);
        0
    } else {
        big.mul_pow(5, (-e2) as u32);
        e2 as i64
    };
    // At most 113 digits (2^24 * 5^149 < 10^113).
    let mut rev = [0u8; MAX_DIGITS];
    let mut n = 0;
    while !big.is_zero() {
        let d = big.div_small(10) as u8;
        if let Some(slot) = rev.get_mut(n) {
            *slot = d;
            n += 1;
        }
    }
    let mut dec = Decimal::new();
    for &d in rev.get(..n).unwrap_or(&[]).iter().rev() {
        dec.push(d);
    }
    dec.exp10 = exp10;
    Some(dec)
}

/// `full` rounded to `p` significant digits (ties up), and which way it went. The result
/// can carry into one more digit (9.99 → 10.0), then its `exp10` grows by one.
fn round_to(full: &Decimal, p: usize, up: Option<bool>) -> (Decimal, bool) {
    let digits = full.digits();
    let p = p.min(digits.len());
    let kept = digits.get(..p).unwrap_or(&[]);
    let rest = digits.get(p..).unwrap_or(&[]);
    let mut out = Decimal::new();
    for &d in kept {
        out.push(d);
    }
    out.exp10 = full.exp10 + rest.len() as i64;
    let round_up = match up {
        Some(u) => u,
        None => match rest.first() {
            None => false,
            Some(&d) if d > 5 => true,
            Some(&d) if d < 5 => false,
            // An exact tie rounds up, as core's shortest printing does.
            Some(_) => true,
        },
    };
    if round_up {
        // Add one unit in the last kept digit.
        let mut carry = true;
        for d in out
            .digits
            .get_mut(..out.len)
            .unwrap_or(&mut [])
            .iter_mut()
            .rev()
        {
            if !carry {
                break;
            }
            if *d == 9 {
                *d = 0;
            } else {
                *d += 1;
                carry = false;
            }
        }
        if carry {
            // All nines: 1 followed by zeros, one place up.
            if let Some(first) = out.digits.get_mut(0) {
                *first = 1;
            }
            for d in out.digits.get_mut(1..out.len).unwrap_or(&mut []) {
                *d = 0;
            }
            out.exp10 += 1;
        }
    } else if rest.iter().all(|&d| d == 0) {
        return (out, false);
    }
    (out, round_up)
}

/// Drops trailing zero digits into the exponent.
fn trim(mut d: Decimal) -> Decimal {
    while d.len > 1 && d.digits.get(d.len - 1) == Some(&0) {
        d.len -= 1;
        d.exp10 += 1;
    }
    d
}

/// The shortest decimal that reads back as `x` (the nearest one among the shortest).
fn shortest(x: f32) -> Option<Decimal> {
    let full = exact_digits(x)?;
    let target = x.to_bits() & 0x7fff_ffff;
    let reads_back = |d: &Decimal| d.to_f32(false).map(f32::to_bits) == Some(target);
    for p in 1..=9 {
        let (near, went_up) = round_to(&full, p, None);
        if reads_back(&near) {
            return Some(trim(near));
        }
        // Next to a power of two the interval is lopsided: the neighbour on the other side
        // of x may read back when the nearest does not.
        if p < full.len {
            let (other, _) = round_to(&full, p, Some(!went_up));
            if reads_back(&other) {
                return Some(trim(other));
            }
        }
    }
    Some(trim(full))
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
