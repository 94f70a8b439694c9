//! ADC1 of the STM32F4 (RM0090 §13, RM0390 §13; offsets from 0x40012000, the common
//! registers from 0x40012300): the regular sequence (SQR1.L + 1 conversions) started by an
//! external trigger (CR2.EXTEN ≠ 0, EXTSEL 1110 = TIM8's TRGO, RM0090 Table 69) or SWSTART,
//! its conversion time ((SMPR + 12) ADC clocks each, the ADC clock APB2 / ADCPRE), and DMA
//! requests (CR2.DMA). The machine takes the conversions as they finish
//! ([`Adc::take_conversion`]) and hands each to DMA2 stream 0; a conversion whose data the
//! DMA did not take sets OVR. The analog watchdog (RM0090 §13.3.7: CR1.AWDEN on the regular
//! channels, AWDSGL with AWDCH for one channel, HTR and LTR) sets SR.AWD on a conversion above
//! HTR or below LTR, and interrupts with CR1.AWDIE.

/// SR.AWD.
pub const SR_AWD: u32 = 1;
/// SR.EOC.
pub const SR_EOC: u32 = 1 << 1;
/// SR.STRT.
pub const SR_STRT: u32 = 1 << 4;
/// SR.OVR.
pub const SR_OVR: u32 = 1 << 5;
/// CR2.ADON.
const ADON: u32 = 1;
/// CR2.DMA.
pub const CR2_DMA: u32 = 1 << 8;
/// CR2.DDS.
pub const CR2_DDS: u32 = 1 << 9;
/// CR1.OVRIE.
const OVRIE: u32 = 1 << 26;
/// CR1.EOCIE.
const EOCIE: u32 = 1 << 5;
/// CR1.AWDIE.
const AWDIE: u32 = 1 << 6;
/// CR1.AWDSGL.
const AWDSGL: u32 = 1 << 9;
/// CR1.AWDEN (the regular channels).
const AWDEN: u32 = 1 << 23;
/// The trigger latency \[ADC clocks\] (DS10693 t_latr: 2 typical, 3 at most).
pub const LATENCY: u64 = 2;

/// ADC1 and the common registers.
#[derive(Debug, Clone)]
pub struct Adc {
    regs: [u32; 0x50 / 4],
    /// ADC_CCR.
    pub ccr: u32,
    /// The sequence in progress: the time its next conversion ends \[cycles\] and how many
    /// are left.
    running: Option<(u64, u32)>,
    /// The APB2 clock as a divisor of the core's (2 at 168 MHz core / 84 MHz APB2).
    pub apb2_div: u64,
    /// Set while the DMA has not yet taken the last conversion's data.
    pub dr_full: bool,
    /// The data register.
    dr: u32,
    /// The injected conversion in progress: when it ends \[cycles\].
    injected: Option<u64>,
}

/// SR.JEOC.
pub const SR_JEOC: u32 = 1 << 2;
/// SR.JSTRT.
pub const SR_JSTRT: u32 = 1 << 3;
/// CR2.JSWSTART.
const JSWSTART: u32 = 1 << 22;

const SR: usize = 0;
const CR1: usize = 1;
const CR2: usize = 2;
const SMPR1: usize = 3;
const SMPR2: usize = 4;
const HTR: usize = 9;
const LTR: usize = 10;
const SQR1: usize = 11;
const SQR3: usize = 13;
const DR: usize = 19;
const JSQR: usize = 14;
const JDR1: usize = 15;

impl Adc {
    /// The ADC at reset on a core whose APB2 clock is 1/`apb2_div` of the core's.
    pub fn new(apb2_div: u64) -> Adc {
        let mut regs = [0; 0x50 / 4];
        // HTR resets to 0x0FFF (RM0090 §13.13.7).
        regs[HTR] = 0x0FFF;
        Adc {
            regs,
            ccr: 0,
            running: None,
            apb2_div,
            dr_full: false,
            dr: 0,
            injected: None,
        }
    }

    /// The ADC clock's period \[cycles\]: APB2 / (2, 4, 6, 8 by ADCPRE).
    fn adc_clock(&self) -> u64 {
        self.apb2_div * 2 * (((self.ccr >> 16) & 3) as u64 + 1)
    }

