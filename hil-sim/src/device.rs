//! The virtual device: the simulated axis in real time behind gms-core's device core, the same
//! core the firmware runs (`gms_core::device`): the control loop steps at the PWM rate against
//! the simulated plant, the protocol front answers clients over TCP or a pseudo-terminal. This
//! file only moves numbers: encoder counts and current-sense codes in, the duty out, the
//! mailbox behind a mutex, the store on a file.
//!
//! Clients are served one after another; a client that drops does not stop the device. With
//! `--store FILE` the parameter store is a file holding the image of the board's store flash
//! (gms-core's [`FlashStore`]: same record, same sequential-storage map, same word and sector
//! sizes), written through at every flash write, so a crash leaves what a power cut leaves on a
//! board, and a store written by one is read by the other. Without `--store` the store is in
//! memory (lost at exit).

use crate::Error;
use std::collections::VecDeque;
use std::fs::{File, OpenOptions};
use std::io::{ErrorKind, Read, Seek, SeekFrom, Write};
use std::net::TcpListener;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use embedded_storage_async::nor_flash::{
    ErrorType, NorFlash, NorFlashError, NorFlashErrorKind, ReadNorFlash,
};
use gms_core::device::{
    self, Board, Chunk, ControlLoop, Front, Inputs, Link, Mailbox, ParamStore, Requests, Sample,
    SenseChain, Status,
};
use gms_core::drive::BoardLimits;
use gms_core::protocol::{self, LineReader, Settings};
use gms_core::store::{FlashStore, SECTOR_SIZE, STORE_RANGE, WORD_SIZE};

use crate::plant::Plant;
use crate::scenario::Scenario;

/// The virtual device's capture buffer (values), the board's.
pub const CAPTURE_VALUES: u32 = gms_core::boards::power_stage::CAPTURE_VALUES;

/// Telemetry samples kept for the client (0.4 s at 10 kHz; older ones are dropped).
pub const QUEUE: usize = 4000;

/// The simulated board: the F405 board as gms-core describes it (`boards::f405::BOARD`: its
/// PWM timer, encoder counter, sense zero tolerance, trip factor, following-error and speed
/// limits, capture buffer), with what a simulation cannot share: the plant's ADC as the current
/// sense (one conversion per sample, zero at mid-scale; a 3.3 V ADC, so that the plant's range
/// ±`adc_range` is the sense scale `sense.v_per_a` = 1.65 V / `adc_range` of
/// [`Scenario::controller_params`]), sampled at once (no window); step durations in host
/// nanoseconds (`clock_hz` 1e9) with a budget of 1 s at 20 kHz (the host is shared, so only a
/// stalled simulation counts as an overrun); the true friction in the telemetry; a bridge that
/// needs no wake-up.
pub fn board(sc: &Scenario) -> Board {
    let real = gms_core::boards::f405::BOARD;
    let adc = Adc::new(sc);
    Board {
        sense_oversample: 1,
        sense: SenseChain {
            vref: SIM_ADC_VREF,
            full_scale: (2.0 * adc.mid) as f32,
            zero_code: adc.mid as f32,
            window_s: 0.0,
            ..real.sense
        },
        limits: BoardLimits {
            clock_hz: 1_000_000_000,
            budget_fraction: 20_000.0,
            ..real.limits
        },
        has_truth: true,
        bridge_wake_s: 0.0,
        ..real
    }
}

/// The simulated ADC's reference \[V\]: the plant's ±`adc_range` spans it.
pub const SIM_ADC_VREF: f32 = 3.3;

/// The plant's current sense as ADC codes: one code per LSB, zero current mid-scale.
struct Adc {
    lsb: f64,
    mid: f64,
    top: f64,
}

impl Adc {
    fn new(sc: &Scenario) -> Adc {
        let full = (1u64 << sc.plant.adc_bits) as f64;
        Adc {
            lsb: 2.0 * sc.plant.adc_range / full,
            mid: full / 2.0,
            top: full - 1.0,
        }
    }

