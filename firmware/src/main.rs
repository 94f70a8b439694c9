//! gms firmware for the STM32F405 motor driver: a thin embassy shell around gms-core.
//!
//! - `board`: pins, peripherals, clocks (the only file to change for another board).
//! - `control`: the control loop in the current-sense DMA interrupt (current loop at the PWM
//!   rate, position loop every `ratio`-th period, faults, step timing).
//! - `comms`: USB CDC-ACM and the bench protocol in the thread executor.
//! - `storage`: the parameter record in flash (sequential-storage).
//!
//! Start-up: a first log line on the reset clock (HSI); the HSE started and waited for within
//! a bound (a clear log line and a halt, bridge pins untouched at reset, if it does not come);
//! clocks, the watchdog, peripherals (the bridge off); the brown-out reset at 2.7 V in the
//! option bytes (programmed at the first boot; `enable` refused if it cannot be); the stored parameters (defaults and a
//! latched `invalid_params` fault when missing or invalid); the current-sense zero measured
//! with the bridge off, each reading waited for within a bound (a latched `current_sense`
//! fault and a log line saying why, when the chain is dead or its zero out of the board's
//! window); the control interrupt, and the deadman above it once the loop has stepped; USB. A panic, a HardFault or an
//! unhandled interrupt switches the bridge off before anything else
//! (`board::bridge_off_now`), and so does a debug halt (TIM8 stops); so does the deadman when
//! the control step has not run for two PWM periods, or the sense chain's DMA or ADC fails.
#![no_std]
#![no_main]

mod board;
mod boards;
mod comms;
mod control;
mod irq;
mod port;
mod storage;

use defmt::{error, info, unwrap, warn};
use defmt_rtt as _;
use embassy_executor::Spawner;
use embassy_stm32::wdg::IndependentWatchdog;
use embassy_stm32::{gpio::Output, peripherals::IWDG};
use embassy_time::Timer;
use gms_core::device::{self, ControlLoop, ParamStore as _, SenseTrouble};
use gms_core::drive::{self, Faults, Stall};
use static_cell::{ConstStaticCell, StaticCell};

use crate::control::Loop;

/// The capture buffer's values: the board's (`Board::capture_values`: the F405's 8192 in its
/// CCM, the Nucleo's 4096, for the code run from SRAM).
const CAPTURE_VALUES: usize = board::BOARD.capture_values as usize;

