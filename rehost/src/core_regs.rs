//! The Cortex-M4's memory-mapped system registers (the private peripheral bus, 0xE0000000 to
//! 0xE00FFFFF) as the firmware uses them: the SCB, the NVIC, the MPU, the DWT's cycle
//! counter, SysTick (read back only), the FPU's context control and the STM32's DBGMCU.
//! Addresses and fields from the ARMv7-M Architecture Reference Manual (B3.2 "System Control
//! Space", B3.4 "NVIC", B3.5 "MPU", C1.8 "DWT") and PM0214 §4; DBGMCU from RM0090 §38.16.

/// Exception numbers (ARMv7-M ARM B1.5.2).
pub mod exc {
    /// HardFault.
    pub const HARD_FAULT: u32 = 3;
    /// MemManage.
    pub const MEM_MANAGE: u32 = 4;
    /// BusFault.
    pub const BUS_FAULT: u32 = 5;
    /// UsageFault.
    pub const USAGE_FAULT: u32 = 6;
    /// SVCall.
    pub const SVCALL: u32 = 11;
    /// PendSV.
    pub const PENDSV: u32 = 14;
    /// SysTick.
    pub const SYSTICK: u32 = 15;
    /// The first external interrupt (IRQ 0).
    pub const IRQ0: u32 = 16;
}

/// External interrupts the F4 has (RM0090 Table 61: 82 on the F405; RM0390: 97 on the F446).
pub const IRQS: usize = 97;

/// The core's system registers.
#[derive(Debug, Clone)]
pub struct CoreRegs {
    /// NVIC_ISER: enabled external interrupts.
    pub enabled: [bool; IRQS],
    /// Pending exceptions, by exception number (system ones and external).
    pub pending: [bool; IRQS + 16],
    /// Priorities of the external interrupts (NVIC_IPR, one byte each; the F4 keeps the top 4
    /// bits).
    pub irq_prio: [u8; IRQS],
    /// SHPR1-3: priorities of the system exceptions 4-15 (byte `n - 4`).
    pub shpr: [u8; 12],
    /// SCB_VTOR.
    pub vtor: u32,
    /// SCB_AIRCR's PRIGROUP.
    pub prigroup: u32,
    /// SCB_SCR.
    pub scr: u32,
    /// SCB_CCR.
    pub ccr: u32,
    /// SCB_SHCSR.
    pub shcsr: u32,
    /// SCB_CFSR (fault status, write 1 to clear).
    pub cfsr: u32,
    /// SCB_HFSR.
    pub hfsr: u32,
    /// SCB_MMFAR.
    pub mmfar: u32,
    /// SCB_BFAR.
    pub bfar: u32,
    /// SCB_CPACR.
    pub cpacr: u32,
    /// FPCCR.
    pub fpccr: u32,
    /// FPCAR.
    pub fpcar: u32,
    /// FPDSCR.
    pub fpdscr: u32,
    /// MPU_CTRL.
    pub mpu_ctrl: u32,
    /// MPU_RNR.
    pub mpu_rnr: u32,
    /// MPU_RBAR/RASR of the 8 regions.
    pub mpu_regions: [(u32, u32); 8],
    /// DEMCR.
    pub demcr: u32,
    /// DWT_CTRL.
    pub dwt_ctrl: u32,
    /// DWT_CYCCNT at the instant `cyccnt_base_at` (cycles).
    cyccnt_base: u32,
    cyccnt_base_at: u64,
    /// SysTick CTRL/LOAD/VAL (the firmware does not use SysTick; `cargo target-bench`'s
    /// image counts with it): VAL counts down at the core clock (CLKSOURCE 1) from LOAD while
    /// ENABLE is set, from the time it was last written or enabled.
    pub systick: [u32; 3],
    /// When VAL was last set \[cycles\].
    systick_at: u64,
    /// DBGMCU_CR, APB1_FZ, APB2_FZ.
    pub dbgmcu: [u32; 3],
    /// DBGMCU_IDCODE.
    pub idcode: u32,
    /// Set by a write of SYSRESETREQ to AIRCR: the machine resets.
    pub reset_requested: bool,
    /// The active exception (for ICSR's VECTACTIVE), set by the machine.
    pub vect_active: u32,
}

/// AIRCR's VECTKEY.
const VECTKEY: u32 = 0x05FA;

