//! The conformance suite's checks: protocol exchanges that every device answers alike, run
//! by `hil-sim/tests/conformance.rs` against the device core in-process and `hil-sim serve`,
//! and by `rehost/tests/conformance.rs` against the shipped firmware image on emulated silicon.
//! Each check takes the device under test and asserts on its replies; a check that needs a
//! scenario of its own, or the simulator's extras, stays with its test.

#![allow(dead_code)]

use std::io::{Read, Write};
use std::net::TcpStream;
use std::time::{Duration, Instant};

/// A device under test.
pub trait Dut {
    /// Sends a line; returns every line received up to its reply (telemetry included).
    fn ask_all(&mut self, line: &str) -> Vec<String>;
    /// Lets `seconds` pass on the device.
    fn wait(&mut self, seconds: f64);
    /// Powers the device off and on again (its store kept).
    fn restart(&mut self);
    /// The client goes away and a new one comes.
    fn reconnect(&mut self);
    /// Bytes on the link that wait for no reply (a half request line).
    fn send_bytes(&mut self, bytes: &[u8]);
    /// The reply line.
    fn ask(&mut self, line: &str) -> String {
        self.ask_all(line).pop().unwrap_or_default()
    }
}

/// The host's end of a device's TCP link (`hil-sim serve`, `rehost serve`): lines out, the
/// lines up to each reply back.
pub struct TcpLink {
    s: TcpStream,
    /// What has come and is not a reply's yet.
    pending: String,
}

impl TcpLink {
    /// Connected to `addr`; CAN LF sent first, as a host starts (gms-core's
    /// `protocol::CANCEL`: a half line an earlier host left is dropped, no reply).
    pub fn connect(addr: &str) -> TcpLink {
        let mut s = TcpStream::connect(addr).unwrap();
        s.set_read_timeout(Some(Duration::from_millis(20))).unwrap();
        s.write_all(&[gms_core::protocol::CANCEL, b'\n']).unwrap();
        TcpLink {
            s,
            pending: String::new(),
        }
    }

    /// Sends `bytes` as they are (no line end, no reply awaited).
    pub fn send_bytes(&mut self, bytes: &[u8]) {
        self.s.write_all(bytes).unwrap();
    }

    /// Sends `line`; returns every line received up to its reply (`ok…` or `err …`,
    /// telemetry included), or None when `within` passes first (what came is kept).
    pub fn exchange(&mut self, line: &str, within: Duration) -> Option<Vec<String>> {
        self.s.write_all(format!("{line}\n").as_bytes()).unwrap();
        let deadline = Instant::now() + within;
        let mut buf = [0u8; 8192];
        loop {
            if let Some(end) = self.pending.match_indices('\n').map(|(i, _)| i).find(|&i| {
                let start = self.pending[..i].rfind('\n').map_or(0, |j| j + 1);
                let l = &self.pending[start..i];
                l.starts_with("ok") || l.starts_with("err ")
            }) {
                let lines = self.pending[..end].lines().map(String::from).collect();
                self.pending = self.pending[end + 1..].to_string();
                return Some(lines);
            }
            if Instant::now() > deadline {
                return None;
            }
            if let Ok(n) = self.s.read(&mut buf) {
                assert!(n > 0, "the device closed the link");
                self.pending.push_str(&String::from_utf8_lossy(&buf[..n]));
            }
        }
    }

    /// What has come and is not a reply's yet.
    pub fn pending(&self) -> &str {
        &self.pending
    }

    /// This client goes away and a new one connects to `addr` (a device serves one client at
    /// a time: the new one is taken once the old one is seen gone).
    pub fn reconnect(&mut self, addr: &str) {
        self.s.shutdown(std::net::Shutdown::Both).unwrap();
        *self = TcpLink::connect(addr);
    }
}

/// The value of `key=` in a status or telemetry line.
pub fn field(line: &str, key: &str) -> f64 {
    line.split_whitespace()
        .find_map(|w| w.strip_prefix(key).and_then(|v| v.strip_prefix('=')))
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("no {key} in {line}"))
}

pub fn keys(line: &str) -> Vec<String> {
    line.split_whitespace()
        .skip(1)
        .filter_map(|w| w.split_once('=').map(|(k, _)| k.to_string()))
        .collect()
}

