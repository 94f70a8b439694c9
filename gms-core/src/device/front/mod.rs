//! The protocol half of the device core: what `set`, `move`, `save`, `status`, `stream` and
//! the rest do, whatever carries the bytes.

use core::fmt::{self, Write};

mod device;

mod table;

use super::{ParamStore, decode_settings, encode_settings, prepare};
use crate::control::reference::{MOVE_AMAX, Motion, SUB_PER_COUNT, Sweep, VelocityProfile};
use crate::drive;
use crate::protocol::{self, Device, Settings};

use super::{
    Board, CaptureRequest, CaptureSpec, CaptureState, Chunk, CtrlBuf, Drive, FIELDS, FrfRequest,
    MAP_WRITE_BINS, MAX_STREAM_HZ, Mailbox, MapRequest, MoveRequest, Requests, RequestsBuf, Sample,
    Staged, Status, StatusReply, VelocityRequest, capture_fields,
};

use crate::control::frf::{Channel, FrfSpec, Injection};
use crate::control::table::{
    TABLE_WRITE_VALUES, TableError, TableReport, TableRequest, TableState, Upload, Which,
};

use crate::protocol::TableCmd;

/// The longest frequency-response measurement \[s\] (settling and summing).
pub const FRF_MAX_S: f32 = 600.0;

/// How the protocol side reaches the loop.
pub trait LoopLink {
    /// Runs `f` on the mailbox, atomically with respect to the loop (a critical section on a
    /// board, a mutex on a host); `f` only copies.
    fn with_mailbox<R>(&mut self, f: impl FnOnce(&mut Mailbox) -> R) -> R;
    /// A monotonic time \[us\], for waiting on the loop.
    fn now_us(&self) -> u64;
    /// Lets the loop run for a moment while waiting (nothing where the loop is an interrupt
    /// that preempts the caller; a short sleep where it is a thread).
    fn pause(&mut self);
    /// How long to wait for the loop to take a request before giving up \[us\].
    fn timeout_us(&self) -> u64 {
        50_000
    }
    /// The motor supply divider's latest ADC code \[code\] ([`Board::supply`]): 0 where the
    /// board has none or before its first conversion. Read in thread mode (a board's ADC
    /// data register, which the control step's conversion keeps current): the control step
    /// carries nothing for it.
    fn supply_code(&mut self) -> u32 {
        0
    }
}

/// The protocol side of a device: implements [`Device`] over a [`LoopLink`] to the loop and a
/// [`ParamStore`].
pub struct Front<L: LoopLink, S: ParamStore> {
    link: L,
    store: S,
    board: Board,
    settings: Settings,
    defaults: Settings,
    staged: Option<Settings>,
    fields: [u8; FIELDS.len()],
    nfields: usize,
    /// The running settings were set for this axis (stored, set, or given by the shell).
    configured: bool,
    /// `defaults` configures the axis (a simulator's defaults describe its plant).
    defaults_configured: bool,
    /// The loop has a table motion's buffer.
    has_table: bool,
    /// The table being written, as checked so far.
    upload: Upload,
    /// The requests' storage and the spare controller's, while not with the loop.
    bufs: Bufs,
    /// The last frequency-response report read whole ([`read_frf`]).
    frf: crate::control::frf::FrfReport,
    /// Why the board must not drive at all, found at start ([`Front::refusing_to_drive`]).
    no_drive: Option<&'static str>,
    /// The motor supply measured \[V\] (filtered), the time of its last reading \[µs\], and the
    /// value last handed to the loop ([`Front::supervise`]).
    supply: Option<(f32, u64)>,
    supply_posted: Option<f32>,
    /// On a board without a supply divider: `lim.v_supply` came from the store, the shell,
    /// a `set` of it or a change by `commit`, so `enable` may trust it.
    supply_confirmed: bool,
}

/// Loop pauses `enable` waits at most for the supply's first reading (each a period or more).
const SUPPLY_WAIT_PAUSES: u32 = 100;

/// The protocol side's share of the storage the two halves hand each other: the requests'
/// (while not posted or with the loop) and the spare controller's (where the next parameter
/// set is built, outside the control interrupt).
#[derive(Debug)]
struct Bufs {
    req: Option<RequestsBuf>,
    spare: Option<CtrlBuf>,
}

