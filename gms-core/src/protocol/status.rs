//! The `status` reply, typed: the device writes it from a [`StatusReply`] and a host reads it
//! back into one ([`StatusReply::parse`]), so the reply's keys and formats live in one place.
//!
//! The reply is one line of `key=value` words (after `ok `), in this order: `mode enabled
//! faults t pos error_counts moving current fault_names ff duty step_us_worst step_us_mean
//! sense_offset missed late duty_max duty_limited supply drive configured`. A reader ignores
//! keys it does not know (a newer device may add some) and refuses a reply that lacks one it
//! needs.

use core::fmt::{self, Write};

use super::Words;
use crate::control::controller::FfMode;
use crate::drive::Faults;
use crate::numtext::Num;

/// What the loop drives while the bridge is on, as `status` names it (`drive=`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum DriveKind {
    /// Position control: holding, or a `move`.
    #[default]
    Position,
    /// A speed profile (`velocity`).
    Velocity,
    /// A held current (`current`), the position loop off.
    Current,
}

impl DriveKind {
    /// Every kind, in the order of the protocol's documentation.
    pub const ALL: [DriveKind; 3] = [DriveKind::Position, DriveKind::Velocity, DriveKind::Current];

    /// The name in `status` (`position`, `velocity`, `current`).
    pub fn name(self) -> &'static str {
        match self {
            DriveKind::Position => "position",
            DriveKind::Velocity => "velocity",
            DriveKind::Current => "current",
        }
    }

    /// The kind called `name`, if any.
    pub fn from_name(name: &str) -> Option<DriveKind> {
        DriveKind::ALL.into_iter().find(|k| k.name() == name)
    }
}

/// The device's state as `status` reports it.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct StatusReply {
    /// The friction feedforward's mode (`ff.mode`).
    pub mode: FfMode,
    /// The bridge is on.
    pub enabled: bool,
    /// The latched faults (`faults=` the bit mask; `fault_names=` their names, written from it).
    pub faults: Faults,
    /// Device time since start \[s\] (written as an f32, read as the f64 of its decimal text).
    pub t: f64,
    /// Position from the power-up position \[rad\] (written as an f32, read as the f64 of its
    /// decimal text).
    pub pos: f64,
    /// Position error \[counts\].
    pub error_counts: f32,
    /// A move is under way.
    pub moving: bool,
    /// Measured motor current \[A\].
    pub current: f32,
    /// Friction feedforward applied \[N·m\].
    pub ff: f32,
    /// PWM duty [-] (-1 … 1).
    pub duty: f32,
    /// Longest control step since start \[µs\].
    pub step_us_worst: f32,
    /// Mean control step \[µs\].
    pub step_us_mean: f32,
    /// The current sense's zero found at start-up \[ADC code\].
    pub sense_offset: f32,
    /// Control periods missed since start [-].
    pub missed: u32,
    /// Control steps that wrote their duty after the PWM update they were for, since start
    /// [-] (each latches `overrun`).
    pub late: u32,
    /// The largest |duty| the board's current sense allows at `rate.cur_hz` [-]: above it a
    /// bridge edge would fall in the sense window (1: no limit, the simulator's sense).
    pub duty_max: f32,
    /// Current steps held at `duty_max` since start [-]: the limit bound (the loop asked for
    /// more voltage than it allows).
    pub duty_limited: u32,
    /// The motor supply the current loop's duty is worked out for \[V\]: measured (the
    /// board's divider, filtered over 0.2 s) where the board has one, else `lim.v_supply`.
    pub supply: f32,
    /// What the loop drives.
    pub drive: DriveKind,
    /// False while the device runs on its built-in defaults (never configured for an axis:
    /// the encoder's resolution and the sense's scale are the paper's rig's).
    pub configured: bool,
}

/// Why a `status` reply could not be read (the reply named `status`).
pub type StatusError = crate::protocol::ReplyError;