/// The largest |error| \[counts\] in the telemetry lines.
pub fn peak_error(lines: &[String]) -> f64 {
    lines
        .iter()
        .filter(|l| l.starts_with('#'))
        .map(|l| field(l, "error").abs() / 3.8e-6)
        .fold(0.0, f64::max)
}

/// A slow move, with `before` set (if any) ahead of it; at 0.2 s `set` (if any); the error's
/// peak over the next 150 ms.
pub fn error_after(d: &mut dyn Dut, before: Option<&str>, set: Option<&str>) -> f64 {
    if let Some(line) = before {
        assert_eq!(d.ask(line), "ok", "{line}");
    }
    assert_eq!(d.ask("enable"), "ok");
    assert_eq!(d.ask("move 0.05 0.1"), "ok");
    d.wait(0.2);
    assert_eq!(d.ask("stream error 1000"), "ok");
    if let Some(line) = set {
        assert_eq!(d.ask(line), "ok", "{line}");
    }
    d.wait(0.15);
    peak_error(&d.ask_all("stream off"))
}

/// The word after `key=` in a status line.
pub fn word<'a>(line: &'a str, key: &str) -> &'a str {
    line.split_whitespace()
        .find_map(|w| w.strip_prefix(key).and_then(|v| v.strip_prefix('=')))
        .unwrap_or_else(|| panic!("no {key} in {line}"))
}

pub fn enable_and_disable(d: &mut dyn Dut) {
    assert_eq!(d.ask("enable"), "ok");
    assert_eq!(field(&d.ask("status"), "enabled"), 1.0);
    assert_eq!(d.ask("disable"), "ok");
    assert_eq!(field(&d.ask("status"), "enabled"), 0.0);
    assert!(
        d.ask("move 0.01").starts_with("err 8 "),
        "move while disabled"
    );
}

pub fn a_second_move_mid_move_continues_the_reference(d: &mut dyn Dut) {
    assert_eq!(d.ask("enable"), "ok");
    assert_eq!(d.ask("stream ref 1000"), "ok");
    assert_eq!(d.ask("move 0.01 0.1"), "ok");
    d.wait(0.05);
    assert_eq!(d.ask("move 0.02 0.1"), "ok");
    d.wait(0.35);
    let lines = d.ask_all("stream off");
    let refs: Vec<f64> = lines
        .iter()
        .filter(|l| l.starts_with('#'))
        .map(|l| field(l, "ref"))
        .collect();
    assert!(refs.len() > 300, "{} samples", refs.len());
    let count = 3.8e-6;
    for w in refs.windows(2) {
        // Monotonic, and no step above the speed limit (0.1 rad/s over 1 ms).
        assert!(
            w[1] >= w[0] - 0.01 * count,
            "backs up: {} -> {}",
            w[0],
            w[1]
        );
        assert!(
            w[1] - w[0] <= 0.1 * 1e-3 * 1.02,
            "jumps: {} -> {}",
            w[0],
            w[1]
        );
    }
    assert!(
        (refs.last().unwrap() - 0.02).abs() < count,
        "{:?}",
        refs.last()
    );
}

pub fn a_following_error_latches_and_clear_works(d: &mut dyn Dut) {
    assert_eq!(d.ask("set lim.i_max 0.02"), "ok");
    assert_eq!(d.ask("enable"), "ok");
    assert_eq!(d.ask("move 0.5 5"), "ok");
    d.wait(0.3);
    let st = d.ask("status");
    assert!(st.contains("fault_names=following_error "), "{st}");
    assert_eq!(field(&st, "enabled"), 0.0);
    assert!(d.ask("enable").starts_with("err 8 "));
    assert_eq!(d.ask("clear"), "ok");
    assert_eq!(d.ask("enable"), "ok");
}

pub fn an_over_current_latches(d: &mut dyn Dut) {
    // A current loop far too stiff for the winding oscillates beyond the trip. The trip at
    // 1.5 × `lim.i_max` = 0.15 A: on a board the duty is held within the sense window's
    // limit (0.43 of 12 V at 40 kHz), whose bang-bang swing no longer reaches the default
    // trip (0.46 A: the winding's 10.6 Ω take 5.2 V to it).
    assert_eq!(d.ask("set lim.i_max 0.1"), "ok");
    assert_eq!(d.ask("set cur.kp 5000"), "ok");
    // It may trip before `enable` has answered ("not enabled (fault)").
    d.ask("enable");
    d.wait(0.1);
    let st = d.ask("status");
    assert!(st.contains("over_current"), "{st}");
    assert_eq!(field(&st, "enabled"), 0.0);
}

