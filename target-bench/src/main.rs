//! The gms-core cost benchmark and host/target equivalence check, for an emulated
//! STM32F405 (QEMU `netduinoplus2`, Cortex-M4F) with `-icount shift=0`, where every
//! instruction takes 1 ns of virtual time and SysTick runs at the 168 MHz core clock.
//!
//! Prints, over semihosting, lines the host tool (`cargo target-bench`) turns into
//! instruction counts:
//! - `calib <ticks>`: SysTick ticks for `CALIB_REPS` × 32 extra `nop`s (the tick/instruction
//!   ratio, measured rather than assumed);
//! - `cost <name> <ticks> <calls>`: ticks of `calls` calls minus the same loop without them
//!   (`device_period`: one position period of the device core, `ControlLoop::step` for the
//!   position step and each current step, `finish` after each, the mailbox exchange);
//! - `equiv <name> <hash>`: gms-core's self-test hashes.
#![no_std]
#![no_main]

use core::fmt::Write;
use core::hint::black_box;

use cortex_m::peripheral::{SYST, syst::SystClkSource};
use cortex_m_rt::entry;
use cortex_m_semihosting::{debug, hio};
use gms_core::control::controller::{Controller, FfMode};
use gms_core::control::reference::{Motion, RefSample};
use gms_core::device::{self, Board, ControlLoop, Inputs, Mailbox, MoveRequest, Requests};
use gms_core::friction::presets;
use gms_core::{FrictionModel, Gms, LuGre, LugreParams, StaticMap, StaticParams, selftest};

#[panic_handler]
fn panic(_: &core::panic::PanicInfo) -> ! {
    debug::exit(debug::EXIT_FAILURE);
    loop {
        cortex_m::asm::wfi();
    }
}

/// Repetitions of each measured call.
const CALLS: u32 = 2000;
/// Repetitions of the calibration block.
const CALIB_REPS: u32 = 2000;

/// SysTick ticks elapsed while running `f` (the counter counts down, 24 bits).
fn ticks(f: impl FnOnce()) -> u32 {
    let t0 = SYST::get_current();
    f();
    let t1 = SYST::get_current();
    t0.wrapping_sub(t1) & 0x00ff_ffff
}

macro_rules! nops {
    (8) => {
        cortex_m::asm::nop();
        cortex_m::asm::nop();
        cortex_m::asm::nop();
        cortex_m::asm::nop();
        cortex_m::asm::nop();
        cortex_m::asm::nop();
        cortex_m::asm::nop();
        cortex_m::asm::nop();
    };
}

#[inline(never)]
fn block32() {
    nops!(8);
    nops!(8);
    nops!(8);
    nops!(8);
}

#[inline(never)]
fn block64() {
    nops!(8);
    nops!(8);
    nops!(8);
    nops!(8);
    nops!(8);
    nops!(8);
    nops!(8);
    nops!(8);
}

/// Ticks of `CALLS` calls of `step(i)` minus `CALLS` iterations of `base(i)`.
fn cost(mut step: impl FnMut(u32), mut base: impl FnMut(u32)) -> u32 {
    let with = ticks(|| {
        for i in 0..CALLS {
            step(black_box(i));
        }
    });
    let without = ticks(|| {
        for i in 0..CALLS {
            base(black_box(i));
        }
    });
    with.saturating_sub(without)
}