impl StatusReply {
    /// Writes the reply (without the leading `ok `) on one line.
    pub fn write(&self, out: &mut dyn Write) -> fmt::Result {
        write!(
            out,
            "mode={} enabled={} faults={} t={} pos={} error_counts={} moving={} current={} \
             fault_names=",
            self.mode.name(),
            self.enabled as u8,
            self.faults.0,
            Num(self.t as f32),
            Num(self.pos as f32),
            Num(self.error_counts),
            self.moving as u8,
            Num(self.current),
        )?;
        self.faults.write_names(out)?;
        write!(
            out,
            " ff={} duty={} step_us_worst={} step_us_mean={} sense_offset={} missed={} late={} \
             duty_max={} duty_limited={} supply={} drive={} configured={}",
            Num(self.ff),
            Num(self.duty),
            Num(self.step_us_worst),
            Num(self.step_us_mean),
            Num(self.sense_offset),
            self.missed,
            self.late,
            Num(self.duty_max),
            self.duty_limited,
            Num(self.supply),
            self.drive.name(),
            self.configured as u8,
        )
    }

    /// Reads a reply (the text after `ok`). Keys it does not know are ignored; `fault_names`
    /// is not read (it follows from `faults`).
    pub fn parse(text: &str) -> Result<StatusReply, StatusError> {
        let w = Words::new(text, "status");
        Ok(StatusReply {
            mode: w.named("mode", FfMode::from_name)?,
            enabled: w.flag("enabled")?,
            faults: Faults(w.number("faults")?),
            t: w.number("t")?,
            pos: w.number("pos")?,
            error_counts: w.number("error_counts")?,
            moving: w.flag("moving")?,
            current: w.number("current")?,
            ff: w.number("ff")?,
            duty: w.number("duty")?,
            step_us_worst: w.number("step_us_worst")?,
            step_us_mean: w.number("step_us_mean")?,
            sense_offset: w.number("sense_offset")?,
            missed: w.number("missed")?,
            late: w.number("late")?,
            duty_max: w.number("duty_max")?,
            duty_limited: w.number("duty_limited")?,
            supply: w.number("supply")?,
            drive: w.named("drive", DriveKind::from_name)?,
            configured: w.flag("configured")?,
        })
    }
}

/// One value of the reply, for a table or a dictionary ([`StatusReply::entries`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum StatusValue {
    /// A number (flags as 0 and 1).
    Number(f64),
    /// A name (`mode`, `drive`).
    Text(&'static str),
    /// The latched faults' names (`fault_names`; written as [`Faults::write_names`]).
    Faults(Faults),
}

impl StatusReply {
    /// The reply's keys and values in the order the device writes them.
    pub fn entries(&self) -> [(&'static str, StatusValue); 21] {
        use StatusValue::{Number as N, Text};
        let b = |x: bool| N(x as u8 as f64);
        [
            ("mode", Text(self.mode.name())),
            ("enabled", b(self.enabled)),
            ("faults", N(self.faults.0 as f64)),
            ("t", N(self.t)),
            ("pos", N(self.pos)),
            ("error_counts", N(self.error_counts as f64)),
            ("moving", b(self.moving)),
            ("current", N(self.current as f64)),
            ("fault_names", StatusValue::Faults(self.faults)),
            ("ff", N(self.ff as f64)),
            ("duty", N(self.duty as f64)),
            ("step_us_worst", N(self.step_us_worst as f64)),
            ("step_us_mean", N(self.step_us_mean as f64)),
            ("sense_offset", N(self.sense_offset as f64)),
            ("missed", N(self.missed as f64)),
            ("late", N(self.late as f64)),
            ("duty_max", N(self.duty_max as f64)),
            ("duty_limited", N(self.duty_limited as f64)),
            ("supply", N(self.supply as f64)),
            ("drive", Text(self.drive.name())),
            ("configured", b(self.configured)),
        ]
    }
}