#[embassy_executor::main]
async fn main(spawner: Spawner) {
    // The first line, on the reset clock, before anything that could hang.
    info!(
        "gms firmware {} on board {} ({}): starting on HSI",
        env!("CARGO_PKG_VERSION"),
        board::NAME,
        board::memory::PROBE_RS_CHIP
    );
    // The DWT cycle counter times the HSE's start, the calibration's waits and the control
    // step.
    // SAFETY: only the DCB and DWT are touched, here, before any interrupt starts; nothing
    // else in the firmware writes them.
    let mut cp = unsafe { cortex_m::Peripherals::steal() };
    cp.DCB.enable_trace();
    cp.DWT.enable_cycle_counter();
    if !board::start_hse() {
        // Before embassy's RCC set-up, which would wait for it forever; the watchdog is not
        // started and the bridge pins are still inputs (the DRV8871's pull-downs: coast).
        error!(
            "no HSE ({} Hz{}) within {} ms: {}. Stopped here.",
            board::CLOCKS.hse_hz,
            if board::CLOCKS.hse_bypass {
                ", external clock in bypass"
            } else {
                ", crystal"
            },
            board::HSE_WAIT_MS,
            board::HSE_HINT
        );
        loop {
            cortex_m::asm::wfi();
        }
    }
    let (mut hw, rest) = board::init();
    // The clock security system: the HSE failing from here on switches the bridge off (NMI).
    f4_regs::clock::enable_css(embassy_stm32::pac::RCC);
    info!(
        "clocks up: {} Hz; clock security system on",
        board::CLOCKS.sysclk_hz()
    );

    // The brown-out reset at 2.7 V, in the option bytes: programmed at the first boot, checked
    // at every boot; a board without it refuses to drive (gms-core's `hw::BOR_LEV_2V7`).
    let no_drive = match f4_regs::clock::brown_out_reset(
        embassy_stm32::pac::FLASH,
        gms_core::boards::hw::BOR_LEV_2V7,
        cortex_m::peripheral::DWT::cycle_count,
        board::CLOCKS.hclk_hz(),
    ) {
        f4_regs::clock::BrownOut::Set => {
            info!("brown-out reset at 2.7 V");
            None
        }
        f4_regs::clock::BrownOut::Programmed => {
            info!("brown-out reset set to 2.7 V (option bytes programmed)");
            None
        }
        f4_regs::clock::BrownOut::Failed => {
            error!(
                "brown-out reset not at 2.7 V and the option bytes could not be programmed: \
                 `enable` is refused"
            );
            Some(gms_core::boards::hw::NO_BROWN_OUT_RESET)
        }
    };

    let mut faults = Faults::NONE;
    if rest.update_at_bottom {
        info!("PWM update event at the counter's bottom");
    } else {
        error!(
            "PWM update event not found at the counter's bottom: compare values may be taken mid-step"
        );
    }
    if rest.watchdog_reset {
        warn!("reset by the watchdog");
        faults.latch(Faults::WATCHDOG_RESET);
    }

    // Parameters: the stored set, or the defaults (and a fault if a stored set was unusable);
    // never a mix. The decision is gms-core's.
    // The store keeps the position map too, in a static buffer (8 KiB: out of the stack).
    static STORE_MAP: ConstStaticCell<[u8; gms_core::device::store::MAP_BUFFER_LEN]> =
        ConstStaticCell::new([0; gms_core::device::store::MAP_BUFFER_LEN]);
    let mut store = storage::new(rest.flash).with_map_buffer(STORE_MAP.take());
    let defaults = device::default_settings();
    let mut log = |line: gms_core::device::ReportLine| warn!("{}", line);
    let start = match device::startup(store.load(), &defaults, &board::BOARD, &mut log) {
        Ok(s) => s,
        Err(e) => {
            // The built-in set always passes; stop rather than run without one.
            error!("the built-in parameters cannot run: {}", e);
            loop {
                cortex_m::asm::wfi();
            }
        }
    };
    info!("{}", start.note);
    info!(
        "encoder {} counts/rev, current sense {} V/A (the power stage as built: {} V/A){}",
        start.settings.counts_per_rev,
        start.settings.sense_v_per_a,
        board::SENSE_V_PER_A,
        if start.configured {
            ""
        } else {
            ": the built-in defaults, set enc.counts_per_rev and sense.v_per_a for your axis"
        }
    );
    faults.latch(start.faults);

    // Current-sense zero, with the bridge off (the decision is gms-core's).
    let zero = device::calibrate_sense(&board::BOARD, start.settings.sense_v_per_a, || {
        hw.next_current_codes()
    });
    match zero.trouble {
        SenseTrouble::None => info!("current-sense zero at {} codes", zero.sense.offset),
        SenseTrouble::NoSamples { taken } => error!(
            "current_sense: no ADC samples within {} us after {} of {} readings: the ADC is \
             not triggered by TIM8 or its DMA stopped; the bridge stays off",
            board::SENSE_WAIT_US,
            taken,
            device::ZERO_SAMPLES
        ),
        SenseTrouble::OutOfWindow { mean_code } => warn!(
            "current_sense: zero at {} codes, outside {} +- {}: check the amplifier's supply \
             and reference; the bridge stays off until `clear`",
            mean_code,
            board::BOARD.sense.zero_code,
            board::BOARD.sense.zero_tolerance
        ),
    }
    faults.latch(zero.faults);
    let sense = zero.sense;

    let encoder = hw.encoder_raw();
    // The capture buffer: a zeroed static (in .bss, or the F405's CCM: firmware/build.rs;
    // never copied through the stack) that the loop owns from here on.
    #[cfg_attr(feature = "board-f405", unsafe(link_section = ".ccm"))]
    static CAPTURE: ConstStaticCell<[f32; CAPTURE_VALUES]> =
        ConstStaticCell::new([0.0; CAPTURE_VALUES]);
    let capture = CAPTURE.take();
    // The position map's table, likewise (4 KiB).
    static MAP: ConstStaticCell<[f32; gms_core::control::posmap::MAP_VALUES]> =
        ConstStaticCell::new([0.0; gms_core::control::posmap::MAP_VALUES]);
    let table = MAP.take();
    // The stored map for these settings, or none; a map of another period or bin count is
    // left out with the reason (the decision is gms-core's).
    match gms_core::device::restore_map(&mut store, &start.settings.map, table) {
        Ok(true) => info!("position map loaded from the store"),
        Ok(false) => {}
        Err(why) => warn!("{}", why),
    }
    // The table motion's buffer (reference, two corrections, two period errors: 20 KiB; in
    // the F405's CCM).
    #[cfg_attr(feature = "board-f405", unsafe(link_section = ".ccm"))]
    static TABLE: ConstStaticCell<[f32; gms_core::control::table::TABLE_VALUES]> =
        ConstStaticCell::new([0.0; gms_core::control::table::TABLE_VALUES]);
    let (telemetry_tx, telemetry_rx) = control::telemetry();
    let spare = install_loop(
        hw,
        LoopParts {
            applied: start.applied,
            sense,
            faults,
            encoder,
            capture,
        },
        telemetry_tx,
        table,
        TABLE.take(),
    );
    // The stack guard: an MPU region with no access at the bottom of the stack, before
    // anything runs above thread mode.
    match board::stack_guard() {
        Some((base, left)) => info!(
            "stack guard at {=u32:#x}, {} B; {} B of stack above it",
            base,
            gms_core::boards::hw::STACK_GUARD_BYTES,
            left
        ),
        None => warn!("no room for the stack guard: running without it"),
    }
    // `configured=0` in the status until someone sets, loads or stored this axis's settings.
    // The device front lives in a static (its task holds a reference: the task's future, built
    // on the stack by the spawn, stays small).
    let dev = install_dev(
        store,
        start.settings,
        defaults,
        start.configured,
        spare,
        no_drive,
    );
    #[cfg(feature = "board-f405")]
    let port = {
        // USB CDC-ACM.
        let mut usb_cfg = embassy_usb::Config::new(0x1209, 0x0001);
        usb_cfg.manufacturer = Some("gms");
        usb_cfg.product = Some("gms motor driver");
        // The chip's 96-bit unique ID (RM0090 §39.1) as 24 hex digits: two boards on one PC are
        // two ports with their own serial numbers (udev names them by it).
        usb_cfg.serial_number = Some(embassy_stm32::uid::uid_hex());
        usb_cfg.max_power = 100;
        usb_cfg.max_packet_size_0 = 64;
        static CONFIG_DESC: StaticCell<[u8; 256]> = StaticCell::new();
        static BOS_DESC: StaticCell<[u8; 256]> = StaticCell::new();
        static CONTROL_BUF: StaticCell<[u8; 64]> = StaticCell::new();
        static STATE: StaticCell<embassy_usb::class::cdc_acm::State> = StaticCell::new();
        let mut builder = embassy_usb::Builder::new(
            rest.link,
            usb_cfg,
            CONFIG_DESC.init([0; 256]),
            BOS_DESC.init([0; 256]),
            &mut [],
            CONTROL_BUF.init([0; 64]),
        );
        let class = embassy_usb::class::cdc_acm::CdcAcmClass::new(
            &mut builder,
            STATE.init(embassy_usb::class::cdc_acm::State::new()),
            64,
        );
        // The bus events that end a session (a reset, a suspend, the configuration dropped).
        static BUS_WATCH: StaticCell<port::BusWatch> = StaticCell::new();
        builder.handler(BUS_WATCH.init(port::BusWatch));
        let usb = builder.build();
        spawner.spawn(unwrap!(usb_task(usb)));
        port::HostPort {
            class,
            dtr_seen: false,
            bus_events: 0,
        }
    };
    #[cfg(feature = "board-nucleo-f446")]
    let port = rest.link;
    spawner.spawn(unwrap!(comms_task(port, dev, telemetry_rx)));
    spawner.spawn(unwrap!(supervisor(
        rest.watchdog,
        rest.led_run,
        rest.led_fault
    )));
}

