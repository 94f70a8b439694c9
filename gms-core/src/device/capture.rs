//! The capture buffer: chosen fields recorded at the position-loop rate (or every N-th step)
//! into RAM from a trigger, then read back over the protocol in chunks — the bench
//! identification's data, at rates the 1 kHz ASCII stream cannot carry (like ODrive's
//! oscilloscope). The buffer is the shell's (a static on the board, a heap block in the
//! simulator); the loop owns it while recording.

/// Fields one capture records at most.
pub const CAPTURE_FIELDS: usize = 4;
use crate::control::chunk::{CHUNK_VALUES, Chunk};
use crate::math::i64_to_f32;
use crate::protocol::CaptureState;

/// The fields a capture may record (the telemetry's, without the simulator's truth): time
/// since the trigger \[s\], position and reference since the trigger \[rad\], error \[rad\],
/// feedforward and estimated friction [N·m], current \[A\], the bridge voltage commanded
/// (duty × supply) \[V\], and the current's and the voltage's means over the `every` steps a
/// sample stands for \[A, V\] (`current` and `volts` are that step's alone: decimated, a
/// current or a voltage that ripples at the encoder's count rate aliases into its mean;
/// `current_mean` and `volts_mean` are the boxcar's, every PWM period counted: with the
/// current loop faster than the position loop, the periods between position steps too), and
/// the mean of the measured current's sign over the same periods \[-1, 1\] (`sign_mean`: the
/// share of the time a bridge's dead time takes its voltage one way less the other's, when a
/// loop swings the current through zero faster than a capture can sample it).
pub const CAPTURE_NAMES: [&str; 11] = [
    "t",
    "pos",
    "ref",
    "error",
    "ff",
    "current",
    "friction",
    "volts",
    "current_mean",
    "volts_mean",
    "sign_mean",
];

/// The index in [`CAPTURE_NAMES`] of the field `name`.
pub fn capture_field(name: &str) -> Option<u8> {
    // A match rather than a search of the table: the no-panic link check could not see
    // through the search.
    match name {
        "t" => Some(0),
        "pos" => Some(1),
        "ref" => Some(2),
        "error" => Some(3),
        "ff" => Some(4),
        "current" => Some(5),
        "friction" => Some(6),
        "volts" => Some(7),
        "current_mean" => Some(8),
        "volts_mean" => Some(9),
        "sign_mean" => Some(10),
        _ => None,
    }
}

/// The field indexes of a comma-separated list of names (at most [`CAPTURE_FIELDS`]). The
/// list is cut at the commas by hand: `str::split`'s searcher keeps a panic path that the
/// no-panic link check cannot see through here.
pub fn capture_fields(list: &str) -> Result<([u8; CAPTURE_FIELDS], u8), &'static str> {
    let mut idx = [0u8; CAPTURE_FIELDS];
    let mut n = 0usize;
    let bytes = list.as_bytes();
    let mut start = 0usize;
    let mut at = 0usize;
    while at <= bytes.len() {
        let end_of_name = at == bytes.len() || bytes.get(at) == Some(&b',');
        if end_of_name {
            let name = list.get(start..at).unwrap_or("");
            let i = capture_field(name).ok_or(
                "unknown field (t, pos, ref, error, ff, current, friction, volts, current_mean, \
                 volts_mean, sign_mean)",
            )?;
            let slot = idx.get_mut(n).ok_or("at most 4 fields")?;
            *slot = i;
            n += 1;
            start = at + 1;
        }
        at += 1;
    }
    Ok((idx, n as u8))
}

/// What a capture records.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct CaptureSpec {
    /// Indexes into [`CAPTURE_NAMES`], `nfields` of them used.
    pub fields: [u8; CAPTURE_FIELDS],
    /// Fields used.
    pub nfields: u8,
    /// One sample every this many position steps (`>= 1`).
    pub every: u32,
    /// Samples to record.
    pub samples: u32,
    /// Start at the next experiment request (`current`, `velocity`, `move`, `hold`) instead
    /// of at once.
    pub on_next: bool,
}

impl Default for Chunk {
    fn default() -> Chunk {
        Chunk::new(0, 0)
    }
}

