//! The HSE, the flash accelerator, the flash's erase set-up.

use crate::pac;

/// Starts the HSE (an external clock in bypass, or a crystal) and waits at most
/// `limit_cycles` of `now` (a free-running cycle counter, the DWT's) for HSERDY (RCC_CR,
/// RM0090 §7.3.1: HSEBYP is written while the HSE is off, then HSEON). False, with the HSE
/// switched off again, if it did not come.
pub fn start_hse(
    rcc: pac::rcc::Rcc,
    bypass: bool,
    mut now: impl FnMut() -> u32,
    limit_cycles: u32,
) -> bool {
    rcc.cr().modify(|w| w.set_hseon(false));
    rcc.cr().modify(|w| w.set_hsebyp(bypass));
    rcc.cr().modify(|w| w.set_hseon(true));
    let t0 = now();
    while !rcc.cr().read().hserdy() {
        if now().wrapping_sub(t0) > limit_cycles {
            rcc.cr().modify(|w| w.set_hseon(false));
            return false;
        }
    }
    true
}

/// Switches the clock security system on (RCC_CR.CSSON, RM0090 §7.3.1; §6.2.7): should the
/// HSE fail while it clocks the system, the HSE is switched off, the system clock falls back
/// to the HSI, and an NMI is raised (RCC_CIR.CSSF), which cannot be masked: the firmware's
/// NMI handler switches the bridge off. Call with the HSE running (CSS is ignored otherwise).
pub fn enable_css(rcc: pac::rcc::Rcc) {
    rcc.cr().modify(|w| w.set_csson(true));
}

/// Whether the clock security system raised the NMI (RCC_CIR.CSSF, RM0090 §7.3.4); the flag
/// cleared (CSSC), as the NMI handler must, or the NMI comes again at once.
pub fn css_ack(rcc: pac::rcc::Rcc) -> bool {
    let fired = rcc.cir().read().cssf();
    if fired {
        rcc.cir().modify(|w| w.set_cssc(true));
    }
    fired
}

/// Switches the flash accelerator on (RM0090 §3.5.2, FLASH_ACR): the instruction and data
/// caches, and the prefetch buffer where the part allows it — `idcode` is DBGMCU_IDCODE as
/// read, `dev_id` the part's DEV_ID (a code that does not read as this part, or an F405/407 of
/// revision A, keeps the prefetch off: gms-core's `hw::f4_prefetch_allowed`). The caches are
/// empty after reset, so no ICRST/DCRST is needed first. Returns whether the prefetch is on.
pub fn flash_accelerator(flash: pac::flash::Flash, idcode: u32, dev_id: u32) -> bool {
    let prefetch = (idcode & 0xFFF) == dev_id && gms_core::boards::hw::f4_prefetch_allowed(idcode);
    flash.acr().modify(|w| {
        w.set_prften(prefetch);
        w.set_icen(true);
        w.set_dcen(true);
    });
    prefetch
}

/// The flash's key sequence (RM0090 §3.5.1, FLASH_KEYR).
pub const FLASH_KEYS: [u32; 2] = [0x4567_0123, 0xCDEF_89AB];

/// Sets the flash's program/erase parallelism to ×32 for the erase that follows
/// (FLASH_CR.PSIZE = 10, RM0090 §3.9.7; allowed from 2.7 V, §3.6.2 table 9), leaving STRT,
/// which starts the erase, alone. CR can only be written unlocked: the key sequence is written
/// only while LOCK is set (a key written to an unlocked CR is a wrong sequence and locks CR
/// until reset), as embassy's `unlock` does; embassy-stm32 0.6's erase then finds CR
/// unlocked, only *modifies* it (keeping PSIZE: `flash/f4.rs`, `blocking_erase_sector`) and
/// locks it again when done.
pub fn erase_at_x32(flash: pac::flash::Flash) {
    if flash.cr().read().lock() {
        for key in FLASH_KEYS {
            flash.keyr().write_value(key);
        }
    }
    flash
        .cr()
        .modify(|w| w.set_psize(pac::flash::vals::Psize::PSIZE32));
}

