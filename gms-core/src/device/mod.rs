//! The device core: the whole behaviour of a gms motor driver behind the bench protocol,
//! shared by the firmware (STM32F405) and the simulator's virtual device (`hil-sim serve`).
//!
//! A device is two halves that meet at a [`Mailbox`]:
//!
//! - [`ControlLoop`] runs once per PWM period (the current-loop rate; on the board in the
//!   PWM timer's interrupt): encoder count extension, current sense, every `ratio`-th period a
//!   position step (reference, controller, every fault check), the current step and the
//!   bridge's compare values, the step statistics and the telemetry decimation. Once per
//!   position step it publishes a [`Status`] and takes the pending [`Requests`].
//! - [`Front`] is the protocol side ([`crate::protocol::Device`]): it validates and prepares
//!   parameter sets (a set the board cannot run is refused with `err`), plans moves from the
//!   loop's current reference, decides save/load/defaults, formats `status` and telemetry.
//!
//! The shells only move numbers: the firmware reads TIM2, the ADC and the DWT and writes TIM8;
//! the virtual device runs the simulated plant between the steps. Hardware and time enter
//! through [`Inputs`], the [`LoopLink`] (how the front reaches the mailbox and waits) and the
//! [`ParamStore`] (where the parameter record lives); what a board is comes as a [`Board`].

mod capture;
mod control;
mod front;
mod record;
mod startup;
#[cfg(feature = "store")]
pub mod store;

pub use capture::{
    CAPTURE_FIELDS, CAPTURE_NAMES, Capture, CaptureSpec, StepValues, capture_field, capture_fields,
};

pub use crate::protocol::{CaptureState, DriveKind, StatusError, StatusReply, StatusValue};
pub use control::{
    ControlLoop, Inputs, MapTable, Outputs, SUPERVISE_MS, SUPPLY_TAU_S, SenseStart, SenseTrouble,
    TableBuf, ZERO_SAMPLES, calibrate_sense,
};
pub use front::{Front, LoopLink};
pub use record::*;
pub use startup::{ParamStore, Startup, StoreError, prepare, restore_map, startup};

pub use crate::control::chunk::{CHUNK_VALUES, Chunk};
use crate::control::controller::Controller;
use crate::control::reference::{MovePlan, RefSample, VelocityProfile};
use crate::drive::{BoardLimits, Faults, Limits, StepStats};
use crate::protocol::Settings;

/// The controller type a device runs (6 GMS blocks, as the protocol's settings).
pub type Ctrl = Controller<6>;

/// What a board is, as far as the device core needs to know.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Board {
    /// Clock of the PWM timer \[Hz\].
    pub pwm_timer_hz: u32,
    /// Largest period register value of the PWM timer \[counts\].
    pub pwm_max_arr: u32,
    /// Width of the encoder counter \[bits\].
    pub encoder_bits: u32,
    /// ADC conversions summed per current sample [-] (`>= 1`).
    pub sense_oversample: u32,
    /// The current-sense chain (scale and the zero the start-up calibration expects).
    pub sense: SenseChain,
    /// Safety limits of the board (trip factor, sense range, step budget).
    pub limits: BoardLimits,
    /// True on a simulator, whose telemetry also has the true friction (`friction_true`).
    pub has_truth: bool,
    /// How long the bridge needs to wake from its sleep before it drives \[s\]: after `enable`
    /// the loop holds both inputs high (brake: no voltage across the motor) this long before
    /// it starts controlling, so that no command is lost while the driver wakes (which the
    /// integrators would make up for with a jolt). 0: drives at once.
    pub bridge_wake_s: f32,
    /// The capture buffer's size (values) (the loop's `CaptureBuf`).
    pub capture_values: u32,
    /// The motor supply's divider on a spare channel of the sense ADC, if the board has one:
    /// the loop then measures the supply, its current loop's gain follows it, and driving
    /// outside the bridge's range is refused or latched (`supply`). Without one the supply
    /// is `lim.v_supply` as set.
    pub supply: Option<SupplySense>,
}

/// A board's motor-supply divider, read by the sense ADC (its `vref` and `full_scale`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SupplySense {
    /// Supply volts per volt at the ADC's pin \[-\]: (R_top + R_bottom) / R_bottom.
    pub divider: f32,
    /// The bridge's operating range \[V\] (low, high): the DRV8871's 6.5 … 45 V.
    pub range_v: (f32, f32),
}