    /// The code of a current the plant's ADC measured \[A\].
    fn code(&self, amps: f32) -> u32 {
        (amps as f64 / self.lsb + self.mid)
            .round()
            .clamp(0.0, self.top) as u32
    }
}

/// The loop side: the device core's control loop and the plant, owned by the real-time thread.
struct Sim {
    core: ControlLoop,
    plant: Plant,
    adc: Adc,
    substeps: u32,
    /// Simulated time \[s\].
    t: f64,
}

impl Sim {
    /// One position period: `ratio` PWM periods of the core, the plant between them.
    /// `exchange` is the mailbox's (behind a mutex or local); step durations are timed on the
    /// host when `timed` (real time), else counted as 0 (simulated time).
    fn tick(
        &mut self,
        mut exchange: impl FnMut(Status, Option<&Chunk>) -> Option<Requests>,
        queue: &Mutex<VecDeque<Sample>>,
        timed: bool,
    ) {
        let n = self.core.ratio();
        let dt_plant = self.core.controller().dt_cur() as f64 / self.substeps as f64;
        for _ in 0..n {
            let inp = Inputs {
                encoder: self.plant.encoder() as u32,
                current_codes: self.adc.code(self.plant.adc()),
                // Simulated time: the steps are exactly one period apart (in the board's
                // step clock, ns), so none is ever missed.
                since_last: (self.core.controller().dt_cur() as f64 * 1e9) as u32,
            };
            let t0 = timed.then(Instant::now);
            let out = self.core.step(inp, &mut exchange);
            let ns = t0.map_or(0, |t| t.elapsed().as_nanos().min(u32::MAX as u128) as u32);
            self.core.finish(ns);
            let duty = if self.core.enabled() { out.duty } else { 0.0 };
            if let Some(mut s) = out.sample {
                s.friction_true = self.plant.friction as f32;
                let mut q = relock(queue);
                if q.len() == QUEUE {
                    q.pop_front();
                }
                q.push_back(s);
            }
            self.plant.set_duty(duty);
            for _ in 0..self.substeps {
                self.plant.step(dt_plant);
            }
            self.t += dt_plant * self.substeps as f64;
        }
    }
}

/// A virtual device just powered up: the loop on the plant, the store, and what the start-up
/// decided.
struct PowerUp {
    sim: Sim,
    store: FlashStore<HostFlash>,
    board: Board,
    settings: Settings,
    defaults: Settings,
    /// Why the start-up latched faults, if it did.
    why: Option<&'static str>,
}

/// The start-up of the board, on the plant: the parameter set from the store (gms-core's
/// decision), the current-sense zero measured with the bridge off (gms-core's), the loop at
/// rest at the encoder's reading.
fn power_up(sc: &Scenario, flash: HostFlash) -> Result<PowerUp, String> {
    let defaults = sc.controller_params()?;
    let board = board(sc);
    let mut store = FlashStore::new(flash);
    let start = device::startup(store.load(), &defaults, &board)
        .map_err(|e| format!("the scenario's controller: {e}"))?;
    let adc = Adc::new(sc);
    let mut plant = Plant::new(&sc.plant, sc.plant.seed)?;
    let zero = device::calibrate_sense(&board, start.settings.sense_v_per_a, || {
        Some(adc.code(plant.adc()))
    });
    let mut faults = start.faults;
    faults.latch(zero.faults);
    let why = if !start.faults.is_empty() {
        Some(start.note)
    } else if !zero.faults.is_empty() {
        Some("current-sense zero out of the board's window")
    } else {
        None
    };
    let encoder = plant.encoder() as u32;
    Ok(PowerUp {
        sim: Sim {
            core: ControlLoop::new(
                board,
                start.applied,
                zero.sense,
                faults,
                encoder,
                // One buffer per power-up of a virtual device (a board's is a static).
                Box::leak(vec![0.0; CAPTURE_VALUES as usize].into_boxed_slice()),
            ),
            plant,
            adc,
            substeps: sc.plant.substeps,
            t: 0.0,
        },
        store,
        board,
        settings: start.settings,
        defaults,
        why,
    })
}

