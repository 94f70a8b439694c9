//! Validation, presets, the direction asymmetry, and the LuGre and static models.

use gms_core::friction::presets;
use gms_core::{
    Block, Field, FrictionModel, Gms, GmsParams, LuGre, LugreParams, ParamError, Side, StaticMap,
    StaticParams, StribeckParams,
};

const ST: StribeckParams = StribeckParams {
    fs: 1.0,
    fc: 0.6,
    vs: 0.01,
    delta: 1.0,
};

fn two_blocks() -> GmsParams<2> {
    GmsParams {
        stribeck: ST,
        negative: None,
        sigma: 0.5,
        c: 50.0,
        blocks: [Block { k: 1e4, alpha: 0.5 }, Block { k: 1e3, alpha: 0.5 }],
    }
}

/// The f64 Stribeck magnitude straight from eq. 1 with delta.
fn s_abs(p: &StribeckParams, v: f64) -> f64 {
    let (fs, fc, vs, d) = (p.fs as f64, p.fc as f64, p.vs as f64, p.delta as f64);
    fc + (fs - fc) * (-(v.abs() / vs).powf(d)).exp()
}

/// A change to a valid parameter set.
type Edit = Box<dyn Fn(&mut GmsParams<2>)>;

#[test]
fn every_rule_names_its_field() {
    let ok = two_blocks();
    assert!(Gms::try_new(ok).is_ok());
    let cases: Vec<(Edit, ParamError)> = vec![
        (
            Box::new(|p| p.stribeck.fs = f32::NAN),
            ParamError::NonFinite(Field::Fs(Side::Positive)),
        ),
        (
            Box::new(|p| p.c = f32::INFINITY),
            ParamError::NonFinite(Field::C),
        ),
        (
            Box::new(|p| p.blocks[1].k = f32::NAN),
            ParamError::NonFinite(Field::K(1)),
        ),
        (
            Box::new(|p| p.blocks[0].k = 0.0),
            ParamError::KNotPositive(0),
        ),
        (
            Box::new(|p| p.blocks[1].k = -1.0),
            ParamError::KNotPositive(1),
        ),
        (
            Box::new(|p| p.blocks[1].alpha = 0.0),
            ParamError::AlphaNotPositive(1),
        ),
        (Box::new(|p| p.blocks[0].alpha = 0.48), ParamError::AlphaSum),
        (Box::new(|p| p.blocks[0].alpha = 0.52), ParamError::AlphaSum),
        (
            Box::new(|p| p.stribeck.fs = 0.5),
            ParamError::FsBelowFc(Side::Positive),
        ),
        (
            Box::new(|p| p.stribeck.fc = -0.1),
            ParamError::FcNegative(Side::Positive),
        ),
        (
            Box::new(|p| p.stribeck.vs = 0.0),
            ParamError::VsNotPositive(Side::Positive),
        ),
        (
            Box::new(|p| p.stribeck.delta = -1.0),
            ParamError::DeltaNotPositive(Side::Positive),
        ),
        (Box::new(|p| p.sigma = -1e-9), ParamError::SigmaNegative),
        (Box::new(|p| p.c = 0.0), ParamError::CNotPositive),
        (
            Box::new(|p| p.negative = Some(StribeckParams { fs: 0.1, ..ST })),
            ParamError::FsBelowFc(Side::Negative),
        ),
        (
            Box::new(|p| p.negative = Some(StribeckParams { vs: f32::NAN, ..ST })),
            ParamError::NonFinite(Field::Vs(Side::Negative)),
        ),
    ];
    for (i, (edit, want)) in cases.iter().enumerate() {
        let mut p = ok;
        edit(&mut p);
        assert_eq!(Gms::try_new(p).err(), Some(*want), "case {i}");
        assert_eq!(p.validate(), Err(*want));
    }
    // Sums within ±0.01 of 1 are accepted (the paper's Table 1 sums to 0.999).
    let mut p = ok;
    p.blocks[0].alpha = 0.509;
    assert!(Gms::try_new(p).is_ok());
    // The messages name the file's keys.
    assert_eq!(
        ParamError::KNotPositive(2).to_string(),
        "blocks[2].k must be > 0"
    );
    assert_eq!(
        ParamError::FsBelowFc(Side::Negative).to_string(),
        "negative.fs must be >= negative.fc"
    );
    assert_eq!(
        ParamError::NonFinite(Field::C).to_string(),
        "c is not a finite number"
    );
}

