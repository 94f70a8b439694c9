//! The safety checks as pure functions, their limits, and the latched fault word.

use core::fmt::{self, Write};

use super::{abs, libm_ceil};
use crate::control::controller::Settings;

/// The latched fault word: one bit per cause. Any bit set keeps the bridge off until a
/// `clear` command.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Faults(pub u16);

impl Faults {
    /// None.
    pub const NONE: Faults = Faults(0);
    /// The measured current exceeded [`Limits::i_trip`].
    pub const OVER_CURRENT: Faults = Faults(1 << 0);
    /// The position error exceeded [`Limits::max_error`].
    pub const FOLLOWING_ERROR: Faults = Faults(1 << 1);
    /// The encoder moved more than [`Limits::max_step_counts`] in one position period.
    pub const ENCODER_JUMP: Faults = Faults(1 << 2);
    /// A control step took longer than its budget.
    pub const OVERRUN: Faults = Faults(1 << 3);
    /// The position left [`Limits::pos_min`] .. [`Limits::pos_max`].
    pub const POSITION_LIMIT: Faults = Faults(1 << 4);
    /// The parameter set is invalid, or the stored one was invalid or missing at start-up
    /// (the defaults run).
    pub const INVALID_PARAMS: Faults = Faults(1 << 5);
    /// The current-sense offset at start-up was outside the board's window.
    pub const CURRENT_SENSE: Faults = Faults(1 << 6);
    /// The last reset was by the watchdog.
    pub const WATCHDOG_RESET: Faults = Faults(1 << 7);
    /// The deadman above the control interrupt switched the bridge off (the step stopped
    /// running, or the sense chain's DMA or ADC failed), or the stack ran low: terminal, the
    /// watchdog resets.
    pub const CONTROL_STALL: Faults = Faults(1 << 8);
    /// The measured motor supply left the bridge's operating range while driving (a board
    /// with a supply divider: [`crate::device::SupplySense`]).
    pub const SUPPLY: Faults = Faults(1 << 9);

    /// Names of the bits, lowest first.
    pub const NAMES: [&'static str; 10] = [
        "over_current",
        "following_error",
        "encoder_jump",
        "overrun",
        "position_limit",
        "invalid_params",
        "current_sense",
        "watchdog_reset",
        "control_stall",
        "supply",
    ];

    /// What each bit means to the user, in [`Self::NAMES`]' order.
    pub const MEANINGS: [&'static str; 10] = [
        "the measured current exceeded the trip level (lim.i_max with margin): a runaway, a \
         short, a reversed current sense",
        "the position error exceeded its limit: the axis cannot follow (blocked, too little \
         current, gains too soft)",
        "the encoder moved more in one period than the axis can: noise or a loose encoder",
        "a control step took longer than its period",
        "the position left lim.pos_min .. lim.pos_max",
        "the parameter set was invalid, or the stored one invalid or missing at start-up (the \
         defaults run)",
        "the current-sense zero at start-up was outside the board's window",
        "the last reset was by the watchdog",
        "the control step stopped running, its current sampling failed or the stack ran low: \
         the bridge was switched off at once and the board resets",
        "the measured motor supply left the bridge's operating range while driving (a supply \
         sagging under load, unplugged, or above the bridge's rating)",
    ];

    /// The meaning of the fault named `name` (one of [`Self::NAMES`]).
    pub fn meaning(name: &str) -> Option<&'static str> {
        Self::NAMES
            .iter()
            .position(|n| *n == name)
            .and_then(|i| Self::MEANINGS.get(i).copied())
    }

    /// True when no fault is set.
    pub fn is_empty(self) -> bool {
        self.0 == 0
    }

    /// True when every bit of `other` is set.
    pub fn contains(self, other: Faults) -> bool {
        self.0 & other.0 == other.0
    }

    /// Sets the bits of `other` (latching: bits are only ever added here).
    pub fn latch(&mut self, other: Faults) {
        self.0 |= other.0;
    }

    /// The union.
    pub fn union(self, other: Faults) -> Faults {
        Faults(self.0 | other.0)
    }

    /// Writes the names of the set bits, comma-separated (`none` when empty).
    pub fn write_names(self, out: &mut dyn Write) -> fmt::Result {
        if self.is_empty() {
            return out.write_str("none");
        }
        let mut first = true;
        for (i, name) in Faults::NAMES.iter().enumerate() {
            if self.0 & (1 << i) != 0 {
                if !first {
                    out.write_char(',')?;
                }
                out.write_str(name)?;
                first = false;
            }
        }
        if self.0 >> Faults::NAMES.len() != 0 {
            if !first {
                out.write_char(',')?;
            }
            out.write_str("unknown")?;
        }
        Ok(())
    }
}

/// The safety limits the control step checks.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Limits {
    /// Over-current trip \[A\]: |measured current| above it is a fault.
    pub i_trip: f32,
    /// Following-error limit \[rad\]: |reference - position| above it is a fault.
    pub max_error: f32,
    /// Encoder jump limit [counts per position period].
    pub max_step_counts: i64,
    /// Soft lower position limit \[counts\].
    pub pos_min: i64,
    /// Soft upper position limit \[counts\].
    pub pos_max: i64,
    /// Control-step budget \[cycles\]: a step that takes longer is an overrun.
    pub budget_cycles: u32,
    /// One PWM period [cycles of the step clock]: steps further apart missed periods.
    pub period_cycles: u32,
    /// The largest |duty| the board's current sense allows [-] (1 from [`limits_for`]; the
    /// board's sense window sets it: `device::SenseChain::duty_max`).
    pub duty_max: f32,
}

