//! RCC, PWR and the flash interface's access control as far as the clock set-up needs them:
//! the ready flags follow their enables, the system clock switch status follows the switch
//! (RM0090 §7.3.1-7.3.3, RM0390 §6.3.1-6.3.3; PWR: RM0090 §5.4, RM0390 §5.4 for the F446's
//! over-drive), the reset flags in RCC_CSR.

/// The RCC's registers (offsets from 0x40023800).
#[derive(Debug, Clone)]
pub struct Rcc {
    regs: [u32; 0x90 / 4],
    /// The HSE's source is gone (a dead crystal, the ST-LINK's clock missing): HSEON no
    /// longer brings HSERDY. Kept across resets (the hardware's fault, not the chip's state).
    pub hse_dead: bool,
}

/// RCC_CSR.IWDGRSTF (RM0090 §7.3.21).
pub const CSR_IWDGRSTF: u32 = 1 << 29;
/// RCC_CSR.PORRSTF.
pub const CSR_PORRSTF: u32 = 1 << 27;
/// RCC_CSR.PINRSTF.
pub const CSR_PINRSTF: u32 = 1 << 26;
/// RCC_CSR.SFTRSTF.
pub const CSR_SFTRSTF: u32 = 1 << 28;

impl Rcc {
    /// The registers at a power-on reset (CR: HSION, HSIRDY; CSR: PORRSTF, PINRSTF).
    pub fn new() -> Rcc {
        let mut regs = [0; 0x90 / 4];
        regs[0] = 0x0000_0083;
        regs[1] = 0x2400_3010; // PLLCFGR (0x04)
        regs[0x74 / 4] = CSR_PORRSTF | CSR_PINRSTF;
        Rcc {
            regs,
            hse_dead: false,
        }
    }

    /// The state after a system reset of cause `flag` (RCC_CSR's flags are kept until RMVF;
    /// the other registers go back to their reset values).
    pub fn reset(&mut self, flag: u32) {
        let csr = self.regs[0x74 / 4] | flag | CSR_PINRSTF;
        self.power_on();
        self.regs[0x74 / 4] = csr;
    }

    /// The state after a power-on reset (RCC_CSR: PORRSTF and PINRSTF only); a dead HSE stays
    /// dead (the board's fault, not the chip's state).
    pub fn power_on(&mut self) {
        let dead = self.hse_dead;
        *self = Rcc::new();
        self.hse_dead = dead;
    }

    /// Reads the register at `off`.
    pub fn read(&self, off: u32) -> u32 {
        self.regs.get(off as usize / 4).copied().unwrap_or(0)
    }

    /// Writes the register at `off`.
    pub fn write(&mut self, off: u32, value: u32) {
        match off {
            // CR: HSIRDY (1) follows HSION (0), HSERDY (17) HSEON (16), PLLRDY (25) PLLON (24),
            // PLLI2SRDY (27) PLLI2SON (26), PLLSAIRDY (29) PLLSAION (28).
            0x00 => {
                let mut v = value
                    & 0x15FF_FFF9
                    & !((1 << 1) | (1 << 17) | (1 << 25) | (1 << 27) | (1 << 29));
                for (on, rdy) in [(0, 1), (16, 17), (24, 25), (26, 27), (28, 29)] {
                    if value & (1 << on) != 0 && !(on == 16 && self.hse_dead) {
                        v |= 1 << rdy;
                    }
                }
                // HSEBYP (18) and CSSON (19) kept as written.
                v |= value & ((1 << 18) | (1 << 19));
                self.regs[0] = v;
            }
            // CFGR: SWS (bits 3:2) follows SW (bits 1:0).
            0x08 => self.regs[2] = (value & !0xC) | ((value & 3) << 2),
            // CIR: the enables (bits 8-13) as written; CSSC (bit 23) clears CSSF (bit 7).
            0x0C => {
                let mut v = (self.regs[3] & 0x80) | (value & 0x0000_3F00);
                if value & (1 << 23) != 0 {
                    v &= !0x80;
                }
                self.regs[3] = v;
            }
            // CSR: RMVF (24) clears the reset flags; LSIRDY (1) follows LSION (0).
            0x74 => {
                let flags = if value & (1 << 24) != 0 {
                    0
                } else {
                    self.regs[0x74 / 4] & 0xFE00_0000
                };
                let lsi = if value & 1 != 0 { 3 } else { 0 };
                self.regs[0x74 / 4] = flags | lsi;
            }
            // BDCR: LSERDY (1) follows LSEON (0).
            0x70 => self.regs[0x70 / 4] = value | ((value & 1) << 1),
            _ => {
                if let Some(r) = self.regs.get_mut(off as usize / 4) {
                    *r = value;
                }
            }
        }
    }

    /// The main PLL's 48 MHz output (PLL48CLK, the OTG FS core's clock: RM0090 §7.2, Figure
    /// 21) \[Hz\] with an HSE of `hse_hz`: the PLL on and its source (PLLCFGR.PLLSRC: HSE or
    /// the 16 MHz HSI) divided by PLLM, multiplied by PLLN and divided by PLLQ (§7.3.2); none
    /// while the PLL is off, its dividers invalid, or the OTG FS clock not enabled
    /// (AHB2ENR.OTGFSEN, §7.3.11).
    pub fn pll48_hz(&self, hse_hz: u64) -> Option<u64> {
        let (cr, cfg) = (self.regs[0], self.regs[1]);
        let enabled = self.regs[0x34 / 4] & (1 << 7) != 0;
        if cr & (1 << 25) == 0 || !enabled {
            return None;
        }
        let src = if cfg & (1 << 22) != 0 {
            if self.hse_dead {
                return None;
            }
            hse_hz
        } else {
            16_000_000
        };
        let (m, n, q) = (
            u64::from(cfg & 0x3F),
            u64::from((cfg >> 6) & 0x1FF),
            u64::from((cfg >> 24) & 0xF),
        );
        (m >= 2 && n >= 2 && q >= 2).then(|| src * n / m / q)
    }

