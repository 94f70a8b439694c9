//! Board descriptions as plain numbers, checked on the host: the STM32F4 clock tree a board
//! sets up and its memory map. The firmware's board modules describe themselves with these;
//! `tests/tests/boards.rs` checks every board against the chip's limits, so a board whose
//! numbers disagree (a timer clock typed by hand, a store outside the flash) fails a test
//! instead of a bring-up.

use core::ops::Range;

/// An STM32F4 clock tree (RM0090 §6, RM0390 §6): HSE → PLL (M, N, P, Q) → SYSCLK → AHB →
/// APB1/APB2, as the firmware hands it to embassy-stm32's RCC set-up.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct F4Clocks {
    /// External clock \[Hz\].
    pub hse_hz: u32,
    /// True when the HSE is an external clock signal (bypass), false for a crystal.
    pub hse_bypass: bool,
    /// PLL input divider M [-].
    pub pll_m: u32,
    /// PLL multiplier N [-].
    pub pll_n: u32,
    /// PLL system-clock divider P [-] (2, 4, 6 or 8).
    pub pll_p: u32,
    /// PLL 48 MHz divider Q [-].
    pub pll_q: u32,
    /// AHB prescaler [-] (1, 2, 4, …, 512).
    pub ahb_div: u32,
    /// APB1 prescaler [-] (1, 2, 4, 8, 16).
    pub apb1_div: u32,
    /// APB2 prescaler [-] (1, 2, 4, 8, 16).
    pub apb2_div: u32,
}

/// The limits of one STM32F4 part (its datasheet's "general operating conditions").
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct F4Limits {
    /// Highest SYSCLK/HCLK \[Hz\].
    pub sysclk_max: u32,
    /// Highest APB1 clock \[Hz\].
    pub pclk1_max: u32,
    /// Highest APB2 clock \[Hz\].
    pub pclk2_max: u32,
    /// The part's DEV_ID in DBGMCU_IDCODE (RM0090 §38.6.1, RM0390 §33.6.1).
    pub dev_id: u32,
}

/// STM32F405/407 (DS8626): 168 MHz, APB1 42 MHz, APB2 84 MHz.
pub const F405_LIMITS: F4Limits = F4Limits {
    sysclk_max: 168_000_000,
    pclk1_max: 42_000_000,
    pclk2_max: 84_000_000,
    dev_id: 0x413,
};

/// STM32F446 (DS10693): 180 MHz, APB1 45 MHz, APB2 90 MHz.
pub const F446_LIMITS: F4Limits = F4Limits {
    sysclk_max: 180_000_000,
    pclk1_max: 45_000_000,
    pclk2_max: 90_000_000,
    dev_id: 0x421,
};

impl F4Clocks {
    /// The PLL's input (HSE / M) \[Hz\]; RM0090 asks 1-2 MHz (2 MHz for less jitter).
    pub const fn pll_in_hz(&self) -> u32 {
        self.hse_hz / self.pll_m
    }

    /// The PLL's VCO (input × N) \[Hz\]; 100-432 MHz.
    pub const fn vco_hz(&self) -> u32 {
        self.pll_in_hz() * self.pll_n
    }

    /// SYSCLK (VCO / P) \[Hz\].
    pub const fn sysclk_hz(&self) -> u32 {
        self.vco_hz() / self.pll_p
    }

    /// The 48 MHz clock of USB OTG FS (VCO / Q) \[Hz\].
    pub const fn usb_hz(&self) -> u32 {
        self.vco_hz() / self.pll_q
    }

    /// HCLK (SYSCLK / AHB prescaler) \[Hz\]: the CPU and the DWT cycle counter.
    pub const fn hclk_hz(&self) -> u32 {
        self.sysclk_hz() / self.ahb_div
    }

    /// APB1 \[Hz\].
    pub const fn pclk1_hz(&self) -> u32 {
        self.hclk_hz() / self.apb1_div
    }

