//! The virtual device end to end over TCP: a real `hil-sim serve` process and raw sockets.

use std::io::{Read, Write};
use std::net::TcpStream;
use std::time::{Duration, Instant};

use crate::common;
use common::Server;

/// A raw TCP client of the device.
fn connect(srv: &Server) -> Client {
    let s = TcpStream::connect(&srv.addr).unwrap();
    s.set_read_timeout(Some(Duration::from_millis(50))).unwrap();
    Client {
        s,
        pending: String::new(),
    }
}

struct Client {
    s: TcpStream,
    pending: String,
}

impl Client {
    /// Reads until a line that starts with `ok` or `err` arrives (5 s at most); returns all
    /// lines up to and including it.
    fn reply(&mut self) -> Vec<String> {
        let deadline = Instant::now() + Duration::from_secs(5);
        let mut buf = [0u8; 4096];
        loop {
            if let Some(pos) = self
                .pending
                .lines()
                .position(|l| l.starts_with("ok") || l.starts_with("err "))
            {
                let lines: Vec<String> = self.pending.lines().map(String::from).collect();
                if self.pending.matches('\n').count() > pos {
                    let rest: Vec<String> = lines[pos + 1..].to_vec();
                    self.pending = rest.iter().map(|l| format!("{l}\n")).collect();
                    return lines[..=pos].to_vec();
                }
            }
            assert!(
                Instant::now() < deadline,
                "no reply; got {:?}",
                self.pending
            );
            match self.s.read(&mut buf) {
                Ok(0) => panic!("server closed"),
                Ok(n) => self.pending.push_str(&String::from_utf8_lossy(&buf[..n])),
                Err(_) => {}
            }
        }
    }

    fn ask(&mut self, line: &str) -> String {
        self.s.write_all(format!("{line}\n").as_bytes()).unwrap();
        self.reply().pop().unwrap()
    }
}

#[test]
fn set_save_restart_and_read_back() {
    let dir = tempfile::tempdir().unwrap();
    let store = dir.path().join("flash.img");
    {
        let srv = common::serve(&["--tcp", "127.0.0.1:0"], &store);
        let mut c = connect(&srv);
        assert_eq!(c.ask("get pos.kp"), "ok 0.49");
        assert_eq!(c.ask("set pos.kp 0.31"), "ok");
        assert_eq!(c.ask("set ff.mode static"), "ok");
        assert!(c.ask("set gms.fs 1e-6").starts_with("err 7 "));
        assert_eq!(c.ask("enable"), "ok");
        assert!(
            c.ask("save").starts_with("err 8 "),
            "save while enabled is refused"
        );
        assert_eq!(c.ask("disable"), "ok");
        assert_eq!(c.ask("save"), "ok");
        assert_eq!(c.ask("set pos.kp 0.5"), "ok");
    }
    let srv = common::serve(&["--tcp", "127.0.0.1:0"], &store);
    let mut c = connect(&srv);
    assert_eq!(c.ask("get pos.kp"), "ok 0.31");
    assert_eq!(c.ask("get ff.mode"), "ok static");
    assert!(c.ask("status").contains("faults=0"));
    assert_eq!(c.ask("defaults"), "ok");
    assert_eq!(c.ask("get pos.kp"), "ok 0.49");
    assert_eq!(c.ask("load"), "ok");
    assert_eq!(c.ask("get pos.kp"), "ok 0.31");
}

#[test]
fn a_corrupt_record_means_defaults_and_a_fault() {
    use gms_core::device::ParamStore;
    let dir = tempfile::tempdir().unwrap();
    let store = dir.path().join("flash.img");
    {
        // A record whose checksum fails, written with the board's store code.
        let mut s = default_settings();
        s.pid.kp = 0.4;
        let mut rec = gms_core::device::encode_settings(&s);
        rec[10] ^= 0x40;
        let flash = hil_sim::device::HostFlash::open(&store).unwrap();
        let mut st = gms_core::device::store::FlashStore::new(flash);
        st.save(&rec).unwrap();
    }
    let srv = common::serve(&["--tcp", "127.0.0.1:0"], &store);
    let mut c = connect(&srv);
    assert_eq!(c.ask("get pos.kp"), "ok 0.49");
    let st = c.ask("status");
    assert!(
        st.contains("faults=32 ") && st.contains("fault_names=invalid_params "),
        "{st}"
    );
    assert!(c.ask("enable").starts_with("err 8 "));
    assert_eq!(c.ask("clear"), "ok");
    assert_eq!(c.ask("enable"), "ok");
}