impl SupplySense {
    /// The supply \[V\] a divider's ADC `code` reads, with the sense ADC's `vref` \[V\] and
    /// `full_scale` \[code\].
    pub fn volts(&self, code: u32, vref: f32, full_scale: f32) -> f32 {
        code as f32 / full_scale * vref * self.divider
    }

    /// The ADC code \[code\] a supply of `volts` \[V\] gives through the divider, with the
    /// sense ADC's `vref` \[V\] and `full_scale` \[code\] (rounded, within 0 … `full_scale`):
    /// the inverse of [`SupplySense::volts`], for the boards' models.
    pub fn code(&self, volts: f64, vref: f32, full_scale: f32) -> u32 {
        let fs = f64::from(full_scale);
        // Rounded by hand (no_std has no f64::round): the value is within 0 … fs here.
        let x = (volts / f64::from(self.divider) / f64::from(vref) * fs).clamp(0.0, fs);
        (x + 0.5) as u32
    }

    /// Whether `v` \[V\] is within the bridge's range.
    pub fn within(&self, v: f32) -> bool {
        v >= self.range_v.0 && v <= self.range_v.1
    }
}

/// A board's current-sense chain: its ADC, the zero the start-up calibration expects, and its
/// timing. The amplifier's scale is a parameter (`sense.v_per_a`), for the shunt the user fits.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SenseChain {
    /// The ADC's reference voltage \[V\] (the input that reads `full_scale`).
    pub vref: f32,
    /// The ADC's codes per `vref` \[code\] (4095 for a 12-bit ADC whose top code is `vref`).
    pub full_scale: f32,
    /// ADC code at zero current the board is built for \[code\].
    pub zero_code: f32,
    /// How far the measured zero may lie from `zero_code` \[code\] (amplifier offset, resistor
    /// tolerances).
    pub zero_tolerance: f32,
    /// How near each rail of the ADC's input range the amplifier's output stays linear \[V\]
    /// (an INA240 on a 3.3 V supply: within about 0.2 V of its supply, per the hardware
    /// review of its datasheet; 0 for an ideal sense). Past it the reading no longer grows
    /// with the current, so a trip set there would never be reached.
    pub linear_margin_v: f32,
    /// From the sampling trigger to the last conversion's end \[s\] ([`crate::drive::SenseTiming`];
    /// 0 for an instantaneous sense): the window is centred on the PWM period's turning point
    /// and the control step starts at its end, so it must leave the step its budget:
    /// `window_s <= 2 (1 - budget_fraction) / rate.cur_hz` ([`prepare`] refuses other rates).
    pub window_s: f32,
    /// How long after a PWM edge at the MCU's pin the reading is disturbed \[s\]: the
    /// bridge's propagation delay and dead time, then the amplifier's recovery from the
    /// common-mode step (0 for an ideal sense). Sets [`SenseChain::duty_max`].
    pub edge_settle_s: f32,
}

impl Board {
    /// The limits the loop checks for the settings `s` on this board (the trip below the
    /// current sense's range with `s`'s `sense.v_per_a`).
    pub fn limits(&self, s: &Settings) -> crate::drive::Limits {
        let mut l = crate::drive::limits_for(s, &self.limits, self.sense.range(s.sense_v_per_a));
        l.duty_max = self.sense.duty_max(s.cur_rate_hz);
        l
    }
}

impl SenseChain {
    /// The largest |duty| [-] at which no bridge edge disturbs the sense window at a current
    /// loop of `cur_hz` \[Hz\]: 1 − (`window_s` + 2 `edge_settle_s`) · `cur_hz`, within 0 … 1.
    ///
    /// The drive pulse is centred on the counter's top (`drive::bridge_compare`), the window
    /// on its bottom. The pulse's end comes |d| T / 2 after the top, and the reading is clean
    /// again `edge_settle_s` later; that must be before the window opens, `window_s` / 2
    /// before the bottom: T/2 + |d| T/2 + settle ≤ T − window/2. (The pulse's start, after the
    /// window, is the weaker bound.) An F4 board at 40 kHz: 1 − (10.4 + 2 × 1.92) µs / 25 µs =
    /// 0.43; at 20 kHz, 0.72. An ideal sense (the simulator's): 1.
    pub fn duty_max(&self, cur_hz: f32) -> f32 {
        let d = 1.0 - (self.window_s + 2.0 * self.edge_settle_s) * cur_hz;
        if d.is_finite() {
            d.clamp(0.0, 1.0)
        } else {
            0.0
        }
    }

