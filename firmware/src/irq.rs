//! Interrupt priorities and the two kinds of critical section.
//!
//! Priorities (4 bits on the F405, 0 the most urgent): the control interrupt alone at
//! [`CONTROL`]; embassy's time driver (TIM4) and the DMA streams embassy enables at P2; USB
//! at P3; the executor in thread mode. Nothing can preempt the loop, and the loop preempts
//! everything.
//!
//! The global critical section (the `critical-section` crate, which embassy, embassy-sync's
//! `CriticalSectionRawMutex` and defmt-rtt use) raises BASEPRI to P1 instead of masking every
//! interrupt: it excludes everything but the control interrupt, so no driver, task or log
//! line can hold the loop off (ARMv7-M ARM B1.4.3, BASEPRI_MAX only raises the mask; the F405
//! implements the top 4 priority bits, PM0214 §4.3.7). Data the control interrupt shares with
//! thread mode is behind [`IrqOffRawMutex`] instead (PRIMASK: everything masked, held for a
//! copy of a few hundred cycles), so that the loop and the thread never see it half-written.

use critical_section::RawRestoreState;
use embassy_stm32::interrupt::Priority;
use embassy_sync::blocking_mutex::raw::RawMutex;

/// The control interrupt's priority.
pub const CONTROL: Priority = Priority::P0;
/// The time driver's and the DMA streams' priority (below the loop).
pub const DRIVERS: Priority = Priority::P2;
/// USB's priority.
pub const USB: Priority = Priority::P3;

/// The global critical section's mask: priority P1 and below (BASEPRI holds the priority in
/// its top 4 bits: P1 = 0x10 with embassy-stm32's `prio-bits-4` for the F4).
const MASK: u8 = Priority::P1 as u8;
const _: () = assert!(MASK == 0x10 && CONTROL as u8 == 0);

struct BasepriCriticalSection;
critical_section::set_impl!(BasepriCriticalSection);

// SAFETY: single core; BASEPRI_MAX only ever raises the mask, and release restores the value
// read at acquire, so nesting (in thread mode or in any interrupt) restores correctly. Every
// interrupt that can run inside the section (the control interrupt) shares data with the
// rest only through `IrqOffRawMutex`.
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
