//! The bench protocol: parsing, the parameter table, replies, and robustness to anything on
//! the wire.

use core::fmt::Write;

use gms_core::control::controller::FfMode;
use gms_core::device::{CaptureState, StatusReply};
use gms_core::protocol::{self, Access, Device, Line, LineReader, PARAMS, Settings};
use gms_core::selftest;
use proptest::prelude::*;

/// A device that records what was asked of it.
struct Mock {
    s: Settings,
    saved: Option<Settings>,
    staged: Option<Settings>,
    enabled: bool,
    moves: Vec<(f32, Option<f32>)>,
    stream: Option<(String, f32)>,
    /// The experiment requests received, as text.
    experiments: Vec<String>,
}

impl Mock {
    fn new() -> Self {
        Mock {
            s: selftest::controller_params(),
            saved: None,
            staged: None,
            enabled: false,
            moves: Vec::new(),
            stream: None,
            experiments: Vec::new(),
        }
    }
}

impl Device for Mock {
    fn settings(&self) -> &Settings {
        &self.s
    }
    fn staged(&mut self) -> &mut Option<Settings> {
        &mut self.staged
    }
    fn apply(&mut self, new: Settings) -> Result<(), &'static str> {
        self.s = new;
        Ok(())
    }
    fn save(&mut self) -> Result<(), &'static str> {
        if self.enabled {
            return Err("disable first");
        }
        self.saved = Some(self.s);
        Ok(())
    }
    fn load(&mut self) -> Result<(), &'static str> {
        self.s = self.saved.ok_or("nothing saved")?;
        Ok(())
    }
    fn defaults(&mut self) -> Result<(), &'static str> {
        self.s = selftest::controller_params();
        Ok(())
    }
    fn enable(&mut self) -> Result<(), &'static str> {
        self.enabled = true;
        Ok(())
    }
    fn enable_current(&mut self) -> Result<(), &'static str> {
        self.enabled = true;
        self.experiments.push("current 0".into());
        Ok(())
    }
    fn disable(&mut self) -> Result<(), &'static str> {
        self.enabled = false;
        Ok(())
    }
    fn status(&mut self) -> StatusReply {
        StatusReply {
            enabled: self.enabled,
            ..StatusReply::default()
        }
    }
    fn clear(&mut self) -> Result<(), &'static str> {
        Ok(())
    }
    fn move_to(&mut self, pos: f32, vel: Option<f32>) -> Result<(), &'static str> {
        self.moves.push((pos, vel));
        Ok(())
    }
    fn current(&mut self, amps: f32, seconds: Option<f32>) -> Result<(), &'static str> {
        self.experiments.push(match seconds {
            None => format!("current {amps}"),
            Some(s) => format!("current {amps} for {s}"),
        });
        Ok(())
    }
    fn velocity(
        &mut self,
        vel: f32,
        sweep: Option<gms_core::control::reference::Sweep>,
    ) -> Result<(), &'static str> {
        self.experiments.push(format!("velocity {vel} {sweep:?}"));
        Ok(())
    }
    fn hold(&mut self) -> Result<(), &'static str> {
        self.experiments.push("hold".into());
        Ok(())
    }
    fn capture_arm(
        &mut self,
        fields: &str,
        every: u32,
        samples: u32,
        on_next: bool,
    ) -> Result<(), &'static str> {
        self.experiments
            .push(format!("capture {fields} {every} {samples} {on_next}"));
        Ok(())
    }
    fn capture_off(&mut self) -> Result<(), &'static str> {
        self.experiments.push("capture off".into());
        Ok(())
    }
    fn capture_status(&mut self) -> protocol::CaptureStatus {
        protocol::CaptureStatus {
            state: CaptureState::Idle,
            samples: 0,
            capacity: 100,
            origin: 0.5,
        }
    }
    fn capture_read(
        &mut self,
        start: u32,
        count: u32,
        out: &mut dyn Write,
    ) -> Result<(), &'static str> {
        for i in start..start + count.min(2) {
            writeln!(out, "{i},0").map_err(|_| "too long")?;
        }
        Ok(())
    }
    fn stream(&mut self, fields: &str, rate_hz: f32) -> Result<(), &'static str> {
        self.stream = Some((fields.to_string(), rate_hz));
        Ok(())
    }
    fn stream_off(&mut self) -> Result<(), &'static str> {
        self.stream = None;
        Ok(())
    }
}

