//! The STM32F4's DMA controller (RM0090 §10.5, RM0390 §9.5; offsets from DMA1 0x40026000 or
//! DMA2 0x40026400): the interrupt status and clear registers (LISR/HISR, LIFCR/HIFCR: six
//! bits per stream at 0, 6, 16, 22), and per stream CR, NDTR, PAR, M0AR. The machine moves the
//! data ([`Dma::next_address`] and [`Dma::transferred`]); this model keeps the counters, the
//! circular reload, EN and the half/complete flags.

/// A stream's flags (in its six-bit field).
pub mod flag {
    /// FIFO error.
    pub const FE: u32 = 1;
    /// Direct mode error.
    pub const DME: u32 = 1 << 2;
    /// Transfer error.
    pub const TE: u32 = 1 << 3;
    /// Half transfer.
    pub const HT: u32 = 1 << 4;
    /// Transfer complete.
    pub const TC: u32 = 1 << 5;
}

/// CR.EN.
const EN: u32 = 1;
/// CR.CIRC.
const CIRC: u32 = 1 << 8;
/// CR.MINC.
const MINC: u32 = 1 << 10;

/// One stream's registers.
#[derive(Debug, Clone, Copy, Default)]
pub struct Stream {
    /// CR.
    pub cr: u32,
    /// NDTR as the software wrote it (the reload value in circular mode).
    pub ndtr_set: u32,
    /// NDTR now.
    pub ndtr: u32,
    /// PAR.
    pub par: u32,
    /// M0AR.
    pub m0ar: u32,
    /// FCR.
    pub fcr: u32,
    /// Its six flags.
    pub flags: u32,
}

impl Stream {
    /// Enabled.
    pub fn enabled(&self) -> bool {
        self.cr & EN != 0
    }

    /// Memory data size \[bytes\] (MSIZE).
    pub fn msize(&self) -> u32 {
        1 << ((self.cr >> 13) & 3)
    }

    /// The channel selected (CHSEL).
    pub fn channel(&self) -> u32 {
        (self.cr >> 25) & 7
    }

    /// Direction: memory to peripheral (DIR = 01).
    pub fn to_peripheral(&self) -> bool {
        (self.cr >> 6) & 3 == 1
    }

    /// Its interrupt line: a flag set whose interrupt is enabled (TCIE, HTIE, TEIE, DMEIE;
    /// FEIE in FCR).
    pub fn irq(&self) -> bool {
        let on = |reg: u32, bit: u32, f: u32| if reg & (1 << bit) != 0 { f } else { 0 };
        let ie = on(self.cr, 4, flag::TC)
            | on(self.cr, 3, flag::HT)
            | on(self.cr, 2, flag::TE)
            | on(self.cr, 1, flag::DME)
            | on(self.fcr, 7, flag::FE);
        self.flags & ie != 0
    }
}

/// A DMA controller: 8 streams.
#[derive(Debug, Clone, Default)]
pub struct Dma {
    /// The streams.
    pub streams: [Stream; 8],
}

/// The bit offset of stream `s`'s six flags in LISR/HISR.
fn shift(s: usize) -> u32 {
    [0, 6, 16, 22][s % 4]
}

impl Dma {
    /// Reads the register at `off`.
    pub fn read(&self, off: u32) -> u32 {
        match off {
            0x00 | 0x04 => {
                let base = if off == 0 { 0 } else { 4 };
                (0..4).fold(0, |v, k| v | self.streams[base + k].flags << shift(k))
            }
            0x08 | 0x0C => 0,
            0x10..=0xCF => {
                let s = &self.streams[((off - 0x10) / 0x18) as usize];
                match (off - 0x10) % 0x18 {
                    0x00 => s.cr,
                    0x04 => s.ndtr,
                    0x08 => s.par,
                    0x0C => s.m0ar,
                    0x14 => s.fcr | 0x20, // FS: FIFO empty
                    _ => 0,
                }
            }
            _ => 0,
        }
    }

