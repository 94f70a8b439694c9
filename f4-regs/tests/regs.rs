//! The register-level shell run over stm32-metapac register blocks laid on plain memory: the
//! fields each function leaves are read back against RM0090; the functions that wait on the
//! hardware run against models of it (a centre-aligned TIM8, a dead DMA, an HSE that never
//! comes).

use f4_regs::pac;
use f4_regs::{clock, pwm, remap, sense};
use gms_core::drive::{Deadman, Stall, bridge_off};

/// A register block on zeroed memory (1 KiB: more than any block used here spans).
fn block<T>(make: unsafe fn(*mut ()) -> T) -> T {
    let mem: &'static mut [u32; 256] = Box::leak(Box::new([0u32; 256]));
    // SAFETY: the memory lives for the program, is word-aligned and large enough; nothing
    // else reaches it.
    unsafe { make(mem.as_mut_ptr() as *mut ()) }
}

/// The raw word at byte offset `off` of a block.
fn word(ptr: *mut (), off: usize) -> u32 {
    // SAFETY: within the block's memory (see `block`).
    unsafe { core::ptr::read_volatile((ptr as *const u8).add(off) as *const u32) }
}

fn set_word(ptr: *mut (), off: usize, v: u32) {
    // SAFETY: within the block's memory (see `block`).
    unsafe { core::ptr::write_volatile((ptr as *mut u8).add(off) as *mut u32, v) }
}

fn sense_regs() -> sense::SenseRegs {
    sense::SenseRegs {
        rcc: block(pac::rcc::Rcc::from_ptr),
        gpio: block(pac::gpio::Gpio::from_ptr),
        dma: block(pac::dma::Dma::from_ptr),
        adc: block(pac::adc::Adc::from_ptr),
    }
}

const LAYOUT: sense::SenseLayout = sense::SenseLayout {
    pin: 0,
    channel: 10,
    conversions: 16,
    watchdog: (249, 3846),
};

#[test]
fn the_sense_chain_is_set_up_as_rm0090_says() {
    use pac::adc::vals::{Dds, Eocs, Exten, Res, SampleTime};
    use pac::dma::vals::{Dir, Size};
    let r = sense_regs();
    let buf: sense::SenseBuf<16> = sense::SenseBuf::new();
    sense::init(r, LAYOUT, buf.addr());
    // PC0 analog, DMA2 clocked.
    assert_eq!(
        r.gpio.moder().read().moder(0),
        pac::gpio::vals::Moder::ANALOG
    );
    assert!(r.rcc.ahb1enr().read().dma2en());
    // DMA2 stream 0: channel 0 (ADC1, RM0090 table 43), peripheral to memory, 16-bit both
    // sides, memory increment, circular, 16 transfers, from ADC1_DR (offset 0x4C) into the
    // buffer, every interrupt that matters enabled, on.
    let st = r.dma.st(0);
    let cr = st.cr().read();
    assert_eq!(cr.chsel(), 0);
    assert_eq!(cr.dir(), Dir::PERIPHERAL_TO_MEMORY);
    assert_eq!((cr.psize(), cr.msize()), (Size::BITS16, Size::BITS16));
    assert!(cr.minc() && cr.circ() && cr.en());
    assert!(cr.tcie() && cr.teie() && cr.dmeie());
    assert!(!cr.htie());
    assert_eq!(st.ndtr().read().ndt(), 16);
    assert_eq!(st.par().read(), r.adc.as_ptr() as usize as u32 + 0x4C);
    assert_eq!(st.m0ar().read(), buf.addr());
    // The stream's flags cleared (LIFCR written with stream 0's five bits: 0x3D).
    assert_eq!(word(r.dma.as_ptr(), 0x08) & 0x3D, 0x3D);
    // ADC1: 12 bits, scan, overrun interrupt on; 16 ranks of channel 10 sampled 15 cycles;
    // single sequences started by TIM8_TRGO's rising edge (EXTSEL 1110), DMA with DDS, EOC
    // per sequence, on.
    let cr1 = r.adc.cr1().read();
    assert_eq!(cr1.res(), Res::BITS12);
    assert!(cr1.scan() && cr1.ovrie() && !cr1.eocie());
    assert_eq!(r.adc.smpr1().read().smp(0), SampleTime::CYCLES15);
    assert_eq!(r.adc.sqr1().read().l(), 15);
    let mut ranks = Vec::new();
    for i in 0..6 {
        ranks.push(r.adc.sqr3().read().sq(i));
    }
    for i in 0..6 {
        ranks.push(r.adc.sqr2().read().sq(i));
    }
    for i in 0..4 {
        ranks.push(r.adc.sqr1().read().sq(i));
    }
    assert_eq!(ranks, vec![10u8; 16]);
    // The analog watchdog on channel 10 alone, no interrupt, at the layout's thresholds
    // (LTR, HTR: RM0090 §13.13.7-8).
    assert!(cr1.awden() && !cr1.awdie());
    assert_eq!(cr1.awdsgl(), pac::adc::vals::Awdsgl::SINGLE_CHANNEL);
    assert_eq!(cr1.awdch(), 10);
    assert_eq!(
        (r.adc.ltr().read().lt(), r.adc.htr().read().ht()),
        (249, 3846)
    );
    let cr2 = r.adc.cr2().read();
    assert_eq!(cr2.extsel(), 0b1110);
    assert_eq!(cr2.exten(), Exten::RISING_EDGE);
    assert_eq!(cr2.dds(), Dds::CONTINUOUS);
    assert_eq!(cr2.eocs(), Eocs::EACH_SEQUENCE);
    assert!(cr2.dma() && cr2.adon() && !cr2.cont());
}

