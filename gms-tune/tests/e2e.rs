//! `gms-tune` end to end against the virtual device (`hil-sim`'s device core on the simulated
//! plant) over TCP and over a pseudo-terminal.
//!
//! A custom harness (`harness = false`): the servers are this test binary itself, started
//! with `--serve-child tcp|pty STORE`, in which case it runs `hil_sim::device::serve` and
//! prints `listening on ADDR` (as `hil-sim serve` does), so that a test can stop one (kill)
//! and start another on the same store. Without that argument it runs the tests in turn
//! (`cargo test -p gms-tune --test e2e -- NAME` runs those whose name contains NAME).

use std::io::{BufRead, BufReader, Write as _};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};

const TUNE: &str = env!("CARGO_BIN_EXE_gms-tune");

/// A running virtual device (a child process of this binary), killed on drop.
struct Server {
    child: Child,
    /// What it listens on: a TCP address or a PTY path.
    addr: String,
}

impl Server {
    /// `kind` is `tcp` or `pty`.
    fn start(kind: &str, store: &Path) -> Server {
        Server::start_at(kind, store, 1.0)
    }

    /// The same, the simulated axis running `speed` times faster than the wall clock.
    fn start_at(kind: &str, store: &Path, speed: f64) -> Server {
        Server::start_with(kind, store, speed, None)
    }

