//! The pure logic of the motor driver firmware: everything the firmware decides, kept here so
//! that it is tested on the host. The firmware only moves numbers between these functions and
//! the hardware.
//!
//! - [`CountExtender`]: a wrapping 16- or 32-bit encoder counter extended to i64.
//! - [`CurrentSense`], [`OffsetCalibration`]: ADC code to amps, with the zero-current offset
//!   measured at start-up.
//! - [`Faults`], [`Limits`], [`check`]: the safety checks as pure functions and the latched
//!   fault word.
//! - [`StepStats`]: worst and mean duration of the control step (DWT cycles).
//! - [`bridge_compare`], [`pwm_timing`]: H-bridge duty to timer compare values, and the timer
//!   setting for a PWM rate.
//! - [`encode_settings`], [`decode_settings`]: the parameter record kept in flash, with a
//!   version, a layout id and a checksum.

use core::fmt::{self, Write};

use crate::protocol::{Access, PARAMS, Settings};

/// Extends a wrapping hardware counter of `bits` bits (1 to 32) to an i64 count.
///
/// Correct as long as the counter moves by less than half its range between two updates
/// (32 767 counts for a 16-bit timer; 2^31 for a 32-bit one).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CountExtender {
    bits: u32,
    last: u32,
    count: i64,
}

/// The signed difference `raw - last` of a `bits`-bit wrapping counter \[counts\], taken as the
/// shortest way round (in `-2^(bits-1) .. 2^(bits-1)`). `bits` is clamped to 1..=32.
pub fn wrapping_delta(last: u32, raw: u32, bits: u32) -> i64 {
    let bits = bits.clamp(1, 32);
    let shift = 32 - bits;
    // Move the counter into the top bits so that u32 wrapping is the counter's wrapping.
    let d = (raw << shift).wrapping_sub(last << shift) as i32;
    (d >> shift) as i64
}

impl CountExtender {
    /// An extender for a `bits`-bit counter (clamped to 1..=32) that reads `raw` now; the
    /// extended count starts at 0.
    pub fn new(bits: u32, raw: u32) -> Self {
        CountExtender {
            bits: bits.clamp(1, 32),
            last: raw,
            count: 0,
        }
    }

    /// Takes a new raw reading; returns the increment since the last one \[counts\].
    pub fn update(&mut self, raw: u32) -> i64 {
        let d = wrapping_delta(self.last, raw, self.bits);
        self.last = raw;
        self.count = self.count.saturating_add(d);
        d
    }

    /// The extended count \[counts\].
    pub fn count(&self) -> i64 {
        self.count
    }
}

/// ADC code to motor current \[A\]: `i = (code - offset) * amps_per_code`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CurrentSense {
    /// Current per ADC code [A/code] (negative if the amplifier's sign is reversed).
    pub amps_per_code: f32,
    /// ADC code at zero current \[code\].
    pub offset: f32,
}

impl CurrentSense {
    /// A sense chain: ADC reference `vref` \[V\], `full_scale` codes (4095 for 12 bits),
    /// transimpedance `volts_per_amp` [V/A] (shunt resistance times amplifier gain), zero at
    /// `offset` \[code\]. `None` unless every value is finite and positive (offset >= 0).
    pub fn new(vref: f32, full_scale: f32, volts_per_amp: f32, offset: f32) -> Option<Self> {
        let ok = |x: f32| x.is_finite() && x > 0.0;
        if !(ok(vref) && ok(full_scale) && ok(volts_per_amp) && offset.is_finite()) || offset < 0.0
        {
            return None;
        }
        Some(CurrentSense {
            amps_per_code: vref / full_scale / volts_per_amp,
            offset,
        })
    }

    /// The current for an ADC code (or the sum of `n` codes, see [`CurrentSense::amps_sum`])
    /// \[A\].
    pub fn amps(&self, code: u16) -> f32 {
        (code as f32 - self.offset) * self.amps_per_code
    }

    /// The current for the sum of `n` oversampled codes \[A\] (`n` = 0 gives 0).
    pub fn amps_sum(&self, sum: u32, n: u32) -> f32 {
        if n == 0 {
            return 0.0;
        }
        (sum as f32 / n as f32 - self.offset) * self.amps_per_code
    }