impl Bufs {
    /// The requests' storage back from the loop, if the protocol side does not hold it.
    fn reclaim<L: LoopLink>(&mut self, link: &mut L) {
        if self.req.is_none() {
            self.req = link.with_mailbox(|m| m.returned.take());
        }
    }

    /// The requests' storage, emptied: the protocol side's own, or the one the loop gave
    /// back (its controller kept as the spare).
    fn requests<L: LoopLink>(&mut self, link: &mut L) -> Result<RequestsBuf, &'static str> {
        self.reclaim(link);
        let buf = self.req.take().ok_or("control loop not responding")?;
        Ok(self.recycle(buf))
    }

    /// The spare controller's storage (reclaimed with the requests the loop gave back, if
    /// it came with them).
    fn spare<L: LoopLink>(&mut self, link: &mut L) -> Result<CtrlBuf, &'static str> {
        if self.spare.is_none() {
            let buf = self.requests(link)?;
            self.req = Some(buf);
        }
        self.spare.take().ok_or("control loop not responding")
    }

    /// The chunk the loop wrote into the requests it acted on last (a read's answer; a copy,
    /// in the protocol side's time).
    fn chunk<L: LoopLink>(&mut self, link: &mut L) -> Chunk {
        self.reclaim(link);
        self.req.as_ref().map_or_else(Chunk::default, |r| r.chunk)
    }

    /// Empties `buf`, keeping the controller it carries (the old one after a swap, or one
    /// never taken) as the spare.
    fn recycle(&mut self, buf: RequestsBuf) -> RequestsBuf {
        if let Some(a) = buf.apply.take() {
            self.spare = Some(a.ctrl);
        }
        *buf = Requests::new();
        buf
    }
}

impl<L: LoopLink, S: ParamStore> Front<L, S> {
    /// The protocol side of a device running `settings` (what [`super::startup()`] chose), with
    /// `defaults` for `defaults` and `load`; `req` is the storage of the requests it posts,
    /// `spare` that of the controllers it builds (the loop runs its own, given to
    /// [`super::ControlLoop::new`]).
    pub fn new(
        link: L,
        store: S,
        board: Board,
        settings: Settings,
        defaults: Settings,
        req: RequestsBuf,
        spare: CtrlBuf,
    ) -> Self {
        Front {
            bufs: Bufs {
                req: Some(req),
                spare: Some(spare),
            },
            link,
            store,
            board,
            settings,
            defaults,
            staged: None,
            fields: [0; FIELDS.len()],
            nfields: 0,
            configured: false,
            defaults_configured: false,
            has_table: false,
            upload: Upload::default(),
            frf: crate::control::frf::FrfReport::default(),
            no_drive: None,
            supply: None,
            supply_posted: None,
            supply_confirmed: false,
        }
    }

    /// The protocol side of a loop given a table motion's buffer
    /// ([`super::ControlLoop::with_table`]): the `table` commands act (without, they are
    /// refused).
    pub fn with_table(mut self) -> Self {
        self.has_table = true;
        self
    }

    /// Whether the running settings were configured for the axis (`running`: [`super::Startup`]'s
    /// `configured` on a board) and whether the `defaults` are (`defaults`: true on a simulator,
    /// whose defaults come from its plant; false on a board, whose defaults are the paper's
    /// rig). Any `set`, `commit` or `load` configures it; `defaults` sets it to `defaults`.
    /// The status reply reports it (`configured=0|1`), so that a bench tool can refuse to
    /// measure an axis in units nobody chose.
    pub fn with_configured(mut self, running: bool, defaults: bool) -> Self {
        self.configured = running;
        self.defaults_configured = defaults;
        self.supply_confirmed = running;
        self
    }

    /// A reason found at start why this board must not drive (its brown-out reset not at
    /// 2.7 V, say): `enable` and `enable current` answer it as their `err 8` reason, and
    /// nothing else changes. `None` (the default) refuses nothing.
    pub fn refusing_to_drive(mut self, why: Option<&'static str>) -> Self {
        self.no_drive = why;
        self
    }

