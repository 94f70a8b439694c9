//! The bench command protocol: line-based ASCII, typable in any serial terminal, shared by
//! the firmware (USB CDC-ACM) and the simulator's virtual device. No allocation.
//!
//! One request per line (LF or CRLF). Every reply ends with one line that starts with `ok`
//! or `err <code> <reason>`; telemetry lines start with `#` so they never mix with replies.
//!
//! | request | reply |
//! |---|---|
//! | `help` | the commands, then `ok` |
//! | `list` | `PATH VALUE UNIT [MIN, MAX]` per parameter, then `ok` |
//! | `get PATH` | `ok VALUE` |
//! | `set PATH VALUE` | `ok`, or `err` (nothing changes) |
//! | `save`, `load`, `defaults` | `ok` or `err` |
//! | `enable`, `disable`, `status`, `clear` | `ok …` or `err` |
//! | `move POS [VEL]` | `ok` or `err` (rad, rad/s) |
//! | `stream FIELDS RATE_HZ`, `stream off` | `ok` or `err` |

use core::fmt::{self, Write};

use crate::controller::{ControllerParams, FfMode};
use crate::numtext::Num;

/// The longest request line \[bytes\], without its line ending.
pub const MAX_LINE: usize = 120;

/// How long a device may take to answer `save` \[ms\]: a board's flash erases a sector during a
/// save (up to 2 s on the STM32F405, two when the store repairs itself), and answers nothing
/// meanwhile. Other requests are answered within a position period or two.
pub const SAVE_REPLY_MS: u32 = 5000;

/// Error codes of `err` replies.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ErrorCode {
    /// 1: the command is not known.
    UnknownCommand = 1,
    /// 2: missing, extra or malformed arguments.
    BadArgument = 2,
    /// 3: the line was longer than [`MAX_LINE`].
    LineTooLong = 3,
    /// 4: the line held bytes that are not printable ASCII.
    NotText = 4,
    /// 5: no parameter has this path.
    UnknownPath = 5,
    /// 6: the value is not a finite number within the parameter's range.
    OutOfRange = 6,
    /// 7: the value would make the parameter set invalid.
    InvalidSet = 7,
    /// 8: the device refuses now (e.g. `save` while enabled, a latched fault).
    Refused = 8,
}

/// Accumulates received bytes into request lines.
#[derive(Debug, Clone)]
pub struct LineReader {
    buf: [u8; MAX_LINE],
    len: usize,
    too_long: bool,
    not_text: bool,
}

impl Default for LineReader {
    fn default() -> Self {
        LineReader {
            buf: [0; MAX_LINE],
            len: 0,
            too_long: false,
            not_text: false,
        }
    }
}

/// A complete request line, or why it cannot be one.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Line<'a> {
    /// A line of printable ASCII (trailing CR removed).
    Text(&'a str),
    /// The line was longer than [`MAX_LINE`] (the rest was discarded).
    TooLong,
    /// The line held other bytes than printable ASCII and tab.
    NotText,
}

impl LineReader {
    /// Feeds one byte; returns a line when `byte` ends one (LF).
    pub fn push(&mut self, byte: u8) -> Option<Line<'_>> {
        if byte == b'\n' {
            let (too_long, not_text, len) = (self.too_long, self.not_text, self.len);
            self.len = 0;
            self.too_long = false;
            self.not_text = false;
            if too_long {
                return Some(Line::TooLong);
            }
            if not_text {
                return Some(Line::NotText);
            }
            let mut end = len;
            if end > 0 && self.buf.get(end - 1) == Some(&b'\r') {
                end -= 1;
            }
            let bytes = self.buf.get(..end).unwrap_or(&[]);
            return Some(match core::str::from_utf8(bytes) {
                Ok(s) => Line::Text(s),
                Err(_) => Line::NotText,
            });
        }
        let printable = byte == b'\t' || byte == b'\r' || (0x20..0x7f).contains(&byte);
        if !printable {
            self.not_text = true;
        }
        match self.buf.get_mut(self.len) {
            Some(slot) if !self.too_long => {
                *slot = byte;
                self.len += 1;
            }
            _ => self.too_long = true,
        }
        None
    }
}

