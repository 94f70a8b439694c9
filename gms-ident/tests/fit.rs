//! The identification fits recover known parameters from exact and noisy synthetic data.

use gms_core::friction::presets;
use gms_ident::identify::{fit_stribeck, fit_virgin};

/// Deterministic noise in [-1, 1).
fn noise(i: usize) -> f64 {
    let x = ((i as u64)
        .wrapping_mul(6364136223846793005)
        .wrapping_add(1442695040888963407)
        >> 33) as f64;
    x / (1u64 << 30) as f64 - 1.0
}

#[test]
fn virgin_fit_recovers_table1() {
    let p = presets::table1();
    let fs = p.stribeck.fs as f64;
    let virgin = |x: f64| -> f64 {
        p.blocks
            .iter()
            .map(|b| (b.k as f64 * x).min(b.alpha as f64 * fs))
            .sum()
    };
    // Encoder-resolution steps, log-spaced out to 1.5x the last breakpoint, 1 % noise.
    let xs: Vec<f64> = (0..200)
        .map(|i| 3.8e-6 * (12e-3 / 3.8e-6f64).powf(i as f64 / 199.0))
        .collect();
    let fsn: Vec<f64> = xs
        .iter()
        .enumerate()
        .map(|(i, &x)| virgin(x) + 0.01 * fs * noise(i))
        .collect();
    let fit = fit_virgin(&xs, &fsn, 6).unwrap();
    eprintln!(
        "virgin fit: Fs {:.4e}, breakpoints {:?}",
        fit.fs, fit.breakpoints
    );
    assert!((fit.fs / fs - 1.0).abs() < 0.02, "Fs {} vs {fs}", fit.fs);
    // The fitted curve within 2 % of Fs RMS of the true one over the data.
    let model = |x: f64| -> f64 {
        fit.blocks
            .iter()
            .zip(&fit.breakpoints)
            .map(|(b, d)| b.k * x.min(*d))
            .sum()
    };
    let rms = (xs
        .iter()
        .map(|&x| (model(x) - virgin(x)).powi(2))
        .sum::<f64>()
        / xs.len() as f64)
        .sqrt();
    eprintln!("virgin curve RMS {:.3} % of Fs", 100.0 * rms / fs);
    assert!(
        rms < 0.02 * fs,
        "virgin curve RMS {:.3} % of Fs",
        100.0 * rms / fs
    );
    let asum: f64 = fit.blocks.iter().map(|b| b.alpha).sum();
    assert!((asum - 1.0).abs() < 1e-9);
    assert!(fit.blocks.iter().all(|b| b.k > 0.0 && b.alpha > 0.0));
}

#[test]
fn virgin_fit_rejects_bad_data() {
    let xs: Vec<f64> = (1..40).map(|i| i as f64 * 1e-6).collect();
    let mut f: Vec<f64> = xs.iter().map(|x| (x * 1e5).min(1.0)).collect();
    assert!(
        fit_virgin(&xs[..5], &f[..5], 6)
            .unwrap_err()
            .to_string()
            .contains("too few")
    );
    f[20] = f64::NAN;
    let e = fit_virgin(&xs, &f, 3).unwrap_err();
    // A data error, with its one-line reason.
    assert!(
        matches!(&e, gms_ident::Error::Data(m) if m.contains("non-finite")),
        "{e:?}"
    );
    let falling: Vec<f64> = xs.iter().map(|x| 1.0 - x * 1e4).collect();
    assert!(
        fit_virgin(&xs, &falling, 3)
            .unwrap_err()
            .to_string()
            .contains("not monotonic")
    );
    let mut back = xs.clone();
    back.swap(3, 4);
    let f: Vec<f64> = xs.iter().map(|x| (x * 1e5).min(1.0)).collect();
    assert!(
        fit_virgin(&back, &f, 3)
            .unwrap_err()
            .to_string()
            .contains("increase")
    );
}

#[test]
fn a_stribeck_fit_whose_viscous_term_would_be_negative_is_held_at_zero() {
    // A curve with no viscous term (fs 3, fc 2, vs 1, delta 1) whose two fastest points read
    // 2 % low: unconstrained, least squares would take a negative sigma to follow them down.
    let s = |v: f64| 2e-3 + 1e-3 * (-v).exp();
    let v: Vec<f64> = (0..20)
        .map(|i| 2e-2 * 300f64.powf(i as f64 / 19.0))
        .collect();
    let f: Vec<f64> = v
        .iter()
        .enumerate()
        .map(|(i, &v)| s(v) * if i >= 18 { 0.98 } else { 1.0 })
        .collect();
    let fit = fit_stribeck(&v, &f).unwrap();
    eprintln!("held fit: {fit:?}");
    assert_eq!(fit.sigma, 0.0);
    assert!((fit.fs / 3e-3 - 1.0).abs() < 0.03, "fs {}", fit.fs);
    assert!((fit.fc / 2e-3 - 1.0).abs() < 0.03, "fc {}", fit.fc);
    let se = fit.std_err.unwrap();
    assert!(se[..4].iter().all(|e| e.is_finite() && *e > 0.0) && se[4] == 0.0);
}