/// Sends one line; returns the reply.
fn ask(dev: &mut Mock, line: &str) -> String {
    let mut out = String::new();
    let mut rd = LineReader::default();
    for &b in line.as_bytes().iter().chain(b"\n") {
        if let Some(l) = rd.push(b) {
            protocol::execute(dev, l, &mut out).unwrap();
        }
    }
    out
}

#[test]
fn get_and_set_every_parameter() {
    let mut d = Mock::new();
    for p in PARAMS {
        let reply = ask(&mut d, &format!("get {}", p.path));
        assert!(reply.starts_with("ok ") && reply.ends_with('\n'), "{reply}");
        let value = reply[3..].trim().to_string();
        let before = d.s;
        if let Access::Estimate(_) = p.access {
            // An estimate reads (the mock has no adaptation: 1) and refuses to be set.
            assert_eq!(value, "1");
            assert!(ask(&mut d, &format!("set {} 1", p.path)).starts_with("err 8 "));
            assert_eq!(d.s, before);
            continue;
        }
        // Setting the current value back is accepted and changes nothing.
        assert_eq!(
            ask(&mut d, &format!("set {} {value}", p.path)),
            "ok\n",
            "{}",
            p.path
        );
        assert_eq!(d.s, before, "{}", p.path);
        if let Access::Number { get, min, max, .. } = p.access {
            assert_eq!(value.parse::<f32>().unwrap(), get(&d.s));
            // Outside the range: err 6 and nothing changes.
            for bad in [
                format!("{}", max * 2.0 + 1.0),
                "nan".into(),
                "inf".into(),
                "x".into(),
            ] {
                let r = ask(&mut d, &format!("set {} {bad}", p.path));
                assert!(r.starts_with("err 6 "), "{} {bad}: {r}", p.path);
                assert_eq!(d.s, before);
            }
            if min > 0.0 {
                assert!(ask(&mut d, &format!("set {} {}", p.path, -min)).starts_with("err 6 "));
            }
        }
    }
}

#[test]
fn set_changes_what_get_reads_and_invalid_sets_change_nothing() {
    let mut d = Mock::new();
    assert_eq!(ask(&mut d, "set pos.kp 0.125"), "ok\n");
    assert_eq!(ask(&mut d, "get pos.kp"), "ok 0.125\n");
    assert_eq!(d.s.pid.kp, 0.125);
    assert_eq!(ask(&mut d, "set ff.mode static"), "ok\n");
    assert_eq!(d.s.ff.mode, FfMode::Static);
    assert_eq!(ask(&mut d, "get ff.mode"), "ok static\n");
    assert!(ask(&mut d, "set ff.mode fast").starts_with("err 6 "));
    // fs below fc makes the set invalid: err 7, nothing changes.
    let before = d.s;
    assert!(ask(&mut d, "set gms.fs 100e-6").starts_with("err 7 "));
    assert_eq!(d.s, before);
    // A block weight that breaks sum(alpha) = 1 ± 0.01.
    assert!(ask(&mut d, "set gms.a1 0.5").starts_with("err 7 "));
    // Rates that are not integer multiples.
    assert!(ask(&mut d, "set rate.cur_hz 15000").starts_with("err 7 "));
    assert_eq!(d.s, before);
    assert!(ask(&mut d, "set no.such 1").starts_with("err 5 "));
    assert!(ask(&mut d, "get no.such").starts_with("err 5 "));
}

