//! A UART's transmission by DMA from a buffer the caller fills while the previous transfer is
//! still on the line: the stream is started and left running; the next start waits for it
//! to end. embassy-stm32 0.6's `UartTx::write` awaits each transfer's end, so the bytes of
//! the next batch were formatted while the line idled (the window's 1 kHz stream left the
//! Nucleo's UART 12 % idle at 921,600 Bd, found running the image in `rehost check`).
//!
//! Registers: the stream's CR (EN, cleared by the hardware when NDTR reaches 0), NDTR, PAR,
//! M0AR, FCR (RM0090 §10.5.5-10.5.10, §10.3.17); the USART's DR address and CR3.DMAT
//! (§30.6.6).

use crate::pac;

/// The stream the USART's transmit requests go to.
#[derive(Clone, Copy)]
pub struct TxStream {
    /// The DMA controller.
    pub dma: pac::dma::Dma,
    /// The stream (0-7).
    pub stream: usize,
    /// Its channel for the USART's TX request (RM0390 table 28: USART2_TX is DMA1 stream 6
    /// channel 4).
    pub channel: u8,
}

/// Bytes the stream has still to move (0 when it is idle).
pub fn left(s: TxStream) -> u16 {
    let st = s.dma.st(s.stream);
    if st.cr().read().en() {
        st.ndtr().read().ndt()
    } else {
        0
    }
}

/// Whether a transfer is under way (EN set: the hardware clears it at the end).
pub fn busy(s: TxStream) -> bool {
    s.dma.st(s.stream).cr().read().en()
}

/// Starts moving `len` bytes from `buf` to `usart`'s DR: the stream's flags cleared, pointed
/// at DR and `buf`, memory to peripheral, byte-wide, memory incremented, not circular, no
/// interrupt, enabled; the USART's DMA requests for transmission on (CR3.DMAT, kept with the
/// rest of CR3). False, and nothing started, while the last transfer runs or for `len` 0.
///
/// # Safety
/// `buf` must stay valid and unchanged until the stream is no longer [`busy`].
pub unsafe fn start(s: TxStream, usart: pac::usart::Usart, buf: *const u8, len: u16) -> bool {
    use pac::dma::vals::{Dir, Pl, Size};
    if len == 0 || busy(s) {
        return false;
    }
    crate::dma::point(
        s.dma,
        s.stream,
        usart.dr().as_ptr() as usize as u32,
        buf as usize as u32,
        len,
    );
    usart.cr3().modify(|w| w.set_dmat(true));
    s.dma.st(s.stream).cr().write(|w| {
        w.set_chsel(s.channel);
        w.set_dir(Dir::MEMORY_TO_PERIPHERAL);
        w.set_psize(Size::BITS8);
        w.set_msize(Size::BITS8);
        w.set_minc(true);
        w.set_pl(Pl::HIGH);
        w.set_en(true);
    });
    true
}