#[test]
fn stribeck_fit_recovers_table1_within_the_issue_tolerances() {
    let p = presets::table1();
    let (fs, fc, vs, d, sg) = (
        p.stribeck.fs as f64,
        p.stribeck.fc as f64,
        p.stribeck.vs as f64,
        p.stribeck.delta as f64,
        p.sigma as f64,
    );
    let s = |v: f64| fc + (fs - fc) * (-(v / vs).powf(d)).exp() + sg * v;
    // Log-spaced 0.002 .. 20 rad/s, 0.5 % noise.
    let v: Vec<f64> = (0..40)
        .map(|i| 2e-3 * 1e4f64.powf(i as f64 / 39.0))
        .collect();
    let f: Vec<f64> = v
        .iter()
        .enumerate()
        .map(|(i, &v)| s(v) * (1.0 + 0.005 * noise(i + 7)))
        .collect();
    let fit = fit_stribeck(&v, &f).unwrap();
    eprintln!("stribeck fit: {fit:?}");
    assert!((fit.fs / fs - 1.0).abs() < 0.03, "fs {}", fit.fs);
    assert!((fit.fc / fc - 1.0).abs() < 0.03, "fc {}", fit.fc);
    assert!((fit.vs / vs - 1.0).abs() < 0.10, "vs {}", fit.vs);
    assert!((fit.delta / d - 1.0).abs() < 0.10, "delta {}", fit.delta);
    assert!((fit.sigma / sg - 1.0).abs() < 0.10, "sigma {}", fit.sigma);
    let se = fit.std_err.unwrap();
    assert!(se.iter().all(|e| e.is_finite() && *e > 0.0));
    // Bad data: no speed above Vs.
    let slow: Vec<f64> = (0..20).map(|i| 1e-3 * (1.0 + i as f64 * 0.5)).collect();
    let fslow: Vec<f64> = slow.iter().map(|&v| s(v)).collect();
    assert!(fit_stribeck(&slow, &fslow).is_err());
    assert!(
        fit_stribeck(&v[..5], &f[..5])
            .unwrap_err()
            .to_string()
            .contains("too few")
    );
}

/// The identification on arrays and on the same numbers in CSV files (the other reader) give
/// the same set; bad arrays get a one-line error naming the data.
#[test]
fn identification_on_arrays_is_the_files_identification() {
    use gms_ident::identify::{Data, Inputs, Table, identify_data, identify_from};
    let p = presets::table1();
    let (fs, fc, vs) = (
        p.stribeck.fs as f64,
        p.stribeck.fc as f64,
        p.stribeck.vs as f64,
    );
    let virgin = |x: f64| -> f64 {
        p.blocks
            .iter()
            .map(|b| (b.k as f64 * x).min(b.alpha as f64 * fs))
            .sum()
    };
    let xs: Vec<f64> = (1..120).map(|i| 3.8e-6 * 1.06f64.powi(i)).collect();
    let fx: Vec<f64> = xs
        .iter()
        .enumerate()
        .map(|(i, &x)| virgin(x) * (1.0 + 0.005 * noise(i)))
        .collect();
    let dir = vec![1.0; xs.len()];
    let v: Vec<f64> = (0..30).map(|i| 0.01 * 1.25f64.powi(i)).collect();
    let fv: Vec<f64> = v
        .iter()
        .enumerate()
        .map(|(i, &v)| {
            (fc + (fs - fc) * (-(v / vs).powi(2)).exp() + 1e-5 * v) * (1.0 + 0.005 * noise(i + 7))
        })
        .collect();
    let dirp = tempfile::tempdir().unwrap();
    let (pre_p, slide_p) = (dirp.path().join("pre.csv"), dirp.path().join("slide.csv"));
    let mut text = String::from("x,f,dir\n");
    for i in 0..xs.len() {
        text += &format!("{},{},{}\n", xs[i], fx[i], dir[i]);
    }
    std::fs::write(&pre_p, text).unwrap();
    let mut text = String::from("v,f\n");
    for i in 0..v.len() {
        text += &format!("{},{}\n", v[i], fv[i]);
    }
    std::fs::write(&slide_p, text).unwrap();
    let from_files = identify_from(&Inputs {
        presliding: Some(&pre_p),
        sliding: Some(&slide_p),
        lag: None,
        blocks: 6,
        asymmetric: false,
    })
    .unwrap();
    let pre = Table {
        name: "pre-sliding".into(),
        cols: vec![xs.clone(), fx.clone(), dir],
    };
    let slide = Table {
        name: "sliding".into(),
        cols: vec![v, fv],
    };
    let data = Data {
        presliding: Some(&pre),
        sliding: Some(&slide),
        lag: None,
        blocks: 6,
        asymmetric: false,
    };
    let from_arrays = identify_data(&data).unwrap();
    assert_eq!(from_arrays.spec, from_files.spec);
    assert!((from_arrays.spec.fs.unwrap() / fs - 1.0).abs() < 0.02);
    // A non-finite value, or columns of different lengths: refused, naming the data.
    let bad = Table {
        name: "pre-sliding".into(),
        cols: vec![xs.clone(), vec![f64::NAN; xs.len()]],
    };
    let e = match identify_data(&Data {
        presliding: Some(&bad),
        ..data
    }) {
        Err(e) => e.to_string(),
        Ok(_) => panic!("a NaN was fitted"),
    };
    assert!(e.starts_with("pre-sliding: non-finite"), "{e}");
    let short = Table {
        name: "pre-sliding".into(),
        cols: vec![xs, fx[..10].to_vec()],
    };
    let e = match identify_data(&Data {
        presliding: Some(&short),
        ..data
    }) {
        Err(e) => e.to_string(),
        Ok(_) => panic!("columns of different lengths were fitted"),
    };
    assert!(e.contains("different lengths"), "{e}");
}
