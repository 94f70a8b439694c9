//! Numbers for people: four significant digits, an SI prefix for measurements (`13.33 mA`),
//! plain or scientific for a parameter's value as one would type it (`62800`, `2.467e-4`).

/// `x` with an SI prefix (n to G) and four significant digits, then `unit`:
/// `si(0.013332, "A")` is `"13.33 mA"`, `si(9.9949, "Ω")` is `"9.995 Ω"`. Zero is `"0 unit"`;
/// what is not finite is printed as it is.
pub fn si(x: f64, unit: &str) -> String {
    if x == 0.0 || !x.is_finite() {
        return format!("{x} {unit}");
    }
    const PREFIXES: [(i32, &str); 7] = [
        (-9, "n"),
        (-6, "µ"),
        (-3, "m"),
        (0, ""),
        (3, "k"),
        (6, "M"),
        (9, "G"),
    ];
    let e3 = ((x.abs().log10() / 3.0).floor() as i32 * 3).clamp(-9, 9);
    let prefix = PREFIXES.iter().find(|p| p.0 == e3).map_or("", |p| p.1);
    let v = x / 10f64.powi(e3);
    // Rounding may carry into the next prefix (999.96 m → 1000 m): print it as 1.000.
    let digits = |v: f64| (3 - v.abs().log10().floor() as i32).clamp(0, 3) as usize;
    let text = format!("{v:.*}", digits(v));
    if text.trim_start_matches('-').starts_with("1000") && e3 < 9 {
        let v = v / 1000.0;
        let prefix = PREFIXES.iter().find(|p| p.0 == e3 + 3).map_or("", |p| p.1);
        return format!("{v:.3} {prefix}{unit}");
    }
    format!("{text} {prefix}{unit}")
}

/// `x` to four significant digits as a number one would type: fixed from 0.001 to 10⁶, else
/// scientific (`62800`, `0.1963`, `2.467e-4`).
pub fn num4(x: f64) -> String {
    let a = x.abs();
    if x == 0.0 || !x.is_finite() {
        format!("{x}")
    } else if (1e-3..1e6).contains(&a) {
        let decimals = (3 - a.log10().floor() as i32).max(0) as usize;
        format!("{x:.decimals$}")
    } else {
        format!("{x:.3e}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn prefixes_and_digits() {
        assert_eq!(si(0.013332, "A"), "13.33 mA");
        assert_eq!(si(9.9949, "Ω"), "9.995 Ω");
        assert_eq!(si(-4.478e-6, "A"), "-4.478 µA");
        assert_eq!(si(2.4572e-4, "H"), "245.7 µH");
        assert_eq!(si(6.6617e-3, "V·s/rad"), "6.662 mV·s/rad");
        assert_eq!(si(0.99996, "V"), "1.000 V");
        assert_eq!(si(999.96e-3, "V"), "1.000 V");
        assert_eq!(si(0.0, "A"), "0 A");
        assert_eq!(num4(62800.0), "62800");
        assert_eq!(num4(0.19634), "0.1963");
        assert_eq!(num4(2.4671e-4), "2.467e-4");
        assert_eq!(num4(1.5439), "1.544");
    }
}
