//! The position controller of the axis: a PID position loop on the encoder, a PI current
//! loop on the measured motor current, and friction feedforward added to the current command.
//!
//! All f32, fixed size, no allocation. The position loop runs at `pos_rate_hz` (default
//! 10 kHz) and the current loop at `cur_rate_hz` (default 20 kHz, an integer multiple).
//! Torques are motor-side [N·m], angles those of the encoder \[rad\], currents \[A\], volts \[V\].

use crate::control::adaptive::{AdaptInput, Adaptive, AdaptiveParams};
use crate::control::posmap::MapGeometry;
use crate::control::reference::{RefSample, SUB_PER_COUNT, SubCounts, sub_counts};
use crate::control::shaping::{Shaping, ShapingParams};
use crate::friction::error::ParamError;
use crate::friction::gms::{Gms, GmsParams};
use crate::friction::model::FrictionModel;
use crate::friction::static_map::StaticMap;
use crate::math::{self, clamp, i64_to_f32};
use crate::settings::ParamId;

/// The settings a device runs and the protocol edits (the firmware's whole parameter set: a
/// controller of 6 GMS blocks).
pub type Settings = ControllerParams<6>;

/// The least stiffness of a GMS block in use on the device [N·m/rad] (0 marks an unused one).
pub const MIN_BLOCK_K: f32 = 1e-12;

/// The least weight of a GMS block in use on the device [-] (0 marks an unused one).
pub const MIN_BLOCK_ALPHA: f32 = 1e-6;

/// How far below the model the integral's friction level may take the friction it stands
/// for, as a share of the model's sliding level [-]: the level is at least `-FRIC_FLOOR` of
/// it. A plant's friction cannot turn against its motion, and where the model's shape is
/// wrong (a LuGre plant whose friction turns over faster than the model's pre-sliding) the
/// level is taught the model's lag at each reversal: on `hil-sim/tests/truth.rs`'s LuGre
/// plant it went to -1.3 of the level unbounded (the short sine's reversal peak 6.4 -> 16.3
/// counts), 7.3 counts with this floor. Above, it is bounded by `pos.i_limit` only (a gear
/// motor's friction is ten times the model's).
const FRIC_FLOOR: f32 = 0.25;

/// Which friction feedforward the controller adds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(rename_all = "lowercase"))]
pub enum FfMode {
    /// No friction feedforward.
    None,
    /// The static map `s(v) + sigma v` of the reference velocity.
    Static,
    /// The GMS model driven by the reference trajectory's position increments.
    #[default]
    Gms,
    /// The GMS model scaled by an on-line estimate of the friction level
    /// ([`crate::control::adaptive`]).
    #[cfg_attr(feature = "serde", serde(rename = "gms-adaptive"))]
    GmsAdaptive,
}

impl FfMode {
    /// Every mode, in table order.
    pub const ALL: [FfMode; 4] = [
        FfMode::None,
        FfMode::Static,
        FfMode::Gms,
        FfMode::GmsAdaptive,
    ];
    /// The mode's name: `none`, `static`, `gms` or `gms-adaptive`.
    pub fn name(self) -> &'static str {
        match self {
            FfMode::None => "none",
            FfMode::Static => "static",
            FfMode::Gms => "gms",
            FfMode::GmsAdaptive => "gms-adaptive",
        }
    }

    /// The mode with this name, if any.
    pub fn from_name(name: &str) -> Option<FfMode> {
        FfMode::ALL.into_iter().find(|m| m.name() == name)
    }
}

/// Position-loop PID gains (on the position error in rad, output torque in N·m).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct PidParams {
    /// Proportional gain [N·m/rad], `>= 0`.
    pub kp: f32,
    /// Integral gain [N·m/(rad·s)], `>= 0`.
    pub ki: f32,
    /// Derivative gain [N·m·s/rad], `>= 0`: on the velocity error (reference velocity minus
    /// the encoder's), filtered.
    pub kd: f32,
    /// Corner of the derivative's first-order filter \[Hz\], `> 0`.
    pub d_filter_hz: f32,
    /// Limit of the integral term's torque [N·m], `>= 0` (anti-windup).
    pub i_limit: f32,
    /// The share of the integral carried as a level of the friction model [-], in [0, 1]
    /// (modes `gms` and `gms-adaptive`): of what the integral takes in, the share
    /// `ki_fric · φ²` follows the model's sign and level (φ its output over its Coulomb level,
    /// within ±1: it turns over with the model at a reversal, where a plain integral holds
    /// the last direction's friction mismatch and must unwind it); the rest stays a constant
    /// torque (a load, gravity). The integral's action on the error is `ki` whatever the
    /// share, so the loop's margins do not change with it. 0: a plain integral. Optional
    /// in a settings file: [`DEFAULT_KI_FRIC`] when left out.
    #[cfg_attr(feature = "serde", serde(default = "default_ki_fric"))]
    pub ki_fric: f32,
}

/// The device's share of the integral carried as a friction level (`pos.ki_fric`) [-]: on the
/// demo's 20 drawn plants the GMS reversal peak 7.33 -> 5.38 counts, sine RMS 0.458 -> 0.444,
/// margins unchanged (docs/results.md, the trade table).
pub const DEFAULT_KI_FRIC: f32 = 0.5;

#[cfg(feature = "serde")]
fn default_ki_fric() -> f32 {
    DEFAULT_KI_FRIC
}

/// Current-loop PI gains (on the current error in A, output voltage in V).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct CurrentParams {
    /// Proportional gain [V/A], `>= 0`.
    pub kp: f32,
    /// Integral gain [V/(A·s)], `>= 0`.
    pub ki: f32,
}