    /// The largest current the ADC can show in either direction \[A\].
    pub fn range(&self, full_scale: f32) -> f32 {
        let up = (full_scale - self.offset) * self.amps_per_code;
        let down = self.offset * self.amps_per_code;
        let (up, down) = (abs(up), abs(down));
        if up < down { up } else { down }
    }
}

/// Averages ADC codes taken at zero current (bridge off) into the sense offset.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct OffsetCalibration {
    sum: u64,
    n: u32,
}

impl OffsetCalibration {
    /// Adds one reading taken with the bridge off \[code\] (a code, or a sum of oversampled
    /// codes: then `finish`'s window is in sums too).
    pub fn push(&mut self, code: u32) {
        self.sum = self.sum.saturating_add(code as u64);
        self.n = self.n.saturating_add(1);
    }

    /// Samples so far.
    pub fn samples(&self) -> u32 {
        self.n
    }

    /// The mean code \[code\] if at least one sample was taken and it lies within
    /// `expected ± tolerance` \[code\]; `None` means the sense chain is not what the board says
    /// (not connected, wrong reference): a fault.
    pub fn finish(&self, expected: f32, tolerance: f32) -> Option<f32> {
        if self.n == 0 {
            return None;
        }
        let mean = self.sum as f32 / self.n as f32;
        (abs(mean - expected) <= tolerance).then_some(mean)
    }
}

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

    /// Names of the bits, lowest first.
    pub const NAMES: [&'static str; 8] = [
        "over_current",
        "following_error",
        "encoder_jump",
        "overrun",
        "position_limit",
        "invalid_params",
        "current_sense",
        "watchdog_reset",
    ];

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
}

/// What the board allows: the inputs of [`limits_for`].
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct BoardLimits {
    /// Over-current trip as a multiple of the current limit `i_max` [-] (e.g. 1.5).
    pub trip_factor: f32,
    /// Largest current the sense chain can show \[A\]; the trip stays below 95 % of it.
    pub sense_range: f32,
    /// Following-error limit \[rad\].
    pub max_error: f32,
    /// Highest plausible speed [rad/s]: a faster encoder step is a jump.
    pub max_speed: f32,
    /// CPU clock \[Hz\] (DWT cycles).
    pub clock_hz: u32,
    /// Share of the current-loop period one control step may take [-], in (0, 1].
    pub budget_fraction: f32,
}

