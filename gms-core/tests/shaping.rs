//! The loop-shaping filters (`gms_core::control::shaping`): each stage does what its settings say, and
//! the filter that runs has the response that `Shaping::response` computes.

use gms_core::control::frf::{LockIn, Sine};
use gms_core::control::shaping::{Notch, Shaping, ShapingError, ShapingParams};

const RATE: f32 = 20_000.0;

fn db((re, im): (f64, f64)) -> f64 {
    20.0 * re.hypot(im).log10()
}

fn notch(f_hz: f32, q: f32, depth_db: f32) -> ShapingParams {
    ShapingParams {
        notch: [Notch { f_hz, q, depth_db }, Notch::default()],
        lp_hz: 0.0,
    }
}

#[test]
fn a_notch_cuts_its_depth_at_its_centre_and_nothing_far_from_it() {
    for (f0, q, depth) in [(180.0, 2.0, 20.0), (1200.0, 5.0, 30.0), (55.0, 1.0, 12.0)] {
        let s = Shaping::try_new(&notch(f0, q, depth), RATE).unwrap();
        let at = db(s.response(f0 as f64, RATE as f64));
        assert!((at + depth as f64).abs() < 0.01, "{f0} Hz: {at} dB");
        for f in [f0 as f64 / 30.0, (f0 as f64 * 30.0).min(0.4 * RATE as f64)] {
            let g = db(s.response(f, RATE as f64));
            assert!(g.abs() < 0.1, "{f0} Hz notch at {f} Hz: {g} dB");
        }
        // Within the band, less than the full depth.
        let g = db(s.response(f0 as f64 * 1.2, RATE as f64));
        assert!(g < 0.0 && g > -(depth as f64), "{g}");
    }
}

#[test]
fn the_low_pass_is_a_second_order_butterworth() {
    let p = ShapingParams {
        lp_hz: 800.0,
        ..ShapingParams::default()
    };
    let s = Shaping::try_new(&p, RATE).unwrap();
    assert!(db(s.response(1.0, RATE as f64)).abs() < 1e-4);
    assert!((db(s.response(800.0, RATE as f64)) + 3.0103).abs() < 0.01);
    // Above the corner it falls at about 40 dB per decade (the bilinear transform bends it
    // down towards Nyquist): at 5 × the corner within 3 dB of that.
    let g = db(s.response(4000.0, RATE as f64));
    let slope = -40.0 * (4000.0f64 / 800.0).log10();
    assert!((g - slope).abs() < 3.0, "{g} vs {slope}");
}

/// The filter that runs (the crate's direct form, in f32) measured with the device's own
/// whole-period demodulation against the response computed from its coefficients.
#[test]
fn the_running_filter_has_the_computed_response() {
    let p = ShapingParams {
        notch: [
            Notch {
                f_hz: 300.0,
                q: 3.0,
                depth_db: 25.0,
            },
            Notch {
                f_hz: 2000.0,
                q: 8.0,
                depth_db: 15.0,
            },
        ],
        lp_hz: 1500.0,
    };
    for f in [40.0, 290.0, 310.0, 900.0, 1990.0, 3000.0] {
        let mut s = Shaping::try_new(&p, RATE).unwrap();
        let mut sine = Sine::new(f, RATE, 1.0).unwrap();
        let mut lock = LockIn::new();
        let (mut k, mut boundary, mut started) = (0u32, true, false);
        while lock.groups() < 10 {
            let x = sine.value();
            let y = s.run(x);
            let phase = sine.phase();
            started |= k > 20_000 && boundary;
            let done = sine.advance();
            if started {
                lock.add(&[x, y, 0.0], phase, done, sine.samples());
            }
            boundary = done;
            k += 1;
        }
        let m = lock.phasor(1).unwrap().ratio(&lock.phasor(0).unwrap());
        let h = s.response(sine.freq_hz(RATE), RATE as f64);
        let err = (m.0 - h.0).hypot(m.1 - h.1) / h.0.hypot(h.1);
        assert!(err < 1e-3, "{f} Hz: measured {m:?}, computed {h:?}");
    }
}

#[test]
fn off_is_off_and_bad_settings_are_refused() {
    let mut s = Shaping::try_new(&ShapingParams::default(), RATE).unwrap();
    for x in [0.0, 1.5, -0.25, 1e-6] {
        assert_eq!(s.run(x), x);
    }
    assert_eq!(s.response(123.0, RATE as f64), (1.0, 0.0));
    for (p, e) in [
        (notch(-5.0, 2.0, 10.0), ShapingError::Frequency),
        (notch(9500.0, 2.0, 10.0), ShapingError::Frequency),
        (notch(f32::NAN, 2.0, 10.0), ShapingError::Frequency),
        (notch(100.0, 0.0, 10.0), ShapingError::Quality),
        (notch(100.0, 80.0, 10.0), ShapingError::Quality),
        (notch(100.0, 2.0, -3.0), ShapingError::Depth),
        (notch(100.0, 2.0, 90.0), ShapingError::Depth),
    ] {
        assert_eq!(Shaping::try_new(&p, RATE).err(), Some(e), "{p:?}");
        assert!(!e.reason().is_empty());
    }
}

