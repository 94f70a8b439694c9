//! The loop half of the device core: one call per PWM period.

use crate::control::reference::{Motion, RefSample, SUB_PER_COUNT, sub_counts};
use crate::drive::{self, CountExtender, CurrentSense, Faults, Limits, Measured, StepStats};

use crate::control::frf::{CHANNELS, Frf, FrfReport, Injection};
use crate::control::posmap::MapCursor;
use crate::control::table::{Player, Recorded, TableReport};

use super::{
    Applied, Board, Capture, CaptureRequest, Chunk, Ctrl, CtrlBuf, Drive, FrfRequest, Handover,
    MapRequest, Requests, RequestsBuf, Sample, Status, StepValues,
};

/// Readings of the current-sense zero taken at start-up, bridge off (each a sum of
/// [`Board::sense_oversample`] conversions).
pub const ZERO_SAMPLES: u32 = 256;

/// Why the start-up calibration could not use the current sense.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SenseTrouble {
    /// None: the zero was measured and lies in the board's window.
    None,
    /// A reading did not come within the shell's bound (the ADC is not triggered, its DMA
    /// does not run): `taken` readings had come before it. The calibration stops at the
    /// first missing reading, so a dead chain costs one bound, not [`ZERO_SAMPLES`] of them.
    NoSamples {
        /// Readings that came before the missing one.
        taken: u32,
    },
    /// The mean lies outside the board's window (amplifier missing or unpowered, wrong
    /// reference): the mean \[code per conversion\].
    OutOfWindow {
        /// The measured mean \[code per conversion\].
        mean_code: f32,
    },
}

/// What the start-up calibration found about the current sense.
#[derive(Debug, Clone, Copy)]
pub struct SenseStart {
    /// The sense to run with: the measured zero, or the board's nominal one if that was out of
    /// its window.
    pub sense: CurrentSense,
    /// `current_sense` when the measured zero was out of the board's window or no reading
    /// came.
    pub faults: Faults,
    /// What was wrong, for the start-up's log line.
    pub trouble: SenseTrouble,
}

/// The current-sense zero at start-up: the mean of [`ZERO_SAMPLES`] readings taken by `read`
/// (a sum of [`Board::sense_oversample`] codes, bridge off; `None` when the shell's bounded
/// wait for one ran out). A missing reading ends the calibration at once; a zero outside the
/// board's window (amplifier missing, wrong reference) or no reading latches `current_sense`
/// and runs on the nominal zero. The scale is the amplifier's `v_per_a` \[V/A\] (the
/// settings' `sense.v_per_a`).
pub fn calibrate_sense(
    board: &Board,
    v_per_a: f32,
    mut read: impl FnMut() -> Option<u32>,
) -> SenseStart {
    let n = board.sense_oversample.max(1) as f32;
    let chain = board.sense;
    let amps_per_code = chain.amps_per_code(v_per_a);
    let nominal = SenseStart {
        sense: CurrentSense {
            amps_per_code,
            offset: chain.zero_code,
        },
        faults: Faults::CURRENT_SENSE,
        trouble: SenseTrouble::None,
    };
    let mut cal = drive::OffsetCalibration::default();
    for _ in 0..ZERO_SAMPLES {
        match read() {
            Some(codes) => cal.push(codes),
            None => {
                return SenseStart {
                    trouble: SenseTrouble::NoSamples {
                        taken: cal.samples(),
                    },
                    ..nominal
                };
            }
        }
    }
    match cal.finish(chain.zero_code * n, chain.zero_tolerance * n) {
        Some(sum) => SenseStart {
            sense: CurrentSense {
                amps_per_code,
                offset: sum / n,
            },
            faults: Faults::NONE,
            trouble: SenseTrouble::None,
        },
        None => SenseStart {
            trouble: SenseTrouble::OutOfWindow {
                mean_code: cal.mean().unwrap_or(0.0) / n,
            },
            ..nominal
        },
    }
}

/// The measured supply's filter time constant \[s\] ([`crate::device::Front::supervise`],
/// a reading each time it runs: at each request and the shell's periodic tick): a divider
/// code's noise (13 mV a code at 1:16) averaged, a sag under load followed within a second.
pub const SUPPLY_TAU_S: f32 = 0.2;

/// How often a shell calls [`crate::device::Front::supervise`] \[ms\] (besides each request
/// that may drive), with or without a host: a quarter of [`SUPPLY_TAU_S`].
pub const SUPERVISE_MS: u64 = 50;

/// What the hardware measured at the start of a PWM period.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Inputs {
    /// The encoder counter's raw value \[counts\] (wrapping, [`Board::encoder_bits`] wide).
    pub encoder: u32,
    /// The sum of [`Board::sense_oversample`] current-sense ADC codes \[code\].
    pub current_codes: u32,
    /// Time since the previous call started [cycles of the board's step clock,
    /// `BoardLimits::clock_hz`]; 0 when not measured. A call more than 1.5 PWM periods after
    /// the last one missed a period: counted, and an `overrun` while the bridge drives.
    pub since_last: u32,
}