/// The motor as the controller knows it (for feedforward and scaling).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct MotorModel {
    /// Torque constant k_M [N·m/A] (6.6e-3 in the paper), `> 0`.
    pub k_m: f32,
    /// Winding resistance \[ohm\], `>= 0` (voltage feedforward R i).
    pub r: f32,
    /// Back-EMF constant [V·s/rad], `>= 0` (voltage feedforward k_E omega_ref).
    pub k_e: f32,
    /// Rotor-side inertia estimate [kg·m^2], `>= 0` (acceleration feedforward J a_ref).
    pub inertia: f32,
}

/// Friction feedforward: mode, gain, and the nominal friction of both sources.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FeedforwardParams<const N: usize> {
    /// Which model feeds forward.
    pub mode: FfMode,
    /// Scale on the friction feedforward [-], in [0, 2].
    pub gain: f32,
    /// Nominal actuator friction (motor side, N·m and rad).
    pub actuator: GmsParams<N>,
    /// Nominal guideway friction (N and m), reflected through `ratio`; `None` to leave it out.
    pub guideway: Option<GmsParams<N>>,
    /// Slide travel per motor radian [m/rad] (lead / (2 pi gear ratio)), `> 0`.
    pub ratio: f32,
    /// Velocity band of the static map [rad/s], `>= 0`: below it the map's output is scaled
    /// by |v| / band, so that it does not jump by 2 Fs at a reversal (0: no band).
    pub static_band: f32,
    /// Adaptation of the GMS feedforward's level (mode `gms-adaptive`).
    pub adapt: AdaptiveParams,
}

/// Everything the controller needs.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ControllerParams<const N: usize> {
    /// Position-loop rate \[Hz\], `> 0`.
    pub pos_rate_hz: f32,
    /// Current-loop rate \[Hz\], an integer multiple (1 to 16) of `pos_rate_hz`.
    pub cur_rate_hz: f32,
    /// Encoder resolution \[counts/rev\]: counts per motor revolution after quadrature (4 × the
    /// lines of an incremental encoder), `> 0`; the radians per count derive from it
    /// ([`ControllerParams::rad_per_count`]). Not necessarily whole: the paper's encoder is given
    /// as 3.8 µrad per count, 1653469.8 counts/rev.
    pub counts_per_rev: f32,
    /// Current-sense transimpedance \[V/A\]: volts at the ADC per ampere of motor current (the
    /// shunt's resistance times the amplifier's gain), `> 0`; the amps per ADC code derive from
    /// it and the board's ADC (the device's sense chain: `SenseChain::amps_per_code`).
    pub sense_v_per_a: f32,
    /// Position PID.
    pub pid: PidParams,
    /// Loop-shaping filters on the current command (notches and a low-pass; all off by
    /// default).
    pub shaping: ShapingParams,
    /// Current PI.
    pub current: CurrentParams,
    /// Motor model.
    pub motor: MotorModel,
    /// Current command limit \[A\], `> 0`.
    pub i_max: f32,
    /// Supply voltage \[V\], `> 0` (duty = voltage / supply).
    pub v_supply: f32,
    /// The bridge's dead time \[s\], in [0, 5e-6]: each PWM edge of the switching half-bridge
    /// leaves both switches off this long, when the current flows on through a body diode,
    /// so that a period's mean voltage falls short of the duty's by `sign(i) dead_time / T ×
    /// supply`. The current step adds it back to the duty, keyed on the commanded current's
    /// sign (see [`DEAD_TIME_BAND`]). 0: none (the ideal bridge).
    pub dead_time: f32,
    /// Soft stroke limit, low side \[rad\] from the power-up position: the axis below it latches
    /// `position_limit`; a `move` below it is refused. `< pos_max`.
    pub pos_min: f32,
    /// Soft stroke limit, high side \[rad\] from the power-up position (see `pos_min`).
    pub pos_max: f32,
    /// Encoder direction \[-\], 1 or -1: -1 counts the other way (an encoder wired against the
    /// motor, fixed by a parameter instead of a rewiring).
    pub enc_dir: f32,
    /// Current-sense polarity \[-\], 1 or -1: -1 reads the other way (a sense amplifier or
    /// shunt wired the other way round).
    pub sense_dir: f32,
    /// Friction feedforward.
    pub ff: FeedforwardParams<N>,
    /// The position map's settings (its table is the control loop's, [`crate::control::posmap`]).
    pub map: crate::control::posmap::MapParams,
}

/// Why a controller parameter set was rejected.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ControllerError {
    /// A parameter is non-finite or out of its range; names it.
    Invalid(&'static str),
    /// The actuator friction model is invalid.
    Actuator(ParamError),
    /// The guideway friction model is invalid.
    Guideway(ParamError),
}

impl core::fmt::Display for ControllerError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            ControllerError::Invalid(name) => write!(f, "{name} is out of range"),
            ControllerError::Actuator(e) => write!(f, "ff.actuator: {e}"),
            ControllerError::Guideway(e) => write!(f, "ff.guideway: {e}"),
        }
    }
}

impl<const N: usize> ControllerParams<N> {
    /// The encoder's resolution \[rad/count\]: 2π / `counts_per_rev`, divided in double
    /// precision (a default of 3.8e-6 round-trips through its counts per revolution exactly).
    pub fn rad_per_count(&self) -> f32 {
        (core::f64::consts::TAU / self.counts_per_rev as f64) as f32
    }

    /// The position loop's period \[s\] (the one value the controller and the protocol side
    /// both use: a speed profile is prepared for it outside the control interrupt).
    pub fn dt_pos(&self) -> f32 {
        1.0 / self.pos_rate_hz
    }

