//! Table motion: a periodic reference and a feedforward correction played from tables at the
//! position rate, repeated a chosen number of periods, with the error of each period kept for
//! the host — what iterative learning control (`gms-tune learn`) runs on.
//!
//! The tables live in one buffer of the shell's ([`TABLE_VALUES`] values: a static on the
//! board, 20 KiB): the reference, two corrections (the one played and the one being
//! written) and two period errors (the one being filled and the last one complete).
//!
//! - **Decimation**: a table holds at most [`TABLE_POINTS`] points, `steps` position steps
//!   apart (a period of `points × steps` steps: one second at 10 kHz is 1000 points 10 steps
//!   apart). Between points the reference is a periodic Catmull-Rom cubic (position, velocity
//!   and acceleration from the same cubic: the velocity is continuous), the correction linear.
//! - **Reference** (counts, relative to an origin in whole counts: an f32 keeps 1/1000 count
//!   at 16 000 counts from it): uploaded in blocks; the protocol side checks every value as it
//!   comes ([`Upload`]) and `table set` checks the whole (continuous — no chord, the closing
//!   one included, faster than the speed limit —, within the soft limits) before the loop may
//!   play it: all or nothing.
//! - **Correction** \[N·m\], added to the feedforward: written into the spare buffer while the
//!   other plays, and swapped in at the start of the next period (never within one), each
//!   swap a new generation.
//! - **Error** \[counts\], reference minus position: each point's bin is the mean over the
//!   `steps` steps from that point on (a bin is centred `(steps − 1) / 2` steps after its
//!   point), and the period's RMS and peak over every step; at the period's end the buffer
//!   filled becomes the complete one, tagged with the period and the correction's generation
//!   it was played with.
//! - **Held until read**: a complete period played wholly with the newest correction (none
//!   waiting for the period's start) is *held*: the periods after it play on and are counted,
//!   but do not replace it, until the host asks for the next one (`table next`, or a new
//!   correction with `table use` / `table corr off`). However slow the link, the host reads
//!   one whole period, the first of its correction, and never a mix of two.

use crate::control::reference::{RefSample, SUB_PER_COUNT, SubCounts};

/// The most points a table holds.
pub const TABLE_POINTS: usize = 1024;
/// The table buffer's length \[values\]: reference, two corrections, two errors.
pub const TABLE_VALUES: usize = 5 * TABLE_POINTS;
/// The most values one `table ref` or `table corr` line carries.
pub const TABLE_WRITE_VALUES: usize = 8;
/// The most periods one `table run` plays.
pub const TABLE_MAX_PERIODS: u32 = 1_000_000;
/// The longest period \[s\].
pub const TABLE_MAX_PERIOD_S: f32 = 600.0;
/// The largest reference value, either way \[counts from the origin\].
pub const TABLE_MAX_COUNTS: f32 = 16_777_216.0;
/// The refusal of a `table read err` during which the period read was replaced (its values
/// would mix two periods; only a `table next` or a new correction sent meanwhile does that).
pub const READ_RACED: &str = "a period ended during the read (read again)";

/// One of the tables.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Which {
    /// The reference \[counts from the origin\].
    Ref,
    /// The correction played \[N·m\] (for a write: the one being written).
    Corr,
    /// The last complete period's error \[counts\].
    Err,
}

impl Which {
    /// From its protocol name (`ref`, `corr`, `err`).
    pub fn from_name(s: &str) -> Option<Which> {
        match s {
            "ref" => Some(Which::Ref),
            "corr" => Some(Which::Corr),
            "err" => Some(Which::Err),
            _ => None,
        }
    }
}

/// Where a table's points are.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Geometry {
    /// Points in a period (4 … [`TABLE_POINTS`]).
    pub points: u32,
    /// Position steps between two points (`>= 1`).
    pub steps: u32,
    /// The reference's origin \[counts\].
    pub origin: i64,
}

impl Geometry {
    /// Position steps in one period.
    pub fn period_steps(&self) -> u64 {
        u64::from(self.points) * u64::from(self.steps)
    }
}

/// What the table motion is doing.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum TableState {
    /// No reference set.
    #[default]
    Empty,
    /// A reference set, not playing.
    Ready,
    /// Playing.
    Playing,
}