    /// The analog watchdog's thresholds \[code\] for an ADC whose highest code is `top`: a
    /// conversion below the first or above the second is past the amplifier's linear range
    /// ([`SenseChain::linear_margin_v`] inside each rail), which no current within the trip
    /// reaches ([`SenseChain::reach`]): the board's watchdog (its ADC's LTR and HTR) and the
    /// simulator's ADC latch `over_current` on it. At least one code inside each end of the
    /// ADC's range, so that a conversion at 0 or `top` always counts (an ideal sense).
    ///
    /// The F4 boards' INA240 (0.2 V inside a 3.3 V rail, 4095 codes): 249 and 3846, so 248
    /// (0.1998 V) and 3847 (3.1001 V) are past it. Before, the watchdog sat at 1 and 4094,
    /// which the amplifier's output (it swings to about 0.05 V of each rail: codes 62 and
    /// 4033) never reaches.
    pub fn watchdog_codes(&self, top: u32) -> (u32, u32) {
        let margin = self.linear_margin_v / self.vref * self.full_scale;
        let margin = if margin.is_finite() && margin > 0.0 {
            margin
        } else {
            0.0
        };
        // Float to int casts truncate (here: floor, the values are not negative) and
        // saturate; the clamps keep low <= high + 1.
        let whole = margin as u32;
        let ceil = if (whole as f32) < margin {
            whole + 1
        } else {
            whole
        };
        let low = ceil.clamp(1, top.max(1));
        let floor = (top as f32 - margin).max(0.0) as u32;
        let high = floor.clamp(
            low.saturating_sub(1),
            top.saturating_sub(1).max(low.saturating_sub(1)),
        );
        (low, high)
    }

    /// True when the conversion `code` of an ADC whose highest code is `top` is past the
    /// watchdog's thresholds ([`SenseChain::watchdog_codes`]), as the board's ADC flags it
    /// (RM0090 §13.3.7: below the low threshold or above the high one).
    pub fn watchdog_trips(&self, code: u32, top: u32) -> bool {
        let (low, high) = self.watchdog_codes(top);
        code < low || code > high
    }

    /// Current per ADC code \[A/code\] with an amplifier of `v_per_a` \[V/A\].
    pub fn amps_per_code(&self, v_per_a: f32) -> f32 {
        self.vref / self.full_scale / v_per_a
    }

    /// The largest current the chain shows in either direction around its nominal zero
    /// \[A\], with an amplifier of `v_per_a` \[V/A\] ([`SenseChain::reach`] from `zero_code`).
    pub fn range(&self, v_per_a: f32) -> f32 {
        self.reach(self.zero_code, v_per_a)
    }

    /// The largest current \[A\] the chain measures in both directions from a zero at
    /// `zero` \[code\] (the one start-up calibration found), with an amplifier of `v_per_a`
    /// \[V/A\]: the room from the zero to the nearer end of the amplifier's linear range
    /// ([`SenseChain::linear_margin_v`] inside each rail), 0 if there is none.
    pub fn reach(&self, zero: f32, v_per_a: f32) -> f32 {
        let margin = self.linear_margin_v / self.vref * self.full_scale;
        let room = (zero - margin).min(self.full_scale - margin - zero);
        if room > 0.0 {
            room * self.amps_per_code(v_per_a)
        } else {
            0.0
        }
    }
}

/// A complete, validated parameter set prepared for the loop (built on the protocol side,
/// taken by the loop between two steps).
#[derive(Debug, Clone)]
pub struct Applied {
    /// The controller (at rest; the loop hands its running state over to it).
    pub ctrl: Ctrl,
    /// The safety limits that go with it.
    pub limits: Limits,
    /// PWM timer prescaler (register value).
    pub psc: u32,
    /// PWM period (register value) [timer counts].
    pub arr: u32,
}

/// A move planned on the protocol side from the reference published at `from_step`.
#[derive(Debug, Clone, Copy)]
pub struct MoveRequest {
    /// The plan; its time 0 is the reference of position step `from_step`.
    pub plan: MovePlan,
    /// The position step whose reference the plan starts from.
    pub from_step: u64,
}

