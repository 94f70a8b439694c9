//! Link-time proof that the control path cannot panic on the target.
//!
//! This binary runs every function of the control path (the friction models, the controller's
//! position and current steps, the reference generator) and the bench protocol (line reader,
//! parser, `execute` with every command, the number parser and formatter) and the firmware's
//! pure control-step logic (`gms_core::drive`: count extension, current scaling, fault checks,
//! step statistics, bridge compare values) and the device core (`gms_core::device`: the
//! protocol front with every command, move planning, start-up, and the control loop's step
//! with its request handling and bumpless hand-over) on inputs the optimiser cannot see,
//! with `panic-never` as its panic handler: that handler refers to a symbol that does not
//! exist, so the build (the `firmware` profile: fat LTO, one codegen unit) links only if no
//! panic (bounds check, overflow, unwrap, …) is reachable from this code. `cargo build -p
//! target-bench --bin no-panic --profile firmware --target thumbv7em-none-eabihf` is the
//! check; it runs in CI.
#![no_std]
#![no_main]

use core::fmt::{self, Write};
use core::hint::black_box;

use cortex_m_rt::entry;
use gms_core::control::controller::Controller;
use gms_core::control::reference::{Reference, Segment};
use gms_core::device::{
    self, Board, ControlLoop, Front, Inputs, LoopLink, Mailbox, ParamStore, StoreError,
};
use gms_core::drive;
use gms_core::friction::presets;
use gms_core::protocol::{self, LineReader};
use gms_core::{FrictionModel, Gms, LuGre, LugreParams, StaticMap, StaticParams, selftest};
use panic_never as _;

/// The supply divider's code at 12 V on the F405 board (1:16, 3.3 V at 4095), as its ADC
/// register holds it for thread mode.
const SUPPLY_12V: u32 = 931;

/// The device core's link on this check: the mailbox here, and waiting on the loop runs
/// the loop one PWM period on inputs the optimiser cannot see (so `ControlLoop::step`, the
/// exchange and the request handling are all covered).
struct CheckLink {
    mailbox: Mailbox,
    core: ControlLoop,
    t: u64,
}

impl LoopLink for CheckLink {
    fn with_mailbox<R>(&mut self, f: impl FnOnce(&mut Mailbox) -> R) -> R {
        f(&mut self.mailbox)
    }
    fn now_us(&self) -> u64 {
        self.t
    }
    fn pause(&mut self) {
        self.t = self.t.wrapping_add(black_box(50));
        if black_box(false) {
            // The analog watchdog's flag, as the shell hands it over.
            self.core.sense_clipped();
        }
        let inp = Inputs {
            encoder: black_box(7),
            current_codes: black_box(16 * 2048), // zero current: 16 conversions at mid-scale
            since_last: black_box(8400),
        };
        let mb = &mut self.mailbox;
        let out = self.core.step(inp, |st, c| mb.exchange(st, c));
        black_box((
            out.compare,
            out.duty,
            out.timing,
            out.sample.map(|s| s.friction),
        ));
        black_box(self.core.finish(black_box(3000), black_box(false)));
    }
    fn supply_code(&mut self) -> u32 {
        black_box(SUPPLY_12V)
    }
}

/// A store in RAM (one record).
struct RamStore(Option<[u8; gms_core::device::RECORD_LEN]>);

impl ParamStore for RamStore {
    fn save(&mut self, rec: &[u8; gms_core::device::RECORD_LEN]) -> Result<(), StoreError> {
        self.0 = Some(*black_box(rec));
        Ok(())
    }
    fn load(&mut self) -> Result<Option<[u8; gms_core::device::RECORD_LEN]>, StoreError> {
        Ok(black_box(self.0))
    }
}

/// A sink that keeps the last byte written.
struct Sink(u8);

impl Write for Sink {
    fn write_str(&mut self, s: &str) -> fmt::Result {
        for b in s.bytes() {
            self.0 = black_box(b);
        }
        Ok(())
    }
}

