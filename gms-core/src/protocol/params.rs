//! The parameter table: every settable path with its unit, range and access; reading and setting one, and a whole set validated.

use super::*;
pub use crate::settings::range;
use crate::settings::spec;

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

/// A numeric parameter: its unit and range from [`crate::settings::SPECS`], its field here.
macro_rules! num {
    ($path:literal, |$s:ident| $field:expr) => {
        Param {
            path: $path,
            unit: spec($path).unit,
            access: Access::Number {
                get: |$s: &Settings| $field,
                set: |$s: &mut Settings, v: f32| $field = v,
                min: spec($path).min,
                max: spec($path).max,
                integer: spec($path).integer,
            },
        }
    };
}

/// Every parameter, in `list` order: its path and field (units and ranges are
/// [`crate::settings::SPECS`]'s); the whole set must also pass
/// [`ControllerParams::validate`].
pub const PARAMS: &[Param] = &[
    num!("rate.pos_hz", |s| s.pos_rate_hz),
    num!("rate.cur_hz", |s| s.cur_rate_hz),
    num!("pos.kp", |s| s.pid.kp),
    num!("pos.ki", |s| s.pid.ki),
    num!("pos.kd", |s| s.pid.kd),
    num!("pos.d_filter_hz", |s| s.pid.d_filter_hz),
    num!("pos.i_limit", |s| s.pid.i_limit),
    num!("pos.ki_fric", |s| s.pid.ki_fric),
    num!("filt.notch1.f_hz", |s| s.shaping.notch[0].f_hz),
    num!("filt.notch1.q", |s| s.shaping.notch[0].q),
    num!("filt.notch1.depth_db", |s| s.shaping.notch[0].depth_db),
    num!("filt.notch2.f_hz", |s| s.shaping.notch[1].f_hz),
    num!("filt.notch2.q", |s| s.shaping.notch[1].q),
    num!("filt.notch2.depth_db", |s| s.shaping.notch[1].depth_db),
    num!("filt.lp.f_hz", |s| s.shaping.lp_hz),
    num!("cur.kp", |s| s.current.kp),
    num!("cur.ki", |s| s.current.ki),
    num!("motor.k_m", |s| s.motor.k_m),
    num!("motor.r", |s| s.motor.r),
    num!("motor.k_e", |s| s.motor.k_e),
    num!("lim.i_max", |s| s.i_max),
    num!("lim.v_supply", |s| s.v_supply),
    num!("lim.pos_min", |s| s.pos_min),
    num!("lim.pos_max", |s| s.pos_max),
    num!("enc.dir", |s| s.enc_dir),
    num!("enc.counts_per_rev", |s| s.counts_per_rev),
    num!("sense.dir", |s| s.sense_dir),
    num!("sense.v_per_a", |s| s.sense_v_per_a),
    Param {
        path: "ff.mode",
        unit: "-",
        access: Access::Mode,
    },
    num!("ff.gain", |s| s.ff.gain),
    num!("ff.inertia", |s| s.motor.inertia),
    num!("ff.static_band", |s| s.ff.static_band),
    num!("ff.adapt.gain", |s| s.ff.adapt.gain),
    num!("ff.adapt.min", |s| s.ff.adapt.min),
    num!("ff.adapt.max", |s| s.ff.adapt.max),
    num!("ff.adapt.deadzone", |s| s.ff.adapt.deadzone),
    num!("ff.adapt.vmin", |s| s.ff.adapt.v_min),
    Param {
        path: "ff.adapt.scale",
        unit: "-",
        access: Access::Estimate(Estimate::AdaptScale),
    },
    num!("map.enable", |s| s.map.enable),
    num!("map.period", |s| s.map.period),
    num!("map.bins", |s| s.map.bins),
    num!("map.origin", |s| s.map.origin),
    num!("gms.fs", |s| s.ff.actuator.stribeck.fs),
    num!("gms.fc", |s| s.ff.actuator.stribeck.fc),
    num!("gms.vs", |s| s.ff.actuator.stribeck.vs),
    num!("gms.delta", |s| s.ff.actuator.stribeck.delta),
    num!("gms.sigma", |s| s.ff.actuator.sigma),
    num!("gms.c", |s| s.ff.actuator.c),
    Param {
        path: "gms.blocks",
        unit: spec("gms.blocks").unit,
        access: Access::Number {
            get: |s: &Settings| s.ff.actuator.blocks_used() as f32,
            // The blocks past the count become unused (k = alpha = 0); those kept keep their
            // values (a count that grows needs its new blocks set before the set validates).
            set: |s: &mut Settings, v: f32| {
                s.ff.actuator = s.ff.actuator.with_blocks_used(v as usize);
            },
            min: spec("gms.blocks").min,
            max: spec("gms.blocks").max,
            integer: spec("gms.blocks").integer,
        },
    },
    num!("gms.k1", |s| s.ff.actuator.blocks[0].k),
    num!("gms.k2", |s| s.ff.actuator.blocks[1].k),
    num!("gms.k3", |s| s.ff.actuator.blocks[2].k),
    num!("gms.k4", |s| s.ff.actuator.blocks[3].k),
    num!("gms.k5", |s| s.ff.actuator.blocks[4].k),
    num!("gms.k6", |s| s.ff.actuator.blocks[5].k),
    num!("gms.a1", |s| s.ff.actuator.blocks[0].alpha),
    num!("gms.a2", |s| s.ff.actuator.blocks[1].alpha),
    num!("gms.a3", |s| s.ff.actuator.blocks[2].alpha),
    num!("gms.a4", |s| s.ff.actuator.blocks[3].alpha),
    num!("gms.a5", |s| s.ff.actuator.blocks[4].alpha),
    num!("gms.a6", |s| s.ff.actuator.blocks[5].alpha),
];

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