/// What the control loop starts from (start-up's decisions and the capture buffer).
struct LoopParts {
    applied: device::Applied,
    sense: gms_core::drive::CurrentSense,
    faults: Faults,
    encoder: u32,
    capture: &'static mut [f32; CAPTURE_VALUES],
}

/// Builds the control loop in its static and hands it to the interrupt: its own frame (out
/// of `main`'s), the loop copied into the static once and finished there.
#[inline(never)]
fn install_loop(
    hw: board::ControlHw,
    parts: LoopParts,
    telemetry: control::TelemetryTx,
    map: &'static mut [f32; gms_core::control::posmap::MAP_VALUES],
    table: &'static mut [f32; gms_core::control::table::TABLE_VALUES],
) -> device::CtrlBuf {
    // The two controllers' storage: the loop runs one, the protocol side builds the next
    // parameter set in the other (`device::Staged`), and the loop swaps them by reference.
    static RUN: StaticCell<device::Ctrl> = StaticCell::new();
    static SPARE: StaticCell<device::Ctrl> = StaticCell::new();
    let spare = SPARE.init(parts.applied.ctrl.clone());
    let run = RUN.init(parts.applied.ctrl.clone());
    let core = ControlLoop::new(
        board::BOARD,
        parts.applied,
        parts.sense,
        parts.faults,
        parts.encoder,
        parts.capture,
        run,
    );
    if let Some(l) = Loop::new(hw, core, telemetry).install() {
        l.core_mut().attach_map(map);
        l.core_mut().attach_table(table);
        Loop::hand_over(l);
    }
    spare
}