/// The scenario that puts the current sense's zero 130 codes below mid-scale
/// (`[plant.sense] offset_codes`), for [`a_sense_zero_off_mid_scale_refuses_a_limit_it_cannot_reach`].
pub const SENSE_ZERO_LOW: &str = "[plant.sense]\noffset_codes = -130.0\n";

/// On a plant whose current-sense zero lies 130 codes below mid-scale ([`SENSE_ZERO_LOW`]):
/// start-up finds it (inside its window, no fault); with `lim.i_max` 0.48 A `enable` is
/// refused, as the sense no longer reaches it from there (the image's INA240, linear to 0.2 V
/// inside its rails: 0.396 A; the simulator's ADC, ±0.5 A about mid-scale: 0.468 A), and
/// nothing drives; with a limit it reaches the device enables, and a current loop far too
/// stiff still trips `over_current`.
pub fn a_sense_zero_off_mid_scale_refuses_a_limit_it_cannot_reach(d: &mut dyn Dut) {
    let st = d.ask("status");
    assert!((field(&st, "sense_offset") - 1918.0).abs() < 1.0, "{st}");
    assert_eq!(field(&st, "faults"), 0.0, "{st}");
    assert_eq!(d.ask("set lim.i_max 0.48"), "ok");
    assert_eq!(
        d.ask("enable"),
        "err 8 lim.i_max beyond what the current sense reaches from its zero"
    );
    assert_eq!(field(&d.ask("status"), "enabled"), 0.0);
    assert_eq!(d.ask("set lim.i_max 0.3"), "ok");
    assert_eq!(d.ask("enable"), "ok");
    assert_eq!(d.ask("disable"), "ok");
    an_over_current_latches(d);
}

pub fn a_refused_set_changes_nothing(d: &mut dyn Dut) {
    assert!(d.ask("set gms.fs 1e-6").starts_with("err 7 "));
    assert_eq!(d.ask("get gms.fs"), "ok 0.00022");
    assert!(d.ask("set pos.kp 5000").starts_with("err 6 "));
    assert_eq!(d.ask("get pos.kp"), "ok 0.49");
    assert!(d.ask("set ff.adapt.scale 1.1").starts_with("err 8 "));
}

pub fn leaving_the_soft_limits_latches_position_limit(d: &mut dyn Dut) {
    assert_eq!(d.ask("get lim.pos_max"), "ok 50");
    // A limit below the low one is refused, and nothing changes.
    assert!(d.ask("set lim.pos_max -60").starts_with("err 7 "));
    assert_eq!(d.ask("get lim.pos_max"), "ok 50");
    assert_eq!(d.ask("enable"), "ok");
    assert_eq!(d.ask("move 0.02 0.2"), "ok");
    d.wait(0.3);
    let st = d.ask("status");
    assert_eq!(field(&st, "faults"), 0.0, "{st}");
    assert!((field(&st, "pos") - 0.02).abs() < 1e-4, "{st}");
    // A move beyond a limit is refused before it starts.
    assert_eq!(d.ask("set lim.pos_max 0.05"), "ok");
    assert!(d.ask("move 0.06").starts_with("err 8 "));
    assert_eq!(field(&d.ask("status"), "enabled"), 1.0);
    // The limit moved under the axis: it trips.
    assert_eq!(d.ask("set lim.pos_max 0.01"), "ok");
    d.wait(0.05);
    let st = d.ask("status");
    assert!(st.contains("fault_names=position_limit "), "{st}");
    assert_eq!(field(&st, "enabled"), 0.0);
    assert!(d.ask("enable").starts_with("err 8 "));
    assert_eq!(d.ask("set lim.pos_max 0.05"), "ok");
    assert_eq!(d.ask("clear"), "ok");
    assert_eq!(d.ask("enable"), "ok");
    d.wait(0.05);
    assert_eq!(field(&d.ask("status"), "faults"), 0.0);
}

