//! The control step's deadman: a check run above the control interrupt that switches the
//! bridge off when the step stops running or its sampling chain fails.
//!
//! The board ticks [`Deadman::tick`] once per PWM period from an interrupt of a higher
//! priority than the control interrupt (the F4 boards: TIM8's update at the counter's
//! bottom), with the number of control steps started so far. Each period's step starts a
//! fraction of a period after that period's tick (the current samples are centred on the
//! bottom), so a healthy loop has started one step between two ticks. [`Deadman::LIMIT`]
//! ticks in a row without a step switch the bridge off: within two PWM periods of the first
//! step that did not run. One late step (a flash erase stalls every fetch, the deadman's
//! included: the two interrupts then come back pending together, the deadman first) is not
//! a stall. A trip is terminal: the board latches `control_stall`, stops feeding the watchdog
//! and lets it reset the MCU.

/// What made the deadman switch the bridge off (0: nothing), as kept in an atomic byte.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum Stall {
    /// No trip.
    None = 0,
    /// No control step for [`Deadman::LIMIT`] PWM periods.
    NoStep = 1,
    /// The current-sense DMA reported a transfer or direct-mode error (the stream stops).
    DmaError = 2,
    /// The current-sense ADC overran (its DMA requests stop until the flag is cleared).
    AdcOverrun = 3,
    /// The stack came within [`STACK_MARGIN_BYTES`] of its guard (or the statics).
    StackLow = 4,
    /// The HSE failed: the clock security system switched the system clock to the HSI (every
    /// rate and time of the board is then wrong).
    ClockLost = 5,
}

/// The stack's high-water mark may come this close to the bottom of its usable region (the
/// stack guard, or the statics without one) \[bytes\] before the board stops (the control
/// interrupt alone takes about 6.7 KiB at its deepest, `cargo xtask check-elf`).
pub const STACK_MARGIN_BYTES: usize = 2048;

/// Whether `unused` bytes of never-reached stack \[bytes\] are too few: the stack is about
/// to run into the statics (a trip: the board stops before they are overwritten, if the
/// check runs in time — it is a watermark, not a guard).
pub fn stack_low(unused: usize) -> bool {
    unused < STACK_MARGIN_BYTES
}

impl Stall {
    /// The cause kept as `byte` (an unknown value is [`Stall::NoStep`]: a trip all the same).
    pub fn from_u8(byte: u8) -> Stall {
        match byte {
            0 => Stall::None,
            2 => Stall::DmaError,
            3 => Stall::AdcOverrun,
            4 => Stall::StackLow,
            5 => Stall::ClockLost,
            _ => Stall::NoStep,
        }
    }

    /// What it means, for the log line.
    pub fn meaning(self) -> &'static str {
        match self {
            Stall::None => "no stall",
            Stall::NoStep => "the control step did not run for two PWM periods",
            Stall::DmaError => "the current-sense DMA stream reported a transfer error",
            Stall::AdcOverrun => "the current-sense ADC overran (its DMA requests stopped)",
            Stall::StackLow => "the stack came within 2 KiB of its guard",
            Stall::ClockLost => {
                "the HSE failed: the clock security system switched to the HSI (every rate wrong)"
            }
        }
    }

    /// The cause of the sense chain's error flags (the DMA stream's TEIF and DMEIF, the ADC's
    /// OVR), if any; a DMA error first (it stops the stream, and an overrun follows it).
    pub fn from_sense_flags(
        dma_transfer_error: bool,
        dma_direct_error: bool,
        adc_overrun: bool,
    ) -> Stall {
        if dma_transfer_error || dma_direct_error {
            Stall::DmaError
        } else if adc_overrun {
            Stall::AdcOverrun
        } else {
            Stall::None
        }
    }
}

/// The deadman's state (see the module's notes).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Deadman {
    /// The step count at the last tick (`None` before the first).
    last: Option<u32>,
    /// Ticks in a row without a step.
    missed: u32,
    /// Tripped: stays so.
    tripped: bool,
}

impl Deadman {
    /// Ticks in a row without a control step that switch the bridge off.
    pub const LIMIT: u32 = 2;