/// What the protocol side asks of the position map's table.
#[derive(Debug, Clone, Copy)]
pub enum MapRequest {
    /// Write bins `start` … `start + n − 1` from `values` (offset and scale interleaved),
    /// checked on the protocol side.
    Write {
        /// First bin.
        start: u32,
        /// Bins.
        n: u32,
        /// Their values, interleaved.
        values: [f32; 2 * MAP_WRITE_BINS],
    },
    /// Copy bins from `start` (at most `max`) into the requests' chunk (two fields).
    Read {
        /// First bin.
        start: u32,
        /// Bins at most.
        max: u32,
    },
    /// Offsets 0, scales 1.
    Clear,
}

/// The most bins one `map write` carries.
pub const MAP_WRITE_BINS: usize = 8;

/// What the protocol side asks of a frequency-response measurement.
#[derive(Debug, Clone, Copy)]
pub enum FrfRequest {
    /// Start one (a measurement under way is stopped; ignored unless the position loop runs).
    Start(crate::control::frf::FrfSpec),
    /// Stop the one under way (what was summed stands).
    Stop,
}

/// What the loop hands the protocol side at an exchange besides its status (each only when
/// there is something new).
#[derive(Debug, Default)]
pub struct Handover<'a> {
    /// The loop's position step at this exchange (what [`Mailbox::taken_at`] records).
    pub steps: u64,
    /// The requests taken at the last exchange, acted on, given back (with the chunk a read
    /// asked for).
    pub returned: Option<RequestsBuf>,
    /// The frequency-response measurement's report (at the end of each group of periods, and
    /// when it stops).
    pub frf: Option<&'a crate::control::frf::FrfReport>,
    /// The table motion's report (after a request, at each period's end, when a run ends).
    pub table: Option<&'a crate::control::table::TableReport>,
}

/// What the protocol side asks of the capture.
#[derive(Debug, Clone, Copy)]
pub enum CaptureRequest {
    /// Arm a capture (the data of the last one is dropped).
    Arm(CaptureSpec),
    /// Stop and drop.
    Off,
    /// Copy samples from `start` (at most `max`) into the requests' chunk.
    Read {
        /// First sample.
        start: u32,
        /// Samples at most.
        max: u32,
    },
}

/// A speed profile planned on the protocol side from the reference published at `from_step`.
#[derive(Debug, Clone, Copy)]
pub struct VelocityRequest {
    /// The profile; its time 0 is the reference of position step `from_step`.
    pub profile: VelocityProfile,
    /// The position step whose reference the profile starts from.
    pub from_step: u64,
}

/// A controller's storage, handed between the two halves by reference: the loop runs one,
/// the protocol side builds the next in the other (`static`s on a board).
pub type CtrlBuf = &'static mut Ctrl;

/// The requests' storage, handed between the two halves by reference: the protocol side
/// fills it, the loop acts on it in place, and gives it back.
pub type RequestsBuf = &'static mut Requests;

/// A parameter set posted to the loop: the controller built by the protocol side in its
/// spare storage ([`CtrlBuf`]); the loop swaps it for the running one (handing its running
/// state over) and gives the old one back in its place.
#[derive(Debug)]
pub struct Staged {
    /// The new controller (at rest); after the swap, the old one.
    pub ctrl: CtrlBuf,
    /// The safety limits that go with it.
    pub limits: Limits,
    /// PWM timer prescaler (register value).
    pub psc: u32,
    /// PWM period (register value) [timer counts].
    pub arr: u32,
    /// Set by the loop once it has swapped the controllers (`ctrl` is then the old one).
    pub taken: bool,
}

