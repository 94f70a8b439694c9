//! A board's faults, thrown at the shipped image on emulated silicon (`REHOST_ELF`, the
//! Nucleo's): a dead current-sense chain, one conversion at an end of the ADC's range, an
//! encoder that stops counting or jumps, a control step that hangs (the deadman, then the
//! watchdog), control steps that start late and write their duty past the update, a power cut
//! at every flash write of a `save`. Each asserts what the image does: the bridge, the faults latched, the log line,
//! what survives. (No HSE is `rehost check`'s; an over-current and a request cut by a lost
//! link are the conformance suite's, `conformance.rs`.)

use rehost::{Board, Machine, Options};

use crate::support;
use support::{ask, log};

/// The control interrupt (DMA2 stream 0, IRQ 56).
const CONTROL: u32 = 16 + 56;
/// One PWM period \[s\] (40 kHz, the default `rate.cur_hz`).
const PERIOD: f64 = 25e-6;

/// The image from reset, `before` applied before its first instruction; booted to its loop
/// (or to `until`, a log line).
fn boot_with(before: impl FnOnce(&mut Machine), until: &str) -> Machine {
    let elf = std::fs::read(support::elf()).unwrap();
    let board = Board::of_image(&elf).expect("a gms image");
    let mut m = Machine::new(&elf, board, Options::default()).unwrap();
    before(&mut m);
    m.run_until_logged(until, 1.0)
        .unwrap_or_else(|e| panic!("boot: {e}\n{}", log(&m)));
    if m.logged("control loop running") {
        // The F405's USB enumerated and its port opened (the Nucleo's UART is ready).
        m.link_ready(1.0)
            .unwrap_or_else(|e| panic!("the link: {e}\n{}", log(&m)));
    }
    m
}

fn boot() -> Machine {
    boot_with(|_| {}, "control loop running")
}

fn status(m: &mut Machine) -> String {
    ask(m, "status")
}

/// The status, which must say the bridge is off with one of `faults` latched.
fn off_with(m: &mut Machine, faults: &[&str]) -> String {
    let st = status(m);
    assert!(
        faults.iter().any(|f| st.contains(f)) && st.contains("enabled=0"),
        "{st}"
    );
    st
}

/// The image booted, enabled, holding and its bridge driving 10 ms later.
fn driving() -> Machine {
    let mut m = boot();
    assert!(ask(&mut m, "enable").starts_with("ok"));
    m.run_for(0.01).unwrap();
    assert!(m.bridge_driving());
    m
}

/// Runs until the bridge no longer drives (its outputs off, or both inputs low: coasting),
/// in steps of 5 µs, at most `seconds`; the time it took.
fn until_bridge_off(m: &mut Machine, seconds: f64) -> Option<f64> {
    let t0 = m.seconds();
    while m.seconds() - t0 < seconds {
        if !m.bridge_driving() {
            return Some(m.seconds() - t0);
        }
        m.run_for(5e-6).unwrap();
    }
    None
}

/// The current-sense amplifier unpowered (every conversion 0): at start the zero is out of
/// its window, `current_sense` latches and is logged; the image runs on (no boot loop, no
/// reset over 6 s), the bridge stays off and `enable` is refused.
#[test]
fn a_dead_current_sense_latches_current_sense_and_keeps_the_bridge_off() {
    let mut m = boot_with(
        |m| m.chip_mut().inject.sense_code = Some(0),
        "control loop running",
    );
    assert!(
        m.logged("current_sense: zero at 0.0 codes"),
        "the log:\n{}",
        log(&m)
    );
    off_with(&mut m, &["current_sense"]);
    assert!(ask(&mut m, "enable").starts_with("err 8"));
    m.run_for(0.001).unwrap();
    assert!(!m.bridge_driving());
    m.run_for(6.0).unwrap();
    assert_eq!(m.resets, 0, "a boot loop:\n{}", log(&m));
    assert!(status(&mut m).contains("current_sense"));
    // Cleared anyway: the dead chain reads -0.5 A against the nominal zero, and the first
    // step trips over_current.
    assert!(ask(&mut m, "clear").starts_with("ok"));
    let _ = ask(&mut m, "enable");
    assert!(until_bridge_off(&mut m, 0.001).is_some());
    off_with(&mut m, &["over_current"]);
}