impl TableState {
    /// The name `table` reports.
    pub fn name(&self) -> &'static str {
        match self {
            TableState::Empty => "empty",
            TableState::Ready => "ready",
            TableState::Playing => "playing",
        }
    }
}

/// The figures of one complete period.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PeriodError {
    /// The period's number in its run (from 0).
    pub period: u32,
    /// The generation of the correction it was played with (0: none).
    pub generation: u32,
    /// RMS of the error over its steps \[counts\].
    pub rms: f32,
    /// The largest error's magnitude \[counts\].
    pub peak: f32,
}

/// The table motion's state for the protocol side (handed over when it changes and at
/// each period's end).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct TableReport {
    /// What it does.
    pub state: TableState,
    /// The reference's geometry (none while empty).
    pub geometry: Option<Geometry>,
    /// Periods completed in the run (or the last run).
    pub period: u32,
    /// Periods the run plays.
    pub periods: u32,
    /// The generation of the correction played (0: none).
    pub generation: u32,
    /// A correction waits for the next period's start.
    pub pending: bool,
    /// The last complete period, if any.
    pub done: Option<PeriodError>,
    /// The last complete period is held: later periods do not replace it until `table next`
    /// (or a new correction).
    pub held: bool,
    /// The position step the run (or the last run) started at: its first step played (to
    /// align a capture or telemetry with the periods).
    pub started: u64,
}

/// What the protocol side asks of the table motion.
#[derive(Debug, Clone, Copy)]
pub enum TableRequest {
    /// Write points `start` … `start + n − 1` of the reference (`Which::Ref`, which makes the
    /// table empty until the next `Set`) or of the correction being written (`Which::Corr`),
    /// checked on the protocol side.
    Write {
        /// Which table.
        which: Which,
        /// First point.
        start: u32,
        /// Points.
        n: u32,
        /// Their values.
        values: [f32; TABLE_WRITE_VALUES],
    },
    /// The reference written is whole and checked: play it with this geometry (no correction).
    Set(Geometry),
    /// The correction written is whole and checked: play it from the next period's start.
    Use,
    /// Stop playing a correction (from the next period's start).
    NoCorrection,
    /// Play the table this many periods from its start (the reference must be there).
    Run(u32),
    /// End the run at the end of the period under way.
    Stop,
    /// Copy points from `start` (at most `max`) of a table into the mailbox's chunk.
    Read {
        /// Which table.
        which: Which,
        /// First point.
        start: u32,
        /// Points at most.
        max: u32,
    },
    /// Forget the reference and the correction (not while playing).
    Clear,
    /// Release the period held: the next complete period of the correction played replaces
    /// it (and is held in turn).
    Next,
}

/// Offsets of the tables in the buffer: the reference, correction buffer `i`, error buffer `i`
/// (a branch, not an array's index: nothing here can panic).
const REF: usize = 0;
fn corr_at(i: u8) -> usize {
    if i == 0 {
        TABLE_POINTS
    } else {
        2 * TABLE_POINTS
    }
}
fn err_at(i: u8) -> usize {
    if i == 0 {
        3 * TABLE_POINTS
    } else {
        4 * TABLE_POINTS
    }
}

/// The table motion's player (the control loop's): where in the period it is, which buffers
/// play and fill, the period's sums.
#[derive(Debug, Clone, Default)]
pub struct Player {
    geo: Option<Geometry>,
    state: TableState,
    /// Point and step within it.
    k: u32,
    j: u32,
    inv_steps: f32,
    period: u32,
    periods: u32,
    stopping: bool,
    /// The correction played (buffer index), none: no correction.
    corr: Option<u8>,
    generation: u32,
    /// A swap waits for the period's start: the buffer to play (none: stop the correction).
    pending: Option<Option<u8>>,
    /// The error buffer being filled.
    fill: u8,
    acc: f32,
    sumsq: f32,
    peak: f32,
    count: u32,
    generation_at_start: u32,
    done: Option<(PeriodError, u8)>,
    /// `done` is held (the periods ending do not replace it).
    held: bool,
    started: u64,
    /// Cached for the steps: points and steps of the geometry, the origin \[1/65536 count\],
    /// the velocity and acceleration per unit of the cubic's derivatives, counts per radian.
    points: u32,
    steps: u32,
    origin_sub: i64,
    vscale: f32,
    ascale: f32,
    counts_per_rad: f32,
}

