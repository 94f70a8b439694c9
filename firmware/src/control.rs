//! The control loop: runs in the PWM timer's update interrupt (one call per PWM period, the
//! current-loop rate), so that it is locked to the PWM and independent of everything the
//! communication side does. No allocation, no logging, no waiting lock: one short critical
//! section per position period exchanges requests and status with the comms task.
//!
//! Each call: encoder (count extension), motor current (ADC), every `ratio`-th call a
//! position step (reference, controller, all fault checks), then the current step and the
//! bridge's compare values. A fault switches the bridge off in the same call. The step's own
//! duration comes from the DWT cycle counter.

use core::cell::RefCell;

use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::channel::Channel;
use gms_core::controller::{Controller, PositionOutput};
use gms_core::drive::{
    self, CountExtender, CurrentSense, Faults, Limits, Measured, StepStats, bridge_compare,
};
use gms_core::reference::{Motion, RefSample, Reference, SUB_PER_COUNT, SubCounts};

use crate::board::{self, ControlHw};

/// The controller type the firmware runs (6 GMS blocks, as the protocol's settings).
pub type Ctrl = Controller<6>;

/// A complete, validated parameter set for the loop, applied between two steps.
pub struct Applied {
    /// The controller (at rest).
    pub ctrl: Ctrl,
    /// The safety limits that go with it.
    pub limits: Limits,
    /// PWM timer prescaler and period (register values).
    pub psc: u32,
    /// PWM period [timer counts].
    pub arr: u32,
}

/// What the comms side asks of the loop; taken whole at the start of a position step.
#[derive(Default)]
pub struct Requests {
    /// A new parameter set (the bridge is switched off for the change).
    pub apply: Option<Applied>,
    /// Switch the bridge on (ignored while a fault is latched).
    pub enable: bool,
    /// Switch the bridge off.
    pub disable: bool,
    /// Clear the latched faults.
    pub clear: bool,
    /// Latch these faults (e.g. invalid stored parameters found at start-up).
    pub latch: Faults,
    /// Start a motion from the current reference position.
    pub motion: Option<Reference<1>>,
    /// Telemetry every N position steps (0: off).
    pub stream_every: Option<u32>,
    /// Reset the step statistics.
    pub reset_stats: bool,
}

impl Requests {
    fn pending(&self) -> bool {
        self.apply.is_some()
            || self.enable
            || self.disable
            || self.clear
            || !self.latch.is_empty()
            || self.motion.is_some()
            || self.stream_every.is_some()
            || self.reset_stats
    }
}

/// What the loop shows the comms side (updated every position step).
#[derive(Clone, Copy, Default)]
pub struct Status {
    /// Position steps since start.
    pub steps: u64,
    /// Position-loop rate [Hz].
    pub pos_rate_hz: f32,
    /// Encoder position [counts].
    pub pos: i64,
    /// Reference position [1/65536 count].
    pub reference: SubCounts,
    /// Position error [rad].
    pub error: f32,
    /// Friction feedforward [N·m].
    pub ff: f32,
    /// Motor current [A].
    pub current: f32,
    /// Last duty [-1, 1].
    pub duty: f32,
    /// Latched faults.
    pub faults: Faults,
    /// Bridge on.
    pub enabled: bool,
    /// A motion is being played.
    pub moving: bool,
    /// Control-step durations [cycles].
    pub stats: StepStats,
    /// Current-sense zero [code].
    pub sense_offset: f32,
    /// The adaptive scale on the friction feedforward (`ff.adapt.scale`) [-].
    pub adapt_scale: f32,
}

/// One telemetry sample.
#[derive(Clone, Copy)]
pub struct Sample {
    /// Position steps since start.
    pub steps: u64,
    /// Encoder position [counts].
    pub pos: i64,
    /// Reference [1/65536 count].
    pub reference: SubCounts,
    /// Position error [rad].
    pub error: f32,
    /// Friction feedforward [N·m].
    pub ff: f32,
    /// Motor current [A].
    pub current: f32,
    /// Friction estimate: motor torque k_M i minus J a_ref [N·m].
    pub friction: f32,
}

/// The exchange between the loop and the comms task.
pub struct Shared {
    /// Requests to the loop.
    pub requests: Requests,
    /// The loop's latest status.
    pub status: Status,
}

