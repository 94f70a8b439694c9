//! The driver of the power stage (`boards/power_stage.rs`) on an STM32F4, common to every
//! board: clocks from the board's description, the bridge on TIM8, the encoder on TIM2, the
//! current sense on ADC1 with DMA2, USB, flash, watchdog. What differs between boards is in
//! `boards/` (one module per board, chosen by a cargo feature); this file re-exports the
//! chosen board's description.
//!
//! The current is sampled by the hardware, not by the CPU: TIM8's OC4REF (channel 4, no pin)
//! is its trigger output (TRGO), rising once per PWM period [`SENSE_TIMING`]`.lead` before the
//! counter's bottom; it starts ADC1's regular sequence of 8 conversions of PC0, which DMA2
//! stream 0 moves into a buffer; the DMA's transfer-complete interrupt is the control
//! interrupt. The sampling instants are centred on the bottom, the middle of the bridge's
//! slow-decay (brake) phase (`drive::bridge_compare`: both inputs high around the bottom, the
//! drive phase centred on the top), where the current's triangular PWM ripple is
//! point-symmetric about its mean, so the centred window's mean is the period's mean. Timers: TIM2 encoder, TIM8 PWM and
//! sense trigger, TIM4 embassy's time driver (none shared).
//!
//! Every raw register access is `f4-regs`' (its functions take the register blocks, and its
//! host tests run them over blocks laid on plain memory); this file passes the chip's blocks
//! and the board's numbers.

use cortex_m::peripheral::DWT;
use embassy_stm32::adc::Adc;
use embassy_stm32::flash::{Blocking, Flash};
use embassy_stm32::gpio::{Level, Output, OutputType, Pull, Speed};
use embassy_stm32::interrupt;
use embassy_stm32::interrupt::InterruptExt;
use embassy_stm32::peripherals::{ADC1, PC0, PC1, TIM2, TIM8};
use embassy_stm32::time::Hertz;
use embassy_stm32::timer::low_level::CountingMode;
use embassy_stm32::timer::qei::{Qei, QeiMode};
use embassy_stm32::timer::simple_pwm::{PwmPin, SimplePwm};
use embassy_stm32::wdg::IndependentWatchdog;
use embassy_stm32::{Peri, bind_interrupts, pac, peripherals};
use f4_regs::{clock, pwm, sense};
use gms_core::drive;

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
    clock::start_hse(
        pac::RCC,
        CLOCKS.hse_bypass,
        DWT::cycle_count,
        HSI_HZ / 1000 * HSE_WAIT_MS,
    )
}

/// How long the start-up calibration waits for one sequence of current samples \[µs\]:
/// 20 PWM periods at the 20 kHz the timer runs at then. A dead chain costs one such wait
/// (gms-core's `calibrate_sense` stops at the first missing reading), well inside the
/// watchdog.
pub const SENSE_WAIT_US: u32 = 1000;

/// The DMA's destination: the last sequence of current-sense conversions.
static SENSE_BUF: sense::SenseBuf<{ SENSE_OVERSAMPLE as usize }> = sense::SenseBuf::new();