pub fn save_restart_load(d: &mut dyn Dut) {
    assert_eq!(d.ask("set pos.kp 0.25"), "ok");
    assert_eq!(d.ask("set ff.mode gms-adaptive"), "ok");
    assert_eq!(d.ask("save"), "ok");
    assert_eq!(d.ask("set pos.kp 0.3"), "ok");
    d.restart();
    // The saved set runs after a restart, without a fault.
    let st = d.ask("status");
    assert_eq!(field(&st, "faults"), 0.0, "{st}");
    assert!(st.starts_with("ok mode=gms-adaptive "), "{st}");
    assert_eq!(d.ask("get pos.kp"), "ok 0.25");
    // defaults and load: the built-in set, then the saved one again.
    assert_eq!(d.ask("defaults"), "ok");
    assert_eq!(d.ask("get pos.kp"), "ok 0.49");
    assert_eq!(d.ask("load"), "ok");
    assert_eq!(d.ask("get pos.kp"), "ok 0.25");
    assert_eq!(d.ask("get ff.mode"), "ok gms-adaptive");
    // Save and load refuse while the bridge drives.
    assert_eq!(d.ask("enable"), "ok");
    assert!(d.ask("save").starts_with("err 8 "));
    assert!(d.ask("load").starts_with("err 8 "));
}

pub fn current_mode_pushes_and_hold_takes_position_back(d: &mut dyn Dut) {
    assert!(
        d.ask("current 0.05").starts_with("err 8 "),
        "while disabled"
    );
    assert_eq!(d.ask("enable"), "ok");
    // Above the current limit: refused, nothing changes.
    assert!(d.ask("current 0.6").starts_with("err 8 "));
    assert_eq!(word(&d.ask("status"), "drive"), "position");
    let p0 = field(&d.ask("status"), "pos");
    // 15 mA: 99 uN·m, below both the 220 uN·m breakaway and the 125 uN·m of Coulomb
    // friction: the axis creeps in pre-sliding (about 100 urad on the virgin curve) and
    // cannot slide away.
    assert_eq!(d.ask("current 0.015"), "ok");
    d.wait(0.1);
    let st = d.ask("status");
    assert_eq!(word(&st, "drive"), "current", "{st}");
    assert!((field(&st, "current") - 0.015).abs() < 0.003, "{st}");
    let moved = field(&st, "pos") - p0;
    assert!(moved > 2e-5 && moved < 2e-3, "{moved} rad: {st}");
    // hold: position control where the axis is, no fault.
    assert_eq!(d.ask("hold"), "ok");
    d.wait(0.1);
    let st = d.ask("status");
    assert_eq!(word(&st, "drive"), "position", "{st}");
    assert_eq!(field(&st, "faults"), 0.0, "{st}");
    assert!(field(&st, "error_counts").abs() < 20.0, "{st}");
}

pub fn velocity_mode_runs_and_hold_stops_it(d: &mut dyn Dut) {
    assert_eq!(d.ask("enable"), "ok");
    assert!(d.ask("velocity 25").starts_with("err 8 "), "too fast");
    let p0 = field(&d.ask("status"), "pos");
    assert_eq!(d.ask("velocity 0.2"), "ok");
    d.wait(0.3);
    let st = d.ask("status");
    assert_eq!(word(&st, "drive"), "velocity", "{st}");
    assert_eq!(field(&st, "moving"), 1.0, "{st}");
    // 0.2 rad/s for 0.3 s less the 4 ms ramp: about 0.06 rad, tracked within counts.
    let moved = field(&st, "pos") - p0;
    assert!(moved > 0.04 && moved < 0.08, "{moved}");
    assert!(field(&st, "error_counts").abs() < 50.0, "{st}");
    assert_eq!(d.ask("hold"), "ok");
    d.wait(0.2);
    let st = d.ask("status");
    assert_eq!(word(&st, "drive"), "position", "{st}");
    assert_eq!(field(&st, "moving"), 0.0, "{st}");
    assert_eq!(field(&st, "faults"), 0.0, "{st}");
    // Stopped: no further motion.
    let p1 = field(&st, "pos");
    d.wait(0.1);
    assert!((field(&d.ask("status"), "pos") - p1).abs() < 1e-4);
}