/// What the protocol side asks of the loop; acted on in place at the start of a position
/// step (the loop holds it by reference: nothing is copied into the control interrupt).
#[derive(Debug)]
pub struct Requests {
    /// A new parameter set: taken without a bump at the same loop rates; other rates switch
    /// the bridge off for the change.
    pub apply: Option<Staged>,
    /// Switch the bridge on (ignored while a fault is latched).
    pub enable: bool,
    /// Switch the bridge off.
    pub disable: bool,
    /// Clear the latched faults.
    pub clear: bool,
    /// Latch these faults.
    pub latch: Faults,
    /// The motor supply the protocol side measured \[V\] ([`Front::supervise`]): the current
    /// loop's duty follows it from this exchange on.
    pub supply_v: Option<f32>,
    /// Start a move (ignored while disabled).
    pub motion: Option<MoveRequest>,
    /// Start a speed profile (ignored while disabled).
    pub velocity: Option<VelocityRequest>,
    /// Hold a current \[A\] with the position loop off (ignored while disabled).
    pub current: Option<f32>,
    /// For so many position steps, then 0 A (with `current`); `None`: until the next request.
    pub current_steps: Option<u32>,
    /// Leave current mode: hold the position where the axis is.
    pub hold_here: bool,
    /// Arm, stop or read the capture.
    pub capture: Option<CaptureRequest>,
    /// Start or stop a frequency-response measurement.
    pub frf: Option<FrfRequest>,
    /// Write, read or clear the position map's table.
    pub map: Option<MapRequest>,
    /// The table motion.
    pub table: Option<crate::control::table::TableRequest>,
    /// Telemetry every N position steps (0: off).
    pub stream_every: Option<u32>,
    /// Reset the step statistics.
    pub reset_stats: bool,
    /// What a read (capture, map, table) put here for the protocol side: the loop writes it
    /// in place, and it goes back with the requests.
    pub chunk: Chunk,
}

impl Requests {
    /// Nothing asked (as [`Default`], for a `static`).
    pub const fn new() -> Requests {
        Requests {
            apply: None,
            enable: false,
            disable: false,
            clear: false,
            latch: Faults::NONE,
            supply_v: None,
            motion: None,
            velocity: None,
            current: None,
            current_steps: None,
            hold_here: false,
            capture: None,
            frf: None,
            map: None,
            table: None,
            stream_every: None,
            reset_stats: false,
            chunk: Chunk::new(0, 0),
        }
    }
}

impl Default for Requests {
    fn default() -> Requests {
        Requests::new()
    }
}

/// What the loop shows the protocol side, published every position step.
#[derive(Debug, Clone, Copy, Default)]
pub struct Status {
    /// Position steps since start (the step whose values these are).
    pub steps: u64,
    /// Position-loop rate \[Hz\].
    pub pos_rate_hz: f32,
    /// Encoder position \[counts\].
    pub pos: i64,
    /// The reference of that step (position [1/65536 count], velocity, acceleration).
    pub reference: RefSample,
    /// Position error \[rad\] (0 while disabled).
    pub error: f32,
    /// Friction feedforward applied [N·m].
    pub ff: f32,
    /// Motor current \[A\].
    pub current: f32,
    /// Last duty [-1, 1].
    pub duty: f32,
    /// Latched faults.
    pub faults: Faults,
    /// Bridge on.
    pub enabled: bool,
    /// A move is being played.
    pub moving: bool,
    /// Control-step durations [cycles of `limits.clock_hz`].
    pub stats: StepStats,
    /// Current-sense zero \[code\].
    pub sense_offset: f32,
    /// The adaptive scale on the friction feedforward (`ff.adapt.scale`) [-].
    pub adapt_scale: f32,
    /// What the loop controls (`status` `drive=`).
    pub drive: Drive,
    /// The capture's state.
    pub capture: CaptureState,
    /// Samples captured.
    pub captured: u32,
    /// The encoder position at the capture's trigger \[counts\].
    pub capture_origin: i64,
}

/// What the control loop controls while the bridge is on.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub enum Drive {
    /// The position: holding, or a `move`: the normal mode.
    #[default]
    Position,
    /// The position loop tracking a speed profile (`velocity`): the sliding and
    /// frictional-lag experiments.
    Velocity,
    /// A held current \[A\] with the position loop off (`current`): the pre-sliding
    /// experiment's torque.
    Current(f32),
}

impl Drive {
    /// What it drives, as `status` reports it (`drive=`).
    pub fn kind(&self) -> DriveKind {
        match self {
            Drive::Position => DriveKind::Position,
            Drive::Velocity => DriveKind::Velocity,
            Drive::Current(_) => DriveKind::Current,
        }
    }

    /// The name in `status` `drive=`.
    pub fn name(&self) -> &'static str {
        self.kind().name()
    }
}

