//! The H-bridge: duty to timer compare values, the timer setting for a PWM rate, and switching it off from any context.

use super::{abs, libm_ceil};

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
    let mag = crate::math::min(abs(d), 1.0);
    // The PWM side is high for (1 - |duty|) of the period, low (driving) for |duty|.
    let low = (mag * period as f32 + 0.5) as u32;
    // Above the period the output stays high for the whole period.
    let high = period.saturating_add(1);
    // No drive at all: high for the whole period too. A compare value equal to the period
    // would take the output low for the one tick the counter spends at the top (PWM mode 1,
    // centre-aligned: high while CNT < CCR; RM0090 §17.3.10), a 6 ns drive pulse at 168 MHz
    // in every period of a brake.
    let pwm = if low == 0 {
        high
    } else {
        period.saturating_sub(low.min(period))
    };
    if d >= 0.0 { (high, pwm) } else { (pwm, high) }
}

/// The duty [-1, 1] that [`bridge_compare`]'s values for `duty` and `period` apply: `duty`
/// rounded to the timer's counts (|duty| × `period` to the nearest count), what the bridge
/// really drives (0 for a non-finite duty).
pub fn applied_duty(duty: f32, period: u32) -> f32 {
    if !duty.is_finite() || period == 0 {
        return 0.0;
    }
    // At most `period` counts: |duty| ≤ 1 rounds to at most `period`.
    let low = (crate::math::min(abs(duty), 1.0) * period as f32 + 0.5) as u32;
    let mag = low as f32 / period as f32;
    if duty >= 0.0 { mag } else { -mag }
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