/// A dead DMA (TCIF never set): each wait ends after its bound of the cycle counter, and the
/// whole calibration after one wait; a live one returns the buffer's sum and clears the flags.
#[test]
fn a_dead_dma_costs_one_bounded_wait() {
    use gms_core::device::{SenseTrouble, calibrate_sense};
    let r = sense_regs();
    let buf: sense::SenseBuf<16> = sense::SenseBuf::new();
    buf.fill(&[2048; 16]);
    let limit = 168_000u32; // 1 ms at 168 MHz
    // The cycle counter: 40 cycles per read (a poll of the flag in between).
    let mut clock = 0u32;
    let mut reads = 0u64;
    let board = hil_board();
    let z = calibrate_sense(&board, 3.4, || {
        sense::next_sum(
            r.dma,
            &buf,
            || {
                reads += 1;
                clock = clock.wrapping_add(40);
                clock
            },
            limit,
        )
    });
    assert_eq!(z.trouble, SenseTrouble::NoSamples { taken: 0 });
    // One wait: the first read, then reads until 1 ms has passed.
    assert_eq!(reads, 1 + (limit as u64 / 40) + 1);
    // Alive: TCIF (LISR bit 5) set by the "DMA".
    set_word(r.dma.as_ptr(), 0x00, 1 << 5);
    let got = sense::next_sum(r.dma, &buf, || 0, limit);
    assert_eq!(got, Some(16 * 2048));
    assert_eq!(word(r.dma.as_ptr(), 0x08) & 0x3D, 0x3D, "flags cleared");
}

/// The chain's errors: TEIF or DMEIF of stream 0 (LISR bits 3 and 2), the ADC's OVR (SR bit 5).
#[test]
fn a_sequence_under_way_is_seen_from_the_streams_count() {
    let dma = block(pac::dma::Dma::from_ptr);
    // Reloaded to the sequence's 8 after its end: not started.
    dma.st(sense::STREAM).ndtr().write(|w| w.set_ndt(8));
    assert!(!sense::next_sequence_started(dma, 8));
    // One conversion of the next one written.
    dma.st(sense::STREAM).ndtr().write(|w| w.set_ndt(7));
    assert!(sense::next_sequence_started(dma, 8));
}

#[test]
fn the_sense_chain_reports_its_errors() {
    let r = sense_regs();
    assert_eq!(sense::dma_error(r.dma), Stall::None);
    set_word(r.dma.as_ptr(), 0x00, 1 << 3);
    assert_eq!(sense::dma_error(r.dma), Stall::DmaError);
    set_word(r.dma.as_ptr(), 0x00, 1 << 2);
    assert_eq!(sense::dma_error(r.dma), Stall::DmaError);
    set_word(r.dma.as_ptr(), 0x00, 1 << 5);
    assert_eq!(sense::dma_error(r.dma), Stall::None, "TCIF is not an error");
    r.adc.cr1().modify(|w| w.set_ovrie(true));
    assert_eq!(sense::adc_overrun(r.adc), Stall::None);
    r.adc.cr1().modify(|w| w.set_ovrie(true));
    set_word(r.adc.as_ptr(), 0x00, 1 << 5);
    assert_eq!(sense::adc_overrun(r.adc), Stall::AdcOverrun);
    assert!(!r.adc.cr1().read().ovrie(), "the interrupt off");
    assert!(!r.adc.sr().read().ovr(), "the flag cleared");
}

/// The F405 board as gms-core describes it (16 conversions around code 2048).
fn hil_board() -> gms_core::device::Board {
    gms_core::boards::f405::BOARD
}