/// The encoder stops counting in the middle of a move (its cable cut): the loop pushes
/// against a position that does not change, the current command saturates at `lim.i_max`
/// (0.4 A by default, under the over-current trip at 0.46 A: 95 % of the 0.485 A the 3.4 V/A
/// sense shows) until `following_error` latches (or `over_current`, where a board's limit is
/// set above its trip); the bridge goes off, and stays off.
#[test]
fn an_encoder_that_stops_counting_switches_the_bridge_off() {
    let mut m = boot();
    assert!(ask(&mut m, "enable").starts_with("ok"));
    assert!(ask(&mut m, "move 0.5").starts_with("ok"));
    m.run_for(0.02).unwrap();
    assert!(m.bridge_driving());
    m.chip_mut().inject.encoder_frozen = true;
    let off = until_bridge_off(&mut m, 1.0).expect("the bridge stayed on");
    let st = off_with(&mut m, &["over_current", "following_error"]);
    eprintln!(
        "encoder stopped: bridge off after {:.1} ms; {st}",
        off * 1e3
    );
    m.run_for(0.01).unwrap();
    assert!(!m.bridge_driving());
}

/// The encoder jumps 100 000 counts (0.38 rad in one period: 7,600 rad/s): `encoder_jump`
/// latches at the next position step and the bridge goes off within it: at most one position
/// period (two PWM periods at the default rates) after the jump, plus the step's length (at
/// most its budget, 60 % of a period), plus the 5 µs this test polls at.
#[test]
fn an_encoder_jump_latches_encoder_jump_within_two_periods() {
    let mut m = driving();
    m.encoder_jump(100_000);
    let off = until_bridge_off(&mut m, 0.01).expect("the bridge stayed on");
    assert!(off <= 2.0 * PERIOD + 0.6 * PERIOD + 5e-6, "{off} s");
    off_with(&mut m, &["encoder_jump"]);
}

/// The control step hangs (its handler a `b .`): the deadman above it switches the bridge
/// off at the second period's tick without a step (`Deadman::LIMIT`), within two PWM periods
/// of the hung step's start, which comes at most one period after the patch: three periods
/// from the patch at most, plus the 10 µs of the deadman's entry and this test's polling;
/// the supervisor, starved, no longer feeds the watchdog, which
/// resets the board within its 4 s; the next boot says so (`reset by the watchdog`, the
/// `watchdog_reset` fault latched, `enable` refused until `clear`) and runs again.
#[test]
fn a_hung_control_step_is_cut_off_by_the_deadman_then_the_watchdog() {
    let mut m = driving();
    m.hang_handler(CONTROL).unwrap();
    let off = until_bridge_off(&mut m, 0.01).expect("the deadman did not switch the bridge off");
    assert!(off <= 3.0 * PERIOD + 10e-6, "bridge off after {off} s");
    // Starved: no reset before the watchdog's 4 s (the LSI at 32 kHz: 4 s nominal; RM0390's
    // LSI range 17-47 kHz gives 2.7-7.5 s), one after.
    let t0 = m.seconds();
    while m.resets == 0 && m.seconds() - t0 < 8.0 {
        m.run_for(0.05).unwrap();
        assert!(
            !m.bridge_driving() || m.resets > 0,
            "the bridge came back on while hung"
        );
    }
    assert_eq!(m.resets, 1, "no watchdog reset:\n{}", log(&m));
    let waited = m.seconds() - t0;
    assert!(
        (3.0..5.0).contains(&waited),
        "the watchdog after {waited} s"
    );
    assert!(
        m.watchdog_resets.len() == 1 && m.watchdog_resets[0].contains("the watchdog reset"),
        "{:?}",
        m.watchdog_resets
    );
    let booted = |m: &Machine| {
        m.log_lines
            .iter()
            .filter(|l| l.text.contains("control loop running"))
            .count()
    };
    let t1 = m.seconds();
    while booted(&m) < 2 && m.seconds() - t1 < 1.0 {
        m.run_for(0.001).unwrap();
    }
    assert_eq!(booted(&m), 2, "after the reset:\n{}", log(&m));
    assert!(m.logged("reset by the watchdog"), "{}", log(&m));
    off_with(&mut m, &["watchdog_reset"]);
    assert!(ask(&mut m, "enable").starts_with("err 8"));
    assert!(ask(&mut m, "clear").starts_with("ok"));
    assert!(ask(&mut m, "enable").starts_with("ok"));
    m.run_for(0.01).unwrap();
    assert!(m.bridge_driving(), "the loop runs again after the reset");
    eprintln!(
        "hung step: bridge off after {:.1} µs, the watchdog reset after {waited:.2} s",
        off * 1e6
    );
}

