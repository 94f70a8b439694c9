//! The current-sense chain: ADC1's regular sequence of conversions of one channel started by
//! TIM8's trigger output, moved by DMA2 stream 0 into a buffer, circularly, its
//! transfer-complete interrupt the control interrupt.

use core::cell::UnsafeCell;

use gms_core::drive::Stall;

use crate::pac;

/// The DMA's destination: the last sequence of conversions. Written only by the DMA, read only
/// with volatile reads after its transfer-complete flag.
pub struct SenseBuf<const N: usize>(UnsafeCell<[u16; N]>);

// SAFETY: the CPU only reads it (volatile), the DMA only writes it.
unsafe impl<const N: usize> Sync for SenseBuf<N> {}

impl<const N: usize> SenseBuf<N> {
    /// Zeroed.
    pub const fn new() -> Self {
        SenseBuf(UnsafeCell::new([0; N]))
    }

    /// Its address, for the DMA.
    pub fn addr(&self) -> u32 {
        self.0.get() as usize as u32
    }

    /// The sum of its codes (volatile reads: the DMA writes them).
    #[inline(always)]
    pub fn sum(&self) -> u32 {
        let base = self.0.get() as *const u16;
        let mut sum = 0u32;
        for i in 0..N {
            // SAFETY: in bounds of the buffer; volatile, as the DMA writes it.
            sum += unsafe { core::ptr::read_volatile(base.add(i)) } as u32;
        }
        sum
    }

    /// Writes the codes as the DMA would (for a model of it).
    pub fn fill(&self, codes: &[u16; N]) {
        let base = self.0.get() as *mut u16;
        for (i, c) in codes.iter().enumerate() {
            // SAFETY: in bounds; nothing else writes while a model fills it.
            unsafe { core::ptr::write_volatile(base.add(i), *c) };
        }
    }
}

impl<const N: usize> Default for SenseBuf<N> {
    fn default() -> Self {
        Self::new()
    }
}

/// The registers of the chain.
#[derive(Clone, Copy)]
pub struct SenseRegs {
    /// RCC (DMA2's clock).
    pub rcc: pac::rcc::Rcc,
    /// The sense pin's port (GPIOC).
    pub gpio: pac::gpio::Gpio,
    /// DMA2.
    pub dma: pac::dma::Dma,
    /// ADC1.
    pub adc: pac::adc::Adc,
}

/// The chain's layout.
#[derive(Clone, Copy, Debug)]
pub struct SenseLayout {
    /// The pin of the sense input on its port (PC0: 0).
    pub pin: usize,
    /// Its ADC channel (PC0 = ADC123_IN10: 10; 10 to 18 are sampled through SMPR1).
    pub channel: u8,
    /// Conversions per sequence (1 to 16).
    pub conversions: u8,
    /// The analog watchdog's low and high thresholds \[code\] (LTR, HTR; at most
    /// [`TOP_CODE`]): a conversion below the first or above the second sets SR.AWD. The
    /// board's are the ends of its amplifier's linear range (gms-core's
    /// `SenseChain::watchdog_codes`).
    pub watchdog: (u16, u16),
}

/// The ADC's highest code at 12 bits (CR1.RES = 00, RM0090 §13.13.2).
pub const TOP_CODE: u16 = 4095;

/// DMA2's stream the ADC1 requests go to (stream 0 channel 0, RM0090 table 43).
pub const STREAM: usize = 0;

