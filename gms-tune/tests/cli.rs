//! `gms-tune`'s plain commands end to end against the virtual device over TCP and over a
//! pseudo-terminal: set, save, restart, dump and load; record and step tests; send and watch;
//! clear errors for no device; the Python-facing library's capture.
//!
//! One test at a time (each starts a virtual device, most of them faster than real time);
//! the devices are this binary itself (`serve_child`, `hil_sim::harness`).

use gms_core::protocol::ParamId;
use std::path::Path;
use std::process::Command;

use crate::support;
use support::*;

#[test]
fn set_save_restart_dump_and_load() {
    let _one = support::one_at_a_time();
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let store = d.join("flash.toml");
    {
        let srv = Server::child("tcp", &store, 1.0, None);
        assert_eq!(tune(&srv, &["set", "pos.kd", "2.2e-4"], d).0, 0);
        assert_eq!(tune(&srv, &["set", "ff.gain", "0.9"], d).0, 0);
        let (code, _, err) = tune(&srv, &["set", "ff.gain", "-1"], d);
        assert_eq!(code, 1);
        assert!(err.starts_with("error: device answered: err 6"), "{err}");
        assert_eq!(err.lines().count(), 1);
        assert_eq!(tune(&srv, &["save"], d).0, 0);
    }
    let srv = Server::child("tcp", &store, 1.0, None);
    assert_eq!(tune(&srv, &["get", "pos.kd"], d).1, "0.00022\n");
    assert_eq!(tune(&srv, &["get", "ff.gain"], d).1, "0.9\n");
    let (code, list, _) = tune(&srv, &["list"], d);
    assert_eq!(code, 0);
    assert!(list.lines().count() >= 36 && list.contains("gms.k6"));
    // dump → a parameter file the friction command accepts as it is.
    let (code, dump, _) = tune(&srv, &["params", "dump"], d);
    assert_eq!(code, 0);
    std::fs::write(d.join("p.toml"), &dump).unwrap();
    // `hil-sim friction`'s own code.
    let traj = Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/trajectory.csv");
    let fr = hil_sim::friction_cmd::run(&d.join("p.toml"), &traj, &d.join("o.csv"));
    assert!(fr.is_ok(), "{fr:?}");
    // Change things, load the dump back, and read the old values.
    assert_eq!(tune(&srv, &["set", "gms.fs", "300e-6"], d).0, 0);
    assert_eq!(tune(&srv, &["set", "pos.kd", "1e-4"], d).0, 0);
    assert_eq!(tune(&srv, &["params", "load", "p.toml"], d).0, 0);
    assert_eq!(tune(&srv, &["get", "gms.fs"], d).1, "0.00022\n");
    assert_eq!(tune(&srv, &["get", "pos.kd"], d).1, "0.00022\n");
}

#[test]
fn record_and_step_test_write_their_files() {
    let _one = support::one_at_a_time();
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let srv = Server::child("tcp", &d.join("flash.toml"), 1.0, None);
    let (code, _, err) = tune(
        &srv,
        &[
            "record",
            "--fields",
            "t,error",
            "--seconds",
            "0.2",
            "--rate",
            "500",
            "--out",
            "r.csv",
        ],
        d,
    );
    assert_eq!(code, 0, "{err}");
    let rec = std::fs::read_to_string(d.join("r.csv")).unwrap();
    assert_eq!(rec.lines().next(), Some("t,error"));
    // 0.2 s at 500 Hz: about 100 samples (fewer if the machine is loaded), never closer
    // than 2 ms in device time, and mostly exactly 2 ms apart.
    let t: Vec<f64> = rec
        .lines()
        .skip(1)
        .map(|l| l.split(',').next().unwrap().parse().unwrap())
        .collect();
    assert!(t.len() >= 30 && t.len() <= 110, "{} samples", t.len());
    let gaps: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).collect();
    assert!(gaps.iter().all(|g| *g > 2e-3 - 2e-4), "{gaps:?}");
    let exact = gaps.iter().filter(|g| (**g - 2e-3).abs() < 2e-4).count();
    assert!(exact * 10 >= gaps.len() * 8, "{gaps:?}");
    let (code, out, err) = tune(
        &srv,
        &[
            "step-test",
            "--distance",
            "1e-3",
            "--seconds",
            "0.3",
            "--out",
            "st",
        ],
        d,
    );
    assert_eq!(code, 0, "{err}");
    // Readable: the step in mrad and counts, only the figures that apply to a step.
    assert!(out.starts_with("step 1.000 mrad (263 counts)"), "{out}");
    for k in [
        "settle time ",
        "steady-state error ",
        "largest error ",
        "hunting ",
    ] {
        assert!(out.lines().any(|l| l.starts_with(k)), "{k} missing: {out}");
    }
    assert!(!out.contains("sine") && !out.contains("reversal"), "{out}");
    assert!(d.join("st/trace.csv").exists() && d.join("st/plot.svg").exists());
    assert!(d.join("st/metrics.json").exists());
    // The axis followed: the last recorded position is within a few counts of the target.
    let trace = std::fs::read_to_string(d.join("st/trace.csv")).unwrap();
    let last: Vec<f64> = trace
        .lines()
        .last()
        .unwrap()
        .split(',')
        .map(|v| v.parse().unwrap())
        .collect();
    assert!(
        (last[1] - last[2]).abs() < 10.0 * 3.8e-6,
        "ref {} pos {}",
        last[1],
        last[2]
    );
}