    /// The same on the plant of a scenario file.
    fn start_with(kind: &str, store: &Path, speed: f64, scenario: Option<&Path>) -> Server {
        let mut child = Command::new(std::env::current_exe().unwrap())
            .args(["--serve-child", kind])
            .arg(store)
            .arg(speed.to_string())
            .args(scenario)
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
            .unwrap_or_else(|| panic!("server said {line:?}"))
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

/// The server side: `hil-sim serve` on the default scenario (or `scenario`), on TCP
/// 127.0.0.1:0 or a PTY.
fn serve_child(kind: &str, store: PathBuf, speed: f64, scenario: Option<&str>) {
    use hil_sim::device::{Endpoint, serve};
    let endpoint = match kind {
        "tcp" => Endpoint::Tcp(std::net::TcpListener::bind("127.0.0.1:0").unwrap()),
        #[cfg(unix)]
        "pty" => Endpoint::Pty,
        _ => panic!("unknown endpoint {kind}"),
    };
    let sc = match scenario {
        Some(p) => hil_sim::scenario::Scenario::load(Path::new(p)).unwrap(),
        None => hil_sim::scenario::Scenario::default(),
    };
    let r = serve(sc, endpoint, Some(store), speed, |addr, _| {
        println!("listening on {addr}");
        let _ = std::io::stdout().flush();
    });
    panic!("serve ended: {r:?}");
}

/// Runs `cmd` to its end; returns (exit code, stdout, stderr).
fn run(cmd: &mut Command) -> (i32, String, String) {
    let out = cmd.output().expect("the command runs");
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// Runs gms-tune on `link` (`--tcp` or `--port`) to `srv`; returns (exit code, stdout,
/// stderr).
fn tune_on(srv: &Server, link: &str, args: &[&str], cwd: &Path) -> (i32, String, String) {
    run(Command::new(TUNE)
        .args([link, &srv.addr])
        .args(args)
        .current_dir(cwd))
}

/// gms-tune over TCP.
fn tune(srv: &Server, args: &[&str], cwd: &Path) -> (i32, String, String) {
    tune_on(srv, "--tcp", args, cwd)
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if args.get(1).map(String::as_str) == Some("--serve-child") {
        serve_child(
            &args[2],
            PathBuf::from(&args[3]),
            args[4].parse().unwrap(),
            args.get(5).map(String::as_str),
        );
        return;
    }
    let tests: &[(&str, fn())] = &[
        (
            "set_save_restart_dump_and_load",
            set_save_restart_dump_and_load,
        ),
        (
            "record_and_step_test_write_their_files",
            record_and_step_test_write_their_files,
        ),
        ("send_and_watch", send_and_watch),
        (
            "learn_writes_its_files_applies_and_refuses_bad_input",
            learn_writes_its_files_applies_and_refuses_bad_input,
        ),
        (
            "the_window_shows_the_learning_and_applies_it",
            the_window_shows_the_learning_and_applies_it,
        ),
        (
            "step_test_settles_and_tells_hunting_from_dither",
            step_test_settles_and_tells_hunting_from_dither,
        ),
        (
            "the_library_captures_a_velocity_run",
            the_library_captures_a_velocity_run,
        ),
        (
            "clear_errors_for_no_device_and_silence",
            clear_errors_for_no_device_and_silence,
        ),
        (
            "identify_finds_the_hidden_friction_and_applies_it",
            identify_finds_the_hidden_friction_and_applies_it,
        ),
        (
            "identify_refuses_an_older_firmware",
            identify_refuses_an_older_firmware,
        ),
        (
            "identify_asymmetric_apply_is_refused_before_anything_changes",
            identify_asymmetric_apply_is_refused_before_anything_changes,
        ),
        (
            "identify_keeps_the_data_when_the_link_is_lost",
            identify_keeps_the_data_when_the_link_is_lost,
        ),
        (
            "commission_measures_a_hidden_motor_and_applies_it",
            commission_measures_a_hidden_motor_and_applies_it,
        ),
        (
            "tune_ff_sweeps_chooses_and_applies_on_request",
            tune_ff_sweeps_chooses_and_applies_on_request,
        ),
        (
            "commission_finds_random_hidden_motors",
            commission_finds_random_hidden_motors,
        ),
        (
            "commission_with_the_link_lost_applies_nothing",
            commission_with_the_link_lost_applies_nothing,
        ),
        (
            "the_window_shows_the_device_and_sets_what_it_is_told",
            the_window_shows_the_device_and_sets_what_it_is_told,
        ),
        ("the_window_shows_a_lost_link", the_window_shows_a_lost_link),
        (
            "the_window_exports_dumps_and_steps",
            the_window_exports_dumps_and_steps,
        ),
        (
            "the_window_runs_tune_ff_and_applies_it",
            the_window_runs_tune_ff_and_applies_it,
        ),
        (
            "the_window_stops_a_run_with_the_bridge_off",
            the_window_stops_a_run_with_the_bridge_off,
        ),
        (
            "frf_writes_its_files_suggests_and_applies_a_notch",
            frf_writes_its_files_suggests_and_applies_a_notch,
        ),
        ("frf_refuses_bad_input", frf_refuses_bad_input),
        (
            "the_window_measures_a_frequency_response",
            the_window_measures_a_frequency_response,
        ),
        (
            "the_window_measures_and_applies_a_position_map",
            the_window_measures_and_applies_a_position_map,
        ),
        #[cfg(unix)]
        (
            "identify_stops_on_ctrl_c_with_the_bridge_off",
            identify_stops_on_ctrl_c_with_the_bridge_off,
        ),
        (
            "identify_says_when_the_axis_does_not_move",
            identify_says_when_the_axis_does_not_move,
        ),
        (
            "identify_says_when_the_encoder_is_reversed",
            identify_says_when_the_encoder_is_reversed,
        ),
        #[cfg(unix)]
        (
            "over_a_pty_set_save_restart_and_survive_a_dropped_client",
            over_a_pty_set_save_restart_and_survive_a_dropped_client,
        ),
    ];
    let filter = args.iter().skip(1).find(|a| !a.starts_with('-'));
    let mut n = 0;
    for (name, f) in tests {
        if filter.is_some_and(|p| !name.contains(p.as_str())) {
            continue;
        }
        println!("test {name} ...");
        f();
        println!("test {name} ... ok");
        n += 1;
    }
    println!("{n} end-to-end tests passed");
}

fn set_save_restart_dump_and_load() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let store = d.join("flash.toml");
    {
        let srv = Server::start("tcp", &store);
        assert_eq!(tune(&srv, &["set", "pos.kd", "2.2e-4"], d).0, 0);
        assert_eq!(tune(&srv, &["set", "ff.gain", "0.9"], d).0, 0);
        let (code, _, err) = tune(&srv, &["set", "ff.gain", "-1"], d);
        assert_eq!(code, 1);
        assert!(err.starts_with("error: device answered: err 6"), "{err}");
        assert_eq!(err.lines().count(), 1);
        assert_eq!(tune(&srv, &["save"], d).0, 0);
    }
    let srv = Server::start("tcp", &store);
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

fn record_and_step_test_write_their_files() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let srv = Server::start("tcp", &d.join("flash.toml"));
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

fn send_and_watch() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let srv = Server::start("tcp", &d.join("flash.toml"));
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

fn clear_errors_for_no_device_and_silence() {
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
fn over_a_pty_set_save_restart_and_survive_a_dropped_client() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let store = d.join("flash.toml");
    let start = || Server::start("pty", &store);
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
fn the_library_captures_a_velocity_run() {
    use std::time::Duration;
    let dir = tempfile::tempdir().unwrap();
    let srv = Server::start_at("tcp", &dir.path().join("flash.img"), 4.0);
    use gms_bench::{capture_rows, capture_status, capture_wait};
    let mut link = gms_tune::Link::tcp(&srv.addr, Duration::from_secs(2)).unwrap();
    link.request("enable").unwrap();
    link.request("capture t,pos,current 1 2000 next").unwrap();
    assert_eq!(capture_status(&mut link).unwrap().state, "armed");
    link.request("velocity 0.3").unwrap();
    let st = capture_wait(&mut link, 0.02, 500).unwrap();
    assert_eq!((st.samples, st.capacity), (2000, 8192));
    let rows = capture_rows(&mut link).unwrap();
    assert_eq!(rows.len(), 2000);
    // Every position step: 50 µs at the default 20 kHz.
    let dt = 1.0 / gms_bench::get_param(&mut link, "rate.pos_hz").unwrap();
    for (k, r) in rows.iter().enumerate() {
        assert_eq!(r.len(), 3);
        assert!((r[0] - k as f64 * dt).abs() < 1e-7, "row {k}: {r:?}");
    }
    // After the 6 ms ramp the axis follows 0.3 rad/s.
    let speed = (rows[1999][1] - rows[1000][1]) / (999.0 * dt);
    assert!((speed - 0.3).abs() < 0.03, "speed {speed}");
    link.request("hold").unwrap();
    // A second read of the same capture gives the same data.
    assert_eq!(capture_rows(&mut link).unwrap(), rows);
}

/// The default plant with its friction exactly nominal (no draw) and the guideway negligible:
/// the device sees the actuator's Table 1 friction alone (`extra` appended to the file).
fn quiet_scenario(dir: &Path, extra: &str) -> PathBuf {
    let p = dir.join("scenario.toml");
    std::fs::write(
        &p,
        // The device compensates the actuator alone (its default guideway model off), in
        // the extra's [controller.ff] table when it has one.
        if extra.contains("[controller.ff]\n") {
            format!(
                "[plant]\nvariability = 0.0\n{}\n[plant.guideway]\nfs = 1e-6\nfc = 1e-6\n",
                extra.replacen(
                    "[controller.ff]\n",
                    "[controller.ff]\nguideway = false\n",
                    1
                )
            )
        } else {
            format!(
                "[plant]\nvariability = 0.0\n{extra}\n[plant.guideway]\nfs = 1e-6\nfc = 1e-6\n\
                 [controller.ff]\nguideway = false\n"
            )
        },
    )
    .unwrap();
    p
}

/// `gms-tune identify --apply` against a virtual device 20× faster than real time whose
/// plant has Table 1's friction: the files, the figures, and the set loaded.
fn identify_finds_the_hidden_friction_and_applies_it() {
    let dir = tempfile::tempdir().unwrap();
    let sc = quiet_scenario(dir.path(), "");
    let srv = Server::start_with("tcp", &dir.path().join("flash.img"), 20.0, Some(&sc));
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
                let line = String::from_utf8_lossy(&buf).trim().to_string();
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
                                   missed=0 drive=position configured=1"
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

/// `identify --asymmetric --apply` (or `--save`): the device holds one Stribeck curve for both
/// directions, so the asymmetric fit could not be applied whole: refused as a usage error
/// (exit 2) before anything is sent that changes or moves the device.
fn identify_asymmetric_apply_is_refused_before_anything_changes() {
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
fn identify_refuses_an_older_firmware() {
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

/// The link lost mid-run (the device gone): exit 1, a clear error, the data so far kept.
fn identify_keeps_the_data_when_the_link_is_lost() {
    let dir = tempfile::tempdir().unwrap();
    let sc = quiet_scenario(dir.path(), "");
    let mut srv = Server::start_with("tcp", &dir.path().join("flash.img"), 1.0, Some(&sc));
    let child = spawn_identify(&srv, dir.path());
    // Some seconds into the staircase (about 100 steps of some 30 ms each in real time).
    std::thread::sleep(std::time::Duration::from_millis(2500));
    let _ = srv.child.kill();
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
fn identify_says_when_the_axis_does_not_move() {
    for (extra, says) in [
        // An open winding: the device still believes its 10 Ω motor is there.
        (
            "resistance = 1e5\n[controller.motor]\nr = 10.0",
            "no current flows",
        ),
        (
            // Blocked: 100 times the friction the device's compensator (Table 1) expects.
            "[plant.actuator]\nfs = 2.2e-2\nfc = 1.25e-2\n[controller.gms]\nfs = 220e-6\nfc = 125e-6",
            "did not move with current pulses up to 264.5 mA (0.001746 N·m, 60 % of lim.i_max)",
        ),
    ] {
        let dir = tempfile::tempdir().unwrap();
        let sc = quiet_scenario(dir.path(), extra);
        let srv = Server::start_with("tcp", &dir.path().join("flash.img"), 20.0, Some(&sc));
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
fn identify_says_when_the_encoder_is_reversed() {
    let dir = tempfile::tempdir().unwrap();
    let sc = quiet_scenario(dir.path(), "encoder_reversed = true");
    let srv = Server::start_with("tcp", &dir.path().join("flash.img"), 20.0, Some(&sc));
    let (code, out, err) = tune(&srv, &["identify", "--report", "rep"], dir.path());
    assert_eq!(code, 1, "{out}\n{err}");
    assert!(err.contains("counts against the motor"), "{err}");
    let (_, status, _) = tune(&srv, &["send", "status"], dir.path());
    assert!(status.contains("enabled=0"), "{status}");
}

/// Ctrl-C (SIGINT) mid-run: exit 1, "interrupted", the bridge off, the stroke limits back,
/// the data so far written.
#[cfg(unix)]
fn identify_stops_on_ctrl_c_with_the_bridge_off() {
    let dir = tempfile::tempdir().unwrap();
    let sc = quiet_scenario(dir.path(), "");
    let srv = Server::start_with("tcp", &dir.path().join("flash.img"), 1.0, Some(&sc));
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
fn tune_ff_sweeps_chooses_and_applies_on_request() {
    let dir = tempfile::tempdir().unwrap();
    let sc = quiet_scenario(dir.path(), "");
    let srv = Server::start_with("tcp", &dir.path().join("flash.img"), 20.0, Some(&sc));
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

/// `commission --apply` on a virtual device 10× faster than real time whose motor the device
/// does not know (R 7.5 Ω, k 8 mN·m/A) and whose encoder and sense are both wired the other
/// way: found, written, applied; a blocked axis: exit 1, nothing changed.
fn commission_measures_a_hidden_motor_and_applies_it() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let sc = quiet_scenario(
        d,
        "resistance = 7.5\nk_m = 8e-3\nk_e = 8e-3\nencoder_reversed = true\nsense_reversed = true\n\
         [controller.motor]\nr = 10.0\nk_m = 6.6e-3\nk_e = 6.6e-3",
    );
    let srv = Server::start_with("tcp", &d.join("flash.img"), 10.0, Some(&sc));
    let (code, out, err) = tune(&srv, &["commission", "--out", "m.toml", "--apply"], d);
    assert_eq!(code, 0, "{out}\n{err}");
    assert!(out.contains("reversed; enc.dir flipped"), "{out}");
    assert!(out.contains("current sense: reversed"), "{out}");
    let get = |p: &str| tune(&srv, &["get", p], d).1.trim().parse::<f64>().unwrap();
    assert_eq!((get("enc.dir"), get("sense.dir")), (-1.0, -1.0));
    assert!(
        (get("motor.r") / 7.5 - 1.0).abs() < 0.05,
        "{}",
        get("motor.r")
    );
    assert!(
        (get("motor.k_e") / 8e-3 - 1.0).abs() < 0.05,
        "{}",
        get("motor.k_e")
    );
    let text = std::fs::read_to_string(d.join("m.toml")).unwrap();
    assert!(text.contains("\"enc.dir\" = -1.0"), "{text}");
    // The file loads back (`params load`) as it is.
    assert_eq!(tune(&srv, &["params", "load", "m.toml"], d).0, 0);
    // Readable: measurements with prefixes (R 7.5 Ω, k_e 8 mV·s/rad, L in µH).
    assert!(
        out.contains("winding resistance: 7.") && out.contains(" Ω ("),
        "{out}"
    );
    assert!(out.contains(" mV·s/rad") && out.contains(" µH "), "{out}");
    // --json: the settings found, raw.
    let (code, out, err) = tune(&srv, &["commission", "--out", "m2.toml", "--json"], d);
    assert_eq!(code, 0, "{err}");
    let j: serde_json::Value =
        serde_json::from_str(out.trim()).unwrap_or_else(|e| panic!("{e}: {out}"));
    assert!(
        (j["settings"]["motor.r"].as_f64().unwrap() / 7.5 - 1.0).abs() < 0.05,
        "{j}"
    );
    drop(srv);
    let dir2 = tempfile::tempdir().unwrap();
    let d2 = dir2.path();
    let sc = quiet_scenario(
        d2,
        "[plant.actuator]\nfs = 2.2e-2\nfc = 1.25e-2\n[controller.gms]\nfs = 220e-6\nfc = 125e-6",
    );
    let srv = Server::start_with("tcp", &d2.join("flash.img"), 10.0, Some(&sc));
    let (code, _, err) = tune(&srv, &["commission", "--out", "m.toml", "--apply"], d2);
    assert_eq!(code, 1, "{err}");
    assert!(
        err.contains("did not move") && err.contains("nothing changed"),
        "{err}"
    );
    assert!(!d2.join("m.toml").exists());
    let (_, status, _) = tune(&srv, &["send", "status"], d2);
    assert!(status.contains("enabled=0"), "{status}");
}

/// A property over motors the tool is not told (proptest, a fixed seed, five cases): R 5-20
/// ohm, k 4-10 mN·m/A, J 3-12e-8 kg·m², L/R 12-60 µs (a faster winding settles within the
/// 50 µs current period and shows too little of its L), either wiring reversed or not, each
/// behind `hil-sim serve --speed 10`: `gms-tune commission --out m.toml` finds R and k_e
/// within 5 %, J within 15 %, L within 20 % (the issue's bounds) and both directions.
fn commission_finds_random_hidden_motors() {
    use proptest::test_runner::{Config, RngSeed, TestRunner};
    let mut runner = TestRunner::new(Config {
        cases: 5,
        failure_persistence: None,
        rng_seed: RngSeed::Fixed(18),
        ..Config::default()
    });
    let motor = (
        5.0f64..20.0,
        4e-3f64..10e-3,
        3e-8f64..12e-8,
        12e-6f64..60e-6,
        proptest::bool::ANY,
        proptest::bool::ANY,
    );
    runner
        .run(&motor, |(r, k, j, tau, enc, sense)| {
            let l = r * tau;
            let dir = tempfile::tempdir().unwrap();
            let d = dir.path();
            let sc = quiet_scenario(
                d,
                &format!(
                    "resistance = {r}\nk_m = {k}\nk_e = {k}\ninertia = {j}\ninductance = {l}\n\
                     encoder_reversed = {enc}\nsense_reversed = {sense}\n\
                     [controller.motor]\nr = 10.0\nk_m = 6.6e-3\nk_e = 6.6e-3\n\
                     [controller.ff]\ninertia = 6e-8\n\
                     [controller.cur]\nkp = 1.5\nki = 6e4"
                ),
            );
            let srv = Server::start_with("tcp", &d.join("flash.img"), 10.0, Some(&sc));
            let (code, out, err) = tune(&srv, &["commission", "--out", "m.toml"], d);
            assert_eq!(code, 0, "{out}\n{err}");
            let text = std::fs::read_to_string(d.join("m.toml")).unwrap();
            let table: toml::Table = text.parse().unwrap();
            let dev = table["device"].as_table().unwrap();
            let got = |p: &str| dev[p].as_float().unwrap();
            let rel = |a: f64, b: f64| (a / b - 1.0).abs();
            eprintln!(
                "R {r:.3} -> {:+.2} %, k {k:.3e} -> {:+.2} %, J {j:.3e} -> {:+.2} %, L {l:.3e} -> \
                 {:+.2} %, enc {enc} sense {sense}",
                (got("motor.r") / r - 1.0) * 100.0,
                (got("motor.k_e") / k - 1.0) * 100.0,
                (got("ff.inertia") / j - 1.0) * 100.0,
                (got("cur.kp") / (2.0 * std::f64::consts::PI * 1000.0 * l) - 1.0) * 100.0,
            );
            assert!(rel(got("motor.r"), r) < 0.05, "{text}");
            assert!(rel(got("motor.k_e"), k) < 0.05, "{text}");
            assert!(rel(got("ff.inertia"), j) < 0.15, "{text}");
            // cur.kp = 2π 1 kHz L.
            assert!(
                rel(got("cur.kp"), 2.0 * std::f64::consts::PI * 1000.0 * l) < 0.20,
                "{text}"
            );
            let sign = |rev: bool| if rev { -1.0 } else { 1.0 };
            assert_eq!(got("enc.dir"), sign(enc), "{text}");
            assert_eq!(got("sense.dir"), sign(sense), "{text}");
            Ok(())
        })
        .unwrap();
}

/// The link lost mid-commissioning (the device gone): exit 1, a one-line error about the link,
/// no motor file written, nothing applied.
fn commission_with_the_link_lost_applies_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let sc = quiet_scenario(d, "");
    let mut srv = Server::start_with("tcp", &d.join("flash.img"), 1.0, Some(&sc));
    let child = Command::new(TUNE)
        .args([
            "--tcp",
            &srv.addr,
            "commission",
            "--out",
            "m.toml",
            "--apply",
        ])
        .current_dir(d)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // About a second in: past the sense and direction steps.
    std::thread::sleep(std::time::Duration::from_millis(1200));
    let _ = srv.child.kill();
    let out = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    let last = err.trim().lines().last().unwrap_or("");
    assert!(
        last.starts_with("error: ") && last.contains("link"),
        "{err}"
    );
    assert!(!d.join("m.toml").exists());
}

/// The window (`gms_tune::ui::App`, its real widgets driven by egui_kittest without a
/// display) on `srv` over TCP, the harness tall enough to lay out the whole parameter tree.
fn window(srv: &Server) -> egui_kittest::Harness<'static, gms_tune::ui::App> {
    window_on(srv, Vec::new())
}

/// The same, the request lines `first` sent once the link is up.
fn window_on(
    srv: &Server,
    first: Vec<String>,
) -> egui_kittest::Harness<'static, gms_tune::ui::App> {
    let app = gms_tune::ui::App::new(
        gms_tune::ui::Endpoint::Tcp(srv.addr.clone()),
        std::time::Duration::from_secs(2),
        first,
        &egui::Context::default(),
    );
    egui_kittest::Harness::builder()
        .with_size(egui::vec2(1400.0, 3200.0))
        .build_ui_state(|ui, app: &mut gms_tune::ui::App| app.show(ui), app)
}

/// Steps the window (a frame each 20 ms) until `done` holds, at most `seconds`.
fn step_until(
    h: &mut egui_kittest::Harness<'static, gms_tune::ui::App>,
    seconds: f64,
    done: impl Fn(&gms_tune::ui::App) -> bool,
) -> bool {
    let end = std::time::Instant::now() + std::time::Duration::from_secs_f64(seconds);
    while std::time::Instant::now() < end {
        h.step();
        if done(h.state()) {
            return true;
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    false
}

/// Types `text` into the parameter field `path` and presses Enter (a set).
fn type_param(h: &mut egui_kittest::Harness<'static, gms_tune::ui::App>, path: &str, text: &str) {
    replace_text(h, path, text);
    h.key_press(egui::Key::Enter);
    h.step();
}

/// Replaces the text of the field labelled `label` with `text`.
fn replace_text(
    h: &mut egui_kittest::Harness<'static, gms_tune::ui::App>,
    label: &str,
    text: &str,
) {
    use egui_kittest::kittest::Queryable;
    h.get_by_label(label).click();
    h.step();
    h.key_press_modifiers(egui::Modifiers::COMMAND, egui::Key::A);
    h.step();
    h.get_by_label(label).type_text(text);
    h.step();
}

/// Against `hil-sim serve`: the window lists every parameter path with its unit; the
/// telemetry's values change over time; Enable and Disable switch the bridge; a set typed in
/// the window changes the device (read back with `get` once the window is closed); a refused
/// set shows the device's error beside the field and the field shows the device's value again.
fn the_window_shows_the_device_and_sets_what_it_is_told() {
    use egui_kittest::kittest::Queryable;
    use gms_core::protocol::PARAMS;
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let srv = Server::start("tcp", &d.join("flash.img"));
    let mut h = window(&srv);
    assert!(step_until(&mut h, 10.0, |a| a.rows.len() >= PARAMS.len()
        && a.samples.len() > 100));
    for p in PARAMS {
        // The field (labelled by its path) and its unit beside it.
        let field = h.get_by_label(p.path);
        assert!(field.value().is_some(), "{}", p.path);
        assert!(
            h.query_all_by_label(p.unit).count() > 0,
            "{} {}",
            p.path,
            p.unit
        );
    }
    // Live values: the time and the received count go on.
    let (t0, n0) = (h.state().samples.back().unwrap().t, h.state().received);
    assert!(step_until(&mut h, 5.0, |a| a.samples.back().unwrap().t > t0 + 0.5));
    let n1 = h.state().received;
    assert!(n1 > n0 + 300, "{n0} -> {n1}");
    assert!(h.query_by_label_contains("samples received").is_some());
    // Enable, then Disable: the status says so, and the window shows it.
    h.get_by_label("Enable").click();
    assert!(step_until(&mut h, 5.0, |a| a.bridge_on()));
    h.step();
    assert!(h.query_by_label("bridge on").is_some());
    h.get_by_label("Disable").click();
    assert!(step_until(&mut h, 5.0, |a| !a.bridge_on()));
    h.step();
    assert!(h.query_by_label("bridge off").is_some());
    // A set the device takes.
    type_param(&mut h, "pos.kd", "2.2e-4");
    let row = |a: &gms_tune::ui::App, p: &str| a.rows.iter().find(|r| r.listed.path == p).cloned();
    assert!(step_until(&mut h, 5.0, |a| row(a, "pos.kd")
        .unwrap()
        .listed
        .value
        == "0.00022"));
    // A set it refuses (out of range): the error beside the field, the field back at the default 0.7.
    type_param(&mut h, "pos.kp", "5000");
    assert!(step_until(&mut h, 5.0, |a| row(a, "pos.kp")
        .unwrap()
        .error
        .is_some()));
    h.step();
    let r = row(h.state(), "pos.kp").unwrap();
    assert!(
        r.error.as_deref().unwrap().contains("err 6"),
        "{:?}",
        r.error
    );
    assert_eq!(r.edit, "0.7");
    // Beside the field, and in the log below.
    assert_eq!(h.query_all_by_label_contains("err 6").count(), 2);
    assert_eq!(h.get_by_label("pos.kp").value().as_deref(), Some("0.7"));
    // The window closed, the device read back by another client.
    drop(h);
    assert_eq!(tune(&srv, &["get", "pos.kd"], d).1.trim(), "0.00022");
    assert_eq!(tune(&srv, &["get", "pos.kp"], d).1.trim(), "0.7");
}

/// The device gone: the window says the link is lost (and keeps drawing).
fn the_window_shows_a_lost_link() {
    use egui_kittest::kittest::Queryable;
    let dir = tempfile::tempdir().unwrap();
    let mut srv = Server::start("tcp", &dir.path().join("flash.img"));
    let mut h = window(&srv);
    assert!(step_until(&mut h, 10.0, |a| a.link == gms_tune::ui::app::LinkState::Up));
    let _ = srv.child.kill();
    let _ = srv.child.wait();
    assert!(step_until(&mut h, 10.0, |a| matches!(
        a.link,
        gms_tune::ui::app::LinkState::Lost(_)
    )));
    h.step();
    // In the top bar, and in the log below.
    assert!(h.query_all_by_label_contains("link lost").count() >= 2);
    // The window goes on drawing frames while the worker retries.
    for _ in 0..10 {
        h.step();
    }
}

/// The window's Experiments page: tune-ff typed in and started with its button on a virtual
/// device 10 × real time; the sweep's points arrive as it runs; the device's gain stays until
/// "Apply the gain", then it is the chosen one (read back with `get` once the window is
/// closed).
fn the_window_runs_tune_ff_and_applies_it() {
    use egui_kittest::kittest::Queryable;
    use gms_tune::ui::worker::Outcome;
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let sc = quiet_scenario(d, "");
    let srv = Server::start_with("tcp", &d.join("flash.img"), 10.0, Some(&sc));
    let mut h = window(&srv);
    assert!(step_until(&mut h, 10.0, |a| !a.rows.is_empty()));
    h.state_mut().tab = gms_tune::ui::app::Tab::Experiments;
    h.step();
    for (label, v) in [("steps", "5"), ("seconds", "2")] {
        replace_text(&mut h, label, v);
    }
    h.get_by_label("Tune ff").click();
    h.step();
    assert!(h.state().running.is_some());
    let done = step_until(&mut h, 90.0, |a| a.outcome.is_some());
    assert!(done, "{:?} {:?}", h.state().running, h.state().log);
    let (chosen, before, points) = match h.state().outcome.clone().unwrap() {
        Ok(Outcome::TunedFf(t)) => (t.chosen, t.before, t.curve.len()),
        other => panic!("{other:?}"),
    };
    // 5 coarse tests, then 9 gains twice around the optimum.
    assert_eq!(points, 23);
    assert_eq!(h.state().ff_points.len(), 23);
    assert!((0.5..=1.3).contains(&chosen), "{chosen}");
    assert_eq!(before, 0.94);
    h.step();
    h.get_by_label("Apply the gain").click();
    assert!(step_until(&mut h, 5.0, |a| a.rows.iter().any(|r| r
        .listed
        .path
        == "ff.gain"
        && r.listed.value != "0.94")));
    drop(h);
    let got: f64 = tune(&srv, &["get", "ff.gain"], d).1.trim().parse().unwrap();
    assert!((got - chosen).abs() < 1e-5, "{got} vs {chosen}");
}

/// Stop during a run from the window (an identification at real time): the run ends with
/// the window saying it stopped, the bridge is off and the stroke limits are back.
fn the_window_stops_a_run_with_the_bridge_off() {
    use egui_kittest::kittest::Queryable;
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let sc = quiet_scenario(d, "");
    let srv = Server::start_with("tcp", &d.join("flash.img"), 1.0, Some(&sc));
    let mut h = window(&srv);
    assert!(step_until(&mut h, 10.0, |a| !a.rows.is_empty()));
    h.state_mut().tab = gms_tune::ui::app::Tab::Experiments;
    h.step();
    h.get_by_label("Identify").click();
    h.step();
    // Into the run (its first stage).
    assert!(step_until(&mut h, 10.0, |a| a
        .running
        .as_ref()
        .is_some_and(|r| r.done > 0.2)));
    h.get_by_label("Stop").click();
    assert!(step_until(&mut h, 20.0, |a| a.outcome.is_some()));
    let out = h.state().outcome.clone().unwrap();
    assert!(matches!(&out, Err(e) if e.contains("stopped")), "{out:?}");
    assert!(step_until(&mut h, 5.0, |a| !a.bridge_on()));
    drop(h);
    assert_eq!(tune(&srv, &["get", "lim.pos_max"], d).1.trim(), "50");
    assert_eq!(tune(&srv, &["get", "lim.pos_min"], d).1.trim(), "-50");
}

/// Export visible writes the samples of the plots' time window; Dump writes the device's
/// parameters as a parameter file; the step test moves the axis by the step and gives its
/// figures.
fn the_window_exports_dumps_and_steps() {
    use egui_kittest::kittest::Queryable;
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let srv = Server::start("tcp", &d.join("flash.img"));
    let mut h = window_on(&srv, vec!["set pos.kd 2.2e-4".into(), "enable".into()]);
    assert!(step_until(&mut h, 10.0, |a| a.samples.len() > 2000 && a.bridge_on()));
    h.state_mut().csv = d.join("live.csv").display().to_string();
    h.state_mut().file = d.join("dump.toml").display().to_string();
    h.step();
    h.get_by_label("Pause").click();
    h.step();
    h.get_by_label("Export visible").click();
    h.step();
    let text = std::fs::read_to_string(d.join("live.csv")).unwrap();
    let (a, b) = h.state().visible;
    let rows: Vec<Vec<f64>> = text
        .lines()
        .skip(1)
        .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
        .collect();
    assert_eq!(
        text.lines().next(),
        Some("t,pos,ref,error,ff,current,friction")
    );
    assert!(rows.len() > 1000, "{}", rows.len());
    assert!(rows.iter().all(|r| r.len() == 7 && r[0] >= a && r[0] <= b));
    h.get_by_label("Resume").click();
    h.get_by_label("Dump").click();
    assert!(step_until(&mut h, 5.0, |_| d.join("dump.toml").exists()));
    let pf = gms_ident::paramfile::ParamFile::load(&d.join("dump.toml")).unwrap();
    assert_eq!(pf.device.unwrap()["pos.kd"].as_float(), Some(0.00022));
    // A step of 2e-4 rad (53 counts) on the Motion page.
    h.state_mut().tab = gms_tune::ui::app::Tab::Motion;
    h.step();
    h.get_by_label("Step").click();
    assert!(step_until(&mut h, 10.0, |a| a.step.is_some()));
    let s = h.state().step.clone().unwrap();
    let m = s.metrics;
    eprintln!(
        "step {} rad: settle {:.1} ms, steady-state {:.2} counts, largest {:.1} counts, \
         unsettled {}",
        s.step,
        m.settle_time * 1e3,
        m.steady_state_error / 3.8e-6,
        m.max_error / 3.8e-6,
        m.unsettled_steps
    );
    assert_eq!(s.step, 2e-4);
    // Where the reference went (53 counts) the axis followed: a steady-state error of noise
    // size; the largest error (tracking the move) well below the step.
    assert!(m.steady_state_error < 2.0 * 3.8e-6, "{m:?}");
    assert!(m.max_error < 0.5 * 2e-4, "{m:?}");
    h.step();
    assert!(h.query_by_label_contains("steady-state").is_some());
}

/// `step-test` on the default virtual device (20× real time): a 1 mrad step settles in under
/// 0.2 s, and the trace agrees — after the printed settle time the recorded error stays within
/// the printed band but for excursions under 2 ms; no hunting. With the feedforward off and
/// an integral gain 20× the default the axis oscillates about the target: "hunting yes" (5×,
/// 3000, settles in 16 ms; 10× in 66 ms).
/// `status` prints a table and `--json` the raw figures.
fn step_test_settles_and_tells_hunting_from_dither() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let srv = Server::start_with("tcp", &d.join("flash.img"), 20.0, None);
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

/// `gms-tune frf --loop open --suggest --apply` on the virtual device (20× real time): a line
/// per point, frf.csv with its header, margins.toml with its four keys, bode.svg; the notch
/// proposed is set; the bridge is off after it.
fn frf_writes_its_files_suggests_and_applies_a_notch() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // A derivative gain a fifth above the default's: about 11° of phase margin at rest.
    let sc = quiet_scenario(d, "[controller.pos]\nkd = 3.2e-4\n");
    let srv = Server::start_with("tcp", &d.join("flash.img"), 20.0, Some(&sc));
    let (code, out, err) = tune(
        &srv,
        &[
            "frf",
            "--loop",
            "open",
            "--points",
            "16",
            "--amplitude",
            "0.003",
            "--out",
            "f",
            "--suggest",
            "--apply",
        ],
        d,
    );
    assert_eq!(code, 0, "{out}\n{err}");
    assert!(err.contains("16 points from 10 to 3000 Hz"), "{err}");
    let csv = std::fs::read_to_string(d.join("f/frf.csv")).unwrap();
    let mut lines = csv.lines();
    assert_eq!(lines.next(), Some("f_hz,gain_db,phase_deg,coherence"));
    let rows: Vec<Vec<f64>> = lines
        .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
        .collect();
    // The grid and the refinement where the margins are decided, in frequency order.
    assert!(rows.len() > 16, "{csv}");
    assert!(rows.windows(2).all(|w| w[0][0] < w[1][0]));
    assert!(rows.iter().all(|r| (0.0..=1.0).contains(&r[3])));
    let m: toml::Table = std::fs::read_to_string(d.join("f/margins.toml"))
        .unwrap()
        .parse()
        .unwrap();
    for k in [
        "gain_margin_db",
        "phase_margin_deg",
        "crossover_hz",
        "peak_sensitivity_db",
    ] {
        let v = m[k].as_float().unwrap();
        assert!(v.is_finite(), "{k} {v}");
    }
    // At rest the pre-sliding resonance leaves this loop little phase margin.
    assert!(m["phase_margin_deg"].as_float().unwrap() < 20.0);
    assert!(out.contains("warning: the phase margin"), "{out}");
    assert!(d.join("f/bode.svg").exists());
    assert!(
        out.contains("notch 1 at") && out.contains("set filt.notch1.f_hz"),
        "{out}"
    );
    let f: f64 = tune(&srv, &["get", "filt.notch1.f_hz"], d)
        .1
        .trim()
        .parse()
        .unwrap();
    assert!(f > 300.0 && f < 2000.0, "{f}");
    let (_, status, _) = tune(&srv, &["send", "status"], d);
    assert!(status.contains("enabled=0"), "{status}");
}

/// Bad input to `gms-tune frf` and to the device's `frf`: clear one-line errors, nothing
/// moved; an axis that does not respond (an open winding): exit 1, the bridge off, the points
/// measured kept.
fn frf_refuses_bad_input() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let sc = quiet_scenario(d, "");
    let srv = Server::start_with("tcp", &d.join("flash.img"), 20.0, Some(&sc));
    for (args, says) in [
        (
            &["frf", "--loop", "open", "--to", "9500"][..],
            "above the position loop's Nyquist limit",
        ),
        (
            &["frf", "--loop", "plant", "--amplitude", "5"][..],
            "beyond the current limit lim.i_max",
        ),
        (
            &["frf", "--loop", "plant", "--suggest"][..],
            "--suggest and --apply need --loop open",
        ),
        (
            &["frf", "--loop", "open", "--from", "0"][..],
            "need 0 < from < to",
        ),
    ] {
        let (code, out, err) = tune(&srv, args, d);
        assert_eq!(code, 2, "{args:?}: {out}\n{err}");
        assert!(err.contains(says), "{args:?}: {err}");
        assert_eq!(err.lines().count(), 1, "{err}");
    }
    // The protocol's own refusals.
    let (code, _, err) = tune(&srv, &["send", "frf current 100 0.003 8 2"], d);
    assert_eq!(code, 1);
    assert!(err.contains("disabled (enable first)"), "{err}");
    tune(&srv, &["send", "enable"], d);
    let (code, _, err) = tune(&srv, &["send", "frf current 9100 0.003 8 2"], d);
    assert_eq!(code, 1);
    assert!(err.contains("below 0.45"), "{err}");
    let (code, _, err) = tune(&srv, &["send", "frf current 100 5 8 2"], d);
    assert_eq!(code, 1);
    assert!(err.contains("beyond lim.i_max"), "{err}");
    let (code, _, err) = tune(&srv, &["send", "frf position 100 1 8 2"], d);
    assert_eq!(code, 1);
    assert!(err.contains("speed limit"), "{err}");
    tune(&srv, &["send", "disable"], d);
    drop(srv);
    // An open winding: no current flows, nothing responds.
    let sc = quiet_scenario(d, "resistance = 1e5\n[controller.motor]\nr = 10.0");
    let srv = Server::start_with("tcp", &d.join("flash2.img"), 20.0, Some(&sc));
    let (code, out, err) = tune(
        &srv,
        &["frf", "--loop", "plant", "--points", "6", "--out", "g"],
        d,
    );
    assert_eq!(code, 1, "{out}\n{err}");
    assert!(
        err.contains("the axis does not respond") && err.contains("the bridge is off"),
        "{err}"
    );
    let kept = std::fs::read_to_string(d.join("g/frf.csv")).unwrap();
    assert_eq!(kept.lines().count(), 7, "{kept}");
    let (_, status, _) = tune(&srv, &["send", "status"], d);
    assert!(status.contains("enabled=0"), "{status}");
}

/// The window's Frequency response page: a sweep of the open loop measured, its points as
/// they come, the margins and the notch proposed.
fn the_window_measures_a_frequency_response() {
    use egui_kittest::kittest::Queryable;
    use gms_tune::ui::worker::Outcome;
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let sc = quiet_scenario(d, "");
    let srv = Server::start_with("tcp", &d.join("flash.img"), 20.0, Some(&sc));
    let mut h = window(&srv);
    assert!(step_until(&mut h, 10.0, |a| !a.rows.is_empty()));
    h.state_mut().tab = gms_tune::ui::app::Tab::Frf;
    h.step();
    for (label, v) in [("points", "12"), ("amplitude", "0.003")] {
        replace_text(&mut h, label, v);
    }
    h.get_by_label("Measure").click();
    h.step();
    assert!(h.state().running.is_some());
    let done = step_until(&mut h, 90.0, |a| a.outcome.is_some());
    assert!(done, "{:?} {:?}", h.state().running, h.state().log);
    match h.state().outcome.clone().unwrap() {
        Ok(Outcome::Frf {
            sweep, suggestion, ..
        }) => {
            assert!(sweep.points.len() >= 12);
            assert_eq!(h.state().frf_points.len(), sweep.points.len());
            let m = sweep.margins.unwrap();
            assert!(m.phase_margin_deg.is_finite() && m.crossover_hz > 0.0);
            assert!(matches!(suggestion, Some(Ok(_))), "{suggestion:?}");
        }
        other => panic!("{other:?}"),
    }
    h.step();
    assert!(h.query_by_label("Apply the notch").is_some());
}

/// The window's Position map page on an axis with a hidden cogging: the map measured, its
/// ripple shown, applied (the device's map switched on, the switch showing it), switched off.
fn the_window_measures_and_applies_a_position_map() {
    use egui_kittest::kittest::Queryable;
    use gms_tune::ui::worker::Outcome;
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let sc = quiet_scenario(
        d,
        "gear_ratio = 1.0\nlead = 1.13636e-4\n[plant.ripple]\namplitude = 20e-6\nper_rev = 12",
    );
    let srv = Server::start_with("tcp", &d.join("flash.img"), 20.0, Some(&sc));
    let mut h = window(&srv);
    assert!(step_until(&mut h, 10.0, |a| !a.rows.is_empty()));
    h.state_mut().tab = gms_tune::ui::app::Tab::Map;
    h.step();
    replace_text(&mut h, "bins", "256");
    h.get_by_label("Measure the map").click();
    h.step();
    assert!(h.state().running.is_some());
    let done = step_until(&mut h, 90.0, |a| a.outcome.is_some());
    assert!(done, "{:?} {:?}", h.state().running, h.state().log);
    match h.state().outcome.clone().unwrap() {
        Ok(Outcome::Map { map, .. }) => {
            assert_eq!(map.angle.len(), 256);
            let peak = map.offset.iter().fold(0.0f64, |a, o| a.max(o.abs()));
            assert!((peak - 20e-6).abs() < 4e-6, "{peak}");
        }
        other => panic!("{other:?}"),
    }
    h.step();
    h.get_by_label("Apply the map").click();
    let on = |a: &gms_tune::ui::App| {
        a.rows
            .iter()
            .any(|r| r.listed.path == "map.enable" && r.listed.value == "1")
    };
    assert!(step_until(&mut h, 20.0, on), "{:?}", h.state().log);
    h.get_by_label("the map acts (map.enable)").click();
    assert!(step_until(&mut h, 5.0, |a| !on(a)));
    drop(h);
    let bins: f64 = tune(&srv, &["get", "map.bins"], d)
        .1
        .trim()
        .parse()
        .unwrap();
    assert_eq!(bins, 256.0);
}

/// `gms-tune learn` on the default virtual device: a line per iteration, the files, the
/// correction left playing with `--apply` (none without); bad arguments and a path beyond the
/// soft limits refused with a clear line, the latter before anything moves (the axis holding
/// as it was).
fn learn_writes_its_files_applies_and_refuses_bad_input() {
    let dir = tempfile::tempdir().unwrap();
    let srv = Server::start_at("tcp", &dir.path().join("flash.img"), 20.0);
    let d = dir.path();
    let table = |srv: &Server| tune(srv, &["send", "table"], d).1;
    let (code, out, err) = tune(&srv, &["learn", "--iterations", "3", "--out", "ln"], d);
    assert_eq!(code, 0, "{out}\n{err}");
    let rows: Vec<(usize, f64, f64)> = out
        .lines()
        .filter_map(|l| {
            let w: Vec<&str> = l.split_whitespace().collect();
            match w.as_slice() {
                [n, r, p] => Some((n.parse().ok()?, r.parse().ok()?, p.parse().ok()?)),
                _ => None,
            }
        })
        .collect();
    assert_eq!(rows.len(), 4, "{out}");
    assert!(rows.iter().all(|(_, r, p)| *r > 0.0 && p >= r), "{out}");
    // What repeats over the last iterations (4 of them here) and what does not: the parts'
    // squares make the iterations' mean square.
    let repeat = out
        .lines()
        .find(|l| l.starts_with("over the last 4 iterations: "))
        .unwrap_or_else(|| panic!("{out}"));
    let nums: Vec<f64> = repeat
        .split(|c: char| !(c.is_ascii_digit() || c == '.'))
        .filter_map(|w| w.parse().ok())
        .collect();
    let [_, rms, rep, nonrep] = nums[..] else {
        panic!("{repeat}")
    };
    let ms = rows.iter().map(|(_, r, _)| r * r).sum::<f64>() / 4.0;
    assert!((rms * rms - ms).abs() < 0.01 * ms, "{repeat}: {ms}");
    assert!(
        (rep * rep + nonrep * nonrep - ms).abs() < 0.01 * ms,
        "{repeat}"
    );
    let csv = std::fs::read_to_string(d.join("ln/iterations.csv")).unwrap();
    assert_eq!(csv.lines().next(), Some("iteration,rms_counts,peak_counts"));
    assert_eq!(csv.lines().count(), 5);
    let corr = std::fs::read_to_string(d.join("ln/correction.csv")).unwrap();
    assert_eq!(corr.lines().next(), Some("t_s,position_rad,correction_nm"));
    assert_eq!(corr.lines().count(), 1001, "1000 points a second");
    assert!(d.join("ln/learning.svg").exists());
    assert!(table(&srv).contains("state=ready") && table(&srv).contains(" gen=0 "));
    let (code, out, err) = tune(
        &srv,
        &["learn", "--iterations", "2", "--out", "ln2", "--apply"],
        d,
    );
    assert_eq!(code, 0, "{out}\n{err}");
    // The best correction plays (a generation of its own), the one in correction.csv.
    let t = table(&srv);
    assert!(t.contains("state=ready") && !t.contains(" gen=0 "), "{t}");
    let (code, read, _) = tune(&srv, &["send", "table", "read", "corr", "0", "4"], d);
    assert_eq!(code, 0, "{read}");
    let played: Vec<f32> = read.lines().filter_map(|l| l.trim().parse().ok()).collect();
    let kept: Vec<f32> = std::fs::read_to_string(d.join("ln2/correction.csv"))
        .unwrap()
        .lines()
        .skip(1)
        .take(4)
        .map(|l| l.split(',').nth(2).unwrap().parse::<f64>().unwrap() as f32)
        .collect();
    assert_eq!(played, kept);
    // Bad arguments: usage errors (exit 2), nothing sent.
    for args in [
        &["learn", "--sine", "0.05", "--out", "x"][..],
        &["learn", "--gain", "5", "--out", "x"],
        &["learn", "--sine", "-1", "1", "--out", "x"],
        &["learn", "--trajectory", "missing.csv", "--out", "x"],
        &["learn", "--iterations", "0", "--out", "x"],
    ] {
        let (code, out, err) = tune(&srv, args, d);
        assert_eq!(code, 2, "{args:?}: {out}\n{err}");
        let first = err.trim().lines().next().unwrap_or("");
        assert!(first.starts_with("error:"), "{args:?}: {err}");
    }
    // A path to 60 rad (the soft limits are ±50): refused by the device when set.
    let (_, status, _) = tune(&srv, &["send", "status"], d);
    std::fs::write(
        d.join("far.csv"),
        "t_s,position_rad\n0,0\n3,30\n6,60\n12,0\n",
    )
    .unwrap();
    let (code, out, err) = tune(&srv, &["learn", "--trajectory", "far.csv", "--out", "x"], d);
    assert_eq!(code, 1, "{out}\n{err}");
    assert!(
        err.contains("soft limits") && err.contains("holds where it was"),
        "{err}"
    );
    let (_, after, _) = tune(&srv, &["send", "status"], d);
    let pos = |s: &str| -> f64 {
        s.split_whitespace()
            .find_map(|w| w.strip_prefix("pos=")?.parse().ok())
            .unwrap()
    };
    assert!(
        (pos(&after) - pos(&status)).abs() < 1e-5,
        "{status} / {after}"
    );
    assert!(after.contains("enabled=1"), "as it was: {after}");
}

/// The window's Learning page: the iterations arrive one by one as the learning runs (each
/// shown before the run ends), the error over the period after it; Apply leaves the best
/// correction playing (the device's table says so).
fn the_window_shows_the_learning_and_applies_it() {
    use egui_kittest::kittest::Queryable;
    use gms_tune::ui::worker::Outcome;
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let srv = Server::start_at("tcp", &d.join("flash.img"), 20.0);
    let mut h = window(&srv);
    assert!(step_until(&mut h, 10.0, |a| !a.rows.is_empty()));
    h.state_mut().tab = gms_tune::ui::app::Tab::Learn;
    h.step();
    replace_text(&mut h, "iterations", "3");
    h.get_by_label("Learn").click();
    h.step();
    assert!(h.state().running.is_some());
    // Iterations come while the run goes on.
    let some = step_until(&mut h, 60.0, |a| !a.learn_points.is_empty());
    assert!(some && h.state().running.is_some(), "{:?}", h.state().log);
    let done = step_until(&mut h, 90.0, |a| a.outcome.is_some());
    assert!(done, "{:?} {:?}", h.state().running, h.state().log);
    let n = match h.state().outcome.clone().unwrap() {
        Ok(Outcome::Learned(l)) => {
            assert_eq!(l.iterations.len(), 4);
            assert_eq!(h.state().learn_points, l.iterations);
            l.correction.len()
        }
        other => panic!("{other:?}"),
    };
    assert_eq!(n, 1000);
    h.step();
    h.get_by_label("Apply the correction").click();
    let applied = step_until(&mut h, 20.0, |a| {
        a.log.iter().any(|l| l.contains("the correction plays"))
    });
    assert!(applied, "{:?}", h.state().log);
    drop(h);
    let t = tune(&srv, &["send", "table"], d).1;
    assert!(!t.contains(" gen=0 "), "{t}");
}
