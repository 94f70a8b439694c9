//! A stack guard: the MPU's region 0, no access at all, at the bottom of the stack's region
//! (the stack grows down towards the statics), so that a stack that overflows faults on its
//! first access to the guard instead of overwriting the statics.
//!
//! The fault comes as a MemManage fault (enabled, at the top priority, above every interrupt
//! the firmware uses), or as a HardFault where it cannot preempt (a higher or equal priority
//! running, or PRIMASK set). Its handler cannot use the stack it was entered on — the
//! exception's own stacking may have failed (MSTKERR) and left SP inside the guard — so both
//! handlers are a few instructions of assembly ([`crate::stack_guard_fault_handlers`]): MSP back to the top
//! of the stack's region (whatever was on it is abandoned: the handler never returns), then
//! the binary's `gms_fault_stop`, which switches the bridge off and waits for the watchdog.
//!
//! Registers (ARMv7-M ARM B3.5, PM0214 §4.2): MPU_CTRL, MPU_RNR, MPU_RBAR, MPU_RASR from
//! 0xE000ED94; SHPR1 (MemManage's priority, its byte 0) at 0xE000ED18, SHCSR (MEMFAULTENA,
//! bit 16) at 0xE000ED24.

/// The core's MPU and SCB, as pointers (host tests lay them on memory).
#[derive(Clone, Copy, Debug)]
pub struct CoreRegs {
    /// MPU_TYPE (0xE000ED90); CTRL, RNR, RBAR and RASR follow at +4 … +16.
    pub mpu: *mut u32,
    /// The SCB's base (0xE000ED00); SHPR1 at +0x18, SHCSR at +0x24.
    pub scb: *mut u32,
}

impl CoreRegs {
    /// The Cortex-M4's own.
    pub const CORE: CoreRegs = CoreRegs {
        mpu: 0xE000_ED90 as *mut u32,
        scb: 0xE000_ED00 as *mut u32,
    };
}

/// MPU_RASR.XN: no instruction fetch.
pub const RASR_XN: u32 = 1 << 28;
/// MPU_RASR.ENABLE.
pub const RASR_ENABLE: u32 = 1;
/// MPU_CTRL.ENABLE.
pub const CTRL_ENABLE: u32 = 1;
/// MPU_CTRL.PRIVDEFENA: the default memory map everywhere no region covers.
pub const CTRL_PRIVDEFENA: u32 = 1 << 2;
/// SHCSR.MEMFAULTENA.
pub const SHCSR_MEMFAULTENA: u32 = 1 << 16;

/// Where the guard goes: `size` bytes (a power of two from 32) at the first multiple of
/// `size` at or above `stack_end` (an MPU region is aligned to its size), and the stack that
/// is left above it \[bytes\]; `None` if that leaves less than `min_stack`.
pub const fn guard_region(
    stack_end: u32,
    stack_start: u32,
    size: u32,
    min_stack: u32,
) -> Option<(u32, u32)> {
    if size < 32 || !size.is_power_of_two() {
        return None;
    }
    let base = match stack_end.checked_add(size - 1) {
        Some(v) => v & !(size - 1),
        None => return None,
    };
    let top = match base.checked_add(size) {
        Some(t) => t,
        None => return None,
    };
    if top > stack_start || stack_start - top < min_stack {
        return None;
    }
    Some((base, stack_start - top))
}

/// MPU_RASR for a guard of `size` bytes (a power of two from 32): SIZE = log2(size) − 1,
/// AP = 000 (no access, privileged or not), XN, enabled.
pub const fn guard_rasr(size: u32) -> u32 {
    let log2 = size.trailing_zeros();
    RASR_XN | ((log2 - 1) << 1) | RASR_ENABLE
}

/// Sets the guard up as region 0 (`base` aligned to `size`, see [`guard_region`]), MemManage
/// at the top priority and enabled, and the MPU on with the default map elsewhere
/// (PRIVDEFENA) and off in HardFault (HFNMIENA = 0).
///
/// # Safety
///
/// `r` must point at the core's MPU and SCB (or at memory laid out like them); nothing may
/// use the guard's memory from then on.
pub unsafe fn enable_stack_guard(r: CoreRegs, base: u32, size: u32) {
    // SAFETY: the caller's promise; word accesses at the registers' offsets.
    unsafe {
        let w = |p: *mut u32, off: usize, v: u32| core::ptr::write_volatile(p.add(off / 4), v);
        // The MPU off while its region is written.
        w(r.mpu, 0x04, 0);
        w(r.mpu, 0x08, 0); // RNR: region 0
        w(r.mpu, 0x0C, base); // RBAR: VALID = 0, the region of RNR
        w(r.mpu, 0x10, guard_rasr(size));
        // MemManage's priority (SHPR1 byte 0) at 0, the top; the fault enabled.
        core::ptr::write_volatile((r.scb as *mut u8).add(0x18), 0);
        let shcsr = r.scb.add(0x24 / 4);
        core::ptr::write_volatile(shcsr, core::ptr::read_volatile(shcsr) | SHCSR_MEMFAULTENA);
        w(r.mpu, 0x04, CTRL_PRIVDEFENA | CTRL_ENABLE);
        // The new map for every access after this (ARMv7-M ARM B3.5.2: DSB, ISB).
        #[cfg(target_arch = "arm")]
        core::arch::asm!("dsb", "isb", options(nostack, preserves_flags));
    }
}

/// The fault handlers (see the module's notes), for the binary that invokes it once: MSP back
/// to `_stack_start` (cortex-m-rt's linker symbol, the top of the stack's region), then
/// `gms_fault_stop` (the binary's: `#[unsafe(no_mangle)] extern "C" fn() -> !`). They replace
/// cortex-m-rt's defaults (its link.x PROVIDEs `HardFault` and `MemoryManagement` only where
/// nothing defines them).
#[macro_export]
macro_rules! stack_guard_fault_handlers {
    () => {
        core::arch::global_asm!(
            ".section .HardFault.gms, \"ax\", %progbits",
            ".global HardFault",
            ".global MemoryManagement",
            ".type HardFault, %function",
            ".type MemoryManagement, %function",
            ".thumb_func",
            "HardFault:",
            ".thumb_func",
            "MemoryManagement:",
            "ldr r0, =_stack_start",
            "msr msp, r0",
            "isb",
            "b gms_fault_stop",
            ".ltorg",
            ".size HardFault, . - HardFault",
        );
    };
}
