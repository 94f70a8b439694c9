//! The end-to-end tests' harness, shared by hil-sim's tests and gms-tune's: a virtual device
//! in a process of its own (killed on drop, so that a test can stop one and start another on
//! the same store), a command run to its end, and time limits sized in device time.
//!
//! A test binary that cannot name the `hil-sim` binary (another crate's tests) serves from
//! itself: [`Server::child`] starts the binary again with [`SERVE_CHILD`] set in its
//! environment, and the binary's `serve_child` test (see [`serve_child`]) then runs
//! [`crate::device::serve`] and prints `listening on ADDR`, as `hil-sim serve` does.

use std::io::{BufRead, BufReader, Write as _};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// The environment variable that makes a test binary's `serve_child` test a server: the
/// endpoint (`tcp` or `pty`), the store, the speed and optionally a scenario file, separated
/// by tabs.
pub const SERVE_CHILD: &str = "GMS_SERVE_CHILD";

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

/// A running virtual device (a child process), killed on drop.
pub struct Server {
    child: Child,
    /// What it listens on: a TCP address or a PTY path.
    pub addr: String,
    /// How much faster than the wall clock it was asked to run (its `--speed`).
    pub speed: f64,
}

impl Server {
    /// Starts `cmd`, which prints `listening on ADDR` on its standard output before it
    /// serves (lines before it are skipped), and waits for that line. `speed` is the device's
    /// `--speed`, for [`Server::wall`].
    pub fn spawn(cmd: &mut Command, speed: f64) -> Server {
        let mut child = cmd
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .expect("the server starts");
        let mut out = BufReader::new(child.stdout.take().expect("its standard output"));
        let mut line = String::new();
        let addr = loop {
            line.clear();
            let n = out.read_line(&mut line).unwrap_or(0);
            if n == 0 {
                let _ = child.kill();
                panic!("the server ended before it listened");
            }
            // (A test binary's harness may have begun the line: `test serve_child ... `.)
            if let Some((_, a)) = line.trim().split_once("listening on ") {
                break a.to_string();
            }
        };
        // Whatever it prints after is read and dropped (a full pipe would block it).
        std::thread::spawn(move || {
            let mut sink = String::new();
            while out.read_line(&mut sink).is_ok_and(|n| n > 0) {
                sink.clear();
            }
        });
        Server { child, addr, speed }
    }

    /// The running test binary started again as a server (its `serve_child` test, with
    /// [`SERVE_CHILD`] set): `kind` `tcp` or `pty`, the store `store`, `speed` times faster
    /// than the wall clock, on the default scenario or `scenario`.
    pub fn child(kind: &str, store: &Path, speed: f64, scenario: Option<&Path>) -> Server {
        let spec = [
            kind.to_string(),
            store.display().to_string(),
            speed.to_string(),
            scenario
                .map(|p| p.display().to_string())
                .unwrap_or_default(),
        ]
        .join("\t");
        Server::spawn(
            Command::new(std::env::current_exe().expect("the test binary"))
                .args(["serve_child", "--exact", "--ignored", "--nocapture"])
                .args(["--test-threads", "1"])
                .env(SERVE_CHILD, spec),
            speed,
        )
    }

    /// Stops it (as a power cut: the store keeps what was written).
    pub fn kill(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }

    /// Wall time \[s\] to allow for `device_s` seconds of device time: at the speed asked
    /// for, with room for a machine [`SLOWER`] times slower than this one (the device slows
    /// its clock when the host cannot keep up), and `extra` seconds of the host's own work.
    pub fn wall(&self, device_s: f64, extra: f64) -> f64 {
        wall(device_s, self.speed, extra)
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// How much slower than the machine the tests were written on a machine may be (a loaded CI
/// runner) before a time limit fails a test.
pub const SLOWER: f64 = 4.0;

/// Wall time \[s\] for `device_s` seconds of device time on a device asked to run `speed`
/// times faster than the wall clock, with room for a machine [`SLOWER`] times slower, plus
/// `extra` seconds (also stretched) of host work.
pub fn wall(device_s: f64, speed: f64, extra: f64) -> f64 {
    SLOWER * (device_s / speed + extra)
}

/// The server side of [`Server::child`], for a test binary's `serve_child` test: with
/// [`SERVE_CHILD`] set, serves (never returns); without it (the test run as an ordinary
/// ignored test), returns at once.
pub fn serve_child() {
    let Ok(spec) = std::env::var(SERVE_CHILD) else {
        return;
    };
    let f: Vec<&str> = spec.split('\t').collect();
    let (kind, store, speed, scenario) = match f.as_slice() {
        [k, s, v, sc] => (*k, *s, v.parse::<f64>().expect("a speed"), *sc),
        _ => panic!("{SERVE_CHILD}={spec:?}: endpoint, store, speed, scenario"),
    };
    use crate::device::{Endpoint, serve};
    let endpoint = match kind {
        "tcp" => Endpoint::Tcp(std::net::TcpListener::bind("127.0.0.1:0").expect("a port")),
        #[cfg(unix)]
        "pty" => Endpoint::Pty,
        _ => panic!("unknown endpoint {kind}"),
    };
    let sc = if scenario.is_empty() {
        crate::scenario::Scenario::default()
    } else {
        crate::scenario::Scenario::load(Path::new(scenario)).expect("the scenario")
    };
    let r = serve(sc, endpoint, Some(store.into()), speed, |addr, _| {
        println!("listening on {addr}");
        let _ = std::io::stdout().flush();
    });
    panic!("serve ended: {r:?}");
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

/// Waits until `done` holds, looking every 20 ms, for at most `seconds` of wall time; true if
/// it came.
pub fn wait_for(seconds: f64, mut done: impl FnMut() -> bool) -> bool {
    let end = Instant::now() + Duration::from_secs_f64(seconds);
    loop {
        if done() {
            return true;
        }
        if Instant::now() >= end {
            return false;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}
