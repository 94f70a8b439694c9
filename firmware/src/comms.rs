//! The bench link: USB CDC-ACM at low priority (thread mode), speaking gms-core's protocol
//! (`LineReader` → `execute` over the [`Device`] below). Parameters cross to the control loop
//! as one validated, complete [`Applied`] set, taken by the loop between two steps.

use core::fmt::{self, Write};

use defmt::{info, warn};
use embassy_futures::select::{Either, select};
use embassy_stm32::peripherals::USB_OTG_FS;
use embassy_stm32::usb::Driver;
use embassy_time::{Duration, Instant};
use embassy_usb::class::cdc_acm::CdcAcmClass;
use embassy_usb::driver::EndpointError;
use gms_core::controller::Controller;
use gms_core::drive::{self, Faults};
use gms_core::numtext::Num;
use gms_core::protocol::{self, Device, LineReader, Settings};
use gms_core::reference::{Motion, SUB_PER_COUNT};

use crate::board;
use crate::control::{Applied, Requests, SHARED, Sample, Status, TELEMETRY};
use crate::storage::Store;

/// Telemetry fields `stream` accepts (as the simulator's virtual device).
pub const FIELDS: [&str; 7] = ["t", "pos", "ref", "error", "ff", "current", "friction"];

/// The highest telemetry rate [Hz].
pub const MAX_STREAM_HZ: f32 = 1000.0;

/// The loop's parameter set for `s`: the controller, the limits and the PWM timing, or
/// `None` when the board cannot run it (no PWM setting for the current-loop rate).
pub fn prepare(s: &Settings) -> Option<Applied> {
    let ctrl = Controller::try_new(*s).ok()?;
    let (psc, arr) = drive::pwm_timing(board::PWM_TIMER_HZ, s.cur_rate_hz, board::PWM_MAX_ARR)?;
    Some(Applied {
        ctrl,
        limits: drive::limits_for(s, &board::LIMITS),
        psc,
        arr,
    })
}

/// The latest status of the loop.
pub fn status() -> Status {
    SHARED.lock(|s| s.borrow().status)
}

/// Posts requests to the loop and waits (at most 50 ms, busy) until it has taken them and
/// published a status after them, so that a reply and the status after it agree.
fn post(f: impl FnOnce(&mut Requests)) {
    let steps0 = SHARED.lock(|s| {
        let mut s = s.borrow_mut();
        f(&mut s.requests);
        s.status.steps
    });
    let deadline = Instant::now() + Duration::from_millis(50);
    while Instant::now() < deadline {
        // Taken at one step, reflected in the status published at the next.
        if status().steps >= steps0.wrapping_add(2) {
            return;
        }
    }
}

/// The firmware's side of the protocol.
pub struct Dev {
    settings: Settings,
    defaults: Settings,
    store: Store,
    fields: [u8; FIELDS.len()],
    nfields: usize,
}

impl Dev {
    /// A device running `settings`, with `defaults` for `defaults` and `load`.
    pub fn new(settings: Settings, defaults: Settings, store: Store) -> Dev {
        Dev {
            settings,
            defaults,
            store,
            fields: [0; FIELDS.len()],
            nfields: 0,
        }
    }

    fn fields(&self) -> &[u8] {
        self.fields.get(..self.nfields).unwrap_or(&[])
    }

    /// Applies a set the protocol validated; one the board cannot run latches
    /// `invalid_params` and leaves the running set as it is.
    fn apply_checked(&mut self, new: Settings) -> Result<(), &'static str> {
        match prepare(&new) {
            Some(a) => {
                post(|r| r.apply = Some(a));
                self.settings = new;
                Ok(())
            }
            None => {
                warn!("parameter set refused by the board (PWM rate)");
                post(|r| r.latch.latch(Faults::INVALID_PARAMS));
                Err("the board cannot run this set (PWM rate)")
            }
        }
    }
}

impl Device for Dev {
    fn settings(&self) -> &Settings {
        &self.settings
    }

    fn apply(&mut self, new: Settings) {
        let _ = self.apply_checked(new);
    }

