//! USART2 of the STM32F4 (RM0090 §30.6, RM0390 §25.6; offsets from 0x40004400): SR, DR, BRR,
//! CR1-3; a frame of 10 bits (8N1) at the rate BRR sets (16× oversampling: baud = f_PCLK1 /
//! BRR); received bytes into DR (RXNE, ORE when one was not read) or taken by the DMA
//! (CR3.DMAR); IDLE after a frame of silence following a reception; SR's error and idle flags
//! cleared by reading SR then DR; transmission from DR or by the DMA (CR3.DMAT), TXE and TC.
//! The machine moves DMA data; the line's two ends are byte queues.

use std::collections::VecDeque;

/// SR.ORE.
pub const SR_ORE: u32 = 1 << 3;
/// SR.FE.
pub const SR_FE: u32 = 1 << 1;
/// SR.IDLE.
pub const SR_IDLE: u32 = 1 << 4;
/// SR.RXNE.
pub const SR_RXNE: u32 = 1 << 5;
/// SR.TC.
pub const SR_TC: u32 = 1 << 6;
/// SR.TXE.
pub const SR_TXE: u32 = 1 << 7;
/// CR1.UE | TE | RE.
const UE: u32 = 1 << 13;
const TE: u32 = 1 << 3;
const RE: u32 = 1 << 2;
/// CR3.DMAR.
pub const CR3_DMAR: u32 = 1 << 6;
/// CR3.DMAT.
pub const CR3_DMAT: u32 = 1 << 7;

/// What came due on the line.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LineEvent {
    /// A byte arrived: with DMAR the DMA must take it (`Usart::dma_rx`), else it is in DR.
    Received(u8),
    /// The transmitter is free: the DMA may give the next byte (`Usart::dma_tx`).
    TxFree,
    /// Nothing for the machine (a flag changed).
    None,
}

/// USART2 and its line.
#[derive(Debug, Clone)]
pub struct Usart {
    sr: u32,
    dr_rx: u8,
    brr: u32,
    cr1: u32,
    cr2: u32,
    cr3: u32,
    /// SR read since the last DR read (the flag-clearing sequence).
    sr_read: u32,
    /// The core's cycles per APB1 cycle (4 at 168/42 MHz).
    pub apb1_div: u64,
    /// Bytes from the host, not yet on the line.
    pub from_host: VecDeque<u8>,
    /// Bytes the image sent.
    pub to_host: Vec<u8>,
    /// Bytes received so far on the line.
    pub received: u64,
    /// Which received bytes (numbered from 0 by [`Usart::received`]) arrive with a framing
    /// error (SR.FE with the byte).
    pub framing_errors: std::collections::BTreeSet<u64>,
    /// When the byte on the receive line ends \[cycles\].
    rx_at: Option<u64>,
    /// When the byte being sent ends \[cycles\].
    tx_at: Option<u64>,
    /// The byte being sent.
    tx_byte: u8,
    /// When the line has been idle a frame after the last byte \[cycles\].
    idle_at: Option<u64>,
    /// The transmit line's busy time so far \[cycles\]: a frame for each byte sent.
    tx_busy: u64,
}

impl Usart {
    /// A USART at reset whose PCLK1 is 1/`apb1_div` of the core's clock.
    pub fn new(apb1_div: u64) -> Usart {
        Usart {
            sr: SR_TXE | SR_TC,
            dr_rx: 0,
            brr: 0,
            cr1: 0,
            cr2: 0,
            cr3: 0,
            sr_read: 0,
            apb1_div,
            from_host: VecDeque::new(),
            to_host: Vec::new(),
            received: 0,
            framing_errors: Default::default(),
            rx_at: None,
            tx_at: None,
            tx_byte: 0,
            idle_at: None,
            tx_busy: 0,
        }
    }

    /// The transmit line's busy time so far \[cycles\] (a frame for each byte sent).
    pub fn line_busy_cycles(&self) -> u64 {
        self.tx_busy
    }

    /// One frame (start, 8 data, stop) \[cycles\].
    pub fn frame(&self) -> u64 {
        10 * self.brr.max(16) as u64 * self.apb1_div
    }