/// One step's values of every field, in [`CAPTURE_NAMES`] order (SI; positions relative to
/// the trigger are made here).
#[derive(Debug, Clone, Copy, Default)]
pub struct StepValues {
    /// Position step number.
    pub steps: u64,
    /// Position step period \[s\].
    pub dt: f32,
    /// Encoder position \[counts\].
    pub pos: i64,
    /// Reference position [1/65536 count].
    pub reference: i64,
    /// Encoder resolution [rad/count].
    pub rad_per_count: f32,
    /// Error \[rad\].
    pub error: f32,
    /// Feedforward [N·m].
    pub ff: f32,
    /// Current \[A\].
    pub current: f32,
    /// Estimated friction [N·m].
    pub friction: f32,
    /// The bridge voltage commanded \[V\] (0 while off).
    pub volts: f32,
    /// The current summed over the PWM periods since the last position step \[A\] (with the
    /// current loop faster than the position loop, `current` is one of them).
    pub current_period: f32,
    /// The bridge voltage summed over those periods \[V\].
    pub volts_period: f32,
    /// The measured current's sign summed over those periods \[-\] (+1 at +0 A).
    pub sign_period: f32,
    /// How many periods the sums hold.
    pub periods: u32,
}

/// A capture in progress over a buffer of `B`.
#[derive(Debug)]
pub struct Capture<B: AsRef<[f32]> + AsMut<[f32]>> {
    buf: B,
    spec: CaptureSpec,
    state: CaptureState,
    count: u32,
    skip: u32,
    t0: u64,
    pos0: i64,
    /// The current \[A\], the voltage \[V\] and the current's sign \[-\] summed over the
    /// PWM periods of the steps since the last sample, and their number.
    sum: (f32, f32, f32, u32),
}

impl<B: AsRef<[f32]> + AsMut<[f32]>> Capture<B> {
    /// An idle capture over `buf`.
    pub fn new(buf: B) -> Self {
        Capture {
            buf,
            spec: CaptureSpec::default(),
            state: CaptureState::Idle,
            count: 0,
            skip: 0,
            t0: 0,
            pos0: 0,
            sum: (0.0, 0.0, 0.0, 0),
        }
    }

    /// The buffer's size (values).
    pub fn capacity(&self) -> usize {
        self.buf.as_ref().len()
    }

    /// Where it is and how many samples it holds.
    pub fn state(&self) -> (CaptureState, u32) {
        (self.state, self.count)
    }

    /// Whether the capture is armed or recording (the loop's period sums are wanted).
    pub fn active(&self) -> bool {
        matches!(self.state, CaptureState::Armed | CaptureState::Recording)
    }

    /// The encoder position at the trigger \[counts\] (the origin of `pos` and `ref`).
    pub fn origin(&self) -> i64 {
        self.pos0
    }

    /// Arms `spec` (checked by the caller against [`Capture::capacity`]; a spec that does not
    /// fit is cut to what fits); armed at once unless `on_next`.
    pub fn arm(&mut self, mut spec: CaptureSpec) {
        let n = if spec.nfields == 0 {
            1
        } else if spec.nfields as usize > CAPTURE_FIELDS {
            CAPTURE_FIELDS
        } else {
            spec.nfields as usize
        };
        spec.nfields = n as u8;
        spec.every = spec.every.max(1);
        // n is 1 to CAPTURE_FIELDS: checked_div only to keep a panic path out of sight.
        let fit = self.capacity().checked_div(n).unwrap_or(0) as u32;
        spec.samples = spec.samples.min(fit);
        self.spec = spec;
        self.count = 0;
        self.skip = 0;
        self.state = CaptureState::Armed;
    }

    /// Back to idle (the data is dropped).
    pub fn off(&mut self) {
        self.state = CaptureState::Idle;
        self.count = 0;
    }

    /// An experiment request arrived: an armed `on_next` capture starts.
    pub fn experiment_started(&mut self) {
        if self.state == CaptureState::Armed && self.spec.on_next {
            self.spec.on_next = false;
        }
    }