    /// Not yet ticked.
    pub const fn new() -> Self {
        Deadman {
            last: None,
            missed: 0,
            tripped: false,
        }
    }

    /// One PWM period's tick with the number of control steps started so far (wrapping).
    /// True when the bridge must be off: now and from then on.
    pub fn tick(&mut self, steps: u32) -> bool {
        if self.tripped {
            return true;
        }
        match self.last {
            Some(last) if last == steps => self.missed += 1,
            _ => self.missed = 0,
        }
        self.last = Some(steps);
        self.tripped = self.missed >= Self::LIMIT;
        self.tripped
    }

    /// True once tripped.
    pub fn tripped(&self) -> bool {
        self.tripped
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A model of the two interrupts over PWM periods: each period's tick at the bottom, then
    /// its step (if it runs). Returns the period whose tick tripped, if any.
    fn run(step_runs: impl Fn(u32) -> bool, periods: u32) -> Option<u32> {
        let mut d = Deadman::new();
        let mut steps = 0u32;
        for k in 0..periods {
            if d.tick(steps) {
                return Some(k);
            }
            if step_runs(k) {
                steps = steps.wrapping_add(1);
            }
        }
        None
    }

    #[test]
    fn a_running_loop_never_trips() {
        assert_eq!(run(|_| true, 100_000), None);
    }

    #[test]
    fn a_dead_loop_trips_within_two_periods_of_its_first_missing_step() {
        for dies in [0u32, 1, 5, 977] {
            let trip = run(|k| k < dies, dies + 10).expect("trips");
            // Step `dies` was due just after tick `dies`; the bridge is off at tick dies + 2.
            assert_eq!(trip, dies + 2, "dies at {dies}");
        }
    }

    #[test]
    fn one_missing_step_is_not_a_stall_two_are() {
        assert_eq!(run(|k| k != 40, 1000), None);
        assert_eq!(run(|k| k != 40 && k != 41, 1000), Some(42));
        // Missing every other step never leaves two ticks without one.
        assert_eq!(run(|k| k % 2 == 0, 1000), None);
    }

    /// A flash erase stalls every fetch: the tick and the step of the period it began in come
    /// back pending together, the tick first (higher priority), the step after it.
    #[test]
    fn a_stall_of_the_whole_core_is_one_late_step() {
        let mut d = Deadman::new();
        let mut steps = 0u32;
        for _ in 0..10 {
            assert!(!d.tick(steps));
            steps += 1;
        }
        // The erase begins between a tick and its step: after it, the pending tick sees no
        // step since the last, then the step runs.
        assert!(!d.tick(steps));
        assert!(!d.tick(steps));
        steps += 1;
        for _ in 0..10 {
            assert!(!d.tick(steps));
            steps += 1;
        }
    }

    #[test]
    fn a_trip_is_terminal_and_the_count_may_wrap() {
        let mut d = Deadman::new();
        assert!(!d.tick(u32::MAX));
        assert!(!d.tick(0));
        assert!(!d.tick(0));
        assert!(d.tick(0));
        assert!(d.tick(1), "the loop coming back does not undo the trip");
        assert!(d.tripped());
    }

    #[test]
    fn sense_errors() {
        assert_eq!(Stall::from_sense_flags(false, false, false), Stall::None);
        assert_eq!(Stall::from_sense_flags(true, false, true), Stall::DmaError);
        assert_eq!(Stall::from_sense_flags(false, true, false), Stall::DmaError);
        assert_eq!(
            Stall::from_sense_flags(false, false, true),
            Stall::AdcOverrun
        );
        for s in [
            Stall::None,
            Stall::NoStep,
            Stall::DmaError,
            Stall::AdcOverrun,
        ] {
            assert_eq!(Stall::from_u8(s as u8), s);
        }
        assert_eq!(Stall::from_u8(200), Stall::NoStep);
    }

    #[test]
    fn stack_margin() {
        assert!(stack_low(0));
        assert!(stack_low(STACK_MARGIN_BYTES - 4));
        assert!(!stack_low(STACK_MARGIN_BYTES));
    }
}
