//! The current sense: ADC codes to amps, the zero measured at start-up, and when the ADC samples within the PWM period.

use super::abs;

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

    /// The mean of the readings so far \[code\] (`None` before the first).
    pub fn mean(&self) -> Option<f32> {
        (self.n > 0).then(|| self.sum as f32 / self.n as f32)
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
