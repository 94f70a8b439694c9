//! The adaptation of the feedforward level: convergence against the analytic rate, the
//! gates (dead zone, rest, saturation) and the bounds under adversarial inputs.

use gms_core::control::adaptive::{AdaptInput, Adaptive, AdaptiveParams};
use proptest::prelude::*;

fn params() -> AdaptiveParams {
    AdaptiveParams {
        gain: 4.0,
        min: 0.5,
        max: 1.5,
        deadzone: 0.0,
        v_min: 0.01,
    }
}

/// With the loop's feedback equal to the unmodelled friction, `(theta - scale) F̂`, and a
/// model output `F_n sin(w t)`, the mismatch decays as exp(-gain t / 2) (the mean of sin² is
/// 1/2): after 2 s at gain 4, by e^-4.
#[test]
fn the_scale_converges_at_the_analytic_rate() {
    let (f_n, theta, dt) = (220e-6f32, 1.15f32, 1e-4f32);
    let p = params();
    let mut a = Adaptive::new(f_n);
    let w = 2.0 * core::f32::consts::PI * 5.0;
    let n = 20_000;
    for k in 0..n {
        let t = k as f32 * dt;
        let model = f_n * (w * t).sin();
        let x = AdaptInput {
            feedback: (theta - a.scale()) * model,
            applied: a.scale() * model,
            model,
            v_ref: 0.3,
            saturated: false,
        };
        a.update(&p, &x, dt);
    }
    let expected = theta - (theta - 1.0) * (-p.gain * n as f32 * dt / 2.0).exp();
    assert!(
        (a.scale() - expected).abs() < 2e-3,
        "scale {} expected {expected}",
        a.scale()
    );
}

#[test]
fn dead_zone_rest_and_saturation_freeze_it() {
    let p = AdaptiveParams {
        deadzone: 1e-6,
        ..params()
    };
    let mut a = Adaptive::new(1e-4);
    let base = AdaptInput {
        feedback: 5e-5,
        applied: 1e-4,
        model: 1e-4,
        v_ref: 0.3,
        saturated: false,
    };
    for x in [
        AdaptInput {
            feedback: 0.9e-6,
            ..base
        },
        AdaptInput {
            feedback: -0.9e-6,
            ..base
        },
        AdaptInput {
            v_ref: 0.009,
            ..base
        },
        AdaptInput {
            v_ref: -0.009,
            ..base
        },
        AdaptInput {
            saturated: true,
            ..base
        },
    ] {
        assert_eq!(a.update(&p, &x, 1e-3), 1.0, "{x:?}");
    }
    // And it does move outside the gates, in the direction of the unmodelled friction.
    assert!(a.update(&p, &base, 1e-3) > 1.0);
    let neg = AdaptInput {
        feedback: -5e-5,
        ..base
    };
    let mut b = Adaptive::new(1e-4);
    assert!(b.update(&p, &neg, 1e-3) < 1.0);
}

fn any_f32() -> impl Strategy<Value = f32> {
    prop_oneof![
        -1e3f32..1e3,
        Just(f32::NAN),
        Just(f32::INFINITY),
        Just(f32::NEG_INFINITY),
        Just(f32::MAX),
        Just(0.0f32),
    ]
}

proptest! {
    /// Whatever the loop feeds it (noise, no motion, saturation, NaN, huge values) the scale
    /// stays finite and within its bounds.
    #[test]
    fn the_scale_stays_within_its_bounds(
        inputs in prop::collection::vec(
            (any_f32(), any_f32(), any_f32(), any_f32(), any::<bool>()),
            1..400,
        ),
        gain in 0.0f32..1e4,
        lo in 0.0f32..1.0,
        width in 0.0f32..2.0,
        f_n in any_f32(),
    ) {
        let p = AdaptiveParams { gain, min: lo, max: lo + width, deadzone: 0.0, v_min: 0.0 };
        let mut a = Adaptive::new(f_n);
        a.reset(&p);
        for (feedback, applied, model, v_ref, saturated) in inputs {
            let x = AdaptInput { feedback, applied, model, v_ref, saturated };
            let s = a.update(&p, &x, 1e-4);
            prop_assert!(s.is_finite() && s >= p.min && s <= p.max, "{s}");
        }
    }
}