/// One telemetry sample (one position step).
#[derive(Debug, Clone, Copy, Default)]
pub struct Sample {
    /// Position steps since start.
    pub steps: u64,
    /// Encoder position \[counts\].
    pub pos: i64,
    /// Reference [1/65536 count].
    pub reference: i64,
    /// Position error \[rad\].
    pub error: f32,
    /// Friction feedforward applied [N·m].
    pub ff: f32,
    /// Motor current \[A\].
    pub current: f32,
    /// Friction estimate: motor torque k_M i minus J a_ref [N·m] (what a board can know).
    pub friction: f32,
    /// The true friction [N·m]: filled in by a simulator ([`Board::has_truth`]), NaN on a
    /// board.
    pub friction_true: f32,
}

/// Telemetry fields `stream` accepts, in the order of [`Sample`]'s values. `friction_true`
/// only on a board with [`Board::has_truth`].
pub const FIELDS: [&str; 8] = [
    "t",
    "pos",
    "ref",
    "error",
    "ff",
    "current",
    "friction",
    "friction_true",
];

/// The highest telemetry rate \[Hz\].
pub const MAX_STREAM_HZ: f32 = 1000.0;

/// The exchange between the two halves: requests one way, the status the other. Held by the
/// shell behind whatever makes it atomic (a critical section on a board, a mutex on a host),
/// and only for a copy of the status and the move of a reference: the requests themselves
/// travel as a [`RequestsBuf`], so the loop acts on them outside the critical section.
#[derive(Debug, Default)]
pub struct Mailbox {
    /// Requests posted to the loop and not taken yet.
    pub requests: Option<RequestsBuf>,
    /// Requests the loop has acted on, back for the protocol side.
    pub returned: Option<RequestsBuf>,
    /// The loop's latest status.
    pub status: Status,
    /// The position step at which the loop last took requests.
    pub taken_at: u64,
    /// The frequency-response measurement's last report.
    pub frf: crate::control::frf::FrfReport,
    /// Reports published into [`Mailbox::frf`] (wrapping): a reader that copies it in parts
    /// ([`crate::control::frf::FrfReport::copy_part`]) compares it before and after.
    pub frf_seq: u32,
    /// The table motion's last report.
    pub table: crate::control::table::TableReport,
}

impl Mailbox {
    /// An empty mailbox (for a `static`).
    pub const fn new() -> Mailbox {
        Mailbox {
            requests: None,
            returned: None,
            status: Status {
                steps: 0,
                pos_rate_hz: 0.0,
                pos: 0,
                reference: RefSample {
                    pos: 0,
                    vel: 0.0,
                    acc: 0.0,
                },
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
                drive: Drive::Position,
                capture: CaptureState::Idle,
                captured: 0,
                capture_origin: 0,
            },
            taken_at: 0,
            frf: crate::control::frf::FrfReport {
                state: crate::control::frf::FrfState::Idle,
                injection: None,
                freq_hz: 0.0,
                amp: 0.0,
                lock: crate::control::frf::LockIn::new(),
                groups: 0,
            },
            frf_seq: 0,
            table: crate::control::table::TableReport {
                state: crate::control::table::TableState::Empty,
                geometry: None,
                period: 0,
                periods: 0,
                generation: 0,
                pending: false,
                done: None,
                held: false,
                started: 0,
            },
        }
    }

    /// Requests are posted and not taken yet.
    pub fn posted(&self) -> bool {
        self.requests.is_some()
    }

    /// The protocol side's: posts the requests `buf` holds for the loop to take.
    pub fn post(&mut self, buf: RequestsBuf) {
        self.requests = Some(buf);
    }

    /// The loop's side, once a position period (in its last current step, which with both
    /// loops at one rate is every step): gives back the requests acted on; then takes
    /// the posted requests, if any, or else publishes the status `status` builds (with the
    /// reports handed over). The step that takes requests (a parameter set: the heaviest,
    /// with its hand-over) neither builds nor copies the status; the next one publishes it.
    /// Returns the requests taken. (A shell that must keep its critical sections short calls
    /// [`Mailbox::take`] and [`Mailbox::publish`] under two, and builds the status between.)
    pub fn exchange(
        &mut self,
        status: &dyn Fn() -> Status,
        mut h: Handover<'_>,
    ) -> Option<RequestsBuf> {
        if let Some(taken) = self.take(&mut h) {
            return Some(taken);
        }
        self.publish(status(), &h);
        None
    }

    /// The first half of [`Mailbox::exchange`]: the requests acted on given back (moved out
    /// of `h`), the posted ones taken, if any.
    pub fn take(&mut self, h: &mut Handover<'_>) -> Option<RequestsBuf> {
        if let Some(b) = h.returned.take() {
            self.returned = Some(b);
        }
        let taken = self.requests.take()?;
        self.taken_at = h.steps;
        Some(taken)
    }