#[test]
fn list_help_and_device_commands() {
    let mut d = Mock::new();
    let list = ask(&mut d, "list");
    let lines: Vec<&str> = list.lines().collect();
    assert_eq!(lines.len(), PARAMS.len() + 1);
    assert_eq!(*lines.last().unwrap(), "ok");
    for (l, p) in lines.iter().zip(PARAMS) {
        let row = protocol::ListRow::parse(l).unwrap();
        assert_eq!(row.path, p.path);
        assert_eq!(row.unit, p.unit);
        match (p.access, row.range) {
            (
                Access::Number { get, min, max, .. },
                protocol::ListRange::Number { min: a, max: b },
            ) => {
                assert_eq!((a, b), (min, max), "{l}");
                assert_eq!(row.value, protocol::ListValue::Number(get(&d.s)), "{l}");
            }
            (Access::Mode, protocol::ListRange::Names(n)) => {
                assert_eq!(row.value, protocol::ListValue::Name(d.s.ff.mode.name()));
                for m in FfMode::ALL {
                    assert!(n.split(", ").any(|x| x == m.name()), "{l}");
                }
            }
            (Access::Estimate(_), protocol::ListRange::ReadOnly) => {}
            _ => panic!("{l}: the range is not the parameter's kind"),
        }
    }
    assert!(ask(&mut d, "help").ends_with("\nok\n"));
    assert_eq!(ask(&mut d, "save"), "ok\n");
    assert_eq!(ask(&mut d, "set pos.kp 0.3"), "ok\n");
    assert_eq!(ask(&mut d, "load"), "ok\n");
    assert_eq!(d.s.pid.kp, gms_core::device::default_settings().pid.kp);
    assert_eq!(ask(&mut d, "enable"), "ok\n");
    assert!(ask(&mut d, "save").starts_with("err 8 disable first"));
    let st = ask(&mut d, "status");
    let st = StatusReply::parse(st.strip_prefix("ok ").unwrap().trim_end()).unwrap();
    assert!(st.enabled);
    assert_eq!(ask(&mut d, "move 0.5"), "ok\n");
    assert_eq!(ask(&mut d, "move -1e-3 0.2"), "ok\n");
    assert_eq!(d.moves, vec![(0.5, None), (-1e-3, Some(0.2))]);
    assert!(ask(&mut d, "move").starts_with("err 2 "));
    assert!(ask(&mut d, "move 1 -2").starts_with("err 2 "));
    assert!(ask(&mut d, "move 1 2 3").starts_with("err 2 "));
    assert_eq!(ask(&mut d, "stream error,ff 500"), "ok\n");
    assert_eq!(d.stream, Some(("error,ff".to_string(), 500.0)));
    assert_eq!(ask(&mut d, "stream off"), "ok\n");
    assert_eq!(d.stream, None);
    assert!(ask(&mut d, "stream error").starts_with("err 2 "));
    assert!(ask(&mut d, "frobnicate").starts_with("err 1 "));
    assert_eq!(ask(&mut d, ""), "");
    assert_eq!(ask(&mut d, "   "), "");
    let kp = gms_core::device::default_settings().pid.kp;
    assert_eq!(ask(&mut d, "get pos.kp\r"), format!("ok {kp}\n"));
}

