//! One closed-loop run: gms-core's controller (the firmware's code) against the plant.

use crate::Error;
use gms_core::control::controller::{Controller, FfMode, PositionOutput};
use gms_core::control::reference::{RefSample, Reference, SUB_PER_COUNT, Segment};
use gms_ident::trace::{Metrics, TraceRow, metrics};

use crate::plant::{Energy, Plant};
use crate::scenario::{FF_BLOCKS, MAX_SEGMENTS, Scenario};

/// The control schedule of a closed-loop run, one PWM period per call: on the first period of
/// each position period the position step, with the encoder's count and the reference at that
/// instant; then, in every period, the current step with the current measured in it, whose
/// duty drives the period after. The device core's `ControlLoop::step` runs this schedule on
/// the board and in the virtual device; `hil-sim/tests/schedule.rs` holds the two equal, duty
/// for duty, on the same inputs, so the runs of `hil-sim run`, `compare` and `demo` are
/// figures of the device core's control.
pub struct Schedule<const N: usize> {
    ctrl: Controller<N>,
    ratio: u32,
    phase: u32,
}

impl<const N: usize> Schedule<N> {
    /// The schedule of `ctrl` (its current periods per position period from its rates).
    pub fn new(ctrl: Controller<N>) -> Schedule<N> {
        let ratio = ctrl.params().ratio().max(1);
        Schedule {
            ctrl,
            ratio,
            phase: 0,
        }
    }

    /// The controller.
    pub fn controller(&mut self) -> &mut Controller<N> {
        &mut self.ctrl
    }

    /// One PWM period: `count` \[counts\] and `reference` are used on a position period's first
    /// period; `i_meas` \[A\] is the current measured in this period. Returns the duty [-] and,
    /// on a position period's first, the position step's output.
    pub fn period(
        &mut self,
        count: i64,
        reference: &RefSample,
        i_meas: f32,
    ) -> (f32, Option<PositionOutput>) {
        let out = (self.phase == 0).then(|| self.ctrl.position_step(count, reference));
        self.phase = (self.phase + 1) % self.ratio;
        (self.ctrl.current_step(i_meas).duty, out)
    }
}

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
    let ctrl = Controller::<FF_BLOCKS>::try_new(cp).map_err(|e| e.to_string())?;
    let dt_pos = ctrl.dt_pos();
    let dt_plant = ctrl.dt_cur() as f64 / sc.plant.substeps as f64;
    let mut sched = Schedule::new(ctrl);
    let segments = sc.segments()?;
    let rpc = sc.plant.rad_per_count;
    let mut reference =
        Reference::<MAX_SEGMENTS>::try_new(&segments, rpc as f32, 0).map_err(|e| e.to_string())?;
    let mut plant = Plant::new(&sc.plant, seed)?;
    let n_cur = cp.ratio();
    let steps = (reference.duration() / dt_pos).ceil() as usize;
    let mut trace = Vec::with_capacity(steps);
    for k in 0..steps {
        // The reference and the measurement at the same instant t_k.
        let r = reference.next(dt_pos);
        let seg = reference.segment_index();
        let count = plant.encoder();
        if oracle {
            sched
                .controller()
                .set_adaptive_scale(plant.drift_factor() as f32);
        }
        let reference_rad = r.pos as f64 / SUB_PER_COUNT as f64 * rpc;
        let position = count as f64 * rpc;
        let (current, voltage, friction) = (plant.i, plant.voltage, plant.friction);
        let drift = plant.drift_factor();
        let mut out = PositionOutput::default();
        for _ in 0..n_cur {
            let i_meas = plant.adc();
            let (duty, pos_out) = sched.period(count, &r, i_meas);
            if let Some(o) = pos_out {
                out = o;
            }
            plant.set_duty(duty, dt_plant * sc.plant.substeps as f64);
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
