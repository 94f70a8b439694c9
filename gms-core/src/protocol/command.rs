//! Request lines parsed into commands, and the protocol's error codes.

/// The capture buffer's commands.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CaptureCmd<'a> {
    /// `capture`: its state.
    Status,
    /// `capture off`: stop and drop.
    Off,
    /// `capture FIELDS EVERY SAMPLES [next]`: record FIELDS (comma-separated) every EVERY
    /// position steps, SAMPLES of them, from now or from the next experiment request.
    Arm {
        /// Field names, comma-separated.
        fields: &'a str,
        /// Position steps per sample.
        every: u32,
        /// Samples.
        samples: u32,
        /// Start at the next experiment request.
        on_next: bool,
    },
    /// `capture read START COUNT`: samples START.. (COUNT at most [`MAX_READ`]), one line each.
    Read {
        /// First sample.
        start: u32,
        /// Samples.
        count: u32,
    },
}

/// The frequency-response commands.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FrfCmd {
    /// `frf`: the measurement's state and result.
    Status,
    /// `frf off`: stop the one under way.
    Off,
    /// `frf current|position F_HZ AMP PERIODS SETTLE`: inject a sine of `F_HZ` \[Hz\] and
    /// `AMP` (A at the current command, rad at the position reference), let `SETTLE` periods
    /// pass, then demodulate `PERIODS` periods (both rounded up to whole groups).
    Start {
        /// Where the sine goes.
        injection: crate::control::frf::Injection,
        /// Frequency \[Hz\].
        f_hz: f32,
        /// Amplitude \[A or rad\].
        amp: f32,
        /// Periods summed.
        periods: u32,
        /// Periods let pass first.
        settle: u32,
    },
}

/// The position map's table commands.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum MapCmd<'a> {
    /// `map read START COUNT`: bins START.. (COUNT at most [`MAX_READ`]), `offset,scale` a line.
    Read {
        /// First bin.
        start: u32,
        /// Bins.
        count: u32,
    },
    /// `map write START OFFSET,SCALE …`: bins from START (at most
    /// `MAP_WRITE_BINS` a line: the device's mailbox).
    Write {
        /// First bin.
        start: u32,
        /// The pairs, as text (`offset,scale` separated by spaces).
        pairs: &'a str,
    },
    /// `map clear`: offsets 0, scales 1.
    Clear,
}

/// The table motion's commands (`table …`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TableCmd<'a> {
    /// `table`: the state, the geometry, the run and the last complete period.
    Status,
    /// `table ref START V …` or `table corr START V …`: points from START of the reference
    /// \[counts from the origin\] or of the correction being written \[N·m\] (at most
    /// [`crate::control::table::TABLE_WRITE_VALUES`] a line), in order from 0.
    Write {
        /// Which table (`Ref` or `Corr`).
        which: crate::control::table::Which,
        /// First point.
        start: u32,
        /// The values, as text (separated by spaces).
        values: &'a str,
    },
    /// `table set POINTS STEPS ORIGIN`: the reference written is checked whole and played
    /// with this geometry (STEPS position steps between points, ORIGIN \[counts\]).
    Set(crate::control::table::Geometry),
    /// `table use`: the correction written is played from the next period's start.
    Use,
    /// `table corr off`: no correction from the next period's start.
    CorrOff,
    /// `table run PERIODS`: play the table from its start.
    Run(u32),
    /// `table stop`: end the run at the end of the period under way.
    Stop,
    /// `table read ref|corr|err START COUNT`: points START.. (COUNT at most [`MAX_READ`]), a
    /// value a line.
    Read {
        /// Which table.
        which: crate::control::table::Which,
        /// First point.
        start: u32,
        /// Points.
        count: u32,
    },
    /// `table clear`: forget the reference and the correction.
    Clear,
    /// `table next`: release the period held; the next complete period of the correction
    /// played is held in its place.
    Next,
}