#[test]
fn line_reader_handles_crlf_partial_long_and_binary_lines() {
    let mut rd = LineReader::default();
    let mut lines = Vec::new();
    let feed = |rd: &mut LineReader, bytes: &[u8], lines: &mut Vec<String>| {
        for &b in bytes {
            if let Some(l) = rd.push(b) {
                lines.push(match l {
                    Line::Text(t) => format!("T:{t}"),
                    Line::TooLong => "LONG".into(),
                    Line::NotText => "BIN".into(),
                    Line::Cancel => "CAN".into(),
                    Line::Damaged => "DMG".into(),
                });
            }
        }
    };
    feed(&mut rd, b"get po", &mut lines);
    assert!(lines.is_empty());
    feed(&mut rd, b"s.kp\r\n", &mut lines);
    feed(&mut rd, &[b'a'; 500], &mut lines);
    feed(&mut rd, b"\nhelp\n\x00\xff\x1b[A\nlist\n", &mut lines);
    assert_eq!(lines, ["T:get pos.kp", "LONG", "T:help", "BIN", "T:list"]);
    // CAN drops the half line before it, binary or too long ones too: a new host's CAN LF
    // ends as an empty line, and the half request is not run.
    let mut lines = Vec::new();
    feed(&mut rd, b"move 0.2", &mut lines);
    feed(&mut rd, &[protocol::CANCEL, b'\n'], &mut lines);
    feed(&mut rd, b"\x00\x01", &mut lines);
    feed(&mut rd, &[protocol::CANCEL], &mut lines);
    feed(&mut rd, b"status\n", &mut lines);
    feed(&mut rd, &[b'y'; protocol::MAX_LINE + 5], &mut lines);
    feed(&mut rd, &[protocol::CANCEL], &mut lines);
    feed(&mut rd, b"list\n", &mut lines);
    assert_eq!(lines, ["CAN", "T:", "CAN", "T:status", "CAN", "T:list"]);
    // A line damaged on the link is reported at its LF, and only that line; a CAN drops
    // the mark with the line.
    let mut lines = Vec::new();
    feed(&mut rd, b"set pos.k", &mut lines);
    rd.damage();
    feed(&mut rd, b"p 0.5\nstatus\n", &mut lines);
    rd.damage();
    feed(&mut rd, b"\n", &mut lines);
    rd.damage();
    feed(&mut rd, &[protocol::CANCEL], &mut lines);
    feed(&mut rd, b"list\n", &mut lines);
    assert_eq!(lines, ["DMG", "T:status", "DMG", "CAN", "T:list"]);
    // A line lost mid-way: what came is dropped and, if asked, the rest up to its LF.
    let mut lines = Vec::new();
    feed(&mut rd, b"move 0.2", &mut lines);
    rd.drop_line(true);
    feed(&mut rd, b"5\nstatus\n", &mut lines);
    feed(&mut rd, b"move 0.2", &mut lines);
    rd.drop_line(false);
    feed(&mut rd, b"list\nmove", &mut lines);
    rd.drop_line(true);
    feed(&mut rd, &[protocol::CANCEL], &mut lines);
    feed(&mut rd, b"help\n", &mut lines);
    assert_eq!(lines, ["T:status", "T:list", "CAN", "T:help"]);
    // Exactly MAX_LINE bytes fit; one more does not.
    let mut lines = Vec::new();
    feed(&mut rd, &[b'x'; protocol::MAX_LINE], &mut lines);
    feed(&mut rd, b"\n", &mut lines);
    feed(&mut rd, &[b'x'; protocol::MAX_LINE + 1], &mut lines);
    feed(&mut rd, b"\n", &mut lines);
    assert_eq!(lines.len(), 2);
    assert!(lines[0].starts_with("T:xxx"));
    assert_eq!(lines[1], "LONG");
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    /// Anything on the wire: no panic; every complete non-empty line gets exactly one final
    /// line starting with `ok` or `err` (CAN none); the settings stay valid.
    #[test]
    fn any_bytes_are_handled(
        chunks in prop::collection::vec(
            prop_oneof![
                prop::collection::vec(any::<u8>(), 0..300),
                "(get|set|list|help|move|stream|save|load|enable|status)( [a-z0-9.,+-]{0,12}){0,4}\r?\n"
                    .prop_map(|s| s.into_bytes()),
                Just(b"set pos.kp 1e39\n".to_vec()),
                Just(b"set gms.k1 -0\n".to_vec()),
            ],
            1..20,
        ),
    ) {
        let mut d = Mock::new();
        let mut rd = LineReader::default();
        for chunk in chunks {
            for b in chunk {
                if let Some(line) = rd.push(b) {
                    // An empty line and CAN have no reply.
                    let empty = matches!(line, Line::Text(t) if t.trim().is_empty())
                        || line == Line::Cancel;
                    let mut out = String::new();
                    protocol::execute(&mut d, line, &mut out).unwrap();
                    if empty {
                        prop_assert!(out.is_empty());
                    } else {
                        let last = out.lines().last().unwrap_or("");
                        prop_assert!(last.starts_with("ok") || last.starts_with("err "), "{out:?}");
                        prop_assert!(out.lines().all(|l| !l.starts_with('#')));
                    }
                    prop_assert!(d.s.validate().is_ok());
                }
            }
        }
    }
}