    /// The number of current-loop steps per position-loop step.
    pub fn ratio(&self) -> u32 {
        let r = self.cur_rate_hz / self.pos_rate_hz;
        (r + 0.5) as u32
    }

    /// Checks every parameter; the error names the first offending one by its protocol path
    /// (`pos.kp`, `gms.fs`, …). The ranges are the settings table ([`crate::settings::SPECS`]),
    /// the one range table of the project: a set runs here exactly when the protocol accepts it.
    pub fn validate(&self) -> Result<(), ControllerError> {
        let a = &self.ff.actuator;
        let f = &self.shaping;
        let m = &self.map;
        // The `checked` rows of the parameters' table: each one's path, value and range.
        let this = self;
        macro_rules! checked {
            ($($id:ident $path:literal $unit:literal [$min:expr, $max:expr] $num:ident
               $kind:ident |$s:ident| $field:expr;)*) => {
                [$(checked!(@row $kind $path [$min, $max] |$s| $field)),*]
            };
            (@row checked $path:literal [$min:expr, $max:expr] |$s:ident| $field:expr) => {
                Some(($path, { let $s = this; $field }, ($min, $max)))
            };
            (@row $other:ident $path:literal [$min:expr, $max:expr] |$s:ident| $field:expr) => {
                None
            };
        }
        /// A checked parameter: its path, its value and its range.
        type Row = (&'static str, f32, (f32, f32));
        let scalars: [Option<Row>; crate::settings::SPECS.len()] = crate::for_each_param!(checked);
        for (name, v, (lo, hi)) in scalars.into_iter().flatten() {
            if !(v.is_finite() && v >= lo && v <= hi) {
                return Err(ControllerError::Invalid(name));
            }
        }
        if self.pos_min >= self.pos_max {
            return Err(ControllerError::Invalid("lim.pos_min"));
        }
        // The filters run at the position rate: a frequency must lie below 0.45 of it.
        let nyquist = 0.45 * self.pos_rate_hz;
        for (name, hz) in [
            ("filt.notch1.f_hz", f.notch[0].f_hz),
            ("filt.notch2.f_hz", f.notch[1].f_hz),
            ("filt.lp.f_hz", f.lp_hz),
        ] {
            if hz != 0.0 && hz >= nyquist {
                return Err(ControllerError::Invalid(name));
            }
        }
        if m.enable != 0.0 && m.enable != 1.0 {
            return Err(ControllerError::Invalid("map.enable"));
        }
        if m.bins != (m.bins as u32) as f32 {
            return Err(ControllerError::Invalid("map.bins"));
        }
        // A bin at least a count wide.
        if m.period / m.bins < self.rad_per_count() {
            return Err(ControllerError::Invalid("map.period"));
        }
        if self.enc_dir != 1.0 && self.enc_dir != -1.0 {
            return Err(ControllerError::Invalid("enc.dir"));
        }
        if self.sense_dir != 1.0 && self.sense_dir != -1.0 {
            return Err(ControllerError::Invalid("sense.dir"));
        }
        // The protocol's ranges admit 0 (an unused block); a block in use needs at least
        // these (the model's structure, used blocks first, is checked by its own validate).
        const K: (f32, f32) = (MIN_BLOCK_K, ParamId::GmsK1.range().1);
        const ALPHA: (f32, f32) = (MIN_BLOCK_ALPHA, ParamId::GmsA1.range().1);
        for b in a.blocks.iter().take(a.blocks_used()) {
            if !(b.k.is_finite() && b.k >= K.0 && b.k <= K.1) {
                return Err(ControllerError::Invalid("gms.k"));
            }
            if !(b.alpha.is_finite() && b.alpha >= ALPHA.0 && b.alpha <= ALPHA.1) {
                return Err(ControllerError::Invalid("gms.a"));
            }
        }
        if !(self.ff.ratio.is_finite() && self.ff.ratio > 0.0) {
            return Err(ControllerError::Invalid("ff.ratio"));
        }
        if !(self.ff.static_band.is_finite() && self.ff.static_band >= 0.0) {
            return Err(ControllerError::Invalid("ff.static_band"));
        }
        self.ff.adapt.validate().map_err(ControllerError::Invalid)?;
        let r = self.cur_rate_hz / self.pos_rate_hz;
        let n = self.ratio();
        if !(1..=16).contains(&n) || (r - n as f32) > 1e-3 * r || (n as f32 - r) > 1e-3 * r {
            return Err(ControllerError::Invalid("rate.cur_hz"));
        }
        self.ff
            .actuator
            .validate()
            .map_err(ControllerError::Actuator)?;
        if let Some(g) = &self.ff.guideway {
            g.validate().map_err(ControllerError::Guideway)?;
        }
        Ok(())
    }
}

/// What one position-loop step computed (per term, for telemetry and tuning).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PositionOutput {
    /// Position error, reference minus measurement \[rad\].
    pub error: f32,
    /// Proportional torque [N·m].
    pub p: f32,
    /// Integral torque [N·m].
    pub i: f32,
    /// Derivative torque [N·m].
    pub d: f32,
    /// Friction feedforward torque, after the gain and the adaptive scale [N·m].
    pub ff_friction: f32,
    /// The adaptive scale applied to the friction feedforward [-] (1 unless `gms-adaptive`).
    pub ff_scale: f32,
    /// Inertia feedforward torque [N·m].
    pub ff_inertia: f32,
    /// Current command after limiting \[A\].
    pub i_cmd: f32,
    /// True when the current command hit `i_max`.
    pub saturated: bool,
}