/// A parsed request.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Command<'a> {
    /// Empty line: no reply.
    Empty,
    /// `help`.
    Help,
    /// `list`.
    List,
    /// `get PATH`.
    Get(&'a str),
    /// `set PATH VALUE` (the value as text: numbers, or a mode name).
    Set(&'a str, &'a str),
    /// `save`.
    Save,
    /// `load`.
    Load,
    /// `defaults`.
    Defaults,
    /// `enable`.
    Enable,
    /// `disable`.
    Disable,
    /// `status`.
    Status,
    /// `clear`.
    Clear,
    /// `move POS [VEL]` [rad, rad/s].
    Move {
        /// Target \[rad\].
        pos: f32,
        /// Speed limit [rad/s].
        vel: Option<f32>,
    },
    /// `stream FIELDS RATE_HZ`: comma-separated field names, rate \[Hz\].
    Stream {
        /// Field names, comma-separated.
        fields: &'a str,
        /// Rate \[Hz\].
        rate_hz: f32,
    },
    /// `stream off`.
    StreamOff,
}

/// Why a request line is not a command.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ParseError {
    /// The error code to reply with.
    pub code: ErrorCode,
    /// A short reason.
    pub reason: &'static str,
}

fn bad(reason: &'static str) -> ParseError {
    ParseError {
        code: ErrorCode::BadArgument,
        reason,
    }
}

/// A finite f32 from text, or `None`.
pub fn parse_f32(s: &str) -> Option<f32> {
    crate::numtext::parse_f32(s)
}

/// Parses one request line.
pub fn parse(line: &str) -> Result<Command<'_>, ParseError> {
    let mut words = line.split_ascii_whitespace();
    let Some(cmd) = words.next() else {
        return Ok(Command::Empty);
    };
    let mut arg = || words.next();
    let no_more = |w: Option<&str>| match w {
        None => Ok(()),
        Some(_) => Err(bad("too many arguments")),
    };
    let c = match cmd {
        "help" => Command::Help,
        "list" => Command::List,
        "save" => Command::Save,
        "load" => Command::Load,
        "defaults" => Command::Defaults,
        "enable" => Command::Enable,
        "disable" => Command::Disable,
        "status" => Command::Status,
        "clear" => Command::Clear,
        "get" => Command::Get(arg().ok_or(bad("usage: get PATH"))?),
        "set" => {
            let path = arg().ok_or(bad("usage: set PATH VALUE"))?;
            let value = arg().ok_or(bad("usage: set PATH VALUE"))?;
            Command::Set(path, value)
        }
        "move" => {
            let pos = arg()
                .and_then(parse_f32)
                .ok_or(bad("usage: move POS [VEL]"))?;
            let vel = match arg() {
                None => None,
                Some(v) => Some(
                    parse_f32(v)
                        .filter(|v| *v > 0.0)
                        .ok_or(bad("VEL must be a number > 0"))?,
                ),
            };
            Command::Move { pos, vel }
        }
        "stream" => match arg() {
            Some("off") => Command::StreamOff,
            Some(fields) => {
                let rate_hz = arg()
                    .and_then(parse_f32)
                    .filter(|r| *r > 0.0)
                    .ok_or(bad("usage: stream FIELDS RATE_HZ | stream off"))?;
                Command::Stream { fields, rate_hz }
            }
            None => return Err(bad("usage: stream FIELDS RATE_HZ | stream off")),
        },
        _ => {
            return Err(ParseError {
                code: ErrorCode::UnknownCommand,
                reason: "unknown command (try help)",
            });
        }
    };
    no_more(arg())?;
    Ok(c)
}

/// The controller settings the protocol edits (the firmware's whole parameter set).
pub type Settings = ControllerParams<6>;

/// How a parameter is read and written.
#[derive(Clone, Copy)]
pub enum Access {
    /// A number.
    Number {
        /// Reads it.
        get: fn(&Settings) -> f32,
        /// Writes it.
        set: fn(&mut Settings, f32),
        /// Smallest allowed value.
        min: f32,
        /// Largest allowed value.
        max: f32,
    },
    /// The feedforward mode: `none`, `static`, `gms` or `gms-adaptive`.
    Mode,
    /// A read-only estimate of the device's state (see [`Device::estimate`]).
    Estimate(Estimate),
}

/// The device's on-line estimates, readable with `get` (not settable).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Estimate {
    /// The adaptive scale on the friction feedforward [-].
    AdaptScale,
}

/// One parameter of the table: its path, unit and access.
#[derive(Clone, Copy)]
pub struct Param {
    /// The path, e.g. `pos.kp`.
    pub path: &'static str,
    /// The unit, e.g. `N·m/rad` (`-` for none).
    pub unit: &'static str,
    /// How to read and write it.
    pub access: Access,
}

macro_rules! num {
    ($path:literal, $unit:literal, $min:expr, $max:expr, |$s:ident| $field:expr) => {
        Param {
            path: $path,
            unit: $unit,
            access: Access::Number {
                get: |$s: &Settings| $field,
                set: |$s: &mut Settings, v: f32| $field = v,
                min: $min,
                max: $max,
            },
        }
    };
}

