//! The parameter table: every parameter's path, unit, range and access (made from the one
//! table of rows, [`crate::for_each_param!`]); reading and setting one, and a whole set
//! validated.

use super::*;
pub use crate::settings::ParamId;

pub use crate::control::controller::Settings;

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
        /// Only whole numbers (a count).
        integer: bool,
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

/// One parameter of a table (this firmware's, [`PARAMS`], or in a test another's): its
/// path, unit and access.
#[derive(Clone, Copy)]
pub struct Param {
    /// The path, e.g. `pos.kp`.
    pub path: &'static str,
    /// The unit, e.g. `N·m/rad` (`-` for none).
    pub unit: &'static str,
    /// How to read and write it.
    pub access: Access,
}

/// [`PARAMS`] from the parameters' rows ([`crate::for_each_param!`]): each row's field read
/// and written by its access.
macro_rules! params {
    ($($id:ident $path:literal $unit:literal [$min:expr, $max:expr] $num:ident $kind:ident
       |$s:ident| $field:expr;)*) => {
        /// Every parameter, in `list` order (indexed by [`ParamId`]): its path and field, its
        /// unit and range from [`crate::settings::SPECS`]; the whole set must also pass
        /// [`crate::control::controller::ControllerParams::validate`].
        pub const PARAMS: &[Param] = &[$(
            Param {
                path: $path,
                unit: $unit,
                access: params!(@access $kind $id |$s| $field),
            },
        )*];
    };
    (@access mode $id:ident |$s:ident| $field:expr) => { Access::Mode };
    (@access estimate $id:ident |$s:ident| $field:expr) => {
        Access::Estimate(Estimate::AdaptScale)
    };
    (@access blocks $id:ident |$s:ident| $field:expr) => {
        Access::Number {
            get: |s: &Settings| s.ff.actuator.blocks_used() as f32,
            // The blocks past the count become unused (k = alpha = 0); those kept keep their
            // values (a count that grows needs its new blocks set before the set validates).
            set: |s: &mut Settings, v: f32| {
                s.ff.actuator = s.ff.actuator.with_blocks_used(v as usize);
            },
            min: ParamId::$id.spec().min,
            max: ParamId::$id.spec().max,
            integer: ParamId::$id.spec().integer,
        }
    };
    (@access $other:ident $id:ident |$s:ident| $field:expr) => {
        Access::Number {
            get: |$s: &Settings| $field,
            set: |$s: &mut Settings, v: f32| $field = v,
            min: ParamId::$id.spec().min,
            max: ParamId::$id.spec().max,
            integer: ParamId::$id.spec().integer,
        }
    };
}

crate::for_each_param!(params);

impl ParamId {
    /// Its entry in [`PARAMS`] (how to read and write it).
    pub fn param(self) -> &'static Param {
        &PARAMS[self as usize]
    }
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
        Access::Number {
            set,
            min,
            max,
            integer,
            ..
        } => {
            let v = parse_f32(value)
                .filter(|v| *v >= min && *v <= max && (!integer || *v == (*v as i32) as f32))
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

/// `stage`: the settings with `path` set to `value`, the value checked against its range but
/// the set not validated as a whole (that waits for `commit`: weights that must sum to 1 are
/// changed one at a time).
pub fn with_value_staged(s: &Settings, path: &str, value: &str) -> Result<Settings, ParseError> {
    let p = find(path).ok_or(ParseError {
        code: ErrorCode::UnknownPath,
        reason: "unknown parameter (try list)",
    })?;
    let mut new = *s;
    set_param(&mut new, p, value)?;
    Ok(new)
}

/// `set`: the settings with `path` set to `value`, validated as a whole; on error nothing is
/// returned and the caller's settings stay as they are.
pub fn with_value(s: &Settings, path: &str, value: &str) -> Result<Settings, ParseError> {
    let new = with_value_staged(s, path, value)?;
    new.validate().map_err(|_| ParseError {
        code: ErrorCode::InvalidSet,
        reason: "the parameter set would be invalid",
    })?;
    Ok(new)
}
