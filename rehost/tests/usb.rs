//! The F405's USB link's faults, on the image (`REHOST_ELF` the F405's: on the Nucleo's image
//! each test says so and passes, its link being the UART's tests): the cable pulled in the
//! middle of a reply, DTR dropped and raised, a host that stops reading while telemetry
//! streams, requests split across packets and one ending exactly at a packet's end; through
//! each the control loop misses no period.

use rehost::{Board, Machine, Options};

use crate::support;
use support::{ask, log};

/// The F405 image booted, enumerated and its port open; none for another board's image.
fn boot() -> Option<Machine> {
    let elf = std::fs::read(support::elf()).unwrap();
    if Board::of_image(&elf) != Some(Board::F405) {
        eprintln!("not the F405's image: its USB tests do not apply");
        return None;
    }
    let mut m = Machine::new(&elf, Board::F405, Options::default()).unwrap();
    m.run_until_logged("control loop running", 1.0)
        .unwrap_or_else(|e| panic!("boot: {e}\n{}", log(&m)));
    m.link_ready(1.0)
        .unwrap_or_else(|e| panic!("USB: {e}\n{}", log(&m)));
    Some(m)
}

/// A key's value in a reply.
fn value<'a>(reply: &'a str, key: &str) -> &'a str {
    reply
        .split_whitespace()
        .find_map(|kv| kv.strip_prefix(key).and_then(|v| v.strip_prefix('=')))
        .unwrap_or_else(|| panic!("no {key} in {reply}"))
}

/// The loop missed no period and ran no step late (the link cannot hold it off).
fn loop_unharmed(m: &mut Machine) {
    let st = ask(m, "status");
    assert_eq!(value(&st, "missed"), "0", "{st}");
    assert_eq!(value(&st, "late"), "0", "{st}");
    assert_eq!(value(&st, "fault_names"), "none", "{st}");
}

/// Runs until the image has logged `n` session starts (at most a second of device time).
fn until_sessions(m: &mut Machine, n: usize) {
    let sessions = |m: &Machine| log(m).matches("USB session start").count();
    let until = m.seconds() + 1.0;
    while sessions(m) < n && m.seconds() < until {
        m.run_for(0.001).unwrap();
    }
    assert_eq!(sessions(m), n, "{}", log(m));
}

/// Runs `seconds` collecting what the image sends.
fn collect(m: &mut Machine, seconds: f64) -> String {
    let mut text = String::new();
    let steps = (seconds / 0.001).ceil() as usize;
    for _ in 0..steps {
        m.run_for(0.001).unwrap();
        text.push_str(&String::from_utf8_lossy(&m.take_from_image()));
    }
    text
}

/// The cable pulled while a long reply (`list`, a few hundred bytes over several packets) is
/// on its way, put back 50 ms later: the host enumerates the device again (a bus reset, a new
/// session), the next request's reply comes whole with none of the cut reply before it, and
/// the loop, holding the axis all along, missed no period.
#[test]
fn the_cable_pulled_mid_reply_gives_a_new_enumeration_and_session() {
    let Some(mut m) = boot() else { return };
    assert!(ask(&mut m, "enable").starts_with("ok"));
    let _ = m.take_from_image();
    m.send_to_image(b"list\n");
    // Until the reply has begun (a first packet in), then the cable out.
    let mut got = Vec::new();
    for _ in 0..2000 {
        m.run_for(20e-6).unwrap();
        got.extend(m.take_from_image());
        if !got.is_empty() {
            break;
        }
    }
    assert!(!got.is_empty(), "no reply began");
    assert!(
        !String::from_utf8_lossy(&got).contains("\nok"),
        "the whole reply came before the cable was pulled: {}",
        String::from_utf8_lossy(&got)
    );
    let before = m.usb_host().enumerations;
    {
        let (h, dev, _) = m.usb();
        h.unplug(dev);
    }
    m.run_for(0.05).unwrap();
    let _ = m.take_from_image();
    {
        let (h, _, now) = m.usb();
        h.plug(now);
    }
    m.link_ready(1.0).unwrap();
    assert_eq!(m.usb_host().enumerations, before + 1, "enumerated again");
    // The cut reply's session ends (its packet never taken: the endpoint reset) and a new
    // one starts.
    until_sessions(&mut m, 2);
    assert!(log(&m).contains("host gone"), "{}", log(&m));
    let stale = collect(&mut m, 0.05);
    assert!(
        stale.is_empty(),
        "the cut reply went on into the new session: {stale:?}"
    );
    // The next request's reply, and nothing of the one cut.
    let r = m.request("get pos.kp", 0.5).unwrap();
    assert_eq!(r.len(), 1, "{r:?}");
    assert!(r[0].starts_with("ok "), "{r:?}");
    loop_unharmed(&mut m);
    assert!(value(&ask(&mut m, "status"), "enabled") == "1");
}