#[test]
fn tim8_idle_levels_trigger_compares_and_timing() {
    let tim = block(pac::timer::TimAdv::from_ptr);
    // Idle levels low whenever MOE is cleared.
    tim.cr2().modify(|w| {
        w.set_ois(0, true);
        w.set_ois(1, true);
    });
    pwm::idle_low(tim);
    assert_eq!(tim.bdtr().read().ossi(), pac::timer::vals::Ossi::IDLE_LEVEL);
    assert!(!tim.cr2().read().ois(0) && !tim.cr2().read().ois(1));
    // The sense trigger: OC4 in PWM mode 1, preloaded, CCR4 the lead, TRGO = OC4REF.
    pwm::sense_trigger(tim, 877);
    assert_eq!(
        tim.ccmr_output(1).read().ocm(1),
        pac::timer::vals::Ocm::PWM_MODE1
    );
    assert!(tim.ccmr_output(1).read().ocpe(1));
    assert_eq!(tim.ccr(3).read().ccr(), 877);
    assert_eq!(tim.cr2().read().mms(), pac::timer::vals::Mms::COMPARE_OC4);
    // Compare values clamped to 16 bits.
    pwm::set_bridge(tim, 4201, 70_000);
    assert_eq!(
        (tim.ccr(0).read().ccr(), tim.ccr(1).read().ccr()),
        (4201, 65535)
    );
    // Timing: the period clamped to the board's largest, the lead below it.
    pwm::set_timing(tim, 3, 70_000, 65_534, 100_000);
    assert_eq!(tim.psc().read(), 3);
    assert_eq!(tim.arr().read().arr(), 65_534);
    assert_eq!(tim.ccr(3).read().ccr(), 65_533);
    pwm::set_timing(tim, 0, 4200, 65_534, 877);
    assert_eq!(
        (tim.arr().read().arr(), tim.ccr(3).read().ccr()),
        (4200, 877)
    );
}

#[test]
fn the_bridge_goes_off_on_its_registers() {
    let tim = block(pac::timer::TimAdv::from_ptr);
    let gpio = block(pac::gpio::Gpio::from_ptr);
    tim.bdtr().modify(|w| w.set_moe(true));
    // PC6/PC7 as alternate functions (MODER = 10), PC0 analog (11): only 6 and 7 change.
    gpio.moder().write(|w| {
        w.set_moder(6, pac::gpio::vals::Moder::ALTERNATE);
        w.set_moder(7, pac::gpio::vals::Moder::ALTERNATE);
        w.set_moder(0, pac::gpio::vals::Moder::ANALOG);
    });
    pwm::low_speed(gpio, [6, 7]);
    assert_eq!(
        gpio.ospeedr().read().ospeedr(6),
        pac::gpio::vals::Ospeedr::LOW_SPEED
    );
    let mut b = pwm::BridgeRegs {
        tim,
        gpio,
        pins: [6, 7],
    };
    bridge_off(&mut b);
    assert!(!tim.bdtr().read().moe());
    // BSRR: BR6 and BR7 (bits 22 and 23), nothing set.
    assert_eq!(word(gpio.as_ptr(), 0x18), (1 << 22) | (1 << 23));
    assert_eq!(gpio.moder().read().moder(6), pac::gpio::vals::Moder::OUTPUT);
    assert_eq!(gpio.moder().read().moder(7), pac::gpio::vals::Moder::OUTPUT);
    assert_eq!(gpio.moder().read().moder(0), pac::gpio::vals::Moder::ANALOG);
}

#[test]
fn the_break_input_is_on_for_the_clock_failure_alone() {
    let tim = block(pac::timer::TimAdv::from_ptr);
    // As embassy leaves it: MOE set, OSSI set by `idle_low`.
    tim.bdtr().modify(|w| w.set_moe(true));
    pwm::idle_low(tim);
    pwm::break_on_clock_failure(tim);
    let bdtr = word(tim.as_ptr(), 0x44);
    // BKE (bit 12), BKP (bit 13, active high), AOE (bit 14) clear, MOE (bit 15) and OSSI
    // (bit 10) kept.
    assert_eq!(bdtr & (1 << 12), 1 << 12, "BKE");
    assert_eq!(bdtr & (1 << 13), 1 << 13, "BKP active high");
    assert_eq!(
        bdtr & (1 << 14),
        0,
        "AOE clear: MOE stays off after a break"
    );
    assert_eq!(bdtr & ((1 << 15) | (1 << 10)), (1 << 15) | (1 << 10));
}

#[test]
fn the_deadman_tick_clears_its_flag_and_stops_after_a_trip() {
    let tim = block(pac::timer::TimAdv::from_ptr);
    pwm::deadman_arm(tim);
    assert!(tim.dier().read().uie());
    let mut d = Deadman::new();
    let mut steps = 0;
    for _ in 0..10 {
        set_word(tim.as_ptr(), 0x10, 1); // UIF
        assert!(!pwm::deadman_tick(tim, &mut d, steps));
        assert_eq!(
            word(tim.as_ptr(), 0x10),
            pwm::SR_CLEAR_UIF,
            "UIF cleared alone"
        );
        steps += 1;
    }
    assert!(!pwm::deadman_tick(tim, &mut d, steps));
    assert!(!pwm::deadman_tick(tim, &mut d, steps));
    assert!(pwm::deadman_tick(tim, &mut d, steps));
    assert!(
        !tim.dier().read().uie(),
        "the update interrupt off after the trip"
    );
}