/// The value of `pos.kp` the image runs, and whether it started on a stored set without
/// complaint.
fn kp_after_power_cycle(m: &mut Machine) -> (String, String) {
    m.power_cycle().unwrap();
    m.run_until_logged("control loop running", 1.0)
        .unwrap_or_else(|e| panic!("after the power cycle: {e}\n{}", log(m)));
    (ask(m, "get pos.kp"), status(m))
}

/// A power cut at every flash write of a `save` (each program store landing on its low half
/// only, or an erase on half its sector, then nothing): after the power comes back the image
/// runs the old settings or the new, never neither, never a mix, and answers. One machine
/// throughout, its flash put back to the old save before each cut.
#[test]
fn a_power_cut_at_every_flash_write_of_a_save_leaves_the_old_or_the_new() {
    const OLD: &str = "0.61";
    const NEW: &str = "0.73";
    let mut m = boot();
    assert!(ask(&mut m, &format!("set pos.kp {OLD}")).starts_with("ok"));
    assert!(
        m.request("save", 3.0)
            .unwrap()
            .last()
            .unwrap()
            .starts_with("ok")
    );
    let saved_old = m.flash().unwrap();
    // The writes a save of NEW takes, uncut.
    let w0 = m.chip().inject.flash_writes;
    assert!(ask(&mut m, &format!("set pos.kp {NEW}")).starts_with("ok"));
    assert!(
        m.request("save", 3.0)
            .unwrap()
            .last()
            .unwrap()
            .starts_with("ok")
    );
    let writes = m.chip().inject.flash_writes - w0;
    assert!(writes > 0);
    let (kp, _) = kp_after_power_cycle(&mut m);
    assert_eq!(kp, format!("ok {NEW}"));
    // Every write (REHOST_EVERY_WRITE=1, 1,098 cuts, about 2 min), or every one of the first
    // 96 (the parameter record and its commit: the new set lands at the 70th), every 16th
    // of the rest (the position map's) and the last 8.
    let every = std::env::var_os("REHOST_EVERY_WRITE").is_some();
    let cuts: Vec<u64> = (1..=writes)
        .filter(|&k| every || k <= 96 || k % 16 == 0 || k + 8 > writes)
        .collect();
    let (mut old, mut new) = (0, 0);
    for &k in &cuts {
        m.set_flash(&saved_old).unwrap();
        let (kp, st) = kp_after_power_cycle(&mut m);
        assert_eq!(kp, format!("ok {OLD}"), "{st}");
        assert!(ask(&mut m, &format!("set pos.kp {NEW}")).starts_with("ok"));
        let w = m.chip().inject.flash_writes;
        m.chip_mut().inject.cut_at_flash_write = Some(w + k);
        // No reply: the supply fails during the save.
        assert!(m.request("save", 0.5).is_err(), "cut at write {k}");
        assert!(m.chip().inject.power_lost);
        let (kp, st) = kp_after_power_cycle(&mut m);
        match kp.as_str() {
            l if l == format!("ok {OLD}") => old += 1,
            l if l == format!("ok {NEW}") => new += 1,
            _ => panic!(
                "cut at write {k} of {writes}: pos.kp {kp}; {st}\n{}",
                log(&m)
            ),
        }
        assert!(
            !st.contains("invalid_params"),
            "cut at write {k}: {st}\n{}",
            log(&m)
        );
    }
    eprintln!(
        "a save is {writes} flash writes; cut at {} of them: {old} came back old, {new} new",
        cuts.len()
    );
    assert!(old > 0 && new > 0, "{old} old, {new} new");
}