/// The response of a cookbook stage as the `biquad` crate computes its coefficients (the
/// other implementation of the formulas) at `f` for the rate `fs`.
fn crate_response(t: biquad::Type<f32>, f0: f32, q: f32, fs: f32, f: f64) -> (f64, f64) {
    use biquad::{Coefficients, ToHertz};
    let c = Coefficients::<f32>::from_params(t, fs.hz(), f0.hz(), q).unwrap();
    let w = std::f64::consts::TAU * f / fs as f64;
    let z1 = (w.cos(), -w.sin());
    let z2 = ((2.0 * w).cos(), -(2.0 * w).sin());
    let num = (
        c.b0 as f64 + c.b1 as f64 * z1.0 + c.b2 as f64 * z2.0,
        c.b1 as f64 * z1.1 + c.b2 as f64 * z2.1,
    );
    let den = (
        1.0 + c.a1 as f64 * z1.0 + c.a2 as f64 * z2.0,
        c.a1 as f64 * z1.1 + c.a2 as f64 * z2.1,
    );
    let d = den.0 * den.0 + den.1 * den.1;
    (
        (num.0 * den.0 + num.1 * den.1) / d,
        (num.1 * den.0 - num.0 * den.1) / d,
    )
}

/// The coefficients the device computes with its own sine and exponential are the `biquad`
/// crate's (`Coefficients::from_params`, libm's): the same response within 0.01 dB and 0.05°
/// over notches from 50 Hz to 4.4 kHz (q 0.5 to 20, 6 to 40 dB) and low-passes, at 10 kHz.
#[test]
fn the_coefficients_are_the_biquad_crates() {
    let fs = 10_000.0f32;
    let (mut worst_db, mut worst_deg) = (0.0f64, 0.0f64);
    let mut check = |ours: (f64, f64), theirs: (f64, f64)| {
        let d_db = (db(ours) - db(theirs)).abs();
        let d_deg = (ours.1.atan2(ours.0) - theirs.1.atan2(theirs.0)).to_degrees();
        let d_deg = (d_deg + 180.0).rem_euclid(360.0) - 180.0;
        worst_db = worst_db.max(d_db);
        worst_deg = worst_deg.max(d_deg.abs());
    };
    for f0 in [50.0f32, 700.0, 3000.0, 4400.0] {
        for q in [0.5f32, 2.0, 20.0] {
            for depth in [6.0f32, 20.0, 40.0] {
                let sh = Shaping::try_new(&notch(f0, q, depth), fs).unwrap();
                for k in 0..60 {
                    let f = 10.0 * 490f64.powf(k as f64 / 59.0);
                    check(
                        sh.response(f, fs as f64),
                        crate_response(biquad::Type::PeakingEQ(-depth), f0, q, fs, f),
                    );
                }
            }
        }
        let lp = ShapingParams {
            lp_hz: f0,
            ..ShapingParams::OFF
        };
        let sh = Shaping::try_new(&lp, fs).unwrap();
        for k in 0..60 {
            let f = 10.0 * 490f64.powf(k as f64 / 59.0);
            check(
                sh.response(f, fs as f64),
                crate_response(biquad::Type::LowPass, f0, biquad::Q_BUTTERWORTH_F32, fs, f),
            );
        }
    }
    println!("worst {worst_db:.2e} dB, {worst_deg:.2e}°");
    assert!(
        worst_db < 0.01 && worst_deg < 0.05,
        "{worst_db} dB {worst_deg}°"
    );
}

/// A change of filters while they run is bumpless: switched on at a steady level, a notch's
/// output stays at that level (no transient); retuned while a sine runs through it, the
/// output's step at the change is no larger than its steps before.
#[test]
fn a_change_of_filters_is_bumpless() {
    let fs = 10_000.0f32;
    // Off, then a notch and the low-pass switched on at a steady 0.3 A.
    let mut a = Shaping::try_new(&ShapingParams::OFF, fs).unwrap();
    for _ in 0..10 {
        a.run(0.3);
    }
    let p = ShapingParams {
        notch: [
            Notch {
                f_hz: 700.0,
                q: 2.0,
                depth_db: 20.0,
            },
            Notch::OFF,
        ],
        lp_hz: 2000.0,
    };
    let mut b = Shaping::try_new(&p, fs).unwrap();
    b.take_state_from(&a);
    for k in 0..200 {
        let y = b.run(0.3);
        assert!((y - 0.3).abs() < 1e-5, "step {k}: {y}");
    }
    // Retuned while a 50 Hz sine runs through it (the notch moved, the low-pass the same).
    let x = |k: usize| 0.2 * (std::f32::consts::TAU * 50.0 * k as f32 / fs).sin();
    let mut largest = 0.0f32;
    let mut last = 0.0;
    // The change at k = 450: the sine at its peak.
    for k in 0..450 {
        let y = b.run(x(k));
        if k > 250 {
            largest = largest.max((y - last).abs());
        }
        last = y;
    }
    let mut q = p;
    q.notch[0].f_hz = 900.0;
    q.notch[0].depth_db = 30.0;
    let mut c = Shaping::try_new(&q, fs).unwrap();
    c.take_state_from(&b);
    let y = c.run(x(450));
    // Without the hand-over (a filter at rest) the first output is a jump of the whole level.
    let mut cold = Shaping::try_new(&q, fs).unwrap();
    let jump_cold = (cold.run(x(450)) - last).abs();
    println!(
        "step at the change {:.2e} A, largest step before {largest:.2e} A, at rest {jump_cold:.2e} A",
        (y - last).abs()
    );
    assert!(
        (y - last).abs() <= 1.5 * largest,
        "{} vs {largest}",
        (y - last).abs()
    );
    assert!(jump_cold > 5.0 * largest);
}