/// A model of TIM8 counting centre-aligned (RM0090 §17.3.3): up from 0 to ARR (an overflow,
/// then down), down to 0 (an underflow, then up); at each turning point the repetition
/// counter, if at 0, makes an update and reloads from RCR, else counts down. The CPU's polls
/// advance it by `per_poll` timer clocks.
struct CentreAligned {
    cnt: u32,
    up: bool,
    arr: u32,
    rep_cnt: u8,
    rcr: u8,
    uif: bool,
    per_poll: u32,
    /// Where each update came: true at the bottom.
    updates: Vec<bool>,
}

impl CentreAligned {
    fn tick(&mut self) {
        let turned = if self.up {
            self.cnt += 1;
            self.cnt >= self.arr
        } else {
            self.cnt -= 1;
            self.cnt == 0
        };
        if turned {
            let at_bottom = !self.up;
            self.up = !self.up;
            if self.rep_cnt == 0 {
                self.uif = true;
                self.rep_cnt = self.rcr;
                self.updates.push(at_bottom);
            } else {
                self.rep_cnt -= 1;
            }
        }
    }
}

impl pwm::UpdateTimer for CentreAligned {
    fn clear_update(&mut self) {
        self.uif = false;
    }
    fn update_pending(&mut self) -> bool {
        for _ in 0..self.per_poll {
            self.tick();
        }
        self.uif
    }
    fn counting_up(&mut self) -> bool {
        self.tick();
        self.up
    }
    fn set_repetition(&mut self, rep: u8) {
        self.rcr = rep;
    }
}

/// From every starting phase (counter value, direction, repetition counter and its reload)
/// and several poll speeds, the alignment ends with exactly one update per period, at the
/// bottom, and says so.
#[test]
fn the_update_is_put_at_the_bottom_from_every_phase() {
    let arr = 60u32;
    let mut runs = 0;
    for per_poll in [1u32, 3, 7] {
        for start in 1..arr {
            for up in [true, false] {
                for (rep_cnt, rcr) in [(0u8, 0u8), (1, 1), (0, 1), (1, 0)] {
                    let mut t = CentreAligned {
                        cnt: start,
                        up,
                        arr,
                        rep_cnt,
                        rcr,
                        uif: false,
                        per_poll,
                        updates: Vec::new(),
                    };
                    assert!(
                        pwm::align_update_to_bottom(&mut t, 10_000),
                        "start {start} up {up} rep {rep_cnt}/{rcr} per poll {per_poll}"
                    );
                    // Ten more periods: ten updates, all at the bottom.
                    let before = t.updates.len();
                    for _ in 0..10 * 2 * arr {
                        t.tick();
                    }
                    let after = &t.updates[before..];
                    assert_eq!(after.len(), 10, "one update per period");
                    assert!(after.iter().all(|&b| b), "at the bottom: {after:?}");
                    runs += 1;
                }
            }
        }
    }
    assert_eq!(runs, 3 * 59 * 2 * 4);
}

/// With no update at all (the timer not running) the alignment says it failed, within its
/// polls.
#[test]
fn a_stopped_timer_fails_the_alignment() {
    let mut t = CentreAligned {
        cnt: 5,
        up: true,
        arr: 60,
        rep_cnt: 0,
        rcr: 0,
        uif: false,
        per_poll: 0,
        updates: Vec::new(),
    };
    assert!(!pwm::align_update_to_bottom(&mut t, 1000));
}

#[test]
fn the_hse_is_waited_for_within_its_bound() {
    let rcc = block(pac::rcc::Rcc::from_ptr);
    let mut clock = 0u32;
    let mut reads = 0u32;
    let ok = clock::start_hse(
        rcc,
        true,
        || {
            reads += 1;
            clock = clock.wrapping_add(10);
            clock
        },
        1_600_000,
    );
    assert!(!ok);
    assert_eq!(reads, 1 + 160_000 + 1);
    assert!(rcc.cr().read().hsebyp(), "bypass as asked");
    assert!(!rcc.cr().read().hseon(), "switched off again");
    // Ready at once (HSERDY, bit 17, set by the "oscillator"): true, HSE on, a crystal.
    rcc.cr().modify(|w| w.set_hserdy(true));
    assert!(clock::start_hse(rcc, false, || 0, 1_600_000));
    assert!(rcc.cr().read().hseon() && !rcc.cr().read().hsebyp());
}

