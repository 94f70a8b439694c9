//! A UART's reception into a ring by circular DMA, read by the DMA's count alone: the data
//! register is never read by the CPU, so no byte can be taken from under the DMA.
//!
//! embassy-stm32 0.6's ring-buffered reader (`usart/ringbuffered.rs`) reads SR then DR at
//! every call to clear IDLE and the error flags (`check_idle_and_errors`); on the F4's
//! USART (RM0090 §30.6.1, RM0390 §25.6.1) a DR read clears RXNE, and a byte that has just
//! arrived, its DMA request not yet served, is consumed by that read and lost from the ring
//! (embassy-rs/embassy issue 1556). Here the stream runs on its own (no interrupt), CR3.DMAR
//! requests it for each byte, and the reader compares the stream's count with where it read
//! last; it polls, at a rate the caller chooses (a byte every 10.9 µs at 921,600 Bd: a
//! 1024-byte ring holds 11 ms).
//!
//! What the reader checks at each look ([`look`]): the USART's error flags (parity, framing,
//! noise, overrun: SR read only — they clear when the stream's next DR read follows, §30.6.1),
//! the stream's half- and full-transfer flags for gms-core's `protocol::RingWatch` (a lapped
//! ring), and whether the stream still runs (EN, TEIF).
//!
//! Registers: the stream's CR, NDTR, PAR, M0AR, FCR (RM0090 §10.5.5-10.5.10), the DMA's
//! LISR/HISR and LIFCR/HIFCR (§10.5.1-10.5.4); the USART's SR, DR address and CR3.DMAR
//! (§30.6.1, §30.6.6).

use crate::pac;

/// Where the stream writes: a ring in RAM.
#[derive(Clone, Copy, Debug)]
pub struct Ring {
    /// Its address.
    pub addr: *mut u8,
    /// Its length \[bytes\] (1 to 65535).
    pub len: u16,
}

/// The stream the USART's receive requests go to.
#[derive(Clone, Copy)]
pub struct RxStream {
    /// The DMA controller.
    pub dma: pac::dma::Dma,
    /// The stream (0-7).
    pub stream: usize,
    /// Its channel for the USART's RX request (RM0390 table 28: USART2_RX is DMA1 stream 5
    /// channel 4).
    pub channel: u8,
}

/// Bounded wait for a stream's EN to read 0 after it is cleared (RM0090 §10.3.17: the stream
/// stops at the end of the current transfer, a few bus cycles) \[register reads\].
const STOP_POLLS: u32 = 10_000;

/// Starts reception: the stream stopped, its flags cleared, pointed at `usart`'s DR and at
/// `ring`, circular, byte-wide, memory incremented, no interrupt, enabled; then the USART's
/// DMA requests for reception on (CR3.DMAR, kept with the rest of CR3). False if the stream
/// did not stop (it is left as it was).
pub fn start(s: RxStream, usart: pac::usart::Usart, ring: Ring) -> bool {
    use pac::dma::vals::{Dir, Pl, Size};
    let st = s.dma.st(s.stream);
    st.cr().modify(|w| w.set_en(false));
    let mut polls = 0;
    while st.cr().read().en() {
        polls += 1;
        if polls > STOP_POLLS {
            return false;
        }
    }
    crate::dma::point(
        s.dma,
        s.stream,
        usart.dr().as_ptr() as usize as u32,
        ring.addr as usize as u32,
        ring.len,
    );
    st.cr().write(|w| {
        w.set_chsel(s.channel);
        w.set_dir(Dir::PERIPHERAL_TO_MEMORY);
        w.set_psize(Size::BITS8);
        w.set_msize(Size::BITS8);
        w.set_minc(true);
        w.set_circ(true);
        w.set_pl(Pl::VERY_HIGH);
        w.set_en(true);
    });
    usart.cr3().modify(|w| w.set_dmar(true));
    true
}

/// Where the stream will write next in the ring (0 to len − 1): len − NDTR. NDTR counts down
/// from len and is reloaded when it reaches 0 (circular mode), so it reads 1 to len; a 0
/// read in the reload's instant is taken as len.
pub fn write_pos(s: RxStream, len: u16) -> u16 {
    let ndt = s.dma.st(s.stream).ndtr().read().ndt();
    let ndt = if ndt == 0 || ndt > len { len } else { ndt };
    len - ndt
}

/// Copies the bytes from `from` up to `to` (ring positions; `to` < `from` wraps) into `out`,
/// as many as fit; returns how many.
///
/// # Safety
/// `ring` must be the ring the stream writes (valid for its length); the bytes between
/// `from` and `to` are ones it has written and will not write again before a lap.
pub unsafe fn copy_out(ring: Ring, from: u16, to: u16, out: &mut [u8]) -> usize {
    let len = ring.len as usize;
    let (from, to) = (from as usize % len.max(1), to as usize % len.max(1));
    let avail = if to >= from {
        to - from
    } else {
        len - from + to
    };
    let n = avail.min(out.len());
    for (k, o) in out.iter_mut().take(n).enumerate() {
        let at = (from + k) % len;
        // SAFETY: `at` < len, within the ring (the caller's promise); volatile, as the DMA
        // writes the ring behind the compiler's back.
        *o = unsafe { core::ptr::read_volatile(ring.addr.add(at)) };
    }
    n
}

/// What one look at the reception found.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Look {
    /// The USART's SR showed a parity, framing, noise or overrun error (PE, FE, NF, ORE: bits
    /// 0-3): a byte received since the flags last cleared was damaged or lost.
    pub line_error: bool,
    /// The stream reached the ring's middle since the last look (HTIF; cleared now).
    pub half: bool,
    /// The stream reached the ring's end since the last look (TCIF; cleared now).
    pub full: bool,
    /// Where the stream writes next (as [`write_pos`]).
    pub to: u16,
    /// The stream no longer runs (EN clear, or TEIF: a transfer error disabled it).
    pub stopped: bool,
}

/// One look at the reception, in this order: the USART's SR (an error flag set for a byte
/// the stream has already taken: the position read after it includes that byte), the
/// stream's flags (HTIF and TCIF cleared where seen, by writing LIFCR/HIFCR), its position,
/// its EN.
pub fn look(s: RxStream, usart: pac::usart::Usart, len: u16) -> Look {
    let sr = usart.sr().read().0;
    let (reg, n) = (s.stream / 4, s.stream % 4);
    let isr = s.dma.isr(reg).read();
    let (half, full, te) = (isr.htif(n), isr.tcif(n), isr.teif(n));
    if half || full {
        s.dma.ifcr(reg).write(|w| {
            w.set_htif(n, half);
            w.set_tcif(n, full);
        });
    }
    let to = write_pos(s, len);
    let stopped = te || !s.dma.st(s.stream).cr().read().en();
    Look {
        line_error: sr & 0xF != 0,
        half,
        full,
        to,
        stopped,
    }
}
