//! The control loop's shell: runs gms-core's [`ControlLoop`] in the current-sense DMA's
//! transfer-complete interrupt (one call per PWM period, the current-loop rate, as soon as the
//! period's samples are in; see `board.rs`), so that it is locked to the PWM and independent
//! of everything the communication side does. No allocation, no logging,
//! no waiting lock: one short critical section per position step exchanges requests and status
//! with the comms task through the [`MAILBOX`].
//!
//! Each call reads the encoder counter and the current-sense codes, calls the core, writes
//! the bridge's compare values (and the timer, after a change of loop rates), queues a
//! telemetry sample when one is due, and hands the step's own duration (DWT cycles) and whether
//! its compare values went in after the PWM update they were for (the timer's counter read at
//! the start and after the write) back to the core, which latches an overrun and switches the
//! bridge off in the same call. The time since
//! the previous step's start goes in with the inputs: a step more than 1.5 periods after the
//! last means a period was missed (another interrupt or a critical section held the loop
//! off), which the core counts and latches as an overrun while the bridge drives.
//!
//! Each step counts itself in [`STEPS`] first thing, for the deadman above it (`board.rs`,
//! gms-core's `drive::Deadman`), which switches the bridge off through [`trip`] when two PWM
//! periods pass without a step or the sense chain reports an error. A trip is terminal: the
//! cause stays in [`STALL`], the status says `control_stall`, a step that still runs halts its
//! core, and the supervisor stops feeding the watchdog.

use core::sync::atomic::{AtomicU8, AtomicU32, Ordering};

use gms_core::device::{ControlLoop, Inputs, Mailbox, Sample};
use gms_core::drive::{self, Faults, Stall};
use static_cell::StaticCell;

use embassy_stm32::{interrupt, pac};
use f4_regs::{pwm, sense};
use gms_core::drive::Deadman;

use crate::board::ControlHw;
use crate::irq::LoopShared;

/// Requests and status: thread mode holds the control interrupt off while it copies (never
/// for longer), the control interrupt reaches it freely (`irq::LoopShared`).
pub static MAILBOX: LoopShared<Mailbox> = LoopShared::new(Mailbox::new());

/// Telemetry samples from the loop to the comms task: a lock-free queue (heapless's MPMC
/// one, used by one producer and one consumer), so that the loop never wakes a task — an
/// executor's waker takes the global critical section, which does not exclude an interrupt
/// above its mask (`irq.rs`); the comms task polls the queue instead. A full queue drops the
/// sample. (Not heapless's SPSC queue: in heapless 0.9 its capacity is a run-time value and
/// its index arithmetic a `%` whose division by zero would link a panic into the control
/// interrupt; this one masks a power-of-two index.)
pub type TelemetryQueue = heapless::mpmc::Queue<Sample, 64>;
/// The loop's end of the telemetry queue.
pub type TelemetryTx = &'static TelemetryQueue;
/// The comms task's end of the telemetry queue.
pub type TelemetryRx = &'static TelemetryQueue;

/// The telemetry queue's two ends.
pub fn telemetry() -> (TelemetryTx, TelemetryRx) {
    static QUEUE: TelemetryQueue = TelemetryQueue::new();
    (&QUEUE, &QUEUE)
}

/// Control steps started so far (wrapping): written by the control interrupt only, read by
/// the deadman.
static STEPS: AtomicU32 = AtomicU32::new(0);

/// Why the deadman switched the bridge off ([`Stall`] as a byte; 0 while it has not).
static STALL: AtomicU8 = AtomicU8::new(Stall::None as u8);

/// Control steps started so far (wrapping), for the deadman.
#[inline(always)]
pub fn steps() -> u32 {
    STEPS.load(Ordering::Relaxed)
}

/// What the deadman found ([`Stall::None`] while the loop runs).
pub fn stall() -> Stall {
    Stall::from_u8(STALL.load(Ordering::Relaxed))
}