#[test]
fn send_and_watch() {
    let _one = support::one_at_a_time();
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let srv = Server::child("tcp", &d.join("flash.toml"), 1.0, None);
    assert_eq!(tune(&srv, &["send", "enable"], d).0, 0);
    assert_eq!(tune(&srv, &["send", "move", "-0.002"], d).0, 0);
    let (code, status, _) = tune(&srv, &["send", "status"], d);
    assert_eq!(code, 0);
    assert!(status.contains("enabled=1"), "{status}");
    let (code, out, err) = tune(
        &srv,
        &["watch", "--seconds", "0.5", "--refresh-ms", "100"],
        d,
    );
    assert_eq!(code, 0, "{err}");
    assert!(out.starts_with("  t [s]"), "{out}");
    // Refreshes: carriage return + clear line, at least three in 0.5 s.
    assert!(out.matches("\r\x1b[K").count() >= 3, "{out:?}");
    let (code, _, err) = tune(&srv, &["send", "frobnicate"], d);
    assert_eq!(code, 1);
    assert!(err.contains("err 1"), "{err}");
}

#[test]
fn clear_errors_for_no_device_and_silence() {
    let _one = support::one_at_a_time();
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let out = Command::new(TUNE)
        .args(["--port", "/dev/does-not-exist", "get", "pos.kp"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(
        err.contains("/dev/does-not-exist") && err.lines().count() == 1,
        "{err}"
    );
    // A device that never answers: a timeout, exit 1. The silent device accepts and reads
    // everything (a connection left in the backlog depends on the host's state), and the
    // tool's wait is long against a loaded host's scheduling but still a timeout.
    let silent = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = silent.local_addr().unwrap().to_string();
    std::thread::spawn(move || {
        use std::io::Read;
        if let Ok((mut c, _)) = silent.accept() {
            let mut buf = [0u8; 256];
            while matches!(c.read(&mut buf), Ok(n) if n > 0) {}
        }
    });
    let out = Command::new(TUNE)
        .args(["--tcp", &addr, "--timeout-ms", "500", "get", "pos.kp"])
        .current_dir(d)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("timeout: no reply within 500 ms") && err.lines().count() == 1,
        "{err}"
    );
}

/// The same over a pseudo-terminal (`hil-sim serve --pty`), as the tool talks to the USB
/// CDC-ACM port of the firmware.
#[cfg(unix)]
#[test]
fn over_a_pty_set_save_restart_and_survive_a_dropped_client() {
    let _one = support::one_at_a_time();
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let store = d.join("flash.toml");
    let start = || Server::child("pty", &store, 1.0, None);
    let tune = |srv: &Server, args: &[&str]| {
        let (code, out, _) = tune_on(srv, "--port", args, d);
        (code, out)
    };
    {
        let srv = start();
        assert_eq!(tune(&srv, &["set", "pos.kp", "0.27"]), (0, String::new()));
        // A client that writes half a line and goes away.
        {
            use std::io::Write;
            let mut f = std::fs::OpenOptions::new()
                .write(true)
                .open(&srv.addr)
                .unwrap();
            f.write_all(b"set pos.k").unwrap();
        }
        // gms-tune starts with an empty line, which ends the half line (answered with an
        // error it skips); its own request is then answered normally.
        assert_eq!(tune(&srv, &["get", "pos.kp"]), (0, "0.27\n".into()));
        assert_eq!(tune(&srv, &["save"]).0, 0);
    }
    let srv = start();
    assert_eq!(tune(&srv, &["get", "pos.kp"]), (0, "0.27\n".into()));
}

/// The bench client (`gms_tune::Link` as a `gms_bench::Bench`) arms a capture, starts a velocity run and
/// reads every sample back, on a virtual device four times faster than real time.
#[test]
fn the_library_captures_a_velocity_run() {
    let _one = support::one_at_a_time();
    use std::time::Duration;
    let dir = tempfile::tempdir().unwrap();
    let srv = Server::child("tcp", &dir.path().join("flash.img"), 4.0, None);
    use gms_bench::{capture_rows, capture_status, capture_wait};
    let mut link = gms_tune::Link::tcp(&srv.addr, Duration::from_secs(2)).unwrap();
    link.console("enable").unwrap();
    link.console("capture t,pos,current 1 2000 next").unwrap();
    assert_eq!(
        capture_status(&mut link).unwrap().state,
        gms_core::device::CaptureState::Armed
    );
    link.console("velocity 0.3").unwrap();
    let st = capture_wait(&mut link, 0.02, 500).unwrap();
    assert_eq!((st.samples, st.capacity), (2000, 8192));
    let rows = capture_rows(&mut link).unwrap();
    assert_eq!(rows.len(), 2000);
    // Every position step: 50 µs at the default 20 kHz.
    let dt = 1.0 / gms_bench::get_param(&mut link, ParamId::RatePosHz).unwrap();
    for (k, r) in rows.iter().enumerate() {
        assert_eq!(r.len(), 3);
        assert!((r[0] - k as f64 * dt).abs() < 1e-7, "row {k}: {r:?}");
    }
    // After the 6 ms ramp the axis follows 0.3 rad/s.
    let speed = (rows[1999][1] - rows[1000][1]) / (999.0 * dt);
    assert!((speed - 0.3).abs() < 0.03, "speed {speed}");
    link.console("hold").unwrap();
    // A second read of the same capture gives the same data.
    assert_eq!(capture_rows(&mut link).unwrap(), rows);
}

/// `step-test` on the default virtual device (20× real time): a 1 mrad step settles in under
/// 0.2 s, and the trace agrees — after the printed settle time the recorded error stays within
/// the printed band but for excursions under 2 ms; no hunting. With the feedforward off and
/// an integral gain 20× the default the axis oscillates about the target: "hunting yes" (5×,
/// 3000, settles in 16 ms; 10× in 66 ms).
/// `status` prints a table and `--json` the raw figures.
#[test]
fn step_test_settles_and_tells_hunting_from_dither() {
    let _one = support::one_at_a_time();
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let srv = Server::child("tcp", &d.join("flash.img"), 20.0, None);
    let (code, out, err) = tune(&srv, &["step-test", "--distance", "1e-3", "--out", "st"], d);
    assert_eq!(code, 0, "{err}");
    let field = |line: &str, after: &str| -> f64 {
        out.lines()
            .find_map(|l| l.strip_prefix(line))
            .and_then(|r| r.split(after).nth(1))
            .and_then(|r| r.split_whitespace().next())
            .and_then(|v| v.trim_start_matches('±').parse().ok())
            .unwrap_or_else(|| panic!("{line}: {out}"))
    };
    let settle_ms: f64 = out
        .lines()
        .find_map(|l| l.strip_prefix("settle time"))
        .and_then(|r| r.split_whitespace().next())
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("{out}"));
    let band = field("settle time", "band ") * 3.8e-6;
    assert!(settle_ms < 200.0, "{out}");
    assert!(out.contains("hunting            none"), "{out}");
    // The trace: the reference at rest from some row on; from the settle time after that,
    // every excursion beyond the band shorter than 2 ms.
    let rows: Vec<Vec<f64>> = std::fs::read_to_string(d.join("st/trace.csv"))
        .unwrap()
        .lines()
        .skip(1)
        .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
        .collect();
    let target = rows.last().unwrap()[1];
    let rest = rows
        .iter()
        .position(|r| (r[1] - target).abs() < 1e-12)
        .unwrap();
    let t_settled = rows[rest][0] + settle_ms * 1e-3;
    let mut excursion_start: Option<f64> = None;
    for r in rows.iter().filter(|r| r[0] >= t_settled) {
        if r[3].abs() > band {
            let s = *excursion_start.get_or_insert(r[0]);
            assert!(r[0] - s < 2e-3, "out of the band from {s} to {} s", r[0]);
        } else {
            excursion_start = None;
        }
    }
    // --json: the raw figures.
    let (code, out, _) = tune(
        &srv,
        &["step-test", "--distance", "-1e-3", "--out", "st", "--json"],
        d,
    );
    assert_eq!(code, 0);
    let j: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert!(j["settle_time"].as_f64().unwrap() < 0.2 && j["settle_band"].as_f64().unwrap() > 0.0);
    // status as a table, and as JSON.
    let (code, out, _) = tune(&srv, &["status"], d);
    assert_eq!(code, 0);
    assert!(
        out.lines()
            .any(|l| l.starts_with("enabled") && l.contains("bridge on")),
        "{out}"
    );
    let (_, out, _) = tune(&srv, &["status", "--json"], d);
    let j: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(j["enabled"], 1.0);
    // A genuine limit cycle.
    for (p, v) in [("ff.mode", "none"), ("pos.ki", "12000")] {
        assert_eq!(tune(&srv, &["set", p, v], d).0, 0);
    }
    let (code, out, err) = tune(&srv, &["step-test", "--distance", "1e-3", "--out", "st"], d);
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("hunting            yes"), "{out}");
}