    fn receiving(&self) -> bool {
        self.cr1 & (UE | RE) == UE | RE
    }

    fn transmitting(&self) -> bool {
        self.cr1 & (UE | TE) == UE | TE
    }

    /// Whether the DMA takes received bytes (CR3.DMAR).
    pub fn dma_rx(&self) -> bool {
        self.cr3 & CR3_DMAR != 0
    }

    /// Whether the DMA gives bytes to send (CR3.DMAT).
    pub fn dma_tx(&self) -> bool {
        self.cr3 & CR3_DMAT != 0
    }

    /// Starts the next byte from the host on the line at `now` if the line is free.
    pub fn poll_host(&mut self, now: u64) {
        if self.rx_at.is_none() && self.receiving() && !self.from_host.is_empty() {
            self.rx_at = Some(now + self.frame());
        }
    }

    /// When the next line event is due \[cycles\].
    pub fn next_event(&self) -> Option<u64> {
        [self.rx_at, self.tx_at, self.idle_at]
            .into_iter()
            .flatten()
            .min()
    }

    /// Fires what is due at `t`.
    pub fn fire(&mut self, t: u64) -> LineEvent {
        if self.tx_at == Some(t) {
            self.tx_at = None;
            self.to_host.push(self.tx_byte);
            self.tx_busy += self.frame();
            self.sr |= SR_TC;
            return LineEvent::TxFree;
        }
        if self.rx_at == Some(t) {
            self.rx_at = None;
            let Some(b) = self.from_host.pop_front() else {
                return LineEvent::None;
            };
            self.idle_at = Some(t + self.frame());
            if !self.from_host.is_empty() {
                self.rx_at = Some(t + self.frame());
            }
            let n = self.received;
            self.received += 1;
            if self.framing_errors.remove(&n) {
                self.sr |= SR_FE;
            }
            if self.dma_rx() {
                // The stream reads DR at once: the flags the core's last SR read showed are
                // cleared by it (the sequence SR then DR, RM0090 §30.6.1), and so is one this
                // byte raised if the same flag was shown.
                self.sr &= !(self.sr_read & (SR_IDLE | SR_ORE | 7));
                self.sr_read = 0;
            } else {
                if self.sr & SR_RXNE != 0 {
                    self.sr |= SR_ORE;
                } else {
                    self.dr_rx = b;
                    self.sr |= SR_RXNE;
                }
            }
            return LineEvent::Received(b);
        }
        if self.idle_at == Some(t) {
            self.idle_at = None;
            if self.rx_at.is_none() {
                self.sr |= SR_IDLE;
            }
        }
        LineEvent::None
    }

    /// The DMA (or the core) gives a byte to send at `now`.
    pub fn send(&mut self, b: u8, now: u64) {
        if !self.transmitting() {
            return;
        }
        self.tx_byte = b;
        self.sr &= !SR_TC;
        self.tx_at = Some(now + self.frame());
    }

    /// The transmitter is free for the next byte.
    pub fn tx_free(&self) -> bool {
        self.tx_at.is_none() && self.transmitting()
    }

    /// SR as the core reads it: TXE set while no byte is being sent.
    fn sr_now(&self) -> u32 {
        if self.tx_at.is_none() {
            self.sr | SR_TXE
        } else {
            self.sr & !SR_TXE
        }
    }

    /// The interrupt line: IDLE with IDLEIE, RXNE or ORE with RXNEIE, TC with TCIE, TXE
    /// with TXEIE, errors with CR3.EIE (in DMA mode).
    pub fn irq(&self) -> bool {
        let sr = self.sr_now();
        (sr & SR_IDLE != 0 && self.cr1 & (1 << 4) != 0)
            || (sr & (SR_RXNE | SR_ORE) != 0 && self.cr1 & (1 << 5) != 0)
            || (sr & SR_TC != 0 && self.cr1 & (1 << 6) != 0)
            || (sr & SR_TXE != 0 && self.cr1 & (1 << 7) != 0)
            || (sr & (SR_ORE | 7) != 0 && self.cr3 & 1 != 0)
    }