/// Sets up the chain (the module's notes), the DMA moving into `buf` (its address, room for
/// `layout.conversions` codes), with its transfer-complete, transfer-error and direct-mode
/// error interrupts enabled in the stream (the NVIC decides when they run), and the ADC's
/// overrun interrupt. ADC1 is already clocked, prescaled and on (embassy's `Adc::new`).
pub fn init(r: SenseRegs, layout: SenseLayout, buf: u32) {
    use pac::adc::vals::{Dds, Eocs, Exten, Res, SampleTime};
    use pac::dma::vals::{Dir, Size};
    let n = layout.conversions.clamp(1, 16);
    // The pin analog (RM0090 §8.4.1: MODER = 11).
    r.gpio
        .moder()
        .modify(|w| w.set_moder(layout.pin, pac::gpio::vals::Moder::ANALOG));
    // The stream, disabled while configured (RM0090 §10.3.17).
    r.rcc.ahb1enr().modify(|w| w.set_dma2en(true));
    let st = r.dma.st(STREAM);
    st.cr().modify(|w| w.set_en(false));
    while st.cr().read().en() {}
    ack(r.dma);
    st.par().write_value(r.adc.dr().as_ptr() as usize as u32);
    st.m0ar().write_value(buf);
    st.ndtr().write(|w| w.set_ndt(n as u16));
    st.cr().write(|w| {
        w.set_chsel(0);
        w.set_dir(Dir::PERIPHERAL_TO_MEMORY);
        w.set_psize(Size::BITS16);
        w.set_msize(Size::BITS16);
        w.set_minc(true);
        w.set_circ(true);
        w.set_tcie(true);
        // A transfer error (a bus error: the stream stops, EN cleared) and a direct-mode
        // error (RM0090 §10.3.18) interrupt too, on the same vector, checked first.
        w.set_teie(true);
        w.set_dmeie(true);
        w.set_en(true);
    });
    // ADC1 (RM0090 §13.13): 12 bits, a scan of `n` ranks of the channel, each sampled 15
    // cycles; DMA requests continuing after each sequence (DDS); EOC per sequence; started by
    // the rising edge of TIM8_TRGO (EXTSEL = 1110, §13.13.3 table "External trigger for
    // regular channels"). An overrun (a conversion lost: the ADC stops its DMA requests until
    // OVR is cleared, §13.8.1) interrupts on the ADC vector.
    let adc = r.adc;
    // The analog watchdog on the channel (RM0090 §13.3.7, §13.13.2 ADC_CR1, §13.13.7-8
    // HTR/LTR, 12 bits each): a conversion above HTR or below LTR (the layout's: the ends of
    // the amplifier's linear range) sets SR.AWD, which the control step reads ([`clipped`]);
    // no interrupt (a clipped channel would raise one per conversion). Its thresholds first,
    // then CR1 in one read-modify-write.
    let (low, high) = layout.watchdog;
    adc.htr().write(|w| w.set_ht(high.min(TOP_CODE)));
    adc.ltr().write(|w| w.set_lt(low.min(TOP_CODE)));
    adc.cr1().modify(|w| {
        w.set_res(Res::BITS12);
        w.set_scan(true);
        w.set_eocie(false);
        w.set_ovrie(true);
        w.set_awdch(layout.channel);
        w.set_awdsgl(pac::adc::vals::Awdsgl::SINGLE_CHANNEL);
        w.set_awden(true);
        w.set_awdie(false);
    });
    if layout.channel >= 10 {
        adc.smpr1()
            .modify(|w| w.set_smp((layout.channel - 10) as usize, SampleTime::CYCLES15));
    } else {
        adc.smpr2()
            .modify(|w| w.set_smp(layout.channel as usize, SampleTime::CYCLES15));
    }
    // Ranks 1-6 in SQR3, 7-12 in SQR2, 13-16 in SQR1; L = ranks - 1.
    adc.sqr3().write(|w| {
        for i in 0..6 {
            w.set_sq(i, layout.channel);
        }
    });
    adc.sqr2().write(|w| {
        for i in 0..6 {
            w.set_sq(i, layout.channel);
        }
    });
    adc.sqr1().write(|w| {
        for i in 0..4 {
            w.set_sq(i, layout.channel);
        }
        w.set_l(n - 1);
    });
    adc.cr2().modify(|w| {
        w.set_cont(false);
        w.set_dma(true);
        w.set_dds(Dds::CONTINUOUS);
        w.set_eocs(Eocs::EACH_SEQUENCE);
        w.set_extsel(0b1110);
        w.set_exten(Exten::RISING_EDGE);
        w.set_adon(true);
    });
}

/// ADC_SR written to clear AWD alone: rc_w0 flags in bits 0-5 (AWD, EOC, JEOC, JSTRT,
/// STRT, OVR), 1 leaves a flag, 0 clears it; reserved bits 0 (RM0090 §13.13.1). Not a
/// read-modify-write, which would clear a flag set between the read and the write.
pub const SR_CLEAR_AWD: u32 = 0x3E;

/// True when a conversion since the last call read at an end of the ADC's range (SR.AWD,
/// [`init`]'s watchdog); the flag cleared.
#[inline(always)]
pub fn clipped(adc: pac::adc::Adc) -> bool {
    let hit = adc.sr().read().awd();
    if hit {
        adc.sr().write(|w| w.0 = SR_CLEAR_AWD);
    }
    hit
}