    /// The start's refusal to drive, if any ([`Front::refusing_to_drive`]).
    fn may_drive(&self) -> Result<(), &'static str> {
        match self.no_drive {
            Some(why) => Err(why),
            None => Ok(()),
        }
    }

    /// The motor supply, where the board has a divider (thread mode: the control step has
    /// no room for it): the loop's latest divider code in volts, filtered over
    /// [`SUPPLY_TAU_S`](crate::device::SUPPLY_TAU_S) of the calls' own times (the first
    /// reading at once); handed to the loop when it moved by more than 0.5 % since the last
    /// (its current loop's duty follows it); while driving outside the bridge's range,
    /// `supply` latched (the loop switches off). Called at each request that may drive and
    /// by the shell's periodic tick. A refused hand-over (a lost loop) changes nothing.
    pub fn supervise(&mut self) {
        let Some(ss) = self.board.supply else {
            return;
        };
        let code = self.link.supply_code();
        if code == 0 {
            return;
        }
        let st = self.status_now();
        let v = ss.volts(code, self.board.sense.vref, self.board.sense.full_scale);
        let now = self.link.now_us();
        let f = match self.supply {
            Some((f, at)) => {
                let dt = now.saturating_sub(at) as f32 * 1e-6;
                f + (dt / crate::device::SUPPLY_TAU_S).min(1.0) * (v - f)
            }
            None => v,
        };
        self.supply = Some((f, now));
        if st.enabled && !ss.within(f) {
            let _ = self.post(|r| r.latch = crate::drive::Faults::SUPPLY);
        } else if self
            .supply_posted
            .is_none_or(|p| (f / p - 1.0).abs() > 0.005)
            && self.post(|r| r.supply_v = Some(f)).is_ok()
        {
            self.supply_posted = Some(f);
        }
    }

    /// The motor supply measured \[V\] ([`Front::supervise`]), none without a divider or
    /// before its first reading.
    pub fn supply_v(&self) -> Option<f32> {
        self.supply.map(|s| s.0)
    }

    /// Refuses to drive when the board measures its supply outside the bridge's range (or
    /// has no reading yet).
    fn supply_in_range(&mut self) -> Result<(), &'static str> {
        let Some(ss) = self.board.supply else {
            // Nothing measures it: the duty is worked out for `lim.v_supply`, which a 24 V
            // supply under the 12 V default would make twice the loop's gain.
            return if self.supply_confirmed {
                Ok(())
            } else {
                Err("this board does not measure its motor supply: set lim.v_supply first")
            };
        };
        // Right after the start the loop may not have published a reading yet: a few
        // periods' wait for its first.
        for _ in 0..SUPPLY_WAIT_PAUSES {
            if self.link.supply_code() != 0 {
                break;
            }
            self.link.pause();
        }
        self.supervise();
        match self.supply_v() {
            Some(v) if ss.within(v) => Ok(()),
            Some(v) if v < ss.range_v.0 => Err("motor supply below the bridge's range"),
            Some(_) => Err("motor supply above the bridge's range"),
            None => Err("motor supply not measured yet"),
        }
    }

    /// The loop's latest status.
    pub fn status_now(&mut self) -> Status {
        self.link.with_mailbox(|m| m.status)
    }

    /// Refuses to drive when the current sense cannot see the current the loop may command:
    /// from the zero start-up calibration found, the amplifier's linear range reaches less
    /// than `lim.i_max` (the loop's over-current trip, at most 0.95 of that reach, would
    /// then sit below currents the loop commands, or be out of reach).
    fn sense_reaches_i_max(&mut self) -> Result<(), &'static str> {
        let zero = self.status_now().sense_offset;
        let v_per_a = self.settings.sense_v_per_a;
        let reach = self.board.sense.reach(zero, v_per_a);
        // Within a code (the ADC's resolution, and the calibrated zero's noise): a sense whose
        // range is the current limit itself (the simulator's) reaches it.
        let code = self.board.sense.amps_per_code(v_per_a);
        if reach + code < self.settings.i_max {
            return Err("lim.i_max beyond what the current sense reaches from its zero");
        }
        Ok(())
    }

    /// The link (for the shell's own use of the mailbox).
    pub fn link_mut(&mut self) -> &mut L {
        &mut self.link
    }

    /// The link and the store back (the device is gone: a power cycle, a shell shutting down).
    pub fn into_parts(self) -> (L, S) {
        (self.link, self.store)
    }

    /// The store.
    pub fn store_mut(&mut self) -> &mut S {
        &mut self.store
    }

    /// True while a telemetry stream is on.
    pub fn streaming(&self) -> bool {
        self.nfields > 0
    }

    /// The client went away: its stream ends (a new client starts without one).
    pub fn disconnected(&mut self) {
        let _ = self.stream_off();
        // A frequency response ends with its link (the position loop goes on); a table run
        // at the end of its period (the reference holds at the table's start).
        let _ = self.frf_off();
        if self.has_table {
            let _ = self.post(|r| r.table = Some(TableRequest::Stop));
        }
        // An experiment (current or speed) ends with its link: the bridge goes off. A held
        // position or a move goes on.
        if self.status_now().drive != Drive::Position {
            let _ = self.disable();
        }
    }

    /// Posts requests and waits until the loop has taken them and published a status after
    /// them, so that a reply and the status after it agree. If the loop does not take them
    /// within the link's timeout they are withdrawn and nothing changes.
    fn post(&mut self, f: impl FnOnce(&mut Requests)) -> Result<(), &'static str> {
        post_on(&mut self.link, &mut self.bufs, f)
    }

    /// Writes rows `start..end` that the loop copies into the mailbox's chunk (`ask` puts the
    /// request for the rows from `at`, `max` at most), one a line, values comma-separated;
    /// `missing` when a chunk does not come.
    fn write_chunks(
        &mut self,
        (start, end): (u32, u32),
        ask: impl Fn(&mut Requests, u32, u32),
        missing: &'static str,
        out: &mut dyn Write,
    ) -> Result<(), &'static str> {
        let mut at = start;
        while at < end {
            self.post(|r| ask(r, at, end - at))?;
            let c = self.bufs.chunk(&mut self.link);
            if c.start != at || c.samples == 0 {
                return Err(missing);
            }
            let n = c.nfields as usize;
            for s in 0..c.samples as usize {
                let row = c.values.get(s * n..(s + 1) * n).unwrap_or(&[]);
                protocol::write_row(out, row).map_err(|_| "reply too long")?;
            }
            at += c.samples;
        }
        Ok(())
    }

    /// Stores the loop's position map (read from it in chunks into the store's map buffer)
    /// beside the parameter record; nothing when the store keeps no map or the loop has none.
    fn save_map(&mut self) -> Result<(), &'static str> {
        let (bins, period) = (self.settings.map.bins as u32, self.settings.map.period);
        let Front {
            link, store, bufs, ..
        } = self;
        let Some(buf) = store.map_buffer() else {
            return Ok(());
        };
        let mut at = 0;
        while at < bins {
            post_on(link, bufs, |r| {
                r.map = Some(MapRequest::Read {
                    start: at,
                    max: bins - at,
                })
            })?;
            let c = bufs.chunk(link);
            if c.start != at || c.samples == 0 || c.nfields != 2 {
                // A loop without a table: nothing to keep.
                return Ok(());
            }
            for (k, v) in c.values.iter().enumerate().take(2 * c.samples as usize) {
                crate::control::posmap::map_record_put(buf, 2 * at as usize + k, *v);
            }
            at += c.samples;
        }
        let len = crate::control::posmap::map_record_finish(period, bins, buf);
        store
            .save_map(len)
            .map_err(|_| "store write failed (the map)")
    }

    /// Loads the stored position map into the loop's table (the settings' geometry; checked
    /// whole first, then written in pieces while the bridge is off); nothing when none is
    /// stored. A map of another period or bin count is refused with the reason.
    fn load_map(&mut self) -> Result<(), &'static str> {
        let p = self.settings.map;
        let Front {
            link, store, bufs, ..
        } = self;
        let len = match store.load_map() {
            Ok(Some(len)) => len,
            Ok(None) => return Ok(()),
            Err(_) => return Err("stored map unreadable"),
        };
        let Some(buf) = store.map_buffer() else {
            return Ok(());
        };
        let rec = buf.get(..len).ok_or("stored map: wrong length")?;
        crate::control::posmap::decode_map(rec, &p, &mut [])
            .map_err(crate::control::posmap::MapRecordError::reason)?;
        let bins = p.bins as usize;
        let mut start = 0;
        while start < bins {
            let n = (bins - start).min(MAP_WRITE_BINS);
            let mut values = [0.0f32; 2 * MAP_WRITE_BINS];
            for (k, v) in values.iter_mut().enumerate().take(2 * n) {
                *v = crate::control::posmap::map_record_value(rec, 2 * start + k);
            }
            post_on(link, bufs, |r| {
                r.map = Some(MapRequest::Write {
                    start: start as u32,
                    n: n as u32,
                    values,
                })
            })?;
            start += n;
        }
        Ok(())
    }

    /// One telemetry line (`# t=… pos=…\n`) of the fields streamed, SI units.
    pub fn telemetry_line(&self, out: &mut impl Write, s: &Sample) -> fmt::Result {
        let rpc = self.settings.rad_per_count();
        let fields = self.fields.get(..self.nfields).unwrap_or(&[]);
        let pairs = fields.iter().map(|&f| {
            let v = match f {
                0 => (s.steps as f64 / self.settings.pos_rate_hz as f64) as f32,
                1 => (s.pos as f64 * rpc as f64) as f32,
                2 => (s.reference as f64 / SUB_PER_COUNT as f64 * rpc as f64) as f32,
                3 => s.error,
                4 => s.ff,
                5 => s.current,
                6 => s.friction,
                _ => s.friction_true,
            };
            (FIELDS.get(f as usize).copied().unwrap_or("?"), v)
        });
        protocol::write_telemetry(out, pairs)
    }
}

