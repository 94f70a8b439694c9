//! Code run from SRAM: a load image copied into SRAM1, SRAM1 then mapped at 0 by SYSCFG, so
//! that the core fetches it through the I-bus without the flash's wait states.
//!
//! RM0090 §9.2.1 (RM0390 §8.2.1 for the F446) SYSCFG_MEMRMP: MEM_MODE = 11 maps SRAM1 (112
//! KiB) at 0x0000_0000; it stays at 0x2000_0000 too. §2.4 "Boot configuration": the memory at
//! 0 is then fetched over the I-bus. The vector table is read at VTOR, 0 after reset (PM0214
//! §4.4.4): VTOR is set to the flash's table before the remap, or the next exception would be
//! taken through whatever SRAM holds at 0. SYSCFG's clock (RCC_APB2ENR.SYSCFGEN, §7.3.14) must
//! be on; embassy-stm32's `init` resets SYSCFG (0.6.0 `lib.rs`: `enable_and_reset` of SYSCFG),
//! so the remap is done after it. The barriers: DSB so that the copy and the remap are done,
//! ISB so that no instruction fetched before them runs (ARMv7-M ARM A3.7.3).

use crate::pac;

/// SYSCFG_MEMRMP.MEM_MODE: SRAM1 at 0 (RM0090 §9.2.1).
pub const MEM_MODE_SRAM: u8 = 0b11;

/// SCB_VTOR's offset in the SCB (PM0214 §4.4.4: 0xE000ED08).
const VTOR: usize = 0x08 / 4;

/// What the remap touches: RCC (SYSCFG's clock), SYSCFG, and the SCB (VTOR), as pointers or
/// blocks (host tests lay them on memory).
#[derive(Clone, Copy)]
pub struct RemapRegs {
    /// RCC.
    pub rcc: pac::rcc::Rcc,
    /// SYSCFG.
    pub syscfg: pac::syscfg::Syscfg,
    /// The SCB's base (0xE000ED00).
    pub scb: *mut u32,
}

/// Copies the `words` words at `load` to `sram` (SRAM1's address of the code's place), points
/// VTOR at `vector_table` (the flash's), switches SYSCFG's clock on and maps SRAM1 at 0.
///
/// # Safety
/// `load` must hold `words` readable words, `sram` must have room for them and nothing else
/// may use that room (the linker keeps it out of RAM's sections); no code in it may run before
/// this returns; `vector_table` must be the image's table (128-word aligned, PM0214 §4.4.4).
pub unsafe fn sram_at_zero(
    r: RemapRegs,
    load: *const u32,
    sram: *mut u32,
    words: usize,
    vector_table: u32,
) {
    for i in 0..words {
        // SAFETY: within both ranges (the caller's).
        unsafe { core::ptr::write_volatile(sram.add(i), core::ptr::read_volatile(load.add(i))) };
    }
    // SAFETY: VTOR is the SCB's word at +8 (the caller's block).
    unsafe { core::ptr::write_volatile(r.scb.add(VTOR), vector_table) };
    r.rcc.apb2enr().modify(|w| w.set_syscfgen(true));
    // The clock's enable takes effect after a read back of the register (RM0090 §7.3.14's
    // note on the delay after enabling a peripheral clock: two AHB cycles; the read covers
    // it).
    let _ = r.rcc.apb2enr().read();
    r.syscfg.memrm().modify(|w| w.set_mem_mode(MEM_MODE_SRAM));
    // SAFETY: barriers only.
    #[cfg(target_arch = "arm")]
    unsafe {
        core::arch::asm!("dsb", "isb", options(nostack, preserves_flags));
    }
}