#[test]
fn a_file_that_is_not_a_store_image_is_refused_and_left_alone() {
    let dir = tempfile::tempdir().unwrap();
    let store = dir.path().join("flash.toml");
    std::fs::write(&store, "\"pos.kp\" = 0.3\n").unwrap();
    let (code, _, err) = common::hil(
        &[
            "serve",
            "--tcp",
            "127.0.0.1:0",
            "--store",
            store.to_str().unwrap(),
        ],
        dir.path(),
    );
    assert_eq!(code, 2, "{err}");
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(err.contains("not a store image"), "{err}");
    assert_eq!(
        std::fs::read_to_string(&store).unwrap(),
        "\"pos.kp\" = 0.3\n"
    );
}

fn default_settings() -> gms_core::protocol::Settings {
    gms_core::device::default_settings()
}

#[test]
fn garbage_floods_and_dropped_clients_leave_the_device_running() {
    let dir = tempfile::tempdir().unwrap();
    let srv = common::serve(&["--tcp", "127.0.0.1:0"], &dir.path().join("flash.toml"));
    let mut c = connect(&srv);
    c.s.write_all(b"\x00\x01\xfe\xff\x1b[2J\n").unwrap();
    assert!(c.reply().pop().unwrap().starts_with("err 4 "));
    c.s.write_all(&[b'z'; 10_000]).unwrap();
    c.s.write_all(b"\n").unwrap();
    assert!(c.reply().pop().unwrap().starts_with("err 3 "));
    // A flood of valid requests: one reply each, in order.
    let mut flood = String::new();
    for i in 0..200 {
        flood += &format!("set pos.ki {}\n", 50 + i);
    }
    c.s.write_all(flood.as_bytes()).unwrap();
    for _ in 0..200 {
        assert_eq!(c.reply().pop().unwrap(), "ok");
    }
    assert_eq!(c.ask("get pos.ki"), "ok 249");
    // Disconnect in the middle of a line; the next client is served.
    c.s.write_all(b"set pos.k").unwrap();
    drop(c);
    let mut c2 = connect(&srv);
    assert_eq!(c2.ask("get pos.ki"), "ok 249");
    assert_eq!(c2.ask("get pos.kp"), "ok 0.49");
}

#[test]
fn telemetry_lines_start_with_hash_and_never_mix_with_replies() {
    let dir = tempfile::tempdir().unwrap();
    let srv = common::serve(&["--tcp", "127.0.0.1:0"], &dir.path().join("flash.toml"));
    let mut c = connect(&srv);
    assert_eq!(c.ask("enable"), "ok");
    assert_eq!(c.ask("stream t,error,ff 200"), "ok");
    assert_eq!(c.ask("move 0.002"), "ok");
    std::thread::sleep(Duration::from_millis(300));
    let lines = {
        c.s.write_all(b"get pos.kp\n").unwrap();
        c.reply()
    };
    assert_eq!(lines.last().unwrap(), "ok 0.49");
    let telemetry: Vec<&String> = lines.iter().filter(|l| l.starts_with('#')).collect();
    assert!(telemetry.len() >= 20, "{} telemetry lines", telemetry.len());
    for l in &lines[..lines.len() - 1] {
        assert!(l.starts_with("# t="), "{l}");
        assert_eq!(l.split_whitespace().count(), 4, "{l}");
    }
    assert!(c.ask("stream bogus 10").starts_with("err 8 "));
    assert_eq!(c.ask("stream off"), "ok");
}