/// The limits the control step checks for the settings `s` on a board `b`.
pub fn limits_for(s: &Settings, b: &BoardLimits) -> Limits {
    let trip = b.trip_factor * s.i_max;
    let cap = 0.95 * b.sense_range;
    let rpc = s.rad_per_count;
    let per_step = b.max_speed / rpc / s.pos_rate_hz;
    Limits {
        i_trip: if trip < cap { trip } else { cap },
        max_error: b.max_error,
        // Float to int casts saturate (NaN gives 0).
        max_step_counts: (libm_ceil(per_step as f64) as i64).max(1),
        pos_min: (s.pos_min as f64 / rpc as f64) as i64,
        pos_max: (s.pos_max as f64 / rpc as f64) as i64,
        budget_cycles: (b.clock_hz as f32 / s.cur_rate_hz * b.budget_fraction) as u32,
        period_cycles: (b.clock_hz as f64 / s.cur_rate_hz as f64 + 0.5) as u32,
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
    /// Encoder increment over the last position period \[counts\].
    pub delta: i64,
    /// Position \[counts\].
    pub pos: i64,
    /// Duration of the previous control step \[cycles\].
    pub cycles: u32,
}

/// The faults `m` shows against `lim`. While the bridge is off (`enabled` false) only the
/// encoder jump is checked (the others follow from driving).
pub fn check(m: &Measured, lim: &Limits, enabled: bool) -> Faults {
    let mut f = Faults::NONE;
    if encoder_jump(m.delta, lim.max_step_counts) {
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

/// Periods missed between two control steps `since_last` \[cycles\] apart, for a period of
/// `period` \[cycles\]: the nearest whole number of periods, less the one expected (a step more
/// than 1.5 periods after the last missed one). 0 when either is 0 (not measured).
pub fn missed_periods(since_last: u32, period: u32) -> u32 {
    if since_last == 0 || period == 0 {
        return 0;
    }
    let periods = (since_last as u64 + period as u64 / 2) / period as u64;
    periods.saturating_sub(1).min(u32::MAX as u64) as u32
}

/// Worst and mean duration of the control step \[cycles\], and the periods missed.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct StepStats {
    worst: u32,
    last: u32,
    sum: u64,
    n: u64,
    missed: u32,
}

impl StepStats {
    /// No step recorded.
    pub const fn new() -> Self {
        StepStats {
            worst: 0,
            last: 0,
            sum: 0,
            n: 0,
            missed: 0,
        }
    }

    /// Records `n` missed periods.
    pub fn record_missed(&mut self, n: u32) {
        self.missed = self.missed.saturating_add(n);
    }

    /// Periods missed while the bridge drove.
    pub fn missed(&self) -> u32 {
        self.missed
    }

    /// Records one step of `cycles`.
    pub fn record(&mut self, cycles: u32) {
        self.last = cycles;
        if cycles > self.worst {
            self.worst = cycles;
        }
        self.sum = self.sum.saturating_add(cycles as u64);
        self.n = self.n.saturating_add(1);
    }

    /// The longest step recorded \[cycles\].
    pub fn worst(&self) -> u32 {
        self.worst
    }

    /// The last step recorded \[cycles\].
    pub fn last(&self) -> u32 {
        self.last
    }

    /// Steps recorded.
    pub fn count(&self) -> u64 {
        self.n
    }

    /// The mean step \[cycles\] (0 before the first).
    pub fn mean(&self) -> f32 {
        if self.n == 0 {
            0.0
        } else {
            (self.sum as f64 / self.n as f64) as f32
        }
    }
}

/// `cycles` of a `clock_hz` clock in microseconds \[us\].
pub fn cycles_to_us(cycles: f32, clock_hz: u32) -> f32 {
    if clock_hz == 0 {
        0.0
    } else {
        cycles * (1e6 / clock_hz as f32)
    }
}

/// STM32 timer input filters (TIMx_CCMRx ICxF, RM0090 §18.4.7): for each code 0..=15, the
/// sampling clock's divider of f_DTS (0: f_CK_INT) and the samples N an input must keep its
/// new level before the edge is taken. Code 0 is no filter.
pub const INPUT_FILTERS: [(u32, u32); 16] = [
    (1, 1),
    (1, 2),
    (1, 4),
    (1, 8),
    (2, 6),
    (2, 8),
    (4, 6),
    (4, 8),
    (8, 6),
    (8, 8),
    (16, 5),
    (16, 6),
    (16, 8),
    (32, 5),
    (32, 6),
    (32, 8),
];

/// The strongest timer input filter for a quadrature encoder counted on both edges of both
/// channels up to `max_count_rate` [counts/s], on a timer clocked at `timer_hz` \[Hz\] (f_DTS =
/// f_CK_INT): the filter's window (N samples) stays at most half of the shortest time between
/// two edges (1 / `max_count_rate`), so edges at the highest rate pass with a factor 2 for
/// phase error and duty spread, while glitches shorter than the window are rejected. Returns
/// the ICxF code and the window \[s\]; code 0 (no filter, window 0) when even the lightest
/// filter would be too slow or the arguments are not positive.
pub fn encoder_filter(timer_hz: u32, max_count_rate: f32) -> (u8, f32) {
    if timer_hz == 0 || !max_count_rate.is_finite() || max_count_rate <= 0.0 {
        return (0, 0.0);
    }
    let limit = 0.5 / max_count_rate as f64;
    let mut best = (0u8, 0.0f32);
    let mut longest = 0.0f64;
    for (code, &(div, n)) in INPUT_FILTERS.iter().enumerate().skip(1) {
        let window = n as f64 * div as f64 / timer_hz as f64;
        if window <= limit && window > longest {
            longest = window;
            best = (code as u8, window as f32);
        }
    }
    best
}

/// A board's means of switching its bridge off from any context (a panic, a fault handler,
/// the supervisor), register writes only.
pub trait BridgeOff {
    /// The PWM timer stops driving its outputs (on an STM32 advanced timer: BDTR.MOE cleared;
    /// with OSSI set the outputs go to their idle level).
    fn disable_timer_outputs(&mut self);
    /// The bridge inputs' GPIO output latches set low (no effect on the pins yet while the
    /// timer owns them).
    fn latch_pins_low(&mut self);
    /// The bridge inputs taken from the timer as plain GPIO outputs (driving the latches).
    fn pins_to_gpio_outputs(&mut self);
}

/// Switches the bridge off, whatever state the timer is in: the timer's outputs off, then the
/// pins' latches low, and only then the pins handed to the GPIO, so that no pin ever drives
/// an old latch value (a high latch handed over first would switch that input on).
pub fn bridge_off<B: BridgeOff>(b: &mut B) {
    b.disable_timer_outputs();
    b.latch_pins_low();
    b.pins_to_gpio_outputs();
}

/// Timer compare values for the two inputs of an H-bridge driven sign-magnitude with slow
/// decay (drive / brake, as a DRV8871's IN1/IN2), for `duty` in [-1, 1] and a timer period
/// of `period` counts: the input on the side of the direction stays high, the other is low
/// for |duty| of the period (PWM mode 1: the output is high while the counter is below the
/// compare value). `enabled` false gives both low (the bridge coasts, outputs off).
/// A non-finite duty counts as 0.
pub fn bridge_compare(duty: f32, period: u32, enabled: bool) -> (u32, u32) {
    if !enabled {
        return (0, 0);
    }
    let d = if duty.is_finite() { duty } else { 0.0 };
    let mag = abs(d).min(1.0);
    // The PWM side is high for (1 - |duty|) of the period, low (driving) for |duty|.
    let low = (mag * period as f32 + 0.5) as u32;
    let pwm = period.saturating_sub(low.min(period));
    // Above the period the output stays high for the whole period.
    let high = period.saturating_add(1);
    if d >= 0.0 { (high, pwm) } else { (pwm, high) }
}

/// How a board's ADC samples the motor current: a sequence of `conversions` conversions of
/// one channel started by a hardware trigger, each `sample_cycles` of sampling plus 12 cycles
/// of 12-bit conversion (RM0090 §13.5: T_conv = sampling time + 12 ADC cycles), at `adc_hz`.
/// The trigger leads the PWM period's turning point so that the sampling instants are centred
/// on it: the triangular ripple of the current is point-symmetric about its mid-value there,
/// so the mean of a centred window is the period's mean current, without the ripple.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SenseTiming {
    /// ADC clock \[Hz\].
    pub adc_hz: u32,
    /// Sampling time of one conversion [ADC cycles].
    pub sample_cycles: u32,
    /// Conversions per sample (summed) [-].
    pub conversions: u32,
    /// Delay from the trigger to the start of the first sampling [ADC cycles] (the
    /// datasheet's trigger-to-conversion latency).
    pub latency_cycles: u32,
}

impl SenseTiming {
    /// One conversion [ADC cycles].
    pub const fn conversion_cycles(&self) -> u32 {
        self.sample_cycles + 12
    }

    /// From the trigger to the end of the last conversion \[s\].
    pub const fn window_s(&self) -> f32 {
        if self.adc_hz == 0 {
            return 0.0;
        }
        (self.latency_cycles + self.conversions * self.conversion_cycles()) as f32
            / self.adc_hz as f32
    }

    /// From the trigger to the centroid of the sampling instants (each at the end of its
    /// sampling time) \[s\]: how far the trigger must lead the turning point.
    pub const fn lead_s(&self) -> f32 {
        if self.adc_hz == 0 {
            return 0.0;
        }
        let n = if self.conversions == 0 {
            1.0
        } else {
            self.conversions as f32
        };
        (self.latency_cycles as f32
            + self.sample_cycles as f32
            + 0.5 * (n - 1.0) * self.conversion_cycles() as f32)
            / self.adc_hz as f32
    }

    /// The lead in counts of a timer clocked at `timer_hz` \[Hz\] with prescaler register `psc`
    /// (counting at timer_hz / (psc + 1)), rounded.
    pub fn lead_counts(&self, timer_hz: u32, psc: u32) -> u32 {
        let f = timer_hz as f64 / (psc as f64 + 1.0);
        (self.lead_s() as f64 * f + 0.5) as u32
    }
}

/// Prescaler and period (both as the register values, i.e. minus one) of a center-aligned
/// timer at `clock_hz` \[Hz\] giving `rate_hz` \[Hz\], with a period of at most `max_arr`
/// (65535 for a 16-bit timer). The period is the largest that fits, so that the duty
/// resolution is the best the clock allows. `None` if no setting gives the rate within 1 %
/// or the period would be below 100 counts.
pub fn pwm_timing(clock_hz: u32, rate_hz: f32, max_arr: u32) -> Option<(u32, u32)> {
    if !(rate_hz.is_finite() && rate_hz > 0.0) || clock_hz == 0 {
        return None;
    }
    // Center-aligned: one period is 2 * (ARR) timer ticks.
    let ticks = clock_hz as f64 / (2.0 * rate_hz as f64);
    if ticks > 4.3e9 * 65536.0 {
        return None;
    }
    let max = max_arr.max(1) as f64;
    let psc = libm_ceil(ticks / max).max(1.0);
    let arr = (ticks / psc + 0.5) as u64;
    if !(100..=max_arr as u64).contains(&arr) || psc > 65536.0 {
        return None;
    }
    let actual = clock_hz as f64 / (2.0 * psc * arr as f64);
    let err = (actual - rate_hz as f64) / rate_hz as f64;
    if !(-0.01..=0.01).contains(&err) {
        return None;
    }
    Some((psc as u32 - 1, arr as u32))
}

fn libm_ceil(x: f64) -> f64 {
    let t = x as u64 as f64;
    if t < x { t + 1.0 } else { t }
}

fn abs(x: f32) -> f32 {
    if x < 0.0 { -x } else { x }
}

/// Version of the stored parameter record.
pub const RECORD_VERSION: u8 = 1;

/// Bytes of a stored parameter record: version (1), layout id (4), mode (1), one f32 per
/// numeric parameter of [`PARAMS`] (little-endian), CRC-32 (4).
pub const RECORD_LEN: usize = 1 + 4 + 1 + 4 * MAX_NUMBERS + 4;

/// The most numeric parameters a record holds (room for the table to grow).
pub const MAX_NUMBERS: usize = 64;

/// Why a stored record was not used.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum RecordError {
    /// Shorter or longer than [`RECORD_LEN`].
    Length,
    /// The checksum does not match.
    Checksum,
    /// Another record version.
    Version,
    /// Written for another parameter table (parameters added or renamed).
    Layout,
    /// A value is out of its range, or the whole set is invalid.
    Invalid,
}

