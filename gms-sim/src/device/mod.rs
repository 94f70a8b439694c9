//! The virtual device: the simulated axis in real time behind gms-core's device core, the same
//! core the firmware runs (`gms_core::device`): the control loop steps at the PWM rate against
//! the simulated plant, the protocol front answers clients over TCP or a pseudo-terminal. This
//! file only moves numbers: encoder counts and current-sense codes in, the duty out, the
//! mailbox behind a mutex, the store on a file.
//!
//! Clients are served one after another; a client that drops does not stop the device. With
//! `--store FILE` the parameter store is a file holding the image of the board's store flash
//! (gms-core's [`FlashStore`]: same record, same sequential-storage map, same word and sector
//! sizes), written through at every flash write, so a crash leaves what a power cut leaves on a
//! board, and a store written by one is read by the other. Without `--store` the store is in
//! memory (lost at exit).

use crate::Error;
use std::collections::VecDeque;
use std::fs::{File, OpenOptions};
use std::io::{ErrorKind, Read, Seek, SeekFrom, Write};
use std::net::TcpListener;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use embedded_storage_async::nor_flash::{
    ErrorType, NorFlash, NorFlashError, NorFlashErrorKind, ReadNorFlash,
};
use gms_core::device::store::{FlashStore, SECTOR_SIZE, STORE_RANGE, WORD_SIZE};
use gms_core::device::{
    self, Board, ControlLoop, Front, Inputs, LoopLink, Mailbox, ParamStore, Sample, SenseChain,
    Status,
};
use gms_core::drive::BoardLimits;
use gms_core::protocol::{self, LineReader, Settings};

use crate::plant::Plant;
use crate::scenario::Scenario;

/// The virtual device's capture buffer (values), the board's.
pub const CAPTURE_VALUES: u32 = gms_core::boards::power_stage::CAPTURE_VALUES;

/// Telemetry samples kept for the client (0.4 s at 10 kHz; older ones are dropped).
pub const QUEUE: usize = 4000;

/// The simulated board: the F405 board as gms-core describes it (`boards::f405::BOARD`: its
/// PWM timer, encoder counter, sense zero tolerance, trip factor, following-error and speed
/// limits, capture buffer), with what a simulation cannot share: the plant's ADC as the current
/// sense (one conversion per sample, zero at mid-scale; a 3.3 V ADC, so that the plant's range
/// ±`adc_range` is the sense scale `sense.v_per_a` = 1.65 V / `adc_range` of
/// [`Scenario::controller_params`]), sampled at once (no window); step durations in host
/// nanoseconds (`clock_hz` 1e9) with a budget of 1 s at 20 kHz (the host is shared, so only a
/// stalled simulation counts as an overrun); the true friction in the telemetry; a bridge that
/// needs no wake-up.
pub fn board(sc: &Scenario) -> Board {
    let real = gms_core::boards::f405::BOARD;
    let adc = Adc::new(sc);
    Board {
        sense_oversample: 1,
        sense: SenseChain {
            vref: SIM_ADC_VREF,
            full_scale: (2.0 * adc.mid) as f32,
            zero_code: adc.mid as f32,
            // The plant's ADC is linear to its ends (its range is the scenario's).
            linear_margin_v: 0.0,
            window_s: 0.0,
            edge_settle_s: 0.0,
            ..real.sense
        },
        limits: BoardLimits {
            clock_hz: 1_000_000_000,
            budget_fraction: 20_000.0,
            ..real.limits
        },
        has_truth: true,
        bridge_wake_s: 0.0,
        ..real
    }
}

/// The simulated ADC's reference \[V\]: the plant's ±`adc_range` spans it.
pub const SIM_ADC_VREF: f32 = 3.3;

/// The plant's current sense as ADC codes: one code per LSB, zero current mid-scale.
struct Adc {
    lsb: f64,
    mid: f64,
    top: f64,
    /// The chain's zero off mid-scale (`[plant.sense] offset_codes`) \[codes\].
    offset: f64,
    /// The lowest and highest codes the amplifier's output reaches (`[plant.sense] swing_v`).
    limits: (f64, f64),
}

impl Adc {
    fn new(sc: &Scenario) -> Adc {
        let full = (1u64 << sc.plant.adc_bits) as f64;
        Adc {
            lsb: 2.0 * sc.plant.adc_range / full,
            mid: full / 2.0,
            top: full - 1.0,
            offset: sc.plant.sense.offset_codes,
            limits: sc.plant.sense.code_limits(SIM_ADC_VREF as f64, full - 1.0),
        }
    }

