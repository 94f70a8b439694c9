//! The replies that carry data, typed: each is written by the device and read back on a host
//! by the same type, so a reply's keys and formats live in one place (as [`StatusReply`] for
//! `status`).
//!
//! - [`CaptureStatus`]: `capture` (`state= samples= capacity= origin=`).
//! - [`FrfStatus`]: `frf` (`state= inj= f_hz= amp= groups=G/N in= cmd= cur= pos= coh=`).
//! - [`TableStatus`]: `table` (`state= points= steps= origin= period= … held=`).
//! - [`write_row`] / [`row`]: a line of comma-separated numbers (`capture read`, `map read`,
//!   `table read`).
//! - [`ListRow`]: a line of `list` (`PATH VALUE UNIT [RANGE]`).
//! - [`write_telemetry`] / [`telemetry`]: a telemetry line's `name=value` words.
//!
//! A reader ignores keys it does not know (a newer device may add some) and refuses a reply
//! that lacks one it needs, naming it ([`ReplyError`]). Numbers are written as
//! [`Num`](crate::numtext::Num) writes them (shortest round-trip digits), so an f32 reads
//! back exactly.
//!
//! [`StatusReply`]: crate::device::StatusReply

use core::fmt::{self, Write};

use crate::control::frf::{FrfState, Injection};
use crate::control::table::{Geometry, PeriodError, TableReport, TableState};
use crate::numtext::{Int, Num};

/// Why a reply could not be read: the key that is missing or whose value does not parse.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ReplyError {
    /// The reply (`status`, `capture`, `frf`, `table`, `list`, a row).
    pub reply: &'static str,
    /// The key (for a row or a `list` line, what of it: `value`, `range`).
    pub key: &'static str,
    /// True when the key is there but its value does not parse.
    pub bad_value: bool,
}

impl fmt::Display for ReplyError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.bad_value {
            write!(f, "the {} reply's {} does not parse", self.reply, self.key)
        } else {
            write!(f, "the {} reply has no {}", self.reply, self.key)
        }
    }
}

/// A reply of `key=value` words being read: each key's value found by name.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Words<'a> {
    text: &'a str,
    reply: &'static str,
}

impl<'a> Words<'a> {
    /// The words of `text`, a reply of kind `reply` (named in errors).
    pub(crate) fn new(text: &'a str, reply: &'static str) -> Words<'a> {
        Words { text, reply }
    }

    /// The error for `key`.
    pub(crate) fn error(&self, key: &'static str, bad_value: bool) -> ReplyError {
        ReplyError {
            reply: self.reply,
            key,
            bad_value,
        }
    }

    /// The value of `key`, if the reply has it.
    pub(crate) fn get(&self, key: &str) -> Option<&'a str> {
        self.text
            .split_ascii_whitespace()
            .find_map(|w| w.strip_prefix(key)?.strip_prefix('='))
    }

    /// The value of `key`.
    pub(crate) fn value(&self, key: &'static str) -> Result<&'a str, ReplyError> {
        self.get(key).ok_or(self.error(key, false))
    }

    /// The value of `key`, parsed.
    pub(crate) fn number<T: core::str::FromStr>(&self, key: &'static str) -> Result<T, ReplyError> {
        self.value(key)?.parse().map_err(|_| self.error(key, true))
    }

    /// The value of `key`, parsed, or `None` without it (a bad value is still an error).
    pub(crate) fn number_if<T: core::str::FromStr>(
        &self,
        key: &'static str,
    ) -> Result<Option<T>, ReplyError> {
        self.get(key)
            .map(|v| v.parse().map_err(|_| self.error(key, true)))
            .transpose()
    }

    /// The flag `key` (`0` or `1`).
    pub(crate) fn flag(&self, key: &'static str) -> Result<bool, ReplyError> {
        match self.value(key)? {
            "0" => Ok(false),
            "1" => Ok(true),
            _ => Err(self.error(key, true)),
        }
    }

    /// The value of `key` read by `from_name` (a state's or a mode's name).
    pub(crate) fn named<T>(
        &self,
        key: &'static str,
        from_name: impl Fn(&str) -> Option<T>,
    ) -> Result<T, ReplyError> {
        from_name(self.value(key)?).ok_or(self.error(key, true))
    }

    /// `N` values of `key` separated by `,`.
    pub(crate) fn numbers<const N: usize>(
        &self,
        key: &'static str,
    ) -> Result<[f32; N], ReplyError> {
        let mut out = [0.0; N];
        let mut parts = self.value(key)?.split(',');
        for slot in &mut out {
            *slot = parts
                .next()
                .and_then(|p| p.parse().ok())
                .ok_or(self.error(key, true))?;
        }
        match parts.next() {
            None => Ok(out),
            Some(_) => Err(self.error(key, true)),
        }
    }
}