/// What the real-time thread and the client sessions share.
struct Shared {
    mailbox: Mutex<Mailbox>,
    telemetry: Mutex<VecDeque<Sample>>,
}

fn relock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|p| p.into_inner())
}

impl Shared {
    fn mailbox(&self) -> MutexGuard<'_, Mailbox> {
        relock(&self.mailbox)
    }
    fn telemetry(&self) -> MutexGuard<'_, VecDeque<Sample>> {
        relock(&self.telemetry)
    }
}

/// The front's way to the loop: the mailbox behind a mutex; the loop is a thread, so waiting
/// sleeps a little.
struct HostLink {
    shared: Arc<Shared>,
    start: Instant,
}

impl Link for HostLink {
    fn with_mailbox<R>(&mut self, f: impl FnOnce(&mut Mailbox) -> R) -> R {
        f(&mut self.shared.mailbox())
    }
    fn now_us(&self) -> u64 {
        self.start.elapsed().as_micros() as u64
    }
    fn pause(&mut self) {
        std::thread::sleep(Duration::from_micros(200));
    }
    /// A loaded host may hold the simulation thread back for a while.
    fn timeout_us(&self) -> u64 {
        2_000_000
    }
}

/// The board's store flash on the host: the image of [`STORE_RANGE`] in memory, written
/// through to a file when there is one. NOR semantics: a write can only clear bits, an erase
/// sets a whole sector to 0xFF; both are checked for alignment like the F405's.
pub struct HostFlash {
    image: Vec<u8>,
    file: Option<File>,
}

/// A host flash failure.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum HostFlashError {
    /// Outside the store's range.
    OutOfBounds,
    /// Not aligned to a word (write) or a sector (erase).
    NotAligned,
    /// The file could not be written.
    Io,
}

impl NorFlashError for HostFlashError {
    fn kind(&self) -> NorFlashErrorKind {
        match self {
            HostFlashError::OutOfBounds => NorFlashErrorKind::OutOfBounds,
            HostFlashError::NotAligned => NorFlashErrorKind::NotAligned,
            HostFlashError::Io => NorFlashErrorKind::Other,
        }
    }
}

/// Bytes of the store's image.
pub const IMAGE_LEN: usize = (STORE_RANGE.end - STORE_RANGE.start) as usize;

impl HostFlash {
    /// An erased flash in memory.
    pub fn in_memory() -> HostFlash {
        HostFlash {
            image: vec![0xFF; IMAGE_LEN],
            file: None,
        }
    }

    /// The flash in `path`: created erased if missing; an existing file must be a store image
    /// ([`IMAGE_LEN`] bytes).
    pub fn open(path: &Path) -> Result<HostFlash, Error> {
        Self::open_inner(path).map_err(Error::Device)
    }

    fn open_inner(path: &Path) -> Result<HostFlash, String> {
        let shown = path.display();
        let mut file = OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .open(path)
            .map_err(|e| format!("{shown}: {e}"))?;
        let mut image = Vec::new();
        file.read_to_end(&mut image)
            .map_err(|e| format!("{shown}: {e}"))?;
        if image.is_empty() {
            image = vec![0xFF; IMAGE_LEN];
            file.write_all(&image)
                .and_then(|_| file.sync_data())
                .map_err(|e| format!("{shown}: {e}"))?;
        } else if image.len() != IMAGE_LEN {
            return Err(format!(
                "{shown}: not a store image ({} bytes, a store is {IMAGE_LEN}); move it away \
                 to start a fresh store",
                image.len()
            ));
        }
        Ok(HostFlash {
            image,
            file: Some(file),
        })
    }

    /// The image (the store's flash bytes).
    pub fn image(&self) -> &[u8] {
        &self.image
    }

    fn span(&self, offset: u32, len: usize) -> Result<std::ops::Range<usize>, HostFlashError> {
        let start = offset
            .checked_sub(STORE_RANGE.start)
            .ok_or(HostFlashError::OutOfBounds)? as usize;
        let end = start.checked_add(len).ok_or(HostFlashError::OutOfBounds)?;
        if end > self.image.len() {
            return Err(HostFlashError::OutOfBounds);
        }
        Ok(start..end)
    }