    fn save(&mut self) -> Result<(), &'static str> {
        if status().enabled {
            return Err("disable before save");
        }
        let rec = drive::encode_settings(&self.settings);
        info!("saving parameters (flash stalls the CPU up to ~2 s)");
        let r = self.store.save(&rec);
        // The stall distorts the step statistics: start them afresh.
        post(|r| r.reset_stats = true);
        match r {
            Ok(()) => Ok(()),
            Err(e) => {
                warn!("save failed: {}", e);
                Err("flash write failed")
            }
        }
    }

    fn load(&mut self) -> Result<(), &'static str> {
        if status().enabled {
            return Err("disable before load");
        }
        let rec = match self.store.load() {
            Ok(Some(rec)) => rec,
            Ok(None) => return Err("nothing saved"),
            Err(_) => return Err("flash read failed"),
        };
        let s = drive::decode_settings(&rec, &self.defaults).map_err(|_| "stored set invalid")?;
        self.apply_checked(s)
    }

    fn defaults(&mut self) {
        let d = self.defaults;
        let _ = self.apply_checked(d);
    }

    fn enable(&mut self) -> Result<(), &'static str> {
        if !status().faults.is_empty() {
            return Err("fault latched (clear first)");
        }
        post(|r| r.enable = true);
        if status().enabled {
            info!("bridge enabled");
            Ok(())
        } else {
            Err("not enabled (fault)")
        }
    }

    fn disable(&mut self) {
        post(|r| r.disable = true);
        info!("bridge disabled");
    }

    fn status(&self, out: &mut dyn Write) -> fmt::Result {
        let st = status();
        let rpc = self.settings.rad_per_count;
        let mode = self.settings.ff.mode.name();
        let t = st.steps as f32 / st.pos_rate_hz.max(1.0);
        let error_counts = st.error / rpc;
        write!(
            out,
            "mode={mode} enabled={} faults={} t={} pos={} error_counts={} moving={} current={} \
             fault_names=",
            st.enabled as u8,
            st.faults.0,
            Num(t),
            Num(st.pos as f32 * rpc),
            Num(error_counts),
            st.moving as u8,
            Num(st.current),
        )?;
        st.faults.write_names(out)?;
        write!(
            out,
            " ff={} duty={} step_us_worst={} step_us_mean={} sense_offset={}",
            Num(st.ff),
            Num(st.duty),
            Num(drive::cycles_to_us(
                st.stats.worst() as f32,
                board::SYSCLK_HZ
            )),
            Num(drive::cycles_to_us(st.stats.mean(), board::SYSCLK_HZ)),
            Num(st.sense_offset),
        )
    }

    fn clear(&mut self) {
        post(|r| r.clear = true);
        info!("faults cleared");
    }

    fn move_to(&mut self, pos: f32, vel: Option<f32>) -> Result<(), &'static str> {
        let st = status();
        if !st.enabled {
            return Err("disabled (enable first)");
        }
        let rpc = self.settings.rad_per_count;
        let limits = drive::limits_for(&self.settings, &board::LIMITS);
        let target = pos / rpc;
        if !(target >= limits.pos_min as f32 && target <= limits.pos_max as f32) {
            return Err("beyond the soft limits");
        }
        // From the current reference.
        let r = Motion::plan(st.reference, pos, vel, rpc).map_err(|_| "bad move")?;
        post(|q| q.motion = Some(r));
        Ok(())
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
                .ok_or("unknown field (t, pos, ref, error, ff, current, friction)")?;
            let slot = idx.get_mut(n).ok_or("too many fields")?;
            *slot = i as u8;
            n += 1;
        }
        let every = (self.settings.pos_rate_hz / rate_hz + 0.5).max(1.0) as u32;
        self.fields = idx;
        self.nfields = n;
        post(|r| r.stream_every = Some(every));
        Ok(())
    }

    fn stream_off(&mut self) {
        post(|r| r.stream_every = Some(0));
        self.nfields = 0;
    }

    fn estimate(&self, which: protocol::Estimate) -> f32 {
        match which {
            protocol::Estimate::AdaptScale => status().adapt_scale,
        }
    }
}

/// A fixed buffer that `fmt::Write` fills; past its end it reports an error.
pub struct Buf<const N: usize> {
    bytes: [u8; N],
    len: usize,
}

impl<const N: usize> Buf<N> {
    /// Empty.
    pub const fn new() -> Self {
        Buf {
            bytes: [0; N],
            len: 0,
        }
    }