    /// APB2 \[Hz\].
    pub const fn pclk2_hz(&self) -> u32 {
        self.hclk_hz() / self.apb2_div
    }

    /// The clock of the timers on APB1 (TIM2-5, …) \[Hz\]: twice PCLK1 when the APB1
    /// prescaler is not 1 (RM0090 §6.2, TIMPRE = 0).
    pub const fn tim_apb1_hz(&self) -> u32 {
        if self.apb1_div == 1 {
            self.pclk1_hz()
        } else {
            2 * self.pclk1_hz()
        }
    }

    /// The clock of the timers on APB2 (TIM1, TIM8, …) \[Hz\].
    pub const fn tim_apb2_hz(&self) -> u32 {
        if self.apb2_div == 1 {
            self.pclk2_hz()
        } else {
            2 * self.pclk2_hz()
        }
    }

    /// The ADC clock as embassy-stm32 0.6 sets it (`adc/v2.rs` `from_pclk2`: with
    /// `raw = (PCLK2 - 1) / 36 MHz`, the prescaler is 2 for raw 0-1, 4 for 2-3, 6 for 4-5, 8
    /// for 6-7) \[Hz\]; 0 where embassy would panic (raw above 7).
    pub const fn adc_hz(&self) -> u32 {
        let p = self.pclk2_hz();
        let raw = p.saturating_sub(1) / 36_000_000;
        if raw > 7 {
            return 0;
        }
        p / (2 * (raw / 2 + 1))
    }

    /// Whether the tree is valid for a part with limits `lim`; the error says what is not.
    pub const fn check(&self, lim: &F4Limits) -> Result<(), &'static str> {
        if self.pll_m < 2 || self.pll_m > 63 || self.hse_hz == 0 {
            return Err("PLL M outside 2..=63");
        }
        if self.pll_in_hz() < 1_000_000 || self.pll_in_hz() > 2_000_000 {
            return Err("PLL input outside 1-2 MHz");
        }
        if self.pll_n < 50 || self.pll_n > 432 {
            return Err("PLL N outside 50..=432");
        }
        if self.vco_hz() < 100_000_000 || self.vco_hz() > 432_000_000 {
            return Err("VCO outside 100-432 MHz");
        }
        if !matches!(self.pll_p, 2 | 4 | 6 | 8) {
            return Err("PLL P not 2, 4, 6 or 8");
        }
        if self.pll_q < 2 || self.pll_q > 15 {
            return Err("PLL Q outside 2..=15");
        }
        if self.vco_hz() % self.pll_q != 0 || self.usb_hz() != 48_000_000 {
            return Err("USB clock not exactly 48 MHz");
        }
        if !self.ahb_div.is_power_of_two()
            || self.ahb_div > 512
            || self.ahb_div == 32
            || !self.apb1_div.is_power_of_two()
            || self.apb1_div > 16
            || !self.apb2_div.is_power_of_two()
            || self.apb2_div > 16
        {
            return Err("a bus prescaler is not one the RCC has");
        }
        if self.sysclk_hz() > lim.sysclk_max {
            return Err("SYSCLK above the part's maximum");
        }
        if self.pclk1_hz() > lim.pclk1_max {
            return Err("APB1 above the part's maximum");
        }
        if self.pclk2_hz() > lim.pclk2_max {
            return Err("APB2 above the part's maximum");
        }
        if self.adc_hz() == 0 {
            return Err("no ADC prescaler brings PCLK2 to 36 MHz");
        }
        Ok(())
    }
}

/// Where a board's firmware and parameter store live in its flash, and its RAM.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MemoryMap {
    /// The chip's flash \[bytes\].
    pub flash_len: u32,
    /// The flash the firmware may use, from the start \[bytes\] (`memory.x` FLASH).
    pub app_len: u32,
    /// The RAM the firmware uses \[bytes\] (`memory.x` RAM; the F4's main SRAM).
    pub ram_len: u32,
    /// The parameter store's sectors, as offsets from the flash start \[bytes\].
    pub store: Range<u32>,
    /// The store's sector size \[bytes\].
    pub store_sector: u32,
}

