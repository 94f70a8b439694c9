//! The driver of the power stage (`boards/power_stage.rs`) on an STM32F4, common to every
//! board: clocks from the board's description, the bridge on TIM8, the encoder on TIM2, the
//! current sense on ADC1 with DMA2, USB, flash, watchdog. What differs between boards is in
//! `boards/` (one module per board, chosen by a cargo feature); this file re-exports the
//! chosen board's description.
//!
//! The current is sampled by the hardware, not by the CPU: TIM8's OC4REF (channel 4, no pin)
//! is its trigger output (TRGO), rising once per PWM period [`SENSE_TIMING`]`.lead` before the
//! counter's bottom; it starts ADC1's regular sequence of 16 conversions of PC0, which DMA2
//! stream 0 moves into a buffer; the DMA's transfer-complete interrupt is the control
//! interrupt. The sampling instants are centred on the bottom, the middle of the bridge's
//! slow-decay (brake) phase (`drive::bridge_compare`: both inputs high around the bottom, the
//! drive phase centred on the top), where the current's triangular PWM ripple is
//! point-symmetric about its mean, so the centred window's mean is the period's mean. Timers: TIM2 encoder, TIM8 PWM and
//! sense trigger, TIM4 embassy's time driver (none shared).

use core::cell::UnsafeCell;

use cortex_m::peripheral::DWT;
use embassy_stm32::adc::Adc;
use embassy_stm32::flash::{Blocking, Flash};
use embassy_stm32::gpio::{Level, Output, OutputType, Pull, Speed};
use embassy_stm32::interrupt;
use embassy_stm32::interrupt::InterruptExt;
use embassy_stm32::peripherals::{ADC1, PC0, TIM2, TIM8};
use embassy_stm32::time::Hertz;
use embassy_stm32::timer::low_level::CountingMode;
use embassy_stm32::timer::qei::{Qei, QeiMode};
use embassy_stm32::timer::simple_pwm::{PwmPin, SimplePwm};
use embassy_stm32::wdg::IndependentWatchdog;
use embassy_stm32::{Peri, bind_interrupts, pac, peripherals};
use gms_core::drive::{self, BridgeOff, Deadman, Stall};

#[cfg(feature = "board-f405")]
bind_interrupts!(struct Irqs {
    OTG_FS => embassy_stm32::usb::InterruptHandler<peripherals::USB_OTG_FS>;
});

#[cfg(feature = "board-nucleo-f446")]
bind_interrupts!(struct Irqs {
    USART2 => embassy_stm32::usart::InterruptHandler<peripherals::USART2>;
    DMA1_STREAM5 => embassy_stm32::dma::InterruptHandler<peripherals::DMA1_CH5>;
    DMA1_STREAM6 => embassy_stm32::dma::InterruptHandler<peripherals::DMA1_CH6>;
});

/// The link to the host as the board brings it up: the USB OTG FS driver on the F405 board
/// (`main.rs` puts the CDC-ACM class on it).
#[cfg(feature = "board-f405")]
pub type HostLink = embassy_stm32::usb::Driver<'static, peripherals::USB_OTG_FS>;

/// The link to the host as the board brings it up: USART2 to the ST-LINK's virtual COM port.
#[cfg(feature = "board-nucleo-f446")]
pub type HostLink = crate::port::HostPort;

pub use crate::boards::power_stage::*;
pub use crate::boards::*;

/// TIM8's clock \[Hz\] (on APB2).
pub const PWM_TIMER_HZ: u32 = CLOCKS.tim_apb2_hz();
/// TIM2's clock \[Hz\] (on APB1; f_DTS with CKD = 0).
pub const ENCODER_TIMER_HZ: u32 = CLOCKS.tim_apb1_hz();
/// ADC conversions summed per current sample.
pub const SENSE_OVERSAMPLE: u32 = SENSE_TIMING.conversions;

// The board's numbers hold together (also checked by `tests/tests/boards.rs`).
const _: () = assert!(CLOCKS.check(&PART).is_ok());
const _: () = assert!(MEMORY.check().is_ok());

/// The RCC's register encoding of an APB prescaler (RM0090 §7.3.3 PPREx: 1 → 0, 2 → 100,
/// 4 → 101, 8 → 110, 16 → 111).
const fn ppre(div: u32) -> u8 {
    if div <= 1 {
        0
    } else {
        3 + div.trailing_zeros() as u8
    }
}