/// Every parameter, in `list` order. Ranges are the protocol's; the whole set must also pass
/// [`ControllerParams::validate`].
pub const PARAMS: &[Param] = &[
    num!("rate.pos_hz", "Hz", 100.0, 50_000.0, |s| s.pos_rate_hz),
    num!("rate.cur_hz", "Hz", 100.0, 100_000.0, |s| s.cur_rate_hz),
    num!("pos.kp", "N·m/rad", 0.0, 1e3, |s| s.pid.kp),
    num!("pos.ki", "N·m/(rad·s)", 0.0, 1e6, |s| s.pid.ki),
    num!("pos.kd", "N·m·s/rad", 0.0, 1e3, |s| s.pid.kd),
    num!("pos.d_filter_hz", "Hz", 1.0, 1e5, |s| s.pid.d_filter_hz),
    num!("pos.i_limit", "N·m", 0.0, 1e3, |s| s.pid.i_limit),
    num!("cur.kp", "V/A", 0.0, 1e4, |s| s.current.kp),
    num!("cur.ki", "V/(A·s)", 0.0, 1e8, |s| s.current.ki),
    num!("motor.k_m", "N·m/A", 1e-6, 10.0, |s| s.motor.k_m),
    num!("motor.r", "ohm", 0.0, 1e4, |s| s.motor.r),
    num!("motor.k_e", "V·s/rad", 0.0, 10.0, |s| s.motor.k_e),
    num!("lim.i_max", "A", 1e-6, 100.0, |s| s.i_max),
    num!("lim.v_supply", "V", 0.1, 1e3, |s| s.v_supply),
    num!("lim.pos_min", "rad", -1e5, 1e5, |s| s.pos_min),
    num!("lim.pos_max", "rad", -1e5, 1e5, |s| s.pos_max),
    Param {
        path: "ff.mode",
        unit: "-",
        access: Access::Mode,
    },
    num!("ff.gain", "-", 0.0, 2.0, |s| s.ff.gain),
    num!("ff.inertia", "kg·m^2", 0.0, 1.0, |s| s.motor.inertia),
    num!("ff.static_band", "rad/s", 0.0, 1e3, |s| s.ff.static_band),
    num!("ff.adapt.gain", "1/s", 0.0, 1e4, |s| s.ff.adapt.gain),
    num!("ff.adapt.min", "-", 0.0, 10.0, |s| s.ff.adapt.min),
    num!("ff.adapt.max", "-", 0.0, 10.0, |s| s.ff.adapt.max),
    num!("ff.adapt.deadzone", "N·m", 0.0, 1e3, |s| s
        .ff
        .adapt
        .deadzone),
    num!("ff.adapt.vmin", "rad/s", 0.0, 1e4, |s| s.ff.adapt.v_min),
    Param {
        path: "ff.adapt.scale",
        unit: "-",
        access: Access::Estimate(Estimate::AdaptScale),
    },
    num!("gms.fs", "N·m", 0.0, 10.0, |s| s.ff.actuator.stribeck.fs),
    num!("gms.fc", "N·m", 0.0, 10.0, |s| s.ff.actuator.stribeck.fc),
    num!("gms.vs", "rad/s", 1e-9, 1e4, |s| s.ff.actuator.stribeck.vs),
    num!("gms.delta", "-", 0.01, 10.0, |s| s
        .ff
        .actuator
        .stribeck
        .delta),
    num!("gms.sigma", "N·m·s/rad", 0.0, 10.0, |s| s
        .ff
        .actuator
        .sigma),
    num!("gms.c", "N·m/s", 1e-12, 1e6, |s| s.ff.actuator.c),
    num!("gms.k1", "N·m/rad", 1e-12, 1e9, |s| s.ff.actuator.blocks
        [0]
    .k),
    num!("gms.k2", "N·m/rad", 1e-12, 1e9, |s| s.ff.actuator.blocks
        [1]
    .k),
    num!("gms.k3", "N·m/rad", 1e-12, 1e9, |s| s.ff.actuator.blocks
        [2]
    .k),
    num!("gms.k4", "N·m/rad", 1e-12, 1e9, |s| s.ff.actuator.blocks
        [3]
    .k),
    num!("gms.k5", "N·m/rad", 1e-12, 1e9, |s| s.ff.actuator.blocks
        [4]
    .k),
    num!("gms.k6", "N·m/rad", 1e-12, 1e9, |s| s.ff.actuator.blocks
        [5]
    .k),
    num!("gms.a1", "-", 1e-6, 1.0, |s| s.ff.actuator.blocks[0].alpha),
    num!("gms.a2", "-", 1e-6, 1.0, |s| s.ff.actuator.blocks[1].alpha),
    num!("gms.a3", "-", 1e-6, 1.0, |s| s.ff.actuator.blocks[2].alpha),
    num!("gms.a4", "-", 1e-6, 1.0, |s| s.ff.actuator.blocks[3].alpha),
    num!("gms.a5", "-", 1e-6, 1.0, |s| s.ff.actuator.blocks[4].alpha),
    num!("gms.a6", "-", 1e-6, 1.0, |s| s.ff.actuator.blocks[5].alpha),
];