/// Switches the bridge off for good from the deadman, an error interrupt or the supervisor:
/// the pins low as GPIO outputs (registers only), the first cause kept, and `control_stall`
/// put in the status the host reads (the loop may never run again to say it).
pub fn trip(cause: Stall) {
    crate::board::bridge_off_now();
    let _ = STALL.compare_exchange(
        Stall::None as u8,
        cause as u8,
        Ordering::Relaxed,
        Ordering::Relaxed,
    );
    // Not into the mailbox: the deadman and the NMI never touch it (`irq::LoopShared`). The
    // status the host reads shows the stall from `STALL` ([`show_stall`]), and a loop that
    // still runs latches it itself.
}

/// A stall the deadman or the NMI found shown in `status`: `control_stall` latched, disabled
/// (the loop may never run again to say it).
pub fn show_stall(status: &mut gms_core::device::Status) {
    if stall() != Stall::None {
        status.faults.latch(Faults::CONTROL_STALL);
        status.enabled = false;
    }
}

/// The loop's state, handed to the interrupt once at start: a reference to it in its
/// [`StaticCell`] (`None` is a null pointer, so this static and the interrupt's slot are
/// zero-initialised, in .bss: a `Loop` held by value here and there would be 2.9 KB of
/// initialiser each in the flash's .data).
static HANDOFF: LoopShared<Option<&'static mut Loop>> = LoopShared::new(None);

/// The control loop and the hardware it owns.
pub struct Loop {
    hw: ControlHw,
    core: ControlLoop,
    telemetry: TelemetryTx,
    /// DWT cycle count at the start of the last step (0: none yet).
    last_start: u32,
}

impl Loop {
    /// The loop `core` on the hardware `hw`, bridge off, timer set for the core's rates.
    pub fn new(mut hw: ControlHw, core: ControlLoop, telemetry: TelemetryTx) -> Loop {
        let (psc, arr) = core.timing();
        hw.set_pwm_timing(psc, arr);
        hw.set_bridge(0, 0);
        // The loop's status from the start (before its first step).
        MAILBOX.lock(|m| m.borrow_mut().status = core.status());
        Loop {
            hw,
            core,
            telemetry,
            last_start: 0,
        }
    }

    /// Puts the loop in its static (once; `None` on a second call), where the caller
    /// finishes it in place (the map's and the table's buffers) before [`Loop::hand_over`]:
    /// the 3 KiB loop is not copied through the stack again.
    pub fn install(self) -> Option<&'static mut Loop> {
        static CELL: StaticCell<Loop> = StaticCell::new();
        CELL.try_init(self)
    }

    /// The loop's core, to finish in place before the hand-over.
    pub fn core_mut(&mut self) -> &mut ControlLoop {
        &mut self.core
    }

    /// Hands the installed loop to the interrupt (before [`crate::board::start_control`]).
    pub fn hand_over(l: &'static mut Loop) {
        HANDOFF.lock(|h| *h.borrow_mut() = Some(l));
    }

    /// One PWM period.
    fn step(&mut self) {
        let t0 = cortex_m::peripheral::DWT::cycle_count();
        let phase0 = self.hw.pwm_phase();
        // Only this interrupt writes it: a load and a store, no read-modify-write needed.
        STEPS.store(
            STEPS.load(Ordering::Relaxed).wrapping_add(1),
            Ordering::Relaxed,
        );
        self.hw.ack_sample();
        if STALL.load(Ordering::Relaxed) != Stall::None as u8 {
            // The deadman tripped while this loop was held off: it stays off and says so.
            self.core.halt(Faults::CONTROL_STALL);
        }
        // The DWT counter wraps every 25.6 s at 168 MHz: a difference of one period is exact
        // across the wrap. The first step has nothing to compare with.
        let since_last = if self.last_start == 0 {
            0
        } else {
            t0.wrapping_sub(self.last_start)
        };
        self.last_start = t0.max(1);
        if self.hw.sense_clipped() {
            self.core.sense_clipped();
        }
        let inp = Inputs {
            encoder: self.hw.encoder_raw(),
            current_codes: self.hw.current_codes(),
            since_last,
        };
        // The supply divider's conversion, for thread mode (`comms::IrqLink::supply_code`).
        self.hw.supply_start();
        // A buffer the DMA has begun to overwrite (a single buffer: the step started so late
        // that the next sequence is under way) is not a reading.
        if self.hw.sense_stale() {
            self.core.sense_stale();
        }
        // The exchange with nothing masked (`irq::LoopShared`): the status built and a
        // report copied here hold off neither thread mode's users of the mailbox (they cannot
        // run meanwhile anyway) nor the deadman.
        // SAFETY: in the control interrupt.
        let out = self.core.step(inp, |status, h| unsafe {
            MAILBOX.in_loop(|m| m.try_borrow_mut().ok()?.exchange(status, h))
        });
        if let Some((psc, arr)) = out.timing {
            self.hw.set_bridge(0, 0);
            self.hw.set_pwm_timing(psc, arr);
        }
        self.hw.set_bridge(out.compare.0, out.compare.1);
        // The deadline: the compare values written before the update they are for (the
        // counter's bottom, where the preloaded values take effect, RM0090 §17.3.9), not only
        // a step within its length: a step that started late and ends past the update leaves
        // the bridge a period on the old duty.
        let late = drive::past_update(phase0, self.hw.pwm_phase());
        if let Some(s) = out.sample {
            // A full queue drops the sample: the loop never waits for the comms side.
            let _ = self.telemetry.enqueue(s);
        }
        let cycles = cortex_m::peripheral::DWT::cycle_count().wrapping_sub(t0);
        if self.core.finish(cycles, late) {
            self.hw.set_bridge(0, 0);
        }
    }
}

