//! Identification round trip: the paper's experiments simulated on a known friction, then
//! identified back (hil-sim's experiment and identify, as the CLI runs them).

use hil_sim::experiment::{Kind, Setup, run};
use hil_sim::identify::identify;
use hil_sim::paramfile::{FrictionSpec, ParamFile};

fn example(name: &str) -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../examples")
        .join(name)
}

/// The quasi-static virgin curve of a GMS table at x.
fn virgin(spec: &FrictionSpec, fs: f64, x: f64) -> f64 {
    spec.blocks
        .iter()
        .flatten()
        .map(|b| (b.k * x).min(b.alpha * fs))
        .sum()
}

/// RMS difference of two virgin curves over [0, xmax], relative to Fs.
fn virgin_rms(a: &FrictionSpec, b: &FrictionSpec, xmax: f64) -> f64 {
    let (fa, fb) = (a.fs.unwrap(), b.fs.unwrap());
    let n = 400;
    let s: f64 = (1..=n)
        .map(|i| {
            let x = xmax * i as f64 / n as f64;
            (virgin(a, fa, x) - virgin(b, fb, x)).powi(2)
        })
        .sum();
    (s / n as f64).sqrt() / fa
}

fn round_trip(file: &str, kinds: &[Kind], seed: u64) -> (FrictionSpec, FrictionSpec) {
    let truth = ParamFile::load(&example(file)).unwrap().friction;
    let dir = tempfile::tempdir().unwrap();
    let mut paths = Vec::new();
    for (i, k) in kinds.iter().enumerate() {
        let text = run(*k, &truth, &Setup::paper(*k, &truth, 0.0), seed + i as u64).unwrap();
        let p = dir.path().join(format!("{i}.csv"));
        std::fs::write(&p, text).unwrap();
        paths.push(p);
    }
    let (pre, slide) = match kinds {
        [Kind::Sliding] => (None, Some(paths[0].as_path())),
        [_, Kind::Sliding] => (Some(paths[0].as_path()), Some(paths[1].as_path())),
        _ => (Some(paths[0].as_path()), None),
    };
    let id = identify(pre, slide, 6).unwrap();
    (truth, id.spec)
}

#[test]
fn table1_is_identified_back_within_the_issue_tolerances() {
    for seed in [1, 2, 3] {
        let (t, id) = round_trip("table1.toml", &[Kind::Presliding, Kind::Sliding], seed);
        let rel = |a: Option<f64>, b: Option<f64>| (a.unwrap() / b.unwrap() - 1.0).abs();
        eprintln!("seed {seed}: identified {id:?}");
        assert!(rel(id.fs, t.fs) < 0.03, "fs {:?}", id.fs);
        assert!(rel(id.fc, t.fc) < 0.03, "fc {:?}", id.fc);
        assert!(rel(id.vs, t.vs) < 0.10, "vs {:?}", id.vs);
        assert!(rel(id.delta, t.delta) < 0.10, "delta {:?}", id.delta);
        assert!(rel(id.sigma, t.sigma) < 0.10, "sigma {:?}", id.sigma);
        let r = virgin_rms(&t, &id, 8e-3);
        eprintln!("seed {seed}: virgin curve RMS {:.3} % of Fs", 100.0 * r);
        assert!(r < 0.02, "virgin curve RMS {:.3} % of Fs", 100.0 * r);
        // The file is accepted as it is.
        assert!(id.build().is_ok());
    }
}

#[test]
fn the_guideway_presliding_is_identified_back() {
    for seed in [1, 2] {
        let (t, id) = round_trip("guideway.toml", &[Kind::Guideway], seed);
        let fs_rel = (id.fs.unwrap() / t.fs.unwrap() - 1.0).abs();
        let r = virgin_rms(&t, &id, 45e-6);
        eprintln!(
            "guideway seed {seed}: Fs {:.4} N, virgin RMS {:.3} % of Fs",
            id.fs.unwrap(),
            100.0 * r
        );
        assert!(fs_rel < 0.03, "Fs {:?}", id.fs);
        assert!(r < 0.02, "virgin curve RMS {:.3} % of Fs", 100.0 * r);
    }
}

/// `--asymmetric`: a friction with its own negative branch is identified per direction.
#[test]
fn the_direction_asymmetry_is_identified_per_direction() {
    let mut truth = ParamFile::load(&example("table1.toml")).unwrap().friction;
    truth.negative = Some(hil_sim::paramfile::NegativeSpec {
        fs: Some(250e-6),
        fc: Some(140e-6),
        vs: None,
        delta: None,
    });
    let dir = tempfile::tempdir().unwrap();
    let mut paths = Vec::new();
    for (i, k) in [Kind::Presliding, Kind::Sliding].iter().enumerate() {
        let text = run(*k, &truth, &Setup::paper(*k, &truth, 0.0), 7 + i as u64).unwrap();
        let p = dir.path().join(format!("{i}.csv"));
        std::fs::write(&p, text).unwrap();
        paths.push(p);
    }
    let id = hil_sim::identify::identify_with(Some(&paths[0]), Some(&paths[1]), 6, true).unwrap();
    let n = id.spec.negative.unwrap();
    assert!((n.fs.unwrap() / 250e-6 - 1.0).abs() < 0.03, "{n:?}");
    assert!((n.fc.unwrap() / 140e-6 - 1.0).abs() < 0.03, "{n:?}");
    assert!((id.spec.fs.unwrap() / 220e-6 - 1.0).abs() < 0.03);
    assert!((id.spec.fc.unwrap() / 125e-6 - 1.0).abs() < 0.03);
    assert!(id.spec.build().is_ok());
}