/// The RCC's register encoding of the AHB prescaler (RM0090 §7.3.3 HPRE: 1 → 0, 2 → 1000,
/// …, 16 → 1011, 64 → 1100, …, 512 → 1111; there is no 32).
const fn hpre(div: u32) -> u8 {
    let log = div.trailing_zeros() as u8;
    match div {
        0 | 1 => 0,
        _ if div < 32 => 7 + log,
        _ => 6 + log,
    }
}

/// Clocks as the board describes them ([`CLOCKS`], checked against the part's limits).
pub fn config() -> embassy_stm32::Config {
    use embassy_stm32::rcc::*;
    let mut c = embassy_stm32::Config::default();
    c.rcc.hse = Some(Hse {
        freq: Hertz(CLOCKS.hse_hz),
        mode: if CLOCKS.hse_bypass {
            HseMode::Bypass
        } else {
            HseMode::Oscillator
        },
    });
    c.rcc.pll_src = PllSource::HSE;
    c.rcc.pll = Some(Pll {
        prediv: PllPreDiv::from_bits(CLOCKS.pll_m as u8),
        mul: PllMul::from_bits(CLOCKS.pll_n as u16),
        // PLLP's encoding: 2 → 0, 4 → 1, 6 → 2, 8 → 3.
        divp: Some(PllPDiv::from_bits((CLOCKS.pll_p / 2 - 1) as u8)),
        divq: Some(PllQDiv::from_bits(CLOCKS.pll_q as u8)),
        divr: None,
    });
    c.rcc.ahb_pre = AHBPrescaler::from_bits(hpre(CLOCKS.ahb_div));
    c.rcc.apb1_pre = APBPrescaler::from_bits(ppre(CLOCKS.apb1_div));
    c.rcc.apb2_pre = APBPrescaler::from_bits(ppre(CLOCKS.apb2_div));
    c.rcc.sys = Sysclk::PLL1_P;
    // The DMA interrupts embassy enables (none used but the loop's, set apart in
    // `start_control`) below the loop.
    c.dma_interrupt_priority = crate::irq::DRIVERS;
    // DBGMCU_CR.DBG_SLEEP (RM0090 §38.16.3), said here rather than left to embassy's default
    // (embassy-stm32 0.6 `lib.rs` writes DBG_SLEEP/STOP/STANDBY from this field, default true):
    // the executor sleeps in WFI between events, and with DBG_SLEEP off HCLK stops there, so a
    // probe could no longer read the RTT log while the firmware idles. It keeps the core's
    // clock on in sleep (some mA); nothing here uses stop or standby.
    c.enable_debug_during_sleep = true;
    c
}

/// HSI's frequency \[Hz\] (RM0090 §6.2.2): the core's clock until embassy's RCC set-up.
const HSI_HZ: u32 = 16_000_000;

/// How long the HSE may take to become ready \[ms\]: a crystal's start-up is 2 ms typical
/// (DS8626 "HSE 4-26 MHz oscillator characteristics", t_SU(HSE)); an external clock in
/// bypass is ready at once.
pub const HSE_WAIT_MS: u32 = 100;

/// Starts the HSE as the board describes it (bypass or crystal) and waits at most
/// [`HSE_WAIT_MS`] for HSERDY, timed by the DWT cycle counter at HSI (call with it enabled,
/// before embassy's RCC set-up, which waits for HSERDY without a bound: embassy-stm32 0.6
/// `rcc/f247.rs`, `while !RCC.cr().read().hserdy() {}`; with HSE already ready it goes on
/// at once, writing the same HSEBYP and HSEON). False, with the HSE switched off again, if it
/// did not come.
pub fn start_hse() -> bool {
    let rcc = pac::RCC;
    // HSEBYP is written while the HSE is off (RM0090 §7.3.1).
    rcc.cr().modify(|w| w.set_hseon(false));
    rcc.cr().modify(|w| w.set_hsebyp(CLOCKS.hse_bypass));
    rcc.cr().modify(|w| w.set_hseon(true));
    let t0 = DWT::cycle_count();
    let limit = HSI_HZ / 1000 * HSE_WAIT_MS;
    while !rcc.cr().read().hserdy() {
        if DWT::cycle_count().wrapping_sub(t0) > limit {
            rcc.cr().modify(|w| w.set_hseon(false));
            return false;
        }
    }
    true
}

