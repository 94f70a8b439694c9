//! The conformance suite (`hil-sim/tests/suite`, the checks hil-sim runs against its virtual
//! device) against the shipped firmware image: the Nucleo ELF that `cargo fw-f446` builds,
//! run by `rehost serve` on emulated silicon, its USART2 bridged to TCP, the plant hil-sim's.
//!
//! The image is named by `REHOST_ELF` (CI sets it to the Nucleo image it has just built; a
//! relative path is from the workspace's root).
//!
//! All twelve of the suite's checks run here. `save_restart_load` restarts `rehost serve` on
//! the flash file it stored to (`--flash`). The Nucleo's USART2 cannot tell that its host went
//! away (`Port::host_here` is always true there; the F405's USB tells by DTR): the next host's
//! CAN (`protocol::CANCEL`) ends the last one's experiment, which
//! `a_lost_link_ends_an_experiment_but_not_a_hold` checks.
//!
//! `velocity` overran the control period on the image until its position was integrated in
//! fixed point (the software f64 took a constant-speed step to 2,105 instructions and the
//! step taking `velocity` to 3,249, against 2,000): these checks found it.
//!
//! The emulator runs slower than a board, so a wait is in the device's own time: `status`'s
//! `t=` polled until it has passed.

use std::time::Duration;

use crate::suite;
use suite::{Dut, TcpLink, field};

use crate::support;
use support::Served;

/// Wall time for one reply at most: the emulator at a tenth of a board's speed or less (a
/// loaded machine) still answers a `status` within a second.
const REPLY_WITHIN: Duration = Duration::from_secs(60);

/// `rehost serve` on the image, and the host's end of its TCP bridge.
struct Image {
    served: Served,
    link: TcpLink,
    /// Telemetry lines received while waiting, handed out with the next reply.
    telemetry: Vec<String>,
    /// The board's flash (`rehost serve --flash`), in a directory of its own.
    flash: std::path::PathBuf,
    _dir: tempfile::TempDir,
}

impl Image {
    /// The image from reset, served on a free port, its flash erased.
    fn start() -> Image {
        Self::start_on(None)
    }

    /// As [`Image::start`], the plant the scenario `toml` (a scenario file's text) if any.
    fn start_on(toml: Option<&str>) -> Image {
        let dir = tempfile::tempdir().unwrap();
        let flash = dir.path().join("flash.bin");
        let mut args = vec!["--flash".to_string(), flash.display().to_string()];
        if let Some(toml) = toml {
            let file = dir.path().join("scenario.toml");
            std::fs::write(&file, toml).unwrap();
            args.extend(["--scenario".to_string(), file.display().to_string()]);
        }
        let served = Self::serve(&args);
        let link = TcpLink::connect(&served.addr);
        Image {
            served,
            link,
            telemetry: Vec::new(),
            flash,
            _dir: dir,
        }
    }

    fn serve(args: &[String]) -> Served {
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        Served::start(&args, REPLY_WITHIN)
    }

    /// Device time \[s\]: `status`'s `t=`, its telemetry kept for the next reply.
    fn now(&mut self) -> f64 {
        let mut lines = self.exchange("status");
        let reply = lines.pop().unwrap_or_default();
        self.telemetry.extend(lines);
        field(&reply, "t")
    }

    fn exchange(&mut self, line: &str) -> Vec<String> {
        self.link.exchange(line, REPLY_WITHIN).unwrap_or_else(|| {
            panic!(
                "no reply to {line:?}: {:?}\nthe image's log:\n{}",
                self.link.pending(),
                self.served.log_text()
            )
        })
    }
}

impl Dut for Image {
    fn ask_all(&mut self, line: &str) -> Vec<String> {
        let mut lines = std::mem::take(&mut self.telemetry);
        lines.extend(self.exchange(line));
        lines
    }
    fn wait(&mut self, seconds: f64) {
        let until = self.now() + seconds;
        while self.now() < until {
            std::thread::sleep(Duration::from_millis(2));
        }
    }
    fn restart(&mut self) {
        // The process ends (as the supply does); the flash file stays.
        self.served.stop();
        self.served = Self::serve(&["--flash".to_string(), self.flash.display().to_string()]);
        self.link = TcpLink::connect(&self.served.addr);
        self.telemetry.clear();
    }
    fn reconnect(&mut self) {
        self.link.reconnect(&self.served.addr);
        self.telemetry.clear();
    }
    fn send_bytes(&mut self, bytes: &[u8]) {
        self.link.send_bytes(bytes);
    }
}

/// One check on a freshly booted image.
fn on_image(check: fn(&mut dyn Dut)) {
    check(&mut Image::start());
}

#[test]
fn enable_and_disable() {
    on_image(suite::enable_and_disable);
}

#[test]
fn a_second_move_mid_move_continues_the_reference() {
    on_image(suite::a_second_move_mid_move_continues_the_reference);
}

#[test]
fn a_following_error_latches_and_clear_works() {
    on_image(suite::a_following_error_latches_and_clear_works);
}

#[test]
fn a_sense_zero_off_mid_scale_refuses_a_limit_it_cannot_reach() {
    suite::a_sense_zero_off_mid_scale_refuses_a_limit_it_cannot_reach(&mut Image::start_on(Some(
        suite::SENSE_ZERO_LOW,
    )));
}

#[test]
fn an_over_current_latches() {
    on_image(suite::an_over_current_latches);
}

#[test]
fn a_refused_set_changes_nothing() {
    on_image(suite::a_refused_set_changes_nothing);
}

#[test]
fn a_half_request_of_a_lost_link_is_not_run() {
    on_image(suite::a_half_request_of_a_lost_link_is_not_run);
}

#[test]
fn save_restart_load() {
    on_image(suite::save_restart_load);
}

#[test]
fn a_lost_link_ends_an_experiment_but_not_a_hold() {
    on_image(suite::a_lost_link_ends_an_experiment_but_not_a_hold);
}

#[test]
fn leaving_the_soft_limits_latches_position_limit() {
    on_image(suite::leaving_the_soft_limits_latches_position_limit);
}

#[test]
fn current_mode_pushes_and_hold_takes_position_back() {
    on_image(suite::current_mode_pushes_and_hold_takes_position_back);
}

#[test]
fn velocity_mode_runs_and_hold_stops_it() {
    on_image(suite::velocity_mode_runs_and_hold_stops_it);
}

#[test]
fn capture_records_at_the_control_rate_and_reads_back() {
    on_image(suite::capture_records_at_the_control_rate_and_reads_back);
}
