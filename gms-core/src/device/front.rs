//! The protocol half of the device core: what `set`, `move`, `save`, `status`, `stream` and
//! the rest do, whatever carries the bytes.

use core::fmt::{self, Write};

use super::RECORD_LEN;
use crate::control::reference::{MOVE_AMAX, Motion, SUB_PER_COUNT, Sweep, VelocityProfile};
use crate::drive::{self, Faults};
use crate::protocol::{self, Device, Settings};

use super::{
    Applied, Board, CaptureRequest, CaptureSpec, CaptureState, Chunk, Ctrl, CtrlBuf, Drive, FIELDS,
    FrfRequest, MAP_WRITE_BINS, MAX_STREAM_HZ, Mailbox, MapRequest, MoveRequest, Requests,
    RequestsBuf, Sample, Staged, Status, StatusReply, VelocityRequest, capture_fields,
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
}

/// Why the parameter store failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum StoreError {
    /// The flash (or its file) or the storage layer reported an error.
    Flash,
    /// The stored item is not one record long.
    Length,
}

/// Where the parameter record lives (the board's flash, a file that stands for it).
pub trait ParamStore {
    /// Stores a record, replacing the last (the old one stays valid until the new is whole).
    fn save(&mut self, rec: &[u8; RECORD_LEN]) -> Result<(), StoreError>;
    /// The last record stored, `None` if nothing was ever saved.
    fn load(&mut self) -> Result<Option<[u8; RECORD_LEN]>, StoreError>;
    /// Where a position map's record is put together before [`ParamStore::save_map`] and
    /// found after [`ParamStore::load_map`] (`None`: this store keeps no map).
    fn map_buffer(&mut self) -> Option<&mut [u8]> {
        None
    }
    /// Stores the map record in the first `len` bytes of the map buffer, replacing the last
    /// (the old one stays valid until the new one is whole).
    fn save_map(&mut self, len: usize) -> Result<(), StoreError> {
        let _ = len;
        Err(StoreError::Flash)
    }
    /// The last map record stored, into the map buffer: its length, `None` if none.
    fn load_map(&mut self) -> Result<Option<usize>, StoreError> {
        Ok(None)
    }
}

/// The loop's parameter set for `s` on `board`: the controller, the limits and the PWM timing;
/// the error says why the board cannot run it.
pub fn prepare(s: &Settings, board: &Board) -> Result<Applied, &'static str> {
    let ctrl = Ctrl::try_new(*s).map_err(|_| "the parameter set is invalid")?;
    let (psc, arr) = drive::pwm_timing(board.pwm_timer_hz, s.cur_rate_hz, board.pwm_max_arr)
        .ok_or("the board's PWM timer cannot run rate.cur_hz")?;
    let window = board.sense.window_s;
    if window > 0.0 && window > 2.0 * (1.0 - board.limits.budget_fraction) / s.cur_rate_hz {
        return Err("the board's current sense cannot sample at rate.cur_hz");
    }
    Ok(Applied {
        ctrl,
        limits: board.limits(s),
        psc,
        arr,
    })
}

/// What a device starts with.
#[derive(Debug, Clone)]
pub struct Startup {
    /// The settings that run.
    pub settings: Settings,
    /// The loop's set for them.
    pub applied: Applied,
    /// Faults to latch (`invalid_params` when the stored set could not be used).
    pub faults: Faults,
    /// What happened, for the log.
    pub note: &'static str,
    /// True when the settings came from the store (someone configured this axis and saved);
    /// false on the built-in defaults (the status reply's `configured`).
    pub configured: bool,
}