/// The values at a step: the reference and the correction \[N·m\].
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct TableSample {
    /// The reference.
    pub r: RefSample,
    /// The correction \[N·m\].
    pub corr: f32,
}

/// What [`Player::record`] found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Recorded {
    /// Within a period.
    Within,
    /// A period ended; the run goes on.
    PeriodEnd,
    /// A period ended and so did the run: hold at the reference (the table's start).
    RunEnd(SubCounts),
}

impl Player {
    /// The report for the protocol side.
    pub fn report(&self) -> TableReport {
        let mut r = TableReport::default();
        self.report_into(&mut r);
        r
    }

    /// The report for the protocol side written into `r` field by field (the control loop's
    /// copy: no report built on the stack and copied over it; one copy of it in the image).
    #[inline(never)]
    pub fn report_into(&self, r: &mut TableReport) {
        r.state = self.state;
        r.geometry = self.geo;
        r.period = self.period;
        r.periods = self.periods;
        r.generation = self.generation;
        r.pending = self.pending.is_some();
        r.done = self.done.map(|d| d.0);
        r.held = self.held;
        r.started = self.started;
    }

    /// Notes what a run just asked for starts with: its first position step (the loop's
    /// count), the encoder's `rpc` \[rad/count\] and the position rate `rate` \[Hz\].
    pub fn set_started(&mut self, step: u64, rpc: f32, rate: f32) {
        self.started = step;
        let per_s = rate * self.inv_steps;
        self.vscale = rpc * per_s;
        self.ascale = rpc * per_s * per_s;
        self.counts_per_rad = if rpc > 0.0 { 1.0 / rpc } else { 0.0 };
    }

    /// True while playing.
    pub fn playing(&self) -> bool {
        self.state == TableState::Playing
    }

    /// The table's start \[1/65536 count\] (none while empty).
    pub fn start(&self, t: &[f32]) -> Option<SubCounts> {
        let g = self.geo?;
        Some(to_sub(g.origin, t.get(REF).copied().unwrap_or(0.0)))
    }

    /// Acts on a request (between two position steps; nothing here loops over a table; a
    /// read fills `chunk`, and does nothing without one). `Run` is taken only from `Ready` (the
    /// protocol side also checks that the loop's reference is at the table's start).
    pub fn take(
        &mut self,
        req: &TableRequest,
        t: &mut [f32],
        chunk: Option<&mut crate::control::chunk::Chunk>,
    ) {
        match *req {
            TableRequest::Write {
                which,
                start,
                n,
                values,
            } => {
                let base = match which {
                    Which::Ref if !self.playing() => {
                        self.geo = None;
                        self.state = TableState::Empty;
                        self.corr = None;
                        self.pending = None;
                        self.done = None;
                        self.held = false;
                        REF
                    }
                    Which::Corr if self.pending.is_none() => corr_at(self.spare()),
                    _ => return,
                };
                let from = base + start as usize;
                let len = (n as usize).min(TABLE_WRITE_VALUES);
                let room = (base + TABLE_POINTS).saturating_sub(from);
                if let Some(dst) = t.get_mut(from..) {
                    for (d, v) in dst.iter_mut().zip(values.iter().take(len.min(room))) {
                        *d = *v;
                    }
                }
            }
            TableRequest::Set(g) => {
                if !self.playing() && g.points >= 4 && g.points as usize <= TABLE_POINTS {
                    self.geo = Some(Geometry {
                        steps: g.steps.max(1),
                        ..g
                    });
                    self.inv_steps = 1.0 / g.steps.max(1) as f32;
                    self.points = g.points;
                    self.steps = g.steps.max(1);
                    self.origin_sub = super::reference::sub_counts(g.origin);
                    self.state = TableState::Ready;
                    self.corr = None;
                    self.pending = None;
                    self.done = None;
                    self.held = false;
                    self.generation = 0;
                    self.period = 0;
                    self.periods = 0;
                }
            }
            // Either waits for the period's start while playing, or is taken at once.
            TableRequest::Use => {
                if self.geo.is_some() && self.pending.is_none() {
                    self.pending = Some(Some(self.spare()));
                    self.generation = self.generation.wrapping_add(1);
                    self.held = false;
                }
                if !self.playing() {
                    self.take_pending();
                }
            }
            TableRequest::NoCorrection => {
                self.pending = Some(None);
                self.held = false;
                if !self.playing() {
                    self.take_pending();
                }
            }
            TableRequest::Run(periods) => {
                if self.state == TableState::Ready && periods > 0 {
                    self.state = TableState::Playing;
                    (self.k, self.j) = (0, 0);
                    self.period = 0;
                    self.periods = periods;
                    self.stopping = false;
                    self.done = None;
                    self.held = false;
                    self.clear_sums();
                }
            }
            TableRequest::Stop => self.stopping = self.playing(),
            TableRequest::Read { which, start, max } => {
                let Some(chunk) = chunk else { return };
                chunk.start = start;
                chunk.samples = 0;
                chunk.nfields = 1;
                let points = self.geo.map_or(0, |g| g.points) as usize;
                let base = match which {
                    Which::Ref => Some(REF),
                    Which::Corr => self.corr.map(corr_at),
                    Which::Err => self.done.map(|d| err_at(d.1)),
                };
                let Some(base) = base else { return };
                let n = (max as usize)
                    .min(crate::control::chunk::CHUNK_VALUES)
                    .min(points.saturating_sub(start as usize));
                if let Some(src) = t.get(base + start as usize..) {
                    for (d, v) in chunk.values.iter_mut().zip(src.iter().take(n)) {
                        *d = *v;
                    }
                    chunk.samples = n as u32;
                }
            }
            TableRequest::Clear => {
                if !self.playing() {
                    *self = Player::default();
                }
            }
            TableRequest::Next => self.held = false,
        }
    }

