//! One conformance suite of protocol exchanges, run against the device core in-process (with
//! the simulated plant, in simulated time) and against `hil-sim serve` over TCP (real time):
//! both are gms-core's device core, so both must answer alike.

use std::io::{Read, Write};
use std::net::TcpStream;
use std::time::{Duration, Instant};

use std::path::{Path, PathBuf};

use hil_sim::device::LocalDevice;
use hil_sim::scenario::Scenario;

mod common;
use common::Server;

/// A device under test.
trait Dut {
    /// Sends a line; returns every line received up to its reply (telemetry included).
    fn ask_all(&mut self, line: &str) -> Vec<String>;
    /// Lets `seconds` pass on the device.
    fn wait(&mut self, seconds: f64);
    /// Powers the device off and on again (its store kept).
    fn restart(&mut self);
    /// The client goes away and a new one comes.
    fn reconnect(&mut self);
    /// The reply line.
    fn ask(&mut self, line: &str) -> String {
        self.ask_all(line).pop().unwrap_or_default()
    }
}

struct Local {
    sc: Scenario,
    dev: Option<LocalDevice>,
}

impl Local {
    fn dev(&mut self) -> &mut LocalDevice {
        self.dev.as_mut().unwrap()
    }
}

impl Dut for Local {
    fn ask_all(&mut self, line: &str) -> Vec<String> {
        let mut lines = self.dev().telemetry();
        let reply = self.dev().ask(line);
        lines.extend(reply.lines().map(String::from));
        lines
    }
    fn wait(&mut self, seconds: f64) {
        self.dev().run(seconds);
    }
    fn restart(&mut self) {
        let flash = self.dev.take().unwrap().into_flash();
        self.dev = Some(LocalDevice::with_flash(&self.sc, flash).unwrap());
    }
    fn reconnect(&mut self) {
        self.dev().disconnect();
    }
}

struct Tcp {
    srv: Option<Server>,
    s: TcpStream,
    pending: String,
    args: Vec<String>,
    store: PathBuf,
}

impl Tcp {
    fn start(args: Vec<String>, store: PathBuf) -> Tcp {
        let a: Vec<&str> = args.iter().map(String::as_str).collect();
        let srv = common::serve(&a, &store);
        let s = TcpStream::connect(&srv.addr).unwrap();
        s.set_read_timeout(Some(Duration::from_millis(20))).unwrap();
        Tcp {
            srv: Some(srv),
            s,
            pending: String::new(),
            args,
            store,
        }
    }
}

impl Dut for Tcp {
    fn ask_all(&mut self, line: &str) -> Vec<String> {
        self.s.write_all(format!("{line}\n").as_bytes()).unwrap();
        let deadline = Instant::now() + Duration::from_secs(10);
        let mut buf = [0u8; 8192];
        loop {
            if let Some(end) = self.pending.match_indices('\n').map(|(i, _)| i).find(|&i| {
                let start = self.pending[..i].rfind('\n').map_or(0, |j| j + 1);
                let l = &self.pending[start..i];
                l.starts_with("ok") || l.starts_with("err ")
            }) {
                let lines = self.pending[..end].lines().map(String::from).collect();
                self.pending = self.pending[end + 1..].to_string();
                return lines;
            }
            assert!(Instant::now() < deadline, "no reply: {:?}", self.pending);
            if let Ok(n) = self.s.read(&mut buf) {
                assert!(n > 0, "server closed");
                self.pending.push_str(&String::from_utf8_lossy(&buf[..n]));
            }
        }
    }
    fn wait(&mut self, seconds: f64) {
        std::thread::sleep(Duration::from_secs_f64(seconds));
    }
    fn reconnect(&mut self) {
        let addr = self.srv.as_ref().unwrap().addr.clone();
        self.s.shutdown(std::net::Shutdown::Both).unwrap();
        // The device serves one client at a time: the new one is taken once the old one
        // is seen gone.
        self.s = TcpStream::connect(&addr).unwrap();
        self.s
            .set_read_timeout(Some(Duration::from_millis(20)))
            .unwrap();
        self.pending.clear();
    }
    fn restart(&mut self) {
        // The process ends (its store file stays, as a board's flash does).
        drop(self.srv.take());
        *self = Tcp::start(std::mem::take(&mut self.args), self.store.clone());
    }
}

fn local() -> Local {
    local_on(Scenario::default())
}

fn local_on(sc: Scenario) -> Local {
    Local {
        dev: Some(LocalDevice::new(&sc).unwrap()),
        sc,
    }
}