/// What one current-loop step computed.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct CurrentOutput {
    /// Voltage command after limiting \[V\].
    pub voltage: f32,
    /// PWM duty in [-1, 1] (sign = direction).
    pub duty: f32,
    /// The voltage was held at the board's duty limit ([`Controller::set_duty_max`]), below
    /// the supply: the sense window's limit binds.
    pub limited: bool,
}

/// The friction feedforward's first half, worked out a step ahead: the actuator model's
/// output [N·m] for the reference's increment `dx` \[rad\] at velocity `vel` [rad/s].
#[derive(Debug, Clone, Copy)]
struct FfAhead {
    act: f32,
    dx: f32,
    vel: f32,
}

/// The controller and its state.
#[derive(Debug, Clone)]
pub struct Controller<const N: usize> {
    p: ControllerParams<N>,
    /// The encoder's resolution \[rad/count\] ([`ControllerParams::rad_per_count`], divided
    /// once here, not in every step).
    rpc: f32,
    /// The position map's geometry for these settings (worked out where the controller is
    /// built, outside the control interrupt).
    map_geometry: MapGeometry,
    dt_pos: f32,
    dt_cur: f32,
    d_alpha: f32,
    /// The integral's constant part [N·m].
    integ: f32,
    /// The integral's friction-level part [N·m at the sliding friction level]: the integral
    /// torque is `integ + integ_fric · φ`, φ the friction model's output over its sliding
    /// (Coulomb) level, within ±1 (`pos.ki_fric`).
    integ_fric: f32,
    /// 1 / the model's sliding (Coulomb) level [1/(N·m)] (0 without a model).
    inv_f_norm: f32,
    /// The lowest friction level the integral holds, as a magnitude [N·m] (`FRIC_FLOOR` of
    /// the sliding level).
    fric_floor: f32,
    d_filt: f32,
    last_meas: Option<i64>,
    last_ref: Option<SubCounts>,
    /// The first half of the friction feedforward for the next position step's reference,
    /// worked out ahead ([`Controller::feedforward_ahead`]).
    ff_ahead: Option<FfAhead>,
    gms_act: Gms<N>,
    gms_guide: Option<Gms<N>>,
    map_act: StaticMap,
    map_guide: Option<StaticMap>,
    i_cmd: f32,
    w_ref: f32,
    a_ref: f32,
    cur_integ: f32,
    e_cur: f32,
    /// The largest |duty| the board's sense allows [-] (1: the supply's).
    duty_max: f32,
    /// The supply the current loop divides by \[V\]: the board's measured one
    /// ([`Controller::set_measured_supply`]), else `lim.v_supply`.
    v_eff: f32,
    /// `v_eff` is the board's measurement (kept across a hand-over), not `lim.v_supply`.
    measured: bool,
    /// 1 / `v_eff` \[1/V\], kept with it: the duty a multiplication, not a division, in each
    /// current step.
    inv_supply: f32,
    adapt: Adaptive,
    shaping: Shaping,
    /// The position map's sample at the reference: torque offset \[N·m\], friction scale [-]
    /// (0 and 1 without a map), set by the control loop before each position step.
    map_sample: (f32, f32),
    out: PositionOutput,
}

impl<const N: usize> Controller<N> {
    /// Validates `p` into a controller at rest.
    pub fn try_new(p: ControllerParams<N>) -> Result<Self, ControllerError> {
        p.validate()?;
        let dt_pos = p.dt_pos();
        let gms_act = Gms::try_new(p.ff.actuator).map_err(ControllerError::Actuator)?;
        let map_act =
            StaticMap::try_new(p.ff.actuator.static_params()).map_err(ControllerError::Actuator)?;
        let (gms_guide, map_guide) = match &p.ff.guideway {
            Some(g) => (
                Some(Gms::try_new(*g).map_err(ControllerError::Guideway)?),
                Some(StaticMap::try_new(g.static_params()).map_err(ControllerError::Guideway)?),
            ),
            None => (None, None),
        };
        // The nominal friction level the adaptation normalises by: both sources' Fs.
        let f_norm = p.ff.actuator.stribeck.fs
            + p.ff
                .guideway
                .as_ref()
                .map_or(0.0, |g| p.ff.ratio * g.stribeck.fs);
        // The sliding level the integral's friction share is weighted by: both sources' Fc
        // (the model's output sliding above the Stribeck velocity).
        let f_slide = p.ff.actuator.stribeck.fc
            + p.ff
                .guideway
                .as_ref()
                .map_or(0.0, |g| p.ff.ratio * g.stribeck.fc);
        let inv_f_norm = if f_slide.is_finite() && f_slide > 0.0 {
            1.0 / f_slide
        } else {
            0.0
        };
        let mut adapt = Adaptive::new(f_norm);
        adapt.reset(&p.ff.adapt);
        let shaping = Shaping::try_new(&p.shaping, p.pos_rate_hz)
            .map_err(|_| ControllerError::Invalid("filt"))?;
        Ok(Controller {
            adapt,
            shaping,
            map_sample: (0.0, 1.0),
            rpc: p.rad_per_count(),
            map_geometry: MapGeometry::new(&p.map, p.rad_per_count()),
            dt_pos,
            dt_cur: 1.0 / (p.ratio() as f32 * p.pos_rate_hz),
            d_alpha: 1.0 - math::exp(-2.0 * core::f32::consts::PI * p.pid.d_filter_hz * dt_pos),
            p,
            integ: 0.0,
            integ_fric: 0.0,
            inv_f_norm,
            fric_floor: FRIC_FLOOR * f_slide.max(0.0),
            d_filt: 0.0,
            last_meas: None,
            last_ref: None,
            ff_ahead: None,
            gms_act,
            gms_guide,
            map_act,
            map_guide,
            i_cmd: 0.0,
            w_ref: 0.0,
            a_ref: 0.0,
            cur_integ: 0.0,
            e_cur: 0.0,
            duty_max: 1.0,
            v_eff: p.v_supply,
            measured: false,
            inv_supply: 1.0 / p.v_supply,
            out: PositionOutput::default(),
        })
    }