impl MemoryMap {
    /// Whether the map holds together: the store is whole sectors (at least two, which
    /// sequential-storage needs to move a record), inside the flash and after the firmware.
    pub const fn check(&self) -> Result<(), &'static str> {
        let (start, end) = (self.store.start, self.store.end);
        if self.store_sector == 0 || start % self.store_sector != 0 || end % self.store_sector != 0
        {
            return Err("the store is not whole sectors");
        }
        if end <= start || (end - start) / self.store_sector < 2 {
            return Err("the store needs two sectors or more");
        }
        if end > self.flash_len {
            return Err("the store ends beyond the flash");
        }
        if self.app_len > start {
            return Err("the firmware's flash overlaps the store");
        }
        if self.app_len == 0 || self.ram_len == 0 {
            return Err("no flash or no RAM for the firmware");
        }
        Ok(())
    }
}

/// The stack guard's size \[bytes\]: an MPU region with no access at the bottom of the stack
/// (the firmware's `f4_regs::mpu`). It must be larger than any single step of the stack
/// pointer (a function's frame, `sub sp`), or an overflow could step over it: `cargo xtask
/// check-elf` checks the image's largest against it. 8 KiB: the MPU aligns a region to its
/// size, so a 16 KiB guard sat at 0x20018000 above 87 KiB of statics and left 16 KiB of
/// stack, less than the image needs (a `set` while the loop runs: some 16 KiB, measured on
/// the image by `rehost check`); at 8 KiB it sits at 0x20016000 and leaves 32 KiB.
pub const STACK_GUARD_BYTES: u32 = 8192;

/// The brown-out reset level the boards need, as FLASH_OPTCR.BOR_LEV holds it: 00, level 3,
/// the reset held below about 2.7 V (RM0090 §5.2.2 "Brownout reset (BOR)": level 3 for
/// supplies of 2.70 to 3.60 V; §3.9.10 FLASH_OPTCR: BOR_LEV 00 level 3, 01 level 2, 10 level
/// 1, 11 off, the factory value). Flash programming at ×32 (the parameter store) and 168 MHz
/// at 5 wait states are specified from 2.7 V only (§3.5.1 table 10, §3.6.2 table 9): without
/// it a slow power-down with the motor supply still up runs the core out of its
/// specification, the bridge live. RM0390 (the F446) lays the field out alike.
pub const BOR_LEV_2V7: u8 = 0b00;

/// Why a board whose brown-out reset is not at [`BOR_LEV_2V7`] refuses to drive (its
/// `enable`'s `err 8` reason).
pub const NO_BROWN_OUT_RESET: &str =
    "brown-out reset not at 2.7 V (option bytes): see docs/bring-up.md, the bridge stays off";

/// Whether the flash prefetch buffer may be switched on, from the part's `DBGMCU_IDCODE`
/// (RM0090 §38.6.1: DEV_ID in bits 11:0, REV_ID in bits 31:16). The STM32F405/407/415/417
/// (DEV_ID 0x413) of revision A (REV_ID 0x1000) do not support it: ST's own clock set-up
/// (STM32CubeF4's examples, `SystemClock_Config`) enables it only from revision Z (0x1001)
/// up. Every other part and revision may.
pub const fn f4_prefetch_allowed(idcode: u32) -> bool {
    let dev_id = idcode & 0xFFF;
    let rev_id = idcode >> 16;
    !(dev_id == 0x413 && rev_id == 0x1000)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn prefetch_only_where_the_part_supports_it() {
        // STM32F405 revision A: no; Z (0x1001), 1 (0x1007) and later: yes.
        assert!(!f4_prefetch_allowed(0x1000_6413));
        assert!(f4_prefetch_allowed(0x1001_6413));
        assert!(f4_prefetch_allowed(0x1007_6413));
        // The F446 (DEV_ID 0x421) of revision A: yes.
        assert!(f4_prefetch_allowed(0x1000_6421));
    }
}