const fn str_eq(a: &str, b: &str) -> bool {
    let (a, b) = (a.as_bytes(), b.as_bytes());
    if a.len() != b.len() {
        return false;
    }
    let mut i = 0;
    while i < a.len() {
        if a[i] != b[i] {
            return false;
        }
        i += 1;
    }
    true
}

/// The range `(min, max)` of the numeric parameter `path` in [`PARAMS`], for use in constant
/// context only (`const { range("pos.kp") }`): an unknown path fails the build.
pub const fn range(path: &str) -> (f32, f32) {
    let mut i = 0;
    while i < PARAMS.len() {
        if str_eq(PARAMS[i].path, path)
            && let Access::Number { min, max, .. } = PARAMS[i].access
        {
            return (min, max);
        }
        i += 1;
    }
    panic!("not a numeric parameter of the table")
}

/// The parameter with this path.
pub fn find(path: &str) -> Option<&'static Param> {
    PARAMS.iter().find(|p| p.path == path)
}

/// Writes a parameter's value (an estimate reads as 1 here: use [`write_param`] for the
/// device's own).
pub fn write_value(p: &Param, s: &Settings, out: &mut impl Write) -> fmt::Result {
    match p.access {
        Access::Number { get, .. } => write!(out, "{}", Num(get(s))),
        Access::Mode => out.write_str(s.ff.mode.name()),
        Access::Estimate(_) => write!(out, "{}", Num(1.0)),
    }
}

/// Writes a parameter's value as `dev` has it (settings and estimates).
pub fn write_param<D: Device + ?Sized>(
    p: &Param,
    dev: &mut D,
    out: &mut impl Write,
) -> fmt::Result {
    match p.access {
        Access::Estimate(e) => write!(out, "{}", Num(dev.estimate(e))),
        _ => write_value(p, dev.settings(), out),
    }
}

/// Sets one parameter of `s` from its text (a number within the table's range, or a mode
/// name), without validating the whole set (see [`with_value`]); on error `s` is unchanged.
pub fn set_param(s: &mut Settings, p: &Param, value: &str) -> Result<(), ParseError> {
    match p.access {
        Access::Number { set, min, max, .. } => {
            let v = parse_f32(value)
                .filter(|v| *v >= min && *v <= max)
                .ok_or(ParseError {
                    code: ErrorCode::OutOfRange,
                    reason: "not a finite number within the range (see list)",
                })?;
            set(s, v);
        }
        Access::Mode => {
            s.ff.mode = FfMode::from_name(value).ok_or(ParseError {
                code: ErrorCode::OutOfRange,
                reason: "ff.mode is none, static, gms or gms-adaptive",
            })?;
        }
        Access::Estimate(_) => {
            return Err(ParseError {
                code: ErrorCode::Refused,
                reason: "read-only: an estimate of the device",
            });
        }
    }
    Ok(())
}

/// `set`: the settings with `path` set to `value`, validated as a whole; on error nothing is
/// returned and the caller's settings stay as they are.
pub fn with_value(s: &Settings, path: &str, value: &str) -> Result<Settings, ParseError> {
    let p = find(path).ok_or(ParseError {
        code: ErrorCode::UnknownPath,
        reason: "unknown parameter (try list)",
    })?;
    let mut new = *s;
    set_param(&mut new, p, value)?;
    new.validate().map_err(|_| ParseError {
        code: ErrorCode::InvalidSet,
        reason: "the parameter set would be invalid",
    })?;
    Ok(new)
}