/// Clears the stream's flags (LIFCR, RM0090 §10.5.3).
#[inline(always)]
pub fn ack(dma: pac::dma::Dma) {
    dma.ifcr(STREAM / 4).write(|w| {
        w.set_tcif(STREAM % 4, true);
        w.set_htif(STREAM % 4, true);
        w.set_teif(STREAM % 4, true);
        w.set_dmeif(STREAM % 4, true);
        w.set_feif(STREAM % 4, true);
    });
}

/// True when the stream has written part of the next sequence already (NDTR below the
/// sequence's `n` conversions; RM0090 §10.5.6: NDTR counts down per item and, circular, is
/// reloaded at the end): the buffer summed now would mix two periods' conversions. Read right
/// after the sum.
#[inline(always)]
pub fn next_sequence_started(dma: pac::dma::Dma, n: u16) -> bool {
    dma.st(STREAM).ndtr().read().ndt() != n
}

/// True when a sequence has completed (TCIF).
#[inline(always)]
pub fn complete(dma: pac::dma::Dma) -> bool {
    dma.isr(STREAM / 4).read().tcif(STREAM % 4)
}

/// What the stream's error flags say (TEIF, DMEIF): [`Stall::DmaError`] or none.
#[inline(always)]
pub fn dma_error(dma: pac::dma::Dma) -> Stall {
    let isr = dma.isr(STREAM / 4).read();
    Stall::from_sense_flags(isr.teif(STREAM % 4), isr.dmeif(STREAM % 4), false)
}

/// The ADC's overrun: [`Stall::AdcOverrun`] if OVR is set; the overrun interrupt off and the
/// flag cleared either way (the caller switches the bridge off for good).
pub fn adc_overrun(adc: pac::adc::Adc) -> Stall {
    let stall = Stall::from_sense_flags(false, false, adc.sr().read().ovr());
    adc.cr1().modify(|w| w.set_ovrie(false));
    adc.sr().modify(|w| w.set_ovr(false));
    stall
}

/// Waits for the next sequence, at most `limit_cycles` of `now` (a free-running cycle
/// counter), for the start-up calibration while the control interrupt is off; its sum, or
/// `None` if none came (the ADC is not triggered or its DMA stopped).
pub fn next_sum<const N: usize>(
    dma: pac::dma::Dma,
    buf: &SenseBuf<N>,
    mut now: impl FnMut() -> u32,
    limit_cycles: u32,
) -> Option<u32> {
    ack(dma);
    let t0 = now();
    loop {
        if complete(dma) {
            ack(dma);
            return Some(buf.sum());
        }
        if now().wrapping_sub(t0) > limit_cycles {
            return None;
        }
    }
}

/// The motor supply's divider as an injected conversion of the sense ADC: its pin analog,
/// sampled 84 cycles (4 µs at 21 MHz: the divider's ~9.4 kΩ source, RM0090 §13.3.11 and the
/// datasheet's R_AIN), one injected rank (ADC_JSQR: JL = 0 converts JSQ4, RM0090 §13.13.12)
/// started by software (JEXTEN = 00). The regular sequence (the current's) is untouched; an
/// injected conversion started while it runs would reset and resume it (§13.3.5), so the
/// control step starts it right after the sequence it read ([`supply_start`]).
pub fn supply_init(adc: pac::adc::Adc, gpio: pac::gpio::Gpio, pin: usize, channel: u8) {
    use pac::adc::vals::{Exten, SampleTime};
    gpio.moder()
        .modify(|w| w.set_moder(pin, pac::gpio::vals::Moder::ANALOG));
    if channel >= 10 {
        adc.smpr1()
            .modify(|w| w.set_smp((channel - 10) as usize, SampleTime::CYCLES84));
    } else {
        adc.smpr2()
            .modify(|w| w.set_smp(channel as usize, SampleTime::CYCLES84));
    }
    adc.jsqr().write(|w| {
        w.set_jl(0);
        w.set_jsq(3, channel);
    });
    adc.cr2().modify(|w| w.set_jexten(Exten::DISABLED));
}

/// Starts the supply's injected conversion (ADC_CR2.JSWSTART, RM0090 §13.13.3).
#[inline(always)]
pub fn supply_start(adc: pac::adc::Adc) {
    adc.cr2().modify(|w| w.set_jswstart(true));
}

/// The supply's latest code (ADC_JDR1, §13.13.14: it holds the last injected conversion's
/// result, 0 from reset until the first), read from any context: SR.JEOC is left alone
/// (its interrupt is not enabled), so no flag is written that the control step's own
/// writes of ADC_SR could race.
#[inline(always)]
pub fn supply_latest(adc: pac::adc::Adc) -> u16 {
    adc.jdr(0).read().jdata()
}