    /// The bytes written.
    pub fn as_bytes(&self) -> &[u8] {
        self.bytes.get(..self.len).unwrap_or(&[])
    }

    /// Forgets the contents.
    pub fn clear(&mut self) {
        self.len = 0;
    }
}

impl<const N: usize> Write for Buf<N> {
    fn write_str(&mut self, s: &str) -> fmt::Result {
        let end = self.len + s.len();
        let dst = self.bytes.get_mut(self.len..end).ok_or(fmt::Error)?;
        dst.copy_from_slice(s.as_bytes());
        self.len = end;
        Ok(())
    }
}

/// One telemetry line (`# t=… pos=…`), SI units.
fn telemetry_line(out: &mut impl Write, s: &Sample, fields: &[u8], dev: &Dev) -> fmt::Result {
    let rpc = dev.settings.rad_per_count;
    out.write_char('#')?;
    for &f in fields {
        let v = match f {
            0 => s.steps as f32 / dev.settings.pos_rate_hz,
            1 => s.pos as f32 * rpc,
            2 => s.reference as f32 / SUB_PER_COUNT * rpc,
            3 => s.error,
            4 => s.ff,
            5 => s.current,
            _ => s.friction,
        };
        let name = FIELDS.get(f as usize).copied().unwrap_or("?");
        write!(out, " {name}={}", Num(v))?;
    }
    out.write_char('\n')
}

/// Writes `bytes` in packets; a final full packet is followed by an empty one, so that the
/// host sees the end of the transfer.
async fn send(
    class: &mut CdcAcmClass<'static, Driver<'static, USB_OTG_FS>>,
    bytes: &[u8],
) -> Result<(), EndpointError> {
    let max = class.max_packet_size() as usize;
    for chunk in bytes.chunks(max) {
        class.write_packet(chunk).await?;
    }
    if !bytes.is_empty() && bytes.len().is_multiple_of(max) {
        class.write_packet(&[]).await?;
    }
    Ok(())
}

/// Replies of one request can be long (`list`: 1.3 KB today, room for the table to grow).
const REPLY: usize = 4096;

/// Serves the protocol while a host is connected, forever.
pub async fn serve(
    mut class: CdcAcmClass<'static, Driver<'static, USB_OTG_FS>>,
    mut dev: Dev,
) -> ! {
    let mut reader = LineReader::default();
    let mut reply = Buf::<REPLY>::new();
    let mut lines = Buf::<512>::new();
    let mut packet = [0u8; 64];
    loop {
        class.wait_connection().await;
        info!("USB host connected");
        loop {
            match select(class.read_packet(&mut packet), TELEMETRY.receive()).await {
                Either::First(Ok(n)) => {
                    let mut link_ok = true;
                    for &b in packet.get(..n).unwrap_or(&[]) {
                        let Some(line) = reader.push(b) else {
                            continue;
                        };
                        // One reply per request line, sent before the next line is read.
                        reply.clear();
                        if protocol::execute(&mut dev, line, &mut reply).is_err() {
                            // The buffer overflowed: say so instead of a cut reply.
                            reply.clear();
                            let _ = writeln!(reply, "err 8 reply too long");
                        }
                        if send(&mut class, reply.as_bytes()).await.is_err() {
                            link_ok = false;
                            break;
                        }
                    }
                    if !link_ok {
                        break;
                    }
                }
                Either::First(Err(_)) => break,
                Either::Second(sample) => {
                    if dev.nfields == 0 {
                        continue;
                    }
                    lines.clear();
                    let mut next = Some(sample);
                    // Batch what is queued, a few lines per transfer.
                    while let Some(s) = next {
                        let mark = lines.len;
                        if telemetry_line(&mut lines, &s, dev.fields(), &dev).is_err() {
                            lines.len = mark;
                            break;
                        }
                        next = if lines.len < 384 {
                            TELEMETRY.try_receive().ok()
                        } else {
                            None
                        };
                    }
                    if send(&mut class, lines.as_bytes()).await.is_err() {
                        break;
                    }
                }
            }
        }
        info!("USB host disconnected");
        // A new client starts with no stream.
        dev.stream_off();
    }
}