    fn persist(&mut self, at: std::ops::Range<usize>) -> Result<(), HostFlashError> {
        let Some(f) = &mut self.file else {
            return Ok(());
        };
        let bytes = self
            .image
            .get(at.clone())
            .ok_or(HostFlashError::OutOfBounds)?;
        f.seek(SeekFrom::Start(at.start as u64))
            .and_then(|_| f.write_all(bytes))
            .and_then(|_| f.sync_data())
            .map_err(|_| HostFlashError::Io)
    }
}

impl ErrorType for HostFlash {
    type Error = HostFlashError;
}

impl ReadNorFlash for HostFlash {
    const READ_SIZE: usize = 1;

    async fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), Self::Error> {
        let at = self.span(offset, bytes.len())?;
        bytes.copy_from_slice(self.image.get(at).ok_or(HostFlashError::OutOfBounds)?);
        Ok(())
    }

    fn capacity(&self) -> usize {
        STORE_RANGE.end as usize
    }
}

impl NorFlash for HostFlash {
    const WRITE_SIZE: usize = WORD_SIZE;
    const ERASE_SIZE: usize = SECTOR_SIZE;

    async fn erase(&mut self, from: u32, to: u32) -> Result<(), Self::Error> {
        if from % SECTOR_SIZE as u32 != 0 || to % SECTOR_SIZE as u32 != 0 || to < from {
            return Err(HostFlashError::NotAligned);
        }
        let at = self.span(from, (to - from) as usize)?;
        self.image
            .get_mut(at.clone())
            .ok_or(HostFlashError::OutOfBounds)?
            .fill(0xFF);
        self.persist(at)
    }

    async fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), Self::Error> {
        if offset % WORD_SIZE as u32 != 0 || bytes.len() % WORD_SIZE != 0 {
            return Err(HostFlashError::NotAligned);
        }
        let at = self.span(offset, bytes.len())?;
        let dst = self
            .image
            .get_mut(at.clone())
            .ok_or(HostFlashError::OutOfBounds)?;
        // NOR: programming only clears bits.
        for (d, s) in dst.iter_mut().zip(bytes) {
            *d &= *s;
        }
        self.persist(at)
    }
}

/// The virtual device's protocol side.
type Dev = Front<HostLink, FlashStore<HostFlash>>;

/// The one line a client connecting while another is served receives before it is closed.
pub const BUSY: &str = "err 8 busy: another client is connected to the device\n";

/// How long a client connecting while another is served waits before it is refused (the
/// other may just have left, unseen yet).
const BUSY_GRACE: Duration = Duration::from_millis(100);

/// Serves one client until it disconnects. `conn` reads must not block for long: a TCP
/// socket with a read timeout, or a non-blocking PTY master. `refuse_others` is called at
/// every turn of the loop while this client is still there: it answers clients that came
/// meanwhile with [`BUSY`].
fn serve_client<C: Read + Write>(
    dev: &mut Dev,
    shared: &Shared,
    mut conn: C,
    refuse_others: &mut dyn FnMut(),
) {
    let mut reader = LineReader::default();
    let mut buf = [0u8; 512];
    shared.telemetry().clear();
    loop {
        // Read first: a client that has just left is seen gone (end of stream) before the
        // next one, which connected after it left, would be refused.
        match conn.read(&mut buf) {
            Ok(0) => break,
            Ok(n) => {
                let mut reply = String::new();
                for &b in &buf[..n] {
                    if let Some(line) = reader.push(b) {
                        let _ = protocol::execute(dev, line, &mut reply);
                    }
                }
                if conn.write_all(reply.as_bytes()).is_err() {
                    break;
                }
            }
            Err(e) if e.kind() == ErrorKind::WouldBlock => {
                std::thread::sleep(Duration::from_millis(2))
            }
            Err(e) if e.kind() == ErrorKind::TimedOut => {}
            Err(_) => break,
        }
        refuse_others();
        let samples: Vec<Sample> = shared.telemetry().drain(..).collect();
        if dev.streaming() && !samples.is_empty() {
            let mut lines = String::new();
            for s in &samples {
                let _ = dev.telemetry_line(&mut lines, s);
            }
            if conn.write_all(lines.as_bytes()).is_err() {
                break;
            }
        }
    }
    // A new client starts without a stream.
    dev.disconnected();
}