/// What the shell writes to the hardware after a PWM period.
#[derive(Debug, Clone, Copy, Default)]
pub struct Outputs {
    /// Bridge on: drive `compare`; off: both bridge inputs low.
    pub enabled: bool,
    /// Duty [-1, 1] (0 while off), for a simulated bridge.
    pub duty: f32,
    /// Compare values of the two bridge inputs ((0, 0) while off), see
    /// [`drive::bridge_compare`].
    pub compare: (u32, u32),
    /// New PWM timer setting (prescaler, period) to write, after a change of loop rates.
    pub timing: Option<(u32, u32)>,
    /// A telemetry sample, when one is due.
    pub sample: Option<Sample>,
}

/// The buffer a control loop records its captures into (the shell's: a static on the board).
pub type CaptureBuf = &'static mut [f32];

/// What the loop keeps of the position step's output for its status, telemetry, table and
/// frequency response.
#[derive(Debug, Clone, Copy)]
struct Out {
    /// Position error [rad].
    error: f32,
    /// The friction feedforward [N·m].
    ff_friction: f32,
}

impl Out {
    const ZERO: Out = Out {
        error: 0.0,
        ff_friction: 0.0,
    };
}

/// The device's control loop and everything it owns.
#[derive(Debug)]
pub struct ControlLoop {
    board: Board,
    /// The running controller, in its storage (swapped, not copied, for a new parameter
    /// set).
    ctrl: CtrlBuf,
    limits: Limits,
    psc: u32,
    arr: u32,
    ratio: u32,
    phase: u32,
    enc: CountExtender,
    /// The encoder counter's last raw reading, before the direction is applied.
    last_raw: u32,
    last_pos: i64,
    /// PWM periods missed since the last position step (the loop stood still).
    missed_since_pos: u32,
    /// The current \[A\], the bridge voltage \[V\] and the current's sign \[-\] summed over
    /// the PWM periods since the last position step, and their number (the capture's means
    /// count every period).
    period_sum: (f32, f32, f32, u32),
    sense: CurrentSense,
    faults: Faults,
    enabled: bool,
    motion: Motion,
    r: RefSample,
    out: Out,
    current: f32,
    duty: f32,
    stats: StepStats,
    last_cycles: u32,
    steps: u64,
    stream_every: u32,
    stream_count: u32,
    /// PWM periods left of the bridge's wake-up after `enable` (brake, no control).
    wake_left: u32,
    /// Current mode: the current held \[A\] (position loop off).
    current_mode: Option<f32>,
    /// The step at which a timed current ends (0 A from then on).
    current_until: Option<u64>,
    capture: Capture<CaptureBuf>,
    /// The frequency-response measurement (the last one, running or not).
    frf: Option<Frf>,
    /// Its report for the protocol side, handed over at the next exchange.
    frf_report: Option<FrfReport>,
    /// The position map's table (offset and scale interleaved), if the shell gave one.
    map_table: Option<MapTable>,
    /// Where the reference is in the map, while the map acts.
    map_cursor: Option<MapCursor>,
    /// The table motion's buffer ([`crate::control::table::TABLE_VALUES`] values), if the shell gave
    /// one.
    table_buf: Option<TableBuf>,
    /// The table motion's player.
    table: Player,
    /// Its report for the protocol side, written in place ([`Player::report_into`])…
    table_report: TableReport,
    /// … and handed over at the next exchange when set.
    table_reported: bool,
    /// The table's correction in the last step \[N·m\] (0 when none plays).
    table_corr: f32,
    /// A chunk or a report waits for the next exchange (one test a step when none does).
    fresh: bool,
    /// Requests acted on, given back at the next exchange.
    done: Option<RequestsBuf>,
    /// The next position step's reference side, worked out in the current step before it
    /// (when the current loop runs faster than the position loop).
    ahead: Option<Ahead>,
}

/// A frequency response's sample in a position step: its injected value, its phase (sine,
/// cosine) and where it goes.
type FrfIn = (f32, (f32, f32), Injection);

/// The reference side of a position step: what depends on the reference alone (the motion or
/// the table, the frequency response's sine, the position map's sample, the friction model
/// advanced), worked out before the measurement side ([`ControlLoop::reference_side`]).
#[derive(Debug, Clone, Copy)]
struct Ahead {
    /// The step's reference (the motion's or the table's), [`ControlLoop::r`] from the step on
    /// (what the status, the telemetry and a capture show).
    base: RefSample,
    /// The reference the position step runs on (a sine at the reference in it).
    r: RefSample,
    /// The frequency response's sample in that step.
    frf: Option<FrfIn>,
}

/// The buffer of the table motion ([`crate::control::table::TABLE_VALUES`] values; the shell's: a
/// static on the board).
pub type TableBuf = &'static mut [f32];

/// The buffer of a position map's table ([`crate::control::posmap::MAP_VALUES`] values; the shell's: a
/// static on the board).
pub type MapTable = &'static mut [f32];

