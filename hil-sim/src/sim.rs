//! One closed-loop run: gms-core's controller (the firmware's code) against the plant.

use crate::Error;
use gms_core::controller::{Controller, FfMode};
use gms_core::reference::{Reference, SUB_PER_COUNT, Segment};
use gms_ident::trace::{Metrics, TraceRow, metrics};

use crate::plant::{Energy, Plant};
use crate::scenario::{FF_BLOCKS, MAX_SEGMENTS, Scenario};

/// The result of one run.
pub struct RunResult {
    /// The trace at the position-loop rate.
    pub trace: Vec<TraceRow>,
    /// Its figures.
    pub metrics: Metrics,
    /// The plant's energy ledger at the end.
    pub energy: Energy,
    /// The expanded reference segments.
    pub segments: Vec<Segment>,
}

/// Runs `sc` with feedforward `mode` and the friction draw `seed`.
pub fn run(sc: &Scenario, mode: FfMode, seed: u64) -> Result<RunResult, Error> {
    run_inner(sc, mode, seed).map_err(Error::Run)
}

fn run_inner(sc: &Scenario, mode: FfMode, seed: u64) -> Result<RunResult, String> {
    run_with(sc, mode, seed, false)
}

/// The level oracle, a yardstick for `gms-adaptive` that only a simulation has: the GMS
/// feedforward scaled at every step by the plant's true drift factor (no estimation, no
/// lag). What it cannot gain over `gms`, no estimate of the friction level can.
pub fn run_oracle(sc: &Scenario, seed: u64) -> Result<RunResult, Error> {
    run_oracle_inner(sc, seed).map_err(Error::Run)
}

fn run_oracle_inner(sc: &Scenario, seed: u64) -> Result<RunResult, String> {
    run_with(sc, FfMode::GmsAdaptive, seed, true)
}

fn run_with(sc: &Scenario, mode: FfMode, seed: u64, oracle: bool) -> Result<RunResult, String> {
    let mut cp = sc.controller_params()?;
    cp.ff.mode = mode;
    if oracle {
        cp.ff.adapt.gain = 0.0;
        cp.ff.adapt.min = 0.0;
        cp.ff.adapt.max = 10.0;
    }
    let mut ctrl = Controller::<FF_BLOCKS>::try_new(cp).map_err(|e| e.to_string())?;
    let segments = sc.segments()?;
    let rpc = sc.plant.rad_per_count;
    let mut reference =
        Reference::<MAX_SEGMENTS>::try_new(&segments, rpc as f32, 0).map_err(|e| e.to_string())?;
    let mut plant = Plant::new(&sc.plant, seed)?;
    let n_cur = cp.ratio();
    let dt_pos = ctrl.dt_pos();
    let dt_plant = ctrl.dt_cur() as f64 / sc.plant.substeps as f64;
    let steps = (reference.duration() / dt_pos).ceil() as usize;
    let mut trace = Vec::with_capacity(steps);
    for k in 0..steps {
        // The reference and the measurement at the same instant t_k.
        let r = reference.next(dt_pos);
        let seg = reference.segment_index();
        let count = plant.encoder();
        if oracle {
            ctrl.set_adaptive_scale(plant.drift_factor() as f32);
        }
        let out = ctrl.position_step(count, &r);
        let reference_rad = r.pos as f64 / SUB_PER_COUNT as f64 * rpc;
        let position = count as f64 * rpc;
        let (current, voltage, friction) = (plant.i, plant.voltage, plant.friction);
        let drift = plant.drift_factor();
        for _ in 0..n_cur {
            let i_meas = plant.adc();
            let c = ctrl.current_step(i_meas);
            plant.set_duty(c.duty);
            for _ in 0..sc.plant.substeps {
                plant.step(dt_plant);
            }
        }
        trace.push(TraceRow {
            t: k as f64 * dt_pos as f64,
            reference: reference_rad,
            position,
            error: reference_rad - position,
            current,
            current_cmd: out.i_cmd as f64,
            voltage,
            friction,
            feedforward: out.ff_friction as f64,
            ff_scale: out.ff_scale as f64,
            drift,
            ref_velocity: r.vel as f64,
            segment: seg,
        });
    }
    let metrics = metrics(&trace, &segments, rpc);
    Ok(RunResult {
        trace,
        metrics,
        energy: plant.energy,
        segments,
    })
}