#[test]
fn the_flash_accelerator_and_erase_set_up() {
    let flash = block(pac::flash::Flash::from_ptr);
    // An F405 of revision Z: prefetch on; of revision A, or an unreadable IDCODE: off.
    assert!(clock::flash_accelerator(flash, 0x1001_6413, 0x413));
    let acr = flash.acr().read();
    assert!(acr.prften() && acr.icen() && acr.dcen());
    assert!(!clock::flash_accelerator(flash, 0x1000_6413, 0x413));
    assert!(!flash.acr().read().prften());
    assert!(!clock::flash_accelerator(flash, 0, 0x413));
    assert!(clock::flash_accelerator(flash, 0x1000_6421, 0x421));
    // The data cache flushed, left on.
    clock::flush_data_cache(flash);
    assert!(flash.acr().read().dcen() && !flash.acr().read().dcrst());
    // ×32 before an erase: unlocked with the two keys only while LOCK is set; STRT untouched.
    flash.cr().modify(|w| w.set_lock(true));
    clock::erase_at_x32(flash);
    assert_eq!(flash.cr().read().psize(), pac::flash::vals::Psize::PSIZE32);
    assert_eq!(word(flash.as_ptr(), 0x04), clock::FLASH_KEYS[1]);
    assert!(!flash.cr().read().strt());
    set_word(flash.as_ptr(), 0x04, 0);
    flash.cr().modify(|w| w.set_lock(false));
    clock::erase_at_x32(flash);
    assert_eq!(
        word(flash.as_ptr(), 0x04),
        0,
        "no key written to an unlocked CR"
    );
}

#[test]
fn the_brown_out_reset_is_programmed_with_only_its_field_changed() {
    use f4_regs::clock::BrownOut;
    let flash = block(pac::flash::Flash::from_ptr);
    // The factory option bytes (RM0090 §3.9.10's reset value): BOR off, RDP level 0 (0xAA),
    // no write protection, locked.
    set_word(flash.as_ptr(), 0x14, 0x0FFF_AAED);
    // The flash busy past the bound: nothing written.
    set_word(flash.as_ptr(), 0x0C, 1 << 16);
    let clock = core::cell::Cell::new(0u32);
    let now = || {
        clock.set(clock.get().wrapping_add(100));
        clock.get()
    };
    assert_eq!(
        clock::brown_out_reset(flash, 0, now, 10_000),
        BrownOut::Failed
    );
    assert_eq!(word(flash.as_ptr(), 0x14), 0x0FFF_AAED);
    assert_eq!(word(flash.as_ptr(), 0x08), 0, "no key written");
    assert!(clock.get() <= 10_300, "bounded: {} cycles", clock.get());
    // Idle: keys, BOR_LEV 00, OPTSTRT, locked again; everything else as it was.
    set_word(flash.as_ptr(), 0x0C, 0);
    assert_eq!(
        clock::brown_out_reset(flash, 0, || 0, 10_000),
        BrownOut::Programmed
    );
    assert_eq!(word(flash.as_ptr(), 0x08), clock::OPTION_KEYS[1]);
    let optcr = word(flash.as_ptr(), 0x14);
    assert_eq!(optcr & 0b1100, 0, "BOR level 3");
    assert_eq!(optcr & 0b11, 0b11, "OPTSTRT written, OPTLOCK set again");
    assert_eq!(optcr & !0b1111, 0x0FFF_AAE0, "RDP, nWRP and the rest kept");
    // Already set: nothing written.
    set_word(flash.as_ptr(), 0x08, 0);
    assert_eq!(
        clock::brown_out_reset(flash, 0, || 0, 10_000),
        BrownOut::Set
    );
    assert_eq!(word(flash.as_ptr(), 0x08), 0);
}

#[test]
fn the_clock_security_system_is_switched_on_and_its_nmi_acknowledged() {
    let rcc = block(pac::rcc::Rcc::from_ptr);
    clock::enable_css(rcc);
    // RCC_CR.CSSON is bit 19 (RM0090 §7.3.1).
    assert_eq!(word(rcc.as_ptr(), 0x00) & (1 << 19), 1 << 19);
    assert!(!clock::css_ack(rcc), "no failure: no NMI");
    // CSSF (RCC_CIR bit 7) set by the hardware: acknowledged with CSSC (bit 23).
    set_word(rcc.as_ptr(), 0x0C, 1 << 7);
    assert!(clock::css_ack(rcc));
    assert_ne!(word(rcc.as_ptr(), 0x0C) & (1 << 23), 0, "CSSC written");
}

