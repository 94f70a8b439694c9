//! `gms-tune identify` and `tune-ff` end to end against the virtual device: the hidden friction
//! found, an older firmware refused, a lost link, an axis that does not move, Ctrl-C.
//!
//! One test at a time (each starts a virtual device, most of them faster than real time);
//! the devices are this binary itself (`serve_child`, `hil_sim::harness`).

use std::io::Write as _;
use std::path::Path;
use std::process::{Child, Command, Stdio};

use crate::support;
use support::*;

/// A device that answers everything but the bench primitives (an older firmware): records
/// the requests it saw.
fn old_firmware() -> (String, std::sync::Arc<std::sync::Mutex<Vec<String>>>) {
    use std::io::Read as _;
    let seen = std::sync::Arc::new(std::sync::Mutex::new(Vec::new()));
    let l = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = l.local_addr().unwrap().to_string();
    let log = seen.clone();
    std::thread::spawn(move || {
        for conn in l.incoming() {
            let Ok(mut c) = conn else { return };
            // Its parameters (no `enc.counts_per_rev`: it predates it), kept across requests.
            let mut params: Vec<(String, String)> = [
                ("motor.k_m", "0.0066"),
                ("rate.pos_hz", "10000"),
                ("lim.i_max", "0.5"),
                ("gms.fs", "0.00022"),
                ("gms.vs", "0.2"),
                ("lim.pos_min", "-50"),
                ("lim.pos_max", "50"),
            ]
            .map(|(k, v)| (k.to_string(), v.to_string()))
            .into();
            let mut buf = Vec::new();
            let mut byte = [0u8; 1];
            while let Ok(1) = c.read(&mut byte) {
                if byte[0] != b'\n' {
                    buf.push(byte[0]);
                    continue;
                }
                // A host's CAN (session start) is not a request.
                let line = String::from_utf8_lossy(&buf)
                    .trim_matches(|c: char| c == '\u{18}' || c.is_whitespace())
                    .to_string();
                buf.clear();
                if line.is_empty() {
                    continue;
                }
                log.lock().unwrap().push(line.clone());
                let w: Vec<&str> = line.split_whitespace().collect();
                let reply = match w.as_slice() {
                    ["get", p] => match params.iter().find(|(k, _)| k == p) {
                        Some((_, v)) => format!("ok {v}"),
                        None => "err 5 unknown parameter (try list)".into(),
                    },
                    ["list"] => {
                        let mut out = String::new();
                        for (k, v) in &params {
                            out.push_str(&format!("{k} {v} - [-1000, 100000]\n"));
                        }
                        out + "ok"
                    }
                    ["set", p, v] => match params.iter_mut().find(|(k, _)| k == p) {
                        Some((_, x)) => {
                            *x = v.to_string();
                            "ok".into()
                        }
                        None => "err 5 unknown parameter (try list)".into(),
                    },
                    ["status"] => "ok mode=gms enabled=0 faults=0 t=1 pos=0 error_counts=0 \
                                   moving=0 current=0 fault_names=none ff=0 duty=0 \
                                   step_us_worst=0 step_us_mean=0 sense_offset=2048 \
                                   missed=0 late=0 duty_max=1 duty_limited=0 supply=12 \
                                   drive=position configured=1"
                        .into(),
                    ["enable"] | ["disable"] => "ok".into(),
                    ["enable", _] => "err 2 too many arguments".into(),
                    _ => "err 1 unknown command".into(),
                };
                if c.write_all(format!("{reply}\n").as_bytes()).is_err() {
                    break;
                }
            }
        }
    });
    (addr, seen)
}