/// The control loop's hardware: owned by the control interrupt.
pub struct ControlHw {
    // Kept alive: dropping them would gate the peripherals' clocks or free the pin.
    _adc: Adc<'static, ADC1>,
    _isense: Peri<'static, PC0>,
    _pwm: SimplePwm<'static, TIM8>,
    _qei: Qei<'static, TIM2>,
    _vsupply: Peri<'static, PC1>,
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
        SENSE_BUF.sum()
    }

    /// Waits for the next sequence (at most [`SENSE_WAIT_US`], timed by the DWT cycle
    /// counter) and returns its sum, for the start-up calibration while the control
    /// interrupt is off. `None` if none came: the ADC is not triggered or its DMA stopped,
    /// which the calibration reports as a `current_sense` fault.
    pub fn next_current_codes(&mut self) -> Option<u32> {
        let limit = CLOCKS.hclk_hz() / 1_000_000 * SENSE_WAIT_US;
        sense::next_sum(pac::DMA2, &SENSE_BUF, DWT::cycle_count, limit)
    }

    /// Writes the two bridge inputs' compare values (take effect at the next PWM period).
    #[inline(always)]
    pub fn set_bridge(&mut self, in1: u32, in2: u32) {
        pwm::set_bridge(pac::TIM8, in1, in2);
    }

    /// True when the sense's DMA has begun the next sequence (the step started more than
    /// about 16 µs late at 40 kHz): the sum just read may mix two periods
    /// (`f4_regs::sense::next_sequence_started`).
    #[inline(always)]
    pub fn sense_stale(&self) -> bool {
        sense::next_sequence_started(pac::DMA2, SENSE_OVERSAMPLE as u16)
    }

    /// True when one of the current sense's conversions since the last call read 0 or 4095
    /// (the ADC's analog watchdog, `f4_regs::sense::clipped`).
    #[inline(always)]
    pub fn sense_clipped(&self) -> bool {
        sense::clipped(pac::ADC1)
    }

    /// Starts the supply divider's injected conversion: the step runs after the sense's
    /// sequence ended, so the conversion (96 ADC clocks, 4.6 µs) is done before the next
    /// sequence's trigger (`f4_regs::sense::supply_init`); thread mode reads its result
    /// ([`supply_code`]).
    #[inline(always)]
    pub fn supply_start(&mut self) {
        sense::supply_start(pac::ADC1);
    }

    /// Where the PWM timer is in its period now (gms-core's `drive::pwm_phase`).
    #[inline(always)]
    pub fn pwm_phase(&self) -> u32 {
        pwm::phase(pac::TIM8)
    }

    /// Sets the PWM timer's prescaler and period (register values; preloaded, so they take
    /// effect at the next update) and the sense trigger's lead for them.
    pub fn set_pwm_timing(&mut self, psc: u32, arr: u32) {
        let lead = SENSE_TIMING.lead_counts(PWM_TIMER_HZ, psc);
        pwm::set_timing(pac::TIM8, psc, arr, PWM_MAX_ARR, lead);
    }

    /// Clears the sense DMA's flags (first thing in the interrupt).
    #[inline(always)]
    pub fn ack_sample(&mut self) {
        sense::ack(pac::DMA2);
    }
}

