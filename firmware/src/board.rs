//! Everything that names a pin, a peripheral or a clock: porting the firmware to another STM32
//! or another board is a change in this file only.
//!
//! The board: an STM32F405RG (8 MHz crystal) with
//!
//! | signal | MCU pin | peripheral | goes to |
//! |---|---|---|---|
//! | H-bridge IN1 | PC6 | TIM8_CH1 (20 kHz PWM, center-aligned) | DRV8871 IN1 |
//! | H-bridge IN2 | PC7 | TIM8_CH2 | DRV8871 IN2 |
//! | motor current | PC0 | ADC1_IN10 | INA240A2 OUT (68 mohm shunt in series with the motor, REF at 1.65 V) |
//! | encoder A | PA0 | TIM2_CH1 (32-bit encoder mode) | encoder A (5 V encoders through a 74LVC14 or a divider) |
//! | encoder B | PA1 | TIM2_CH2 | encoder B |
//! | USB D- / D+ | PA11 / PA12 | OTG_FS | USB connector (CDC-ACM) |
//! | LED run | PB0 | GPIO | LED + 1 k to GND |
//! | LED fault | PB1 | GPIO | LED + 1 k to GND |
//! | SWD | PA13 / PA14 | | probe (probe-rs: flash, defmt logs over RTT) |
//!
//! The DRV8871 (a cheap 3.6 A H-bridge breakout): VM = motor supply (6.5-45 V, `lim.v_supply`),
//! ILIM resistor for its own hardware current limit above our trip level, GND common with the
//! MCU. IN1/IN2 both low = coast (outputs off, the state while disabled or faulted), both high
//! = brake; driving is sign-magnitude with slow decay (one input high, the other PWM), so the
//! motor current flows through the shunt in both phases of the PWM and the INA240 (built for
//! in-line motor sensing, rejects the PWM edges) sees it all the time.
//!
//! Current sense: 68 mohm × gain 50 = 3.4 V/A around 1.65 V: ±0.48 A over the 12-bit ADC,
//! 0.24 mA per code (the simulator's ±0.5 A, 12 bits). Timers: TIM2 encoder, TIM8 PWM, TIM4
//! embassy's time driver (none shared).

use embassy_stm32::adc::{Adc, SampleTime};
use embassy_stm32::flash::{Blocking, Flash};
use embassy_stm32::gpio::{Level, Output, OutputType, Pull, Speed};
use embassy_stm32::interrupt;
use embassy_stm32::interrupt::{InterruptExt, Priority};
use embassy_stm32::peripherals::{ADC1, PC0, TIM2, TIM8};
use embassy_stm32::time::Hertz;
use embassy_stm32::timer::low_level::CountingMode;
use embassy_stm32::timer::qei::{Qei, QeiMode};
use embassy_stm32::timer::simple_pwm::{PwmPin, SimplePwm};
use embassy_stm32::usb::Driver;
use embassy_stm32::wdg::IndependentWatchdog;
use embassy_stm32::{Peri, bind_interrupts, pac, peripherals, usb};
use gms_core::device::{Board, SenseChain};
use gms_core::drive::{self, BoardLimits, BridgeOff};

bind_interrupts!(struct Irqs {
    OTG_FS => usb::InterruptHandler<peripherals::USB_OTG_FS>;
});

/// CPU clock [Hz] (DWT cycles).
pub const SYSCLK_HZ: u32 = 168_000_000;
/// TIM8's clock [Hz] (APB2 84 MHz, doubled for timers).
pub const PWM_TIMER_HZ: u32 = 168_000_000;
/// The largest PWM period the 16-bit TIM8 takes [counts] (one below 65535 so that "always
/// on" is a compare value above it).
pub const PWM_MAX_ARR: u32 = 65_534;
/// Width of the encoder counter [bits] (TIM2 is 32-bit).
pub const ENCODER_BITS: u32 = 32;
/// TIM2's clock [Hz] (APB1 42 MHz, doubled for timers; f_DTS with CKD = 0).
pub const ENCODER_TIMER_HZ: u32 = 84_000_000;
/// The highest count rate the encoder input must pass [counts/s]: 3.8 rad/s at 3.8 urad per
/// count, 7.6 times the protocol's move speed limit (0.5 rad/s). The input filter is sized
/// from it (`drive::encoder_filter`: f_DTS/4, N = 8, a 381 ns window: shorter glitches are not
/// counted); an encoder that must count faster needs this raised (and gets a lighter filter).
pub const ENCODER_MAX_RATE: f32 = 1.0e6;