/// Where the device listens.
pub enum Endpoint {
    /// TCP: clients connect one after another.
    Tcp(TcpListener),
    /// A pseudo-terminal: the device holds the master; clients open the slave path (like a
    /// USB CDC-ACM port) one after another.
    #[cfg(unix)]
    Pty,
}

/// Runs the device: the control loop and the plant in real time on their own thread, clients
/// in turn. The simulated axis runs `speed` times faster than the wall clock (1: real time;
/// above 1 it never skips simulated time, it falls behind the target speed when the host
/// cannot keep up). `on_ready` receives the address (TCP address or PTY path) and what the
/// start-up found in the store (`Some` when the defaults run with `invalid_params` latched)
/// before the first client.
pub fn serve(
    sc: Scenario,
    endpoint: Endpoint,
    store: Option<PathBuf>,
    speed: f64,
    on_ready: impl FnOnce(&str, Option<&str>),
) -> Result<(), Error> {
    if !(speed.is_finite() && (0.01..=1000.0).contains(&speed)) {
        return Err(Error::Device(format!(
            "--speed {speed}: a factor from 0.01 to 1000"
        )));
    }
    serve_inner(sc, endpoint, store, speed, on_ready).map_err(Error::Device)
}

fn serve_inner(
    sc: Scenario,
    endpoint: Endpoint,
    store: Option<PathBuf>,
    speed: f64,
    on_ready: impl FnOnce(&str, Option<&str>),
) -> Result<(), String> {
    let flash = match &store {
        Some(path) => HostFlash::open(path)?,
        None => HostFlash::in_memory(),
    };
    let PowerUp {
        mut sim,
        store: flash_store,
        board,
        settings,
        defaults,
        why,
    } = power_up(&sc, flash)?;
    let shared = Arc::new(Shared {
        // The loop's status from the start (before its first step).
        mailbox: Mutex::new(Mailbox {
            status: sim.core.status(),
            ..Mailbox::new()
        }),
        telemetry: Mutex::new(VecDeque::with_capacity(QUEUE)),
    });
    let rt = Arc::clone(&shared);
    std::thread::spawn(move || {
        // Advance by as many position periods as (scaled) wall time allows.
        let start = Instant::now();
        loop {
            let dt = sim.core.controller().dt_pos() as f64;
            let due = start.elapsed().as_secs_f64() * speed;
            let mut n = 0;
            while sim.t + dt <= due && n < 200 {
                sim.tick(|st, c| rt.mailbox().exchange(st, c), &rt.telemetry, true);
                n += 1;
            }
            if n == 200 {
                if speed == 1.0 {
                    // Real time and cannot keep up: skip ahead rather than fall ever further
                    // behind.
                    sim.t = due;
                } else {
                    // Faster than real time: never skip simulated time, just run on.
                    continue;
                }
            }
            std::thread::sleep(Duration::from_millis(1));
        }
    });
    let link = HostLink {
        shared: Arc::clone(&shared),
        start: Instant::now(),
    };
    // The scenario describes the axis: its defaults are configured for it.
    let mut dev =
        Front::new(link, flash_store, board, settings, defaults).with_configured(true, true);
    match endpoint {
        Endpoint::Tcp(listener) => {
            let addr = listener
                .local_addr()
                .map_err(|e| e.to_string())?
                .to_string();
            on_ready(&addr, why);
            // Connections are accepted on their own thread, so that one arriving while a
            // client is served gets a one-line refusal at once rather than silence.
            let (tx, rx) = std::sync::mpsc::channel::<std::net::TcpStream>();
            std::thread::spawn(move || {
                for conn in listener.incoming() {
                    let Ok(c) = conn else { continue };
                    if tx.send(c).is_err() {
                        break;
                    }
                }
            });
            // A client that connects just after the previous one left may arrive before that
            // one is seen gone: a newcomer waits for a grace period before it is refused, and
            // is served if the current client leaves meanwhile.
            let waiting =
                std::cell::RefCell::new(VecDeque::<(std::net::TcpStream, Instant)>::new());
            let mut refuse = || {
                let mut w = waiting.borrow_mut();
                while let Ok(c) = rx.try_recv() {
                    w.push_back((c, Instant::now()));
                }
                while w.front().is_some_and(|(_, at)| at.elapsed() >= BUSY_GRACE) {
                    if let Some((mut other, _)) = w.pop_front() {
                        let _ = other.write_all(BUSY.as_bytes());
                        let _ = other.shutdown(std::net::Shutdown::Both);
                    }
                }
            };
            loop {
                let next = waiting.borrow_mut().pop_front().map(|(c, _)| c);
                let c = match next {
                    Some(c) => c,
                    None => match rx.recv() {
                        Ok(c) => c,
                        Err(_) => break,
                    },
                };
                let _ = c.set_read_timeout(Some(Duration::from_millis(2)));
                let _ = c.set_nodelay(true);
                serve_client(&mut dev, &shared, c, &mut refuse);
            }
            Ok(())
        }
        #[cfg(unix)]
        Endpoint::Pty => serve_pty(&mut dev, &shared, |path| on_ready(path, why)),
    }
}