/// The start-up decision: the stored set if it is valid and the board runs it; the defaults
/// and a latched `invalid_params` fault if a stored set is unreadable, invalid or not
/// runnable; the defaults without a fault if nothing was ever saved. `Err` only if the
/// defaults themselves cannot run on `board`. A record of another firmware's parameter table
/// loads what this one knows; `log` gets a line for each setting it clamped, dropped or left
/// at its default ([`super::LoadReport`]).
// Not inlined: the stored record, the decoded set and the loaded report stay in this frame, out
// of the start-up task's poll frame (a task's frame must step the stack by less than the
// board's guard: `cargo xtask check-elf`).
#[inline(never)]
pub fn startup(
    stored: Result<Option<[u8; RECORD_LEN]>, StoreError>,
    defaults: &Settings,
    board: &Board,
    log: &mut dyn FnMut(super::ReportLine),
) -> Result<Startup, &'static str> {
    let fallback = |faults: Faults, note: &'static str| -> Result<Startup, &'static str> {
        Ok(Startup {
            settings: *defaults,
            applied: prepare(defaults, board)?,
            faults,
            note,
            configured: false,
        })
    };
    match stored {
        Ok(None) => fallback(Faults::NONE, "nothing saved: running the defaults"),
        Err(_) => fallback(
            Faults::INVALID_PARAMS,
            "parameter store unreadable: running the defaults",
        ),
        Ok(Some(rec)) => match super::decode_settings(&rec, defaults) {
            Err(_) => fallback(
                Faults::INVALID_PARAMS,
                "stored parameters invalid: running the defaults",
            ),
            Ok(loaded) => match prepare(&loaded.settings, board) {
                // What the record of another firmware clamped, dropped or left at a default,
                // a line each for the log (once the set runs).
                Ok(applied) if !loaded.report.is_clean() => {
                    loaded.report.lines().for_each(&mut *log);
                    Ok(Startup {
                        settings: loaded.settings,
                        applied,
                        faults: Faults::NONE,
                        note: "parameters loaded from the store (of another firmware: what it \
                               clamped, dropped or left at a default is logged)",
                        configured: true,
                    })
                }
                Ok(applied) => Ok(Startup {
                    settings: loaded.settings,
                    applied,
                    faults: Faults::NONE,
                    note: "parameters loaded from the store",
                    configured: true,
                }),
                Err(_) => fallback(
                    Faults::INVALID_PARAMS,
                    "stored parameters not runnable on this board: running the defaults",
                ),
            },
        },
    }
}