#[test]
fn reset_cause_debug_freeze_and_encoder() {
    let rcc = block(pac::rcc::Rcc::from_ptr);
    assert!(!clock::watchdog_reset(rcc));
    assert!(rcc.csr().read().rmvf(), "flags cleared for the next time");
    rcc.csr().modify(|w| w.set_wdgrstf(true));
    assert!(clock::watchdog_reset(rcc));
    let dbg = block(pac::dbgmcu::Dbgmcu::from_ptr);
    clock::freeze_in_debug(dbg);
    assert!(dbg.apb2fzr().read().tim8() && dbg.apb1fzr().read().iwdg());
    let tim2 = block(pac::timer::TimGp32::from_ptr);
    // The filter code for a 1 MHz count rate on TIM2's 84 MHz: gms-core's choice.
    let (filter, _) = gms_core::drive::encoder_filter(84_000_000, 1.0e6);
    f4_regs::encoder::range_and_filter(tim2, filter);
    assert_eq!(tim2.arr().read(), u32::MAX);
    let ccmr = tim2.ccmr_input(0).read();
    assert_eq!(ccmr.icf(0).to_bits(), filter);
    assert_eq!(ccmr.icf(1).to_bits(), filter);
    assert_ne!(filter, 0);
}

#[test]
fn the_stack_high_water_mark_counts_the_paint_left() {
    use f4_regs::stack::{PAINT, unused_bytes};
    // 1 KiB of stack region, painted; the stack (growing down from the top) reached 300 bytes.
    let mut region = vec![PAINT; 256];
    for w in region.iter_mut().skip(256 - 75) {
        *w = 0x2000_1234;
    }
    // One word of the used part happens to hold the paint: still counted as used.
    region[200] = PAINT;
    let r = region.as_ptr_range();
    // SAFETY: the vector's own memory.
    assert_eq!(unsafe { unused_bytes(r.start, r.end) }, 4 * (256 - 75));
    region.fill(PAINT);
    let r = region.as_ptr_range();
    // SAFETY: as above.
    assert_eq!(unsafe { unused_bytes(r.start, r.end) }, 1024);
    region[0] = 0;
    let r = region.as_ptr_range();
    // SAFETY: as above.
    assert_eq!(
        unsafe { unused_bytes(r.start, r.end) },
        0,
        "reached the bottom"
    );
}

/// The two compare values are not written within the guard before the update at the bottom:
/// a counter counting down within 16 counts of it is waited out (on plain memory it never
/// moves: the wait ends at its bound); anywhere else, at once.
#[test]
fn the_compare_values_are_written_clear_of_the_update() {
    use pac::timer::vals::Dir;
    let tim = block(pac::timer::TimAdv::from_ptr);
    let at = |cnt: u16, dir: Dir| {
        tim.cr1().modify(|w| w.set_dir(dir));
        tim.cnt().write(|w| w.set_cnt(cnt));
        pwm::wait_clear_of_update(tim, 100)
    };
    assert_eq!(at(5, Dir::DOWN), 100);
    assert_eq!(at(16, Dir::DOWN), 100);
    assert_eq!(at(17, Dir::DOWN), 0);
    assert_eq!(at(5, Dir::UP), 0, "just after the update");
    assert_eq!(at(4000, Dir::DOWN), 0);
    assert!(pwm::near_update(0, true, pwm::UPDATE_GUARD));
    assert!(!pwm::near_update(0, false, pwm::UPDATE_GUARD));
}

#[test]
fn the_stack_guard_region_and_registers() {
    use f4_regs::mpu::{self, CoreRegs};
    // The F405 firmware's statics end at 0x2000DB0C, the stack's region at 0x20020000: an
    // 8 KiB guard at 0x2000E000, 64 KiB of stack above it.
    assert_eq!(
        mpu::guard_region(0x2000_DB0C, 0x2002_0000, 8192, 16 * 1024),
        Some((0x2000_E000, 0x1_0000))
    );
    assert_eq!(
        mpu::guard_region(0x2000_E000, 0x2002_0000, 8192, 0),
        Some((0x2000_E000, 0x1_0000)),
        "already aligned"
    );
    assert_eq!(
        mpu::guard_region(0x2001_A001, 0x2002_0000, 8192, 16 * 1024),
        None
    );
    assert_eq!(mpu::guard_region(0x2000_0000, 0x2002_0000, 100, 0), None);
    // RASR: 8 KiB is SIZE 12 (2^(12+1)), AP 000, XN, enabled.
    assert_eq!(mpu::guard_rasr(8192), (1 << 28) | (12 << 1) | 1);
    assert_eq!(mpu::guard_rasr(32), (1 << 28) | (4 << 1) | 1);
    // On memory laid out as the MPU and the SCB.
    let mpu_mem: &'static mut [u32; 16] = Box::leak(Box::new([0; 16]));
    let scb_mem: &'static mut [u32; 64] = Box::leak(Box::new([0; 64]));
    scb_mem[0x18 / 4] = 0xE0E0_E0E0; // SHPR1: every priority at 0xE0
    let r = CoreRegs {
        mpu: mpu_mem.as_mut_ptr(),
        scb: scb_mem.as_mut_ptr(),
    };
    // SAFETY: the memory above, laid out as the registers.
    unsafe { mpu::enable_stack_guard(r, 0x2000_E000, 8192) };
    assert_eq!(
        mpu_mem[1], 0b101,
        "CTRL: ENABLE and PRIVDEFENA, HFNMIENA off"
    );
    assert_eq!(mpu_mem[2], 0, "RNR: region 0");
    assert_eq!(mpu_mem[3], 0x2000_E000, "RBAR");
    assert_eq!(mpu_mem[4], mpu::guard_rasr(8192), "RASR");
    assert_eq!(
        scb_mem[0x18 / 4],
        0xE0E0_E000,
        "MemManage at priority 0, the others kept"
    );
    assert_eq!(scb_mem[0x24 / 4], 1 << 16, "MEMFAULTENA");
}