/// Serves the protocol on a pseudo-terminal. The device keeps the slave open too, so a client
/// that closes it does not end the session: the next one finds the device where it was.
#[cfg(unix)]
fn serve_pty(dev: &mut Dev, shared: &Shared, on_ready: impl FnOnce(&str)) -> Result<(), String> {
    use nix::fcntl::{FcntlArg, OFlag, fcntl};
    use nix::sys::termios::{SetArg, cfmakeraw, tcgetattr, tcsetattr};

    let pty = nix::pty::openpty(None, None).map_err(|e| format!("openpty: {e}"))?;
    let mut t = tcgetattr(&pty.slave).map_err(|e| format!("tcgetattr: {e}"))?;
    cfmakeraw(&mut t);
    tcsetattr(&pty.slave, SetArg::TCSANOW, &t).map_err(|e| format!("tcsetattr: {e}"))?;
    let path = nix::unistd::ttyname(&pty.slave).map_err(|e| format!("ttyname: {e}"))?;
    fcntl(&pty.master, FcntlArg::F_SETFL(OFlag::O_NONBLOCK)).map_err(|e| format!("fcntl: {e}"))?;
    on_ready(&path.display().to_string());
    let master = File::from(pty.master);
    let _slave = pty.slave;
    loop {
        // serve_client returns only on an I/O error; start over after a pause.
        serve_client(dev, shared, &master, &mut || {});
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// The virtual device in-process and in simulated time: the same core, plant and store as
/// [`serve`], with the protocol's waits driving the simulation instead of a real-time thread
/// (deterministic: every run of the same requests gives the same numbers). For tests and
/// scripted experiments.
pub struct LocalDevice {
    dev: Front<LocalLink, FlashStore<HostFlash>>,
}

/// The in-process link: waiting on the loop runs it one position period.
struct LocalLink {
    sim: Sim,
    mailbox: Mailbox,
    queue: Mutex<VecDeque<Sample>>,
}

impl Link for LocalLink {
    fn with_mailbox<R>(&mut self, f: impl FnOnce(&mut Mailbox) -> R) -> R {
        f(&mut self.mailbox)
    }
    fn now_us(&self) -> u64 {
        (self.sim.t * 1e6) as u64
    }
    fn pause(&mut self) {
        self.tick();
    }
}

impl LocalLink {
    fn tick(&mut self) {
        let mb = &mut self.mailbox;
        self.sim
            .tick(|st, c| mb.exchange(st, c), &self.queue, false);
    }
}

impl LocalDevice {
    /// The plant as it is now: the truth a test holds the device's readings against.
    pub fn plant(&mut self) -> &Plant {
        &self.dev.link_mut().sim.plant
    }

    /// A device on the scenario `sc`, its store in memory (erased).
    pub fn new(sc: &Scenario) -> Result<LocalDevice, Error> {
        Self::new_inner(sc).map_err(Error::Device)
    }

    fn new_inner(sc: &Scenario) -> Result<LocalDevice, String> {
        Self::with_flash_inner(sc, HostFlash::in_memory())
    }

    /// A device on the scenario `sc` starting on the store flash `flash` (what a board finds
    /// at power-up).
    pub fn with_flash(sc: &Scenario, flash: HostFlash) -> Result<LocalDevice, Error> {
        Self::with_flash_inner(sc, flash).map_err(Error::Device)
    }

    fn with_flash_inner(sc: &Scenario, flash: HostFlash) -> Result<LocalDevice, String> {
        let p = power_up(sc, flash)?;
        let mailbox = Mailbox {
            status: p.sim.core.status(),
            ..Mailbox::new()
        };
        let link = LocalLink {
            sim: p.sim,
            mailbox,
            queue: Mutex::new(VecDeque::with_capacity(QUEUE)),
        };
        Ok(LocalDevice {
            dev: Front::new(link, p.store, p.board, p.settings, p.defaults)
                .with_configured(true, true),
        })
    }

    /// Sends one request line; returns the reply (its lines, the last `ok …` or `err …`).
    pub fn ask(&mut self, line: &str) -> String {
        let mut out = String::new();
        let mut reader = LineReader::default();
        for b in line.bytes().chain(std::iter::once(b'\n')) {
            if let Some(l) = reader.push(b) {
                let _ = protocol::execute(&mut self.dev, l, &mut out);
            }
        }
        out
    }

    /// The store flash as it is now (the device is gone: to power up again on it, with
    /// [`LocalDevice::with_flash`]).
    pub fn into_flash(self) -> HostFlash {
        let (_, store) = self.dev.into_parts();
        // `FlashStore::new` accepted this flash's geometry, so the map is there.
        store.into_flash().unwrap_or_else(HostFlash::in_memory)
    }

    /// The client went away (as a closed TCP connection or USB port): the stream ends, an
    /// experiment (current or speed) ends with the bridge off.
    pub fn disconnect(&mut self) {
        self.dev.disconnected();
    }

    /// Runs the device for `seconds` of simulated time.
    pub fn run(&mut self, seconds: f64) {
        let link = self.dev.link_mut();
        let end = link.sim.t + seconds;
        while link.sim.t < end {
            link.tick();
        }
    }

    /// The telemetry lines produced since the last call (while a stream is on).
    pub fn telemetry(&mut self) -> Vec<String> {
        let samples: Vec<Sample> = relock(&self.dev.link_mut().queue).drain(..).collect();
        if !self.dev.streaming() {
            return Vec::new();
        }
        let mut text = String::new();
        for s in &samples {
            let _ = self.dev.telemetry_line(&mut text, s);
        }
        text.lines().map(String::from).collect()
    }
}

/// The device as an abstract bench (`gms_ident::bench`): experiments run on it in simulated
/// time, through the same protocol as on a board.
impl gms_ident::bench::Bench for LocalDevice {
    fn request(&mut self, line: &str) -> Result<(Vec<String>, String), gms_ident::Error> {
        let reply = self.ask(line);
        let mut lines: Vec<String> = reply.lines().map(String::from).collect();
        match lines.pop() {
            Some(l) if l == "ok" || l.starts_with("ok ") => {
                Ok((lines, l.get(3..).unwrap_or("").to_string()))
            }
            Some(l) => Err(gms_ident::Error::Device(format!("device answered: {l}"))),
            None => Err(gms_ident::Error::Device("no reply".into())),
        }
    }

    fn wait(&mut self, seconds: f64) -> Result<(), gms_ident::Error> {
        if seconds.is_finite() && seconds > 0.0 {
            self.run(seconds);
        }
        Ok(())
    }
}