#[entry]
fn main() -> ! {
    let p = presets::table1();
    let (Ok(mut gms), Ok(mut guide), Ok(mut lugre), Ok(mut map), Ok(mut ctl)) = (
        Gms::try_new(black_box(p)),
        Gms::try_new(black_box(presets::guideway())),
        LuGre::try_new(black_box(LugreParams {
            stribeck: p.stribeck,
            negative: None,
            sigma0: 2.0,
            sigma1: 1e-3,
            sigma: p.sigma,
        })),
        StaticMap::try_new(black_box(StaticParams {
            stribeck: p.stribeck,
            negative: None,
            sigma: p.sigma,
        })),
        Controller::try_new(black_box(selftest::controller_params())),
    ) else {
        loop {
            cortex_m::asm::wfi();
        }
    };
    let segs = [
        Segment::Sine {
            amplitude: 0.05,
            freq: 1.0,
            cycles: 2.0,
        },
        Segment::Move {
            distance: 1e-3,
            vmax: 0.5,
            amax: 50.0,
            jmax: 1e4,
            dwell: 0.1,
        },
    ];
    let Ok(mut reference) = Reference::<8>::try_new(black_box(&segs), 3.8e-6, 0) else {
        loop {
            cortex_m::asm::wfi();
        }
    };
    let board = Board {
        bridge_wake_s: 0.0,
        ..gms_core::boards::f405::BOARD
    };
    let limits = black_box(&board).limits(&selftest::controller_params());
    let mut enc = drive::CountExtender::new(black_box(32), black_box(0));
    let sense = drive::CurrentSense::new(3.3, 4095.0, 3.4, black_box(2048.0));
    let mut stats = drive::StepStats::new();
    let mut faults = drive::Faults::NONE;
    let defaults = device::default_settings();
    let mut store = RamStore(None);
    let Ok(start) = device::startup(store.load(), &defaults, black_box(&board), &mut |l| {
        black_box(l);
    }) else {
        loop {
            cortex_m::asm::wfi();
        }
    };
    let zero = device::calibrate_sense(black_box(&board), black_box(3.4), || {
        Some(black_box(board.sense_oversample * 2048))
    });
    static mut CAPTURE: [f32; 256] = [0.0; 256];
    // SAFETY: the check's only reference to the buffer, taken once.
    let capture = unsafe { &mut *core::ptr::addr_of_mut!(CAPTURE) };
    static mut MAP: [f32; gms_core::control::posmap::MAP_VALUES] =
        [0.0; gms_core::control::posmap::MAP_VALUES];
    // SAFETY: the check's only reference to the table, taken once.
    let map_table = unsafe { &mut *core::ptr::addr_of_mut!(MAP) };
    gms_core::control::posmap::clear(map_table);
    // The controllers' storage (the loop's running one, the front's spare) and the
    // requests', as the firmware's statics.
    static mut CTRL: [Option<device::Ctrl>; 2] = [None, None];
    // SAFETY: the check's only references to the two, taken once.
    let [run, spare] = unsafe { &mut *core::ptr::addr_of_mut!(CTRL) };
    let run = run.insert(start.applied.ctrl.clone());
    let spare = spare.insert(start.applied.ctrl.clone());
    static mut REQUESTS: device::Requests = device::Requests::new();
    // SAFETY: the check's only reference to it, taken once.
    let requests = unsafe { &mut *core::ptr::addr_of_mut!(REQUESTS) };
    let core = ControlLoop::new(
        board,
        start.applied,
        zero.sense,
        zero.faults,
        black_box(0),
        capture,
        run,
    )
    .with_map(map_table);
    let link = CheckLink {
        mailbox: Mailbox::new(),
        core,
        t: 0,
    };
    let mut dev = Front::new(
        link,
        store,
        board,
        start.settings,
        defaults,
        requests,
        spare,
    );
    let mut reader = LineReader::default();
    let mut sink = Sink(0);
    loop {
        // The protocol: bytes the optimiser cannot see, through the reader into execute.
        let byte: u8 = black_box(b'\n');
        if let Some(line) = reader.push(byte) {
            let _ = protocol::execute(&mut dev, line, &mut sink);
        }
        let sample = device::Sample::default();
        let _ = dev.telemetry_line(&mut sink, black_box(&sample));
        // The shell's periodic supply supervision.
        dev.supervise();
        black_box(gms_core::numtext::parse_f32(black_box("1.5e-3")));
        // The firmware's control-step logic.
        let delta = enc.update(black_box(7u32));
        let amps = sense.map_or(0.0, |s| s.amps_sum(black_box(8192), black_box(4)));
        let m = drive::Measured {
            current: amps,
            error: black_box(1e-4),
            delta,
            periods: black_box(1),
            pos: enc.count(),
            cycles: black_box(3000),
        };
        faults.latch(drive::check(&m, &limits, black_box(true)));
        stats.record(black_box(3000));
        black_box((stats.worst(), stats.mean(), faults));
        black_box(drive::bridge_compare(
            black_box(0.3),
            black_box(4200),
            black_box(true),
        ));
        black_box(drive::pwm_timing(168_000_000, black_box(20_000.0), 65_534));
        let dx: f32 = black_box(1e-6);
        let dt: f32 = black_box(1e-4);
        black_box(gms.advance(dx, dt));
        black_box(guide.advance(dx, dt));
        black_box(lugre.advance(dx, dt));
        black_box(map.advance(dx, dt));
        let r = reference.next(dt);
        black_box(ctl.position_step(black_box(12345i64), &r));
        black_box(ctl.current_step(black_box(0.01)));
        black_box(ctl.current_step(black_box(0.01)));
    }
}