/// The cost of one position period of the device core on the firmware's timing (20 kHz
/// current loop, 10 kHz position loop: two `ControlLoop::step` calls, each followed by
/// `finish`), enabled, during a `move` at 0.3 rad/s with telemetry every 10th position step,
/// the exchange going through a [`Mailbox`] as on the board; the encoder follows the
/// reference with a 0-3 count lag.
///
/// `shaped`: with both notches and the low-pass on and a frequency-response measurement
/// running (a sine at the current command, demodulated) — `device_period_frf`; `mapped`: with
/// the position map acting (512 bins over a revolution) — `device_period_map`; `table`: the
/// table motion playing instead of the move (a sine of 0.05 rad, 100 points 10 steps apart:
/// two periods' ends among the steps counted, with a correction, each period's error kept) —
/// `device_period_table`.
fn device_period(out: &mut hio::HostStream, shaped: bool, mapped: bool, table: bool) {
    // The F405 board as the firmware links it (gms-core's description: 8 conversions per
    // current sample, a 75 % step budget), its bridge driving at once on `enable`.
    let board = Board {
        bridge_wake_s: 0.0,
        ..gms_core::boards::f405::BOARD
    };
    let mut settings = device::default_settings();
    if shaped {
        settings.shaping = gms_core::control::shaping::ShapingParams {
            notch: [
                gms_core::control::shaping::Notch {
                    f_hz: 700.0,
                    q: 2.0,
                    depth_db: 20.0,
                },
                gms_core::control::shaping::Notch {
                    f_hz: 1500.0,
                    q: 4.0,
                    depth_db: 10.0,
                },
            ],
            lp_hz: 3000.0,
        };
    }
    if mapped {
        settings.map.enable = 1.0;
    }
    let name = match (shaped, mapped, table) {
        (_, _, true) => "device_period_table",
        (true, _, _) => "device_period_frf",
        (false, true, _) => "device_period_map",
        (false, false, _) => "device_period",
    };
    let a = match device::prepare(&settings, &board) {
        Ok(a) => a,
        Err(e) => {
            writeln!(out, "{name}: the defaults do not run on the board: {e:?}").ok();
            return;
        }
    };
    let zero = device::calibrate_sense(&board, 3.4, || Some(board.sense_oversample * 2048));
    let rpc = settings.rad_per_count();
    // One current-loop period in cycles of the step clock, as the loop reckons it: each step
    // on time, as the board's interrupt is (twice it reads as a missed period: `overrun`).
    let period = board.limits(&settings).period_cycles;
    static mut CAPTURE: [f32; 256] = [0.0; 256];
    // SAFETY: the benchmark's references to the buffer, one per call, never alive together.
    let capture = unsafe { &mut *core::ptr::addr_of_mut!(CAPTURE) };
    static mut MAP: [f32; gms_core::control::posmap::MAP_VALUES] =
        [0.0; gms_core::control::posmap::MAP_VALUES];
    // SAFETY: the benchmark's references to the table, one per call, never alive together.
    let map = unsafe { &mut *core::ptr::addr_of_mut!(MAP) };
    gms_core::control::posmap::clear(map);
    static mut TABLE: [f32; gms_core::control::table::TABLE_VALUES] =
        [0.0; gms_core::control::table::TABLE_VALUES];
    // SAFETY: the benchmark's references to the table, one per call, never alive together.
    let tb = unsafe { &mut *core::ptr::addr_of_mut!(TABLE) };
    // The sine x = A (1 − cos), 0.05 rad, and a correction of 20 µN·m's sign of its speed,
    // written where `Set` and `Use` find them (the reference, the first correction buffer).
    let points = 100usize;
    for k in 0..points {
        let (s, c) = gms_core::control::reference::sin_cos(
            core::f32::consts::TAU * k as f32 / points as f32,
        );
        tb[k] = 0.05 / rpc * (1.0 - c);
        tb[gms_core::control::table::TABLE_POINTS + k] = if s >= 0.0 { 20e-6 } else { -20e-6 };
    }
    static mut CTRL: Option<device::Ctrl> = None;
    // SAFETY: the benchmark's references to the storage, one per call, never alive together.
    let ctrl = unsafe { (*core::ptr::addr_of_mut!(CTRL)).insert(a.ctrl.clone()) };
    let mut lp = ControlLoop::new(board, a, zero.sense, zero.faults, 0, capture, ctrl)
        .with_map(map)
        .with_table(tb);
    let mut mb = Mailbox::new();
    // About 0.02 A: the board's 16 conversions of 2048 + 84 codes (3.3 V / 4095 codes / 3.4 V/A).
    let codes = board.sense_oversample * (2048 + 84);
    let mut first = Some(stored(Requests {
        enable: true,
        stream_every: Some(10),
        ..Requests::default()
    }));
    // Requests are taken in the last current step of a position period: a whole period's
    // steps (two at the default 40 kHz current loop under the 20 kHz position loop).
    for _ in 0..lp.ratio() {
        lp.step(
            Inputs {
                encoder: 0,
                current_codes: codes,
                since_last: 0,
            },
            |_, _| first.take(),
        );
    }
    let st = lp.status();
    let Ok(plan) = Motion::plan(st.reference, 0.5, Some(0.3), rpc) else {
        writeln!(out, "{name}: no move planned").ok();
        return;
    };
    let frf = gms_core::control::frf::FrfSpec::new(
        gms_core::control::frf::Injection::Current,
        123.4,
        0.005,
        1_000_000,
        1,
        settings.pos_rate_hz,
    )
    .ok()
    .filter(|_| shaped);
    let ratio = lp.ratio();
    if table {
        use gms_core::control::table::{Geometry, TableRequest};
        let g = Geometry {
            points: points as u32,
            steps: 10,
            origin: 0,
        };
        for t in [
            TableRequest::Set(g),
            TableRequest::Use,
            TableRequest::Run(1_000_000),
        ] {
            let mut r = Some(stored(Requests {
                table: Some(t),
                ..Requests::default()
            }));
            for _ in 0..ratio {
                lp.step(
                    Inputs {
                        encoder: 0,
                        current_codes: codes,
                        since_last: 0,
                    },
                    |st, c| mb.exchange(st, c).or_else(|| r.take()),
                );
            }
        }
    }
    let mut mv = Some(stored(Requests {
        motion: Some(MoveRequest {
            plan,
            from_step: st.steps,
        }),
        frf: frf.map(device::FrfRequest::Start),
        ..Requests::default()
    }))
    .filter(|_| !table);
    for _ in 0..ratio {
        lp.step(
            Inputs {
                encoder: 0,
                current_codes: codes,
                since_last: 0,
            },
            |_, _| mv.take(),
        );
    }
    let reference = core::cell::Cell::new(0i64);
    let c = cost(
        |i| {
            let encoder = ((reference.get() >> 16) - (i & 3) as i64) as u32;
            for _ in 0..ratio {
                let o = lp.step(
                    Inputs {
                        encoder: black_box(encoder),
                        current_codes: black_box(codes),
                        since_last: black_box(period),
                    },
                    |st, c| {
                        let r = mb.exchange(st, c);
                        reference.set(mb.status.reference.pos);
                        r
                    },
                );
                black_box((o.compare, o.sample.map(|s| s.error)));
                black_box(lp.finish(black_box(3000), black_box(false)));
            }
        },
        |i| {
            let encoder = ((reference.get() >> 16) - (i & 3) as i64) as u32;
            for _ in 0..ratio {
                black_box((black_box(encoder), black_box(codes)));
                black_box(black_box(3000u32));
            }
        },
    );
    let measuring = !shaped || mb.frf.state == gms_core::control::frf::FrfState::Measuring;
    let playing = mb.table.state == gms_core::control::table::TableState::Playing
        && mb.table.generation == 1
        && mb.table.done.is_some();
    let running = if table { playing } else { lp.status().moving };
    if lp.enabled() && running && measuring {
        writeln!(out, "cost {name} {c} {CALLS}").ok();
    } else {
        // A fault switched the loop off, or the measurement is not running: the figure
        // would not be the path's it names.
        writeln!(
            out,
            "{name}: the loop left the move or the measurement (faults {:?}, frf {})",
            lp.faults().0,
            mb.frf.state.name()
        )
        .ok();
    }
}