impl ControlLoop {
    /// A loop at rest (bridge off) running the parameter set `a` on `board`, with the current
    /// sense `sense`, the faults found at start-up, the encoder counter's value now, the
    /// buffer for captures (`Board::capture_values` long) and the storage of its running
    /// controller (`ctrl`: `a`'s is put there).
    pub fn new(
        board: Board,
        a: Applied,
        sense: CurrentSense,
        faults: Faults,
        encoder: u32,
        capture: CaptureBuf,
        ctrl: CtrlBuf,
    ) -> Self {
        let ratio = a.ctrl.params().ratio().max(1);
        let enc_dir = a.ctrl.params().enc_dir;
        *ctrl = a.ctrl;
        let mut lp = ControlLoop {
            board,
            ratio,
            ctrl,
            limits: a.limits,
            psc: a.psc,
            arr: a.arr,
            phase: 0,
            enc: CountExtender::new(board.encoder_bits, directed(encoder, enc_dir)),
            last_raw: encoder,
            last_pos: 0,
            missed_since_pos: 0,
            period_sum: (0.0, 0.0, 0.0, 0),
            sense,
            faults,
            enabled: false,
            motion: Motion::holding(0),
            r: RefSample::default(),
            out: Out::ZERO,
            current: 0.0,
            duty: 0.0,
            stats: StepStats::new(),
            last_cycles: 0,
            steps: 0,
            stream_every: 0,
            stream_count: 0,
            wake_left: 0,
            current_mode: None,
            current_until: None,
            capture: Capture::new(capture),
            frf: None,
            frf_report: None,
            map_table: None,
            map_cursor: None,
            table_buf: None,
            table: Player::default(),
            table_report: TableReport::default(),
            table_reported: false,
            table_corr: 0.0,
            fresh: false,
            done: None,
            ahead: None,
        };
        lp.limits = lp.reachable(lp.limits);
        lp
    }

    /// The loop with a table motion's buffer (`buf`: [`crate::control::table::TABLE_VALUES`] values).
    /// Without one the table's requests are refused by the protocol side and do nothing here.
    pub fn with_table(mut self, buf: TableBuf) -> Self {
        self.attach_table(buf);
        self
    }

    /// Gives the loop its table-motion buffer in place (as [`ControlLoop::with_table`], for a
    /// loop already in its static: no copy of the loop through the stack).
    pub fn attach_table(&mut self, buf: TableBuf) {
        self.table_buf = Some(buf);
    }

    /// Ends a table run now (another motion takes over, the bridge goes off); its report goes
    /// over at the next exchange.
    fn stop_table(&mut self) {
        if self.table.playing() {
            self.table.abort();
            self.table_ended();
        }
    }

    /// The table's report written for the next exchange.
    fn report_table(&mut self) {
        self.table.report_into(&mut self.table_report);
        self.table_reported = true;
        self.fresh = true;
    }

    /// A table run ended: its correction leaves the feedforward (the map's sample alone from
    /// the next step; none without a map), its report goes over at the next exchange.
    fn table_ended(&mut self) {
        self.table_corr = 0.0;
        if self.map_cursor.is_none() {
            self.ctrl.set_map_sample(0.0, 1.0);
        }
        self.report_table();
    }

    /// The loop with a position map's table (`table`: [`crate::control::posmap::MAP_VALUES`] values,
    /// as the start-up left it: [`crate::device::restore_map`], or [`crate::control::posmap::clear`]ed).
    /// Without one the map settings have no effect and the map's requests read and write
    /// nothing.
    pub fn with_map(mut self, table: MapTable) -> Self {
        self.attach_map(table);
        self
    }

    /// Gives the loop its position map's table in place (as [`ControlLoop::with_map`], for a
    /// loop already in its static).
    pub fn attach_map(&mut self, table: MapTable) {
        self.map_table = Some(table);
        self.map_cursor = self.map_cursor_for(self.ctrl);
    }

    /// The map's cursor for the controller `c`'s settings (its geometry worked out when `c` was
    /// built) at the reference now (none while the map is off or there is no table).
    fn map_cursor_for(&self, c: &Ctrl) -> Option<MapCursor> {
        (c.params().map.enable != 0.0 && self.map_table.is_some())
            .then(|| MapCursor::at(c.map_geometry(), self.r.pos))
    }

    /// The PWM timer setting (prescaler, period) of the running set.
    pub fn timing(&self) -> (u32, u32) {
        (self.psc, self.arr)
    }

    /// The controller.
    pub fn controller(&self) -> &Ctrl {
        self.ctrl
    }

    /// Current-loop steps per position step.
    pub fn ratio(&self) -> u32 {
        self.ratio
    }

    /// True while the bridge drives.
    pub fn enabled(&self) -> bool {
        self.enabled
    }

    /// The latched faults.
    pub fn faults(&self) -> Faults {
        self.faults
    }

    /// Latches `faults` found outside the step (the board's deadman) and switches the bridge
    /// off; the status says so from the next position step.
    pub fn halt(&mut self, faults: Faults) {
        self.faults.latch(faults);
        self.switch_off();
    }

    /// Ends a running frequency-response measurement (what was summed stands) and hands its
    /// report over at the next exchange.
    fn stop_frf(&mut self) {
        let rate = self.ctrl.params().pos_rate_hz;
        if let Some(f) = &mut self.frf
            && f.stop()
        {
            self.frf_report = Some(f.report(rate));
            self.fresh = true;
        }
    }

    fn switch_off(&mut self) {
        self.stop_table();
        self.enabled = false;
        self.motion.stop();
        self.current_mode = None;
        self.duty = 0.0;
    }

    /// Position control holding where the axis is, from rest (entering or leaving current
    /// mode, `enable`).
    fn hold_here(&mut self) {
        self.stop_table();
        self.ctrl.reset();
        self.current_mode = None;
        let here = sub_counts(self.enc.count());
        self.motion.hold_at(here);
        self.r = RefSample {
            pos: here,
            vel: 0.0,
            acc: 0.0,
        };
        self.last_pos = self.enc.count();
    }