/// Where a capture is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum CaptureState {
    /// Nothing asked.
    #[default]
    Idle,
    /// Waiting for its trigger.
    Armed,
    /// Recording.
    Recording,
    /// Full: readable.
    Done,
}

impl CaptureState {
    /// The name in `capture`'s reply.
    pub fn name(self) -> &'static str {
        match self {
            CaptureState::Idle => "idle",
            CaptureState::Armed => "armed",
            CaptureState::Recording => "recording",
            CaptureState::Done => "done",
        }
    }

    /// Every state, in the order a capture goes through them.
    pub const ALL: [CaptureState; 4] = [
        CaptureState::Idle,
        CaptureState::Armed,
        CaptureState::Recording,
        CaptureState::Done,
    ];

    /// The state called `name`, if any.
    pub fn from_name(name: &str) -> Option<CaptureState> {
        CaptureState::ALL.into_iter().find(|s| s.name() == name)
    }
}

/// The capture's state as `capture` reports it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CaptureStatus {
    /// Where the capture is.
    pub state: CaptureState,
    /// Samples recorded.
    pub samples: u32,
    /// The buffer's size (values: samples × fields at most that).
    pub capacity: u32,
    /// The position the captured positions are relative to \[rad\] (written as an f32, read as
    /// the f64 of its decimal text).
    pub origin: f64,
}

impl CaptureStatus {
    /// Writes the reply (without the leading `ok `) on one line.
    pub fn write(&self, out: &mut dyn Write) -> fmt::Result {
        write!(
            out,
            "state={} samples={} capacity={} origin={}",
            self.state.name(),
            self.samples,
            self.capacity,
            Num(self.origin as f32)
        )
    }

    /// Reads a reply (the text after `ok`).
    pub fn parse(text: &str) -> Result<CaptureStatus, ReplyError> {
        let w = Words::new(text, "capture");
        Ok(CaptureStatus {
            state: w.named("state", CaptureState::from_name)?,
            samples: w.number("samples")?,
            capacity: w.number("capacity")?,
            origin: w.number("origin")?,
        })
    }
}

impl FrfState {
    /// Every state, in the order a measurement goes through them.
    pub const ALL: [FrfState; 5] = [
        FrfState::Idle,
        FrfState::Settling,
        FrfState::Measuring,
        FrfState::Done,
        FrfState::Stopped,
    ];

    /// The state called `name`, if any.
    pub fn from_name(name: &str) -> Option<FrfState> {
        FrfState::ALL.into_iter().find(|s| s.name() == name)
    }
}

/// The signals a frequency response reports, in the reply's order: the sine injected (`in`),
/// the current command (`cmd`), the measured current (`cur`) and the position (`pos`).
pub const FRF_SIGNALS: [&str; 4] = ["in", "cmd", "cur", "pos"];

/// A measurement's figures as `frf` reports them (once one was asked).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrfMeasure {
    /// Where the sine goes.
    pub injection: Injection,
    /// The frequency run \[Hz\].
    pub f_hz: f32,
    /// The amplitude injected (A or rad).
    pub amp: f32,
    /// Groups of periods summed so far.
    pub groups_done: u32,
    /// Groups to be summed in all.
    pub groups: u32,
    /// Each signal's component at the frequency, `[re, im]` (units of the signal), in
    /// [`FRF_SIGNALS`]' order.
    pub phasors: [[f32; 2]; 4],
    /// Each signal's coherence with the sine (0 … 1, NaN before a group is summed), in
    /// [`FRF_SIGNALS`]' order.
    pub coherence: [f32; 4],
}

/// The frequency-response measurement as `frf` reports it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrfStatus {
    /// Where it stands.
    pub state: FrfState,
    /// Its figures (`None` before the first measurement since start).
    pub measure: Option<FrfMeasure>,
}

impl FrfStatus {
    /// Writes the reply (without the leading `ok `) on one line.
    pub fn write(&self, out: &mut dyn Write) -> fmt::Result {
        write!(out, "state={}", self.state.name())?;
        let Some(m) = &self.measure else {
            return Ok(());
        };
        write!(
            out,
            " inj={} f_hz={} amp={} groups={}/{}",
            m.injection.name(),
            Num(m.f_hz),
            Num(m.amp),
            m.groups_done,
            m.groups
        )?;
        for (name, [re, im]) in FRF_SIGNALS.iter().zip(m.phasors) {
            write!(out, " {name}={},{}", Num(re), Num(im))?;
        }
        out.write_str(" coh=")?;
        for (k, c) in m.coherence.iter().enumerate() {
            if k > 0 {
                out.write_char(',')?;
            }
            write!(out, "{}", Num(*c))?;
        }
        Ok(())
    }