pub fn a_lost_link_ends_an_experiment_but_not_a_hold(d: &mut dyn Dut) {
    assert_eq!(d.ask("enable"), "ok");
    d.reconnect();
    assert_eq!(field(&d.ask("status"), "enabled"), 1.0, "holding goes on");
    assert_eq!(d.ask("velocity 0.1"), "ok");
    d.wait(0.05);
    d.reconnect();
    d.wait(0.05);
    let st = d.ask("status");
    assert_eq!(field(&st, "enabled"), 0.0, "{st}");
    assert_eq!(word(&st, "drive"), "position", "{st}");
}

pub fn capture_records_at_the_control_rate_and_reads_back(d: &mut dyn Dut) {
    assert_eq!(d.ask("enable"), "ok");
    // 3 fields × 1000 samples, every position step (10 kHz), from the next request.
    assert!(
        d.ask("capture t,pos,current 1 3000").starts_with("err 8 "),
        "too big"
    );
    assert!(
        d.ask("capture t,speed 1 10").starts_with("err 8 "),
        "unknown field"
    );
    assert_eq!(d.ask("capture t,pos,current 1 1000 next"), "ok");
    assert!(d.ask("capture").starts_with("ok state=armed samples=0"));
    d.wait(0.05);
    assert!(
        d.ask("capture").starts_with("ok state=armed"),
        "waits for its trigger"
    );
    assert!(
        d.ask("capture read 0 10").starts_with("err 8 "),
        "nothing to read yet"
    );
    assert_eq!(d.ask("velocity 0.2"), "ok");
    d.wait(0.2);
    assert!(
        d.ask("capture").starts_with("ok state=done samples=1000"),
        "{}",
        d.ask("capture")
    );
    let mut rows: Vec<Vec<f64>> = Vec::new();
    let mut start = 0;
    while start < 1000 {
        let lines = d.ask_all(&format!("capture read {start} 64"));
        assert_eq!(lines.last().map(String::as_str), Some("ok"));
        let body: Vec<&String> = lines.iter().filter(|l| !l.starts_with('#')).collect();
        let n = body.len() - 1;
        assert_eq!(n, 64.min(1000 - start) as usize);
        for l in &body[..n] {
            rows.push(l.split(',').map(|v| v.parse().unwrap()).collect());
        }
        start += n as u32;
    }
    assert_eq!(rows.len(), 1000);
    // Time: every position step (0.05 ms at the default 20 kHz), from 0 at the trigger.
    let dt = 1.0 / d.ask("get rate.pos_hz")[3..].parse::<f64>().unwrap();
    for (k, r) in rows.iter().enumerate() {
        assert_eq!(r.len(), 3);
        assert!((r[0] - k as f64 * dt).abs() < 1e-7, "row {k}: {r:?}");
    }
    // Position from 0 at the trigger, following the 0.2 rad/s ramp: after the 4 ms ramp
    // it advances 0.2 rad/s × 0.05 ms = 10 urad (2.6 counts) per sample on average.
    assert!(rows[0][1].abs() < 4e-5, "{:?}", rows[0]);
    let late = (rows[999][1] - rows[500][1]) / (499.0 * dt);
    assert!((late - 0.2).abs() < 0.02, "speed {late}");
    // The current is the loop's, within the sense range.
    assert!(rows.iter().all(|r| r[2].abs() < 0.5));
    // Reading past the end returns what there is: 10 samples and `ok`.
    let tail = d.ask_all("capture read 990 20");
    assert_eq!(
        tail.iter().filter(|l| !l.starts_with('#')).count(),
        11,
        "{tail:?}"
    );
    assert_eq!(d.ask("capture off"), "ok");
    assert!(d.ask("capture").starts_with("ok state=idle"));
}

/// A request cut by a lost link (half a line, then the host gone) is not run: the next host's
/// CAN LF drops the half line, and the device answers that host as before. (`set pos.kp 0.5`
/// of a `set pos.kp 0.55`, completed by a bare newline, would set 0.5.)
pub fn a_half_request_of_a_lost_link_is_not_run(d: &mut dyn Dut) {
    let kp = d.ask("get pos.kp");
    assert!(kp.starts_with("ok "), "{kp}");
    assert_ne!(kp, "ok 0.5");
    d.send_bytes(b"set pos.kp 0.5");
    d.reconnect();
    assert_eq!(d.ask("get pos.kp"), kp, "the half request was run");
    let st = d.ask("status");
    assert_eq!(field(&st, "faults"), 0.0, "{st}");
}