#[entry]
fn main() -> ! {
    let Some(mut p) = cortex_m::Peripherals::take() else {
        debug::exit(debug::EXIT_FAILURE);
        loop {
            cortex_m::asm::wfi();
        }
    };
    // The flash as the boards run it at 168 MHz (RM0090 §3.9.1 FLASH_ACR: LATENCY 5 wait
    // states, PRFTEN, ICEN, DCEN): `rehost bench` counts cycles behind the accelerator as on
    // the board; QEMU leaves the flash interface unimplemented (the write is dropped).
    // SAFETY: FLASH_ACR's address on the STM32F4 (RM0090 §3.9), written once before any
    // measurement; nothing else touches it.
    unsafe { core::ptr::write_volatile(0x4002_3C00 as *mut u32, 0x0000_0705) };
    p.SYST.set_clock_source(SystClkSource::Core);
    p.SYST.set_reload(0x00ff_ffff);
    p.SYST.clear_current();
    p.SYST.enable_counter();
    let Ok(mut out) = hio::hstdout() else {
        debug::exit(debug::EXIT_FAILURE);
        loop {
            cortex_m::asm::wfi();
        }
    };

    // Calibration: 32 nops more per repetition.
    let t64 = ticks(|| {
        for _ in 0..CALIB_REPS {
            block64();
        }
    });
    let t32 = ticks(|| {
        for _ in 0..CALIB_REPS {
            block32();
        }
    });
    writeln!(out, "calib {} {}", t64.saturating_sub(t32), CALIB_REPS * 32).ok();

    let table1 = presets::table1();
    let dither = [3.8e-6f32, -3.8e-6];
    let dt = 1e-4f32;

    // Gms<6>, sticking: a ±1 count dither in pre-sliding (every block elastic).
    if let Ok(mut m) = Gms::try_new(table1) {
        let c = cost(
            |i| {
                black_box(m.advance(black_box(dither[(i & 1) as usize]), black_box(dt)));
            },
            |i| {
                black_box(black_box(dither[(i & 1) as usize]) + black_box(dt));
            },
        );
        writeln!(out, "cost gms6_step_sticking {c} {CALLS}").ok();
    }
    // Gms<6>, slipping: steady sliding at 0.5 rad/s (every block on the slip branch).
    if let Ok(mut m) = Gms::try_new(table1) {
        m.advance(0.5, 1.0);
        let c = cost(
            |_| {
                black_box(m.advance(black_box(0.5 * dt), black_box(dt)));
            },
            |_| {
                black_box(black_box(0.5 * dt) + black_box(dt));
            },
        );
        writeln!(out, "cost gms6_step_slipping {c} {CALLS}").ok();
    }
    let lp = LugreParams {
        stribeck: table1.stribeck,
        negative: None,
        sigma0: 2.0,
        sigma1: 1e-3,
        sigma: table1.sigma,
    };
    if let Ok(mut m) = LuGre::try_new(lp) {
        let c = cost(
            |_| {
                black_box(m.advance(black_box(0.5 * dt), black_box(dt)));
            },
            |_| {
                black_box(black_box(0.5 * dt) + black_box(dt));
            },
        );
        writeln!(out, "cost lugre_step {c} {CALLS}").ok();
    }
    let sp = StaticParams {
        stribeck: table1.stribeck,
        negative: None,
        sigma: table1.sigma,
    };
    if let Ok(mut m) = StaticMap::try_new(sp) {
        let c = cost(
            |_| {
                black_box(m.advance(black_box(0.5 * dt), black_box(dt)));
            },
            |_| {
                black_box(black_box(0.5 * dt) + black_box(dt));
            },
        );
        writeln!(out, "cost static_step {c} {CALLS}").ok();
    }
    // One controller step: position loop (PID + GMS feedforward of both friction sources +
    // inertia feedforward) and one current-loop step, tracking a 0.3 rad/s ramp.
    for (name, mode) in [
        ("controller_step", FfMode::Gms),
        ("controller_step_adaptive", FfMode::GmsAdaptive),
    ] {
        let mut p = selftest::controller_params();
        p.ff.mode = mode;
        let Ok(mut ctl) = Controller::try_new(p) else {
            continue;
        };
        let inc = (0.3f32 * 1e-4 / 3.8e-6 * 65536.0) as i64;
        let c = cost(
            |i| {
                let pos = (i as i64 + 1) * inc;
                let r = RefSample {
                    pos,
                    vel: 0.3,
                    acc: 0.0,
                };
                let count = black_box(pos >> 16) - black_box(i as i64 & 3);
                black_box(ctl.position_step(count, &black_box(r)));
                black_box(ctl.current_step(black_box(0.02)));
            },
            |i| {
                let pos = (i as i64 + 1) * inc;
                let r = RefSample {
                    pos,
                    vel: 0.3,
                    acc: 0.0,
                };
                black_box(black_box(pos >> 16) - black_box(i as i64 & 3));
                black_box(black_box(r));
                black_box(black_box(0.02f32));
            },
        );
        writeln!(out, "cost {name} {c} {CALLS}").ok();
    }

    device_period(&mut out, false, false, false);
    device_period(&mut out, true, false, false);
    device_period(&mut out, false, true, false);
    device_period(&mut out, false, false, true);

    {
        let xs = [0.3f32, 1.7, 0.05, 3.0];
        let c = cost(
            |i| {
                black_box(gms_core::math::exp(black_box(-xs[(i & 3) as usize])));
            },
            |i| {
                black_box(black_box(-xs[(i & 3) as usize]));
            },
        );
        writeln!(out, "cost math_exp {c} {CALLS}").ok();
        let c = cost(
            |i| {
                black_box(gms_core::math::log2(black_box(xs[(i & 3) as usize])));
            },
            |i| {
                black_box(black_box(xs[(i & 3) as usize]));
            },
        );
        writeln!(out, "cost math_log2 {c} {CALLS}").ok();
        let c = cost(
            |i| {
                black_box(gms_core::math::exp2(black_box(xs[(i & 3) as usize])));
            },
            |i| {
                black_box(black_box(xs[(i & 3) as usize]));
            },
        );
        writeln!(out, "cost math_exp2 {c} {CALLS}").ok();
        if let Ok(st) = gms_core::Stribeck::try_new(table1.stribeck, None) {
            let c = cost(
                |i| {
                    black_box(st.magnitude(black_box(xs[(i & 3) as usize])));
                },
                |i| {
                    black_box(black_box(xs[(i & 3) as usize]));
                },
            );
            writeln!(out, "cost stribeck_magnitude {c} {CALLS}").ok();
        }
    }
    writeln!(out, "equiv friction {}", selftest::friction_hash(20_000)).ok();
    writeln!(out, "equiv controller {}", selftest::controller_hash(5_000)).ok();
    writeln!(out, "done").ok();
    debug::exit(debug::EXIT_SUCCESS);
    loop {
        cortex_m::asm::wfi();
    }
}

/// Requests in storage of their own (the loop takes them by reference and gives them back at
/// its next exchange): a ring of eight, the benchmark posting one at a time, so a slot is
/// reused only long after the loop gave it back.
fn stored(r: Requests) -> &'static mut Requests {
    use core::sync::atomic::{AtomicUsize, Ordering};
    static mut POOL: [Requests; 8] = [const { Requests::new() }; 8];
    static NEXT: AtomicUsize = AtomicUsize::new(0);
    let k = NEXT.fetch_add(1, Ordering::Relaxed) % 8;
    // SAFETY: slot k is not referenced any more (see above); the index is the pool's own.
    let slot = unsafe { &mut (*core::ptr::addr_of_mut!(POOL))[k] };
    *slot = r;
    slot
}