    /// The channel of the sequence's first conversion (SQR3.SQ1).
    pub fn first_channel(&self) -> u32 {
        self.regs[SQR3] & 0x1F
    }

    /// One conversion's time \[cycles\]: the sampling time of its channel (SMPR: 3, 15, 28,
    /// 56, 84, 112, 144, 480 cycles) + 12.
    pub fn conversion_cycles(&self) -> u64 {
        self.conversion_cycles_of(self.first_channel())
    }

    /// Channel `ch`'s conversion time \[cycles\] (see [`Adc::conversion_cycles`]).
    fn conversion_cycles_of(&self, ch: u32) -> u64 {
        let smp = if ch >= 10 {
            (self.regs[SMPR1] >> (3 * (ch - 10))) & 7
        } else {
            (self.regs[SMPR2] >> (3 * ch)) & 7
        };
        let sampling = [3, 15, 28, 56, 84, 112, 144, 480][smp as usize];
        (sampling + 12) * self.adc_clock()
    }

    /// Conversions per sequence (SQR1.L + 1).
    pub fn length(&self) -> u32 {
        ((self.regs[SQR1] >> 20) & 0xF) + 1
    }

    fn on(&self) -> bool {
        self.regs[CR2] & ADON != 0
    }

    /// Whether external triggers start the sequence from TIM8's TRGO (EXTEN ≠ 0, EXTSEL =
    /// 1110).
    pub fn on_tim8_trgo(&self) -> bool {
        let exten = (self.regs[CR2] >> 28) & 3;
        let extsel = (self.regs[CR2] >> 24) & 0xF;
        self.on() && exten != 0 && extsel == 0b1110
    }

    /// A trigger at `now`: the sequence starts (ignored while one runs).
    pub fn trigger(&mut self, now: u64) {
        if !self.on() || self.running.is_some() {
            return;
        }
        self.regs[SR] |= SR_STRT;
        self.running = Some((
            now + LATENCY * self.adc_clock() + self.conversion_cycles(),
            self.length(),
        ));
    }

