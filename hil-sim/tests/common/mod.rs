//! Shared by hil-sim's tests: `hil-sim` run for its exit code and output, a running `hil-sim
//! serve` (the workspace's one harness, `hil_sim::harness`), the identification's errors.
//! (Each test binary uses a part of it.)
#![allow(dead_code, unused_imports)]

use std::path::Path;
use std::process::Command;

pub use hil_sim::harness::{QUIET, Server, run};

/// Runs `sc` in the simulator with the GMS feedforward (seed 3) and without (seed 4) and
/// checks each run's energy ledger closes: electrical input = copper + magnetic + the
/// mechanical terms within 1 %, with input and friction work both positive. Returns the two
/// ledgers for the caller's own checks.
pub fn energy_balance_closes(sc: &hil_sim::scenario::Scenario) -> Vec<hil_sim::plant::Energy> {
    use gms_core::control::controller::FfMode;
    [(FfMode::Gms, 3), (FfMode::None, 4)]
        .into_iter()
        .map(|(mode, seed)| {
            let e = hil_sim::sim::run(sc, mode, seed).unwrap().energy;
            let out = e.copper + e.magnetic + e.mechanical();
            assert!(e.input > 0.0 && e.friction > 0.0, "{e:?}");
            assert!((e.input - out).abs() < 0.01 * e.input, "{e:?}");
            e
        })
        .collect()
}

/// The errors of an identified friction `found` against the truth: the relative errors of
/// Fs, Fc, Vs, delta, sigma and C, and the virgin curves' RMS difference (uniform in x over
/// the pre-sliding range `g` measured) as a fraction of the true Fs.
pub fn identification_errors(
    truth: &gms_ident::paramfile::FrictionSpec,
    g: &gms_bench::Gathered,
    found: &gms_ident::paramfile::FrictionSpec,
) -> [f64; 7] {
    let rel = |got: Option<f64>, want: Option<f64>| {
        let want = want.unwrap();
        (got.unwrap() - want).abs() / want
    };
    let xmax = g.presliding.iter().map(|p| p.0).fold(0.0, f64::max);
    let n = 400;
    let rms = ((1..=n)
        .map(|i| {
            let x = xmax * i as f64 / n as f64;
            (found.virgin(x) - truth.virgin(x)).powi(2)
        })
        .sum::<f64>()
        / n as f64)
        .sqrt();
    [
        rel(found.fs, truth.fs),
        rel(found.fc, truth.fc),
        rel(found.vs, truth.vs),
        rel(found.delta, truth.delta),
        rel(found.sigma, truth.sigma),
        rel(found.c, truth.c),
        rms / truth.fs.unwrap(),
    ]
}

/// Runs `hil-sim ARGS…` in `cwd`; returns (exit code, stdout, stderr).
pub fn hil(args: &[&str], cwd: &Path) -> (i32, String, String) {
    run(Command::new(env!("CARGO_BIN_EXE_hil-sim"))
        .args(args)
        .current_dir(cwd))
}

/// Starts `hil-sim serve ENDPOINT… --store STORE` (`["--tcp", "127.0.0.1:0"]` or
/// `["--pty"]`, and any other options) and waits for the address it prints.
pub fn serve(args: &[&str], store: &Path) -> Server {
    let speed = args
        .iter()
        .position(|a| *a == "--speed")
        .and_then(|i| args.get(i + 1)?.parse().ok())
        .unwrap_or(1.0);
    Server::spawn(
        Command::new(env!("CARGO_BIN_EXE_hil-sim"))
            .arg("serve")
            .args(args)
            .arg("--store")
            .arg(store),
        speed,
    )
}