    /// The code of the sense chain's output \[A\] (the plant's `sense`, noise included):
    /// quantised around the chain's zero, held within the amplifier's swing.
    fn code(&self, amps: f64) -> u32 {
        ((amps / self.lsb).round() + self.mid + self.offset)
            .round()
            .clamp(self.limits.0.ceil(), self.limits.1.floor()) as u32
    }
}

/// The loop side: the device core's control loop and the plant, owned by the real-time thread.
struct Sim {
    core: ControlLoop,
    plant: Plant,
    adc: Adc,
    /// The board's sense chain (its analog watchdog's thresholds).
    sense: gms_core::device::SenseChain,
    /// The board's supply divider, read on the sense's ADC.
    supply: Option<gms_core::device::SupplySense>,
    /// Its code after the last tick (0: no divider), as the board's ADC data register holds
    /// it for thread mode.
    supply_code: u32,
    substeps: u32,
    /// Simulated time \[s\].
    t: f64,
    /// The truth at each position step, while recorded.
    truth: Option<Vec<Truth>>,
}

/// The truth at one position step: what the device saw and where the axis really was.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Truth {
    /// The device's position step.
    pub steps: u64,
    /// Its reference \[1/65536 count\].
    pub reference: i64,
    /// Its encoder count \[counts\].
    pub pos: i64,
    /// The true angle at the step's sampling instant \[counts, fractional\] (the encoder
    /// reads its floor: the count `n` is the interval `[n, n + 1)`).
    pub theta_counts: f64,
}

impl Truth {
    /// The error against the true position \[counts\]: the reference minus the true angle,
    /// shifted by the half count the encoder's floor takes off on average (so that a perfect
    /// tracking of the reading scores alike).
    pub fn true_error(&self) -> f64 {
        self.reference as f64 / 65536.0 - (self.theta_counts - 0.5)
    }

    /// The error the device saw \[counts\]: the reference minus the encoder's count.
    pub fn device_error(&self) -> f64 {
        self.reference as f64 / 65536.0 - self.pos as f64
    }
}

impl Sim {
    /// The board's supply divider read as its ADC would (no noise: a 1:16 divider's codes
    /// are 13 mV) at the plant's supply terminal now; 0 without a divider.
    fn supply_code_now(&self) -> u32 {
        self.supply.map_or(0, |ss| {
            ss.code(
                self.plant.supply_volts(),
                self.sense.vref,
                self.sense.full_scale,
            )
        })
    }

    /// One position period: `ratio` PWM periods of the core, the plant between them.
    /// `exchange` is the mailbox's (behind a mutex or local); step durations are timed on the
    /// host when `timed` (real time), else counted as 0 (simulated time).
    fn tick(
        &mut self,
        mut exchange: impl FnMut(
            &dyn Fn() -> Status,
            device::Handover<'_>,
        ) -> Option<device::RequestsBuf>,
        queue: &Mutex<VecDeque<Sample>>,
        timed: bool,
    ) {
        let n = self.core.ratio();
        // The true angle at the position step's sampling instant (this tick's first period).
        let (theta, count) = (self.plant.theta, self.plant.encoder());
        let dt_plant = self.core.controller().dt_cur() as f64 / self.substeps as f64;
        for _ in 0..n {
            let code = self.adc.code(self.plant.sense(1.0));
            if self.sense.watchdog_trips(code, self.adc.top as u32) {
                // Past the sense's linear range (the ends of the ADC's: its margin is 0), as
                // the board's analog watchdog sees it (gms-core decides where).
                self.core.sense_clipped();
            }
            let inp = Inputs {
                encoder: self.plant.encoder() as u32,
                current_codes: code,
                // Simulated time: the steps are exactly one period apart (in the board's
                // step clock, ns), so none is ever missed.
                since_last: (self.core.controller().dt_cur() as f64 * 1e9) as u32,
            };
            let t0 = timed.then(Instant::now);
            let out = self.core.step(inp, &mut exchange);
            let ns = t0.map_or(0, |t| t.elapsed().as_nanos().min(u32::MAX as u128) as u32);
            // The simulated bridge takes each period's duty in time: never late.
            self.core.finish(ns, false);
            let duty = if self.core.enabled() { out.duty } else { 0.0 };
            if let Some(mut s) = out.sample {
                s.friction_true = self.plant.friction as f32;
                let mut q = relock(queue);
                if q.len() == QUEUE {
                    q.pop_front();
                }
                q.push_back(s);
            }
            self.plant.set_duty(duty, dt_plant * self.substeps as f64);
            for _ in 0..self.substeps {
                self.plant.step(dt_plant);
            }
            self.t += dt_plant * self.substeps as f64;
        }
        self.supply_code = self.supply_code_now();
        if let Some(truth) = &mut self.truth {
            let st = self.core.status();
            truth.push(Truth {
                steps: st.steps,
                reference: st.reference.pos,
                pos: count,
                theta_counts: theta / self.core.controller().rad_per_count() as f64,
            });
        }
    }
}