/// ADC reference [V].
pub const ADC_VREF: f32 = 3.3;
/// ADC full scale [codes].
pub const ADC_FULL_SCALE: f32 = 4095.0;
/// Current-sense transimpedance [V/A]: 68 mohm shunt × INA240A2 gain 50.
pub const SENSE_V_PER_A: f32 = 0.068 * 50.0;
/// ADC code at zero current the board is built for [code] (REF at VDD/2).
pub const SENSE_OFFSET_EXPECTED: f32 = 2048.0;
/// How far the measured zero may lie from it [code] (INA240 offset, resistor tolerances).
pub const SENSE_OFFSET_TOLERANCE: f32 = 150.0;
/// ADC conversions averaged per current sample.
pub const SENSE_OVERSAMPLE: u32 = 2;

/// What the board allows (see [`BoardLimits`]).
pub const LIMITS: BoardLimits = BoardLimits {
    trip_factor: 1.5,
    sense_range: 0.48,
    max_error: 0.01,
    max_speed: 100.0,
    clock_hz: SYSCLK_HZ,
    budget_fraction: 0.8,
};

/// The board as the device core sees it.
pub const BOARD: Board = Board {
    pwm_timer_hz: PWM_TIMER_HZ,
    pwm_max_arr: PWM_MAX_ARR,
    encoder_bits: ENCODER_BITS,
    sense_oversample: SENSE_OVERSAMPLE,
    sense: SenseChain {
        amps_per_code: ADC_VREF / ADC_FULL_SCALE / SENSE_V_PER_A,
        zero_code: SENSE_OFFSET_EXPECTED,
        zero_tolerance: SENSE_OFFSET_TOLERANCE,
    },
    limits: LIMITS,
    has_truth: false,
};

/// Watchdog timeout [us], at the LSI's nominal 32 kHz (2.72 s at its 47 kHz maximum): above a
/// 128 KiB sector erase at ×32 (2 s at most, during which nothing runs from flash; the store
/// reloads the watchdog right before each, see `storage.rs`).
pub const WATCHDOG_US: u32 = 4_000_000;

/// Clocks: 8 MHz HSE, PLL to 168 MHz, 48 MHz for USB.
pub fn config() -> embassy_stm32::Config {
    use embassy_stm32::rcc::*;
    let mut c = embassy_stm32::Config::default();
    c.rcc.hse = Some(Hse {
        freq: Hertz(8_000_000),
        mode: HseMode::Oscillator,
    });
    c.rcc.pll_src = PllSource::HSE;
    c.rcc.pll = Some(Pll {
        prediv: PllPreDiv::DIV4,
        mul: PllMul::MUL168,
        divp: Some(PllPDiv::DIV2), // 8 / 4 × 168 / 2 = 168 MHz
        divq: Some(PllQDiv::DIV7), // 336 / 7 = 48 MHz
        divr: None,
    });
    c.rcc.ahb_pre = AHBPrescaler::DIV1;
    c.rcc.apb1_pre = APBPrescaler::DIV4;
    c.rcc.apb2_pre = APBPrescaler::DIV2;
    c.rcc.sys = Sysclk::PLL1_P;
    c
}

/// The control loop's hardware: owned by the control interrupt.
pub struct ControlHw {
    adc: Adc<'static, ADC1>,
    isense: Peri<'static, PC0>,
    // Kept alive: dropping them would gate the timers' clocks.
    _pwm: SimplePwm<'static, TIM8>,
    _qei: Qei<'static, TIM2>,
}

impl ControlHw {
    /// The encoder's raw 32-bit count.
    #[inline(always)]
    pub fn encoder_raw(&self) -> u32 {
        pac::TIM2.cnt().read()
    }

    /// Sum of [`SENSE_OVERSAMPLE`] ADC codes of the motor current.
    #[inline(always)]
    pub fn current_codes(&mut self) -> u32 {
        let mut sum = 0;
        for _ in 0..SENSE_OVERSAMPLE {
            sum += self
                .adc
                .blocking_read(&mut self.isense, SampleTime::CYCLES15) as u32;
        }
        sum
    }

    /// Writes the two bridge inputs' compare values (take effect at the next PWM period).
    #[inline(always)]
    pub fn set_bridge(&mut self, in1: u32, in2: u32) {
        let clamp = |v: u32| v.min(u16::MAX as u32) as u16;
        pac::TIM8.ccr(0).write(|w| w.set_ccr(clamp(in1)));
        pac::TIM8.ccr(1).write(|w| w.set_ccr(clamp(in2)));
    }

    /// Sets the PWM timer's prescaler and period (register values; preloaded, so they take
    /// effect at the next update).
    pub fn set_pwm_timing(&mut self, psc: u32, arr: u32) {
        pac::TIM8.psc().write_value(psc.min(u16::MAX as u32) as u16);
        pac::TIM8
            .arr()
            .write(|w| w.set_arr(arr.min(PWM_MAX_ARR) as u16));
    }