/// Switches the bridge off from any context (panic, HardFault, an unexpected interrupt, the
/// supervisor seeing the loop stalled): register writes only, no lock, callable with
/// interrupts off. Both DRV8871 inputs end low (coast) as GPIO outputs, whatever TIM8 does
/// afterwards; only a reset gives the pins back to the timer.
pub fn bridge_off_now() {
    drive::bridge_off(&mut pwm::BridgeRegs {
        tim: pac::TIM8,
        gpio: pac::GPIOC,
        pins: BRIDGE_PINS,
    });
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

/// The supply divider's latest code (ADC1's JDR1: 0 before the first conversion), read in
/// thread mode: the control step only starts the conversions ([`ControlHw::supply_start`]).
pub fn supply_code() -> u32 {
    u32::from(sense::supply_latest(pac::ADC1))
}

/// Sets up the board. The bridge starts off (both inputs low) and the PWM timer's update
/// interrupt is configured but not enabled: [`start_control`] does that.
pub fn init() -> (ControlHw, Rest) {
    // Reset cause, then clear the flags for the next time.
    let watchdog_reset = clock::watchdog_reset(pac::RCC);

    let p = embassy_stm32::init(config());
    // After embassy's init, which resets SYSCFG (and with it the remap), before anything that
    // could call into the code run from SRAM or take a static from the CCM.
    run_code_from_sram();
    #[cfg(feature = "board-f405")]
    zero_ccm();
    // The watchdog first: from here on a hang resets the MCU (the supervisor feeds it; until
    // it runs, the start-up below takes well under a second).
    let mut watchdog = IndependentWatchdog::new(p.IWDG, WATCHDOG_US);
    watchdog.unleash();
    // A debug halt stops TIM8 (its outputs to their idle level: the bridge coasts) and the
    // watchdog (a breakpoint does not reset the MCU).
    clock::freeze_in_debug(pac::DBGMCU);
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
    clock::flash_accelerator(pac::FLASH, pac::DBGMCU.idcode().read().0, PART.dev_id);

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
    // The bridge inputs' edges at low speed (embassy's AF pins come up at very high speed).
    pwm::low_speed(pac::GPIOC, BRIDGE_PINS);
    // Off-state when idle: outputs low whenever MOE is cleared.
    pwm::idle_low(pac::TIM8);
    pwm::break_on_clock_failure(pac::TIM8);
    let mut tim8 = pac::TIM8;
    let update_at_bottom = pwm::align_update_to_bottom(&mut tim8, pwm::UPDATE_POLLS);
    pac::TIM8.sr().write(|w| w.0 = 0);
    // The sense trigger: channel 4's OC4REF as TRGO, rising `lead` before the bottom.
    pwm::sense_trigger(pac::TIM8, SENSE_TIMING.lead_counts(PWM_TIMER_HZ, 0) as u16);

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
    // The full 32-bit range and the input filter for the encoder's highest count rate.
    let (filter, _window) = drive::encoder_filter(ENCODER_TIMER_HZ, ENCODER_MAX_RATE);
    f4_regs::encoder::range_and_filter(pac::TIM2, filter);

    let adc = Adc::new(p.ADC1);
    // The control interrupt stays off in the NVIC (embassy's init enabled every DMA stream's)
    // until the loop is handed over; the start-up calibration polls the flag meanwhile.
    interrupt::DMA2_STREAM0.disable();
    sense::init(
        sense::SenseRegs {
            rcc: pac::RCC,
            gpio: pac::GPIOC,
            dma: pac::DMA2,
            adc: pac::ADC1,
        },
        sense::SenseLayout {
            pin: SENSE_PIN,
            channel: SENSE_CHANNEL,
            conversions: SENSE_OVERSAMPLE as u8,
            watchdog: sense_watchdog(),
        },
        SENSE_BUF.addr(),
    );
    // The motor supply's divider (PC1, ADC1_IN11): an injected conversion the control step
    // starts after it read its sequence; thread mode reads its data register (`supply_code`).
    sense::supply_init(pac::ADC1, pac::GPIOC, SUPPLY_PIN, SUPPLY_CHANNEL);

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
        // Reception by our own circular DMA on stream 5 (`f4_regs::uart_rx`), read by the
        // stream's count: embassy's ring-buffered reader reads DR at every call and can take a
        // byte from under the DMA (embassy-rs/embassy issue 1556). embassy's `UartRx` is kept
        // (it owns the pins and the stream) and never read.
        let ring = RX_RING.take();
        let ring = f4_regs::uart_rx::Ring {
            addr: ring.as_mut_ptr(),
            len: ring.len() as u16,
        };
        let stream = f4_regs::uart_rx::RxStream {
            dma: pac::DMA1,
            stream: 5,
            channel: 4,
        };
        if !f4_regs::uart_rx::start(stream, pac::USART2, ring) {
            defmt::error!("USART2's receive DMA stream did not stop: no reception");
        }
        // Transmission by our own stream 6 from the port's buffer (`f4_regs::uart_tx`): the
        // next batch is formatted while this one is on the line. embassy's `UartTx` is kept
        // (it owns the pin and the stream) and never written.
        static TX_BUF: static_cell::ConstStaticCell<[u8; crate::port::TX_BUF]> =
            static_cell::ConstStaticCell::new([0; crate::port::TX_BUF]);
        crate::port::HostPort {
            _tx: tx,
            tx_stream: f4_regs::uart_tx::TxStream {
                dma: pac::DMA1,
                stream: 6,
                channel: 4,
            },
            tx_buf: TX_BUF.take(),
            _rx: rx,
            stream,
            ring,
            at: 0,
            watch: gms_core::protocol::RingWatch::new(),
            error_seen: false,
            suspect: 0,
            started: false,
        }
    };

    let (run_pin, fault_pin) = crate::boards::led_pins!(p);
    let hw = ControlHw {
        _adc: adc,
        _isense: p.PC0,
        _pwm: pwm,
        _qei: qei,
        _vsupply: p.PC1,
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
/// [`crate::irq::CONTROL`], and the ADC's overrun above it at [`crate::irq::DEADMAN`]. The
/// deadman follows once the loop has run ([`arm_deadman`]).
pub fn start_control() {
    sense::ack(pac::DMA2);
    // The NVIC kept the interrupt pending while it was masked: without this the handler
    // would run once at once, mid-sequence.
    interrupt::DMA2_STREAM0.unpend();
    interrupt::DMA2_STREAM0.set_priority(crate::irq::CONTROL);
    interrupt::ADC.set_priority(crate::irq::DEADMAN);
    // SAFETY: the handlers below only touch state they own, atomics, or data behind a
    // critical section; enabling them cannot break another critical section.
    unsafe {
        interrupt::ADC.enable();
        interrupt::DMA2_STREAM0.enable();
    }
}

/// Enables the deadman (TIM8's update, once per period at the counter's bottom) at
/// [`crate::irq::DEADMAN`], above the control interrupt: after the loop's first step, so that
/// its first periods count steps that the loop takes, not the start's own gap.
pub fn arm_deadman() {
    pwm::deadman_arm(pac::TIM8);
    interrupt::TIM8_UP_TIM13.unpend();
    interrupt::TIM8_UP_TIM13.set_priority(crate::irq::DEADMAN);
    // SAFETY: the deadman's handler touches its own state, an atomic and the bridge's
    // registers (`control.rs`).
    unsafe { interrupt::TIM8_UP_TIM13.enable() };
}

/// The control interrupt before the loop is handed over: bridge off, flags cleared.
pub fn idle_sample() {
    sense::ack(pac::DMA2);
    pwm::set_bridge(pac::TIM8, 0, 0);
}

unsafe extern "C" {
    /// cortex-m-rt's linker symbols: the bottom (just above the statics) and the top of the
    /// stack's region.
    static _stack_end: u32;
    static _stack_start: u32;
}

/// The stack's region and its guard: (bottom, top) \[addresses\].
fn stack_region() -> (u32, u32) {
    (
        core::ptr::addr_of!(_stack_end) as usize as u32,
        core::ptr::addr_of!(_stack_start) as usize as u32,
    )
}

/// The sense ADC's analog watchdog thresholds \[code\]: the ends of the amplifier's linear
/// range, as gms-core decides them (`SenseChain::watchdog_codes`: 249 and 3846 for the INA240
/// on 3.3 V), for the ADC's 12-bit codes.
fn sense_watchdog() -> (u16, u16) {
    let top = sense::TOP_CODE;
    let (low, high) = BOARD.sense.watchdog_codes(u32::from(top));
    let code = |c: u32| u16::try_from(c).unwrap_or(top).min(top);
    (code(low), code(high))
}

/// The F405's `.ccm` statics (not loaded: firmware/build.rs) zeroed, as cortex-m-rt zeroes
/// `.bss`, before any is taken.
#[cfg(feature = "board-f405")]
fn zero_ccm() {
    unsafe extern "C" {
        static mut __sccm: u32;
        static mut __eccm: u32;
    }
    let (start, end) = (
        core::ptr::addr_of_mut!(__sccm),
        core::ptr::addr_of_mut!(__eccm),
    );
    let words = (end as usize - start as usize) / 4;
    for i in 0..words {
        // SAFETY: within the section the linker laid in the CCM; nothing has used it yet.
        unsafe { core::ptr::write_volatile(start.add(i), 0) };
    }
}

/// The control interrupt's code (the linker's `.ramcode`, loaded in flash: firmware/build.rs)
/// copied to its place in SRAM1, which is then mapped at 0, where the code was linked to run
/// (`f4_regs::remap`).
fn run_code_from_sram() {
    unsafe extern "C" {
        static __sramcode: u32;
        static __eramcode: u32;
        static __siramcode: u32;
        static __vector_table: u32;
    }
    /// SRAM1's address: the code linked at 0 + x sits at SRAM1 + x.
    const SRAM1: usize = 0x2000_0000;
    let (start, end, load, table) = (
        core::ptr::addr_of!(__sramcode) as usize,
        core::ptr::addr_of!(__eramcode) as usize,
        core::ptr::addr_of!(__siramcode),
        core::ptr::addr_of!(__vector_table) as usize as u32,
    );
    let regs = f4_regs::remap::RemapRegs {
        rcc: pac::RCC,
        syscfg: pac::SYSCFG,
        scb: f4_regs::mpu::CoreRegs::CORE.scb,
    };
    // SAFETY: the linker put the load image at `__siramcode` and kept SRAM1's first
    // `end - start` bytes out of RAM's sections (`.ramcode.room`, asserted there); nothing has
    // called into the code yet (this runs right after embassy's init); the table is
    // cortex-m-rt's.
    unsafe {
        f4_regs::remap::sram_at_zero(
            regs,
            load,
            (SRAM1 + start) as *mut u32,
            (end - start) / 4,
            table,
        );
    }
}

/// The least stack the guard must leave above it \[bytes\].
const STACK_MIN: u32 = 16 * 1024;

/// Sets up the stack guard (`f4_regs::mpu`: gms-core's `hw::STACK_GUARD_BYTES` at the bottom
/// of the stack's region, MemManage on at the top priority); its base and the stack left above
/// it, or `None` if the statics leave no room.
pub fn stack_guard() -> Option<(u32, u32)> {
    let (end, start) = stack_region();
    let size = gms_core::boards::hw::STACK_GUARD_BYTES;
    let (base, left) = f4_regs::mpu::guard_region(end, start, size, STACK_MIN)?;
    // SAFETY: the core's own MPU and SCB; nothing uses the guard's memory (the stack is far
    // above it, the statics below).
    unsafe { f4_regs::mpu::enable_stack_guard(f4_regs::mpu::CoreRegs::CORE, base, size) };
    Some((base, left))
}

/// The stack's usable region, above the guard (or all of it without one): (bottom, top).
pub fn stack_usable() -> (*const u32, *const u32) {
    let (end, start) = stack_region();
    let size = gms_core::boards::hw::STACK_GUARD_BYTES;
    let bottom = f4_regs::mpu::guard_region(end, start, size, STACK_MIN)
        .map(|(base, _)| base + size)
        .unwrap_or(end);
    (bottom as usize as *const u32, start as usize as *const u32)
}
