//! The power stage every board carries, on the same pins of an STM32F4 (`board.rs` drives
//! it): a DRV8871 H-bridge, an INA240A2 current-sense amplifier, a quadrature encoder.
//! Plain numbers, checked on the host (`tests/tests/boards.rs`).
//!
//! | signal | MCU pin | peripheral | goes to |
//! |---|---|---|---|
//! | H-bridge IN1 | PC6 | TIM8_CH1 (40 kHz PWM, `rate.cur_hz`, center-aligned) | DRV8871 IN1 |
//! | H-bridge IN2 | PC7 | TIM8_CH2 | DRV8871 IN2 |
//! | motor current | PC0 | ADC1_IN10 | INA240A2 OUT (68 mohm shunt in series with the motor, REF at 1.65 V) |
//! | encoder A | PA0 | TIM2_CH1 (32-bit encoder mode) | encoder A (5 V encoders through a 74LVC14 or a divider) |
//! | encoder B | PA1 | TIM2_CH2 | encoder B |
//! | USB D- / D+ | PA11 / PA12 | OTG_FS | USB connector (CDC-ACM) |
//! | SWD | PA13 / PA14 | | probe (probe-rs: flash, defmt logs over RTT) |
//! | motor supply | PC1 | ADC1_IN11 (injected) | VM through 150 kΩ over 10 kΩ to GND (1:16) |
//!
//! The DRV8871 (a cheap 3.6 A H-bridge breakout): VM = motor supply (6.5-45 V, `lim.v_supply`),
//! ILIM resistor for its own hardware current limit above our trip level, GND common with the
//! MCU. IN1/IN2 both low = coast (outputs off, the state while disabled or faulted), both high
//! = brake; driving is sign-magnitude with slow decay (one input high, the other PWM), so the
//! motor current flows through the shunt in both phases of the PWM and the INA240 (built for
//! in-line motor sensing, rejects the PWM edges) sees it all the time.
//!
//! Current sense: 68 mohm × gain 50 = 3.4 V/A around 1.65 V: ±0.48 A over the 12-bit ADC,
//! 0.24 mA per code (the simulator's ±0.5 A, 12 bits), sampled 16 times per PWM period by the
//! hardware, centred on the counter's bottom (`board.rs`).

use crate::boards::hw::F4Clocks;
use crate::device::{Board, SenseChain, SupplySense};
use crate::drive::{BoardLimits, SenseTiming};

/// GPIOC pins of the bridge inputs IN1, IN2 (TIM8_CH1, TIM8_CH2).
pub const BRIDGE_PINS: [usize; 2] = [6, 7];
/// GPIOC pin of the current sense (PC0).
pub const SENSE_PIN: usize = 0;
/// ADC1 channel of the current sense (PC0 = ADC123_IN10).
pub const SENSE_CHANNEL: u8 = 10;

/// The largest PWM period the 16-bit TIM8 takes \[counts\] (one below 65535 so that "always
/// on" is a compare value above it).
pub const PWM_MAX_ARR: u32 = 65_534;
/// Width of the encoder counter \[bits\] (TIM2 is 32-bit).
pub const ENCODER_BITS: u32 = 32;
/// The highest count rate the encoder input must pass [counts/s]: 3.8 rad/s at 3.8 urad per
/// count, 7.6 times the protocol's move speed limit (0.5 rad/s). The input filter is sized
/// from it (`drive::encoder_filter`: at 84 MHz f_DTS/4, N = 8, a 381 ns window: shorter
/// glitches are not counted); an encoder that must count faster needs this raised (and gets
/// a lighter filter).
pub const ENCODER_MAX_RATE: f32 = 1.0e6;

/// ADC reference \[V\].
pub const ADC_VREF: f32 = 3.3;
/// ADC full scale \[codes\].
pub const ADC_FULL_SCALE: f32 = 4095.0;
/// Current-sense transimpedance [V/A]: 68 mohm shunt × INA240A2 gain 50, as built; the
/// default of the parameter `sense.v_per_a` (gms-core's `default_settings`, checked equal on
/// the host), which a board with another shunt sets and saves.
pub const SENSE_V_PER_A: f32 = 0.068 * 50.0;
/// ADC code at zero current the board is built for \[code\] (REF at VDD/2).
pub const SENSE_OFFSET_EXPECTED: f32 = 2048.0;
/// How far the measured zero may lie from it \[code\] (INA240 offset, resistor tolerances).
pub const SENSE_OFFSET_TOLERANCE: f32 = 150.0;

/// How near its 3.3 V supply and ground the INA240's output stays linear \[V\]: about 0.2 V
/// (the hardware review of its datasheet's output swing). With the zero at 1.65 V and 3.4 V/A
/// that leaves ±0.43 A; a zero at the calibration window's edge (150 codes off), ±0.39 A.
pub const SENSE_LINEAR_MARGIN_V: f32 = 0.2;