    /// The clock security system found the HSE failed: RCC_CIR.CSSF.
    pub fn css_fired(&mut self) {
        self.regs[3] |= 0x80;
    }

    /// RCC_CSR (the reset flags).
    pub fn csr(&self) -> u32 {
        self.regs[0x74 / 4]
    }
}

impl Default for Rcc {
    fn default() -> Self {
        Rcc::new()
    }
}

/// PWR (offsets from 0x40007000): CR and CSR; VOSRDY set, and on the F446 ODRDY following ODEN
/// and ODSWRDY following ODSWEN (RM0390 §5.4.1-5.4.2).
#[derive(Debug, Clone, Default)]
pub struct Pwr {
    cr: u32,
}

impl Pwr {
    /// Reads CR (0) or CSR (4).
    pub fn read(&self, off: u32) -> u32 {
        match off {
            0 => self.cr,
            4 => {
                let mut csr = 1 << 14; // VOSRDY
                if self.cr & (1 << 16) != 0 {
                    csr |= 1 << 16; // ODRDY
                }
                if self.cr & (1 << 17) != 0 {
                    csr |= 1 << 17; // ODSWRDY
                }
                csr
            }
            _ => 0,
        }
    }

    /// Writes CR (0); CSR's writable bits are not used by the firmware.
    pub fn write(&mut self, off: u32, value: u32) {
        if off == 0 {
            self.cr = value;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ready_flags_follow_their_enables_and_sws_follows_sw() {
        let mut r = Rcc::new();
        assert_eq!(r.read(0) & 3, 3, "HSION and HSIRDY at reset");
        r.write(0, 0x83 | (1 << 16) | (1 << 18));
        assert_ne!(r.read(0) & (1 << 17), 0, "HSERDY");
        assert_ne!(r.read(0) & (1 << 18), 0, "HSEBYP kept");
        r.write(0, r.read(0) | (1 << 24));
        assert_ne!(r.read(0) & (1 << 25), 0, "PLLRDY");
        r.write(0, r.read(0) & !(1 << 16));
        assert_eq!(r.read(0) & (1 << 17), 0, "HSERDY off with HSEON");
        r.write(8, 2);
        assert_eq!((r.read(8) >> 2) & 3, 2, "SWS = PLL");
    }

    #[test]
    fn a_dead_hse_never_becomes_ready_even_after_a_reset() {
        let mut r = Rcc::new();
        r.hse_dead = true;
        r.reset(CSR_IWDGRSTF);
        r.write(0, 0x83 | (1 << 16));
        assert_eq!(r.read(0) & (1 << 17), 0);
    }

    #[test]
    fn cssf_is_cleared_by_cssc_only() {
        let mut r = Rcc::new();
        r.css_fired();
        r.write(0x0C, 0x0000_0100);
        assert_eq!(r.read(0x0C) & 0x80, 0x80, "an enable write leaves CSSF");
        r.write(0x0C, 1 << 23);
        assert_eq!(r.read(0x0C) & 0x80, 0);
    }

    #[test]
    fn reset_flags_are_kept_across_a_reset_until_rmvf() {
        let mut r = Rcc::new();
        r.write(0x74, 1 << 24);
        assert_eq!(r.csr() & 0xFE00_0000, 0);
        r.reset(CSR_IWDGRSTF);
        assert_ne!(r.csr() & CSR_IWDGRSTF, 0);
        r.write(0x74, 1 << 24);
        assert_eq!(r.csr() & CSR_IWDGRSTF, 0);
    }

    #[test]
    fn pwr_over_drive_flags_follow_their_enables() {
        let mut p = Pwr::default();
        assert_eq!(p.read(4), 1 << 14);
        p.write(0, 1 << 16);
        assert_eq!(p.read(4), (1 << 14) | (1 << 16));
        p.write(0, (1 << 16) | (1 << 17));
        assert_eq!(p.read(4), (1 << 14) | (1 << 16) | (1 << 17));
    }
}

#[cfg(test)]
mod pll48_tests {
    use super::*;

    /// The boards' set-up (HSE 8 MHz, M 4, N 168, Q 7: gms-core's boards/f405) gives 48 MHz;
    /// Q 8 gives 42 MHz, which the OTG core's check refuses; the PLL off or OTGFSEN clear
    /// gives none.
    #[test]
    fn the_pll_s_48_mhz_output_follows_its_dividers() {
        let mut r = Rcc::new();
        let cfg = |q: u32| (1 << 22) | 4 | (168 << 6) | (q << 24);
        r.write(0x04, cfg(7));
        assert_eq!(r.pll48_hz(8_000_000), None, "PLL off");
        r.write(0x00, (1 << 16) | (1 << 24));
        assert_eq!(r.pll48_hz(8_000_000), None, "OTGFSEN clear");
        r.write(0x34, 1 << 7);
        assert_eq!(r.pll48_hz(8_000_000), Some(48_000_000));
        r.write(0x04, cfg(8));
        assert_eq!(r.pll48_hz(8_000_000), Some(42_000_000));
        let mut o = super::super::otg::OtgFs::new();
        o.clk48_hz = r.pll48_hz(8_000_000);
        assert!(o.signalling().is_err());
        o.clk48_hz = Some(48_100_000);
        assert!(o.signalling().is_ok());
    }
}