/// `gms-tune identify --no-erase --report rep` on `srv` in `cwd`, running in the background
/// (without the erase the staircase starts at once).
fn spawn_identify(srv: &Server, cwd: &Path) -> Child {
    Command::new(TUNE)
        .args([
            "--tcp",
            &srv.addr,
            "identify",
            "--no-erase",
            "--report",
            "rep",
        ])
        .current_dir(cwd)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

/// `gms-tune identify --apply` against a virtual device 20× faster than real time whose
/// plant has Table 1's friction: the files, the figures, and the set loaded.
#[test]
fn identify_finds_the_hidden_friction_and_applies_it() {
    let _one = support::one_at_a_time();
    let dir = tempfile::tempdir().unwrap();
    let sc = quiet_scenario(dir.path(), "");
    let srv = Server::child("tcp", &dir.path().join("flash.img"), 20.0, Some(&sc));
    // The compensator starts at a wrong model (Fs 30 % high), so --apply visibly changes it.
    assert_eq!(tune(&srv, &["set", "gms.fs", "286e-6"], dir.path()).0, 0);
    let (code, out, err) = tune(
        &srv,
        &["identify", "--out", "id.toml", "--report", "rep", "--apply"],
        dir.path(),
    );
    assert_eq!(code, 0, "{out}\n{err}");
    assert!(err.contains("experiments done in"), "{err}");
    // The identified set in one readable line, in the device's units.
    assert!(
        out.lines()
            .any(|l| l.starts_with("identified: Fs ") && l.contains(" µN·m, Fc ")),
        "{out}"
    );
    for f in [
        "presliding.csv",
        "sliding.csv",
        "lag.csv",
        "report.txt",
        "virgin.svg",
        "stribeck.svg",
        "lag.svg",
    ] {
        assert!(dir.path().join("rep").join(f).exists(), "{f}");
    }
    let pf = gms_ident::paramfile::ParamFile::load(&dir.path().join("id.toml")).unwrap();
    let fs = pf.friction.fs.unwrap();
    let fc = pf.friction.fc.unwrap();
    // Table 1: Fs 220e-6, Fc 125e-6 N·m; the staircase's steps came from the wrong 286e-6.
    assert!((fs / 220e-6 - 1.0).abs() < 0.03, "fs {fs}");
    assert!((fc / 125e-6 - 1.0).abs() < 0.03, "fc {fc}");
    // The device runs the file's set now.
    let (_, got, _) = tune(&srv, &["get", "gms.fs"], dir.path());
    let got: f64 = got.trim().parse().unwrap();
    assert!((got / fs - 1.0).abs() < 1e-6, "device {got} vs file {fs}");
    // The CSVs are what `hil-sim identify` reads: the same fit again gives the same set.
    let rep = dir.path().join("rep");
    let again = gms_ident::identify::identify_from(&gms_ident::identify::Inputs {
        presliding: Some(&rep.join("presliding.csv")),
        sliding: Some(&rep.join("sliding.csv")),
        lag: Some(&rep.join("lag.csv")),
        blocks: 6,
        asymmetric: false,
    })
    .unwrap();
    assert_eq!(again.spec.fs, Some(fs));
    // The bridge is off at the end, the stroke limits are the device's own again.
    let (_, status, _) = tune(&srv, &["send", "status"], dir.path());
    assert!(
        status.contains("enabled=0") && status.contains("faults=0"),
        "{status}"
    );
    assert_eq!(tune(&srv, &["get", "lim.pos_max"], dir.path()).1, "50\n");
}

/// `identify --asymmetric --apply` (or `--save`): the device holds one Stribeck curve for both
/// directions, so the asymmetric fit could not be applied whole: refused as a usage error
/// (exit 2) before anything is sent that changes or moves the device.
#[test]
fn identify_asymmetric_apply_is_refused_before_anything_changes() {
    let _one = support::one_at_a_time();
    for flag in ["--apply", "--save"] {
        let dir = tempfile::tempdir().unwrap();
        let (addr, seen) = old_firmware();
        let (code, out, err) = run(Command::new(TUNE)
            .args([
                "--tcp",
                &addr,
                "identify",
                "--asymmetric",
                flag,
                "--report",
                "rep",
            ])
            .current_dir(dir.path()));
        assert_eq!(code, 2, "{out}\n{err}");
        assert!(
            err.contains("--asymmetric") && err.contains("[friction.negative]"),
            "{err}"
        );
        let seen = seen.lock().unwrap().clone();
        assert!(
            seen.iter().all(|l| l == "status" || l.starts_with("get ")),
            "{seen:?}"
        );
        assert!(!dir.path().join("rep").exists());
    }
}

/// An older firmware without the bench primitives: a clear error, exit 1, the bridge off
/// (`disable` sent), the stroke limits put back, the (empty) data files written.
#[test]
fn identify_refuses_an_older_firmware() {
    let _one = support::one_at_a_time();
    let dir = tempfile::tempdir().unwrap();
    let (addr, seen) = old_firmware();
    let (code, out, err) = run(Command::new(TUNE)
        .args(["--tcp", &addr, "identify", "--report", "rep"])
        .current_dir(dir.path()));
    assert_eq!(code, 1, "{out}\n{err}");
    assert!(
        err.contains("does not know `enable`") && err.contains("predates"),
        "{err}"
    );
    assert!(err.contains("the bridge is off"), "{err}");
    // One line of error after the plan.
    let last = err.trim().lines().last().unwrap_or("");
    assert!(
        last.starts_with("error: ") && last.contains("predates"),
        "{err}"
    );
    let seen = seen.lock().unwrap().clone();
    assert!(seen.iter().any(|l| l == "disable"), "{seen:?}");
    assert!(seen.iter().any(|l| l == "set lim.pos_max 50"), "{seen:?}");
    assert!(dir.path().join("rep/presliding.csv").exists());
}

/// The link lost mid-run (the device gone): exit 1, a clear error, the data so far kept.
#[test]
fn identify_keeps_the_data_when_the_link_is_lost() {
    let _one = support::one_at_a_time();
    let dir = tempfile::tempdir().unwrap();
    let sc = quiet_scenario(dir.path(), "");
    let mut srv = Server::child("tcp", &dir.path().join("flash.img"), 1.0, Some(&sc));
    let child = spawn_identify(&srv, dir.path());
    // Some seconds into the staircase (about 100 steps of some 30 ms each in real time).
    std::thread::sleep(std::time::Duration::from_millis(2500));
    srv.kill();
    let out = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("link:") && err.contains("the data so far"),
        "{err}"
    );
    let kept = std::fs::read_to_string(dir.path().join("rep/presliding.csv")).unwrap();
    assert!(kept.lines().count() > 5, "{kept}");
}