    /// The correction buffer not played.
    fn spare(&self) -> u8 {
        match self.corr {
            Some(0) => 1,
            _ => 0,
        }
    }

    /// The correction waiting (a buffer, or none) becomes the one played.
    fn take_pending(&mut self) {
        if let Some(p) = self.pending.take() {
            self.corr = p;
            if p.is_none() {
                self.generation = 0;
            }
        }
    }

    fn clear_sums(&mut self) {
        self.acc = 0.0;
        self.sumsq = 0.0;
        self.peak = 0.0;
        self.count = 0;
        self.generation_at_start = self.generation;
    }

    /// Ends the run now (the bridge went off, another motion took over).
    pub fn abort(&mut self) {
        if self.playing() {
            self.state = TableState::Ready;
            self.stopping = false;
            // A correction waiting is taken now: it was asked for.
            self.take_pending();
        }
    }

    /// The reference and the correction at this step (the encoder and the rate as the run
    /// started with, [`Player::set_started`]). Only while playing.
    pub fn sample(&self, t: &[f32]) -> TableSample {
        let n = self.points as usize;
        let k = self.k as usize;
        // The neighbours, wrapping round the period (no division in the step).
        let km1 = if k == 0 { n.saturating_sub(1) } else { k - 1 };
        let kp1 = if k + 1 >= n { k + 1 - n } else { k + 1 };
        let kp2 = if k + 2 >= n { k + 2 - n } else { k + 2 };
        let at = |i: usize| t.get(REF + i).copied().unwrap_or(0.0);
        let s = self.j as f32 * self.inv_steps;
        let (pos, dds, d2ds2) = catmull_rom([at(km1), at(k), at(kp1), at(kp2)], s);
        let corr = match self.corr {
            Some(c) => {
                let base = corr_at(c);
                let c1 = t.get(base + k).copied().unwrap_or(0.0);
                let c2 = t.get(base + kp1).copied().unwrap_or(0.0);
                c1 + s * (c2 - c1)
            }
            None => 0.0,
        };
        // In fixed point through 32-bit conversions (a float to a 64-bit integer is a library
        // call on this core): the whole counts, then the fraction (|pos| < 2^24 counts).
        let whole = pos as i32;
        let frac = ((pos - whole as f32) * SUB_PER_COUNT) as i32;
        TableSample {
            r: RefSample {
                pos: self
                    .origin_sub
                    .wrapping_add(i64::from(whole) << 16)
                    .wrapping_add(i64::from(frac)),
                vel: dds * self.vscale,
                acc: d2ds2 * self.ascale,
            },
            corr,
        }
    }