/// How the current is sampled on a board clocked by `clocks`: 8 conversions of 15 cycles'
/// sampling (0.71 us at 21 MHz: the INA240's output drives the pin directly) + 12, from a
/// trigger latency of 2 ADC cycles (DS8626 t_latr, at most 3): 218 ADC cycles, a 10.4 us
/// window centred on the counter's bottom. Eight, not sixteen: with the current loop at
/// 40 kHz, sixteen (20.7 us) left the control step 55 % of the 25 us period, and a position
/// step with a capture and a swept speed starting (1,611 instructions) overran it; eight
/// leave 75 %. The average's noise is the amplifier's per conversion over √8 (the
/// simulator's default 0.21 mA for 0.6 mA).
pub const fn sense_timing(clocks: &F4Clocks) -> SenseTiming {
    SenseTiming {
        adc_hz: clocks.adc_hz(),
        sample_cycles: 15,
        conversions: 8,
        latency_cycles: 2,
    }
}

/// How long after a PWM edge at the MCU's pin the current reading is disturbed \[s\]: the
/// DRV8871's propagation delay (t_PD, 0.7 µs typical) and dead time (t_DEAD, 220 ns typical:
/// the DRV8870/DRV8871 datasheets' switching characteristics), then the INA240's recovery
/// from the output's common-mode step (about 1 µs: the hardware review of its datasheet's
/// PWM rejection). The duty is limited so that none falls in the sense window
/// (`device::SenseChain::duty_max`: 0.43 at 40 kHz, 0.72 at 20 kHz).
pub const EDGE_SETTLE_S: f32 = 0.7e-6 + 0.22e-6 + 1.0e-6;

/// The DRV8871 sleeps once both inputs have been low for about 1 ms (as they are while the
/// bridge is off) and must wake before it drives: `enable` brakes (both inputs high) this long
/// first. Taken at the 1 ms of TI's drivers of this family (a DRV8871 specific figure is to be
/// confirmed at bring-up: an `enable` that jolts means it is too short).
pub const BRIDGE_WAKE_S: f32 = 1.0e-3;

/// The capture buffer (values): 32 KiB of the F4's 128 KiB of RAM (the firmware's statics
/// are about 20 KiB), e.g. 8192 samples of one field, 2048 of four.
pub const CAPTURE_VALUES: u32 = 8192;

/// Watchdog timeout \[us\], at the LSI's nominal 32 kHz (2.72 s at its 47 kHz maximum): above a
/// 128 KiB sector erase at ×32 (2 s at most, during which nothing runs from flash; the store
/// reloads the watchdog right before each, see `storage.rs`).
pub const WATCHDOG_US: u32 = 4_000_000;

/// What the power stage allows on a board clocked by `clocks` (see [`BoardLimits`]).
pub const fn limits(clocks: &F4Clocks) -> BoardLimits {
    BoardLimits {
        trip_factor: 1.5,
        max_error: 0.01,
        max_speed: 100.0,
        clock_hz: clocks.hclk_hz(),
        // The step starts when the samples are in, half the sense window (5.2 us) after
        // the bottom, and must end before the next bottom (its compare values are taken
        // there): 75 % of the period (18.75 us, 3,150 cycles at 168 MHz, at the default
        // 40 kHz current loop) leaves 1.06 us; at 20 kHz, 37.5 us and 7.3 us.
        budget_fraction: 0.75,
    }
}

/// The board as the device core sees it, for the clock tree `clocks`.
pub const fn board(clocks: &F4Clocks) -> Board {
    let timing = sense_timing(clocks);
    Board {
        pwm_timer_hz: clocks.tim_apb2_hz(),
        pwm_max_arr: PWM_MAX_ARR,
        encoder_bits: ENCODER_BITS,
        sense_oversample: timing.conversions,
        sense: SenseChain {
            vref: ADC_VREF,
            full_scale: ADC_FULL_SCALE,
            zero_code: SENSE_OFFSET_EXPECTED,
            zero_tolerance: SENSE_OFFSET_TOLERANCE,
            linear_margin_v: SENSE_LINEAR_MARGIN_V,
            window_s: timing.window_s(),
            edge_settle_s: EDGE_SETTLE_S,
        },
        limits: limits(clocks),
        has_truth: false,
        bridge_wake_s: BRIDGE_WAKE_S,
        capture_values: CAPTURE_VALUES,
        supply: Some(SupplySense {
            divider: SUPPLY_DIVIDER,
            range_v: SUPPLY_RANGE_V,
        }),
    }
}

/// GPIOC pin of the motor supply's divider (PC1; on the NUCLEO-F446RE's Arduino A4).
pub const SUPPLY_PIN: usize = 1;
/// Its ADC1 channel (PC1 = ADC123_IN11), converted as an injected channel.
pub const SUPPLY_CHANNEL: u8 = 11;
/// The divider, 150 kΩ over 10 kΩ \[-\]: 45 V (the DRV8871's most) reads 2.81 V of the
/// ADC's 3.3, one code 12.9 mV.
pub const SUPPLY_DIVIDER: f32 = 16.0;
/// The DRV8871's operating supply \[V\] (its datasheet's V_M, 6.5 to 45 V).
pub const SUPPLY_RANGE_V: (f32, f32) = (6.5, 45.0);