    /// The second half of [`Mailbox::exchange`], when nothing was taken: `status` published,
    /// with the reports `h` hands over.
    pub fn publish(&mut self, status: Status, h: &Handover<'_>) {
        self.status = status;
        if let Some(f) = h.frf {
            self.frf = *f;
            self.frf_seq = self.frf_seq.wrapping_add(1);
        }
        if let Some(t) = h.table {
            self.table = *t;
        }
    }
}

/// The one default parameter set of a device (the firmware's built-in set, `defaults`, the
/// simulator's controller before a scenario's `[controller]` table): the paper's motor and
/// Table 1 compensation, the current loop at 40 kHz, the position loop at 20 kHz.
///
/// The loops are the commissioning rule's for the default motor (`gms_ident::gains`): the
/// current PI with 4 dB of gain margin against its delay (the resistance's drop fed forward),
/// and the position PID with its kd chosen, and kp lowered, for the margins over the plant
/// variations the rule holds them over (the pre-sliding stiffness ×0.5…×2, the inertia ±20 %):
/// at rest 47.9° and 12.9 dB, sliding 47.4° and 13.3 dB on the default plant, 40.2° and
/// 10.4 dB at the worst variation (the linear model). The current loop at twice the position loop's
/// rate halves the delay from a position sample to the winding's voltage, which is what the
/// margins were short of at 20 kHz (the earlier default had 20° and 2.4 dB at rest).
///
/// `ff.gain` is 0.94, not 1: the GMS model follows the reference while the axis lags it, so a
/// full feedforward turns over at a reversal before the real friction does. On the
/// simulator's default plant (20 draws of the demo's run, the earlier 20 kHz loop) the sine's
/// RMS error was 0.486 counts at 0.94 against 0.501 at 1.0, 0.497 at 0.97, 0.493 at 0.9 and
/// 0.509 at 0.85. A board with another motor or other gains is tuned on the bench.
pub fn default_settings() -> Settings {
    use crate::control::controller::{
        ControllerParams, CurrentParams, FeedforwardParams, FfMode, MotorModel, PidParams,
    };
    ControllerParams {
        pos_rate_hz: 20_000.0,
        cur_rate_hz: 40_000.0,
        // The paper's encoder: 2π / 3.8 µrad in single precision (1653469.75), whose radians
        // per count are 3.8e-6 exactly again (`ControllerParams::rad_per_count`).
        counts_per_rev: 1_653_469.8,
        // The power stage's INA240A2 (gain 50) over a 68 mΩ shunt (gms-core/src/boards/power_stage.rs).
        sense_v_per_a: 3.4,
        pid: PidParams {
            kp: 0.49,
            ki: 700.0,
            kd: 2.45e-4,
            d_filter_hz: 9000.0,
            i_limit: 1e-3,
            ki_fric: crate::control::controller::DEFAULT_KI_FRIC,
        },
        shaping: crate::control::shaping::ShapingParams::OFF,
        map: crate::control::posmap::MapParams::DEFAULT,
        current: CurrentParams {
            kp: 10.85,
            ki: 1.98e4,
        },
        motor: MotorModel {
            k_m: 6.6e-3,
            r: 10.0,
            k_e: 6.6e-3,
            inertia: 6e-8,
        },
        // Under the over-current trip, which the sense's range puts at 0.456 A (95 % of the
        // ±0.485 A it shows): a loop that saturates (a blocked or stalled axis) is then held
        // at the limit and trips `following_error`, not `over_current` (at 0.5 A it did, once
        // the current loop tracked its command closely).
        i_max: 0.4,
        v_supply: 12.0,
        dead_time: 0.0,
        // ±50 rad of the motor: ±0.9 mm of the slide through the gearhead and lead screw.
        pos_min: -50.0,
        pos_max: 50.0,
        enc_dir: 1.0,
        sense_dir: 1.0,
        ff: FeedforwardParams {
            mode: FfMode::Gms,
            gain: 0.94,
            actuator: crate::friction::presets::table1(),
            guideway: Some(crate::friction::presets::guideway()),
            ratio: 18.1e-6,
            static_band: 0.05,
            adapt: crate::control::adaptive::AdaptiveParams::default(),
        },
    }
}