    /// After the step played with [`Player::sample`]: its error `error_rad` \[rad\] summed (in
    /// counts), the phase advanced; at a period's end the error buffers swap, a correction
    /// waiting is taken, and the run ends when it has played its periods (or was stopped).
    pub fn record(&mut self, t: &mut [f32], error_rad: f32) -> Recorded {
        if !self.playing() {
            return Recorded::Within;
        }
        let error = error_rad * self.counts_per_rad;
        self.acc += error;
        self.sumsq += error * error;
        let mag = if error < 0.0 { -error } else { error };
        if mag > self.peak {
            self.peak = mag;
        }
        self.count += 1;
        self.j += 1;
        if self.j < self.steps {
            return Recorded::Within;
        }
        self.j = 0;
        let bin = err_at(self.fill) + self.k as usize;
        if let Some(v) = t.get_mut(bin) {
            *v = self.acc * self.inv_steps;
        }
        self.acc = 0.0;
        self.k += 1;
        if self.k < self.points {
            return Recorded::Within;
        }
        // The period's end: kept unless one is held (then the buffer filled is filled again);
        // held when it was played wholly with the newest correction (none waiting).
        self.k = 0;
        if !self.held {
            let count = self.count.max(1) as f32;
            self.done = Some((
                PeriodError {
                    period: self.period,
                    generation: self.generation_at_start,
                    rms: crate::math::sqrt(self.sumsq / count),
                    peak: self.peak,
                },
                self.fill,
            ));
            self.fill ^= 1;
            self.held = self.pending.is_none();
        }
        self.period = self.period.saturating_add(1);
        self.take_pending();
        self.clear_sums();
        if self.stopping || self.period >= self.periods {
            self.state = TableState::Ready;
            self.stopping = false;
            return Recorded::RunEnd(self.start(t).unwrap_or(self.origin_sub));
        }
        Recorded::PeriodEnd
    }
}

/// The reference between points `p[1]` and `p[2]` at `s` (0 … 1 of the interval), with `p[0]`
/// and `p[3]` their neighbours: the Catmull-Rom cubic (tangents from the neighbours), its
/// value and its first and second derivatives per interval. The device plays its table
/// with it; a host that needs the reference at every step (the learning's friction model run
/// along the path) calls it too.
#[inline(always)]
pub fn catmull_rom(p: [f32; 4], s: f32) -> (f32, f32, f32) {
    let [p0, p1, p2, p3] = p;
    let m1 = 0.5 * (p2 - p0);
    let m2 = 0.5 * (p3 - p1);
    let d = p2 - p1;
    let a = 3.0 * d - 2.0 * m1 - m2;
    let b = -2.0 * d + m1 + m2;
    (
        p1 + s * (m1 + s * (a + s * b)),
        m1 + s * (2.0 * a + 3.0 * s * b),
        2.0 * a + 6.0 * s * b,
    )
}

/// The position `counts` from `origin` \[counts\] in 1/65536 count.
fn to_sub(origin: i64, counts: f32) -> SubCounts {
    super::reference::sub_counts(origin).saturating_add((counts * SUB_PER_COUNT) as i64)
}

/// Why a table is refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TableError {
    /// A value is not finite or beyond [`TABLE_MAX_COUNTS`] (reference) or the drive's torque
    /// (correction).
    BadValue,
    /// Written out of order (each block must start where the last one ended, or at 0).
    OutOfOrder,
    /// More than [`TABLE_POINTS`] points, or beyond the geometry's.
    TooMany,
    /// The reference written is not whole (`points` values from 0).
    NotWhole,
    /// Points outside 4 … [`TABLE_POINTS`], steps 0, or a period over [`TABLE_MAX_PERIOD_S`].
    BadGeometry,
    /// A chord (the closing one from the last point to the first included) faster than the
    /// speed limit: not continuous.
    TooFast,
    /// The reference leaves the soft limits.
    OutOfStroke,
}

impl TableError {
    /// The reason as the protocol words it.
    pub fn reason(&self) -> &'static str {
        match self {
            TableError::BadValue => "a value not finite or too large",
            TableError::OutOfOrder => "blocks must follow each other from point 0",
            TableError::TooMany => "beyond the table's points",
            TableError::NotWhole => "the reference is not written whole (POINTS values from 0)",
            TableError::BadGeometry => {
                "POINTS from 4 to 1024, STEPS >= 1, a period of at most 600 s"
            }
            TableError::TooFast => {
                "a jump: a step between points faster than the speed limit (20 rad/s)"
            }
            TableError::OutOfStroke => "the reference leaves the soft limits",
        }
    }
}