/// Requests and status, behind a critical section (held for a copy, never for a step).
pub static SHARED: Mutex<CriticalSectionRawMutex, RefCell<Shared>> =
    Mutex::new(RefCell::new(Shared {
        requests: Requests {
            apply: None,
            enable: false,
            disable: false,
            clear: false,
            latch: Faults::NONE,
            motion: None,
            stream_every: None,
            reset_stats: false,
        },
        status: Status {
            steps: 0,
            pos_rate_hz: 0.0,
            pos: 0,
            reference: 0,
            error: 0.0,
            ff: 0.0,
            current: 0.0,
            duty: 0.0,
            faults: Faults::NONE,
            enabled: false,
            moving: false,
            stats: StepStats::new(),
            sense_offset: 0.0,
            adapt_scale: 1.0,
        },
    }));

/// Telemetry samples to the comms task (dropped when it falls behind).
pub static TELEMETRY: Channel<CriticalSectionRawMutex, Sample, 64> = Channel::new();

/// The loop's state, handed to the interrupt once at start.
static HANDOFF: Mutex<CriticalSectionRawMutex, RefCell<Option<Loop>>> =
    Mutex::new(RefCell::new(None));

/// The control loop and everything it owns.
pub struct Loop {
    hw: ControlHw,
    ctrl: Ctrl,
    limits: Limits,
    psc: u32,
    arr: u32,
    ratio: u32,
    phase: u32,
    enc: CountExtender,
    last_pos: i64,
    sense: CurrentSense,
    faults: Faults,
    enabled: bool,
    motion: Motion,
    r: RefSample,
    out: PositionOutput,
    current: f32,
    duty: f32,
    stats: StepStats,
    last_cycles: u32,
    steps: u64,
    stream_every: u32,
    stream_count: u32,
}

impl Loop {
    /// A loop at rest (bridge off) with the parameter set `a`.
    pub fn new(mut hw: ControlHw, a: Applied, sense: CurrentSense, faults: Faults) -> Loop {
        let enc = CountExtender::new(board::ENCODER_BITS, hw.encoder_raw());
        hw.set_pwm_timing(a.psc, a.arr);
        hw.set_bridge(0, 0);
        let ratio = a.ctrl.params().ratio().max(1);
        Loop {
            hw,
            ratio,
            ctrl: a.ctrl,
            limits: a.limits,
            psc: a.psc,
            arr: a.arr,
            phase: 0,
            enc,
            last_pos: 0,
            sense,
            faults,
            enabled: false,
            motion: Motion::holding(0),
            r: RefSample::default(),
            out: PositionOutput::default(),
            current: 0.0,
            duty: 0.0,
            stats: StepStats::new(),
            last_cycles: 0,
            steps: 0,
            stream_every: 0,
            stream_count: 0,
        }
    }

    /// Hands the loop to the interrupt (call before [`board::start_control`]).
    pub fn hand_over(self) {
        HANDOFF.lock(|h| *h.borrow_mut() = Some(self));
    }

    fn switch_off(&mut self) {
        self.enabled = false;
        self.motion.stop();
        self.duty = 0.0;
        self.hw.set_bridge(0, 0);
    }

    /// Takes the comms side's requests and publishes the status (one critical section).
    fn exchange(&mut self) {
        let status = Status {
            steps: self.steps,
            pos_rate_hz: self.ctrl.params().pos_rate_hz,
            pos: self.enc.count(),
            reference: self.r.pos,
            error: self.out.error,
            ff: self.out.ff_friction,
            current: self.current,
            duty: self.duty,
            faults: self.faults,
            enabled: self.enabled,
            moving: self.motion.is_moving(),
            stats: self.stats,
            sense_offset: self.sense.offset,
            adapt_scale: self.ctrl.adaptive_scale(),
        };
        let req = SHARED.lock(|s| {
            let mut s = s.borrow_mut();
            s.status = status;
            if s.requests.pending() {
                Some(core::mem::take(&mut s.requests))
            } else {
                None
            }
        });
        let Some(req) = req else { return };
        if req.reset_stats {
            self.stats = StepStats::new();
        }
        if let Some(n) = req.stream_every {
            self.stream_every = n;
            self.stream_count = 0;
        }
        if req.clear {
            self.faults = Faults::NONE;
        }
        self.faults.latch(req.latch);
        if let Some(a) = req.apply {
            let ratio = a.ctrl.params().ratio().max(1);
            if (a.psc, a.arr, ratio) != (self.psc, self.arr, self.ratio) {
                // New rates: the bridge goes off for the change.
                self.switch_off();
                self.ratio = ratio;
                self.phase = 0;
                self.psc = a.psc;
                self.arr = a.arr;
                self.hw.set_pwm_timing(a.psc, a.arr);
            }
            // Same rates: the new controller (at rest) takes over at the same reference, as
            // the simulator's device does; gains can be tuned while running.
            // What the adaptation learned is about the axis, not the settings: keep it.
            let scale = self.ctrl.adaptive_scale();
            self.ctrl = a.ctrl;
            self.ctrl.set_adaptive_scale(scale);
            self.limits = a.limits;
        }
        if req.disable {
            self.switch_off();
        }
        if req.enable && self.faults.is_empty() {
            self.ctrl.reset();
            self.motion
                .hold_at(self.enc.count().saturating_mul(SUB_PER_COUNT as i64));
            self.last_pos = self.enc.count();
            self.enabled = true;
        }
        if let Some(m) = req.motion
            && self.enabled
        {
            self.motion.start(m);
        }
    }

