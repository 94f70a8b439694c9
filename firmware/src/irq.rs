//! Interrupt priorities and the two kinds of critical section.
//!
//! Priorities (4 bits on the F4, 0 the most urgent): the deadman alone at [`DEADMAN`] (TIM8's
//! update once per PWM period, and the ADC's overrun: `board.rs`, gms-core's
//! `drive::Deadman`); the control interrupt at [`CONTROL`]; embassy's time driver (TIM4) and
//! the DMA streams embassy enables at [`DRIVERS`]; the host link at [`LINK`]; the executor in
//! thread mode. Nothing but the deadman can preempt the loop, and the deadman can preempt the
//! loop: a loop that stops running, however, cannot hold it off.
//!
//! The global critical section (the `critical-section` crate, which embassy, embassy-sync's
//! `CriticalSectionRawMutex` and defmt-rtt use) raises BASEPRI to [`MASK`] instead of masking
//! every interrupt: it excludes everything but the deadman and the control interrupt, so no
//! driver, task or log line can hold the loop off (ARMv7-M ARM B1.4.3, BASEPRI_MAX only
//! raises the mask; the F4 implements the top 4 priority bits, PM0214 §4.3.7). Data the
//! control interrupt shares with thread mode is behind [`IrqOffRawMutex`] instead (PRIMASK:
//! everything masked, held for a copy of a few hundred cycles, well under a PWM period, so
//! the deadman never sees two periods without a step because of it), so that the loop and
//! the thread never see it half-written.

use critical_section::RawRestoreState;
use embassy_stm32::interrupt::Priority;
use embassy_sync::blocking_mutex::raw::RawMutex;

/// The deadman's priority (above the loop).
pub const DEADMAN: Priority = Priority::P0;
/// The control interrupt's priority.
pub const CONTROL: Priority = Priority::P1;
/// The time driver's and the DMA streams' priority (below the loop).
pub const DRIVERS: Priority = Priority::P3;
/// The host link's priority (USB, or the UART and its DMA streams).
pub const LINK: Priority = Priority::P4;

/// The global critical section's mask: priority P2 and below (BASEPRI holds the priority in
/// its top 4 bits: P2 = 0x20 with embassy-stm32's `prio-bits-4` for the F4).
const MASK: u8 = Priority::P2 as u8;
const _: () = assert!(
    MASK == 0x20
        && (DEADMAN as u8) < (CONTROL as u8)
        && (CONTROL as u8) < MASK
        && MASK <= DRIVERS as u8
        && (DRIVERS as u8) < (LINK as u8)
);

struct BasepriCriticalSection;
critical_section::set_impl!(BasepriCriticalSection);

// SAFETY: single core; BASEPRI_MAX only ever raises the mask, and release restores the value
// read at acquire, so nesting (in thread mode or in any interrupt) restores correctly. Every
// interrupt that can run inside the section (the deadman and the control interrupt) shares
// data with the rest only through `IrqOffRawMutex` or atomics.
unsafe impl critical_section::Impl for BasepriCriticalSection {
    unsafe fn acquire() -> RawRestoreState {
        let old = cortex_m::register::basepri::read();
        // Raising the mask cannot break another critical section.
        cortex_m::register::basepri_max::write(MASK);
        old
    }

    unsafe fn release(old: RawRestoreState) {
        // SAFETY: restores the mask of the matching `acquire`.
        unsafe { cortex_m::register::basepri::write(old) };
    }
}

/// A raw mutex for data shared with the control interrupt: every interrupt masked (PRIMASK)
/// while held.
pub struct IrqOffRawMutex(());

// SAFETY: the lock masks every interrupt on this single core, so `f` runs alone.
unsafe impl RawMutex for IrqOffRawMutex {
    const INIT: Self = IrqOffRawMutex(());

    fn lock<R>(&self, f: impl FnOnce() -> R) -> R {
        cortex_m::interrupt::free(|_| f())
    }
}