/// A value of a `status` reply.
fn value(st: &str, key: &str) -> f64 {
    st.split_whitespace()
        .find_map(|w| w.strip_prefix(key)?.strip_prefix('='))
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("no {key} in {st}"))
}

/// The deadline, not only the length: control steps that start late (held off by something
/// above them, here 1,800 cycles) while the axis moves, so that a long one ends past the PWM
/// update its duty was for. Each is caught by the timer's counter read after the duty is
/// written: `overrun` latched, the bridge off, counted as `late` — not as a missed period
/// (the steps stay less than 1.5 periods apart) nor by length (each runs as long as ever).
/// Started 300 cycles late, every step still writes in time: nothing latched.
#[test]
fn a_step_that_writes_its_duty_past_the_update_is_an_overrun() {
    let mut m = driving();
    assert!(ask(&mut m, "move 0.02").starts_with("ok"));
    m.start_late(CONTROL, 300, 400);
    m.run_for(0.012).unwrap();
    let st = status(&mut m);
    assert!(
        st.contains("enabled=1") && st.contains("fault_names=none"),
        "{st}"
    );
    assert_eq!(
        (value(&st, "late"), value(&st, "missed")),
        (0.0, 0.0),
        "{st}"
    );

    let mut m = driving();
    assert!(ask(&mut m, "move 0.02").starts_with("ok"));
    m.start_late(CONTROL, 1800, 400);
    m.run_for(0.012).unwrap();
    assert!(!m.bridge_driving());
    let st = off_with(&mut m, &["overrun"]);
    assert!(value(&st, "late") >= 1.0, "{st}");
    assert_eq!(value(&st, "missed"), 0.0, "{st}");
    // Not by length: the longest step within the 18.75 µs budget of a 25 µs period.
    assert!(value(&st, "step_us_worst") < 18.75, "{st}");
}

/// One conversion of one period past the amplifier's linear range (0.2 V inside each rail:
/// below 249 or above 3846 codes, the thresholds gms-core works out) or at an end of the
/// ADC's range (a spike the average of eight hides: 2048 + 2047/8 codes is 0.06 A, far below
/// the trip) while the bridge drives: the ADC's analog watchdog sees it, the step latches
/// `over_current` and switches the bridge off. One conversion one code inside the linear
/// range at either end: nothing. (With the watchdog at 1 and 4094, which the INA240's output
/// never reaches, 3847 and 248 went unseen.)
#[test]
fn one_conversion_past_the_senses_linear_range_latches_over_current() {
    for inside in [3846, 249] {
        let mut m = driving();
        m.chip_mut().inject.sense_code_once = Some(inside);
        m.run_for(0.002).unwrap();
        assert!(m.chip().inject.sense_code_once.is_none());
        let st = status(&mut m);
        assert!(
            st.contains("enabled=1") && st.contains("fault_names=none"),
            "{inside}: {st}"
        );
    }
    for end in [3847, 248, 4095, 0] {
        let mut m = driving();
        m.chip_mut().inject.sense_code_once = Some(end);
        m.run_for(0.002).unwrap();
        assert!(!m.bridge_driving(), "{end}");
        off_with(&mut m, &["over_current"]);
    }
}