/// What the board allows: the inputs of [`limits_for`].
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct BoardLimits {
    /// Over-current trip as a multiple of the current limit `i_max` [-] (e.g. 1.5).
    pub trip_factor: f32,
    /// Following-error limit \[rad\] (at least [`MIN_ERROR_COUNTS`] counts of the encoder).
    pub max_error: f32,
    /// Highest plausible speed [rad/s]: a faster encoder step is a jump.
    pub max_speed: f32,
    /// CPU clock \[Hz\] (DWT cycles).
    pub clock_hz: u32,
    /// Share of the current-loop period one control step may take [-], in (0, 1].
    pub budget_fraction: f32,
}

/// The smallest following-error limit \[counts\]: with a coarse encoder the board's limit in
/// radians may be only a few counts, which quantisation and an ordinary move's lag exceed.
pub const MIN_ERROR_COUNTS: f32 = 64.0;

/// The share of what the current sense reaches that the over-current trip may use [-]: the
/// trip is met with 5 % of the sense's reach to spare (noise, the ripple about the mean).
pub const TRIP_SHARE_OF_REACH: f32 = 0.95;

/// `trip` \[A\] held to [`TRIP_SHARE_OF_REACH`] of the sense's `reach` \[A\] (a NaN trip
/// gives the cap): the one rule for the trip at start-up and at every hand-over.
pub fn trip_within(trip: f32, reach: f32) -> f32 {
    let cap = TRIP_SHARE_OF_REACH * reach;
    if trip < cap { trip } else { cap }
}

/// The limits the control step checks for the settings `s` on a board `b` whose current
/// sense shows up to `sense_range` \[A\] with the settings' `sense.v_per_a` (the trip stays
/// below 95 % of it; see `device::Board::limits`).
pub fn limits_for(s: &Settings, b: &BoardLimits, sense_range: f32) -> Limits {
    let trip = b.trip_factor * s.i_max;
    let rpc = s.rad_per_count();
    let min_error = MIN_ERROR_COUNTS * rpc;
    let per_step = b.max_speed / rpc / s.pos_rate_hz;
    Limits {
        i_trip: trip_within(trip, sense_range),
        max_error: if b.max_error > min_error {
            b.max_error
        } else {
            min_error
        },
        // Float to int casts saturate (NaN gives 0).
        max_step_counts: (libm_ceil(per_step as f64) as i64).max(1),
        pos_min: (s.pos_min as f64 / rpc as f64) as i64,
        pos_max: (s.pos_max as f64 / rpc as f64) as i64,
        budget_cycles: (b.clock_hz as f32 / s.cur_rate_hz * b.budget_fraction) as u32,
        period_cycles: (b.clock_hz as f64 / s.cur_rate_hz as f64 + 0.5) as u32,
        duty_max: 1.0,
    }
}

/// Over-current: |`i`| \[A\] above `trip` \[A\], or `i` not finite.
pub fn over_current(i: f32, trip: f32) -> bool {
    abs(i) > trip || i.is_nan()
}

/// Following error: |`error`| \[rad\] above `max` \[rad\], or not finite.
pub fn following_error(error: f32, max: f32) -> bool {
    abs(error) > max || error.is_nan()
}

/// Encoder jump: |`delta`| \[counts\] in one period above `max` \[counts\].
pub fn encoder_jump(delta: i64, max: i64) -> bool {
    delta.unsigned_abs() > max.unsigned_abs()
}

/// Outside the soft limits: `pos` \[counts\] below `min` or above `max`.
pub fn outside_limits(pos: i64, min: i64, max: i64) -> bool {
    pos < min || pos > max
}

/// Overrun: a step of `cycles` above `budget` \[cycles\].
pub fn overrun(cycles: u32, budget: u32) -> bool {
    cycles > budget
}

/// What the control step measured, for [`check`].
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Measured {
    /// Motor current \[A\].
    pub current: f32,
    /// Position error \[rad\] (0 while the bridge is off).
    pub error: f32,
    /// Encoder increment since the last position step \[counts\].
    pub delta: i64,
    /// Position periods that increment took (1 normally; more after the loop stood still,
    /// e.g. through a flash erase): the encoder-jump limit scales with it.
    pub periods: u32,
    /// Position \[counts\].
    pub pos: i64,
    /// Duration of the previous control step \[cycles\].
    pub cycles: u32,
}

/// The faults `m` shows against `lim`. While the bridge is off (`enabled` false) only the
/// encoder jump is checked (the others follow from driving).
pub fn check(m: &Measured, lim: &Limits, enabled: bool) -> Faults {
    let mut f = Faults::NONE;
    // The common case (one period) without the 64-bit multiply.
    let max_step = if m.periods > 1 {
        lim.max_step_counts.saturating_mul(m.periods as i64)
    } else {
        lim.max_step_counts
    };
    if encoder_jump(m.delta, max_step) {
        f.latch(Faults::ENCODER_JUMP);
    }
    if !enabled {
        return f;
    }
    if over_current(m.current, lim.i_trip) {
        f.latch(Faults::OVER_CURRENT);
    }
    if following_error(m.error, lim.max_error) {
        f.latch(Faults::FOLLOWING_ERROR);
    }
    if outside_limits(m.pos, lim.pos_min, lim.pos_max) {
        f.latch(Faults::POSITION_LIMIT);
    }
    if overrun(m.cycles, lim.budget_cycles) {
        f.latch(Faults::OVERRUN);
    }
    f
}