    /// The status as of the last position step.
    pub fn status(&self) -> Status {
        Status {
            steps: self.steps,
            pos_rate_hz: self.ctrl.params().pos_rate_hz,
            pos: self.enc.count(),
            reference: self.r,
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
            drive: match self.current_mode {
                Some(a) => Drive::Current(a),
                None if self.motion.is_velocity() => Drive::Velocity,
                None => Drive::Position,
            },
            capture: self.capture.state().0,
            captured: self.capture.state().1,
            capture_origin: self.capture.origin(),
        }
    }

    /// Acts on the protocol side's requests (between two position steps). Returns a new PWM
    /// timer setting when the loop rates changed.
    /// (By reference: the requests, 2 KB with a parameter set, are not copied again into the
    /// control interrupt's frame.)
    fn take(&mut self, req: &mut Requests) -> Option<(u32, u32)> {
        let mut timing = None;
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
        if let Some(a) = req.apply.as_mut().filter(|a| !a.taken) {
            let ratio = a.ctrl.params().ratio().max(1);
            let rates = self.ctrl.rates_differ(a.ctrl.params())
                || (a.psc, a.arr, ratio) != (self.psc, self.arr, self.ratio);
            // Same rates: the running state is handed over (bumpless); new rates: the new
            // controller starts at rest, keeping what the adaptation learned about the axis.
            // The new controller is the protocol side's storage, worked on in place.
            let next: &mut Ctrl = &mut *a.ctrl;
            // The new map's cursor, and its sample at the reference set before the hand-over,
            // so that switching the map on or off (or another table geometry) is bumpless.
            let mut cursor = self.map_cursor_for(next);
            // A table's correction playing stays in the sample (bumpless too).
            if let (Some(c), Some(t)) = (&mut cursor, self.map_table.as_deref()) {
                let (o, s) = c.sample(self.r.pos, t);
                next.set_map_sample(o + self.table_corr, s);
            } else if self.table.playing() {
                next.set_map_sample(self.table_corr, 1.0);
            }
            next.take_state_from(self.ctrl);
            let (old, new) = (self.ctrl.params(), next.params());
            // A direction or a scale changed: the loop's feedback changes sign or size.
            let dirs = old.enc_dir != new.enc_dir
                || old.sense_dir != new.sense_dir
                || old.counts_per_rev != new.counts_per_rev
                || old.sense_v_per_a != new.sense_v_per_a;
            let amps_per_code = self.board.sense.amps_per_code(new.sense_v_per_a);
            let new_enc_dir = new.enc_dir;
            if dirs {
                // The bridge goes off, and the count goes on from where it is, counting the
                // new way (the same count is the same place: a new resolution reads it in
                // other radians from the power-up position on).
                self.switch_off();
                self.enc.rebase(directed(self.last_raw, new_enc_dir));
                self.sense.amps_per_code = amps_per_code;
            }
            if dirs || rates {
                // A table's counts, steps and speeds were checked for the old encoder and
                // rates: it is forgotten (the next run needs a new `table set`).
                self.table = Player::default();
                self.report_table();
            }
            if rates {
                // The bridge goes off for the change.
                self.switch_off();
                self.ratio = ratio;
                self.phase = 0;
                self.psc = a.psc;
                self.arr = a.arr;
                timing = Some((a.psc, a.arr));
            }
            // The running controller swapped for the new one by reference (no copy in the
            // control interrupt); the old one goes back to the protocol side in its place.
            core::mem::swap(&mut self.ctrl, &mut a.ctrl);
            a.taken = true;
            self.limits = self.reachable(a.limits);
            self.map_cursor = cursor;
        }
        match req.map {
            Some(MapRequest::Write { start, n, values }) => {
                if let Some(t) = self.map_table.as_deref_mut() {
                    let from = 2 * start as usize;
                    let len = 2 * (n as usize).min(super::MAP_WRITE_BINS);
                    if let Some(dst) = t.get_mut(from..) {
                        for (d, v) in dst.iter_mut().zip(values.iter().take(len)) {
                            *d = *v;
                        }
                    }
                }
            }
            Some(MapRequest::Read { start, max }) => {
                // Into the requests' own storage (it goes back to the protocol side).
                let c = &mut req.chunk;
                c.restart(start, 2);
                if let Some(t) = self.map_table.as_deref() {
                    let n = (max as usize)
                        .min(super::CHUNK_VALUES / 2)
                        .min((t.len() / 2).saturating_sub(start as usize));
                    let from = 2 * start as usize;
                    if let Some(src) = t.get(from..) {
                        for (d, v) in c.values.iter_mut().zip(src.iter().take(2 * n)) {
                            *d = *v;
                        }
                        c.samples = n as u32;
                    }
                }
            }
            Some(MapRequest::Clear) => {
                if let Some(t) = self.map_table.as_deref_mut() {
                    crate::control::posmap::clear(t);
                }
            }
            None => {}
        }
        // By reference: a write's values are not copied into the frame.
        if let Some(t) = req.table.as_ref() {
            self.take_table(t, &mut req.chunk);
        }
        if req.disable {
            self.switch_off();
        }
        if let Some(v) = req.supply_v {
            self.ctrl.set_measured_supply(Some(v));
        }
        if req.enable && self.faults.is_empty() && !self.enabled {
            self.hold_here();
            self.enabled = true;
            let wake = self.board.bridge_wake_s * self.ctrl.params().cur_rate_hz;
            // Float to int casts saturate (NaN gives 0).
            self.wake_left = (wake + 0.999) as u32;
        }
        match req.capture {
            Some(CaptureRequest::Arm(spec)) => self.capture.arm(spec),
            Some(CaptureRequest::Off) => self.capture.off(),
            Some(CaptureRequest::Read { start, max }) => {
                self.capture.read_into(start, max, &mut req.chunk);
            }
            None => {}
        }
        let frf_start = matches!(req.frf, Some(FrfRequest::Start(_)));
        let experiment = req.hold_here
            || req.current.is_some()
            || req.motion.is_some()
            || req.velocity.is_some()
            || (frf_start && self.enabled && req.current.is_none() && self.current_mode.is_none());
        if experiment && self.enabled {
            self.capture.experiment_started();
        }
        if req.hold_here && self.enabled {
            self.hold_here();
        }
        if let Some(amps) = req.current
            && self.enabled
        {
            self.stop_table();
            self.motion.stop();
            self.current_mode = Some(amps);
            // The pulse counts from the step that takes it.
            self.current_until = req
                .current_steps
                .map(|n| self.steps.saturating_add(1).saturating_add(n as u64));
        }
        if let Some(m) = req.motion
            && self.enabled
        {
            if self.current_mode.is_some() {
                // The plan starts at the axis's position (the reference in current mode).
                self.hold_here();
            }
            self.stop_table();
            let mut plan = m.plan;
            // The plan starts at the reference of step `from_step`; this step is `steps + 1`.
            let behind = self.steps.saturating_add(1).saturating_sub(m.from_step);
            plan.skip(behind as f32 * self.ctrl.dt_pos());
            self.motion.start(plan);
        }
        match req.frf {
            Some(FrfRequest::Start(spec)) => {
                self.stop_frf();
                // Only with the position loop running (not in current mode, not off); the
                // report says `running` from the next exchange.
                if self.enabled && self.current_mode.is_none() {
                    let mut f = Frf::start(spec);
                    self.frf_report = Some(f.report(self.ctrl.params().pos_rate_hz));
                    self.fresh = true;
                    self.frf = Some(f);
                }
            }
            Some(FrfRequest::Stop) => self.stop_frf(),
            None => {}
        }
        if let Some(v) = &req.velocity
            && self.enabled
        {
            if self.current_mode.is_some() {
                self.hold_here();
            }
            self.stop_table();
            // Catch up with the steps since `from_step` (in place: the profile is copied
            // once): to step `steps`, since `VelocityProfile::next` advances before it returns
            // (a move's plan is sampled, then advanced) and the reference side after this take
            // calls it for the next step. (It caught up to `steps + 1`, as a move does: a speed
            // asked for while one ran jumped by a position step's travel, 13 counts at
            // 1 rad/s: `gms-core/tests/device.rs`.)
            let behind = self.steps.saturating_sub(v.from_step);
            let dt = self.ctrl.dt_pos();
            self.motion.start_velocity(&v.profile);
            if let Some(p) = self.motion.velocity_mut() {
                for _ in 0..behind.min(1000) {
                    p.next(dt);
                }
            }
        }
        timing
    }