impl CoreRegs {
    /// The registers at reset; `idcode` is the part's DBGMCU_IDCODE (RM0090 §38.6.1: DEV_ID
    /// 0x413 for the F405/407, RM0390 §33.6.1: 0x421 for the F446; REV_ID in the top half).
    pub fn new(idcode: u32) -> CoreRegs {
        CoreRegs {
            enabled: [false; IRQS],
            pending: [false; IRQS + 16],
            irq_prio: [0; IRQS],
            shpr: [0; 12],
            vtor: 0,
            prigroup: 0,
            scr: 0,
            ccr: 0x200,
            shcsr: 0,
            cfsr: 0,
            hfsr: 0,
            mmfar: 0,
            bfar: 0,
            cpacr: 0,
            fpccr: 0xC000_0000,
            fpcar: 0,
            fpdscr: 0,
            mpu_ctrl: 0,
            mpu_rnr: 0,
            mpu_regions: [(0, 0); 8],
            demcr: 0,
            dwt_ctrl: 0x4000_0000,
            cyccnt_base: 0,
            cyccnt_base_at: 0,
            systick: [0; 3],
            systick_at: 0,
            dbgmcu: [0; 3],
            idcode,
            reset_requested: false,
            vect_active: 0,
        }
    }

    /// DWT_CYCCNT at `now` \[cycles\]: counts while DWT_CTRL.CYCCNTENA (bit 0) is set.
    pub fn cyccnt(&self, now: u64) -> u32 {
        if self.dwt_ctrl & 1 != 0 {
            self.cyccnt_base
                .wrapping_add(now.wrapping_sub(self.cyccnt_base_at) as u32)
        } else {
            self.cyccnt_base
        }
    }

    /// The priority of exception `n` (lower is more urgent; HardFault −1).
    pub fn priority(&self, n: u32) -> i32 {
        match n {
            2 => -2,
            exc::HARD_FAULT => -1,
            4..=15 => self.shpr[n as usize - 4] as i32,
            _ if n >= exc::IRQ0 && ((n - exc::IRQ0) as usize) < IRQS => {
                self.irq_prio[(n - exc::IRQ0) as usize] as i32
            }
            _ => 256,
        }
    }

    /// The group (pre-emption) priority of exception `n` after PRIGROUP (B1.5.4).
    pub fn group_priority(&self, n: u32) -> i32 {
        let p = self.priority(n);
        if p < 0 {
            return p;
        }
        let sub_bits = self.prigroup + 1;
        (p >> sub_bits << sub_bits) & 0xFF
    }

    /// Whether the system exception `n` (MemManage, BusFault, UsageFault) is enabled in
    /// SHCSR; other exceptions are always.
    pub fn fault_enabled(&self, n: u32) -> bool {
        match n {
            exc::MEM_MANAGE => self.shcsr & (1 << 16) != 0,
            exc::BUS_FAULT => self.shcsr & (1 << 17) != 0,
            exc::USAGE_FAULT => self.shcsr & (1 << 18) != 0,
            _ => true,
        }
    }

    /// Sets an external interrupt pending (a peripheral's request).
    pub fn set_irq_pending(&mut self, irq: usize) {
        if irq < IRQS {
            self.pending[irq + 16] = true;
        }
    }