/// `gms-adaptive` on the device: moving adapts the scale, `get ff.adapt.scale` reads it, a
/// new parameter set keeps it (it is about the axis, not the settings), and it cannot be set.
#[test]
fn the_adaptive_scale_is_read_kept_across_sets_and_read_only() {
    let dir = tempfile::tempdir().unwrap();
    let srv = common::serve(&["--tcp", "127.0.0.1:0"], &dir.path().join("flash.toml"));
    let mut c = connect(&srv);
    assert_eq!(c.ask("get ff.adapt.scale"), "ok 1");
    assert_eq!(c.ask("set ff.mode gms-adaptive"), "ok");
    assert_eq!(c.ask("enable"), "ok");
    let wait_still = |c: &mut Client| {
        let deadline = Instant::now() + Duration::from_secs(10);
        while c.ask("status").contains("moving=1") {
            assert!(Instant::now() < deadline, "the move never ended");
            std::thread::sleep(Duration::from_millis(20));
        }
    };
    for target in ["0.2", "0", "0.2", "0"] {
        assert_eq!(c.ask(&format!("move {target}")), "ok");
        wait_still(&mut c);
    }
    let scale: f32 = c.ask("get ff.adapt.scale")[3..].parse().unwrap();
    assert!(scale != 1.0 && (0.5..=1.5).contains(&scale), "{scale}");
    // At rest the adaptation is frozen: a new set finds the same scale.
    assert_eq!(c.ask("set pos.kp 0.21"), "ok");
    assert_eq!(c.ask("get ff.adapt.scale"), format!("ok {scale}"));
    assert!(c.ask("set ff.adapt.scale 1").starts_with("err 8 "));
    assert_eq!(c.ask("get ff.adapt.scale"), format!("ok {scale}"));
}

/// Device time (`status` `t=`) [s].
fn device_time(c: &mut Client) -> f64 {
    let st = c.ask("status");
    let text = st
        .trim()
        .strip_prefix("ok ")
        .unwrap_or_else(|| panic!("{st}"));
    gms_core::device::StatusReply::parse(text)
        .unwrap_or_else(|e| panic!("{e}: {st}"))
        .t
}

#[test]
fn serve_faster_than_real_time() {
    let dir = tempfile::tempdir().unwrap();
    let srv = common::serve(
        &["--tcp", "127.0.0.1:0", "--speed", "5"],
        &dir.path().join("flash.img"),
    );
    let mut c = connect(&srv);
    let (w0, t0) = (Instant::now(), device_time(&mut c));
    std::thread::sleep(Duration::from_millis(400));
    let (w1, t1) = (Instant::now(), device_time(&mut c));
    let ratio = (t1 - t0) / (w1 - w0).as_secs_f64();
    // 5 times the wall clock; a loaded host may fall behind (never ahead, never skipping).
    assert!(ratio > 1.5 && ratio < 5.5, "device/wall time ratio {ratio}");
    // Nonsense speeds are refused before anything starts.
    let (code, _, err) = common::hil(
        &["serve", "--tcp", "127.0.0.1:0", "--speed", "0"],
        dir.path(),
    );
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("--speed 0"), "{err}");
}

/// A second client while one is served gets one line, `err 8 busy: …`, and is closed; the
/// first is undisturbed (its requests answered, its stream not mixed with the refusal), and
/// once it leaves the next client is served.
#[test]
fn a_second_client_is_refused_with_one_line_and_the_first_is_undisturbed() {
    let dir = tempfile::tempdir().unwrap();
    let srv = common::serve(&["--tcp", "127.0.0.1:0"], &dir.path().join("flash.img"));
    let mut first = connect(&srv);
    assert_eq!(first.ask("set pos.ki 120"), "ok");
    let mut second = connect(&srv);
    second.s.write_all(b"get pos.ki\n").unwrap();
    let mut got = String::new();
    let deadline = Instant::now() + Duration::from_secs(5);
    let mut buf = [0u8; 256];
    loop {
        match second.s.read(&mut buf) {
            Ok(0) => break,
            Ok(n) => got.push_str(&String::from_utf8_lossy(&buf[..n])),
            Err(_) => assert!(Instant::now() < deadline, "no refusal; got {got:?}"),
        }
    }
    assert_eq!(
        got,
        "err 8 busy: another client is connected to the device\n"
    );
    // The first goes on as before.
    assert_eq!(first.ask("get pos.ki"), "ok 120");
    assert_eq!(first.ask("set pos.ki 130"), "ok");
    drop(first);
    let mut third = connect(&srv);
    assert_eq!(third.ask("get pos.ki"), "ok 130");
}