/// How long the start-up calibration waits for one sequence of current samples \[µs\]:
/// 20 PWM periods at the 20 kHz the timer runs at then. A dead chain costs one such wait
/// (gms-core's `calibrate_sense` stops at the first missing reading), well inside the
/// watchdog.
pub const SENSE_WAIT_US: u32 = 1000;

/// The DMA's destination: the last sequence of current-sense conversions. Written only by
/// DMA2 stream 0, read only with volatile reads after its transfer-complete flag.
struct SenseBuf(UnsafeCell<[u16; SENSE_OVERSAMPLE as usize]>);

// SAFETY: the CPU only reads it (volatile), the DMA only writes it.
unsafe impl Sync for SenseBuf {}

static SENSE_BUF: SenseBuf = SenseBuf(UnsafeCell::new([0; SENSE_OVERSAMPLE as usize]));

/// The control loop's hardware: owned by the control interrupt.
pub struct ControlHw {
    // Kept alive: dropping them would gate the peripherals' clocks or free the pin.
    _adc: Adc<'static, ADC1>,
    _isense: Peri<'static, PC0>,
    _pwm: SimplePwm<'static, TIM8>,
    _qei: Qei<'static, TIM2>,
}

impl ControlHw {
    /// The encoder's raw 32-bit count.
    #[inline(always)]
    pub fn encoder_raw(&self) -> u32 {
        pac::TIM2.cnt().read()
    }

    /// Sum of the [`SENSE_OVERSAMPLE`] ADC codes of the motor current of the last sequence
    /// (in the control interrupt: the sequence that just completed).
    #[inline(always)]
    pub fn current_codes(&self) -> u32 {
        let base = SENSE_BUF.0.get() as *const u16;
        let mut sum = 0u32;
        for i in 0..SENSE_OVERSAMPLE as usize {
            // SAFETY: in bounds of the buffer; volatile, as the DMA writes it.
            sum += unsafe { core::ptr::read_volatile(base.add(i)) } as u32;
        }
        sum
    }

    /// Waits for the next sequence (at most [`SENSE_WAIT_US`], timed by the DWT cycle
    /// counter) and returns its sum, for the start-up calibration while the control
    /// interrupt is off. `None` if none came: the ADC is not triggered or its DMA stopped,
    /// which the calibration reports as a `current_sense` fault.
    pub fn next_current_codes(&mut self) -> Option<u32> {
        ack_sample();
        let t0 = DWT::cycle_count();
        let limit = CLOCKS.hclk_hz() / 1_000_000 * SENSE_WAIT_US;
        loop {
            if pac::DMA2.isr(0).read().tcif(0) {
                ack_sample();
                return Some(self.current_codes());
            }
            if DWT::cycle_count().wrapping_sub(t0) > limit {
                return None;
            }
        }
    }

    /// Writes the two bridge inputs' compare values (take effect at the next PWM period).
    #[inline(always)]
    pub fn set_bridge(&mut self, in1: u32, in2: u32) {
        let clamp = |v: u32| v.min(u16::MAX as u32) as u16;
        pac::TIM8.ccr(0).write(|w| w.set_ccr(clamp(in1)));
        pac::TIM8.ccr(1).write(|w| w.set_ccr(clamp(in2)));
    }

    /// Sets the PWM timer's prescaler and period (register values; preloaded, so they take
    /// effect at the next update) and the sense trigger's lead for them.
    pub fn set_pwm_timing(&mut self, psc: u32, arr: u32) {
        let arr = arr.min(PWM_MAX_ARR);
        pac::TIM8.psc().write_value(psc.min(u16::MAX as u32) as u16);
        pac::TIM8.arr().write(|w| w.set_arr(arr as u16));
        let lead = SENSE_TIMING.lead_counts(PWM_TIMER_HZ, psc).min(arr - 1);
        pac::TIM8.ccr(3).write(|w| w.set_ccr(lead as u16));
    }

    /// Clears the sense DMA's flags (first thing in the interrupt).
    #[inline(always)]
    pub fn ack_sample(&mut self) {
        ack_sample();
    }
}