    /// The parameters.
    pub fn params(&self) -> &ControllerParams<N> {
        &self.p
    }

    /// Position-loop period \[s\].
    pub fn dt_pos(&self) -> f32 {
        self.dt_pos
    }

    /// Current-loop period \[s\].
    pub fn dt_cur(&self) -> f32 {
        self.dt_cur
    }

    /// Limits the duty to ±`duty_max` [-] (within 0 … 1; the default 1 is the supply's): the
    /// board's sense window must see no bridge edge ([`crate::device::SenseChain::duty_max`]).
    /// The current loop's voltage is held within `duty_max` × the supply, its integrator
    /// with it, and the dead-time compensation within the same bound.
    pub fn set_duty_max(&mut self, duty_max: f32) {
        self.duty_max = if duty_max.is_finite() {
            duty_max.clamp(0.0, 1.0)
        } else {
            1.0
        };
    }

    /// The motor supply as the board measures it \[V\] (none: `lim.v_supply` as set): the
    /// current loop's duty is its voltage over this, so that its gain follows the supply (a
    /// 24 V supply under a 12 V setting doubled the loop's gain, +6 dB against the 4 dB of
    /// margin it has). Values that are not finite or under 0.1 V are taken as none.
    pub fn set_measured_supply(&mut self, v: Option<f32>) {
        let v = v.filter(|v| v.is_finite() && *v >= 0.1);
        self.measured = v.is_some();
        self.v_eff = v.unwrap_or(self.p.v_supply);
        self.inv_supply = 1.0 / self.v_eff;
    }

    /// The supply the current loop divides by \[V\]: the measured one, else `lim.v_supply`.
    #[inline]
    pub fn supply(&self) -> f32 {
        self.v_eff
    }

    /// The duty limit [-] ([`Controller::set_duty_max`]).
    pub fn duty_max(&self) -> f32 {
        self.duty_max
    }

    /// The adaptive scale on the friction feedforward [-] (mode `gms-adaptive`).
    pub fn adaptive_scale(&self) -> f32 {
        self.adapt.scale()
    }

    /// Carries a learned scale over (e.g. into a controller rebuilt with new settings),
    /// clamped into the adaptation's bounds; a non-finite value resets it to 1.
    pub fn set_adaptive_scale(&mut self, scale: f32) {
        self.adapt.set_scale(scale, &self.p.ff.adapt);
    }

    /// The last position-loop output.
    pub fn last_output(&self) -> &PositionOutput {
        &self.out
    }

    /// Sets the feedforward mode and gain (gain clamped to [0, 2]); the friction models keep
    /// their state. The integral's friction-level part is folded into its constant part (the same torque
    /// now: the level was learned on the model of the old mode).
    pub fn set_feedforward(&mut self, mode: FfMode, gain: f32) {
        if mode != self.p.ff.mode {
            self.integ = clamp(
                self.integ + self.integ_fric * self.phi(),
                self.p.pid.i_limit,
            );
            self.integ_fric = 0.0;
        }
        self.p.ff.mode = mode;
        self.p.ff.gain = if gain.is_finite() {
            gain.clamp(0.0, 2.0)
        } else {
            0.0
        };
    }

    /// Current mode: the current loop holds `amps` \[A\] (clamped to `i_max`) with the
    /// position loop off (no speed feedforward: the reference speed is taken as 0).
    pub fn hold_current(&mut self, amps: f32) {
        self.i_cmd = clamp(amps, self.p.i_max);
        self.w_ref = 0.0;
    }

    /// Back to rest: integrators, filters, friction models and outputs cleared.
    pub fn reset(&mut self) {
        self.integ = 0.0;
        self.integ_fric = 0.0;
        self.d_filt = 0.0;
        self.last_meas = None;
        self.last_ref = None;
        self.ff_ahead = None;
        self.gms_act.reset();
        if let Some(g) = &mut self.gms_guide {
            g.reset();
        }
        self.i_cmd = 0.0;
        self.w_ref = 0.0;
        self.a_ref = 0.0;
        self.cur_integ = 0.0;
        self.e_cur = 0.0;
        self.shaping.reset();
        self.out = PositionOutput::default();
    }

    /// The encoder's resolution \[rad/count\] this controller runs with (divided once, when it
    /// was built: cheap in a control step, unlike [`ControllerParams::rad_per_count`]).
    pub fn rad_per_count(&self) -> f32 {
        self.rpc
    }

    /// The position map's geometry for this controller's settings (worked out when it was
    /// built).
    pub fn map_geometry(&self) -> &MapGeometry {
        &self.map_geometry
    }

    /// True when `p` runs at other loop rates than this controller (a change that cannot be
    /// made while the bridge drives: the timer and the step ratio change).
    pub fn rates_differ(&self, p: &ControllerParams<N>) -> bool {
        p.pos_rate_hz != self.p.pos_rate_hz
            || p.cur_rate_hz != self.p.cur_rate_hz
            || p.counts_per_rev != self.p.counts_per_rev
    }

