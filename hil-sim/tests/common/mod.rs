//! Shared by the end-to-end tests: running a command for its exit code and output, and a
//! running `hil-sim serve`, killed on drop. (Each test binary uses a part of it.)
#![allow(dead_code)]

use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Child, Command, Stdio};

/// The default plant with its friction exactly nominal (no draw) and the guideway negligible:
/// a bench sees the actuator's Table 1 friction alone, and the device compensates it alone
/// (its default guideway model off).
pub const QUIET: &str = "[plant]
variability = 0.0

[plant.guideway]
fs = 1e-6
fc = 1e-6

[controller.ff]
guideway = false
";

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

/// Runs `cmd` to its end; returns (exit code, stdout, stderr).
pub fn run(cmd: &mut Command) -> (i32, String, String) {
    let out = cmd.output().expect("the command runs");
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// Runs `hil-sim ARGS…` in `cwd`; returns (exit code, stdout, stderr).
pub fn hil(args: &[&str], cwd: &Path) -> (i32, String, String) {
    run(Command::new(env!("CARGO_BIN_EXE_hil-sim"))
        .args(args)
        .current_dir(cwd))
}

/// A running `hil-sim serve`.
pub struct Server {
    child: Child,
    /// What it listens on: a TCP address or a PTY path.
    pub addr: String,
}

impl Server {
    /// Starts `hil-sim serve ENDPOINT… --store STORE` (`["--tcp", "127.0.0.1:0"]` or
    /// `["--pty"]`) and waits for the address it prints.
    pub fn start(endpoint: &[&str], store: &Path) -> Server {
        let mut child = Command::new(env!("CARGO_BIN_EXE_hil-sim"))
            .arg("serve")
            .args(endpoint)
            .arg("--store")
            .arg(store)
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        let mut line = String::new();
        BufReader::new(child.stdout.take().unwrap())
            .read_line(&mut line)
            .unwrap();
        let addr = line
            .trim()
            .strip_prefix("listening on ")
            .unwrap()
            .to_string();
        Server { child, addr }
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}