#[test]
fn uart_reception_by_circular_dma_never_reads_the_data_register() {
    use f4_regs::uart_rx::{self, Ring, RxStream};
    let dma = block(pac::dma::Dma::from_ptr);
    let usart = block(pac::usart::Usart::from_ptr);
    let ring_mem: &'static mut [u8; 16] = Box::leak(Box::new([0u8; 16]));
    let ring = Ring {
        addr: ring_mem.as_mut_ptr(),
        len: 16,
    };
    let s = RxStream {
        dma,
        stream: 5,
        channel: 4,
    };
    assert!(uart_rx::start(s, usart, ring));
    let st = dma.st(5);
    let cr = st.cr().read();
    // RM0390 §9.5.5: CHSEL 4, peripheral to memory, bytes, MINC, CIRC, enabled, no interrupt.
    assert_eq!(cr.chsel(), 4);
    assert!(cr.minc() && cr.circ() && cr.en());
    assert!(!cr.tcie() && !cr.htie() && !cr.teie() && !cr.dmeie());
    assert_eq!(cr.dir(), pac::dma::vals::Dir::PERIPHERAL_TO_MEMORY);
    assert_eq!(st.par().read(), usart.dr().as_ptr() as usize as u32);
    assert_eq!(st.m0ar().read(), ring_mem.as_ptr() as usize as u32);
    assert_eq!(st.ndtr().read().ndt(), 16);
    assert!(usart.cr3().read().dmar(), "the USART requests the DMA");
    // The stream's flags cleared in HIFCR (stream 5: bits 6-11).
    assert_eq!(word(dma.as_ptr(), 0x0C), 0x3D << 6);
    // The stream wrote 5 bytes: NDTR 11; then it wrapped to 3 written of the next lap.
    st.ndtr().write(|w| w.set_ndt(11));
    assert_eq!(uart_rx::write_pos(s, 16), 5);
    st.ndtr().write(|w| w.set_ndt(0));
    assert_eq!(
        uart_rx::write_pos(s, 16),
        0,
        "a 0 read at the reload is the ring's start"
    );
    for (k, b) in ring_mem.iter_mut().enumerate() {
        *b = k as u8;
    }
    let mut out = [0u8; 8];
    // SAFETY: the ring is the stream's, every byte written.
    let n = unsafe { uart_rx::copy_out(ring, 14, 3, &mut out) };
    assert_eq!(&out[..n], &[14, 15, 0, 1, 2], "across the wrap");
    let n = unsafe { uart_rx::copy_out(ring, 2, 15, &mut out) };
    assert_eq!(n, 8, "as many as fit");
    assert_eq!(out, [2, 3, 4, 5, 6, 7, 8, 9]);
}

#[test]
fn uart_transmission_by_dma_starts_only_when_the_last_has_ended() {
    use f4_regs::uart_tx::{self, TxStream};
    let dma = block(pac::dma::Dma::from_ptr);
    let usart = block(pac::usart::Usart::from_ptr);
    let buf = [b'x'; 8];
    let s = TxStream {
        dma,
        stream: 6,
        channel: 4,
    };
    // SAFETY: `buf` outlives the test's use of the (model) stream.
    assert!(
        !unsafe { uart_tx::start(s, usart, buf.as_ptr(), 0) },
        "nothing to send"
    );
    assert!(unsafe { uart_tx::start(s, usart, buf.as_ptr(), 8) });
    let st = dma.st(6);
    let cr = st.cr().read();
    // RM0390 §9.5.5: CHSEL 4, memory to peripheral, bytes, MINC, not circular, enabled, no
    // interrupt.
    assert_eq!(cr.chsel(), 4);
    assert!(cr.minc() && !cr.circ() && cr.en());
    assert!(!cr.tcie() && !cr.htie() && !cr.teie() && !cr.dmeie());
    assert_eq!(cr.dir(), pac::dma::vals::Dir::MEMORY_TO_PERIPHERAL);
    assert_eq!(st.par().read(), usart.dr().as_ptr() as usize as u32);
    assert_eq!(st.m0ar().read(), buf.as_ptr() as usize as u32);
    assert_eq!(st.ndtr().read().ndt(), 8);
    assert!(usart.cr3().read().dmat(), "the USART requests the DMA");
    // The stream's flags cleared in HIFCR (stream 6: bits 16-21).
    assert_eq!(word(dma.as_ptr(), 0x0C), 0x3D << 16);
    // Running: 8 left, a second start refused.
    assert!(uart_tx::busy(s));
    assert_eq!(uart_tx::left(s), 8);
    assert!(!unsafe { uart_tx::start(s, usart, buf.as_ptr(), 4) });
    // The hardware ends it (EN cleared, NDTR 0): idle, a new start taken.
    st.ndtr().write(|w| w.set_ndt(0));
    st.cr().modify(|w| w.set_en(false));
    assert!(!uart_tx::busy(s));
    assert_eq!(uart_tx::left(s), 0);
    assert!(unsafe { uart_tx::start(s, usart, buf.as_ptr(), 4) });
    assert_eq!(st.ndtr().read().ndt(), 4);
}