    /// Live tuning: this controller (new, built by [`Controller::try_new`] from the new set,
    /// at rest) takes the running state of `old`, without a bump. Cheap (no validation, no
    /// transcendental function): fit for a control step, so that the set is validated and
    /// built outside the loop.
    ///
    /// At the same rates every state is kept: the integrators, the derivative filter, the
    /// friction models' block forces (each clamped into its new limit, see
    /// [`Gms::take_state_from`]), the adaptive scale (clamped into its new bounds), the last
    /// reference. The position loop's integrator is handed over so that its total torque at
    /// the last step's inputs (error, filtered velocity error, friction model, reference
    /// acceleration) stays the same, scaled by `k_M new / k_M old` so that the current command
    /// stays the same; the current loop's integrator likewise keeps its voltage at the last
    /// current error. Both stay within their new limits (`pos.i_limit`, `lim.v_supply`), so a
    /// change that needs more than those limits allow is bumpless only up to them. After a
    /// change of the loop rates or of the encoder resolution ([`Controller::rates_differ`])
    /// it stays at rest and keeps only the adaptive scale.
    pub fn take_state_from(&mut self, old: &Controller<N>) {
        let scale = old.adapt.scale();
        let ad = self.p.ff.adapt;
        self.adapt.set_scale(scale, &ad);
        if old.rates_differ(&self.p) {
            return;
        }
        // The models with the old state.
        self.gms_act.take_state_from(&old.gms_act);
        if let (Some(new), Some(prev)) = (&mut self.gms_guide, &old.gms_guide) {
            new.take_state_from(prev);
        }
        self.last_meas = old.last_meas;
        self.last_ref = old.last_ref;
        self.ff_ahead = None;
        self.d_filt = old.d_filt;
        self.i_cmd = old.i_cmd;
        self.w_ref = old.w_ref;
        self.a_ref = old.a_ref;
        self.e_cur = old.e_cur;
        // A supply the board measured stays (the new set's `lim.v_supply` is the nominal),
        // even one that happens to equal the old set's nominal.
        // (Copied, not re-validated: the hand-over runs in a control step, where a division
        // and the filter cost cycles the step does not have.)
        if old.measured {
            self.measured = true;
            self.v_eff = old.v_eff;
            self.inv_supply = old.inv_supply;
        }
        self.shaping.take_state_from(&old.shaping);
        // The map's sample is this controller's own (the loop sets it, for the new settings,
        // before the hand-over): a map switched on or off changes the feedforward, and the
        // integrator takes the difference over below.

        // Position loop: the same torque (times k_M new / k_M old) at the last inputs. (The
        // parameters by reference: a copy is 348 B through memmove in the control interrupt.)
        let p = &self.p;
        let o = old.out;
        let km = p.motor.k_m / old.p.motor.k_m;
        let before = (o.p + o.i + o.d + o.ff_friction + o.ff_inertia) * km;
        let adaptive = p.ff.mode == FfMode::GmsAdaptive;
        let ff_scale = if adaptive { self.adapt.scale() } else { 1.0 };
        let p_term = p.pid.kp * o.error;
        let d_term = p.pid.kd * self.d_filt;
        let (map_offset, map_scale) = self.map_sample;
        let ff_fric = p.ff.gain * ff_scale * self.friction_now() * map_scale + map_offset;
        let ff_inertia = p.motor.inertia * self.a_ref;
        let integ = before - (p_term + d_term + ff_fric + ff_inertia);
        let total = clamp(if integ.is_finite() { integ } else { 0.0 }, p.pid.i_limit);
        // The friction-level part kept (none where the new set carries none), the constant
        // part the rest of the same total.
        let fric = if p.pid.ki_fric > 0.0 {
            old.integ_fric
        } else {
            0.0
        };
        self.integ_fric = clamp(if fric.is_finite() { fric } else { 0.0 }, p.pid.i_limit);
        self.integ = clamp(total - self.integ_fric * self.phi(), p.pid.i_limit);
        self.out = PositionOutput {
            error: o.error,
            p: p_term,
            i: total,
            d: d_term,
            ff_friction: ff_fric,
            ff_scale,
            ff_inertia,
            i_cmd: o.i_cmd,
            saturated: o.saturated,
        };

        // Current loop: the same voltage for the last command and speed (a new R or k_e
        // changes the feedforward for as long as they last: the integrator takes the
        // difference). Not for the last current error: that is the sense's noise and the
        // last position step's change of command, gone a period later, and a new kp's
        // difference at it, taken into the integrator, stayed there as an offset until the
        // integral unwound it (`set cur.kp` live bumped the axis by 0.8 counts).
        let c0 = &old.p;
        let ff_old = c0.motor.r * old.i_cmd + c0.motor.k_e * old.w_ref;
        let ff_new = p.motor.r * old.i_cmd + p.motor.k_e * old.w_ref;
        let cur = old.cur_integ + ff_old - ff_new;
        self.cur_integ = clamp(if cur.is_finite() { cur } else { 0.0 }, p.v_supply);
    }

    /// The friction model's output now over its sliding level, within ±1 [-]: the weight of
    /// the integral's friction-level part.
    fn phi(&self) -> f32 {
        self.phi_of(self.friction_now())
    }

    /// φ for the friction model's output `f` [N·m]: 0 unless the mode is a GMS one (the
    /// static map turns over within a velocity band, not where the friction does).
    fn phi_of(&self, f: f32) -> f32 {
        match self.p.ff.mode {
            FfMode::Gms | FfMode::GmsAdaptive => clamp(f * self.inv_f_norm, 1.0),
            FfMode::None | FfMode::Static => 0.0,
        }
    }

    /// The friction feedforward model's output now (before the gain and scale) for the mode
    /// set, without advancing it [N·m].
    fn friction_now(&self) -> f32 {
        let ratio = self.p.ff.ratio;
        match self.p.ff.mode {
            FfMode::None => 0.0,
            FfMode::Gms | FfMode::GmsAdaptive => {
                self.gms_act.force() + self.gms_guide.as_ref().map_or(0.0, |g| ratio * g.force())
            }
            FfMode::Static => self.static_ff(self.w_ref),
        }
    }