/// Every feedforward mode is set and read back by its name, and no other name is a mode.
#[test]
fn every_mode_round_trips_by_name() {
    let mut d = Mock::new();
    for m in FfMode::ALL {
        assert_eq!(FfMode::from_name(m.name()), Some(m));
        assert_eq!(ask(&mut d, &format!("set ff.mode {}", m.name())), "ok\n");
        assert_eq!(d.s.ff.mode, m);
        assert_eq!(ask(&mut d, "get ff.mode"), format!("ok {}\n", m.name()));
    }
    for bad in ["GMS", "adaptive", "gms_adaptive", ""] {
        assert_eq!(FfMode::from_name(bad), None);
    }
    assert!(ask(&mut d, "set ff.mode lugre").starts_with("err 6 "));
}

#[test]
fn experiment_commands_parse() {
    let mut d = Mock::new();
    assert_eq!(ask(&mut d, "current -0.05"), "ok\n");
    assert_eq!(ask(&mut d, "current 0.1 0.002"), "ok\n");
    assert_eq!(ask(&mut d, "velocity 0.2"), "ok\n");
    assert_eq!(ask(&mut d, "velocity 0.3 0.1 1 5 2.5"), "ok\n");
    assert_eq!(ask(&mut d, "hold"), "ok\n");
    assert_eq!(
        d.experiments,
        [
            "current -0.05",
            "current 0.1 for 0.002",
            "velocity 0.2 None",
            "velocity 0.3 Some(Sweep { amp: 0.1, f0: 1.0, f1: 5.0, seconds: 2.5 })",
            "hold",
        ]
    );
    // Bad arguments: err 2, nothing asked of the device.
    for bad in [
        "current",
        "current x",
        "current 1 x",
        "current 1 2 3",
        "velocity",
        "velocity 0.3 0.1",
        "velocity 0.3 0.1 1 5",
        "velocity 0.3 0.1 1 5 2 9",
        "hold now",
    ] {
        assert!(ask(&mut d, bad).starts_with("err 2 "), "{bad}");
    }
    assert_eq!(d.experiments.len(), 5);
}

#[test]
fn capture_commands_parse() {
    let mut d = Mock::new();
    assert_eq!(
        ask(&mut d, "capture"),
        "ok state=idle samples=0 capacity=100 origin=0.5\n"
    );
    assert_eq!(ask(&mut d, "capture t,pos,current 2 500"), "ok\n");
    assert_eq!(ask(&mut d, "capture pos 1 100 next"), "ok\n");
    assert_eq!(ask(&mut d, "capture off"), "ok\n");
    assert_eq!(ask(&mut d, "capture read 10 5"), "10,0\n11,0\nok\n");
    assert_eq!(
        d.experiments,
        [
            "capture t,pos,current 2 500 false",
            "capture pos 1 100 true",
            "capture off"
        ]
    );
    for bad in [
        "capture pos",
        "capture pos 0 10",
        "capture pos 1 0",
        "capture pos 1 -5",
        "capture pos 1 10 later",
        "capture read 0",
        "capture read 0 65",
        "capture read x 1",
    ] {
        assert!(ask(&mut d, bad).starts_with("err 2 "), "{bad}");
    }
    assert_eq!(d.experiments.len(), 3);
}

