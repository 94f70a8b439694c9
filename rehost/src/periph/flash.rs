//! The flash interface (RM0090 §3.9, RM0390 §3.8; offsets from 0x40023C00): ACR read back,
//! the unlock keys, sector erase and programming, the status flags, and the user option bytes
//! (OPTKEYR, OPTCR: programmed by OPTSTRT, kept over resets and power cycles, §3.7.2). The memory itself is the
//! machine's (mapped read-only to the core: a write outside a programming sequence is caught);
//! an erase is returned to the machine as an [`Erase`] to carry out.

/// A sector to erase (fill with 0xFF) \[address, bytes\].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Erase {
    /// Its first address.
    pub addr: u32,
    /// Its length \[bytes\].
    pub len: u32,
}

/// The flash interface's registers.
#[derive(Debug, Clone)]
pub struct FlashIf {
    acr: u32,
    cr: u32,
    sr: u32,
    optcr: u32,
    key_step: u8,
    opt_key_step: u8,
    /// The option bytes as programmed (OPTCR's value at reset, with OPTLOCK set).
    options: u32,
    /// Option programming fails (a part that will not take it: WRPERR, nothing programmed).
    pub refuse_options: bool,
    /// The part's flash size \[bytes\] (512 KiB on the F446RE, 1 MiB on the F405RG).
    size: u32,
}

const OPTKEY1: u32 = 0x0819_2A3B;
const OPTKEY2: u32 = 0x4C5D_6E7F;
/// OPTCR.OPTLOCK.
const OPTLOCK: u32 = 1;
/// OPTCR.OPTSTRT.
const OPTSTRT: u32 = 1 << 1;
/// The factory option bytes (RM0090 §3.9.10 FLASH_OPTCR's reset value: BOR off, read
/// protection level 0, no write protection, locked).
pub const FACTORY_OPTIONS: u32 = 0x0FFF_AAED;
const KEY1: u32 = 0x4567_0123;
const KEY2: u32 = 0xCDEF_89AB;
/// CR.LOCK.
pub const CR_LOCK: u32 = 1 << 31;
/// CR.PG.
pub const CR_PG: u32 = 1;
const CR_SER: u32 = 1 << 1;
const CR_STRT: u32 = 1 << 16;
/// SR.PGSERR: programming sequence error (a write without PG).
pub const SR_PGSERR: u32 = 1 << 7;
/// SR.EOP.
const SR_EOP: u32 = 1;

impl FlashIf {
    /// The interface at reset (locked), for a part with `size` bytes of flash.
    pub fn new(size: u32) -> FlashIf {
        FlashIf {
            acr: 0,
            cr: CR_LOCK,
            sr: 0,
            optcr: FACTORY_OPTIONS,
            key_step: 0,
            opt_key_step: 0,
            options: FACTORY_OPTIONS,
            refuse_options: false,
            size,
        }
    }

    /// FLASH_ACR: the wait states and the accelerator's switches (RM0090 §3.9.1).
    pub fn acr(&self) -> u32 {
        self.acr
    }

    /// Whether a programming sequence is open (CR.PG set, unlocked).
    pub fn programming(&self) -> bool {
        self.cr & CR_PG != 0 && self.cr & CR_LOCK == 0
    }

    /// A write to flash memory outside a programming sequence: PGSERR (RM0090 §3.9.7).
    pub fn bad_write(&mut self) {
        self.sr |= SR_PGSERR;
    }

    /// The sectors of the part: 4 × 16 KiB, 64 KiB, then 128 KiB ones (RM0090 Table 5,
    /// RM0390 Table 4).
    pub fn sector(&self, n: u32) -> Option<Erase> {
        let (addr, len) = match n {
            0..=3 => (n * 0x4000, 0x4000),
            4 => (0x1_0000, 0x1_0000),
            _ => (0x2_0000 * (n - 4), 0x2_0000),
        };
        (addr + len <= self.size).then_some(Erase {
            addr: 0x0800_0000 + addr,
            len,
        })
    }

    /// The option bytes as programmed and whether programming them is refused, to carry over
    /// a reset ([`FlashIf::restore_options`]).
    pub fn options(&self) -> (u32, bool) {
        (self.options, self.refuse_options)
    }

    /// The interface after a reset with option bytes `options` (OPTCR loaded from them,
    /// locked).
    pub fn restore_options(&mut self, (options, refuse): (u32, bool)) {
        self.options = options | OPTLOCK;
        self.optcr = self.options;
        self.refuse_options = refuse;
    }

    /// Reads the register at `off`.
    pub fn read(&self, off: u32) -> u32 {
        match off {
            0x00 => self.acr,
            0x0C => self.sr,
            0x10 => self.cr,
            0x14 => self.optcr,
            _ => 0,
        }
    }

