//! The independent watchdog (RM0090 §19, RM0390 §18; offsets from 0x40003000): started by
//! 0xCCCC, reloaded by 0xAAAA, PR and RLR writable after 0x5555; a down-counter at the LSI's
//! 32 kHz / 4·2^PR that resets the chip at zero.

/// The LSI's nominal frequency \[Hz\].
pub const LSI_HZ: u64 = 32_000;

/// The watchdog.
#[derive(Debug, Clone, Default)]
pub struct Iwdg {
    pr: u32,
    rlr: u32,
    unlocked: bool,
    /// When it expires \[cycles\], once started.
    pub expires: Option<u64>,
    /// The core's clock \[Hz\] (cycles per second).
    pub hz: u64,
}

impl Iwdg {
    /// A watchdog at reset (stopped; PR 0, RLR 0xFFF) on a core clocked at `hz`.
    pub fn new(hz: u64) -> Iwdg {
        Iwdg {
            pr: 0,
            rlr: 0xFFF,
            unlocked: false,
            expires: None,
            hz,
        }
    }

    /// Its timeout \[cycles\]: (RLR + 1) · 4 · 2^PR / 32 kHz.
    pub fn timeout(&self) -> u64 {
        (self.rlr as u64 + 1) * (4 << self.pr.min(6)) * self.hz / LSI_HZ
    }

    /// Reads the register at `off` (SR: PVU/RVU never busy).
    pub fn read(&self, off: u32) -> u32 {
        match off {
            0x04 => self.pr,
            0x08 => self.rlr,
            _ => 0,
        }
    }

    /// Writes the register at `off` at `now` \[cycles\].
    pub fn write(&mut self, off: u32, value: u32, now: u64) {
        match off {
            0x00 => match value & 0xFFFF {
                0xCCCC => {
                    self.expires = Some(now + self.timeout());
                    self.unlocked = false;
                }
                0xAAAA => {
                    if self.expires.is_some() {
                        self.expires = Some(now + self.timeout());
                    }
                    self.unlocked = false;
                }
                0x5555 => self.unlocked = true,
                _ => self.unlocked = false,
            },
            0x04 if self.unlocked => self.pr = value & 7,
            0x08 if self.unlocked => self.rlr = value & 0xFFF,
            _ => {}
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_timeout_follows_prescaler_and_reload_and_feeding_defers_it() {
        let mut w = Iwdg::new(168_000_000);
        w.write(0x04, 4, 0);
        assert_eq!(w.read(0x04), 0, "PR locked without 0x5555");
        w.write(0x00, 0x5555, 0);
        w.write(0x04, 4, 0); // /64
        w.write(0x08, 1999, 0);
        // 2000 · 64 / 32 kHz = 4 s.
        assert_eq!(w.timeout(), 4 * 168_000_000);
        assert_eq!(w.expires, None);
        w.write(0x00, 0xCCCC, 100);
        assert_eq!(w.expires, Some(100 + 4 * 168_000_000));
        w.write(0x00, 0xAAAA, 1000);
        assert_eq!(w.expires, Some(1000 + 4 * 168_000_000));
    }
}