    /// One position step: starts an armed capture whose trigger has come, records when due.
    pub fn step(&mut self, v: &StepValues) {
        if self.state == CaptureState::Armed && !self.spec.on_next {
            self.state = CaptureState::Recording;
            self.t0 = v.steps;
            self.pos0 = v.pos;
            self.skip = 0;
            self.sum = (0.0, 0.0, 0.0, 0);
        }
        if self.state != CaptureState::Recording {
            return;
        }
        self.sum = (
            self.sum.0 + v.current_period,
            self.sum.1 + v.volts_period,
            self.sum.2 + v.sign_period,
            self.sum.3.saturating_add(v.periods),
        );
        if self.skip > 0 {
            self.skip -= 1;
            return;
        }
        self.skip = self.spec.every - 1;
        // In f32 from integer differences: no f64 (soft-float on the M4F, and hoisted out of
        // the loop below by the optimiser whether a field asks for it or not: 150
        // instructions a sample, which overran the 40 kHz step on the image). The counts
        // since the trigger are exact in f32 up to 2^24; the reference's sub-counts split
        // into whole counts and a fraction so that neither loses what the f32 result keeps.
        let rpc = v.rad_per_count;
        let (bits, sub) = (
            crate::control::reference::SUB_BITS,
            crate::control::reference::SUB_PER_COUNT,
        );
        let n = self.spec.nfields as usize;
        let at = self.count as usize * n;
        let (fields, t0, pos0) = (self.spec.fields, self.t0, self.pos0);
        // At least this step is in the sum.
        let per = 1.0 / self.sum.3.max(1) as f32;
        let (mean, volts_mean, sign_mean) = (self.sum.0 * per, self.sum.1 * per, self.sum.2 * per);
        self.sum = (0.0, 0.0, 0.0, 0);
        let buf = self.buf.as_mut();
        for (k, &f) in fields.iter().take(n).enumerate() {
            let x = match f {
                0 => i64_to_f32(v.steps.saturating_sub(t0).min(i64::MAX as u64) as i64) * v.dt,
                1 => i64_to_f32(v.pos.saturating_sub(pos0)) * rpc,
                2 => {
                    let d = v.reference.saturating_sub(pos0.saturating_mul(1 << bits));
                    let (whole, frac) = (d >> bits, d & ((1 << bits) - 1));
                    (i64_to_f32(whole) + i64_to_f32(frac) / sub) * rpc
                }
                3 => v.error,
                4 => v.ff,
                5 => v.current,
                6 => v.friction,
                7 => v.volts,
                8 => mean,
                9 => volts_mean,
                _ => sign_mean,
            };
            if let Some(slot) = buf.get_mut(at + k) {
                *slot = x;
            }
        }
        self.count += 1;
        if self.count >= self.spec.samples {
            self.state = CaptureState::Done;
        }
    }

    /// The recorded samples from `start`, as many as a chunk holds and at most `max`.
    pub fn read(&self, start: u32, max: u32) -> Chunk {
        let mut c = Chunk::default();
        self.read_into(start, max, &mut c);
        c
    }

    /// [`Capture::read`] into `c` in place (the requests' storage: nothing copied after).
    pub fn read_into(&self, start: u32, max: u32, c: &mut Chunk) {
        let n = self.spec.nfields.max(1) as usize;
        let avail = self.count.saturating_sub(start);
        let per_chunk = CHUNK_VALUES.checked_div(n).unwrap_or(0) as u32;
        let samples = avail.min(max).min(per_chunk);
        c.restart(start, n as u8);
        c.samples = samples;
        let from = start as usize * n;
        let len = samples as usize * n;
        // One slice copy (a memcpy: a full chunk of 128 values cost ~500 instructions as an
        // element loop, and overran the 40 kHz step that takes the request on the image).
        let src = self.buf.as_ref().get(from..).unwrap_or(&[]);
        let len = len.min(src.len()).min(c.values.len());
        if let (Some(d), Some(s)) = (c.values.get_mut(..len), src.get(..len)) {
            d.copy_from_slice(s);
        }
    }

    /// The spec armed last.
    pub fn spec(&self) -> CaptureSpec {
        self.spec
    }
}