    /// Reads a reply (the text after `ok`): the figures when it names an injection.
    pub fn parse(text: &str) -> Result<FrfStatus, ReplyError> {
        let w = Words::new(text, "frf");
        let state = w.named("state", FrfState::from_name)?;
        if w.get("inj").is_none() {
            return Ok(FrfStatus {
                state,
                measure: None,
            });
        }
        let (done, all) = w
            .value("groups")?
            .split_once('/')
            .and_then(|(a, b)| Some((a.parse().ok()?, b.parse().ok()?)))
            .ok_or(w.error("groups", true))?;
        let mut phasors = [[0.0; 2]; 4];
        for (p, name) in phasors.iter_mut().zip(FRF_SIGNALS) {
            *p = w.numbers::<2>(name)?;
        }
        Ok(FrfStatus {
            state,
            measure: Some(FrfMeasure {
                injection: w.named("inj", Injection::from_name)?,
                f_hz: w.number("f_hz")?,
                amp: w.number("amp")?,
                groups_done: done,
                groups: all,
                phasors,
                coherence: w.numbers::<4>("coh")?,
            }),
        })
    }
}

impl TableState {
    /// Every state.
    pub const ALL: [TableState; 3] = [TableState::Empty, TableState::Ready, TableState::Playing];

    /// The state called `name`, if any.
    pub fn from_name(name: &str) -> Option<TableState> {
        TableState::ALL.into_iter().find(|s| s.name() == name)
    }
}

/// The table motion as `table` reports it: `None` on a device without one (`state=none`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TableStatus(pub Option<TableReport>);

impl TableStatus {
    /// Writes the reply (without the leading `ok `) on one line.
    pub fn write(&self, out: &mut dyn Write) -> fmt::Result {
        let Some(t) = &self.0 else {
            return out.write_str("state=none");
        };
        write!(out, "state={}", t.state.name())?;
        if let Some(g) = t.geometry {
            write!(
                out,
                " points={} steps={} origin={}",
                g.points,
                g.steps,
                Int(g.origin)
            )?;
        }
        write!(
            out,
            " period={} periods={} gen={} pending={} started={}",
            t.period,
            t.periods,
            t.generation,
            u8::from(t.pending),
            Int(t.started as i64)
        )?;
        if let Some(d) = t.done {
            write!(
                out,
                " done={} done_gen={} rms={} peak={}",
                d.period,
                d.generation,
                Num(d.rms),
                Num(d.peak),
            )?;
        }
        write!(out, " held={}", u8::from(t.held))
    }

    /// Reads a reply (the text after `ok`): the geometry when it has `points`, the last
    /// period's figures when it has `done`.
    pub fn parse(text: &str) -> Result<TableStatus, ReplyError> {
        let w = Words::new(text, "table");
        if w.value("state")? == "none" {
            return Ok(TableStatus(None));
        }
        let geometry = match w.number_if("points")? {
            None => None,
            Some(points) => Some(Geometry {
                points,
                steps: w.number("steps")?,
                origin: w.number("origin")?,
            }),
        };
        let done = match w.number_if("done")? {
            None => None,
            Some(period) => Some(PeriodError {
                period,
                generation: w.number("done_gen")?,
                rms: w.number("rms")?,
                peak: w.number("peak")?,
            }),
        };
        Ok(TableStatus(Some(TableReport {
            state: w.named("state", TableState::from_name)?,
            geometry,
            period: w.number("period")?,
            periods: w.number("periods")?,
            generation: w.number("gen")?,
            pending: w.flag("pending")?,
            done,
            held: w.flag("held")?,
            started: w.number("started")?,
        })))
    }
}

/// Writes one row of values, comma-separated, and its newline (a line of `capture read`,
/// `map read`, `table read`).
pub fn write_row(out: &mut dyn Write, values: &[f32]) -> fmt::Result {
    for (k, v) in values.iter().enumerate() {
        if k > 0 {
            out.write_char(',')?;
        }
        write!(out, "{}", Num(*v))?;
    }
    out.write_char('\n')
}

/// The values of one row written by [`write_row`] (without its newline), each read as the
/// f64 of its decimal text; an item is an error where a value does not parse.
pub fn row(line: &str) -> impl Iterator<Item = Result<f64, ReplyError>> + '_ {
    line.split(',').map(|v| {
        v.trim().parse().map_err(|_| ReplyError {
            reply: "row",
            key: "value",
            bad_value: true,
        })
    })
}