/// `hil-sim serve` on TCP with its store in `dir`, on the scenario file `scenario` if any.
fn tcp(dir: &Path, scenario: Option<&Path>) -> Tcp {
    let mut args = vec!["--tcp".to_string(), "127.0.0.1:0".to_string()];
    if let Some(p) = scenario {
        args.extend(["--scenario".to_string(), p.display().to_string()]);
    }
    Tcp::start(args, dir.join("flash.img"))
}

/// Runs `check` on both devices.
fn both(check: impl Fn(&mut dyn Dut)) {
    check(&mut local());
    let dir = tempfile::tempdir().unwrap();
    check(&mut tcp(dir.path(), None));
}

/// Runs `check` on both devices, both on the default scenario changed by `toml` (a scenario
/// file's text).
fn both_on(toml: &str, check: impl Fn(&mut dyn Dut)) {
    check(&mut local_on(
        Scenario::parse(toml, "test scenario").unwrap(),
    ));
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("scenario.toml");
    std::fs::write(&file, toml).unwrap();
    check(&mut tcp(dir.path(), Some(&file)));
}

/// The value of `key=` in a status or telemetry line.
fn field(line: &str, key: &str) -> f64 {
    line.split_whitespace()
        .find_map(|w| w.strip_prefix(key).and_then(|v| v.strip_prefix('=')))
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("no {key} in {line}"))
}

fn keys(line: &str) -> Vec<String> {
    line.split_whitespace()
        .skip(1)
        .filter_map(|w| w.split_once('=').map(|(k, _)| k.to_string()))
        .collect()
}

#[test]
fn status_keys_are_one_set() {
    let expect = [
        "mode",
        "enabled",
        "faults",
        "t",
        "pos",
        "error_counts",
        "moving",
        "current",
        "fault_names",
        "ff",
        "duty",
        "step_us_worst",
        "step_us_mean",
        "sense_offset",
        "missed",
        "drive",
        "configured",
    ];
    both(|d| {
        let st = d.ask("status");
        assert_eq!(keys(&st), expect);
        // The current-sense zero is measured at start as on the board (the plant's ADC reads
        // 0 A at code 2048 with 0.6 codes of noise).
        assert_eq!(field(&st, "faults"), 0.0, "{st}");
        assert_eq!(field(&st, "missed"), 0.0, "{st}");
        let zero = field(&st, "sense_offset");
        assert!(zero != 2048.0 && (zero - 2048.0).abs() < 0.5, "{st}");
    });
}

#[test]
fn enable_and_disable() {
    both(|d| {
        assert_eq!(d.ask("enable"), "ok");
        assert_eq!(field(&d.ask("status"), "enabled"), 1.0);
        assert_eq!(d.ask("disable"), "ok");
        assert_eq!(field(&d.ask("status"), "enabled"), 0.0);
        assert!(
            d.ask("move 0.01").starts_with("err 8 "),
            "move while disabled"
        );
    });
}

#[test]
fn a_second_move_mid_move_continues_the_reference() {
    both(|d| {
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
    });
}

#[test]
fn a_following_error_latches_and_clear_works() {
    both(|d| {
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
    });
}

#[test]
fn an_over_current_latches() {
    both(|d| {
        // A current loop far too stiff for the winding oscillates beyond the trip.
        assert_eq!(d.ask("set cur.kp 5000"), "ok");
        // It may trip before `enable` has answered ("not enabled (fault)").
        d.ask("enable");
        d.wait(0.1);
        let st = d.ask("status");
        assert!(st.contains("over_current"), "{st}");
        assert_eq!(field(&st, "enabled"), 0.0);
    });
}

#[test]
fn a_refused_set_changes_nothing() {
    both(|d| {
        assert!(d.ask("set gms.fs 1e-6").starts_with("err 7 "));
        assert_eq!(d.ask("get gms.fs"), "ok 0.00022");
        assert!(d.ask("set pos.kp 5000").starts_with("err 6 "));
        assert_eq!(d.ask("get pos.kp"), "ok 0.7");
        assert!(d.ask("set ff.adapt.scale 1.1").starts_with("err 8 "));
    });
}

#[test]
fn leaving_the_soft_limits_latches_position_limit() {
    both(|d| {
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
    });
}

#[test]
fn an_encoder_jump_latches() {
    // 100 000 counts (0.38 rad) in one period, far above 100 rad/s.
    let scenario = "[plant.encoder_glitch]\nat = 0.5\ncounts = 100000\n";
    both_on(scenario, |d| {
        // Enabled, or not yet if the server was slow: the jump latches either way.
        d.ask("enable");
        d.wait(0.8);
        let st = d.ask("status");
        assert!(st.contains("encoder_jump"), "{st}");
        assert_eq!(field(&st, "enabled"), 0.0);
        assert!(d.ask("enable").starts_with("err 8 "));
        // The encoder reads steadily again: clear and enable work, holding where it reads.
        assert_eq!(d.ask("clear"), "ok");
        assert_eq!(d.ask("enable"), "ok");
        d.wait(0.05);
        let st = d.ask("status");
        assert_eq!(field(&st, "faults"), 0.0, "{st}");
        assert!((field(&st, "pos") - 0.38).abs() < 1e-3, "{st}");
    });
}