    /// The static map's feedforward at the reference velocity `vel` [rad/s] [N·m], ramped to
    /// zero inside the velocity band.
    fn static_ff(&self, vel: f32) -> f32 {
        let ratio = self.p.ff.ratio;
        let band = self.p.ff.static_band;
        let speed = if vel < 0.0 { -vel } else { vel };
        let scale = if speed < band { speed / band } else { 1.0 };
        let guide = self.map_guide.as_ref();
        scale
            * (self.map_act.force_at(vel) + guide.map_or(0.0, |m| ratio * m.force_at(ratio * vel)))
    }

    /// The friction feedforward's first half: the actuator's model advanced by `dx` \[rad\]
    /// (the reference's increment over one position period, at velocity `vel` [rad/s]). Every
    /// model is advanced whatever the mode, so that switching modes finds them in the right
    /// state.
    #[inline(always)]
    fn friction_ff_first(&mut self, dx: f32, vel: f32) -> FfAhead {
        FfAhead {
            act: self.gms_act.advance(dx, self.dt_pos),
            dx,
            vel,
        }
    }

    /// The friction feedforward's second half: the guideway's model advanced by the same
    /// increment, and the mode's torque [N·m] (before the gain).
    #[inline(always)]
    fn friction_ff_second(&mut self, half: FfAhead) -> f32 {
        let FfAhead { act, dx, vel } = half;
        let dt = self.dt_pos;
        let ratio = self.p.ff.ratio;
        let gms = act
            + self
                .gms_guide
                .as_mut()
                .map_or(0.0, |g| ratio * g.advance(ratio * dx, dt));
        match self.p.ff.mode {
            FfMode::None => 0.0,
            FfMode::Gms | FfMode::GmsAdaptive => gms,
            FfMode::Static => self.static_ff(vel),
        }
    }

    /// The friction feedforward for the next position step's reference `r`, its first half
    /// worked out now: the actuator's friction model advanced by the reference's increment
    /// (it depends on the reference alone, not on the measurement). The control loop calls it
    /// in the current step before the position step's when the current loop runs faster, so
    /// that the two steps share the work; [`Controller::position_step`] with the same `r` then
    /// advances the guideway's model and sums them, in the same order as when it works it
    /// all out itself (bit for bit the same feedforward), which it does when this was not
    /// called.
    pub fn feedforward_ahead(&mut self, r: &RefSample) {
        let dx = self.ref_increment(r);
        let half = self.friction_ff_first(dx, r.vel);
        self.ff_ahead = Some(half);
    }

    /// Forgets the feedforward worked out ahead (its position step does not run).
    pub fn forget_ahead(&mut self) {
        self.ff_ahead = None;
    }

    /// The friction models advanced to the reference `r` from the last one; the feedforward
    /// torque \[N·m\] (before the gain).
    fn friction_ff_at(&mut self, r: &RefSample) -> f32 {
        let dx_ref = self.ref_increment(r);
        let half = self.friction_ff_first(dx_ref, r.vel);
        self.friction_ff_second(half)
    }

    /// The reference's increment to `r` from the last one \[rad\] (exact in fixed point; 0 at
    /// the first), `r` kept as the last.
    fn ref_increment(&mut self, r: &RefSample) -> f32 {
        let dx_ref = match self.last_ref {
            Some(prev) => i64_to_f32(r.pos.saturating_sub(prev)) * (self.rpc / SUB_PER_COUNT),
            None => 0.0,
        };
        self.last_ref = Some(r.pos);
        dx_ref
    }