/// The HSE fails while the bridge drives: the clock failure at TIM8's break input clears MOE
/// in hardware, so the bridge is off before the core has run one instruction of the NMI (the
/// NMI's `bridge_off_now` only follows; without the break input the outputs stayed on until
/// then).
#[test]
fn a_clock_failure_switches_the_bridge_off_in_hardware() {
    let mut m = driving();
    assert!(m.bridge_on());
    m.hse_fails();
    assert!(
        !m.bridge_on(),
        "the outputs still on after the clock failure event"
    );
    m.run_until_logged("the HSE failed", 0.5).unwrap();
    assert!(!m.bridge_driving());
}

/// The deadman (TIM8's update, IRQ 44) is armed once the loop has taken its first step: its
/// first tick comes after the control interrupt's first run, never in the gap before the loop
/// starts (armed first, it ticked up to a period before the first step).
#[test]
fn the_deadman_starts_after_the_loops_first_step() {
    const DEADMAN: u32 = 16 + 44;
    let m = boot();
    let first = |exc: u32| m.handled.iter().find(|h| h.exc == exc).map(|h| h.at);
    let (step, tick) = (first(CONTROL), first(DEADMAN));
    let (Some(step), Some(tick)) = (step, tick) else {
        panic!(
            "no step ({step:?}) or no deadman tick ({tick:?})\n{}",
            log(&m)
        );
    };
    assert!(
        tick > step,
        "the deadman's first tick at cycle {tick}, the loop's first step at {step}"
    );
}

/// A chip with its option bytes as they come from the factory (brown-out reset off): the
/// image programs level 3 (2.7 V) at its first boot, keeping the rest of the option bytes,
/// and finds it set at the next; a part that refuses the programming refuses `enable` with
/// the reason, and logs it.
#[test]
fn the_brown_out_reset_is_set_at_the_first_boot_or_enable_is_refused() {
    let mut m = boot();
    assert!(
        m.logged("brown-out reset set to 2.7 V (option bytes programmed)"),
        "{}",
        log(&m)
    );
    let optcr = m.chip().p.flash.read(0x14);
    assert_eq!(optcr & 0b1100, 0, "BOR_LEV: level 3");
    assert_eq!(
        optcr & 0xFFFF_FF00,
        0x0FFF_AA00,
        "read and write protection kept"
    );
    m.power_cycle().unwrap();
    m.run_until_logged("control loop running", 1.0).unwrap();
    assert!(
        m.log_lines
            .iter()
            .any(|l| l.text == "brown-out reset at 2.7 V"),
        "{}",
        log(&m)
    );
    assert!(ask(&mut m, "enable").starts_with("ok"));

    let mut m = boot_with(
        |m| m.chip_mut().p.flash.refuse_options = true,
        "control loop running",
    );
    assert!(m.logged("could not be programmed"), "{}", log(&m));
    let reply = ask(&mut m, "enable");
    assert!(
        reply.starts_with("err 8 brown-out reset not at 2.7 V"),
        "{reply}"
    );
    m.run_for(0.001).unwrap();
    assert!(!m.bridge_driving());
}

/// One byte of a request arrives with a framing error (noise on the line): the request is
/// not run, its reply is `err 9`, and the next request is served as usual.
#[test]
fn a_byte_damaged_on_the_line_refuses_its_request_with_err_9() {
    let mut m = boot();
    if m.board() == Board::F405 {
        // USB: a damaged packet fails its CRC and the host sends it again (USB 2.0 §8.3.5);
        // none reaches the firmware.
        eprintln!("the F405's link is USB: no damaged byte reaches the image");
        return;
    }
    let kp = ask(&mut m, "get pos.kp");
    // "set pos.kp 0.55", its '5' of "0.55" damaged (it arrives as sent: only the flag says).
    let line = b"set pos.kp 0.55\n";
    let _ = m.take_from_image();
    m.send_damaged_to_image(line, 13);
    m.run_for(0.01).unwrap();
    let reply = String::from_utf8_lossy(&m.take_from_image()).to_string();
    assert!(
        reply.starts_with("err 9 line damaged on the link"),
        "{reply:?}"
    );
    assert_eq!(ask(&mut m, "get pos.kp"), kp, "the damaged request ran");
    assert!(ask(&mut m, "set pos.kp 0.55").starts_with("ok"));
}