#[test]
fn presets_are_valid_and_as_documented() {
    let t = presets::table1();
    assert!(t.validate().is_ok());
    let d: Vec<f32> = t
        .blocks
        .iter()
        .map(|b| b.breakpoint(t.stribeck.fs))
        .collect();
    // docs/design.md#reading-table-1: breakpoints from 0.11 to 7.8 mrad, 29 to 2000 counts of 3.8 urad.
    assert!((d[0] / 0.109e-3 - 1.0).abs() < 0.01, "{d:?}");
    assert!((d[5] / 7.78e-3 - 1.0).abs() < 0.01, "{d:?}");
    let g = presets::guideway();
    assert!(g.validate().is_ok());
    // Breakaway 0.9 N reached after 40 um of pre-sliding, quasi-statically.
    let mut m = Gms::try_new(g).unwrap();
    let mut f_at = Vec::new();
    for _ in 0..80 {
        f_at.push(m.advance(0.5e-6, 1e3)); // 0.5 nm/s: quasi-static
    }
    assert!((f_at[79] - 0.9).abs() < 1e-3, "at 40 um: {}", f_at[79]);
    assert!(
        f_at[70] < 0.9 - 1e-3,
        "saturated before 40 um: {}",
        f_at[70]
    );
}

#[test]
fn asymmetric_stribeck_uses_the_negative_branch_for_negative_velocity() {
    let mut p = two_blocks();
    let neg = StribeckParams {
        fs: 1.3,
        fc: 0.8,
        vs: 0.02,
        delta: 2.0,
    };
    p.negative = Some(neg);
    for v in [0.003f64, 0.01, 0.05] {
        for (dir, branch) in [(1.0, &ST), (-1.0, &neg)] {
            let mut m = Gms::try_new(p).unwrap();
            let t = 10.0;
            let f = m.advance((dir * v * t) as f32, t as f32) as f64;
            let want = dir * s_abs(branch, v) + 0.5 * dir * v;
            assert!(
                (f - want).abs() < 1e-5 * want.abs(),
                "v={} {f} vs {want}",
                dir * v
            );
        }
    }
}

#[test]
fn lugre_steady_state_presliding_stiffness_and_step_invariance() {
    let p = LugreParams {
        stribeck: ST,
        negative: None,
        sigma0: 1e5,
        sigma1: 300.0,
        sigma: 0.5,
    };
    // Steady sliding: s(v) + sigma v.
    for v in [-0.1f64, -0.004, 0.001, 0.02, 1.0] {
        let mut m = LuGre::try_new(p).unwrap();
        let f = m.advance((v * 5.0) as f32, 5.0) as f64;
        let want = v.signum() * s_abs(&ST, v) + 0.5 * v;
        assert!((f - want).abs() < 1e-5 * want.abs(), "v={v}: {f} vs {want}");
    }
    // Pre-sliding: initial stiffness sigma0 (a 1 nm move at 1 um/s: F ≈ sigma0 x + ...).
    let mut m = LuGre::try_new(p).unwrap();
    let x = 1e-9;
    m.advance(x as f32, 1e-3);
    let z = m.deflection() as f64;
    assert!((z / x - 1.0).abs() < 1e-3, "z = {z:e}");
    // Step invariance at constant velocity.
    let mut a = LuGre::try_new(p).unwrap();
    let mut b = LuGre::try_new(p).unwrap();
    a.advance(2e-5, 0.01);
    for _ in 0..40 {
        b.advance(2e-5 / 40.0, 0.01 / 40.0);
    }
    assert!(
        (a.force() - b.force()).abs() < 1e-5,
        "{} vs {}",
        a.force(),
        b.force()
    );
    // Bounded bristles and no NaN under hostile input.
    let mut m = LuGre::try_new(p).unwrap();
    for (dx, dt) in [
        (1e30f32, 0.0f32),
        (-1e30, 1e-45),
        (1e-9, 0.0),
        (f32::MAX, 1.0),
    ] {
        let f = m.advance(dx, dt);
        assert!(!f.is_nan());
        assert!(m.deflection().abs() <= 1.0 / 1e5 * 1.0001);
    }
    assert!(
        LuGre::try_new(LugreParams { sigma0: 0.0, ..p }).err()
            == Some(ParamError::Sigma0NotPositive)
    );
    assert!(
        LuGre::try_new(LugreParams { sigma1: -1.0, ..p }).err() == Some(ParamError::Sigma1Negative)
    );
    m.reset();
    assert_eq!((m.force(), m.deflection()), (0.0, 0.0));
}

#[test]
fn static_map_is_stribeck_plus_viscous_without_memory() {
    let p = StaticParams {
        stribeck: ST,
        negative: None,
        sigma: 0.5,
    };
    let mut m = StaticMap::try_new(p).unwrap();
    for v in [-0.3f64, -0.01, 1e-6, 0.005, 2.0] {
        let f = m.advance((v * 1e-3) as f32, 1e-3) as f64;
        let want = v.signum() * s_abs(&ST, v) + 0.5 * v;
        assert!((f - want).abs() < 1e-5 * want.abs(), "v={v}: {f} vs {want}");
    }
    assert_eq!(m.advance(0.0, 1e-3), 0.0);
    assert_eq!(m.advance(1.0, 0.0), 0.6); // infinite velocity: Coulomb, no viscous term
    assert!(StaticMap::try_new(StaticParams { sigma: -1.0, ..p }).is_err());
}