/// The protocol side's check of a table as it is written: each block in order, each value,
/// and the reference's extent and steepest chord for [`Upload::check_set`].
#[derive(Debug, Clone, Copy, Default)]
pub struct Upload {
    /// Reference points written from 0.
    pub ref_next: u32,
    first: f32,
    last: f32,
    min: f32,
    max: f32,
    max_chord: f32,
    /// Correction points written from 0 (into the buffer not played).
    pub corr_next: u32,
}

impl Upload {
    /// Checks a block of the reference from `start` (\[counts\]); on success it is counted.
    pub fn write_ref(&mut self, start: u32, values: &[f32]) -> Result<(), TableError> {
        if start != 0 && start != self.ref_next {
            return Err(TableError::OutOfOrder);
        }
        if start as usize + values.len() > TABLE_POINTS {
            return Err(TableError::TooMany);
        }
        if values
            .iter()
            .any(|v| !v.is_finite() || *v > TABLE_MAX_COUNTS || *v < -TABLE_MAX_COUNTS)
        {
            return Err(TableError::BadValue);
        }
        let mut u = if start == 0 {
            Upload {
                corr_next: self.corr_next,
                ..Upload::default()
            }
        } else {
            *self
        };
        for v in values {
            if u.ref_next == 0 {
                (u.first, u.last, u.min, u.max) = (*v, *v, *v, *v);
            } else {
                let chord = abs(*v - u.last);
                u.max_chord = u.max_chord.max(chord);
                u.min = u.min.min(*v);
                u.max = u.max.max(*v);
                u.last = *v;
            }
            u.ref_next += 1;
        }
        *self = u;
        Ok(())
    }

    /// The reference's first point from `origin` \[1/65536 count\] (as written).
    pub fn start(&self, origin: i64) -> SubCounts {
        to_sub(origin, self.first)
    }

    /// Checks a block of the correction from `start` (\[N·m\], each within `torque_max`) for a
    /// table of `points`.
    pub fn write_corr(
        &mut self,
        start: u32,
        values: &[f32],
        points: u32,
        torque_max: f32,
    ) -> Result<(), TableError> {
        if start != 0 && start != self.corr_next {
            return Err(TableError::OutOfOrder);
        }
        if start as usize + values.len() > points as usize {
            return Err(TableError::TooMany);
        }
        if values
            .iter()
            .any(|v| !v.is_finite() || *v > torque_max || *v < -torque_max)
        {
            return Err(TableError::BadValue);
        }
        self.corr_next = start + values.len() as u32;
        Ok(())
    }

    /// Checks the reference written as a whole for `g` at `rate` \[Hz\] with an encoder of
    /// `rpc` \[rad/count\] and soft limits `(min, max)` \[counts\]: whole, continuous (no chord
    /// beyond `vmax` \[rad/s\], the closing one included), within the limits.
    pub fn check_set(
        &self,
        g: &Geometry,
        rate: f32,
        rpc: f32,
        vmax: f32,
        (min, max): (i64, i64),
    ) -> Result<(), TableError> {
        let period_s = g.period_steps() as f32 / rate;
        if g.points < 4
            || g.points as usize > TABLE_POINTS
            || g.steps == 0
            || !matches!(
                period_s.partial_cmp(&TABLE_MAX_PERIOD_S),
                Some(core::cmp::Ordering::Less | core::cmp::Ordering::Equal)
            )
        {
            return Err(TableError::BadGeometry);
        }
        if self.ref_next != g.points {
            return Err(TableError::NotWhole);
        }
        let chord = self.max_chord.max(abs(self.first - self.last));
        if chord * rpc * rate / g.steps as f32 > vmax {
            return Err(TableError::TooFast);
        }
        let lo = g.origin.saturating_add(floor(self.min));
        let hi = g.origin.saturating_add(ceil(self.max));
        if lo < min || hi > max {
            return Err(TableError::OutOfStroke);
        }
        Ok(())
    }
}

fn abs(x: f32) -> f32 {
    if x < 0.0 { -x } else { x }
}

fn floor(x: f32) -> i64 {
    let i = x as i64;
    if (i as f32) > x { i - 1 } else { i }
}

fn ceil(x: f32) -> i64 {
    let i = x as i64;
    if (i as f32) < x { i + 1 } else { i }
}