/// Up to `max` decimal digits (digits only) as a `u64`, without core's parser (whose error
/// path the no-panic link check cannot see through).
fn parse_digits(s: &str, max: usize) -> Option<u64> {
    if s.is_empty() || s.len() > max {
        return None;
    }
    let mut v: u64 = 0;
    for b in s.bytes() {
        if !b.is_ascii_digit() {
            return None;
        }
        v = v * 10 + u64::from(b - b'0');
    }
    Some(v)
}

/// A decimal `i64` (an optional sign, then up to 18 digits).
fn parse_i64(s: &str) -> Option<i64> {
    let (neg, digits) = match s.as_bytes().first() {
        Some(b'-') => (true, s.get(1..)?),
        Some(b'+') => (false, s.get(1..)?),
        _ => (false, s),
    };
    let v = parse_digits(digits, 18)? as i64;
    Some(if neg { -v } else { v })
}

/// A decimal `u32` (digits only).
fn parse_u32(s: &str) -> Option<u32> {
    u32::try_from(parse_digits(s, 10)?).ok()
}

/// What follows the first `n` words of `line`, trimmed (a command's free-form tail: the map's
/// pairs, the table's values).
fn after_words(line: &str, n: usize) -> &str {
    let mut rest = line.trim_start();
    for _ in 0..n {
        let w = rest.split_ascii_whitespace().next().unwrap_or("");
        rest = rest.strip_prefix(w).unwrap_or("").trim_start();
    }
    rest.trim_end()
}

/// The most samples one `capture read` returns (a reply stays under the firmware's 4 KiB).
pub const MAX_READ: u32 = 64;

/// Error codes of `err` replies.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ErrorCode {
    /// 1: the command is not known.
    UnknownCommand = 1,
    /// 2: missing, extra or malformed arguments.
    BadArgument = 2,
    /// 3: the line was longer than [`MAX_LINE`](super::MAX_LINE).
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
    /// 9: the line was damaged on the link (a UART's framing, noise, parity or overrun error,
    /// or its receive ring lapped or stopped): not run.
    LinkError = 9,
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
    /// `stage PATH VALUE`: a change kept aside (range-checked) until `commit`.
    Stage(&'a str, &'a str),
    /// `commit`: the staged changes applied as one set, validated as a whole.
    Commit,
    /// `discard`: the staged changes dropped.
    Discard,
    /// `save`.
    Save,
    /// `load`.
    Load,
    /// `defaults`.
    Defaults,
    /// `enable`: position control holding where the axis is; `enable current`: straight into
    /// current mode at 0 A, the position loop never closed (the first step of an experiment
    /// on an axis whose encoder direction is not yet known).
    Enable {
        /// `enable current`.
        current: bool,
    },
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
    /// `current AMPS`: hold a current \[A\] with the position loop off.
    Current {
        /// The current \[A\].
        amps: f32,
        /// For how long \[s\] (then 0 A, still in current mode): a pulse the device ends by
        /// itself; `None`: until the next request.
        seconds: Option<f32>,
    },
    /// `velocity VEL [AMP F0 F1 SECONDS]`: a constant speed [rad/s], with a sweep around it.
    Velocity {
        /// Mean speed [rad/s].
        vel: f32,
        /// The sweep, if given.
        sweep: Option<crate::control::reference::Sweep>,
    },
    /// `hold`: back to position control.
    Hold,
    /// `capture …`.
    Capture(CaptureCmd<'a>),
    /// `stream FIELDS RATE_HZ`: comma-separated field names, rate \[Hz\].
    Stream {
        /// Field names, comma-separated.
        fields: &'a str,
        /// Rate \[Hz\].
        rate_hz: f32,
    },
    /// `stream off`.
    StreamOff,
    /// `frf …`.
    Frf(FrfCmd),
    /// `map …`.
    Map(MapCmd<'a>),
    /// `table …`.
    Table(TableCmd<'a>),
}

impl Command<'_> {
    /// The command's first word (`move`, `table`, …; empty for [`Command::Empty`]).
    pub fn name(&self) -> &'static str {
        match self {
            Command::Empty => "",
            Command::Help => "help",
            Command::List => "list",
            Command::Get(_) => "get",
            Command::Set(..) => "set",
            Command::Stage(..) => "stage",
            Command::Commit => "commit",
            Command::Discard => "discard",
            Command::Save => "save",
            Command::Load => "load",
            Command::Defaults => "defaults",
            Command::Enable { .. } => "enable",
            Command::Disable => "disable",
            Command::Status => "status",
            Command::Clear => "clear",
            Command::Move { .. } => "move",
            Command::Current { .. } => "current",
            Command::Velocity { .. } => "velocity",
            Command::Hold => "hold",
            Command::Capture(_) => "capture",
            Command::Stream { .. } | Command::StreamOff => "stream",
            Command::Frf(_) => "frf",
            Command::Map(_) => "map",
            Command::Table(_) => "table",
        }
    }
}