/// What a parameter may be set to, as `list` prints it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ListRange<'a> {
    /// A number within `[min, max]` (in the unit printed).
    Number {
        /// Lowest value.
        min: f32,
        /// Highest value.
        max: f32,
    },
    /// One of these names (`none, static, gms, gms-adaptive`).
    Names(&'a str),
    /// An estimate: read-only.
    ReadOnly,
}

impl fmt::Display for ListRange<'_> {
    /// As `list` prints it: `[0, 1000]`, `[none, static]`, `[read-only]`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ListRange::Number { min, max } => write!(f, "[{}, {}]", Num(*min), Num(*max)),
            ListRange::Names(n) => write!(f, "[{n}]"),
            ListRange::ReadOnly => f.write_str("[read-only]"),
        }
    }
}

/// A parameter's value as `list` and `get` print it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ListValue<'a> {
    /// A number (in the unit printed).
    Number(f32),
    /// A name (the friction mode's).
    Name(&'a str),
}

impl<'a> ListValue<'a> {
    /// Reads a value: a number where it parses as one, else a name.
    pub fn parse(text: &'a str) -> ListValue<'a> {
        match text.parse() {
            Ok(x) => ListValue::Number(x),
            Err(_) => ListValue::Name(text),
        }
    }

    /// The number, if it is one.
    pub fn number(&self) -> Option<f32> {
        match self {
            ListValue::Number(x) => Some(*x),
            ListValue::Name(_) => None,
        }
    }
}

impl fmt::Display for ListValue<'_> {
    /// As the device writes it (a number's shortest round-trip digits), so it can be sent
    /// back exactly.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ListValue::Number(x) => write!(f, "{}", Num(*x)),
            ListValue::Name(n) => f.write_str(n),
        }
    }
}

/// One line of `list`: `PATH VALUE UNIT [RANGE]`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ListRow<'a> {
    /// The parameter's path (`pos.kp`).
    pub path: &'a str,
    /// Its value.
    pub value: ListValue<'a>,
    /// Its unit (`-` for none).
    pub unit: &'a str,
    /// What it may be set to.
    pub range: ListRange<'a>,
}

impl<'a> ListRow<'a> {
    /// Writes the line and its newline.
    pub fn write(&self, out: &mut dyn Write) -> fmt::Result {
        writeln!(
            out,
            "{} {} {} {}",
            self.path, self.value, self.unit, self.range
        )
    }

    /// Reads one line (without its newline).
    pub fn parse(line: &'a str) -> Result<ListRow<'a>, ReplyError> {
        let bad = |key, bad_value| ReplyError {
            reply: "list",
            key,
            bad_value,
        };
        let (head, range) = line.split_once('[').ok_or(bad("range", false))?;
        let range = range
            .trim_end()
            .strip_suffix(']')
            .ok_or(bad("range", true))?;
        let mut w = head.split_ascii_whitespace();
        let path = w.next().ok_or(bad("path", false))?;
        let value = ListValue::parse(w.next().ok_or(bad("value", false))?);
        let unit = w.next().ok_or(bad("unit", false))?;
        if w.next().is_some() {
            return Err(bad("unit", true));
        }
        let range = if range == "read-only" {
            ListRange::ReadOnly
        } else if let Some((a, b)) = range.split_once(", ")
            && let (Ok(min), Ok(max)) = (a.parse(), b.parse())
        {
            ListRange::Number { min, max }
        } else {
            ListRange::Names(range)
        };
        Ok(ListRow {
            path,
            value,
            unit,
            range,
        })
    }
}

/// Writes one telemetry line, `#` then ` name=value` for each pair, and its newline.
pub fn write_telemetry<'a>(
    out: &mut impl Write,
    pairs: impl Iterator<Item = (&'a str, f32)>,
) -> fmt::Result {
    out.write_char('#')?;
    for (name, v) in pairs {
        write!(out, " {name}={}", Num(v))?;
    }
    out.write_char('\n')
}

/// The `name=value` pairs of a telemetry line (without its leading `#`, as written by
/// [`write_telemetry`]), values read as the
/// f64 of their decimal text; words that are not a pair with a number are skipped.
pub fn telemetry(line: &str) -> impl Iterator<Item = (&str, f64)> + '_ {
    line.split_ascii_whitespace().filter_map(|kv| {
        let (k, v) = kv.split_once('=')?;
        Some((k, v.parse().ok()?))
    })
}