/// The code for SRAM: its words copied to their place, VTOR at the flash's vector table,
/// SYSCFG's clock on and SRAM1 mapped at 0 (MEM_MODE 11, RM0090 §9.2.1); the other bits of
/// the registers kept.
#[test]
fn code_for_sram_is_copied_and_sram1_mapped_at_zero() {
    let rcc = block(pac::rcc::Rcc::from_ptr);
    let syscfg = block(pac::syscfg::Syscfg::from_ptr);
    let scb: &'static mut [u32; 64] = Box::leak(Box::new([0u32; 64]));
    // APB2ENR (0x44) with another clock on; MEMRMP (0x00) with FB_MODE (bit 8) set.
    set_word(rcc.as_ptr(), 0x44, 1 << 8);
    set_word(syscfg.as_ptr(), 0x00, 1 << 8);
    let load: Vec<u32> = (0..37u32).map(|i| i.wrapping_mul(0x9E37_79B9)).collect();
    let mut sram = vec![0xA5A5_A5A5u32; 40];
    let r = remap::RemapRegs {
        rcc,
        syscfg,
        scb: scb.as_mut_ptr(),
    };
    // SAFETY: the blocks and both buffers are on this test's memory, large enough.
    unsafe { remap::sram_at_zero(r, load.as_ptr(), sram.as_mut_ptr(), load.len(), 0x0800_0000) };
    assert_eq!(&sram[..37], &load[..]);
    assert_eq!(&sram[37..], &[0xA5A5_A5A5; 3]);
    assert_eq!(scb[2], 0x0800_0000, "VTOR");
    assert_eq!(
        word(rcc.as_ptr(), 0x44),
        (1 << 8) | (1 << 14),
        "APB2ENR: SYSCFGEN added"
    );
    assert_eq!(syscfg.memrm().read().mem_mode(), remap::MEM_MODE_SRAM);
    assert_eq!(
        word(syscfg.as_ptr(), 0x00),
        (1 << 8) | 0b11,
        "MEMRMP: FB_MODE kept"
    );
}

/// The supply divider's injected conversion: PC1 analog, channel 11 sampled 84 cycles
/// (SMPR1's SMP11), one injected rank (JL 0, JSQ4 11: RM0090 §13.13.12), a software start
/// (JEXTEN 00, JSWSTART); its result read from JDR1, with ADC_SR not written.
#[test]
fn the_supply_divider_is_an_injected_conversion() {
    use pac::adc::vals::{Exten, SampleTime};
    let r = sense_regs();
    sense::supply_init(r.adc, r.gpio, 1, 11);
    assert_eq!(
        r.gpio.moder().read().moder(1),
        pac::gpio::vals::Moder::ANALOG
    );
    assert_eq!(r.adc.smpr1().read().smp(1), SampleTime::CYCLES84);
    assert_eq!(r.adc.jsqr().read().jl(), 0);
    assert_eq!(r.adc.jsqr().read().jsq(3), 11);
    assert_eq!(r.adc.cr2().read().jexten(), Exten::DISABLED);
    sense::supply_start(r.adc);
    assert!(r.adc.cr2().read().jswstart());
    // JEOC with AWD and OVR set; JDR1 (offset 0x3C) 1,234: the code read, SR untouched.
    let sr = (1 << 2) | (1 << 0) | (1 << 5);
    set_word(r.adc.as_ptr(), 0x00, sr);
    set_word(r.adc.as_ptr(), 0x3C, 1234);
    assert_eq!(sense::supply_latest(r.adc), 1234);
    assert_eq!(word(r.adc.as_ptr(), 0x00), sr);
}