/// A virtual device just powered up: the loop on the plant, the store, and what the start-up
/// decided.
struct PowerUp {
    sim: Sim,
    store: FlashStore<HostFlash>,
    board: Board,
    settings: Settings,
    defaults: Settings,
    /// The front's requests storage.
    requests: device::RequestsBuf,
    /// The front's spare controller storage.
    spare: device::CtrlBuf,
    /// Why the start-up latched faults, if it did.
    why: Option<&'static str>,
}

/// The start-up of the board, on the plant: the parameter set from the store (gms-core's
/// decision), the current-sense zero measured with the bridge off (gms-core's), the loop at
/// rest at the encoder's reading.
fn power_up(sc: &Scenario, flash: HostFlash) -> Result<PowerUp, String> {
    let defaults = sc.controller_params()?;
    let board = board(sc);
    let mut store = FlashStore::new(flash).with_map_buffer(Box::leak(
        vec![0u8; gms_core::device::store::MAP_BUFFER_LEN].into_boxed_slice(),
    ));
    // The device's log of a record from another firmware, as the board's defmt log.
    let mut log = |line: gms_core::device::ReportLine| eprintln!("device: {line}");
    let start = device::startup(store.load(), &defaults, &board, &mut log)
        .map_err(|e| format!("the scenario's controller: {e}"))?;
    // The position map's table: the stored map for these settings, or none (a stored map of
    // another geometry is left out, as on the board).
    let table = Box::leak(vec![0.0; gms_core::control::posmap::MAP_VALUES].into_boxed_slice());
    let _ = gms_core::device::restore_map(&mut store, &start.settings.map, table);
    let adc = Adc::new(sc);
    let mut plant = Plant::new(&sc.plant, sc.plant.seed)?;
    let zero = device::calibrate_sense(&board, start.settings.sense_v_per_a, || {
        Some(adc.code(plant.sense(1.0)))
    });
    let mut faults = start.faults;
    faults.latch(zero.faults);
    let why = if !start.faults.is_empty() {
        Some(start.note)
    } else if !zero.faults.is_empty() {
        Some("current-sense zero out of the board's window")
    } else {
        None
    };
    let encoder = plant.encoder() as u32;
    // The controllers' storage: the loop's running one and the front's spare (statics on a
    // board; one pair per power-up here).
    let spare: &'static mut device::Ctrl = Box::leak(Box::new(start.applied.ctrl.clone()));
    Ok(PowerUp {
        sim: Sim {
            core: ControlLoop::new(
                board,
                start.applied,
                zero.sense,
                faults,
                encoder,
                // One buffer per power-up of a virtual device (a board's is a static).
                Box::leak(vec![0.0; CAPTURE_VALUES as usize].into_boxed_slice()),
                Box::leak(Box::new(spare.clone())),
            )
            .with_map(table)
            .with_table(Box::leak(
                vec![0.0; gms_core::control::table::TABLE_VALUES].into_boxed_slice(),
            )),
            plant,
            adc,
            sense: board.sense,
            supply: board.supply,
            supply_code: 0,
            substeps: sc.plant.substeps,
            t: 0.0,
            truth: None,
        },
        store,
        board,
        settings: start.settings,
        defaults,
        requests: Box::leak(Box::new(device::Requests::new())),
        spare,
        why,
    })
}

/// The mutex's value, also after a thread panicked holding it (the data is plain numbers).
fn relock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|p| p.into_inner())
}

mod flash;
mod local;
mod server;

pub use flash::{HostFlash, HostFlashError, IMAGE_LEN};
pub use local::LocalDevice;
pub use server::{BUSY, Endpoint, serve};
