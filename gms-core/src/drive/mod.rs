//! The pure logic of the motor driver firmware: everything the firmware decides, kept here so
//! that it is tested on the host. The firmware only moves numbers between these functions and
//! the hardware.
//!
//! - `encoder`: [`CountExtender`] (a wrapping 16- or 32-bit counter extended to i64),
//!   [`encoder_filter`] (the timer input filter for a count rate).
//! - `sense`: [`CurrentSense`], [`OffsetCalibration`] (ADC code to amps, the zero measured at
//!   start-up), [`SenseTiming`] (when the ADC samples within the PWM period).
//! - `faults`: [`Faults`], [`Limits`], [`check`] (the safety checks as pure functions, the
//!   latched fault word).
//! - `stats`: [`StepStats`], [`missed_periods`] (the control step's duration, missed periods).
//! - `bridge`: [`bridge_compare`], [`pwm_timing`], [`bridge_off`] (duty to compare values,
//!   the timer setting for a PWM rate, switching off from any context).
//! - `deadman`: [`Deadman`], [`Stall`] (the check above the control interrupt that switches
//!   the bridge off when the step stops running or the sense chain fails).

mod bridge;
mod deadman;
mod encoder;
mod faults;
mod sense;
mod stats;

pub use bridge::*;
pub use deadman::*;
pub use encoder::*;
pub use faults::*;
pub use sense::*;
pub use stats::*;

/// The smallest whole number not below `x` (for the non-negative `x` used here).
fn libm_ceil(x: f64) -> f64 {
    let t = x as u64 as f64;
    if t < x { t + 1.0 } else { t }
}

/// |x| without std.
fn abs(x: f32) -> f32 {
    if x < 0.0 { -x } else { x }
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