    /// Clears the PWM timer's update flag (first thing in the interrupt).
    #[inline(always)]
    pub fn ack_update(&mut self) {
        pac::TIM8.sr().write(|w| {
            w.0 = !0;
            w.set_uif(false)
        });
    }
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
            w.set_br(6, true);
            w.set_br(7, true);
        });
    }
    fn pins_to_gpio_outputs(&mut self) {
        use embassy_stm32::pac::gpio::vals::Moder;
        pac::GPIOC.moder().modify(|w| {
            w.set_moder(6, Moder::OUTPUT);
            w.set_moder(7, Moder::OUTPUT);
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
    /// USB OTG FS driver.
    pub usb: Driver<'static, peripherals::USB_OTG_FS>,
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
}

/// Sets up the board. The bridge starts off (both inputs low) and the PWM timer's update
/// interrupt is configured but not enabled: [`start_control`] does that.
pub fn init(ep_out_buffer: &'static mut [u8; 256]) -> (ControlHw, Rest) {
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
    // Flash accelerator on: embassy-stm32 0.6's RCC set-up (rcc/f247.rs) writes FLASH_ACR's
    // LATENCY only (`FLASH.acr().write(|w| w.set_latency(..))`), so the prefetch buffer and the
    // instruction and data caches stay at their reset value, off (RM0090 §3.5.2, §3.9.1):
    // at 168 MHz with 5 wait states every fetch outside the prefetch stalls. The caches are
    // empty after reset, so no ICRST/DCRST is needed before enabling them. With the data cache
    // on, lines of the parameter sectors read before an erase or a write could be served stale
    // afterwards: embassy's flash driver (flash/f4.rs) only touches DCEN on dual-bank parts
    // (erratum 2.2.12), so `storage.rs` flushes the data cache after each erase and write, as
    // ST's HAL does after an erase (`FLASH_FlushCaches`).
    pac::FLASH.acr().modify(|w| {
        w.set_prften(true);
        w.set_icen(true);
        w.set_dcen(true);
    });

    // PWM: TIM8 CH1/CH2, center-aligned (the update event at the counter's bottom, every
    // other one through the repetition counter, so one interrupt per period).
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
    // Off-state when idle: outputs forced to their idle level (OIS1 = OIS2 = 0: low) whenever
    // MOE is cleared, by software, a debug halt or a panic (RM0090 §17.4.18).
    pac::TIM8.bdtr().modify(|w| {
        w.set_ossi(pac::timer::vals::Ossi::IDLE_LEVEL);
    });
    pac::TIM8.cr2().modify(|w| {
        w.set_ois(0, false);
        w.set_ois(1, false);
    });
    pac::TIM8.rcr().write(|w| w.set_rep(1));
    pac::TIM8.sr().write(|w| w.0 = 0);
    pac::TIM8.dier().modify(|w| w.set_uie(true));

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

    let mut usb_cfg = usb::Config::default();
    usb_cfg.vbus_detection = false;
    let usb = Driver::new_fs(p.USB_OTG_FS, Irqs, p.PA12, p.PA11, ep_out_buffer, usb_cfg);
    // USB below the control loop (the time driver's TIM4 stays at the top).
    interrupt::OTG_FS.set_priority(Priority::P3);

    let hw = ControlHw {
        adc,
        isense: p.PC0,
        _pwm: pwm,
        _qei: qei,
    };
    let rest = Rest {
        usb,
        flash: Flash::new_blocking(p.FLASH),
        watchdog,
        led_run: Output::new(p.PB0, Level::Low, Speed::Low),
        led_fault: Output::new(p.PB1, Level::Low, Speed::Low),
        watchdog_reset,
    };
    (hw, rest)
}

/// Enables the control interrupt (the PWM timer's update) one level below the time driver.
pub fn start_control() {
    interrupt::TIM8_UP_TIM13.set_priority(Priority::P1);
    // SAFETY: the handler below only touches state it owns or takes through a critical
    // section; enabling it cannot break another critical section.
    unsafe { interrupt::TIM8_UP_TIM13.enable() };
}

/// The control interrupt: the PWM timer's update, once per PWM period.
#[interrupt]
fn TIM8_UP_TIM13() {
    static mut LOOP: Option<crate::control::Loop> = None;
    crate::control::on_pwm_update(LOOP);
}

/// The update interrupt before the loop is handed over: bridge off, flag cleared.
pub fn idle_update() {
    pac::TIM8.sr().write(|w| {
        w.0 = !0;
        w.set_uif(false)
    });
    pac::TIM8.ccr(0).write(|w| w.set_ccr(0));
    pac::TIM8.ccr(1).write(|w| w.set_ccr(0));
}