/// Called by the control interrupt with the interrupt's own slot for the loop
/// (a `static mut` of the handler, reached from nowhere else): the loop is taken from the
/// hand-off on the first call, then owned there.
#[inline(always)]
pub fn on_sample(slot: &mut Option<&'static mut Loop>) {
    if slot.is_none()
        // SAFETY: called by the control interrupt alone.
        && let Some(l) = unsafe { HANDOFF.in_loop(|h| h.try_borrow_mut().ok()?.take()) }
    {
        // A reference: nothing is dropped here, so no drop glue of the loop's drivers (which
        // take the global critical section) is reachable from this interrupt (`cargo xtask
        // check-elf` looks).
        *slot = Some(l);
    }
    match slot {
        Some(l) => l.step(),
        // Not handed over yet: keep the bridge off and the flag clear.
        None => crate::board::idle_sample(),
    }
}

// The interrupt handlers of the control path live here, beside the loop they run: `board.rs`
// sets up their hardware and priorities (`start_control`) and never calls into this module.

/// The control interrupt: the current samples of this PWM period are in — or the sense DMA
/// failed, which switches the bridge off for good.
#[interrupt]
fn DMA2_STREAM0() {
    static mut LOOP: Option<&'static mut Loop> = None;
    let error = sense::dma_error(pac::DMA2);
    if error != Stall::None {
        sense::ack(pac::DMA2);
        trip(error);
        return;
    }
    on_sample(LOOP);
}

/// The deadman, once per PWM period at TIM8's update (the counter's bottom, before the
/// period's step): two periods without a step switch the bridge off (gms-core's
/// `drive::Deadman`); after a trip the update interrupt is switched off.
#[interrupt]
fn TIM8_UP_TIM13() {
    static mut DEADMAN: Deadman = Deadman::new();
    if pwm::deadman_tick(pac::TIM8, DEADMAN, steps()) {
        trip(Stall::NoStep);
    }
}

/// The sense ADC overran: the bridge off for good, the interrupt off (its flag cleared).
#[interrupt]
fn ADC() {
    if sense::adc_overrun(pac::ADC1) != Stall::None {
        trip(Stall::AdcOverrun);
    }
}