/// Builds the device front (the protocol's side) in its static: its own frame, out of
/// `main`'s. Its task holds a reference, so the task's future (built on the stack by the
/// spawn) stays small.
#[inline(never)]
fn install_dev(
    store: storage::Store,
    settings: gms_core::protocol::Settings,
    defaults: gms_core::protocol::Settings,
    configured: bool,
    spare: device::CtrlBuf,
    no_drive: Option<&'static str>,
) -> &'static mut comms::Dev {
    static DEV: StaticCell<comms::Dev> = StaticCell::new();
    // The requests' storage: the loop acts on it by reference, outside the mailbox's
    // critical section.
    static REQUESTS: ConstStaticCell<device::Requests> =
        ConstStaticCell::new(device::Requests::new());
    // `configured=0` in the status until someone sets, loads or stored this axis's settings.
    DEV.init(
        comms::Dev::new(
            comms::IrqLink,
            store,
            board::BOARD,
            settings,
            defaults,
            REQUESTS.take(),
            spare,
        )
        .with_configured(configured, false)
        .with_table()
        .refusing_to_drive(no_drive),
    )
}

/// A panic switches the bridge off first, then logs, then ends in a HardFault (`udf`), where
/// a debugger (probe-rs) stops with a backtrace; the watchdog, started first thing at
/// start-up, resets the MCU.
#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    use core::sync::atomic::{AtomicBool, Ordering};
    static PANICKED: AtomicBool = AtomicBool::new(false);
    cortex_m::interrupt::disable();
    board::bridge_off_now();
    if !PANICKED.swap(true, Ordering::Relaxed) {
        error!("panic: {}", defmt::Display2Format(info));
    }
    cortex_m::asm::udf()
}

// HardFault and MemManage: MSP back to the top of the stack's region (the fault may have come
// from the stack guard, with SP inside it), then `gms_fault_stop` (`f4_regs::mpu`).
f4_regs::stack_guard_fault_handlers!();

/// A HardFault (a bus or usage fault escalated, a panic's `udf`) or a MemManage fault (the
/// stack ran into its guard), entered on a fresh stack: the bridge off, then wait for the
/// watchdog.
#[unsafe(no_mangle)]
extern "C" fn gms_fault_stop() -> ! {
    board::bridge_off_now();
    loop {
        cortex_m::asm::nop();
    }
}

/// The NMI: the clock security system found the HSE failed (the core now runs on the HSI,
/// every rate a tenth of what it was): the bridge off, `control_stall` latched; the supervisor
/// logs it and stops feeding the watchdog. Nothing here can panic or wait (an NMI preempts
/// even PRIMASK).
#[cortex_m_rt::exception]
unsafe fn NonMaskableInt() {
    board::bridge_off_now();
    if f4_regs::clock::css_ack(embassy_stm32::pac::RCC) {
        control::trip(Stall::ClockLost);
    }
}

/// An interrupt nothing handles: the bridge off, then wait for the watchdog.
#[cortex_m_rt::exception]
unsafe fn DefaultHandler(_irqn: i16) {
    board::bridge_off_now();
    loop {
        cortex_m::asm::nop();
    }
}

