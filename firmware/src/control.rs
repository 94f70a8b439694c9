//! The control loop's shell: runs gms-core's [`ControlLoop`] in the current-sense DMA's
//! transfer-complete interrupt (one call per PWM period, the current-loop rate, as soon as the
//! period's samples are in; see `board.rs`), so that it is locked to the PWM and independent
//! of everything the communication side does. No allocation, no logging,
//! no waiting lock: one short critical section per position step exchanges requests and status
//! with the comms task through the [`MAILBOX`].
//!
//! Each call reads the encoder counter and the current-sense codes, calls the core, writes
//! the bridge's compare values (and the timer, after a change of loop rates), queues a
//! telemetry sample when one is due, and hands the step's own duration (DWT cycles) back to the
//! core, which latches an overrun and switches the bridge off in the same call. The time since
//! the previous step's start goes in with the inputs: a step more than 1.5 periods after the
//! last means a period was missed (another interrupt or a critical section held the loop
//! off), which the core counts and latches as an overrun while the bridge drives.

use core::cell::RefCell;

use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::channel::Channel;
use gms_core::device::{ControlLoop, Inputs, Mailbox, Sample};

use crate::board::ControlHw;
use crate::irq::IrqOffRawMutex;

/// Requests and status, with every interrupt masked while held (for a copy, never for a step).
pub static MAILBOX: Mutex<IrqOffRawMutex, RefCell<Mailbox>> =
    Mutex::new(RefCell::new(Mailbox::new()));

/// Telemetry samples to the comms task (dropped when it falls behind).
pub static TELEMETRY: Channel<IrqOffRawMutex, Sample, 64> = Channel::new();

/// The loop's state, handed to the interrupt once at start.
static HANDOFF: Mutex<IrqOffRawMutex, RefCell<Option<Loop>>> = Mutex::new(RefCell::new(None));

/// The control loop and the hardware it owns.
pub struct Loop {
    hw: ControlHw,
    core: ControlLoop,
    /// DWT cycle count at the start of the last step (0: none yet).
    last_start: u32,
}

impl Loop {
    /// The loop `core` on the hardware `hw`, bridge off, timer set for the core's rates.
    pub fn new(mut hw: ControlHw, core: ControlLoop) -> Loop {
        let (psc, arr) = core.timing();
        hw.set_pwm_timing(psc, arr);
        hw.set_bridge(0, 0);
        // The loop's status from the start (before its first step).
        MAILBOX.lock(|m| m.borrow_mut().status = core.status());
        Loop {
            hw,
            core,
            last_start: 0,
        }
    }

    /// Hands the loop to the interrupt (call before [`crate::board::start_control`]).
    pub fn hand_over(self) {
        HANDOFF.lock(|h| *h.borrow_mut() = Some(self));
    }

    /// One PWM period.
    fn step(&mut self) {
        let t0 = cortex_m::peripheral::DWT::cycle_count();
        self.hw.ack_sample();
        // The DWT counter wraps every 25.6 s at 168 MHz: a difference of one period is exact
        // across the wrap. The first step has nothing to compare with.
        let since_last = if self.last_start == 0 {
            0
        } else {
            t0.wrapping_sub(self.last_start)
        };
        self.last_start = t0.max(1);
        let inp = Inputs {
            encoder: self.hw.encoder_raw(),
            current_codes: self.hw.current_codes(),
            since_last,
        };
        let out = self.core.step(inp, |st, chunk| {
            MAILBOX.lock(|m| m.borrow_mut().exchange(st, chunk))
        });
        if let Some((psc, arr)) = out.timing {
            self.hw.set_bridge(0, 0);
            self.hw.set_pwm_timing(psc, arr);
        }
        self.hw.set_bridge(out.compare.0, out.compare.1);
        if let Some(s) = out.sample {
            // A full queue drops the sample: the loop never waits for the comms side.
            let _ = TELEMETRY.try_send(s);
        }
        let cycles = cortex_m::peripheral::DWT::cycle_count().wrapping_sub(t0);
        if self.core.finish(cycles) {
            self.hw.set_bridge(0, 0);
        }
    }
}

/// Called by the control interrupt with the interrupt's own slot for the loop
/// (a `static mut` of the handler, reached from nowhere else): the loop is taken from the
/// hand-off on the first call, then owned there.
#[inline(always)]
pub fn on_sample(slot: &mut Option<Loop>) {
    if slot.is_none() {
        *slot = HANDOFF.lock(|h| h.borrow_mut().take());
    }
    match slot {
        Some(l) => l.step(),
        // Not handed over yet: keep the bridge off and the flag clear.
        None => crate::board::idle_sample(),
    }
}