/// Weights that must sum to 1 cannot be changed one `set` at a time; staged, they change
/// together at `commit`, validated as a whole, or not at all.
#[test]
fn staged_changes_apply_together_or_not_at_all() {
    let mut d = Mock::new();
    let a1: f32 = ask(&mut d, "get gms.a1")[3..].trim().parse().unwrap();
    let a2: f32 = ask(&mut d, "get gms.a2")[3..].trim().parse().unwrap();
    // Moving 0.1 of weight from block 1 to block 2: each half alone breaks the sum.
    let (n1, n2) = (a1 - 0.1, a2 + 0.1);
    assert!(ask(&mut d, &format!("set gms.a1 {n1}")).starts_with("err 7 "));
    let before = d.s;
    assert_eq!(ask(&mut d, &format!("stage gms.a1 {n1}")), "ok\n");
    assert_eq!(ask(&mut d, &format!("stage gms.a2 {n2}")), "ok\n");
    // Nothing changed until the commit.
    assert_eq!(d.s, before);
    assert_eq!(ask(&mut d, "commit"), "ok\n");
    assert_eq!(ask(&mut d, "get gms.a1"), format!("ok {n1}\n"));
    assert_eq!(ask(&mut d, "get gms.a2"), format!("ok {n2}\n"));
    // A staged set that is invalid as a whole: refused at commit, nothing changed, dropped.
    let before = d.s;
    assert_eq!(ask(&mut d, "stage gms.a1 0.9"), "ok\n");
    assert!(ask(&mut d, "commit").starts_with("err 7 "));
    assert_eq!(d.s, before);
    assert!(ask(&mut d, "commit").starts_with("err 8 nothing staged"));
    // A value out of its range is refused at once; a bad path too.
    assert!(ask(&mut d, "stage gms.a1 -1").starts_with("err 6 "));
    assert!(ask(&mut d, "stage gms.nope 1").starts_with("err 5 "));
    // A `set` beside a staging drops it (its commit would undo the set); so does `discard`.
    assert_eq!(ask(&mut d, "stage pos.kp 0.3"), "ok\n");
    assert_eq!(ask(&mut d, "set pos.ki 100"), "ok\n");
    assert!(ask(&mut d, "commit").starts_with("err 8 nothing staged"));
    assert_eq!(ask(&mut d, "stage pos.kp 0.3"), "ok\n");
    assert_eq!(ask(&mut d, "discard"), "ok\n");
    assert!(ask(&mut d, "commit").starts_with("err 8 nothing staged"));
    assert_eq!(ask(&mut d, "get pos.ki"), "ok 100\n");
    assert_ne!(ask(&mut d, "get pos.kp"), "ok 0.3\n");
}