    /// The reference for this position step.
    fn reference(&mut self) -> RefSample {
        let dt = self.ctrl.dt_pos();
        self.motion.next(dt)
    }

    /// One PWM period.
    fn step(&mut self) {
        let t0 = cortex_m::peripheral::DWT::cycle_count();
        self.hw.ack_update();
        self.enc.update(self.hw.encoder_raw());
        let codes = self.hw.current_codes();
        self.current = self.sense.amps_sum(codes, board::SENSE_OVERSAMPLE);

        let mut new_faults = Faults::NONE;
        if self.phase == 0 {
            self.exchange();
            self.steps = self.steps.wrapping_add(1);
            let pos = self.enc.count();
            let delta = pos.saturating_sub(self.last_pos);
            self.last_pos = pos;
            if self.enabled {
                self.r = self.reference();
                self.out = self.ctrl.position_step(pos, &self.r);
            } else {
                self.r = RefSample {
                    pos: pos.saturating_mul(SUB_PER_COUNT as i64),
                    vel: 0.0,
                    acc: 0.0,
                };
                self.out = PositionOutput::default();
            }
            let m = Measured {
                current: self.current,
                error: self.out.error,
                delta,
                pos,
                cycles: self.last_cycles,
            };
            new_faults = drive::check(&m, &self.limits, self.enabled);
            self.telemetry(pos);
        } else if self.enabled && drive::over_current(self.current, self.limits.i_trip) {
            // Over-current is checked at every current step.
            new_faults = Faults::OVER_CURRENT;
        }
        self.phase += 1;
        if self.phase >= self.ratio {
            self.phase = 0;
        }
        if !new_faults.is_empty() {
            self.faults.latch(new_faults);
        }
        if self.enabled && !self.faults.is_empty() {
            self.switch_off();
        }
        if self.enabled {
            self.duty = self.ctrl.current_step(self.current).duty;
            let (a, b) = bridge_compare(self.duty, self.arr, true);
            self.hw.set_bridge(a, b);
        }
        let cycles = cortex_m::peripheral::DWT::cycle_count().wrapping_sub(t0);
        self.stats.record(cycles);
        self.last_cycles = cycles;
        if self.enabled && drive::overrun(cycles, self.limits.budget_cycles) {
            self.faults.latch(Faults::OVERRUN);
            self.switch_off();
        }
    }

    fn telemetry(&mut self, pos: i64) {
        if self.stream_every == 0 {
            return;
        }
        self.stream_count += 1;
        if self.stream_count < self.stream_every {
            return;
        }
        self.stream_count = 0;
        let p = self.ctrl.params();
        let sample = Sample {
            steps: self.steps,
            pos,
            reference: self.r.pos,
            error: self.out.error,
            ff: self.out.ff_friction,
            current: self.current,
            friction: p.motor.k_m * self.current - p.motor.inertia * self.r.acc,
        };
        // A full queue drops the sample: the loop never waits for the comms side.
        let _ = TELEMETRY.try_send(sample);
    }
}

/// Called by the PWM timer's update interrupt with the interrupt's own slot for the loop
/// (a `static mut` of the handler, reached from nowhere else): the loop is taken from the
/// hand-off on the first call, then owned there.
#[inline(always)]
pub fn on_pwm_update(slot: &mut Option<Loop>) {
    if slot.is_none() {
        *slot = HANDOFF.lock(|h| h.borrow_mut().take());
    }
    match slot {
        Some(l) => l.step(),
        // Not handed over yet: keep the bridge off and the flag clear.
        None => crate::board::idle_update(),
    }
}