/// The start-up's position map: cleared (no effect), then the stored map if there is one for
/// the settings' geometry. Returns what happened, for the log: `Ok(true)` loaded, `Ok(false)`
/// none stored, `Err` why a stored one was not used (the table stays clear). The firmware's
/// and the virtual device's start-up both call it.
pub fn restore_map<S: ParamStore + ?Sized>(
    store: &mut S,
    p: &crate::control::posmap::MapParams,
    table: &mut [f32],
) -> Result<bool, &'static str> {
    crate::control::posmap::clear(table);
    let len = match store.load_map() {
        Ok(Some(len)) => len,
        Ok(None) => return Ok(false),
        Err(_) => return Err("stored map unreadable"),
    };
    let Some(buf) = store.map_buffer() else {
        return Ok(false);
    };
    let rec = buf.get(..len).ok_or("stored map: wrong length")?;
    crate::control::posmap::decode_map(rec, p, table)
        .map_err(crate::control::posmap::MapRecordError::reason)?;
    Ok(true)
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
}

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
    /// The protocol side of a device running `settings` (what [`startup`] chose), with
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
        }
    }

    /// The protocol side of a loop given a table motion's buffer
    /// ([`super::ControlLoop::with_table`]): the `table` commands act (without, they are
    /// refused).
    pub fn with_table(mut self) -> Self {
        self.has_table = true;
        self
    }

    /// Whether the running settings were configured for the axis (`running`: [`Startup`]'s
    /// `configured` on a board) and whether the `defaults` are (`defaults`: true on a simulator,
    /// whose defaults come from its plant; false on a board, whose defaults are the paper's
    /// rig). Any `set`, `commit` or `load` configures it; `defaults` sets it to `defaults`.
    /// The status reply reports it (`configured=0|1`), so that a bench tool can refuse to
    /// measure an axis in units nobody chose.
    pub fn with_configured(mut self, running: bool, defaults: bool) -> Self {
        self.configured = running;
        self.defaults_configured = defaults;
        self
    }

    /// The loop's latest status.
    pub fn status_now(&mut self) -> Status {
        self.link.with_mailbox(|m| m.status)
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

    /// The table motion's last report.
    fn table_report(&mut self) -> TableReport {
        self.link.with_mailbox(|m| m.table)
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

impl<L: LoopLink, S: ParamStore> Device for Front<L, S> {
    fn new_session(&mut self) {
        self.disconnected();
    }

    fn settings(&self) -> &Settings {
        &self.settings
    }

    fn staged(&mut self) -> &mut Option<Settings> {
        &mut self.staged
    }

    fn apply(&mut self, new: Settings) -> Result<(), &'static str> {
        let a = prepare(&new, &self.board)?;
        // The new controller built in the spare storage here, on the protocol side; the loop
        // only swaps it in.
        let ctrl = self.bufs.spare(&mut self.link)?;
        *ctrl = a.ctrl;
        let staged = Staged {
            ctrl,
            limits: a.limits,
            psc: a.psc,
            arr: a.arr,
            taken: false,
        };
        self.post(|r| r.apply = Some(staged))?;
        self.settings = new;
        self.configured = true;
        Ok(())
    }

    // Not inlined, as `startup`: the record in this frame, not the link task's.
    #[inline(never)]
    fn save(&mut self) -> Result<(), &'static str> {
        if self.status_now().enabled {
            return Err("disable before save");
        }
        let rec = super::encode_settings(&self.settings);
        let r = self.store.save(&rec);
        // The position map beside it (a store that keeps one, a loop that has one).
        let m = if r.is_ok() { self.save_map() } else { Ok(()) };
        // A flash write stalls the CPU on a board: the statistics start afresh.
        let _ = self.post(|r| r.reset_stats = true);
        r.map_err(|_| "store write failed")?;
        m
    }

    // Not inlined, as `save`.
    #[inline(never)]
    fn load(&mut self) -> Result<(), &'static str> {
        if self.status_now().enabled {
            return Err("disable before load");
        }
        let rec = match self.store.load() {
            Ok(Some(rec)) => rec,
            Ok(None) => return Err("nothing saved"),
            Err(_) => return Err("store read failed"),
        };
        let s = super::decode_settings(&rec, &self.defaults).map_err(|_| "stored set invalid")?;
        self.apply(s.settings)?;
        self.load_map()
    }

    fn defaults(&mut self) -> Result<(), &'static str> {
        let d = self.defaults;
        self.apply(d)?;
        self.configured = self.defaults_configured;
        Ok(())
    }

    fn enable(&mut self) -> Result<(), &'static str> {
        if !self.status_now().faults.is_empty() {
            return Err("fault latched (clear first)");
        }
        self.post(|r| r.enable = true)?;
        if self.status_now().enabled {
            Ok(())
        } else {
            Err("not enabled (fault)")
        }
    }

    fn enable_current(&mut self) -> Result<(), &'static str> {
        if !self.status_now().faults.is_empty() {
            return Err("fault latched (clear first)");
        }
        // One exchange: the loop takes the enable and the current in the same step.
        self.post(|r| {
            r.enable = true;
            r.current = Some(0.0);
            r.current_steps = None;
        })?;
        if self.status_now().enabled {
            Ok(())
        } else {
            Err("not enabled (fault)")
        }
    }

    fn disable(&mut self) -> Result<(), &'static str> {
        self.post(|r| r.disable = true)
    }

    fn status(&mut self) -> StatusReply {
        let st = self.status_now();
        let rpc = self.settings.rad_per_count();
        let clock = self.board.limits.clock_hz;
        StatusReply {
            mode: self.settings.ff.mode,
            enabled: st.enabled,
            faults: st.faults,
            t: st.steps as f64 / st.pos_rate_hz.max(1.0) as f64,
            pos: st.pos as f64 * rpc as f64,
            error_counts: st.error / rpc,
            moving: st.moving,
            current: st.current,
            ff: st.ff,
            duty: st.duty,
            step_us_worst: drive::cycles_to_us(st.stats.worst() as f32, clock),
            step_us_mean: drive::cycles_to_us(st.stats.mean(), clock),
            sense_offset: st.sense_offset,
            missed: st.stats.missed(),
            drive: st.drive.kind(),
            configured: self.configured,
        }
    }

    fn clear(&mut self) -> Result<(), &'static str> {
        self.post(|r| r.clear = true)
    }

    fn capture_arm(
        &mut self,
        fields: &str,
        every: u32,
        samples: u32,
        on_next: bool,
    ) -> Result<(), &'static str> {
        let (idx, n) = capture_fields(fields)?;
        if u64::from(samples) * u64::from(n) > u64::from(self.board.capture_values) {
            return Err("more than the capture buffer holds (samples × fields)");
        }
        let spec = CaptureSpec {
            fields: idx,
            nfields: n,
            every,
            samples,
            on_next,
        };
        self.post(|r| r.capture = Some(CaptureRequest::Arm(spec)))
    }

    fn capture_off(&mut self) -> Result<(), &'static str> {
        self.post(|r| r.capture = Some(CaptureRequest::Off))
    }

    fn capture_status(&mut self) -> protocol::CaptureStatus {
        let st = self.status_now();
        protocol::CaptureStatus {
            state: st.capture,
            samples: st.captured,
            capacity: self.board.capture_values,
            origin: st.capture_origin as f64 * self.settings.rad_per_count() as f64,
        }
    }

    fn capture_read(
        &mut self,
        start: u32,
        count: u32,
        out: &mut dyn Write,
    ) -> Result<(), &'static str> {
        let st = self.status_now();
        if st.capture != CaptureState::Done {
            return Err("no capture to read (capture: state)");
        }
        let end = start.saturating_add(count).min(st.captured);
        self.write_chunks(
            (start, end),
            |r, start, max| r.capture = Some(CaptureRequest::Read { start, max }),
            "capture read failed",
            out,
        )
    }

    fn current(&mut self, amps: f32, seconds: Option<f32>) -> Result<(), &'static str> {
        let st = self.status_now();
        if !st.enabled {
            return Err("disabled (enable first)");
        }
        if !(amps.is_finite() && amps.abs() <= self.settings.i_max) {
            return Err("beyond lim.i_max");
        }
        let steps = match seconds {
            None => None,
            Some(s) if s > 0.0 && s <= 60.0 => {
                // Float to int casts saturate; at most 60 s of steps.
                Some((s * self.settings.pos_rate_hz + 0.5) as u32)
            }
            Some(_) => return Err("SECONDS must be in (0, 60]"),
        };
        self.post(|r| {
            r.current = Some(amps);
            r.current_steps = steps;
        })
    }

    fn velocity(&mut self, vel: f32, sweep: Option<Sweep>) -> Result<(), &'static str> {
        let st = self.status_now();
        if !st.enabled {
            return Err("disabled (enable first)");
        }
        let rpc = self.settings.rad_per_count();
        let profile = VelocityProfile::new(st.reference, vel, sweep, MOVE_AMAX, rpc)
            .map_err(|_| "bad velocity (|VEL| + AMP <= 20 rad/s; frequencies and duration > 0)")?
            .for_step(self.settings.dt_pos());
        let req = VelocityRequest {
            profile,
            from_step: st.steps,
        };
        self.post(|r| r.velocity = Some(req))
    }

    fn hold(&mut self) -> Result<(), &'static str> {
        let st = self.status_now();
        if !st.enabled {
            return Err("disabled (enable first)");
        }
        match st.drive {
            Drive::Current(_) => self.post(|r| r.hold_here = true),
            Drive::Velocity => {
                // Stop where the acceleration limit allows, continuing from the reference.
                let rpc = self.settings.rad_per_count();
                let v = st.reference.vel;
                let here = (st.reference.pos as f64 / SUB_PER_COUNT as f64 * rpc as f64) as f32;
                let target = here + v * v.abs() / (2.0 * MOVE_AMAX);
                let plan = Motion::plan(st.reference, target, None, rpc).map_err(|_| "bad stop")?;
                let req = MoveRequest {
                    plan,
                    from_step: st.steps,
                };
                self.post(|r| r.motion = Some(req))
            }
            Drive::Position => Ok(()),
        }
    }

    fn move_to(&mut self, pos: f32, vel: Option<f32>) -> Result<(), &'static str> {
        let st = self.status_now();
        if !st.enabled {
            return Err("disabled (enable first)");
        }
        let rpc = self.settings.rad_per_count();
        let limits = self.board.limits(&self.settings);
        let target = pos / rpc;
        if !(target >= limits.pos_min as f32 && target <= limits.pos_max as f32) {
            return Err("beyond the soft limits");
        }
        // From the loop's reference now (position, velocity, acceleration): a move under
        // way is continued, not restarted.
        let plan = Motion::plan(st.reference, pos, vel, rpc).map_err(|_| "bad move")?;
        let req = MoveRequest {
            plan,
            from_step: st.steps,
        };
        self.post(|r| r.motion = Some(req))
    }

    fn stream(&mut self, fields: &str, rate_hz: f32) -> Result<(), &'static str> {
        if rate_hz > MAX_STREAM_HZ {
            return Err("rate above 1000 Hz");
        }
        let mut idx = [0u8; FIELDS.len()];
        let mut n = 0;
        for f in fields.split(',') {
            let i = FIELDS
                .iter()
                .position(|x| *x == f)
                .filter(|&i| self.board.has_truth || FIELDS.get(i) != Some(&"friction_true"))
                .ok_or("unknown field (t, pos, ref, error, ff, current, friction)")?;
            let slot = idx.get_mut(n).ok_or("too many fields")?;
            *slot = i as u8;
            n += 1;
        }
        let every = (self.settings.pos_rate_hz / rate_hz + 0.5).max(1.0) as u32;
        self.post(|r| r.stream_every = Some(every))?;
        self.fields = idx;
        self.nfields = n;
        Ok(())
    }

    fn stream_off(&mut self) -> Result<(), &'static str> {
        self.nfields = 0;
        self.post(|r| r.stream_every = Some(0))
    }

    fn estimate(&mut self, which: protocol::Estimate) -> f32 {
        match which {
            protocol::Estimate::AdaptScale => self.status_now().adapt_scale,
        }
    }

    fn frf_start(
        &mut self,
        injection: Injection,
        f_hz: f32,
        amp: f32,
        periods: u32,
        settle: u32,
    ) -> Result<(), &'static str> {
        let st = self.status_now();
        if !st.enabled {
            return Err("disabled (enable first)");
        }
        if matches!(st.drive, Drive::Current(_)) {
            return Err("in current mode: no position loop (hold first)");
        }
        if periods == 0 {
            return Err("PERIODS must be at least 1");
        }
        let rate = self.settings.pos_rate_hz;
        let spec =
            FrfSpec::new(injection, f_hz, amp, periods, settle, rate).map_err(|e| e.reason())?;
        if spec.steps() as f32 > FRF_MAX_S * rate {
            return Err("longer than 600 s (fewer periods)");
        }
        match injection {
            Injection::Current => {
                if amp > self.settings.i_max {
                    return Err("AMP beyond lim.i_max");
                }
            }
            Injection::Position => {
                let w = core::f32::consts::TAU * f_hz;
                if amp * w > crate::control::reference::VELOCITY_MAX {
                    return Err("AMP × 2π F_HZ beyond the speed limit (20 rad/s)");
                }
                let rpc = self.settings.rad_per_count();
                let limits = self.board.limits(&self.settings);
                let here = (st.reference.pos as f64 / SUB_PER_COUNT as f64) as f32;
                let reach = amp / rpc;
                if !(here - reach >= limits.pos_min as f32 && here + reach <= limits.pos_max as f32)
                {
                    return Err("AMP beyond the soft limits from here");
                }
            }
        }
        self.post(|r| r.frf = Some(FrfRequest::Start(spec)))
    }

    fn map_write(&mut self, start: u32, pairs: &str) -> Result<(), &'static str> {
        if self.settings.map.enable != 0.0 {
            return Err("map.enable is 1: set it to 0 to write the table");
        }
        let mut values = [0.0f32; 2 * MAP_WRITE_BINS];
        let mut n = 0usize;
        for pair in pairs.split_ascii_whitespace() {
            // The comma by hand: `split_once` brings a panicking branch into the link.
            let comma = pair.bytes().position(|c| c == b',').unwrap_or(pair.len());
            let (o, s) = (pair.get(..comma), pair.get(comma.saturating_add(1)..));
            let (Some(o), Some(s)) = (
                o.and_then(protocol::parse_f32),
                s.and_then(protocol::parse_f32),
            ) else {
                return Err("a bin is OFFSET,SCALE (N·m, -)");
            };
            if !crate::control::posmap::valid_bin(o, s) {
                return Err("a bin's offset beyond 10 N·m or scale outside 0 … 2");
            }
            match values.get_mut(2 * n..2 * n + 2) {
                Some([a, b]) => (*a, *b) = (o, s),
                _ => return Err("at most 8 bins a line"),
            }
            n += 1;
        }
        let bins = self.settings.map.bins as u32;
        if start.saturating_add(n as u32) > bins {
            return Err("beyond map.bins");
        }
        self.post(|r| {
            r.map = Some(MapRequest::Write {
                start,
                n: n as u32,
                values,
            })
        })
    }

    fn map_read(
        &mut self,
        start: u32,
        count: u32,
        out: &mut dyn Write,
    ) -> Result<(), &'static str> {
        let end = start
            .saturating_add(count)
            .min(self.settings.map.bins as u32);
        self.write_chunks(
            (start, end),
            |r, start, max| r.map = Some(MapRequest::Read { start, max }),
            "no position map on this device",
            out,
        )
    }

    fn map_clear(&mut self) -> Result<(), &'static str> {
        if self.settings.map.enable != 0.0 {
            return Err("map.enable is 1: set it to 0 to clear the table");
        }
        self.post(|r| r.map = Some(MapRequest::Clear))
    }

    fn table_status(&mut self) -> protocol::TableStatus {
        protocol::TableStatus(self.has_table.then(|| self.table_report()))
    }

    fn table(&mut self, cmd: TableCmd<'_>, out: &mut dyn Write) -> Result<(), &'static str> {
        if !self.has_table {
            return Err("no table motion on this device");
        }
        let t = self.table_report();
        let playing = t.state == TableState::Playing;
        let reason = |e: TableError| e.reason();
        match cmd {
            TableCmd::Status => Ok(()),
            TableCmd::Write {
                which,
                start,
                values,
            } => {
                let mut v = [0.0f32; TABLE_WRITE_VALUES];
                let mut n = 0usize;
                for w in values.split_ascii_whitespace() {
                    let x = protocol::parse_f32(w).ok_or("a value is a number")?;
                    *v.get_mut(n).ok_or("at most 8 values a line")? = x;
                    n += 1;
                }
                let vals = v.get(..n).unwrap_or(&[]);
                let mut u = self.upload;
                match which {
                    Which::Ref => {
                        if playing {
                            return Err("playing (table stop first)");
                        }
                        u.write_ref(start, vals).map_err(reason)?;
                        // The loop drops its correction with the reference.
                        u.corr_next = 0;
                    }
                    _ => {
                        let g = t.geometry.ok_or("no table set (table set first)")?;
                        if t.pending {
                            return Err("a correction waits for the next period's start");
                        }
                        let torque = self.settings.motor.k_m * self.settings.i_max;
                        u.write_corr(start, vals, g.points, torque)
                            .map_err(|e| match e {
                                TableError::BadValue => {
                                    "a value not finite or beyond the drive's torque (k_m × i_max)"
                                }
                                e => e.reason(),
                            })?;
                    }
                }
                self.post(|r| {
                    r.table = Some(TableRequest::Write {
                        which,
                        start,
                        n: n as u32,
                        values: v,
                    })
                })?;
                self.upload = u;
                Ok(())
            }
            TableCmd::Set(g) => {
                if playing {
                    return Err("playing (table stop first)");
                }
                let limits = self.board.limits(&self.settings);
                self.upload
                    .check_set(
                        &g,
                        self.settings.pos_rate_hz,
                        self.settings.rad_per_count(),
                        crate::control::reference::VELOCITY_MAX,
                        (limits.pos_min, limits.pos_max),
                    )
                    .map_err(reason)?;
                self.post(|r| r.table = Some(TableRequest::Set(g)))?;
                self.upload.corr_next = 0;
                Ok(())
            }
            TableCmd::Use => {
                let g = t.geometry.ok_or("no table set (table set first)")?;
                if t.pending {
                    return Err("a correction waits for the next period's start");
                }
                if self.upload.corr_next != g.points {
                    return Err("the correction is not written whole (POINTS values from 0)");
                }
                self.post(|r| r.table = Some(TableRequest::Use))?;
                self.upload.corr_next = 0;
                Ok(())
            }
            TableCmd::CorrOff => self.post(|r| r.table = Some(TableRequest::NoCorrection)),
            TableCmd::Run(n) => {
                let g = match t.state {
                    TableState::Empty => return Err("no table set (table set first)"),
                    TableState::Playing => return Err("already playing"),
                    TableState::Ready => t.geometry.ok_or("no table set (table set first)")?,
                };
                let st = self.status_now();
                if !st.enabled {
                    return Err("disabled (enable first)");
                }
                if st.drive != Drive::Position || st.moving {
                    return Err("the axis is not holding a position (hold first)");
                }
                let start = self.upload.start(g.origin);
                if (st.reference.pos.saturating_sub(start)).unsigned_abs() > SUB_PER_COUNT as u64 {
                    return Err("the reference is not at the table's start (move there first)");
                }
                self.post(|r| r.table = Some(TableRequest::Run(n)))?;
                if self.table_report().state != TableState::Playing {
                    return Err("the control loop did not start the table");
                }
                Ok(())
            }
            TableCmd::Stop => self.post(|r| r.table = Some(TableRequest::Stop)),
            TableCmd::Next => self.post(|r| r.table = Some(TableRequest::Next)),
            TableCmd::Read {
                which,
                start,
                count,
            } => {
                let points = t.geometry.map_or(0, |g| g.points);
                match which {
                    Which::Corr if t.generation == 0 => return Err("no correction played"),
                    Which::Err if t.done.is_none() => return Err("no period complete yet"),
                    _ => {}
                }
                if points == 0 {
                    return Err("no table set (table set first)");
                }
                let end = start.saturating_add(count).min(points);
                self.write_chunks(
                    (start, end),
                    |r, start, max| r.table = Some(TableRequest::Read { which, start, max }),
                    "no table to read",
                    out,
                )?;
                if which == Which::Err && self.table_report().done != t.done {
                    return Err(crate::control::table::READ_RACED);
                }
                Ok(())
            }
            TableCmd::Clear => {
                if playing {
                    return Err("playing (table stop first)");
                }
                self.post(|r| r.table = Some(TableRequest::Clear))?;
                self.upload = Upload::default();
                Ok(())
            }
        }
    }

    fn frf_off(&mut self) -> Result<(), &'static str> {
        self.post(|r| r.frf = Some(FrfRequest::Stop))
    }

    fn frf_status(&mut self) -> protocol::FrfStatus {
        if let Some(f) = read_frf(&mut self.link) {
            self.frf = f;
        }
        let f = &self.frf;
        protocol::FrfStatus {
            state: f.state,
            measure: f.injection.map(|injection| {
                let chans = [Channel::Command, Channel::Current, Channel::Position];
                // The sine injected is known exactly: its amplitude, in phase, coherent.
                let mut phasors = [[f.amp, 0.0]; 4];
                let mut coherence = [1.0; 4];
                let slots = phasors.iter_mut().zip(coherence.iter_mut()).skip(1);
                for ((ph, coh), ch) in slots.zip(chans) {
                    let p = f.lock.phasor(ch as usize).unwrap_or_default();
                    *ph = [p.re as f32, p.im as f32];
                    *coh = f.lock.coherence(ch as usize).unwrap_or(f64::NAN) as f32;
                }
                protocol::FrfMeasure {
                    injection,
                    f_hz: f.freq_hz as f32,
                    amp: f.amp,
                    groups_done: f.lock.groups(),
                    groups: f.groups,
                    phasors,
                    coherence,
                }
            }),
        }
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