/// DTR dropped (the application closed its port) while a speed experiment runs: the image
/// ends the experiment as for a lost host (the bridge off, position drive again: the
/// conformance suite's lost link); DTR raised again (the port reopened): a new session
/// answers.
#[test]
fn dtr_dropped_ends_the_session_and_raised_starts_one() {
    let Some(mut m) = boot() else { return };
    assert!(ask(&mut m, "enable").starts_with("ok"));
    assert!(ask(&mut m, "velocity 0.5").starts_with("ok"));
    m.run_for(0.05).unwrap();
    assert_eq!(value(&ask(&mut m, "status"), "moving"), "1");
    {
        let (h, _, now) = m.usb();
        h.close_port(now);
    }
    m.run_until_logged("host gone", 0.5)
        .unwrap_or_else(|e| panic!("DTR dropped: {e}\n{}", log(&m)));
    assert!(!m.usb_host().dtr);
    {
        let (h, _, now) = m.usb();
        h.open_port(now);
    }
    m.link_ready(0.5).unwrap();
    until_sessions(&mut m, 2);
    let st = ask(&mut m, "status");
    assert_eq!(
        value(&st, "moving"),
        "0",
        "the experiment outlived its host: {st}"
    );
    assert_eq!(value(&st, "enabled"), "0", "{st}");
    assert_eq!(value(&st, "drive"), "position", "{st}");
    loop_unharmed(&mut m);
}

/// Stream lines: each whole (`#t=… pos=… current=…`, numbers), in time order; the first
/// may be the end of one under way. Their count.
fn whole_lines(text: &str) -> usize {
    let tail = text.rsplit_once('\n').map_or("", |(whole, _)| whole);
    let mut last_t = f64::MIN;
    let mut n = 0;
    for line in tail.lines().skip(1) {
        assert!(line.starts_with('#'), "a line cut: {line:?}");
        let fields: Vec<(&str, f64)> = line
            .trim_start_matches('#')
            .split_whitespace()
            .map(|w| {
                let (k, v) = w.split_once('=').unwrap_or_else(|| panic!("{line:?}"));
                (k, v.parse().unwrap_or_else(|_| panic!("{line:?}")))
            })
            .collect();
        let keys: Vec<&str> = fields.iter().map(|f| f.0).collect();
        assert_eq!(
            keys,
            ["t", "pos", "current"],
            "a line cut or merged: {line:?}"
        );
        assert!(fields[0].1 > last_t, "out of order: {line:?}");
        last_t = fields[0].1;
        n += 1;
    }
    n
}