/// Clears DMA2 stream 0's flags (LIFCR, RM0090 §10.5.3).
#[inline(always)]
fn ack_sample() {
    pac::DMA2.ifcr(0).write(|w| {
        w.set_tcif(0, true);
        w.set_htif(0, true);
        w.set_teif(0, true);
        w.set_dmeif(0, true);
        w.set_feif(0, true);
    });
}

/// TIMx_SR written to clear UIF alone: rc_w0 flags, 1 leaves a flag, 0 clears it; reserved
/// bits stay 0 (TIMx_SR's flags: bits 0-7 and 9-12, RM0090 §17.4.5).
const SR_CLEAR_UIF: u32 = 0x1EFE;

/// Waits (at most about 40 ms, hundreds of periods) for TIM8's next update event; the
/// counter's direction just after it: `Some(true)` counting up (the update was at the bottom),
/// `Some(false)` down (at the top), `None` if none came.
fn next_update_counting_up() -> Option<bool> {
    let t = pac::TIM8;
    t.sr().write(|w| w.0 = SR_CLEAR_UIF);
    for _ in 0..1_000_000u32 {
        if t.sr().read().uif() {
            return Some(t.cr1().read().dir() == pac::timer::vals::Dir::UP);
        }
    }
    None
}

/// Puts TIM8's update event at the counter's bottom, once per period, and checks it; true if
/// it is there. The repetition counter reloads from RCR at each update and an update comes at
/// a turning point that finds it at 0 (RM0090 §17.3.3, figure "Update rate examples"): with
/// RCR = 0 every turning point updates; RCR = 1 written just after an update at the top is
/// loaded at the next update, the bottom, and from then on every other turning point — every
/// bottom — updates (RM0090's "RCR written after the counter started: the update on the
/// underflow"). Checked on two updates. Run before the control interrupt, with the bridge
/// off.
fn align_update_to_bottom() -> bool {
    let t = pac::TIM8;
    t.rcr().write(|w| w.set_rep(0));
    // Two updates: the repetition counter now reloads from 0 at every turning point.
    let _ = next_update_counting_up();
    let _ = next_update_counting_up();
    // RCR = 1 right after an update at the top (the counter then counts down).
    let mut written = false;
    for _ in 0..4 {
        if next_update_counting_up() == Some(false) {
            t.rcr().write(|w| w.set_rep(1));
            written = true;
            break;
        }
    }
    if !written {
        return false;
    }
    // One update to load it, then two that must both be at the bottom.
    let _ = next_update_counting_up();
    next_update_counting_up() == Some(true) && next_update_counting_up() == Some(true)
}

