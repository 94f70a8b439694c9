//! The device's frequency-response measurement (`gms_core::control::frf`): the sine it injects and the
//! whole-period demodulation, against analytic responses.

use gms_core::control::frf::{CHANNELS, FrfError, LockIn, Sine};

/// The measured ratio of channel 1 to channel 0 for a first-order low-pass
/// `y[k] = a y[k-1] + (1 - a) u[k]` driven by the sine, after `settle` samples, over `groups`
/// groups; and the analytic `H(e^{jω})` at the sine's frequency.
fn low_pass(freq: f32, rate: f32, a: f64, groups: u32) -> ((f64, f64), (f64, f64), Sine) {
    let mut sine = Sine::new(freq, rate, 0.3).unwrap();
    let mut lock = LockIn::new();
    let mut y = 0.0f64;
    // Settle for 40 time constants.
    let settle = (40.0 / (1.0 - a)) as u64;
    let (mut k, mut boundary, mut started) = (0u64, true, false);
    while lock.groups() < groups {
        let u = sine.value() as f64;
        y = a * y + (1.0 - a) * u;
        let phase = sine.phase();
        // Sum whole groups only: from the first group boundary after settling.
        started |= k >= settle && boundary;
        let done = sine.advance();
        if started {
            lock.add(&[u as f32, y as f32, 0.0], phase, done, sine.samples());
        }
        boundary = done;
        k += 1;
    }
    let m = lock.phasor(1).unwrap().ratio(&lock.phasor(0).unwrap());
    let w = std::f64::consts::TAU * sine.freq_hz(rate) / rate as f64;
    // H = (1 - a) / (1 - a e^{-jw})
    let (dr, di) = (1.0 - a * w.cos(), a * w.sin());
    let d = dr * dr + di * di;
    let h = ((1.0 - a) * dr / d, -(1.0 - a) * di / d);
    (m, h, sine)
}

#[test]
fn a_first_order_lag_is_measured_as_its_transfer_function() {
    for (freq, a) in [(5.0, 0.999), (37.3, 0.99), (400.0, 0.95), (2500.0, 0.5)] {
        let (m, h, sine) = low_pass(freq, 20_000.0, a, 20);
        let err = ((m.0 - h.0).powi(2) + (m.1 - h.1).powi(2)).sqrt() / (h.0.hypot(h.1));
        assert!(
            err < 1e-4,
            "{freq} Hz ({} Hz, {} periods in {} samples): measured {m:?}, analytic {h:?}, rel. error {err:e}",
            sine.freq_hz(20_000.0),
            sine.periods(),
            sine.samples()
        );
    }
}

#[test]
fn harmonics_and_offsets_do_not_leak_into_the_whole_period_result() {
    let rate = 10_000.0;
    let mut sine = Sine::new(123.4, rate, 1.0).unwrap();
    let mut lock = LockIn::new();
    let (amp, ph) = (0.7f64, -0.6f64);
    while lock.groups() < 7 {
        let (s, c) = sine.phase();
        let th = (s as f64).atan2(c as f64);
        // The fundamental at phase ph, plus 0.5 of its third harmonic and a 0.2 offset: whole
        // groups of periods reject all but the fundamental.
        let x = amp * (th + ph).sin() + 0.5 * (3.0 * th + 1.0).sin() + 0.2;
        let done = sine.advance();
        lock.add(&[x as f32, 0.0, 0.0], (s, c), done, sine.samples());
    }
    let p = lock.phasor(0).unwrap();
    assert!((p.abs() - amp).abs() < 1e-5, "{p:?}");
    assert!((p.im.atan2(p.re) - ph).abs() < 1e-5, "{p:?}");
    assert!(lock.phasor(CHANNELS).is_none());
}

#[test]
fn the_frequency_fits_the_rate_and_bad_requests_are_refused() {
    for (f, rate) in [
        (10.0, 10_000.0),
        (37.3, 20_000.0),
        (2999.0, 20_000.0),
        (0.1, 10_000.0),
    ] {
        let s = Sine::new(f, rate, 0.1).unwrap();
        let got = s.freq_hz(rate);
        assert!((got / f as f64 - 1.0).abs() <= 1e-3, "{f}: {got}");
        // k periods in exactly n samples.
        assert!((got * s.samples() as f64 / rate as f64 - s.periods() as f64).abs() < 1e-9);
        // The sine repeats every n samples, bit for bit.
        let mut t = s;
        let first: Vec<f32> = (0..5)
            .map(|_| {
                let v = t.value();
                t.advance();
                v
            })
            .collect();
        for _ in 5..s.samples() {
            t.advance();
        }
        let again: Vec<f32> = (0..5)
            .map(|_| {
                let v = t.value();
                t.advance();
                v
            })
            .collect();
        assert_eq!(first, again);
    }
    assert_eq!(Sine::new(4500.0, 10_000.0, 1.0), Err(FrfError::Frequency));
    assert_eq!(Sine::new(0.0, 10_000.0, 1.0), Err(FrfError::Frequency));
    assert_eq!(Sine::new(f32::NAN, 10_000.0, 1.0), Err(FrfError::Frequency));
    assert_eq!(Sine::new(10.0, 10_000.0, 0.0), Err(FrfError::Amplitude));
    assert_eq!(
        Sine::new(10.0, 10_000.0, f32::INFINITY),
        Err(FrfError::Amplitude)
    );
}

#[test]
fn a_compensated_f32_sum_keeps_what_an_f64_one_keeps() {
    use gms_core::control::frf::Sum2;
    // 10^6 additions of 0.1 (as f32) and of a value 1e8 times smaller: a plain f32 sum
    // drifts by 0.35 % (50,177 for 50,000), the pair stays within 1e-9 of the f64 sum of the
    // same f32 values.
    let (mut pair, mut plain, mut exact) = (Sum2::ZERO, 0.0f32, 0.0f64);
    for k in 0..1_000_000u32 {
        let x = if k % 2 == 0 { 0.1f32 } else { 1e-9f32 };
        pair.add(x);
        plain += x;
        exact += x as f64;
    }
    assert!((plain as f64 / exact - 1.0).abs() > 1e-3, "{plain} {exact}");
    assert!(
        (pair.value() / exact - 1.0).abs() < 1e-9,
        "{} {exact}",
        pair.value()
    );
}

#[test]
fn a_report_copied_a_part_at_a_time_is_the_report() {
    use gms_core::control::frf::{FrfReport, FrfState, Injection};
    // A report with every field distinct from the default, every channel its own sums (a
    // part copied into the wrong place, or one left out, shows).
    let mut lock = LockIn::new();
    let mut sine = Sine::new(37.0, 20_000.0, 0.3).unwrap();
    let mut k = 0.0f32;
    while lock.groups() < 3 {
        let phase = sine.phase();
        let done = sine.advance();
        k += 1.0;
        lock.add(&[k, 2.0 * k + 1.0, -0.5 * k], phase, done, sine.samples());
    }
    let src = FrfReport {
        state: FrfState::Measuring,
        injection: Some(Injection::Position),
        freq_hz: 37.0001,
        amp: 0.3,
        lock,
        groups: 7,
    };
    let mut dst = FrfReport::default();
    assert_ne!(dst, src);
    for part in 0..FrfReport::PARTS {
        dst.copy_part(&src, part);
    }
    assert_eq!(dst, src);
    // Beyond the parts, nothing.
    let before = dst;
    dst.copy_part(&FrfReport::default(), FrfReport::PARTS);
    assert_eq!(dst, before);
}