    /// When the next conversion ends \[cycles\] (regular or injected).
    pub fn next_event(&self) -> Option<u64> {
        match (self.running.map(|(t, _)| t), self.injected) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        }
    }

    /// The injected channel (one rank: JL = 0 converts JSQ4, RM0090 §13.13.12).
    pub fn injected_channel(&self) -> u32 {
        (self.regs[JSQR] >> 15) & 0x1F
    }

    /// Whether the conversion due at `t` is the injected one.
    pub fn injected_due(&self, t: u64) -> bool {
        self.injected.is_some_and(|i| i <= t)
    }

    /// Ends the injected conversion with the result `code`: into JDR1, JEOC set.
    pub fn take_injected(&mut self, code: u32) {
        self.injected = None;
        self.regs[JDR1] = code & 0xFFF;
        self.regs[SR] |= SR_JEOC;
    }

    /// Ends the conversion due at `t` with the result `code`: into DR, EOC set, OVR if the
    /// last result was not taken (with DMA). Returns true when the DMA must take it.
    pub fn take_conversion(&mut self, t: u64, code: u32) -> bool {
        let Some((_, left)) = self.running else {
            return false;
        };
        let dma = self.regs[CR2] & CR2_DMA != 0;
        if dma && self.dr_full {
            // The DMA did not take the previous result: overrun, the sequence stops and
            // DMA requests stop until DMA is re-enabled (RM0090 §13.8.2).
            self.regs[SR] |= SR_OVR;
            self.running = None;
            return false;
        }
        self.dr = code & 0xFFF;
        self.regs[SR] |= SR_EOC;
        // The analog watchdog: the channel converted is the sequence's (the firmware's ranks
        // all convert one channel: SQ1's).
        let cr1 = self.regs[CR1];
        let channel = self.regs[SQR3] & 0x1F;
        let watched = cr1 & AWDEN != 0 && (cr1 & AWDSGL == 0 || cr1 & 0x1F == channel);
        if watched && (self.dr > self.regs[HTR] & 0xFFF || self.dr < self.regs[LTR] & 0xFFF) {
            self.regs[SR] |= SR_AWD;
        }
        self.running = if left > 1 {
            Some((t + self.conversion_cycles(), left - 1))
        } else {
            None
        };
        if dma {
            self.dr_full = true;
        }
        dma
    }

    /// The DMA took DR (clears EOC as a read of DR does).
    pub fn dma_read(&mut self) -> u32 {
        self.dr_full = false;
        self.regs[SR] &= !SR_EOC;
        self.dr
    }

    /// The interrupt line (ADC_IRQn): OVR with OVRIE, EOC with EOCIE, AWD with AWDIE.
    pub fn irq(&self) -> bool {
        let sr = self.regs[SR];
        let cr1 = self.regs[CR1];
        (sr & SR_OVR != 0 && cr1 & OVRIE != 0)
            || (sr & SR_EOC != 0 && cr1 & EOCIE != 0)
            || (sr & SR_AWD != 0 && cr1 & AWDIE != 0)
    }

    /// Reads the register at `off` (0x300.. the common ones).
    pub fn read(&mut self, off: u32) -> u32 {
        match off {
            0x304 => self.ccr,
            0x300 => self.regs[SR] & 0x3F, // CSR mirrors ADC1's flags
            _ if off as usize / 4 == DR => {
                self.dr_full = false;
                self.regs[SR] &= !SR_EOC;
                self.dr
            }
            _ => self.regs.get(off as usize / 4).copied().unwrap_or(0),
        }
    }

    /// Writes the register at `off` at `now`.
    pub fn write(&mut self, off: u32, value: u32, now: u64) {
        match off {
            0x304 => self.ccr = value,
            0x00 => self.regs[SR] &= value, // rc_w0
            0x08 => {
                let was_on = self.on();
                self.regs[CR2] = value & !((1 << 30) | JSWSTART);
                if value & JSWSTART != 0 && was_on && self.injected.is_none() {
                    // A software start of the injected rank (RM0090 §13.3.5): a regular
                    // conversion under way is interrupted and resumed after it, its end
                    // later by the injected conversion's time.
                    let d = self.conversion_cycles_of(self.injected_channel());
                    self.injected = Some(now + LATENCY * self.adc_clock() + d);
                    self.regs[SR] |= SR_JSTRT;
                    if let Some((t, left)) = self.running {
                        self.running = Some((t + d, left));
                    }
                }
                if !self.on() {
                    self.running = None;
                    self.injected = None;
                }
                if value & (1 << 30) != 0 && was_on {
                    self.trigger(now);
                }
                if value & CR2_DMA == 0 {
                    self.dr_full = false;
                }
            }
            _ => {
                if let Some(r) = self.regs.get_mut(off as usize / 4) {
                    *r = value;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sequence_of_16_on_tim8() -> Adc {
        let mut a = Adc::new(2);
        a.write(0x304, 1 << 16, 0); // ADCPRE /4: 21 MHz at 84 MHz APB2
        a.write(0x0C, 1 << 0, 0); // SMPR1: channel 10 at 15 cycles
        a.write(0x2C, 15 << 20, 0); // L = 15: 16 conversions
        a.write(0x34, 10, 0); // SQ1 = channel 10
        a.write(
            0x08,
            ADON | CR2_DMA | CR2_DDS | (1 << 28) | (0b1110 << 24),
            0,
        );
        a
    }

    /// The analog watchdog on the sequence's channel with HTR 4094 and LTR 1: a conversion
    /// at either end of the range sets AWD (not one inside), which stays until written 0
    /// (rc_w0: writing 1 to the other flags leaves them); off, or on another channel, never.
    #[test]
    fn the_analog_watchdog_flags_a_conversion_at_either_end() {
        let run = |cr1: u32, codes: &[u32]| {
            let mut a = sequence_of_16_on_tim8();
            a.write(0x24, 4094, 0);
            a.write(0x28, 1, 0);
            a.write(0x04, cr1, 0);
            a.trigger(0);
            for &c in codes {
                assert!(a.take_conversion(a.next_event().unwrap(), c));
                a.dma_read();
            }
            a.read(0) & SR_AWD != 0
        };
        let on = AWDEN | AWDSGL | 10;
        assert!(!run(on, &[1, 2048, 4094]));
        assert!(run(on, &[2048, 4095, 2048]));
        assert!(run(on, &[2048, 0]));
        assert!(!run(0, &[0, 4095]));
        assert!(!run(AWDEN | AWDSGL | 11, &[0, 4095]));
        assert!(run(AWDEN | 11, &[0]));
        let mut a = sequence_of_16_on_tim8();
        a.write(0x28, 1, 0);
        a.write(0x04, on | AWDIE, 0);
        a.trigger(0);
        a.take_conversion(a.next_event().unwrap(), 0);
        assert!(a.irq());
        a.write(0x00, 0x3E, 0);
        assert_eq!(a.read(0) & SR_AWD, 0);
        assert_ne!(a.read(0) & SR_EOC, 0);
    }

    #[test]
    fn a_trigger_runs_the_sequence_at_the_conversion_time() {
        let mut a = sequence_of_16_on_tim8();
        assert!(a.on_tim8_trgo());
        assert_eq!(a.length(), 16);
        // (15 + 12) ADC clocks of 8 core cycles (168 MHz / 21 MHz).
        assert_eq!(a.conversion_cycles(), 27 * 8);
        a.trigger(1000);
        let mut t = a.next_event().unwrap();
        assert_eq!(t, 1000 + 2 * 8 + 27 * 8);
        for k in 0..16 {
            assert!(a.take_conversion(t, 2048 + k));
            assert_eq!(a.dma_read(), 2048 + k);
            if let Some(n) = a.next_event() {
                assert_eq!(n - t, 27 * 8);
                t = n;
            }
        }
        assert_eq!(a.next_event(), None);
        assert_eq!(a.read(0) & SR_OVR, 0);
    }

    #[test]
    fn a_result_the_dma_does_not_take_overruns() {
        let mut a = sequence_of_16_on_tim8();
        a.write(0x04, OVRIE, 0);
        a.trigger(0);
        let t = a.next_event().unwrap();
        assert!(a.take_conversion(t, 1));
        let t = a.next_event().unwrap();
        assert!(!a.take_conversion(t, 2));
        assert_ne!(a.read(0) & SR_OVR, 0);
        assert!(a.irq());
        assert_eq!(a.next_event(), None, "the sequence stopped");
    }

    /// A software-started injected conversion (JSWSTART) of JSQ4's channel ends after the
    /// trigger latency and its channel's conversion time, JSTRT at the start, JEOC and JDR1 at
    /// the end; a regular sequence under way is delayed by it (RM0090 §13.3.5).
    #[test]
    fn an_injected_conversion_delays_the_regular_one_it_interrupts() {
        let mut a = Adc::new(2);
        a.write(0x304, 1 << 16, 0); // ADCPRE /4: an ADC clock of 8 core cycles
        a.write(0x0C, (1 << 0) | (4 << 3), 0); // SMPR1: ch 10 at 15, ch 11 at 84 cycles
        a.write(0x34, 10, 0); // SQ1 = 10, one conversion
        a.write(0x38, 11 << 15, 0); // JL 0, JSQ4 = 11
        a.write(0x08, 1, 0); // ADON
        a.trigger(1000);
        let regular = a.next_event().unwrap();
        assert_eq!(regular, 1000 + (LATENCY + 15 + 12) * 8);
        a.write(0x08, 1 | (1 << 22), 1010);
        assert_ne!(a.read(0x00) & SR_JSTRT, 0);
        assert_eq!(a.read(0x08) & (1 << 22), 0, "JSWSTART clears itself");
        let inj = 1010 + (LATENCY + 84 + 12) * 8;
        assert_eq!(a.next_event(), Some(inj.min(regular + 96 * 8)));
        assert!(!a.injected_due(inj - 1) && a.injected_due(inj));
        a.take_injected(931);
        assert_ne!(a.read(0x00) & SR_JEOC, 0);
        assert_eq!(a.read(0x3C), 931);
        assert_eq!(
            a.next_event(),
            Some(regular + 96 * 8),
            "the regular one resumed later"
        );
    }
}