/// Sets up the hardware sampling of the motor current (see the module's notes): ADC1's regular
/// sequence of [`SENSE_OVERSAMPLE`] conversions of PC0 on TIM8's TRGO, moved by DMA2 stream 0
/// (channel 0 = ADC1, RM0090 table 43) into [`SENSE_BUF`], circularly, with its
/// transfer-complete interrupt (left disabled in the NVIC until [`start_control`]). ADC1 is
/// already clocked, prescaled and on (`Adc::new`).
fn sense_init() {
    use pac::adc::vals::{Dds, Eocs, Exten, Res, SampleTime};
    use pac::dma::vals::{Dir, Size};
    // PC0 analog (RM0090 §8.4.1: MODER = 11).
    pac::GPIOC
        .moder()
        .modify(|w| w.set_moder(SENSE_PIN, pac::gpio::vals::Moder::ANALOG));
    // DMA2 stream 0, disabled while configured (RM0090 §10.3.17).
    pac::RCC.ahb1enr().modify(|w| w.set_dma2en(true));
    let st = pac::DMA2.st(0);
    st.cr().modify(|w| w.set_en(false));
    while st.cr().read().en() {}
    ack_sample();
    st.par().write_value(pac::ADC1.dr().as_ptr() as u32);
    st.m0ar().write_value(SENSE_BUF.0.get() as u32);
    st.ndtr().write(|w| w.set_ndt(SENSE_OVERSAMPLE as u16));
    st.cr().write(|w| {
        w.set_chsel(0);
        w.set_dir(Dir::PERIPHERAL_TO_MEMORY);
        w.set_psize(Size::BITS16);
        w.set_msize(Size::BITS16);
        w.set_minc(true);
        w.set_circ(true);
        w.set_tcie(true);
        // A transfer error (a bus error: the stream stops, EN cleared) and a direct-mode error
        // (RM0090 §10.3.18) interrupt too, on the same vector: the handler switches the bridge
        // off before anything else.
        w.set_teie(true);
        w.set_dmeie(true);
        w.set_en(true);
    });
    // ADC1 (RM0090 §13.13): 12 bits, scan of 16 ranks of channel 10, each sampled 15 cycles;
    // DMA requests continuing after each sequence (DDS); EOC per sequence; started by the
    // rising edge of TIM8_TRGO (EXTSEL = 1110, §13.13.3 table "External trigger for regular
    // channels").
    let adc = pac::ADC1;
    adc.cr1().modify(|w| {
        w.set_res(Res::BITS12);
        w.set_scan(true);
        w.set_eocie(false);
        // An overrun (a conversion lost: the ADC stops its DMA requests until OVR is cleared,
        // RM0090 §13.8.1) interrupts on the ADC vector, at the deadman's priority.
        w.set_ovrie(true);
    });
    adc.smpr1()
        .modify(|w| w.set_smp((SENSE_CHANNEL - 10) as usize, SampleTime::CYCLES15));
    adc.sqr1().modify(|w| w.set_l(SENSE_OVERSAMPLE as u8 - 1));
    // Ranks 1-6 in SQR3, 7-12 in SQR2, 13-16 in SQR1.
    adc.sqr3().write(|w| {
        for i in 0..6 {
            w.set_sq(i, SENSE_CHANNEL);
        }
    });
    adc.sqr2().write(|w| {
        for i in 0..6 {
            w.set_sq(i, SENSE_CHANNEL);
        }
    });
    adc.sqr1().modify(|w| {
        for i in 0..4 {
            w.set_sq(i, SENSE_CHANNEL);
        }
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

/// The bridge inputs PC6/PC7 (TIM8_CH1/CH2) as registers, for [`bridge_off_now`].
struct Bridge;

impl BridgeOff for Bridge {
    fn disable_timer_outputs(&mut self) {
        // MOE cleared: with OSSI set at init and OIS1/OIS2 at 0, both outputs go to their idle
        // level, low (RM0090 §17.4.18 TIMx_BDTR, table 95 "Output control bits").
        pac::TIM8.bdtr().modify(|w| w.set_moe(false));
    }
    fn latch_pins_low(&mut self) {
        pac::GPIOC.bsrr().write(|w| {
            for pin in BRIDGE_PINS {
                w.set_br(pin, true);
            }
        });
    }
    fn pins_to_gpio_outputs(&mut self) {
        use embassy_stm32::pac::gpio::vals::Moder;
        pac::GPIOC.moder().modify(|w| {
            for pin in BRIDGE_PINS {
                w.set_moder(pin, Moder::OUTPUT);
            }
        });
    }
}

/// Switches the bridge off from any context (panic, HardFault, an unexpected interrupt, the
/// supervisor seeing the loop stalled): register writes only, no lock, callable with
/// interrupts off. Both DRV8871 inputs end low (coast) as GPIO outputs, whatever TIM8 does
/// afterwards; only a reset gives the pins back to the timer.
pub fn bridge_off_now() {
    drive::bridge_off(&mut Bridge);
}

/// Everything else the firmware uses.
pub struct Rest {
    /// The link to the host ([`HostLink`]).
    pub link: HostLink,
    /// Internal flash (blocking; parameters).
    pub flash: Flash<'static, Blocking>,
    /// Independent watchdog (started: feed it).
    pub watchdog: IndependentWatchdog<'static, peripherals::IWDG>,
    /// Run LED (on while the bridge is enabled, blinking while disabled).
    pub led_run: Output<'static>,
    /// Fault LED (on while a fault is latched).
    pub led_fault: Output<'static>,
    /// True when the last reset came from the watchdog.
    pub watchdog_reset: bool,
    /// True when TIM8's update event was seen at the counter's bottom (see
    /// [`align_update_to_bottom`]); false means the compare values may be taken mid-step.
    pub update_at_bottom: bool,
}

/// Sets up the board. The bridge starts off (both inputs low) and the PWM timer's update
/// interrupt is configured but not enabled: [`start_control`] does that.
pub fn init() -> (ControlHw, Rest) {
    // Reset cause, then clear the flags for the next time.
    let csr = pac::RCC.csr().read();
    let watchdog_reset = csr.wdgrstf() || csr.wwdgrstf();
    pac::RCC.csr().modify(|w| w.set_rmvf(true));

    let p = embassy_stm32::init(config());
    // The watchdog first: from here on a hang resets the MCU (the supervisor feeds it; until
    // it runs, the start-up below takes well under a second).
    let mut watchdog = IndependentWatchdog::new(p.IWDG, WATCHDOG_US);
    watchdog.unleash();
    // A debug halt stops TIM8, and a stopped advanced timer's outputs are disabled, forced to
    // their idle level with OSSI set (RM0090 §17.3.21 "Debug mode", §38.16.5 DBGMCU_APB2_FZ
    // DBG_TIM8_STOP): the bridge coasts while the core is halted.
    pac::DBGMCU.apb2fzr().modify(|w| w.set_tim8(true));
    // And the watchdog stops too (DBGMCU_APB1_FZ DBG_IWDG_STOP, RM0090 §38.16.4): a breakpoint
    // does not reset the MCU under the debugger.
    pac::DBGMCU.apb1fzr().modify(|w| w.set_iwdg(true));
    // Flash accelerator on: embassy-stm32 0.6's RCC set-up (rcc/f247.rs) writes FLASH_ACR's
    // LATENCY only (`FLASH.acr().write(|w| w.set_latency(..))`), so the prefetch buffer and the
    // instruction and data caches stay at their reset value, off (RM0090 §3.5.2, §3.9.1):
    // at 168 MHz with 5 wait states every fetch outside the prefetch stalls. The caches are
    // empty after reset, so no ICRST/DCRST is needed before enabling them. With the data cache
    // on, lines of the parameter sectors read before an erase or a write could be served stale
    // afterwards: embassy's flash driver (flash/f4.rs) only touches DCEN on dual-bank parts
    // (erratum 2.2.12), so `storage.rs` flushes the data cache after each erase and write, as
    // ST's HAL does after an erase (`FLASH_FlushCaches`).
    //
    // The prefetch buffer only where the part supports it: not on an STM32F405/407 of
    // revision A, nor where DBGMCU_IDCODE cannot be read as this part (gms-core's
    // `hw::f4_prefetch_allowed`).
    let idcode = pac::DBGMCU.idcode().read().0;
    let prefetch = (idcode & 0xFFF) == PART.dev_id && gms_core::hw::f4_prefetch_allowed(idcode);
    pac::FLASH.acr().modify(|w| {
        w.set_prften(prefetch);
        w.set_icen(true);
        w.set_dcen(true);
    });

    // PWM: TIM8 CH1/CH2, center-aligned. The update event (where the preloaded compare values
    // take effect) comes at every other turning point through the repetition counter (RCR =
    // 1); which one depends on when RCR was written (RM0090 §17.3.3), so
    // `align_update_to_bottom` puts it at the bottom and checks it.
    let in1 = PwmPin::new(p.PC6, OutputType::PushPull);
    let in2 = PwmPin::new(p.PC7, OutputType::PushPull);
    let mut pwm = SimplePwm::new(
        p.TIM8,
        Some(in1),
        Some(in2),
        None,
        None,
        Hertz(20_000),
        CountingMode::CenterAlignedBothInterrupts,
    );
    pwm.ch1().set_duty_cycle(0);
    pwm.ch2().set_duty_cycle(0);
    pwm.ch1().enable();
    pwm.ch2().enable();
    // The bridge inputs' edges at low speed (OSPEEDR = 00, RM0090 §8.4.3; embassy's AF pins
    // come up at very high speed): at 20 kHz nothing needs nanosecond edges, and slower ones
    // ring less on the wires to the DRV8871 (its inputs deglitch anyway).
    pac::GPIOC.ospeedr().modify(|w| {
        for pin in BRIDGE_PINS {
            w.set_ospeedr(pin, pac::gpio::vals::Ospeedr::LOW_SPEED);
        }
    });
    // Off-state when idle: outputs forced to their idle level (OIS1 = OIS2 = 0: low) whenever
    // MOE is cleared, by software, a debug halt or a panic (RM0090 §17.4.18).
    pac::TIM8.bdtr().modify(|w| {
        w.set_ossi(pac::timer::vals::Ossi::IDLE_LEVEL);
    });
    pac::TIM8.cr2().modify(|w| {
        w.set_ois(0, false);
        w.set_ois(1, false);
    });
    let update_at_bottom = align_update_to_bottom();
    pac::TIM8.sr().write(|w| w.0 = 0);
    // The sense trigger: channel 4 (no pin) in PWM mode 1, so OC4REF is high while the
    // counter is below CCR4; rising on the way down, CCR4 counts before the bottom; OC4REF
    // as TRGO (CR2.MMS = 111, RM0090 §17.4.2) is the ADC's trigger, once per period.
    pac::TIM8.ccmr_output(1).modify(|w| {
        w.set_ocm(1, pac::timer::vals::Ocm::PWM_MODE1);
        w.set_ocpe(1, true);
    });
    pac::TIM8
        .ccr(3)
        .write(|w| w.set_ccr(SENSE_TIMING.lead_counts(PWM_TIMER_HZ, 0) as u16));
    pac::TIM8
        .cr2()
        .modify(|w| w.set_mms(pac::timer::vals::Mms::COMPARE_OC4));

    // Encoder: TIM2 in encoder mode on both edges of both channels, 32-bit. Pull-ups so that
    // an open-collector encoder or a loose wire reads a steady level rather than noise (a
    // push-pull or line-receiver output overrides them).
    let qcfg = embassy_stm32::timer::qei::Config {
        mode: QeiMode::Mode3,
        ch1_pull: Pull::Up,
        ch2_pull: Pull::Up,
        ..Default::default()
    };
    let qei = Qei::new(p.TIM2, p.PA0, p.PA1, qcfg);
    pac::TIM2.arr().write_value(u32::MAX);
    // Digital filter on TI1/TI2 (TIMx_CCMR1 IC1F/IC2F, RM0090 §18.4.7; embassy's Qei leaves
    // them at 0, no filter): a glitch that the filter does not reject is a count lost for
    // good in nanometre positioning. Written with the counter running: the filter only
    // delays edges by its window.
    let (filter, _window) = drive::encoder_filter(ENCODER_TIMER_HZ, ENCODER_MAX_RATE);
    pac::TIM2.ccmr_input(0).modify(|w| {
        let f = pac::timer::vals::FilterValue::from_bits(filter);
        w.set_icf(0, f);
        w.set_icf(1, f);
    });

    let adc = Adc::new(p.ADC1);
    // The control interrupt stays off in the NVIC (embassy's init enabled every DMA stream's)
    // until the loop is handed over; the start-up calibration polls the flag meanwhile.
    interrupt::DMA2_STREAM0.disable();
    sense_init();

    // Below the control loop (`irq.rs`): embassy's time driver enabled TIM4's interrupt at
    // the reset priority 0, above the loop (time_driver/gp16.rs); the host link lowest.
    interrupt::TIM4.set_priority(crate::irq::DRIVERS);
    #[cfg(feature = "board-f405")]
    let link = {
        static EP_OUT: static_cell::ConstStaticCell<[u8; 256]> =
            static_cell::ConstStaticCell::new([0; 256]);
        let mut usb_cfg = embassy_stm32::usb::Config::default();
        usb_cfg.vbus_detection = false;
        let usb = HostLink::new_fs(p.USB_OTG_FS, Irqs, p.PA12, p.PA11, EP_OUT.take(), usb_cfg);
        interrupt::OTG_FS.set_priority(crate::irq::LINK);
        usb
    };
    #[cfg(feature = "board-nucleo-f446")]
    let link = {
        // USART2: TX on PA2, RX on PA3 (AF7), wired to the ST-LINK's virtual COM port by the
        // board's default solder bridges SB13/SB14 (UM1724 §6.8).
        static RX_RING: static_cell::ConstStaticCell<[u8; 1024]> =
            static_cell::ConstStaticCell::new([0; 1024]);
        let uart = defmt::unwrap!(embassy_stm32::usart::Uart::new(
            p.USART2,
            p.PA3,
            p.PA2,
            p.DMA1_CH6,
            p.DMA1_CH5,
            Irqs,
            crate::port::uart_config(),
        ));
        // embassy-stm32 0.6 `usart/mod.rs` enables USART2's interrupt at the reset priority
        // 0, above the loop and outside the critical section's mask: moved down with its
        // DMA streams.
        interrupt::USART2.set_priority(crate::irq::LINK);
        interrupt::DMA1_STREAM5.set_priority(crate::irq::LINK);
        interrupt::DMA1_STREAM6.set_priority(crate::irq::LINK);
        let (tx, rx) = uart.split();
        crate::port::HostPort {
            tx,
            rx: rx.into_ring_buffered(RX_RING.take()),
            started: false,
        }
    };

    let (run_pin, fault_pin) = crate::boards::led_pins!(p);
    let hw = ControlHw {
        _adc: adc,
        _isense: p.PC0,
        _pwm: pwm,
        _qei: qei,
    };
    let rest = Rest {
        link,
        flash: Flash::new_blocking(p.FLASH),
        watchdog,
        led_run: Output::new(run_pin, Level::Low, Speed::Low),
        led_fault: Output::new(fault_pin, Level::Low, Speed::Low),
        watchdog_reset,
        update_at_bottom,
    };
    (hw, rest)
}

/// Enables the control interrupt (the sense DMA's transfer complete, once per PWM period) at
/// [`crate::irq::CONTROL`], and above it the deadman (TIM8's update, once per period at the
/// counter's bottom) and the ADC's overrun at [`crate::irq::DEADMAN`].
pub fn start_control() {
    ack_sample();
    // The NVIC kept the interrupt pending while it was masked: without this the handler
    // would run once at once, mid-sequence.
    interrupt::DMA2_STREAM0.unpend();
    interrupt::DMA2_STREAM0.set_priority(crate::irq::CONTROL);
    pac::TIM8.sr().write(|w| w.0 = SR_CLEAR_UIF);
    interrupt::TIM8_UP_TIM13.unpend();
    interrupt::TIM8_UP_TIM13.set_priority(crate::irq::DEADMAN);
    pac::TIM8.dier().modify(|w| w.set_uie(true));
    interrupt::ADC.set_priority(crate::irq::DEADMAN);
    // SAFETY: the handlers below only touch state they own, atomics, or data behind a
    // critical section; enabling them cannot break another critical section.
    unsafe {
        interrupt::TIM8_UP_TIM13.enable();
        interrupt::ADC.enable();
        interrupt::DMA2_STREAM0.enable();
    }
}

/// The control interrupt: the current samples of this PWM period are in — or the sense DMA
/// failed, which switches the bridge off for good.
#[interrupt]
fn DMA2_STREAM0() {
    static mut LOOP: Option<crate::control::Loop> = None;
    let isr = pac::DMA2.isr(0).read();
    let error = Stall::from_sense_flags(isr.teif(0), isr.dmeif(0), false);
    if error != Stall::None {
        ack_sample();
        crate::control::trip(error);
        return;
    }
    crate::control::on_sample(LOOP);
}

/// The deadman, once per PWM period at TIM8's update (the counter's bottom, before the
/// period's step): two periods without a step switch the bridge off (gms-core's
/// `drive::Deadman`); after a trip the update interrupt is switched off.
#[interrupt]
fn TIM8_UP_TIM13() {
    static mut DEADMAN: Deadman = Deadman::new();
    pac::TIM8.sr().write(|w| w.0 = SR_CLEAR_UIF);
    if DEADMAN.tick(crate::control::steps()) {
        crate::control::trip(Stall::NoStep);
        pac::TIM8.dier().modify(|w| w.set_uie(false));
    }
}

/// The sense ADC overran: the bridge off for good, the interrupt off (its flag cleared).
#[interrupt]
fn ADC() {
    let adc = pac::ADC1;
    if Stall::from_sense_flags(false, false, adc.sr().read().ovr()) != Stall::None {
        crate::control::trip(Stall::AdcOverrun);
    }
    adc.cr1().modify(|w| w.set_ovrie(false));
    adc.sr().modify(|w| w.set_ovr(false));
}

/// The control interrupt before the loop is handed over: bridge off, flags cleared.
pub fn idle_sample() {
    ack_sample();
    pac::TIM8.ccr(0).write(|w| w.set_ccr(0));
    pac::TIM8.ccr(1).write(|w| w.set_ccr(0));
}