    /// Reads the register at `off`.
    pub fn read(&mut self, off: u32) -> u32 {
        match off {
            0x00 => {
                let sr = self.sr_now();
                self.sr_read = sr;
                sr
            }
            0x04 => {
                // Reading DR clears RXNE, and the flags SR showed (IDLE, ORE, NF, FE, PE).
                self.sr &= !(SR_RXNE | (self.sr_read & (SR_IDLE | SR_ORE | 7)));
                self.sr_read = 0;
                self.dr_rx as u32
            }
            0x08 => self.brr,
            0x0C => self.cr1,
            0x10 => self.cr2,
            0x14 => self.cr3,
            _ => 0,
        }
    }

    /// Writes the register at `off` at `now`.
    pub fn write(&mut self, off: u32, value: u32, now: u64) {
        match off {
            // SR: RXNE and TC are cleared by writing 0 (rc_w0); the others read-only.
            0x00 => self.sr &= value | !(SR_RXNE | SR_TC),
            0x04 => self.send(value as u8, now),
            0x08 => self.brr = value & 0xFFFF,
            0x0C => {
                self.cr1 = value;
                self.poll_host(now);
            }
            0x10 => self.cr2 = value,
            0x14 => self.cr3 = value,
            _ => {}
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at_921600() -> Usart {
        let mut u = Usart::new(4);
        // 42 MHz / 921,600 = 45.6: BRR 46 at 16× oversampling (913 kBd, −0.93 %).
        u.write(0x08, 46, 0);
        u.write(0x0C, UE | TE | RE | (1 << 4), 0);
        u
    }

    #[test]
    fn bytes_arrive_a_frame_apart_and_idle_comes_a_frame_after_the_last() {
        let mut u = at_921600();
        u.from_host.extend(b"ab");
        u.poll_host(0);
        let f = u.frame();
        assert_eq!(f, 10 * 46 * 4);
        assert_eq!(u.next_event(), Some(f));
        assert_eq!(u.fire(f), LineEvent::Received(b'a'));
        assert_eq!(u.read(0) & SR_RXNE, SR_RXNE);
        assert_eq!(u.read(4), b'a' as u32);
        assert_eq!(u.fire(2 * f), LineEvent::Received(b'b'));
        assert_eq!(u.next_event(), Some(3 * f));
        assert_eq!(u.fire(3 * f), LineEvent::None);
        assert!(u.irq(), "IDLE with IDLEIE");
        // Cleared by SR then DR.
        u.read(0);
        u.read(4);
        assert!(!u.irq());
    }

    #[test]
    fn a_framing_error_with_dma_stays_until_sr_is_read_and_the_next_byte_taken() {
        let mut u = at_921600();
        u.write(0x14, CR3_DMAR, 0);
        u.framing_errors.insert(1);
        u.from_host.extend(b"abc");
        u.poll_host(0);
        let f = u.frame();
        u.fire(f);
        assert_eq!(u.read(0) & SR_FE, 0, "a clean byte");
        u.fire(2 * f);
        assert_eq!(u.read(0) & SR_FE, SR_FE, "with the damaged byte");
        assert_eq!(u.read(0) & SR_FE, SR_FE, "SR alone does not clear it");
        u.fire(3 * f);
        assert_eq!(
            u.read(0) & SR_FE,
            0,
            "the stream's read of the next byte did"
        );
        assert_eq!(u.received, 3);
    }

    #[test]
    fn a_byte_not_read_in_time_overruns_without_dma() {
        let mut u = at_921600();
        u.from_host.extend(b"xy");
        u.poll_host(0);
        let f = u.frame();
        u.fire(f);
        u.fire(2 * f);
        assert_eq!(u.read(0) & SR_ORE, SR_ORE);
        assert_eq!(u.read(4), b'x' as u32, "the first byte kept");
    }

    #[test]
    fn sending_takes_a_frame_and_sets_tc() {
        let mut u = at_921600();
        u.write(0x04, b'z' as u32, 100);
        assert_eq!(u.read(0) & (SR_TC | SR_TXE), 0);
        assert_eq!(u.fire(100 + u.frame()), LineEvent::TxFree);
        assert_eq!(u.to_host, b"z");
        assert_eq!(u.read(0) & (SR_TC | SR_TXE), SR_TC | SR_TXE);
    }
}