#[test]
fn save_restart_load() {
    both(|d| {
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
        assert_eq!(d.ask("get pos.kp"), "ok 0.7");
        assert_eq!(d.ask("load"), "ok");
        assert_eq!(d.ask("get pos.kp"), "ok 0.25");
        assert_eq!(d.ask("get ff.mode"), "ok gms-adaptive");
        // Save and load refuse while the bridge drives.
        assert_eq!(d.ask("enable"), "ok");
        assert!(d.ask("save").starts_with("err 8 "));
        assert!(d.ask("load").starts_with("err 8 "));
    });
}

/// The largest |error| \[counts\] in the telemetry lines.
fn peak_error(lines: &[String]) -> f64 {
    lines
        .iter()
        .filter(|l| l.starts_with('#'))
        .map(|l| field(l, "error").abs() / 3.8e-6)
        .fold(0.0, f64::max)
}

/// A slow move, with `before` set (if any) ahead of it; at 0.2 s `set` (if any); the error's
/// peak over the next 150 ms.
fn error_after(d: &mut dyn Dut, before: Option<&str>, set: Option<&str>) -> f64 {
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

/// The live sets of the bumpless check: each gain, a friction parameter, a mode change.
const LIVE_SETS: [&str; 7] = [
    "set ff.gain 0.94",
    "set ff.gain 0.9",
    "set pos.kp 0.77",
    "set pos.ki 660",
    "set cur.kp 1.65",
    "set gms.fc 1.3e-4",
    "set ff.mode gms-adaptive",
];

/// A set made live is no worse than either setting held throughout: its peak error after
/// the set within 20 % + 0.5 counts of the larger of the run without the set and the run
/// with it made before the move (in simulated time both are exact references; a new mode
/// such as `gms-adaptive` then adapts as it would have from the start).
#[test]
fn live_sets_are_bumpless() {
    let base = error_after(&mut local(), None, None);
    assert!(base > 0.2 && base < 5.0, "{base}");
    for set in LIVE_SETS {
        let held = error_after(&mut local(), Some(set), None);
        let e = error_after(&mut local(), None, Some(set));
        eprintln!("{set}: peak {e:.2} counts (without: {base:.2}, held throughout: {held:.2})");
        let bound = base.max(held);
        assert!(
            e <= bound * 1.2 + 0.5,
            "{set}: peak {e} counts against {base} and {held}"
        );
    }
}

#[test]
fn live_sets_are_bumpless_over_tcp() {
    // In real time every request lands at another step each run, so no two runs are alike
    // (without a set, peaks of 1.1 to 2.5 counts were seen): the current-sense noise is off,
    // the reference is the worst of four runs without a set (or one with the set held
    // throughout, if worse), with a margin of 20 % and one count. A set that restarted the controller peaked at 34 counts in this move.
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("quiet.toml");
    std::fs::write(&file, "[plant]\nadc_noise = 0.0\n").unwrap();
    let base = (0..4)
        .map(|_| error_after(&mut tcp(dir.path(), Some(&file)), None, None))
        .fold(0.0, f64::max);
    assert!(base > 0.2 && base < 5.0, "{base}");
    for set in LIVE_SETS {
        let held = error_after(&mut tcp(dir.path(), Some(&file)), Some(set), None);
        let e = error_after(&mut tcp(dir.path(), Some(&file)), None, Some(set));
        eprintln!("{set}: peak {e:.2} counts (without: {base:.2}, held throughout: {held:.2})");
        let bound = base.max(held);
        assert!(
            e <= bound * 1.2 + 1.0,
            "{set}: peak {e} counts against {base} and {held}"
        );
    }
}

/// The word after `key=` in a status line.
fn word<'a>(line: &'a str, key: &str) -> &'a str {
    line.split_whitespace()
        .find_map(|w| w.strip_prefix(key).and_then(|v| v.strip_prefix('=')))
        .unwrap_or_else(|| panic!("no {key} in {line}"))
}

#[test]
fn current_mode_pushes_and_hold_takes_position_back() {
    both(|d| {
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
    });
}

#[test]
fn velocity_mode_runs_and_hold_stops_it() {
    both(|d| {
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
    });
}

#[test]
fn a_lost_link_ends_an_experiment_but_not_a_hold() {
    both(|d| {
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
    });
}

#[test]
fn capture_records_at_the_control_rate_and_reads_back() {
    both(|d| {
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
    });
}