    /// Writes the register at `off`.
    pub fn write(&mut self, off: u32, value: u32) {
        match off {
            0x08 | 0x0C => {
                let base = if off == 0x08 { 0 } else { 4 };
                for k in 0..4 {
                    self.streams[base + k].flags &= !((value >> shift(k)) & 0x3D);
                }
            }
            0x10..=0xCF => {
                let s = &mut self.streams[((off - 0x10) / 0x18) as usize];
                match (off - 0x10) % 0x18 {
                    0x00 => {
                        // Enabling loads NDTR; clearing EN stops the stream.
                        if value & EN != 0 && s.cr & EN == 0 {
                            s.ndtr = s.ndtr_set;
                        }
                        s.cr = value;
                    }
                    // NDTR, PAR, M0AR are writable only while the stream is disabled.
                    0x04 if !s.enabled() => {
                        s.ndtr_set = value & 0xFFFF;
                        s.ndtr = value & 0xFFFF;
                    }
                    0x08 if !s.enabled() => s.par = value,
                    0x0C if !s.enabled() => s.m0ar = value,
                    0x14 => s.fcr = value & 0xBF,
                    _ => {}
                }
            }
            _ => {}
        }
    }

    /// The memory address of stream `s`'s next item, if it is enabled with items left.
    pub fn next_address(&self, s: usize) -> Option<u32> {
        let st = &self.streams[s];
        if !st.enabled() || st.ndtr == 0 {
            return None;
        }
        let done = st.ndtr_set - st.ndtr;
        Some(if st.cr & MINC != 0 {
            st.m0ar + done * st.msize()
        } else {
            st.m0ar
        })
    }

    /// One item moved on stream `s`: NDTR down, HT at half, TC at the end (reloaded in
    /// circular mode, else the stream disabled).
    pub fn transferred(&mut self, s: usize) {
        let st = &mut self.streams[s];
        if !st.enabled() || st.ndtr == 0 {
            return;
        }
        st.ndtr -= 1;
        if st.ndtr == st.ndtr_set / 2 {
            st.flags |= flag::HT;
        }
        if st.ndtr == 0 {
            st.flags |= flag::TC;
            if st.cr & CIRC != 0 {
                st.ndtr = st.ndtr_set;
            } else {
                st.cr &= !EN;
            }
        }
    }

    /// A transfer error on stream `s` (an access to unmapped memory): TEIF, the stream
    /// disabled.
    pub fn error(&mut self, s: usize) {
        let st = &mut self.streams[s];
        st.flags |= flag::TE;
        st.cr &= !EN;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_circular_stream_reloads_and_flags_half_and_complete() {
        let mut d = Dma::default();
        // Stream 0: NDTR 16, M0AR, MINC, halfwords, CIRC, TCIE, enabled.
        d.write(0x14, 16);
        d.write(0x1C, 0x2000_0100);
        d.write(0x10, (1 << 13) | (1 << 11) | MINC | CIRC | (1 << 4) | EN);
        assert_eq!(d.next_address(0), Some(0x2000_0100));
        for _ in 0..8 {
            d.transferred(0);
        }
        assert_eq!(d.read(0x00) & flag::HT, flag::HT);
        assert!(!d.streams[0].irq(), "HTIE off");
        for _ in 0..8 {
            d.transferred(0);
        }
        assert_eq!(d.read(0x00) & flag::TC, flag::TC);
        assert!(d.streams[0].irq());
        assert_eq!(d.read(0x14), 16, "reloaded");
        assert_eq!(d.next_address(0), Some(0x2000_0100));
        d.write(0x08, flag::TC | flag::HT);
        assert_eq!(d.read(0x00), 0);
    }

    #[test]
    fn a_normal_stream_stops_at_the_end_and_flags_sit_at_their_stream_offsets() {
        let mut d = Dma::default();
        // Stream 6 (HISR bits 16-21): 3 bytes memory to peripheral.
        let cr6 = 0x10 + 6 * 0x18;
        d.write(cr6 + 4, 3);
        d.write(cr6 + 0xC, 0x2000_0000);
        d.write(cr6, (1 << 6) | MINC | EN);
        assert!(d.streams[6].to_peripheral());
        for k in 0..3 {
            assert_eq!(d.next_address(6), Some(0x2000_0000 + k));
            d.transferred(6);
        }
        assert!(!d.streams[6].enabled());
        // HT at half (NDTR 3 → 1), TC at the end.
        assert_eq!(d.read(0x04), (flag::TC | flag::HT) << 16);
        d.write(0x0C, (flag::TC | flag::HT) << 16);
        assert_eq!(d.read(0x04), 0);
        // NDTR is read-only while enabled.
        d.write(cr6 + 4, 5);
        d.write(cr6, EN);
        d.write(cr6 + 4, 9);
        assert_eq!(d.read(cr6 + 4), 5);
    }
}