/// An axis that does not move: the motor not connected (no current flows), or blocked
/// (it never breaks away): a clear error, exit 1, the bridge off; the current stops at
/// 60 % of the current limit.
#[test]
fn identify_says_when_the_axis_does_not_move() {
    let _one = support::one_at_a_time();
    for (extra, says) in [
        // An open winding: the device still believes its 10 Ω motor is there.
        (
            "resistance = 1e5\n[controller.motor]\nr = 10.0",
            "no current flows",
        ),
        (
            // Blocked: 100 times the friction the device's compensator (Table 1) expects.
            "[plant.actuator]\nfs = 2.2e-2\nfc = 1.25e-2\n[controller.gms]\nfs = 220e-6\nfc = 125e-6",
            "did not move with current pulses up to 211.6 mA (0.001396 N·m, 60 % of lim.i_max)",
        ),
    ] {
        let dir = tempfile::tempdir().unwrap();
        let sc = quiet_scenario(dir.path(), extra);
        let srv = Server::child("tcp", &dir.path().join("flash.img"), 20.0, Some(&sc));
        let (code, out, err) = tune(&srv, &["identify", "--report", "rep"], dir.path());
        assert_eq!(code, 1, "{extra}: {out}\n{err}");
        assert!(
            err.contains(says) && err.contains("the bridge is off"),
            "{err}"
        );
        let (_, status, _) = tune(&srv, &["send", "status"], dir.path());
        assert!(status.contains("enabled=0"), "{status}");
    }
}

/// An encoder counting against the motor: a clear error, exit 1, the bridge off.
#[test]
fn identify_says_when_the_encoder_is_reversed() {
    let _one = support::one_at_a_time();
    let dir = tempfile::tempdir().unwrap();
    let sc = quiet_scenario(dir.path(), "encoder_reversed = true");
    let srv = Server::child("tcp", &dir.path().join("flash.img"), 20.0, Some(&sc));
    let (code, out, err) = tune(&srv, &["identify", "--report", "rep"], dir.path());
    assert_eq!(code, 1, "{out}\n{err}");
    assert!(err.contains("counts against the motor"), "{err}");
    let (_, status, _) = tune(&srv, &["send", "status"], dir.path());
    assert!(status.contains("enabled=0"), "{status}");
}