/// What the device does for the commands that are not about parameters. Every command can
/// be refused with a reason (the reply is then `err 8 <reason>` and nothing changed).
pub trait Device {
    /// The current settings.
    fn settings(&self) -> &Settings;
    /// Applies a validated set (between two control steps); refused when the device cannot
    /// run it, and then nothing changes.
    fn apply(&mut self, new: Settings) -> Result<(), &'static str>;
    /// Persists the current set.
    fn save(&mut self) -> Result<(), &'static str>;
    /// Restores the persisted set.
    fn load(&mut self) -> Result<(), &'static str>;
    /// Restores the built-in defaults.
    fn defaults(&mut self) -> Result<(), &'static str>;
    /// Switches the bridge on (position control).
    fn enable(&mut self) -> Result<(), &'static str>;
    /// Switches the bridge off.
    fn disable(&mut self) -> Result<(), &'static str>;
    /// Writes the status (without the leading `ok `) on one line.
    fn status(&mut self, out: &mut dyn Write) -> fmt::Result;
    /// Clears latched faults.
    fn clear(&mut self) -> Result<(), &'static str>;
    /// Moves to `pos` \[rad\] at up to `vel` [rad/s].
    fn move_to(&mut self, pos: f32, vel: Option<f32>) -> Result<(), &'static str>;
    /// Starts telemetry of `fields` at `rate_hz`.
    fn stream(&mut self, fields: &str, rate_hz: f32) -> Result<(), &'static str>;
    /// Stops telemetry.
    fn stream_off(&mut self) -> Result<(), &'static str>;
    /// An on-line estimate (read-only parameter); 1 for the adaptive scale of a device
    /// without adaptation.
    fn estimate(&mut self, which: Estimate) -> f32 {
        match which {
            Estimate::AdaptScale => 1.0,
        }
    }
}

/// The `help` text.
pub const HELP: &str = "help | list | get PATH | set PATH VALUE | save | load | defaults | \
enable | disable | status | clear | move POS [VEL] | stream FIELDS RATE_HZ | stream off";

fn err(out: &mut impl Write, code: ErrorCode, reason: &str) -> fmt::Result {
    writeln!(out, "err {} {}", code as u8, reason)
}

fn done(out: &mut impl Write, r: Result<(), &'static str>) -> fmt::Result {
    match r {
        Ok(()) => writeln!(out, "ok"),
        Err(reason) => err(out, ErrorCode::Refused, reason),
    }
}

/// Handles one received line: parses it, acts on `dev`, writes the reply to `out`.
pub fn execute<D: Device, W: Write>(dev: &mut D, line: Line<'_>, out: &mut W) -> fmt::Result {
    let text = match line {
        Line::Text(t) => t,
        Line::TooLong => return err(out, ErrorCode::LineTooLong, "line too long"),
        Line::NotText => return err(out, ErrorCode::NotText, "not printable ASCII"),
    };
    let cmd = match parse(text) {
        Ok(c) => c,
        Err(e) => return err(out, e.code, e.reason),
    };
    match cmd {
        Command::Empty => Ok(()),
        Command::Help => {
            writeln!(out, "{HELP}")?;
            writeln!(out, "ok")
        }
        Command::List => {
            let s = *dev.settings();
            for p in PARAMS {
                write!(out, "{} ", p.path)?;
                match p.access {
                    Access::Number { min, max, .. } => {
                        write_value(p, &s, out)?;
                        writeln!(out, " {} [{}, {}]", p.unit, Num(min), Num(max))?
                    }
                    Access::Mode => {
                        write_value(p, &s, out)?;
                        writeln!(out, " - [none, static, gms, gms-adaptive]")?
                    }
                    Access::Estimate(e) => writeln!(out, "{} - [read-only]", Num(dev.estimate(e)))?,
                }
            }
            writeln!(out, "ok")
        }
        Command::Get(path) => match find(path) {
            Some(p) => {
                out.write_str("ok ")?;
                write_param(p, dev, out)?;
                writeln!(out)
            }
            None => err(out, ErrorCode::UnknownPath, "unknown parameter (try list)"),
        },
        Command::Set(path, value) => match with_value(dev.settings(), path, value) {
            Ok(new) => done(out, dev.apply(new)),
            Err(e) => err(out, e.code, e.reason),
        },
        Command::Save => done(out, dev.save()),
        Command::Load => done(out, dev.load()),
        Command::Defaults => done(out, dev.defaults()),
        Command::Enable => done(out, dev.enable()),
        Command::Disable => done(out, dev.disable()),
        Command::Status => {
            out.write_str("ok ")?;
            dev.status(out)?;
            writeln!(out)
        }
        Command::Clear => done(out, dev.clear()),
        Command::Move { pos, vel } => done(out, dev.move_to(pos, vel)),
        Command::Stream { fields, rate_hz } => done(out, dev.stream(fields, rate_hz)),
        Command::StreamOff => done(out, dev.stream_off()),
    }
}