impl fmt::Display for RecordError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            RecordError::Length => "stored parameters: wrong length",
            RecordError::Checksum => "stored parameters: checksum mismatch",
            RecordError::Version => "stored parameters: other version",
            RecordError::Layout => "stored parameters: other parameter table",
            RecordError::Invalid => "stored parameters: invalid set",
        })
    }
}

/// CRC-32 (IEEE 802.3, reflected, as zlib's) of `data`.
pub fn crc32(data: &[u8]) -> u32 {
    let mut crc = !0u32;
    for &b in data {
        crc ^= b as u32;
        for _ in 0..8 {
            let mask = (crc & 1).wrapping_neg();
            crc = (crc >> 1) ^ (0xEDB8_8320 & mask);
        }
    }
    !crc
}

/// An id of the parameter table: FNV-1a over every path and its kind, so that a record
/// written for another table is recognised.
pub fn layout_id() -> u32 {
    let mut h = 0x811c_9dc5u32;
    let mut eat = |b: u8| {
        h ^= b as u32;
        h = h.wrapping_mul(0x0100_0193);
    };
    for p in PARAMS {
        for b in p.path.bytes() {
            eat(b);
        }
        eat(match p.access {
            Access::Number { .. } => b'n',
            Access::Mode => b'm',
            Access::Estimate(_) => b'e',
        });
    }
    h
}