#[cfg(feature = "board-f405")]
#[embassy_executor::task]
async fn usb_task(
    mut usb: embassy_usb::UsbDevice<
        'static,
        embassy_stm32::usb::Driver<'static, embassy_stm32::peripherals::USB_OTG_FS>,
    >,
) -> ! {
    usb.run().await
}

#[embassy_executor::task]
async fn comms_task(
    port: port::HostPort,
    dev: &'static mut comms::Dev,
    telemetry: control::TelemetryRx,
) -> ! {
    comms::serve(port, dev, telemetry).await
}

/// How long the supervisor waits for the loop's first step before it arms the deadman \[µs\].
const FIRST_STEP_WAIT_US: u32 = 2000;

/// Starts the control interrupt, then watchdog, LEDs and fault logs, every 250 ms.
///
/// The control interrupt starts here rather than in `main`: `main`'s one poll builds every
/// part of the firmware (its frame, with the spawns', is some 20 KiB of thread stack) and has
/// returned by the time this task first runs, so the loop's interrupts never nest on it.
/// The watchdog is fed only while the control
/// interrupt keeps running (its step counter advances) and the deadman has not tripped: a
/// stall is terminal, the watchdog resets the MCU.
#[embassy_executor::task]
async fn supervisor(
    mut wdg: IndependentWatchdog<'static, IWDG>,
    mut led_run: Output<'static>,
    mut led_fault: Output<'static>,
) -> ! {
    let mut last_steps = 0u64;
    let mut last_faults = Faults::NONE;
    let mut tick = 0u32;
    let mut told = false;
    let mut deepest = 0usize;
    board::start_control();
    // The deadman once the loop has taken its first step (a period is 25-50 us: 2 ms is forty
    // or more); armed all the same if none came, and then it trips within two periods. A
    // bounded spin on the DWT, not a timer: the deadman must not wait on the executor (a task
    // that never yields would keep it unarmed).
    let t0 = cortex_m::peripheral::DWT::cycle_count();
    let limit = board::CLOCKS.hclk_hz() / 1_000_000 * FIRST_STEP_WAIT_US;
    // (No `spin_loop` hint: its YIELD is a no-op on the M4 and not an instruction rehost's
    // emulator takes.)
    while control::steps() == 0 && cortex_m::peripheral::DWT::cycle_count().wrapping_sub(t0) < limit
    {
    }
    board::arm_deadman();
    info!("control loop running");
    loop {
        Timer::after_millis(250).await;
        tick = tick.wrapping_add(1);
        // The stack's high-water mark (cortex-m-rt paints its region before main).
        let (used, region) = stack_use();
        if used >= deepest + 256 {
            deepest = used;
            info!("stack: {} B used at most, of {} B", used, region);
        }
        if drive::stack_low(region - used) {
            control::trip(Stall::StackLow);
        }
        let st = comms::status();
        if st.steps == last_steps {
            // Slower than the deadman, but the last word: the loop no longer runs.
            control::trip(Stall::NoStep);
        }
        last_steps = st.steps;
        // The bench's watchdog check (feature `watchdog-check`): no longer fed after 10 s.
        let checking = cfg!(feature = "watchdog-check") && tick >= 40;
        if checking && tick == 40 {
            warn!("watchdog check: no longer fed; the board must reset within 2.7-4 s");
        }
        match control::stall() {
            Stall::None if !checking => wdg.pet(),
            Stall::None => {}
            cause => {
                if !told {
                    error!(
                        "control_stall: {}: bridge off; the watchdog resets the board",
                        cause.meaning()
                    );
                    told = true;
                }
            }
        }
        if st.faults != last_faults {
            if !st.faults.is_empty() {
                warn!("faults latched: {=u16:#x}", st.faults.0);
            }
            last_faults = st.faults;
        }
        led_fault.set_level((!st.faults.is_empty()).into());
        // Run LED: steady while enabled, 1 Hz blink while disabled.
        let blink = (tick / 2).is_multiple_of(2);
        led_run.set_level((st.enabled || blink).into());
    }
}

/// The stack's deepest use so far and the size of its usable region, above the guard
/// \[bytes\] (`f4_regs::stack`).
fn stack_use() -> (usize, usize) {
    let (bottom, top) = board::stack_usable();
    let region = top as usize - bottom as usize;
    // SAFETY: the region is readable RAM above the guard; words the stack holds are read,
    // never written.
    let unused = unsafe { f4_regs::stack::unused_bytes(bottom, top) };
    (region - unused, region)
}
