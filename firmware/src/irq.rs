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
//! control interrupt shares with thread mode is a [`LoopShared`]: thread mode reaches it with
//! BASEPRI raised to [`CONTROL`], which excludes the control interrupt and everything below
//! it, so that the loop and the thread never see it half-written, and leaves the deadman
//! free; the control interrupt, the most urgent of its users, reaches it with nothing masked
//! (nothing at the deadman's level, nor the NMI, touches it), so a copy there (a frequency
//! response's 136-byte report) delays nothing. In thread mode the lock holds the loop off
//! for the copy (`rehost check` measures it: "the control interrupt held off").

use core::cell::RefCell;

use critical_section::RawRestoreState;
use embassy_stm32::interrupt::Priority;

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

/// Data shared by the control interrupt and the contexts below it (thread mode), and by
/// nothing at the deadman's level or the NMI: the control interrupt, the most urgent of its
/// users, reaches it without masking anything ([`LoopShared::in_loop`]); the others with the
/// control interrupt and everything below it masked ([`LoopShared::lock`]: BASEPRI raised to
/// [`CONTROL`], the deadman left free). The priority ceiling protocol, for two levels.
pub struct LoopShared<T>(RefCell<T>);

// SAFETY: single core. The data is reached only through `lock` (never from the deadman or
// the NMI: `cargo xtask check-elf` finds any BASEPRI access in their chains, and in the
// control interrupt's) and `in_loop` (only from the control interrupt). Under `lock` no user
// can preempt the holder: BASEPRI at CONTROL holds off every exception whose group priority is
// not more urgent (ARMv7-M ARM B1.5.4), and the only more urgent ones are the deadman and the
// NMI. In the control interrupt no user can preempt it either. So the `RefCell` is never
// reached from two contexts at once.
unsafe impl<T: Send> Sync for LoopShared<T> {}

impl<T> LoopShared<T> {
    /// `value`, shared.
    pub const fn new(value: T) -> Self {
        LoopShared(RefCell::new(value))
    }

    /// `f` with the data, the control interrupt and everything below it masked: from thread
    /// mode, or an interrupt below the loop (never from the control interrupt, the deadman
    /// or the NMI).
    pub fn lock<R>(&self, f: impl FnOnce(&RefCell<T>) -> R) -> R {
        let old = cortex_m::register::basepri::read();
        // Both writes are compiler barriers and end with an ISB (cortex-m 0.7.10,
        // `register::basepri_max`, `register::basepri`): `f`'s accesses stay between them,
        // and the new mask acts from the next instruction. BASEPRI_MAX only raises the mask,
        // so inside the global critical section (P2) this raises it to P1, and the restore
        // puts P2 back.
        cortex_m::register::basepri_max::write(CONTROL as u8);
        let r = f(&self.0);
        // SAFETY: restores the mask read above.
        unsafe { cortex_m::register::basepri::write(old) };
        r
    }

    /// `f` with the data, nothing masked.
    ///
    /// # Safety
    ///
    /// Only from the control interrupt, at [`CONTROL`]: no other user of the data can
    /// preempt it.
    pub unsafe fn in_loop<R>(&self, f: impl FnOnce(&RefCell<T>) -> R) -> R {
        f(&self.0)
    }
}