/// The request line of a command (without the line end): what a host sends, read back by
/// [`parse`] as the same command (numbers in the shortest decimal that reads back exactly).
/// `Empty` writes nothing.
impl core::fmt::Display for Command<'_> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        use crate::numtext::Num;
        match *self {
            Command::Empty => Ok(()),
            Command::Help => f.write_str("help"),
            Command::List => f.write_str("list"),
            Command::Get(path) => write!(f, "get {path}"),
            Command::Set(path, value) => write!(f, "set {path} {value}"),
            Command::Stage(path, value) => write!(f, "stage {path} {value}"),
            Command::Commit => f.write_str("commit"),
            Command::Discard => f.write_str("discard"),
            Command::Save => f.write_str("save"),
            Command::Load => f.write_str("load"),
            Command::Defaults => f.write_str("defaults"),
            Command::Enable { current: false } => f.write_str("enable"),
            Command::Enable { current: true } => f.write_str("enable current"),
            Command::Disable => f.write_str("disable"),
            Command::Status => f.write_str("status"),
            Command::Clear => f.write_str("clear"),
            Command::Move { pos, vel } => {
                write!(f, "move {}", Num(pos))?;
                match vel {
                    Some(v) => write!(f, " {}", Num(v)),
                    None => Ok(()),
                }
            }
            Command::Current { amps, seconds } => {
                write!(f, "current {}", Num(amps))?;
                match seconds {
                    Some(s) => write!(f, " {}", Num(s)),
                    None => Ok(()),
                }
            }
            Command::Velocity { vel, sweep } => {
                write!(f, "velocity {}", Num(vel))?;
                match sweep {
                    Some(s) => write!(
                        f,
                        " {} {} {} {}",
                        Num(s.amp),
                        Num(s.f0),
                        Num(s.f1),
                        Num(s.seconds)
                    ),
                    None => Ok(()),
                }
            }
            Command::Hold => f.write_str("hold"),
            Command::Capture(CaptureCmd::Status) => f.write_str("capture"),
            Command::Capture(CaptureCmd::Off) => f.write_str("capture off"),
            Command::Capture(CaptureCmd::Arm {
                fields,
                every,
                samples,
                on_next,
            }) => {
                write!(f, "capture {fields} {every} {samples}")?;
                if on_next {
                    f.write_str(" next")
                } else {
                    Ok(())
                }
            }
            Command::Capture(CaptureCmd::Read { start, count }) => {
                write!(f, "capture read {start} {count}")
            }
            Command::Stream { fields, rate_hz } => write!(f, "stream {fields} {}", Num(rate_hz)),
            Command::StreamOff => f.write_str("stream off"),
            Command::Map(MapCmd::Read { start, count }) => write!(f, "map read {start} {count}"),
            Command::Map(MapCmd::Write { start, pairs }) => write!(f, "map write {start} {pairs}"),
            Command::Map(MapCmd::Clear) => f.write_str("map clear"),
            Command::Table(t) => {
                use crate::control::table::Which;
                let name = |w: Which| match w {
                    Which::Ref => "ref",
                    Which::Corr => "corr",
                    Which::Err => "err",
                };
                match t {
                    TableCmd::Status => f.write_str("table"),
                    TableCmd::Write {
                        which,
                        start,
                        values,
                    } => write!(f, "table {} {start} {values}", name(which)),
                    TableCmd::Set(g) => {
                        write!(f, "table set {} {} {}", g.points, g.steps, g.origin)
                    }
                    TableCmd::Use => f.write_str("table use"),
                    TableCmd::CorrOff => f.write_str("table corr off"),
                    TableCmd::Run(n) => write!(f, "table run {n}"),
                    TableCmd::Stop => f.write_str("table stop"),
                    TableCmd::Read {
                        which,
                        start,
                        count,
                    } => write!(f, "table read {} {start} {count}", name(which)),
                    TableCmd::Clear => f.write_str("table clear"),
                    TableCmd::Next => f.write_str("table next"),
                }
            }
            Command::Frf(FrfCmd::Status) => f.write_str("frf"),
            Command::Frf(FrfCmd::Off) => f.write_str("frf off"),
            Command::Frf(FrfCmd::Start {
                injection,
                f_hz,
                amp,
                periods,
                settle,
            }) => write!(
                f,
                "frf {} {} {} {periods} {settle}",
                injection.name(),
                Num(f_hz),
                Num(amp)
            ),
        }
    }
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
        "enable" => match arg() {
            None => Command::Enable { current: false },
            Some("current") => Command::Enable { current: true },
            Some(_) => return Err(bad("usage: enable [current]")),
        },
        "disable" => Command::Disable,
        "status" => Command::Status,
        "clear" => Command::Clear,
        "get" => Command::Get(arg().ok_or(bad("usage: get PATH"))?),
        "set" => {
            let path = arg().ok_or(bad("usage: set PATH VALUE"))?;
            let value = arg().ok_or(bad("usage: set PATH VALUE"))?;
            Command::Set(path, value)
        }
        "stage" => {
            let path = arg().ok_or(bad("usage: stage PATH VALUE"))?;
            let value = arg().ok_or(bad("usage: stage PATH VALUE"))?;
            Command::Stage(path, value)
        }
        "commit" => Command::Commit,
        "discard" => Command::Discard,
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
        "hold" => Command::Hold,
        "capture" => {
            let usage = "usage: capture | capture off | capture FIELDS EVERY SAMPLES [next] | capture read START COUNT";
            let int = |w: Option<&str>| w.and_then(parse_u32).ok_or(bad(usage));
            match arg() {
                None => Command::Capture(CaptureCmd::Status),
                Some("off") => Command::Capture(CaptureCmd::Off),
                Some("read") => {
                    let start = int(arg())?;
                    let count = int(arg())?;
                    if count == 0 || count > MAX_READ {
                        return Err(bad("COUNT from 1 to 64"));
                    }
                    Command::Capture(CaptureCmd::Read { start, count })
                }
                Some(fields) => {
                    let every = int(arg())?;
                    let samples = int(arg())?;
                    let on_next = match arg() {
                        None => false,
                        Some("next") => true,
                        Some(_) => return Err(bad(usage)),
                    };
                    if every == 0 || samples == 0 {
                        return Err(bad("EVERY and SAMPLES must be >= 1"));
                    }
                    Command::Capture(CaptureCmd::Arm {
                        fields,
                        every,
                        samples,
                        on_next,
                    })
                }
            }
        }
        "current" => {
            let usage = "usage: current AMPS [SECONDS]";
            let amps = arg().and_then(parse_f32).ok_or(bad(usage))?;
            let seconds = match arg() {
                None => None,
                Some(w) => Some(parse_f32(w).ok_or(bad(usage))?),
            };
            Command::Current { amps, seconds }
        }
        "velocity" => {
            let usage = "usage: velocity VEL [AMP F0 F1 SECONDS]";
            let vel = arg().and_then(parse_f32).ok_or(bad(usage))?;
            let sweep = match arg() {
                None => None,
                Some(a) => {
                    let num = |w: Option<&str>| w.and_then(parse_f32).ok_or(bad(usage));
                    let amp = num(Some(a))?;
                    let f0 = num(arg())?;
                    let f1 = num(arg())?;
                    let seconds = num(arg())?;
                    Some(crate::control::reference::Sweep {
                        amp,
                        f0,
                        f1,
                        seconds,
                    })
                }
            };
            Command::Velocity { vel, sweep }
        }
        "map" => {
            let usage =
                "usage: map read START COUNT | map write START OFFSET,SCALE ... | map clear";
            let int = |w: Option<&str>| w.and_then(parse_u32).ok_or(bad(usage));
            match arg() {
                Some("read") => {
                    let start = int(arg())?;
                    let count = int(arg())?;
                    if count == 0 || count > MAX_READ {
                        return Err(bad("COUNT from 1 to 64"));
                    }
                    Command::Map(MapCmd::Read { start, count })
                }
                Some("write") => {
                    let start = int(arg())?;
                    // The rest of the line: the pairs (checked by the device).
                    let rest = after_words(line, 3);
                    if rest.is_empty() {
                        return Err(bad(usage));
                    }
                    return Ok(Command::Map(MapCmd::Write { start, pairs: rest }));
                }
                Some("clear") => Command::Map(MapCmd::Clear),
                _ => return Err(bad(usage)),
            }
        }
        "table" => {
            use crate::control::table::Which;
            let usage = "usage: table | table ref|corr START V ... | table corr off | \
table set POINTS STEPS ORIGIN | table use | table run PERIODS | table stop | \
table read ref|corr|err START COUNT | table next | table clear";
            let int = |w: Option<&str>| w.and_then(parse_u32).ok_or(bad(usage));
            match arg() {
                None => Command::Table(TableCmd::Status),
                Some("corr") if line.split_ascii_whitespace().nth(2) == Some("off") => {
                    let _ = arg();
                    Command::Table(TableCmd::CorrOff)
                }
                Some(w @ ("ref" | "corr")) => {
                    let which = if w == "ref" { Which::Ref } else { Which::Corr };
                    let start = int(arg())?;
                    // The rest of the line: the values (checked by the device).
                    let rest = after_words(line, 3);
                    if rest.is_empty() {
                        return Err(bad(usage));
                    }
                    return Ok(Command::Table(TableCmd::Write {
                        which,
                        start,
                        values: rest,
                    }));
                }
                Some("set") => {
                    let points = int(arg())?;
                    let steps = int(arg())?;
                    let origin = arg().and_then(parse_i64).ok_or(bad(usage))?;
                    Command::Table(TableCmd::Set(crate::control::table::Geometry {
                        points,
                        steps,
                        origin,
                    }))
                }
                Some("use") => Command::Table(TableCmd::Use),
                Some("run") => {
                    let n = int(arg())?;
                    if n == 0 || n > crate::control::table::TABLE_MAX_PERIODS {
                        return Err(bad("PERIODS from 1 to 1000000"));
                    }
                    Command::Table(TableCmd::Run(n))
                }
                Some("stop") => Command::Table(TableCmd::Stop),
                Some("read") => {
                    let which = arg().and_then(Which::from_name).ok_or(bad(usage))?;
                    let start = int(arg())?;
                    let count = int(arg())?;
                    if count == 0 || count > MAX_READ {
                        return Err(bad("COUNT from 1 to 64"));
                    }
                    Command::Table(TableCmd::Read {
                        which,
                        start,
                        count,
                    })
                }
                Some("clear") => Command::Table(TableCmd::Clear),
                Some("next") => Command::Table(TableCmd::Next),
                _ => return Err(bad(usage)),
            }
        }
        "frf" => {
            let usage = "usage: frf | frf off | frf current|position F_HZ AMP PERIODS SETTLE";
            match arg() {
                None => Command::Frf(FrfCmd::Status),
                Some("off") => Command::Frf(FrfCmd::Off),
                Some(w) => {
                    let injection =
                        crate::control::frf::Injection::from_name(w).ok_or(bad(usage))?;
                    let f_hz = arg().and_then(parse_f32).ok_or(bad(usage))?;
                    let amp = arg().and_then(parse_f32).ok_or(bad(usage))?;
                    let periods = arg().and_then(parse_u32).ok_or(bad(usage))?;
                    let settle = arg().and_then(parse_u32).ok_or(bad(usage))?;
                    Command::Frf(FrfCmd::Start {
                        injection,
                        f_hz,
                        amp,
                        periods,
                        settle,
                    })
                }
            }
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