/// FLASH_OPTKEYR's key sequence, which unlocks FLASH_OPTCR (RM0090 §3.7.2).
pub const OPTION_KEYS: [u32; 2] = [0x0819_2A3B, 0x4C5D_6E7F];

/// What [`brown_out_reset`] found and did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BrownOut {
    /// The option bytes already held the level.
    Set,
    /// They did not; programmed now.
    Programmed,
    /// They did not and could not be programmed (the flash stayed busy past the bound, the
    /// option register stayed locked, or it read back otherwise).
    Failed,
}

/// Puts the brown-out reset at `level` (FLASH_OPTCR.BOR_LEV, gms-core's
/// `hw::BOR_LEV_2V7`) in the option bytes, if they do not hold it already, by RM0090 §3.7.2
/// "Modifying user option bytes": no flash operation going on (SR.BSY), OPTCR unlocked by
/// its keys, the value written with only BOR_LEV changed (the whole register is programmed:
/// read protection, write protection and the watchdog's options as read), OPTSTRT, BSY
/// waited for, OPTCR locked again. Each wait is bounded by `limit` cycles of `now` (the DWT
/// cycle counter). RM0390 §3.7.2 is the same on the F446.
pub fn brown_out_reset(
    flash: pac::flash::Flash,
    level: u8,
    now: impl Fn() -> u32,
    limit: u32,
) -> BrownOut {
    if flash.optcr().read().bor_lev() == level {
        return BrownOut::Set;
    }
    let idle = || {
        let t0 = now();
        while flash.sr().read().bsy() {
            if now().wrapping_sub(t0) > limit {
                return false;
            }
        }
        true
    };
    if !idle() {
        return BrownOut::Failed;
    }
    if flash.optcr().read().optlock() {
        for key in OPTION_KEYS {
            flash.optkeyr().write_value(key);
        }
    }
    flash.optcr().modify(|w| w.set_bor_lev(level));
    flash.optcr().modify(|w| w.set_optstrt(true));
    let done = idle();
    flash.optcr().modify(|w| w.set_optlock(true));
    if done && flash.optcr().read().bor_lev() == level {
        BrownOut::Programmed
    } else {
        BrownOut::Failed
    }
}

/// Flushes the flash data cache: DCEN off, a DCRST pulse, DCEN as it was (RM0090 §3.5.2: the
/// cache is reset only while disabled).
pub fn flush_data_cache(flash: pac::flash::Flash) {
    let on = flash.acr().read().dcen();
    flash.acr().modify(|w| w.set_dcen(false));
    flash.acr().modify(|w| w.set_dcrst(true));
    flash.acr().modify(|w| w.set_dcrst(false));
    flash.acr().modify(|w| w.set_dcen(on));
}

/// Whether the last reset was a watchdog's (RCC_CSR: IWDGRSTF or WWDGRSTF, RM0090 §7.3.21),
/// the reset flags then cleared for the next time (RMVF).
pub fn watchdog_reset(rcc: pac::rcc::Rcc) -> bool {
    let csr = rcc.csr().read();
    let by_watchdog = csr.wdgrstf() || csr.wwdgrstf();
    rcc.csr().modify(|w| w.set_rmvf(true));
    by_watchdog
}

/// A debug halt stops TIM8 — a stopped advanced timer's outputs are disabled, forced to their
/// idle level with OSSI set (RM0090 §17.3.21 "Debug mode", §38.16.5 DBGMCU_APB2_FZ
/// DBG_TIM8_STOP): the bridge coasts while the core is halted — and the independent watchdog
/// (DBGMCU_APB1_FZ DBG_IWDG_STOP, §38.16.4): a breakpoint does not reset the MCU.
pub fn freeze_in_debug(dbgmcu: pac::dbgmcu::Dbgmcu) {
    dbgmcu.apb2fzr().modify(|w| w.set_tim8(true));
    dbgmcu.apb1fzr().modify(|w| w.set_iwdg(true));
}