    /// The MPU's no-access regions while it is enabled: (base, size) of each enabled region
    /// with AP = 000 (B3.5.9).
    pub fn mpu_guards(&self) -> impl Iterator<Item = (u32, u32)> + '_ {
        let on = self.mpu_ctrl & 1 != 0;
        self.mpu_regions.iter().filter_map(move |&(rbar, rasr)| {
            let enabled = rasr & 1 != 0;
            let ap = (rasr >> 24) & 7;
            if !on || !enabled || ap != 0 {
                return None;
            }
            let size_bits = ((rasr >> 1) & 0x1F) + 1;
            let size = 1u64 << size_bits;
            let base = rbar & !((size as u32).wrapping_sub(1)) & !0x1F;
            Some((base, size.min(u32::MAX as u64) as u32))
        })
    }

    /// SysTick's VAL at `now`: while enabled on the core clock (CTRL.ENABLE, CLKSOURCE), it
    /// counts down one per cycle, reloading from LOAD after 0 (a VAL of 0 reloads at the next
    /// cycle).
    fn systick_val(&self, now: u64) -> u32 {
        let (ctrl, load, val) = (self.systick[0], u64::from(self.systick[1]), self.systick[2]);
        if ctrl & 0b101 != 0b101 {
            return val;
        }
        let n = now.saturating_sub(self.systick_at);
        let val = u64::from(val);
        if n <= val {
            return (val - n) as u32;
        }
        // Past 0: reloaded, then counting in periods of LOAD + 1.
        let left = n - val - 1;
        (load - left % (load + 1)) as u32
    }

    /// Reads the register at `addr` (a PPB address) at `now` \[cycles\].
    pub fn read(&self, addr: u32, now: u64) -> u32 {
        match addr {
            0xE000_1000 => self.dwt_ctrl,
            0xE000_1004 => self.cyccnt(now),
            0xE000_E004 => 2, // ICTR: 96 interrupts
            0xE000_E010 => self.systick[0],
            0xE000_E014 => self.systick[1],
            0xE000_E018 => self.systick_val(now),
            0xE000_E100..=0xE000_E10C => self.bits(&self.enabled, 0, addr - 0xE000_E100),
            0xE000_E180..=0xE000_E18C => self.bits(&self.enabled, 0, addr - 0xE000_E180),
            0xE000_E200..=0xE000_E20C => self.bits(&self.pending, 16, addr - 0xE000_E200),
            0xE000_E280..=0xE000_E28C => self.bits(&self.pending, 16, addr - 0xE000_E280),
            0xE000_E300..=0xE000_E30C => 0,
            0xE000_E400..=0xE000_E45F => {
                let i = (addr - 0xE000_E400) as usize;
                u32::from_le_bytes([
                    self.irq_prio[i],
                    *self.irq_prio.get(i + 1).unwrap_or(&0),
                    *self.irq_prio.get(i + 2).unwrap_or(&0),
                    *self.irq_prio.get(i + 3).unwrap_or(&0),
                ])
            }
            0xE000_ED00 => 0x410F_C241, // CPUID: Cortex-M4 r0p1
            0xE000_ED04 => {
                let mut v = self.vect_active & 0x1FF;
                if self.pending[exc::PENDSV as usize] {
                    v |= 1 << 28;
                }
                if self.pending.iter().skip(16).any(|&p| p) {
                    v |= 1 << 22;
                }
                v
            }
            0xE000_ED08 => self.vtor,
            0xE000_ED0C => (0xFA05 << 16) | (self.prigroup << 8),
            0xE000_ED10 => self.scr,
            0xE000_ED14 => self.ccr,
            0xE000_ED18..=0xE000_ED23 => {
                let i = (addr - 0xE000_ED18) as usize;
                u32::from_le_bytes([
                    self.shpr[i],
                    *self.shpr.get(i + 1).unwrap_or(&0),
                    *self.shpr.get(i + 2).unwrap_or(&0),
                    *self.shpr.get(i + 3).unwrap_or(&0),
                ])
            }
            0xE000_ED24 => self.shcsr,
            0xE000_ED28 => self.cfsr,
            0xE000_ED2C => self.hfsr,
            0xE000_ED34 => self.mmfar,
            0xE000_ED38 => self.bfar,
            0xE000_ED88 => self.cpacr,
            0xE000_ED90 => 8 << 8, // MPU_TYPE: 8 data regions, unified
            0xE000_ED94 => self.mpu_ctrl,
            0xE000_ED98 => self.mpu_rnr,
            0xE000_ED9C | 0xE000_EDA4 | 0xE000_EDAC | 0xE000_EDB4 => {
                let r = (self.mpu_rnr & 7) as usize;
                self.mpu_regions[r].0 | r as u32
            }
            0xE000_EDA0 | 0xE000_EDA8 | 0xE000_EDB0 | 0xE000_EDB8 => {
                self.mpu_regions[(self.mpu_rnr & 7) as usize].1
            }
            0xE000_EDF0 => 0, // DHCSR: no debugger
            0xE000_EDFC => self.demcr,
            0xE000_EF34 => self.fpccr,
            0xE000_EF38 => self.fpcar,
            0xE000_EF3C => self.fpdscr,
            0xE004_2000 => self.idcode,
            0xE004_2004 => self.dbgmcu[0],
            0xE004_2008 => self.dbgmcu[1],
            0xE004_200C => self.dbgmcu[2],
            _ => 0,
        }
    }

    fn bits(&self, flags: &[bool], skip: usize, off: u32) -> u32 {
        let base = skip + (off as usize / 4) * 32;
        (0..32).fold(0, |v, b| {
            if flags.get(base + b).copied().unwrap_or(false) {
                v | 1 << b
            } else {
                v
            }
        })
    }

    fn set_bits(flags: &mut [bool], skip: usize, off: u32, value: u32, to: bool) {
        let base = skip + (off as usize / 4) * 32;
        for b in 0..32 {
            if value & (1 << b) != 0
                && let Some(f) = flags.get_mut(base + b)
            {
                *f = to;
            }
        }
    }

    /// Writes `value` (`size` bytes) to the register at `addr` at `now` \[cycles\].
    pub fn write(&mut self, addr: u32, size: usize, value: u32, now: u64) {
        match addr {
            0xE000_1000 => {
                let c = self.cyccnt(now);
                self.dwt_ctrl = (self.dwt_ctrl & 0xF000_0000) | (value & 0x0FFF_FFFF);
                self.cyccnt_base = c;
                self.cyccnt_base_at = now;
            }
            0xE000_1004 => {
                self.cyccnt_base = value;
                self.cyccnt_base_at = now;
            }
            0xE000_E010 => {
                // Counting from the current value (ARMv7-M ARM B3.3.3), at the core clock only.
                let val = self.systick_val(now);
                self.systick[0] = value;
                self.systick[2] = val;
                self.systick_at = now;
            }
            0xE000_E014 => self.systick[1] = value & 0x00FF_FFFF,
            0xE000_E018 => {
                // A write clears VAL (and COUNTFLAG); the count restarts from LOAD.
                self.systick[2] = 0;
                self.systick_at = now;
            }
            0xE000_E100..=0xE000_E10C => {
                Self::set_bits(&mut self.enabled, 0, addr - 0xE000_E100, value, true)
            }
            0xE000_E180..=0xE000_E18C => {
                Self::set_bits(&mut self.enabled, 0, addr - 0xE000_E180, value, false)
            }
            0xE000_E200..=0xE000_E20C => {
                Self::set_bits(&mut self.pending, 16, addr - 0xE000_E200, value, true)
            }
            0xE000_E280..=0xE000_E28C => {
                Self::set_bits(&mut self.pending, 16, addr - 0xE000_E280, value, false)
            }
            0xE000_E400..=0xE000_E45F => {
                let i = (addr - 0xE000_E400) as usize;
                for (k, b) in value.to_le_bytes().iter().take(size).enumerate() {
                    if let Some(p) = self.irq_prio.get_mut(i + k) {
                        *p = b & 0xF0;
                    }
                }
            }
            0xE000_ED04 => {
                if value & (1 << 28) != 0 {
                    self.pending[exc::PENDSV as usize] = true;
                }
                if value & (1 << 27) != 0 {
                    self.pending[exc::PENDSV as usize] = false;
                }
            }
            0xE000_ED08 => self.vtor = value & !0x7F,
            0xE000_ED0C if value >> 16 == VECTKEY => {
                self.prigroup = (value >> 8) & 7;
                if value & (1 << 2) != 0 {
                    self.reset_requested = true;
                }
            }
            0xE000_ED10 => self.scr = value,
            0xE000_ED14 => self.ccr = value,
            0xE000_ED18..=0xE000_ED23 => {
                let i = (addr - 0xE000_ED18) as usize;
                for (k, b) in value.to_le_bytes().iter().take(size).enumerate() {
                    if let Some(p) = self.shpr.get_mut(i + k) {
                        *p = b & 0xF0;
                    }
                }
            }
            0xE000_ED24 => self.shcsr = value,
            0xE000_ED28 => self.cfsr &= !value,
            0xE000_ED2C => self.hfsr &= !value,
            0xE000_ED34 => self.mmfar = value,
            0xE000_ED38 => self.bfar = value,
            0xE000_ED88 => self.cpacr = value,
            0xE000_ED94 => self.mpu_ctrl = value & 7,
            0xE000_ED98 => self.mpu_rnr = value & 0xFF,
            0xE000_ED9C | 0xE000_EDA4 | 0xE000_EDAC | 0xE000_EDB4 => {
                if value & 0x10 != 0 {
                    self.mpu_rnr = value & 7;
                }
                self.mpu_regions[(self.mpu_rnr & 7) as usize].0 = value & !0x1F;
            }
            0xE000_EDA0 | 0xE000_EDA8 | 0xE000_EDB0 | 0xE000_EDB8 => {
                self.mpu_regions[(self.mpu_rnr & 7) as usize].1 = value
            }
            0xE000_EDFC => self.demcr = value,
            0xE000_EF00 => self.set_irq_pending((value & 0x1FF) as usize),
            0xE000_EF34 => self.fpccr = value,
            0xE000_EF38 => self.fpcar = value,
            0xE000_EF3C => self.fpdscr = value,
            0xE004_2004 => self.dbgmcu[0] = value,
            0xE004_2008 => self.dbgmcu[1] = value,
            0xE004_200C => self.dbgmcu[2] = value,
            _ => {}
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nvic_enable_pend_and_priorities_follow_the_architecture() {
        let mut c = CoreRegs::new(0x1000_6421);
        // ISER1 bit 24 = IRQ 56 (DMA2 stream 0); ICER clears it; reads show the set.
        c.write(0xE000_E104, 4, 1 << 24, 0);
        assert!(c.enabled[56]);
        assert_eq!(c.read(0xE000_E184, 0), 1 << 24);
        c.write(0xE000_E184, 4, 1 << 24, 0);
        assert!(!c.enabled[56]);
        // IPR as bytes: IRQ 56's byte at 0xE000E438; the low nibble is not implemented.
        c.write(0xE000_E438, 1, 0x1F, 0);
        assert_eq!(c.priority(56 + 16), 0x10);
        // ISPR / ICPR.
        c.write(0xE000_E204, 4, 1 << 24, 0);
        assert!(c.pending[56 + 16]);
        assert_ne!(c.read(0xE000_ED04, 0) & (1 << 22), 0, "ISRPENDING");
        c.write(0xE000_E284, 4, 1 << 24, 0);
        assert!(!c.pending[56 + 16]);
        // SHPR1 byte 0 is MemManage's priority; SHCSR enables it.
        c.write(0xE000_ED18, 4, 0x0000_0000, 0);
        assert_eq!(c.priority(exc::MEM_MANAGE), 0);
        assert!(!c.fault_enabled(exc::MEM_MANAGE));
        c.write(0xE000_ED24, 4, 1 << 16, 0);
        assert!(c.fault_enabled(exc::MEM_MANAGE));
        assert_eq!(c.priority(exc::HARD_FAULT), -1);
    }

    /// SysTick on the core clock: VAL counts down from LOAD once a cycle while enabled,
    /// reloads after 0 (a period of LOAD + 1), holds while disabled, restarts when written.
    #[test]
    fn systick_counts_down_on_the_core_clock_and_reloads() {
        let mut c = CoreRegs::new(0);
        c.write(0xE000_E014, 4, 999, 0);
        c.write(0xE000_E018, 4, 0, 0);
        c.write(0xE000_E010, 4, 0b101, 100);
        assert_eq!(c.read(0xE000_E018, 100), 0);
        assert_eq!(c.read(0xE000_E018, 101), 999, "reloaded a cycle after 0");
        assert_eq!(c.read(0xE000_E018, 600), 500);
        assert_eq!(c.read(0xE000_E018, 1100), 0);
        assert_eq!(c.read(0xE000_E018, 1101), 999, "a period of LOAD + 1");
        c.write(0xE000_E010, 4, 0b100, 1200);
        assert_eq!(c.read(0xE000_E018, 5000), 900, "held while disabled");
        c.write(0xE000_E010, 4, 0b101, 5000);
        assert_eq!(c.read(0xE000_E018, 5100), 800);
        // Not on the core clock (CLKSOURCE 0: the external reference): not modelled, held.
        c.write(0xE000_E010, 4, 0b001, 5100);
        assert_eq!(c.read(0xE000_E018, 9000), 800);
    }

    #[test]
    fn the_cycle_counter_counts_only_while_enabled() {
        let mut c = CoreRegs::new(0);
        assert_eq!(c.read(0xE000_1004, 1000), 0);
        c.write(0xE000_1000, 4, 1, 1000);
        assert_eq!(c.read(0xE000_1004, 1500), 500);
        c.write(0xE000_1000, 4, 0, 2000);
        assert_eq!(c.read(0xE000_1004, 9000), 1000);
    }

    #[test]
    fn an_mpu_region_with_no_access_is_a_guard() {
        let mut c = CoreRegs::new(0);
        // Region 0 at 0x20018000, 16 KiB (SIZE = 13), AP = 000, XN, enabled; MPU on.
        c.write(0xE000_ED98, 4, 0, 0);
        c.write(0xE000_ED9C, 4, 0x2001_8000, 0);
        c.write(0xE000_EDA0, 4, (1 << 28) | (13 << 1) | 1, 0);
        assert_eq!(c.mpu_guards().count(), 0, "the MPU is off");
        c.write(0xE000_ED94, 4, 5, 0);
        assert_eq!(
            c.mpu_guards().collect::<Vec<_>>(),
            vec![(0x2001_8000, 16384)]
        );
        // AP = 011 (full access) is no guard.
        c.write(0xE000_EDA0, 4, (3 << 24) | (13 << 1) | 1, 0);
        assert_eq!(c.mpu_guards().count(), 0);
    }

    #[test]
    fn aircr_takes_writes_only_with_its_key() {
        let mut c = CoreRegs::new(0);
        c.write(0xE000_ED0C, 4, (0x1234 << 16) | (1 << 2) | (3 << 8), 0);
        assert!(!c.reset_requested);
        assert_eq!(c.prigroup, 0);
        c.write(0xE000_ED0C, 4, (VECTKEY << 16) | (1 << 2), 0);
        assert!(c.reset_requested);
    }
}