/// The record of `s` for flash.
pub fn encode_settings(s: &Settings) -> [u8; RECORD_LEN] {
    let mut out = [0u8; RECORD_LEN];
    let mut w = out.iter_mut();
    let mut put = |bytes: &[u8]| {
        for &b in bytes {
            if let Some(slot) = w.next() {
                *slot = b;
            }
        }
    };
    put(&[RECORD_VERSION]);
    put(&layout_id().to_le_bytes());
    put(&[mode_code(s)]);
    let mut n = 0;
    for p in PARAMS {
        if let Access::Number { get, .. } = p.access {
            if n < MAX_NUMBERS {
                put(&get(s).to_le_bytes());
                n += 1;
            }
        }
    }
    let body = RECORD_LEN - 4;
    let crc = crc32(out.get(..body).unwrap_or(&[]));
    if let Some(tail) = out.get_mut(body..) {
        tail.copy_from_slice(&crc.to_le_bytes());
    }
    out
}

fn mode_code(s: &Settings) -> u8 {
    use crate::controller::FfMode;
    match s.ff.mode {
        FfMode::None => 0,
        FfMode::Static => 1,
        FfMode::Gms => 2,
        FfMode::GmsAdaptive => 3,
    }
}

/// The settings in a record, filled into a copy of `base` (the fields the table does not
/// cover) and validated as a whole: either every value is applied or the error says why none
/// is.
pub fn decode_settings(rec: &[u8], base: &Settings) -> Result<Settings, RecordError> {
    use crate::controller::FfMode;
    if rec.len() != RECORD_LEN {
        return Err(RecordError::Length);
    }
    let (body, tail) = rec.split_at(RECORD_LEN - 4);
    let mut crc = [0u8; 4];
    crc.copy_from_slice(tail);
    if crc32(body) != u32::from_le_bytes(crc) {
        return Err(RecordError::Checksum);
    }
    let byte = |i: usize| body.get(i).copied().unwrap_or(0);
    if byte(0) != RECORD_VERSION {
        return Err(RecordError::Version);
    }
    if u32::from_le_bytes([byte(1), byte(2), byte(3), byte(4)]) != layout_id() {
        return Err(RecordError::Layout);
    }
    let mut s = *base;
    s.ff.mode = match byte(5) {
        0 => FfMode::None,
        1 => FfMode::Static,
        2 => FfMode::Gms,
        3 => FfMode::GmsAdaptive,
        _ => return Err(RecordError::Invalid),
    };
    let mut values = body.get(6..).unwrap_or(&[]).chunks_exact(4);
    for p in PARAMS {
        if let Access::Number { set, min, max, .. } = p.access {
            let Some(chunk) = values.next() else {
                return Err(RecordError::Layout);
            };
            let mut b = [0u8; 4];
            b.copy_from_slice(chunk);
            let v = f32::from_le_bytes(b);
            if !(v.is_finite() && v >= min && v <= max) {
                return Err(RecordError::Invalid);
            }
            set(&mut s, v);
        }
    }
    s.validate().map_err(|_| RecordError::Invalid)?;
    Ok(s)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn delta_of_a_16_bit_counter_wraps() {
        assert_eq!(wrapping_delta(65535, 2, 16), 3);
        assert_eq!(wrapping_delta(2, 65535, 16), -3);
        assert_eq!(wrapping_delta(0, 32767, 16), 32767);
        assert_eq!(wrapping_delta(0, 32768, 16), -32768);
        // Bits above the counter's width are ignored.
        assert_eq!(wrapping_delta(0x1_0000, 0x2_0001, 16), 1);
    }

    #[test]
    fn delta_of_a_32_bit_counter_wraps() {
        assert_eq!(wrapping_delta(u32::MAX, 0, 32), 1);
        assert_eq!(wrapping_delta(0, u32::MAX, 32), -1);
        assert_eq!(wrapping_delta(0x7fff_fff0, 0x8000_0010, 32), 0x20);
    }
}