/// Ctrl-C (SIGINT) mid-run: exit 1, "interrupted", the bridge off, the stroke limits back,
/// the data so far written.
#[cfg(unix)]
#[test]
fn identify_stops_on_ctrl_c_with_the_bridge_off() {
    let _one = support::one_at_a_time();
    let dir = tempfile::tempdir().unwrap();
    let sc = quiet_scenario(dir.path(), "");
    let srv = Server::child("tcp", &dir.path().join("flash.img"), 1.0, Some(&sc));
    let child = spawn_identify(&srv, dir.path());
    std::thread::sleep(std::time::Duration::from_millis(2000));
    let kill = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(kill.success());
    let out = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("interrupted (Ctrl-C)") && err.contains("the bridge is off"),
        "{err}"
    );
    let kept = std::fs::read_to_string(dir.path().join("rep/presliding.csv")).unwrap();
    assert!(kept.lines().count() > 5, "{kept}");
    let (_, status, _) = tune(&srv, &["send", "status"], dir.path());
    assert!(status.contains("enabled=0"), "{status}");
    assert_eq!(tune(&srv, &["get", "lim.pos_max"], dir.path()).1, "50\n");
}

/// `tune-ff` on a virtual device 20× faster than real time: the curve printed and written, the
/// gain left alone without --apply and set to the choice with it; a bad range refused (exit 2)
/// with nothing changed.
#[test]
fn tune_ff_sweeps_chooses_and_applies_on_request() {
    let _one = support::one_at_a_time();
    let dir = tempfile::tempdir().unwrap();
    let sc = quiet_scenario(dir.path(), "");
    let srv = Server::child("tcp", &dir.path().join("flash.img"), 20.0, Some(&sc));
    let d = dir.path();
    let gain = |srv: &Server| {
        tune(srv, &["get", "ff.gain"], d)
            .1
            .trim()
            .parse::<f64>()
            .unwrap()
    };
    let before = gain(&srv);
    let (code, out, err) = tune(&srv, &["tune-ff", "--steps", "5", "--out", "tf"], d);
    assert_eq!(code, 0, "{out}\n{err}");
    // The time up front; a line per test (5 coarse, 9 × 2 around the optimum) with the gain
    // to 3 decimals and the error in counts; the optimum with its interval.
    assert!(
        err.contains("23 tests, about") && err.contains("s of device time"),
        "{err}"
    );
    let tests: Vec<&str> = out
        .lines()
        .filter(|l| {
            let w: Vec<&str> = l.split_whitespace().collect();
            w.len() == 3 && w[0].parse::<usize>().is_ok() && w[1].len() == 5
        })
        .collect();
    assert_eq!(tests.len(), 23, "{out}");
    let (chosen, half): (f64, f64) = out
        .lines()
        .find_map(|l| {
            let r = l.strip_prefix("ff.gain ")?;
            let w: Vec<&str> = r.split_whitespace().collect();
            Some((w[0].parse().ok()?, w[2].parse().ok()?))
        })
        .unwrap_or_else(|| panic!("{out}"));
    assert!(
        (0.5..=1.3).contains(&chosen) && half < 0.05,
        "{chosen} ± {half}"
    );
    assert!(d.join("tf/curve.csv").exists() && d.join("tf/curve.svg").exists());
    assert_eq!(gain(&srv), before);
    // --json: the raw values for scripts.
    let (code, out, err) = tune(
        &srv,
        &["tune-ff", "--steps", "5", "--out", "tf", "--json"],
        d,
    );
    assert_eq!(code, 0, "{err}");
    let j: serde_json::Value =
        serde_json::from_str(out.trim()).unwrap_or_else(|e| panic!("{e}: {out}"));
    assert_eq!(j["decided"], true);
    assert!(j["curve"].as_array().unwrap().len() >= 23);
    assert!((j["optimum"].as_f64().unwrap() - chosen).abs() < 0.1, "{j}");
    let (code, out, err) = tune(
        &srv,
        &["tune-ff", "--steps", "5", "--out", "tf", "--apply"],
        d,
    );
    assert_eq!(code, 0, "{out}\n{err}");
    let chosen: f64 = out
        .lines()
        .find_map(|l| l.strip_prefix("set ff.gain "))
        .and_then(|v| v.trim().parse().ok())
        .unwrap_or_else(|| panic!("{out}"));
    assert!(
        (gain(&srv) - chosen).abs() < 1e-4,
        "{} vs {chosen}",
        gain(&srv)
    );
    let (code, _, err) = tune(&srv, &["tune-ff", "--from", "1.5", "--to", "1.0"], d);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("0 <= from < to <= 2"), "{err}");
}