/// The host stops reading (its application busy) while the window's stream runs at 1 kHz:
/// for 0.1 s (under the 200 ms a packet may wait) the stream goes on when it reads again,
/// every line whole and in order (samples the queue could not hold dropped at the source);
/// for 0.5 s the image ends the session (nobody reads: `host gone`, the stream off), and
/// what reaches the host when it reads again is at most the one packet already handed to
/// the endpoint, no stream after it; a request is then served. The loop misses no period.
#[test]
fn a_host_that_stops_reading_gets_whole_lines_when_it_reads_again() {
    let Some(mut m) = boot() else { return };
    assert!(ask(&mut m, "enable").starts_with("ok"));
    assert!(ask(&mut m, "stream t,pos,current 1000").starts_with("ok"));
    assert!(whole_lines(&collect(&mut m, 0.05)) > 20);
    let reading = |m: &mut Machine, on: bool| {
        let (h, _, now) = m.usb();
        h.reading = on;
        h.kick(now);
    };
    reading(&mut m, false);
    let stalled = collect(&mut m, 0.1);
    assert!(stalled.is_empty(), "read while stopped: {stalled:?}");
    reading(&mut m, true);
    let n = whole_lines(&collect(&mut m, 0.1));
    assert!(n > 50, "{n} lines after reading resumed");
    assert!(!log(&m).contains("host gone"), "{}", log(&m));
    reading(&mut m, false);
    let _ = collect(&mut m, 0.5);
    assert!(log(&m).contains("host gone"), "{}", log(&m));
    reading(&mut m, true);
    let after = collect(&mut m, 0.1);
    assert!(
        after.len() <= 64 && after.matches('\n').count() <= 1,
        "more than the packet handed over before the session ended: {after:?}"
    );
    let _ = m.take_from_image();
    until_sessions(&mut m, 2);
    let st = ask(&mut m, "status");
    assert!(st.starts_with("ok "), "{st}");
    assert!(
        collect(&mut m, 0.05).is_empty(),
        "the stream outlived its session"
    );
    loop_unharmed(&mut m);
}

/// A request split across two transfers 2 ms apart is one request; one of exactly 64 bytes
/// (its line feed the packet's last byte, so the host ends the transfer with a zero-length
/// packet) and one of 65 (a second packet of one byte) are each taken whole.
#[test]
fn requests_split_across_packets_and_at_a_packets_end_are_taken_whole() {
    let Some(mut m) = boot() else { return };
    let _ = m.take_from_image();
    m.send_to_image(b"set pos.k");
    m.run_for(0.002).unwrap();
    m.send_to_image(b"p 0.61\n");
    let text = collect(&mut m, 0.05);
    assert_eq!(text, "ok\n");
    assert_eq!(ask(&mut m, "get pos.kp"), "ok 0.61");
    for len in [64, 65] {
        let head = "set pos.kp 0.62";
        let line = format!("{head}{}\n", "0".repeat(len - head.len() - 1));
        assert_eq!(line.len(), len);
        let _ = m.take_from_image();
        m.send_to_image(line.as_bytes());
        let text = collect(&mut m, 0.05);
        assert_eq!(text, "ok\n", "a {len}-byte request");
        assert_eq!(ask(&mut m, "get pos.kp"), "ok 0.62");
        assert!(ask(&mut m, "set pos.kp 0.6").starts_with("ok"));
    }
    loop_unharmed(&mut m);
}

/// The host suspends the bus for 50 ms (a PC asleep) with the port open, then resumes it: the
/// session that was on ends at the suspend, a new one starts after the resume without a new
/// enumeration, and a request is answered; the axis held, no period missed.
#[test]
fn a_suspended_and_resumed_bus_gives_a_new_session() {
    let Some(mut m) = boot() else { return };
    assert!(ask(&mut m, "enable").starts_with("ok"));
    let before = m.usb_host().enumerations;
    {
        let (h, dev, now) = m.usb();
        h.set_suspended(true, now, dev);
    }
    m.run_until_logged("host gone", 0.1)
        .unwrap_or_else(|e| panic!("suspended: {e}\n{}", log(&m)));
    m.run_for(0.05).unwrap();
    assert_eq!(
        log(&m).matches("USB session start").count(),
        1,
        "a session on a suspended bus"
    );
    {
        let (h, dev, now) = m.usb();
        h.set_suspended(false, now, dev);
    }
    until_sessions(&mut m, 2);
    assert_eq!(
        m.usb_host().enumerations,
        before,
        "resumed, not enumerated again"
    );
    assert!(ask(&mut m, "get pos.kp").starts_with("ok "));
    assert_eq!(value(&ask(&mut m, "status"), "enabled"), "1");
    loop_unharmed(&mut m);
}
