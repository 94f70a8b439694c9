//! One conformance suite of protocol exchanges, run against the device core in-process (with
//! the simulated plant, in simulated time) and against `hil-sim serve` over TCP (real time):
//! both are gms-core's device core, so both must answer alike.

use std::time::Duration;

use std::path::{Path, PathBuf};

use hil_sim::device::LocalDevice;
use hil_sim::scenario::Scenario;

use crate::common;
use crate::suite;
use common::Server;
use suite::{Dut, TcpLink, error_after, field, keys};

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
    fn send_bytes(&mut self, _bytes: &[u8]) {
        // The in-process device takes whole lines only (each `ask` its own): a half line
        // never reaches it.
    }
}

struct Tcp {
    srv: Option<Server>,
    link: TcpLink,
    args: Vec<String>,
    store: PathBuf,
}

impl Tcp {
    fn start(args: Vec<String>, store: PathBuf) -> Tcp {
        let a: Vec<&str> = args.iter().map(String::as_str).collect();
        let srv = common::serve(&a, &store);
        let link = TcpLink::connect(&srv.addr);
        Tcp {
            srv: Some(srv),
            link,
            args,
            store,
        }
    }
}

impl Dut for Tcp {
    fn ask_all(&mut self, line: &str) -> Vec<String> {
        let reply = self.link.exchange(line, Duration::from_secs(10));
        reply.unwrap_or_else(|| panic!("no reply: {:?}", self.link.pending()))
    }
    fn wait(&mut self, seconds: f64) {
        std::thread::sleep(Duration::from_secs_f64(seconds));
    }
    fn reconnect(&mut self) {
        let addr = self.srv.as_ref().unwrap().addr.clone();
        self.link.reconnect(&addr);
    }
    fn send_bytes(&mut self, bytes: &[u8]) {
        self.link.send_bytes(bytes);
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

#[test]
fn a_sense_zero_off_mid_scale_refuses_a_limit_it_cannot_reach() {
    both_on(
        suite::SENSE_ZERO_LOW,
        suite::a_sense_zero_off_mid_scale_refuses_a_limit_it_cannot_reach,
    );
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
        "late",
        "duty_max",
        "duty_limited",
        "supply",
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
        assert_eq!(field(&st, "late"), 0.0, "{st}");
        let zero = field(&st, "sense_offset");
        assert!(zero != 2048.0 && (zero - 2048.0).abs() < 0.5, "{st}");
    });
}

#[test]
fn enable_and_disable() {
    both(suite::enable_and_disable);
}

#[test]
fn a_second_move_mid_move_continues_the_reference() {
    both(suite::a_second_move_mid_move_continues_the_reference);
}

#[test]
fn a_following_error_latches_and_clear_works() {
    both(suite::a_following_error_latches_and_clear_works);
}

#[test]
fn an_over_current_latches() {
    both(suite::an_over_current_latches);
}

#[test]
fn a_refused_set_changes_nothing() {
    both(suite::a_refused_set_changes_nothing);
}

#[test]
fn a_half_request_of_a_lost_link_is_not_run() {
    both(suite::a_half_request_of_a_lost_link_is_not_run);
}

#[test]
fn leaving_the_soft_limits_latches_position_limit() {
    both(suite::leaving_the_soft_limits_latches_position_limit);
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
    both(suite::save_restart_load);
}

/// The live sets of the bumpless check: each gain, a friction parameter, a mode change.
const LIVE_SETS: [&str; 7] = [
    "set ff.gain 0.94",
    "set ff.gain 0.9",
    "set pos.kp 0.66",
    "set pos.ki 990",
    "set cur.kp 13.2",
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

#[test]
fn current_mode_pushes_and_hold_takes_position_back() {
    both(suite::current_mode_pushes_and_hold_takes_position_back);
}

#[test]
fn velocity_mode_runs_and_hold_stops_it() {
    both(suite::velocity_mode_runs_and_hold_stops_it);
}

#[test]
fn a_lost_link_ends_an_experiment_but_not_a_hold() {
    both(suite::a_lost_link_ends_an_experiment_but_not_a_hold);
}

#[test]
fn capture_records_at_the_control_rate_and_reads_back() {
    both(suite::capture_records_at_the_control_rate_and_reads_back);
}