    /// One position-loop step: measured encoder count `meas` and the reference sample `r`.
    /// Returns the per-term breakdown; the current command is kept for the current loop.
    pub fn position_step(&mut self, meas: i64, r: &RefSample) -> PositionOutput {
        let rpc = self.rpc;
        let meas_sub = sub_counts(meas);
        let error = i64_to_f32(r.pos.saturating_sub(meas_sub)) * (rpc / SUB_PER_COUNT);
        let ff_model = match self.ff_ahead.take() {
            Some(half) => self.friction_ff_second(half),
            None => self.friction_ff_at(r),
        };
        // Derivative on the measurement, first-order filtered.
        let vel_meas = match self.last_meas {
            Some(prev) => i64_to_f32(meas.saturating_sub(prev)) * rpc / self.dt_pos,
            None => 0.0,
        };
        self.last_meas = Some(meas);
        // Derivative of the error: reference velocity minus measured velocity, filtered.
        self.d_filt += self.d_alpha * ((r.vel - vel_meas) - self.d_filt);

        let pid = self.p.pid;
        let p_term = pid.kp * error;
        let d_term = pid.kd * self.d_filt;
        let adaptive = self.p.ff.mode == FfMode::GmsAdaptive;
        let ff_scale = if adaptive { self.adapt.scale() } else { 1.0 };
        let (map_offset, map_scale) = self.map_sample;
        let ff_fric = self.p.ff.gain * ff_scale * ff_model * map_scale;
        let ff_inertia = self.p.motor.inertia * r.acc;
        // The integral: `integ + integ_fric · φ`, φ the friction model's output over its
        // sliding (Coulomb) level, within ±1. Of what it takes in, the share `ki_fric · φ²`
        // goes to the friction level (times φ, so that it adds `ki_fric · φ² · δ` to the
        // torque now) and the rest to the constant: the torque grows by `ki · error · dt`
        // whatever φ, and a reversal of the model turns the level's torque over with it.
        // The level is bounded below (`FRIC_FLOOR`); what the bound holds back goes to the
        // constant, so that the torque still grows by `ki · error · dt`.
        // Conditional integration: both stop when the command is saturated in the direction
        // the error would push it further.
        let phi = self.phi_of(ff_model);
        let delta = pid.ki * error * self.dt_pos;
        let share = pid.ki_fric * phi;
        let fric_new = math::min(
            math::max(self.integ_fric + share * delta, -self.fric_floor),
            pid.i_limit,
        );
        let const_new = clamp(
            self.integ + delta - (fric_new - self.integ_fric) * phi,
            pid.i_limit,
        );
        let integ_new = clamp(const_new + fric_new * phi, pid.i_limit);
        let torque = p_term + integ_new + d_term + ff_fric + map_offset + ff_inertia;
        // The loop-shaping filters act on the whole command (feedback and feedforward alike:
        // a resonance is excited by either); the limit comes after them.
        let i_unsat = self.shaping.run(torque / self.p.motor.k_m);
        let i_cmd = clamp(i_unsat, self.p.i_max);
        let saturated = i_cmd != i_unsat;
        let integ = if !saturated || (error > 0.0) != (i_unsat > 0.0) {
            self.integ = const_new;
            self.integ_fric = fric_new;
            integ_new
        } else {
            clamp(self.integ + self.integ_fric * phi, pid.i_limit)
        };
        if adaptive {
            let input = AdaptInput {
                feedback: p_term + integ + d_term,
                applied: ff_fric,
                model: ff_model,
                v_ref: r.vel,
                saturated,
            };
            self.adapt.update(&self.p.ff.adapt, &input, self.dt_pos);
        }
        self.i_cmd = i_cmd;
        self.w_ref = r.vel;
        self.a_ref = r.acc;
        self.out = PositionOutput {
            error,
            p: p_term,
            i: integ,
            d: d_term,
            ff_friction: ff_fric + map_offset,
            ff_scale,
            ff_inertia,
            i_cmd,
            saturated,
        };
        self.out
    }

    /// The position map's sample for the next position step: the torque offset \[N·m\] added
    /// to the feedforward and the scale \[-\] on the friction feedforward (the control loop
    /// sets it from its table at the reference, the table motion's correction added to the
    /// offset; 0 and 1: neither).
    pub fn set_map_sample(&mut self, offset: f32, scale: f32) {
        self.map_sample = (offset, scale);
    }

    /// Adds `amps` \[A\] to the current command of the last position step, within `i_max`:
    /// a frequency-response excitation at the plant's input (after the loop-shaping filters,
    /// so that a measured loop gain includes them). Returns the command now \[A\].
    pub fn inject_current(&mut self, amps: f32) -> f32 {
        let want = self.i_cmd + amps;
        let i = clamp(want, self.p.i_max);
        self.i_cmd = i;
        self.out.i_cmd = i;
        self.out.saturated |= i != want;
        i
    }

    /// One current-loop step on the measured current `i_meas` \[A\]; returns the voltage and
    /// PWM duty to apply: the voltage's duty, and the dead time's share of the period added
    /// back on the side of the commanded current (the bridge's loss, whose sign the current
    /// gives: [`ControllerParams::dead_time`]).
    pub fn current_step(&mut self, i_meas: f32) -> CurrentOutput {
        let c = &self.p.current;
        let e = self.i_cmd - i_meas;
        self.e_cur = e;
        let ff = self.p.motor.r * self.i_cmd + self.p.motor.k_e * self.w_ref;
        let integ_new = self.cur_integ + c.ki * e * self.dt_cur;
        let v_unsat = c.kp * e + integ_new + ff;
        let supply = self.supply();
        let vmax = supply * self.duty_max;
        let v = clamp(v_unsat, vmax);
        if v == v_unsat || (e > 0.0) != (v_unsat > 0.0) {
            self.cur_integ = clamp(integ_new, vmax);
        }
        CurrentOutput {
            voltage: v,
            duty: clamp(v * self.inv_supply + self.dead_time_duty(), self.duty_max),
            limited: v != v_unsat && self.duty_max < 1.0,
        }
    }

    /// The duty that makes up for the bridge's dead time \[-\]: `dead_time / T` in the
    /// direction of the commanded current, proportional to it within the band of
    /// [`DEAD_TIME_BAND`] × `i_max` around zero, where the current's ripple crosses zero
    /// within the period and the loss fades (a sign alone would chatter there, a full
    /// step of `2 dead_time / T` at every sign change of a command that hovers at zero).
    pub fn dead_time_duty(&self) -> f32 {
        let p = &self.p;
        if p.dead_time <= 0.0 {
            return 0.0;
        }
        let band = DEAD_TIME_BAND * p.i_max;
        p.dead_time / self.dt_cur * clamp(self.i_cmd / band, 1.0)
    }
}

/// The band of commanded current around zero, as a share of `lim.i_max` \[-\], over which
/// the dead-time compensation goes linearly from one direction's to the other's: 5 mA of the
/// default 0.5 A, where the default motor's current ripple (L/R 25 µs, as long as the PWM
/// period) crosses zero within the period at friction-level currents. Chosen on the default
/// scenario with the real bridge (`hil-sim/tests/bridge.rs`, seven friction draws' median
/// reversal peak): 0.1 % 5.05 counts (the sign chatters), 0.5 % 4.46, 1 % 4.63 (the lowest
/// rms error, 0.410 counts), 2 % 5.15, 5 % 7.27; the ideal bridge 4.40, none 8.64.
pub const DEAD_TIME_BAND: f32 = 0.01;