/// The block count: `gms.blocks N` leaves the blocks past N unused (k = alpha = 0, read back
/// as 0), staged with the new blocks as one set; a fraction, 0 or 7 are refused, and so is a
/// count whose set would not validate, with nothing changed.
#[test]
fn block_count_is_staged_and_applied_with_the_blocks() {
    let mut d = Mock::new();
    assert_eq!(ask(&mut d, "get gms.blocks"), "ok 6\n");
    for bad in ["0", "7", "4.5", "nan"] {
        assert!(
            ask(&mut d, &format!("set gms.blocks {bad}")).starts_with("err 6 "),
            "{bad}"
        );
    }
    // Alone, 4 blocks of the 6 weights do not sum to 1: refused, nothing changed.
    let before = d.s;
    assert!(ask(&mut d, "set gms.blocks 4").starts_with("err 7 "));
    assert_eq!(d.s, before);
    // Staged with weights that sum to 1: applied as one.
    for line in [
        "stage gms.blocks 4",
        "stage gms.k1 1.2",
        "stage gms.a1 0.5",
        "stage gms.k2 0.06",
        "stage gms.a2 0.25",
        "stage gms.k3 0.01",
        "stage gms.a3 0.15",
        "stage gms.k4 0.002",
        "stage gms.a4 0.1",
        "commit",
    ] {
        assert_eq!(ask(&mut d, line), "ok\n", "{line}");
    }
    assert_eq!(ask(&mut d, "get gms.blocks"), "ok 4\n");
    assert_eq!(ask(&mut d, "get gms.k5"), "ok 0\n");
    assert_eq!(ask(&mut d, "get gms.a6"), "ok 0\n");
    assert_eq!(d.s.ff.actuator.blocks_used(), 4);
    // The record keeps the count: encoded and decoded, the same set.
    let rec = gms_core::device::encode_settings(&d.s);
    let back = gms_core::device::decode_settings(&rec, &selftest::controller_params());
    assert_eq!(back.map(|l| l.settings), Ok(d.s));
    // A used block after an unused one is refused; growing back needs the new blocks.
    assert!(ask(&mut d, "set gms.k6 0.001").starts_with("err 7 "));
    assert!(ask(&mut d, "set gms.blocks 5").starts_with("err 7 "));
    for line in [
        "stage gms.blocks 5",
        "stage gms.k5 0.001",
        "stage gms.a5 0.1",
        "stage gms.a1 0.4",
        "commit",
    ] {
        assert_eq!(ask(&mut d, line), "ok\n", "{line}");
    }
    assert_eq!(ask(&mut d, "get gms.blocks"), "ok 5\n");
}

/// A command a host may send, within what `parse` accepts.
fn any_command() -> impl Strategy<Value = (u8, String, String, f32, f32, u32, u32, bool)> {
    (
        0u8..41,
        "[a-z][a-z_.]{0,15}",
        "[a-z0-9_,.-]{1,12}",
        prop::num::f32::NORMAL | prop::num::f32::ZERO,
        (1e-6f32..1e6),
        1u32..100_000,
        1u32..=64,
        any::<bool>(),
    )
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]

    /// Every command a host writes is read by the device as the same command: the request
    /// syntax lives once, in `parse` and `Display` side by side.
    #[test]
    fn a_written_command_parses_back_the_same(
        (which, path, value, x, pos, n, count, flag) in any_command()
    ) {
        use gms_core::control::frf::Injection;
        use gms_core::protocol::{CaptureCmd, Command, FrfCmd, MapCmd, TableCmd, parse};
        use gms_core::control::table::{Geometry, Which};
        use gms_core::control::reference::Sweep;
        // A value word must not be one of the keywords that change a command's meaning.
        prop_assume!(!matches!(value.as_str(), "off" | "read" | "next" | "current"));
        let sweep = Sweep { amp: pos, f0: pos, f1: x.abs().max(1e-3), seconds: pos };
        let c = match which {
            0 => Command::Help,
            1 => Command::List,
            2 => Command::Get(&path),
            3 => Command::Set(&path, &value),
            4 => Command::Stage(&path, &value),
            5 => Command::Commit,
            6 => Command::Discard,
            7 => Command::Save,
            8 => Command::Load,
            9 => Command::Defaults,
            10 => Command::Enable { current: flag },
            11 => Command::Disable,
            12 => Command::Status,
            13 => Command::Clear,
            14 => Command::Move { pos: x, vel: flag.then_some(pos) },
            15 => Command::Current { amps: x, seconds: flag.then_some(pos) },
            16 => Command::Velocity { vel: x, sweep: flag.then_some(sweep) },
            17 => Command::Hold,
            18 => Command::Capture(CaptureCmd::Status),
            19 => Command::Capture(CaptureCmd::Off),
            20 => Command::Capture(CaptureCmd::Arm {
                fields: &value,
                every: n,
                samples: n,
                on_next: flag,
            }),
            21 => Command::Capture(CaptureCmd::Read { start: n, count }),
            22 => Command::Stream { fields: &value, rate_hz: pos },
            23 => Command::StreamOff,
            24 => Command::Table(TableCmd::Status),
            25 => Command::Table(TableCmd::Write {
                which: if flag { Which::Ref } else { Which::Corr },
                start: n,
                values: &value,
            }),
            26 => Command::Table(TableCmd::Set(Geometry {
                points: n,
                steps: count,
                origin: (x as f64).clamp(-1e15, 1e15) as i64,
            })),
            27 => Command::Table(TableCmd::Use),
            28 => Command::Table(TableCmd::CorrOff),
            29 => Command::Table(TableCmd::Run(n)),
            30 => Command::Table(TableCmd::Stop),
            31 => Command::Table(TableCmd::Read {
                which: [Which::Ref, Which::Corr, Which::Err][(n % 3) as usize],
                start: n,
                count,
            }),
            32 => Command::Table(TableCmd::Clear),
            33 => Command::Table(TableCmd::Next),
            34 => Command::Frf(FrfCmd::Status),
            35 => Command::Frf(FrfCmd::Off),
            36 => Command::Frf(FrfCmd::Start {
                injection: if flag { Injection::Current } else { Injection::Position },
                f_hz: pos,
                amp: x,
                periods: n,
                settle: count,
            }),
            37 => Command::Map(MapCmd::Read { start: n, count }),
            38 => Command::Map(MapCmd::Write { start: n, pairs: &value }),
            39 => Command::Map(MapCmd::Clear),
            _ => Command::Empty,
        };
        let line = c.to_string();
        prop_assert_eq!(parse(&line), Ok(c), "{}", line);
        // Its name is the line's first word.
        prop_assert_eq!(line.split(' ').next().unwrap_or(""), c.name());
    }
}

