//! What the UART's two DMA streams (`uart_rx`, `uart_tx`) set up alike: a stopped stream's
//! flags cleared and its addresses and count written (RM0090 §10.5.3-10.5.10).

use crate::pac;

/// Stream `stream` of `dma` (stopped) pointed at the peripheral register `par` and the memory
/// `m0ar` for `ndt` items, its six flags cleared (in LIFCR for streams 0-3, HIFCR for 4-7),
/// direct mode (FCR 0). The caller writes CR.
pub(crate) fn point(dma: pac::dma::Dma, stream: usize, par: u32, m0ar: u32, ndt: u16) {
    let st = dma.st(stream);
    let (reg, shift) = (stream / 4, [0, 6, 16, 22][stream % 4]);
    dma.ifcr(reg)
        .write_value(pac::dma::regs::Ixr(0x3D << shift));
    st.par().write_value(par);
    st.m0ar().write_value(m0ar);
    st.ndtr().write(|w| w.set_ndt(ndt));
    st.fcr().write_value(pac::dma::regs::Fcr(0));
}
