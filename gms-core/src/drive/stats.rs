//! The control step's statistics: its duration (worst, mean) and the periods missed.

/// Periods missed between two control steps `since_last` \[cycles\] apart, for a period of
/// `period` \[cycles\]: the nearest whole number of periods, less the one expected (a step more
/// than 1.5 periods after the last missed one). 0 when either is 0 (not measured).
pub fn missed_periods(since_last: u32, period: u32) -> u32 {
    if since_last == 0 || period == 0 {
        return 0;
    }
    let half_up = since_last as u64 + period as u64 / 2;
    // The usual case (on time) without the soft 64-bit division (`__aeabi_uldivmod`).
    if half_up < 2 * period as u64 {
        return 0;
    }
    let periods = half_up / period as u64;
    periods.saturating_sub(1).min(u32::MAX as u64) as u32
}

/// Where a centre-aligned PWM timer is in its period, as an order \[-\]: counting up from the
/// bottom `cnt` (0 up to the top), counting down back to it `0x2_0000 - cnt` (above every
/// up-counting value, growing as the counter falls). Only the order matters: two readings of
/// one period compare as the times they were taken, whatever the period (`ARR`) is, so a step
/// that changes the timer's period needs nothing else. `cnt` is TIMx_CNT, `down` CR1.DIR
/// (read-only in centre-aligned mode, RM0090 §17.4.1).
pub const fn pwm_phase(cnt: u16, down: bool) -> u32 {
    if down {
        0x2_0000 - cnt as u32
    } else {
        cnt as u32
    }
}

/// Whether a step that started at PWM phase `start` and had written the bridge's compare
/// values at `end` (both [`pwm_phase`]) wrote them after the update event they were for: the
/// counter went through the bottom (the update, where preloaded compare values take effect)
/// in between, so the phase went back. The period ran on the old duty, and the new one acts a
/// period late. Exact for a step shorter than a period (a longer one is an overrun by its
/// length already).
pub const fn past_update(start: u32, end: u32) -> bool {
    end < start
}

/// Worst and mean duration of the control step \[cycles\], the periods missed and the steps
/// that wrote their duty late.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct StepStats {
    worst: u32,
    last: u32,
    sum: u64,
    n: u64,
    missed: u32,
    late: u32,
    limited: u32,
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
            late: 0,
            limited: 0,
        }
    }

    /// One current step held at the board's duty limit (the sense window's: the voltage the
    /// loop asked for was more than the limit allows).
    pub fn record_limited(&mut self) {
        self.limited = self.limited.saturating_add(1);
    }

    /// Current steps held at the duty limit since start.
    pub fn limited(&self) -> u32 {
        self.limited
    }

    /// Records a step that wrote its duty after the update it was for ([`past_update`]).
    pub fn record_late(&mut self) {
        self.late = self.late.saturating_add(1);
    }

    /// Steps that wrote their duty after the update they were for, while the bridge drove.
    pub fn late(&self) -> u32 {
        self.late
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
