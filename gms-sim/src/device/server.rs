//! The virtual device as a server: the loop in a real-time thread, the protocol front serving
//! one client at a time over TCP or a pseudo-terminal.

use super::*;

/// What the real-time thread and the client sessions share.
struct Shared {
    mailbox: Mutex<Mailbox>,
    telemetry: Mutex<VecDeque<Sample>>,
    /// The supply divider's code after the loop's last tick (a board's ADC data register).
    supply_code: std::sync::atomic::AtomicU32,
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

impl LoopLink for HostLink {
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
    fn supply_code(&mut self) -> u32 {
        self.shared
            .supply_code
            .load(std::sync::atomic::Ordering::Relaxed)
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
    let mut supervised = Instant::now();
    loop {
        supervise_every(dev, &mut supervised);
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

/// The supply's supervision, as a board's shell runs it: every
/// [`gms_core::device::SUPERVISE_MS`] of wall time, in a session and between sessions.
fn supervise_every(dev: &mut Dev, last: &mut Instant) {
    if last.elapsed() >= Duration::from_millis(gms_core::device::SUPERVISE_MS) {
        *last = Instant::now();
        dev.supervise();
    }
}

/// The simulation's longest run of steps without a pause \[wall time\].
const SLICE: Duration = Duration::from_millis(4);
/// The pause after each slice \[wall time\]: the protocol side's turn.
const PAUSE: Duration = Duration::from_millis(1);
/// The most the simulated clock may lag the wall clock (scaled) before it slips \[s of wall
/// time\].
const MAX_LAG: f64 = 0.05;

/// The virtual device's clock: simulated time due at `speed` × the wall time since an anchor,
/// the anchor moved on when the simulation falls more than [`MAX_LAG`] behind (the device then
/// runs slower than `speed`, as a board's clock never would, but its replies do not wait for
/// a backlog).
struct Pacer {
    speed: f64,
    wall: Instant,
    sim: f64,
}

impl Pacer {
    fn new(speed: f64) -> Pacer {
        Pacer {
            speed,
            wall: Instant::now(),
            sim: 0.0,
        }
    }

    /// The simulated time due now \[s\].
    fn due(&self) -> f64 {
        self.sim + self.wall.elapsed().as_secs_f64() * self.speed
    }

    /// After a slice: the clock slips if the simulation at `t` \[s\] is too far behind.
    fn behind(&mut self, t: f64) {
        if self.due() - t > MAX_LAG * self.speed {
            self.wall = Instant::now();
            self.sim = t;
        }
    }
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
        requests,
        spare,
    } = power_up(&sc, flash)?;
    let shared = Arc::new(Shared {
        // The loop's status from the start (before its first step).
        mailbox: Mutex::new(Mailbox {
            status: sim.core.status(),
            ..Mailbox::new()
        }),
        telemetry: Mutex::new(VecDeque::with_capacity(QUEUE)),
        supply_code: std::sync::atomic::AtomicU32::new(0),
    });
    let rt = Arc::clone(&shared);
    std::thread::spawn(move || {
        // Advance by as many position periods as (scaled) wall time allows, in slices of at
        // most SLICE of wall time with a pause after each, so that the protocol side always
        // has the processor when a request comes. A host that cannot keep up slows the
        // device's clock (the lag is forgiven: the clock slips) rather than its replies.
        let mut clock = Pacer::new(speed);
        loop {
            let dt = sim.core.controller().dt_pos() as f64;
            let due = clock.due();
            let slice = Instant::now();
            while sim.t + dt <= due && slice.elapsed() < SLICE {
                sim.tick(|st, c| rt.mailbox().exchange(st, c), &rt.telemetry, true);
            }
            rt.supply_code
                .store(sim.supply_code, std::sync::atomic::Ordering::Relaxed);
            clock.behind(sim.t);
            std::thread::sleep(PAUSE);
        }
    });
    let link = HostLink {
        shared: Arc::clone(&shared),
        start: Instant::now(),
    };
    // The scenario describes the axis: its defaults are configured for it.
    let mut dev = Front::new(
        link,
        flash_store,
        board,
        settings,
        defaults,
        requests,
        spare,
    )
    .with_configured(true, true)
    .with_table();
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
            let mut supervised = Instant::now();
            loop {
                let next = waiting.borrow_mut().pop_front().map(|(c, _)| c);
                let c = match next {
                    Some(c) => c,
                    None => match rx
                        .recv_timeout(Duration::from_millis(gms_core::device::SUPERVISE_MS))
                    {
                        Ok(c) => c,
                        // No client: the supply is still supervised (a hold stays on).
                        Err(std::sync::mpsc::RecvTimeoutError::Timeout) => {
                            supervise_every(&mut dev, &mut supervised);
                            continue;
                        }
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