/// Reads of the loop's frequency-response report before [`read_frf`] gives up.
const FRF_READS: usize = 4;

/// The loop's frequency-response report, copied a part at a time (each part a short hold of
/// the mailbox: the whole report under one held the firmware's loop off 164 instructions in
/// `rehost check`), and read again while the loop published another between the first part
/// and the last. `None` after [`FRF_READS`] reads that each saw a new report (the loop
/// publishes one per group of whole periods of the sine, many steps apart; the caller keeps
/// its last whole read).
fn read_frf<L: LoopLink>(link: &mut L) -> Option<crate::control::frf::FrfReport> {
    let mut f = crate::control::frf::FrfReport::default();
    for _ in 0..FRF_READS {
        let seq = link.with_mailbox(|m| m.frf_seq);
        for part in 0..crate::control::frf::FrfReport::PARTS {
            link.with_mailbox(|m| f.copy_part(&m.frf, part));
        }
        if link.with_mailbox(|m| m.frf_seq) == seq {
            return Some(f);
        }
    }
    None
}

/// [`Front::post`] on a link: the requests `f` fills in (in the protocol side's storage)
/// posted by reference, and the wait until the loop has taken them; withdrawn ones come back
/// to `bufs`.
fn post_on<L: LoopLink>(
    link: &mut L,
    bufs: &mut Bufs,
    f: impl FnOnce(&mut Requests),
) -> Result<(), &'static str> {
    let buf = bufs.requests(link)?;
    f(buf);
    link.with_mailbox(|m| m.post(buf));
    match wait_taken(link) {
        Ok(()) => Ok(()),
        Err((why, withdrawn)) => {
            if let Some(b) = withdrawn {
                let b = bufs.recycle(b);
                bufs.req = Some(b);
            }
            Err(why)
        }
    }
}

/// The wait of [`Front::post`], one copy for every request (not generic over the requests:
/// the firmware's flash). On a timeout, the requests withdrawn if the loop has not taken
/// them.
fn wait_taken<L: LoopLink>(link: &mut L) -> Result<(), (&'static str, Option<RequestsBuf>)> {
    let t0 = link.now_us();
    let timeout = link.timeout_us();
    loop {
        let (pending, taken, steps) =
            link.with_mailbox(|m| (m.posted(), m.taken_at, m.status.steps));
        if !pending && steps > taken {
            return Ok(());
        }
        if link.now_us().saturating_sub(t0) > timeout {
            return match link.with_mailbox(|m| m.requests.take()) {
                Some(b) => Err(("control loop not responding", Some(b))),
                None => Ok(()),
            };
        }
        link.pause();
    }
}