/// The protocol's table, the specs and the typed ids are one table: the same parameters in
/// the same order, each path once, each id naming its own row; the specs' kinds are the
/// protocol's accesses.
#[test]
fn the_protocol_table_the_specs_and_the_ids_are_one() {
    use gms_core::settings::{Kind, ParamId, SPECS};
    assert_eq!(PARAMS.len(), SPECS.len());
    assert_eq!(PARAMS.len(), ParamId::ALL.len());
    let mut paths: Vec<&str> = PARAMS.iter().map(|p| p.path).collect();
    paths.sort();
    paths.dedup();
    assert_eq!(paths.len(), PARAMS.len(), "a path twice");
    for ((p, s), &id) in PARAMS.iter().zip(SPECS).zip(ParamId::ALL) {
        assert_eq!((p.path, p.unit), (s.path, s.unit));
        assert_eq!(id.path(), p.path);
        assert_eq!(id.param().path, p.path);
        assert_eq!(ParamId::from_path(p.path), Some(id));
        assert_eq!(id.to_string(), p.path);
        match (p.access, s.kind) {
            (
                Access::Number {
                    min, max, integer, ..
                },
                Kind::Number,
            ) => {
                assert_eq!((min, max, integer), (s.min, s.max, s.integer), "{}", p.path);
                assert!(min <= max, "{}", p.path);
            }
            (Access::Mode, Kind::Mode) | (Access::Estimate(_), Kind::Estimate) => {}
            _ => panic!("{}: the access is not the spec's kind", p.path),
        }
    }
    assert_eq!(ParamId::from_path("pos.nothing"), None);
    // The defaults are in range: the table's ranges and the settings' type agree.
    let d = gms_core::device::default_settings();
    for p in PARAMS {
        if let Access::Number { get, min, max, .. } = p.access {
            assert!((min..=max).contains(&get(&d)), "{} = {}", p.path, get(&d));
        }
    }
}
