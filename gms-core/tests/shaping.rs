//! The loop-shaping filters (`gms_core::shaping`): each stage does what its settings say, and
//! the filter that runs has the response that `Shaping::response` computes.

use gms_core::frf::{LockIn, Sine};
use gms_core::shaping::{Notch, Shaping, ShapingError, ShapingParams};

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
                lock.add(&[x, y, 0.0, 0.0], phase, done, sine.samples());
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
