//! The panic-free decimal parser and formatter against core's (the independent truth on the
//! host): same bits parsed, same text written, and every finite f32 reads back exactly.

use gms_core::numtext::{Num, parse_f32, write_f32};
use proptest::prelude::*;

/// What the protocol accepted before: core's parser, finite values only.
fn core_parse(s: &str) -> Option<f32> {
    s.parse::<f32>().ok().filter(|v| v.is_finite())
}

fn text(x: f32) -> String {
    let mut s = String::new();
    write_f32(&mut s, x).unwrap();
    s
}

fn same(a: Option<f32>, b: Option<f32>) -> bool {
    a.map(f32::to_bits) == b.map(f32::to_bits)
}

#[test]
fn accepts_and_rejects_like_core() {
    let cases = [
        "0",
        "-0",
        "+0",
        "1",
        "+1",
        "-1",
        "1.",
        ".5",
        "-.5",
        "0.1",
        "1e3",
        "1E3",
        "1e+3",
        "1e-3",
        "1.5e-7",
        "3.4028235e38",
        "3.4028236e38",
        "3.40282357e38",
        "3.40282356e38",
        "1e39",
        "-1e39",
        "1e-45",
        "7e-46",
        "7.1e-46",
        "1e-46",
        "1e-50",
        "0e999999999999999",
        "1e-999999999999",
        "1.17549435e-38",
        "1.1754942e-38",
        "123456789012345678901234567890",
        "0.000000000000000000000000000000000000000000001401298464324817070923729583289916",
        "",
        ".",
        "-",
        "+",
        "e5",
        "1e",
        "1e+",
        "1.2.3",
        "1..2",
        "--1",
        "+-1",
        "1 ",
        " 1",
        "0x10",
        "inf",
        "-inf",
        "infinity",
        "NaN",
        "nan",
        "1_000",
        "1e5.5",
        "١",
        "1f",
        "1,5",
    ];
    for c in cases {
        assert!(
            same(parse_f32(c), core_parse(c)),
            "{c:?}: ours {:?}, core {:?}",
            parse_f32(c),
            core_parse(c)
        );
    }
}

#[test]
fn halfway_points_round_to_even() {
    // 16777217 = 2^24 + 1 lies halfway between two f32: ties to even (2^24).
    assert_eq!(parse_f32("16777217"), Some(16_777_216.0));
    // Halfway plus a 1 far behind rounds up: the cut digits count.
    let long = format!("16777217.{}1", "0".repeat(200));
    assert_eq!(parse_f32(&long), Some(16_777_218.0));
    assert_eq!(parse_f32(&long), core_parse(&long));
}

#[test]
fn writes_like_display() {
    for x in [
        0.0f32,
        -0.0,
        1.0,
        0.1,
        0.2,
        1e-12,
        1e9,
        1e20,
        f32::MAX,
        f32::MIN_POSITIVE,
        f32::from_bits(1),
        -3.8e-6,
        6.6e-3,
        220e-6,
        16_777_216.0,
        2.0f32.powi(-126) * 3.0,
    ] {
        assert_eq!(text(x), format!("{x}"), "{x:e}");
        assert_eq!(format!("{}", Num(x)), format!("{x}"));
    }
}

#[test]
fn every_power_of_two_round_trips() {
    // The lopsided intervals next to powers of two are where shortest printing goes wrong.
    for e in 0..254u32 {
        for m in [0u32, 1, 0x7f_ffff] {
            let x = f32::from_bits((e << 23) | m);
            let s = text(x);
            assert_eq!(s, format!("{x}"));
            assert_eq!(parse_f32(&s).map(f32::to_bits), Some(x.to_bits()), "{s}");
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(20_000))]

    /// Every finite f32: Display's text, and it reads back bit for bit.
    #[test]
    fn any_finite_f32_round_trips(bits in any::<u32>()) {
        let x = f32::from_bits(bits);
        prop_assume!(x.is_finite());
        let s = text(x);
        prop_assert_eq!(&s, &format!("{x}"));
        prop_assert_eq!(parse_f32(&s).map(f32::to_bits), Some(bits));
        // And core reads ours the same.
        prop_assert_eq!(core_parse(&s).map(f32::to_bits), Some(bits));
    }

    /// Random decimal text of every shape: the same answer as core.
    #[test]
    fn decimal_text_parses_like_core(
        sign in prop::sample::select(vec!["", "-", "+"]),
        int in "[0-9]{0,30}",
        frac in prop::option::of("[0-9]{0,30}"),
        exp in prop::option::of(-70i32..60),
    ) {
        let mut s = format!("{sign}{int}");
        if let Some(f) = &frac {
            s.push('.');
            s.push_str(f);
        }
        if let Some(e) = exp {
            s.push_str(&format!("e{e}"));
        }
        prop_assert!(same(parse_f32(&s), core_parse(&s)), "{:?}: ours {:?}, core {:?}", s, parse_f32(&s), core_parse(&s));
    }

    /// Near-halfway text: an f32's neighbourhood written with many digits.
    #[test]
    fn near_halfway_text_parses_like_core(bits in 0u32..0x7f7f_ffff, nudge in -3i64..=3) {
        let x = f32::from_bits(bits) as f64;
        let next = f32::from_bits(bits + 1) as f64;
        let mid = (x + next) / 2.0;
        let s = format!("{:.30e}", mid * (1.0 + nudge as f64 * 1e-16));
        prop_assert!(same(parse_f32(&s), core_parse(&s)), "{:?}", s);
    }

    /// Arbitrary text never panics and never yields a non-finite value.
    #[test]
    fn arbitrary_text_is_safe(s in "\\PC{0,40}") {
        let v = parse_f32(&s);
        prop_assert!(v.is_none_or(f32::is_finite));
        prop_assert!(same(v, core_parse(&s)));
    }
}

/// About a million f32 spread over the whole range (every 4099th bit pattern); slow in a
/// debug build: `cargo test --release -p gms-core --test all -- numtext:: --ignored`.
#[test]
#[ignore]
fn sweep_round_trips() {
    for bits in (0..0x7f80_0000u32).step_by(4099) {
        let x = f32::from_bits(bits);
        let s = text(x);
        assert_eq!(s, format!("{x}"));
        assert_eq!(parse_f32(&s).map(f32::to_bits), Some(bits), "{s}");
    }
}

/// `Int` writes what core's formatting writes, at the ends of the range too.
#[test]
fn int_writes_like_core() {
    use gms_core::numtext::Int;
    for v in [
        0i64,
        1,
        -1,
        9,
        10,
        -10,
        12345,
        -987654321,
        i64::MAX,
        i64::MIN,
        1 << 40,
    ] {
        assert_eq!(Int(v).to_string(), v.to_string());
    }
}