    /// One PWM period: `inp` as measured now, `exchange` the shell's access to the mailbox
    /// (called once per position period, in its last current step, with what builds the
    /// status; returns the pending
    /// requests, and publishes the status only when there are none: see
    /// [`Mailbox::exchange`](super::Mailbox)).
    ///
    pub fn step(
        &mut self,
        inp: Inputs,
        exchange: impl FnOnce(&dyn Fn() -> Status, Handover<'_>) -> Option<RequestsBuf>,
    ) -> Outputs {
        self.last_raw = inp.encoder;
        self.enc
            .update(directed(inp.encoder, self.ctrl.params().enc_dir));
        self.current = self.ctrl.params().sense_dir
            * self
                .sense
                .amps_sum(inp.current_codes, self.board.sense_oversample.max(1));
        let mut new_faults = Faults::NONE;
        let missed = drive::missed_periods(inp.since_last, self.limits.period_cycles);
        if missed > 0 {
            self.missed_since_pos = self.missed_since_pos.saturating_add(missed);
            if self.enabled {
                self.stats.record_missed(missed);
                new_faults.latch(Faults::OVERRUN);
            }
        }
        let mut timing = None;
        let mut sample = None;
        // A parameter set handed over in this step (then the next position step works out its
        // reference side itself: the hand-over and the reference side together would be the
        // longest step). Other requests leave this step room for it (a velocity's start: 2,897
        // cycles in the position step that worked it all out, with the code in SRAM; 2,604 in
        // this one).
        let mut handed_over = false;
        // This period's current and the voltage it was driven with (the duty as the timer's
        // counts apply it: the bridge drives whole counts), for the capture's means.
        let volts = if self.enabled {
            drive::applied_duty(self.duty, self.arr) * self.ctrl.supply()
        } else {
            0.0
        };
        // Summed only for a capture armed or recording (the sums count their periods, so a
        // capture armed within a position period averages those after it): a step without
        // one pays a test, not the sums (18 cycles at rest on the F405 with the sign's).
        if self.capture.active() {
            // The sign by its bit (no branch): +1 at +0 A.
            let sign = 1.0f32.copysign(self.current);
            self.period_sum = (
                self.period_sum.0 + self.current,
                self.period_sum.1 + volts,
                self.period_sum.2 + sign,
                self.period_sum.3.saturating_add(1),
            );
        }
        // Requests are taken in the last current step of a position period: with the current
        // loop faster than the position loop, that step has no position step of its own, and a
        // parameter set's hand-over (the costliest request) does not add to one (at 40 kHz the
        // two together would overrun the 25 µs period); with both loops at one rate, it is every
        // step. What a request sets acts from the next position step on either way.
        if self.phase + 1 >= self.ratio {
            // Handed over by reference and then dropped: a chunk or a report is not copied
            // in a step that has none.
            let returned = self.done.take();
            let h = if self.fresh {
                Handover {
                    steps: self.steps,
                    frf: self.frf_report.as_ref(),
                    table: self.table_reported.then_some(&self.table_report),
                    returned,
                }
            } else {
                Handover {
                    steps: self.steps,
                    returned,
                    ..Handover::default()
                }
            };
            // The status built only if published: not in a step that takes requests.
            let req = exchange(&|| self.status(), h);
            if req.is_none() && self.fresh {
                self.frf_report = None;
                self.table_reported = false;
                self.fresh = false;
            }
            if let Some(req) = req {
                // Acted on in place, outside the shell's critical section; given back at the
                // next exchange.
                handed_over = req.apply.as_ref().is_some_and(|a| !a.taken);
                timing = self.take(req);
                self.done = Some(req);
            }
        }
        if self.phase == 0 {
            self.steps = self.steps.wrapping_add(1);
            let pos = self.enc.count();
            let delta = pos.saturating_sub(self.last_pos);
            self.last_pos = pos;
            if self.current_until.is_some_and(|end| self.steps >= end) {
                // A timed current is over: 0 A, still in current mode.
                self.current_mode = self.current_mode.map(|_| 0.0);
                self.current_until = None;
            }
            if !(self.enabled && self.wake_left == 0 && self.current_mode.is_none())
                && self.ahead.take().is_some()
            {
                // Worked out for a position step that does not run (the bridge went off).
                self.ctrl.forget_ahead();
            }
            if let (true, Some(amps)) = (self.enabled, self.current_mode) {
                // Current mode: the reference follows the axis, no position control.
                self.r = RefSample {
                    pos: sub_counts(pos),
                    vel: 0.0,
                    acc: 0.0,
                };
                self.out = Out::ZERO;
                if self.wake_left == 0 {
                    self.ctrl.hold_current(amps);
                }
            } else if self.enabled && self.wake_left == 0 {
                // The reference side as the step before worked it out, or now (both loops at
                // one rate, or the first position step after a start).
                let a = match self.ahead.take() {
                    Some(a) => a,
                    None => self.reference_side(),
                };
                self.r = a.base;
                // The two figures the loop reports, not the whole output (a 40-byte copy
                // through memmove, ~60 instructions on the M4F).
                let o = self.ctrl.position_step(pos, &a.r);
                self.out = Out {
                    error: o.error,
                    ff_friction: o.ff_friction,
                };
                if let Some(f) = a.frf {
                    self.frf_output(f);
                }
                if self.table.playing() {
                    self.table_record();
                }
            } else if self.enabled {
                // The bridge wakes: hold the reference where the axis is, no control yet.
                self.out = Out::ZERO;
            } else {
                self.r = RefSample {
                    pos: sub_counts(pos),
                    vel: 0.0,
                    acc: 0.0,
                };
                self.out = Out::ZERO;
            }
            if !(self.enabled && self.current_mode.is_none()) {
                // No position loop: no frequency response.
                self.stop_frf();
            }
            // The position periods the increment took: one, plus the PWM periods missed since
            // the last position step in whole position periods (rounded up).
            let periods = if self.missed_since_pos == 0 {
                1
            } else {
                1 + self.missed_since_pos.div_ceil(self.ratio.max(1))
            };
            self.missed_since_pos = 0;
            let m = Measured {
                current: self.current,
                error: self.out.error,
                delta,
                periods,
                pos,
                cycles: self.last_cycles,
            };
            new_faults.latch(drive::check(&m, &self.limits, self.enabled));
            sample = self.telemetry(pos);
            let p = self.ctrl.params();
            // The step's values only for a capture armed or recording (not built in every
            // step for nothing).
            // The sums go to the capture as they are: it divides once a sample, and a step
            // without one divides nothing.
            let (current_period, volts_period, sign_period, periods) = self.period_sum;
            self.period_sum = (0.0, 0.0, 0.0, 0);
            if self.capture.active() {
                self.capture.step(&StepValues {
                    steps: self.steps,
                    dt: self.ctrl.dt_pos(),
                    pos,
                    reference: self.r.pos,
                    rad_per_count: self.ctrl.rad_per_count(),
                    error: self.out.error,
                    ff: self.out.ff_friction,
                    current: self.current,
                    friction: p.motor.k_m * self.current - p.motor.inertia * self.r.acc,
                    volts,
                    current_period,
                    volts_period,
                    sign_period,
                    periods,
                });
            }
        } else if self.enabled && drive::over_current(self.current, self.limits.i_trip) {
            // Over-current is checked at every current step.
            new_faults.latch(Faults::OVER_CURRENT);
        }
        self.phase += 1;
        if self.phase >= self.ratio {
            self.phase = 0;
        }
        self.faults.latch(new_faults);
        if self.enabled && !self.faults.is_empty() {
            self.switch_off();
        }
        if self.enabled && self.wake_left > 0 {
            // Duty 0 while enabled is both inputs high: brake, which wakes the driver.
            self.wake_left -= 1;
            self.duty = 0.0;
        } else if self.enabled {
            let out = self.ctrl.current_step(self.current);
            self.duty = out.duty;
            if out.limited {
                self.stats.record_limited();
            }
        }
        // The next step is a position step's and runs one: its reference side now, in this step
        // that has none, so that the two share the work (with the current loop at twice the
        // position loop's rate, the position step alone was 3,150 cycles of the 4,200 at 40 kHz
        // on the M4F, the other 1,000), unless this step handed a parameter set over. Of the friction
        // feedforward only the actuator's model is advanced here, the guideway's in the position
        // step (this step then ran about 2,860 cycles in the M4's costs, the position step 1,680;
        // now about 2,170 and 2,450: docs/rehost.md).
        if self.ratio > 1
            && !handed_over
            && self.phase == 0
            && self.enabled
            && self.wake_left == 0
            && self.current_mode.is_none()
        {
            self.ahead = Some(self.reference_side());
        }
        Outputs {
            enabled: self.enabled,
            duty: if self.enabled { self.duty } else { 0.0 },
            compare: drive::bridge_compare(self.duty, self.arr, self.enabled),
            timing,
            sample,
        }
    }

    /// `l` with its over-current trip within what the current sense measures from the zero
    /// start-up calibration found (at most [`TRIP_SHARE_OF_REACH`](crate::drive::TRIP_SHARE_OF_REACH)
    /// of [`SenseChain::reach`](super::SenseChain)
    /// from it, with the running `sense.v_per_a`): the trip is met before the amplifier leaves
    /// its linear range or the ADC clips, wherever within its window the zero came out.
    fn reachable(&self, mut l: Limits) -> Limits {
        let reach = self
            .board
            .sense
            .reach(self.sense.offset, self.ctrl.params().sense_v_per_a);
        l.i_trip = crate::drive::trip_within(l.i_trip, reach);
        l
    }

    /// A current-sense conversion read at an end of the ADC's range (0 or full scale: the
    /// board's analog watchdog, the simulator's ADC): the current is past what the sense
    /// measures, so while driving `over_current` is latched and the bridge switched off (the
    /// step that follows drives nothing). Call before the period's [`ControlLoop::step`].
    pub fn sense_clipped(&mut self) {
        if self.enabled {
            self.faults.latch(Faults::OVER_CURRENT);
            self.switch_off();
        }
    }

    /// The period's current-sense reading was taken from a buffer the next sequence had begun
    /// to overwrite (the step started too late: the board's single DMA buffer): while driving
    /// `overrun` is latched and the bridge switched off, as for a step that wrote its duty
    /// late. Call before the period's [`ControlLoop::step`].
    pub fn sense_stale(&mut self) {
        if self.enabled {
            self.faults.latch(Faults::OVERRUN);
            self.switch_off();
        }
    }

    /// The safety limits the loop checks (its over-current trip within the sense's reach).
    pub fn limits(&self) -> Limits {
        self.limits
    }

    /// Records the duration of the step just run \[cycles\] and whether it wrote the bridge's
    /// compare values after the PWM update they were for (`late`: the timer's counter went
    /// through the bottom during the step, [`drive::past_update`]; a virtual device's steps
    /// are never late). An overrun by length or by deadline latches the fault and switches the
    /// bridge off (a late step is also counted in the status's `late`). Returns true when the
    /// bridge must be switched off now.
    pub fn finish(&mut self, cycles: u32, late: bool) -> bool {
        self.stats.record(cycles);
        self.last_cycles = cycles;
        if self.enabled && late {
            self.stats.record_late();
        }
        if self.enabled && (late || drive::overrun(cycles, self.limits.budget_cycles)) {
            self.faults.latch(Faults::OVERRUN);
            self.switch_off();
            return true;
        }
        false
    }

    /// The table's reference and its correction, while it plays (out of the step's line: the
    /// step without a table pays for one test).
    #[inline(never)]
    fn table_sample(&mut self) -> Option<(RefSample, f32)> {
        if !self.table.playing() {
            return None;
        }
        let t = self.table_buf.as_deref()?;
        let ts = self.table.sample(t);
        self.table_corr = ts.corr;
        Some((ts.r, ts.corr))
    }

    /// After a position step while the table plays: its error recorded, the period's and the
    /// run's ends acted on.
    #[inline(never)]
    fn table_record(&mut self) {
        let Some(t) = self.table_buf.as_deref_mut() else {
            return;
        };
        match self.table.record(t, self.out.error) {
            Recorded::Within => {}
            Recorded::PeriodEnd => {
                self.report_table();
            }
            Recorded::RunEnd(at) => {
                self.motion.hold_at(at);
                self.table_ended();
            }
        }
    }

    /// Acts on a table request: a read into `chunk` (the requests' storage); a run only with
    /// the position loop running and the reference at the table's start (within a count).
    #[inline(never)]
    fn take_table(&mut self, req: &crate::control::table::TableRequest, chunk: &mut Chunk) {
        use crate::control::table::TableRequest;
        let Some(t) = self.table_buf.as_deref_mut() else {
            return;
        };
        if let TableRequest::Run(_) = req {
            let here = self.r.pos;
            let at_start = self
                .table
                .start(t)
                .is_some_and(|s| (s.saturating_sub(here)).unsigned_abs() <= SUB_PER_COUNT as u64);
            if !(self.enabled && self.current_mode.is_none() && at_start) {
                return;
            }
            if self.motion.is_moving() {
                return;
            }
        }
        match req {
            TableRequest::Read { start, .. } => {
                chunk.restart(*start, 1);
                self.table.take(req, t, Some(chunk));
            }
            _ => self.table.take(req, t, None),
        }
        if let TableRequest::Run(_) = req {
            // The run's first step is the one this exchange starts.
            self.table.set_started(
                self.steps.wrapping_add(1),
                self.ctrl.rad_per_count(),
                self.ctrl.params().pos_rate_hz,
            );
        }
        self.report_table();
    }

    /// The reference side of the next position step: the motion (or the table) advanced, the
    /// frequency response's sine, the position map's sample and the actuator's friction model
    /// advanced to the reference (the position step then advances the guideway's and needs the
    /// measurement).
    fn reference_side(&mut self) -> Ahead {
        // The table's correction goes where the map's offset goes (one sample a step for both).
        // `self.r` stays the running step's until the position step (the status is as of it).
        let (base, corr) = match self.table_sample() {
            Some((r, corr)) => (r, Some(corr)),
            None => (self.motion.next(self.ctrl.dt_pos()), None),
        };
        let frf = self.frf_input();
        let r = match frf {
            Some((v, ph, Injection::Position)) => self.frf_reference(&base, v, ph),
            _ => base,
        };
        if let (Some(c), Some(t)) = (&mut self.map_cursor, self.map_table.as_deref()) {
            let (offset, scale) = c.sample(r.pos, t);
            self.ctrl.set_map_sample(offset + self.table_corr, scale);
        } else if let Some(u) = corr {
            self.ctrl.set_map_sample(u, 1.0);
        }
        self.ctrl.feedforward_ahead(&r);
        Ahead { base, r, frf }
    }

    /// The frequency-response measurement's sample now, if one runs: its injected value, its
    /// phase and where it goes.
    fn frf_input(&self) -> Option<FrfIn> {
        let f = self.frf.as_ref().filter(|f| f.state().running())?;
        let (v, ph) = f.value();
        Some((v, ph, f.injection()))
    }

    /// The reference `base` with the measurement's sine `v` (phase `ph`) added: its position,
    /// velocity and acceleration.
    fn frf_reference(&self, base: &RefSample, v: f32, ph: (f32, f32)) -> RefSample {
        let rpc = self.ctrl.rad_per_count();
        let (w, amp) = self.frf.as_ref().map_or((0.0, 0.0), |f| {
            (f.omega(self.ctrl.params().pos_rate_hz), f.amplitude())
        });
        RefSample {
            pos: base.pos.saturating_add((v / rpc * SUB_PER_COUNT) as i64),
            vel: base.vel + w * amp * ph.1,
            acc: base.acc - w * w * v,
        }
    }

    /// After a position step with the measurement's sample `(v, ph, inj)`: the sine added to
    /// the current command (when it goes there) and the responses summed.
    fn frf_output(&mut self, (v, ph, inj): FrfIn) {
        if inj == Injection::Current {
            self.ctrl.inject_current(v);
        }
        // The position relative to the reference without the sine [rad], from the step's
        // error (reference minus position): at the current command the reference is that
        // one; at the reference the sine is in it.
        let y = match inj {
            Injection::Current => -self.out.error,
            Injection::Position => v - self.out.error,
        };
        let x: [f32; CHANNELS] = [self.ctrl.last_output().i_cmd, self.current, y];
        let rate = self.ctrl.params().pos_rate_hz;
        if let Some(f) = &mut self.frf
            && f.step(&x, ph)
        {
            self.frf_report = Some(f.report(rate));
            self.fresh = true;
        }
    }

    fn telemetry(&mut self, pos: i64) -> Option<Sample> {
        if self.stream_every == 0 {
            return None;
        }
        self.stream_count += 1;
        if self.stream_count < self.stream_every {
            return None;
        }
        self.stream_count = 0;
        let p = self.ctrl.params();
        Some(Sample {
            steps: self.steps,
            pos,
            reference: self.r.pos,
            error: self.out.error,
            ff: self.out.ff_friction,
            current: self.current,
            friction: p.motor.k_m * self.current - p.motor.inertia * self.r.acc,
            friction_true: f32::NAN,
        })
    }
}

/// The encoder counter's reading counted the way `dir` says (negated, modulo the counter's
/// width, for -1: the count extension works on the top bits, so any width wraps alike).
fn directed(raw: u32, dir: f32) -> u32 {
    if dir < 0.0 { raw.wrapping_neg() } else { raw }
}