/// A host that sends requests far faster than the replies go out (250 `list`s at once: 1,250
/// bytes against a 1,024-byte ring, each reply 14 ms of the line): the ring would lap. The
/// image finds it, drops what it has not read and answers the line in progress `err 9`; no
/// request is cut and run as another (before, the lapped ring's bytes ran as `lisst`: `err
/// 1`), and the next request is served. Over the F405's USB the device NAKs what it has no
/// room for and the host sends it again: every request is answered, none with an error.
#[test]
fn a_lapped_receive_ring_drops_its_bytes_with_err_9() {
    let mut m = boot();
    let _ = m.take_from_image();
    let usb = m.board() == Board::F405;
    m.send_to_image(&b"list\n".repeat(250));
    // Until the host's bytes are all on the line and the image has sent nothing for 0.1 s
    // (at most 5 s of device time: all 250 replies take 3.5 s).
    let mut text = String::new();
    let mut quiet = 0;
    for _ in 0..500 {
        m.run_for(0.01).unwrap();
        let out = m.take_from_image();
        quiet = if out.is_empty() { quiet + 1 } else { 0 };
        text.push_str(&String::from_utf8_lossy(&out));
        let sent = m.chip().p.usart2.from_host.is_empty() && m.usb_host().from_host.is_empty();
        if sent && quiet >= 10 {
            break;
        }
    }
    let ends: Vec<&str> = text
        .lines()
        .filter(|l| l.starts_with("ok") || l.starts_with("err"))
        .collect();
    if usb {
        let errs: Vec<_> = ends.iter().filter(|l| !l.starts_with("ok")).collect();
        assert!(errs.is_empty(), "{errs:?}");
        assert_eq!(ends.len(), 250, "every request answered over USB");
        assert!(status(&mut m).starts_with("ok"));
        return;
    }
    let lost = ends.iter().filter(|l| l.starts_with("err 9")).count();
    let other: Vec<_> = ends
        .iter()
        .filter(|l| l.starts_with("err") && !l.starts_with("err 9"))
        .collect();
    assert!(lost >= 1, "no err 9 in {} replies: {ends:?}", ends.len());
    assert!(other.is_empty(), "{other:?}");
    assert!(
        ends.len() < 250,
        "{} replies: nothing was dropped",
        ends.len()
    );
    m.run_for(0.05).unwrap();
    assert!(status(&mut m).starts_with("ok"));
}

/// A control step held off so long (2,800 cycles, 16.7 µs at 168 MHz) that the sense's DMA
/// has begun the next period's sequence in the one buffer it has (16.0 µs after the step's
/// due start at 40 kHz): the step sees the stream's count under way, takes the sum for no
/// reading, latches `overrun` and switches the bridge off before it drives on it, so it is
/// counted neither `missed` nor `late`. Before the check the same step drove on the mixed sum;
/// it latched `overrun` only as a missed period (41.7 µs since the last start), which a late
/// step after another late step is not.
#[test]
fn a_step_that_starts_after_the_next_sequence_does_not_drive_on_its_sum() {
    let mut m = driving();
    assert!(ask(&mut m, "move 0.02").starts_with("ok"));
    m.start_late(CONTROL, 2800, 1);
    m.run_for(0.002).unwrap();
    assert!(!m.bridge_driving());
    let st = off_with(&mut m, &["overrun"]);
    assert_eq!(
        (value(&st, "late"), value(&st, "missed")),
        (0.0, 0.0),
        "{st}"
    );
}