    /// Writes the register at `off`; an erase started is returned to be carried out.
    pub fn write(&mut self, off: u32, value: u32) -> Option<Erase> {
        match off {
            // ACR: LATENCY, PRFTEN, ICEN, DCEN kept; ICRST/DCRST read as 0.
            0x00 => self.acr = value & !((1 << 11) | (1 << 12)),
            // KEYR: KEY1 then KEY2 unlocks CR; anything else locks it until reset.
            0x04 if key_sequence(&mut self.key_step, value, [KEY1, KEY2]) => {
                self.cr &= !CR_LOCK;
            }
            0x0C => self.sr &= !(value & 0xF3), // write 1 to clear
            0x10 => {
                if self.cr & CR_LOCK != 0 {
                    // Writes to a locked CR are ignored (only LOCK stays set).
                    return None;
                }
                self.cr = value & !CR_STRT;
                if value & CR_STRT != 0 && value & CR_SER != 0 {
                    let snb = (value >> 3) & 0xF;
                    self.sr |= SR_EOP;
                    return self.sector(snb);
                }
            }
            // OPTKEYR: OPTKEY1 then OPTKEY2 unlock OPTCR; a wrong sequence keeps it locked
            // until reset.
            0x08 if key_sequence(&mut self.opt_key_step, value, [OPTKEY1, OPTKEY2]) => {
                self.optcr &= !OPTLOCK;
            }
            0x14 => {
                if self.optcr & OPTLOCK != 0 {
                    return None;
                }
                // Programmed at once (BSY never seen set); OPTSTRT reads back 0 after.
                self.optcr = value & !OPTSTRT;
                if value & OPTSTRT != 0 {
                    if self.refuse_options {
                        self.sr |= 1 << 4; // WRPERR
                        self.optcr = (self.options & !OPTLOCK) | (value & OPTLOCK);
                    } else {
                        self.options = (value & !(OPTSTRT | OPTLOCK)) | OPTLOCK;
                    }
                }
            }
            _ => {}
        }
        None
    }
}

/// One write of a two-key unlock sequence (KEYR, OPTKEYR: RM0090 §3.5.1, §3.7.2): `step` is
/// 0 before the first key, 1 after it, 2 after a wrong key (locked until reset). True when
/// `value` completes the sequence (the caller unlocks; `step` back to 0).
fn key_sequence(step: &mut u8, value: u32, keys: [u32; 2]) -> bool {
    match (*step, value) {
        (0, k) if k == keys[0] => *step = 1,
        (1, k) if k == keys[1] => {
            *step = 0;
            return true;
        }
        _ => *step = 2,
    }
    false
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unlock_needs_both_keys_in_order() {
        let mut f = FlashIf::new(512 * 1024);
        f.write(0x10, CR_PG);
        assert!(!f.programming(), "locked: CR not written");
        f.write(0x04, KEY2);
        f.write(0x04, KEY1);
        assert_ne!(f.read(0x10) & CR_LOCK, 0);
        let mut f = FlashIf::new(512 * 1024);
        f.write(0x04, KEY1);
        f.write(0x04, KEY2);
        f.write(0x10, CR_PG);
        assert!(f.programming());
        f.write(0x10, CR_LOCK);
        assert!(!f.programming());
    }

    #[test]
    fn option_bytes_are_programmed_by_optstrt_only_unlocked_and_kept_over_a_reset() {
        let mut f = FlashIf::new(512 * 1024);
        assert_eq!(f.read(0x14), FACTORY_OPTIONS);
        // Locked: ignored.
        f.write(0x14, (FACTORY_OPTIONS & !0b1101) | OPTSTRT);
        assert_eq!(f.read(0x14), FACTORY_OPTIONS);
        f.write(0x08, OPTKEY1);
        f.write(0x08, OPTKEY2);
        assert_eq!(f.read(0x14) & OPTLOCK, 0);
        // Written without OPTSTRT: not programmed, a reset brings the old back.
        f.write(0x14, FACTORY_OPTIONS & !0b1101);
        let mut g = FlashIf::new(512 * 1024);
        g.restore_options(f.options());
        assert_eq!(g.read(0x14), FACTORY_OPTIONS);
        // With OPTSTRT: programmed, kept over the reset.
        f.write(0x14, (FACTORY_OPTIONS & !0b1101) | OPTSTRT);
        assert_eq!(f.read(0x14) & OPTSTRT, 0);
        let mut g = FlashIf::new(512 * 1024);
        g.restore_options(f.options());
        assert_eq!(g.read(0x14), (FACTORY_OPTIONS & !0b1100) | OPTLOCK);
        // Refused: WRPERR, the options as they were.
        let mut f = FlashIf::new(512 * 1024);
        f.refuse_options = true;
        f.write(0x08, OPTKEY1);
        f.write(0x08, OPTKEY2);
        f.write(0x14, (FACTORY_OPTIONS & !0b1101) | OPTSTRT);
        assert_eq!(f.read(0x0C) & (1 << 4), 1 << 4);
        assert_eq!(f.read(0x14) & 0b1100, 0b1100, "BOR still off");
    }

    #[test]
    fn sector_erase_names_the_sector_of_the_part() {
        let mut f = FlashIf::new(512 * 1024);
        f.write(0x04, KEY1);
        f.write(0x04, KEY2);
        // SER, SNB = 6, STRT: the F446's sector 6 is 0x08040000, 128 KiB.
        assert_eq!(
            f.write(0x10, CR_SER | (6 << 3) | CR_STRT),
            Some(Erase {
                addr: 0x0804_0000,
                len: 0x2_0000
            })
        );
        assert_eq!(f.read(0x0C) & 0x1_0000, 0, "BSY clear");
        assert_eq!(f.sector(8), None, "no sector 8 on a 512 KiB part");
        assert_eq!(
            FlashIf::new(1 << 20).sector(11).map(|e| e.addr),
            Some(0x080E_0000)
        );
        assert_eq!(
            f.sector(4).map(|e| (e.addr, e.len)),
            Some((0x0801_0000, 0x1_0000))
        );
    }
}
