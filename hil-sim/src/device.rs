//! The virtual device: the simulated axis running in real time behind the same protocol
//! handler as the firmware (`gms_core::protocol`), served over TCP (`hil-sim serve --tcp`).
//!
//! Clients are served one after another; a client that drops does not stop the device. With
//! `--store FILE`, `save` writes the settings there atomically (temporary file + rename, so a
//! crash leaves the old or the new set) and a restart starts from them.

use std::fmt::Write as _;
use std::io::{ErrorKind, Read, Write};
use std::net::TcpListener;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use gms_core::controller::{Controller, FfMode};
use gms_core::protocol::{self, Access, Device, LineReader, PARAMS, Settings};
use gms_core::reference::{Motion, SUB_PER_COUNT};

use crate::commands::write_atomic;
use crate::plant::Plant;
use crate::scenario::{FF_BLOCKS, Scenario};

/// Telemetry fields `stream` accepts.
pub const FIELDS: [&str; 7] = ["t", "pos", "ref", "error", "ff", "current", "friction"];

/// The latest values of the axis, for `status` and telemetry.
#[derive(Debug, Clone, Copy, Default)]
pub struct Sample {
    /// Time since start [s].
    pub t: f64,
    /// Encoder position [rad].
    pub pos: f64,
    /// Reference position [rad].
    pub reference: f64,
    /// Position error [rad].
    pub error: f64,
    /// Friction feedforward [N·m].
    pub ff: f64,
    /// Motor current [A].
    pub current: f64,
    /// True friction [N·m].
    pub friction: f64,
}

/// The simulated axis with its controller.
pub struct Axis {
    sc: Scenario,
    plant: Plant,
    ctrl: Controller<FF_BLOCKS>,
    settings: Settings,
    enabled: bool,
    faults: u32,
    motion: Motion,
    t: f64,
    last: Sample,
    /// The last [`HISTORY`] samples, one per position period, for telemetry.
    history: std::collections::VecDeque<Sample>,
}

/// Samples kept for telemetry (0.2 s at 10 kHz).
pub const HISTORY: usize = 2000;

impl Axis {
    /// A device at rest with `settings`.
    pub fn new(sc: Scenario, settings: Settings, faults: u32) -> Result<Axis, String> {
        let plant = Plant::new(&sc.plant, sc.plant.seed)?;
        let ctrl = Controller::try_new(settings).map_err(|e| e.to_string())?;
        Ok(Axis {
            sc,
            plant,
            ctrl,
            settings,
            enabled: false,
            faults,
            motion: Motion::holding(0),
            t: 0.0,
            last: Sample::default(),
            history: std::collections::VecDeque::with_capacity(HISTORY),
        })
    }

    fn rpc(&self) -> f64 {
        self.sc.plant.rad_per_count
    }

    /// One position-loop period of the device.
    pub fn tick(&mut self) {
        let dt = self.ctrl.dt_pos();
        let r = self.motion.next(dt);
        let count = self.plant.encoder();
        let out = if self.enabled {
            self.ctrl.position_step(count, &r)
        } else {
            Default::default()
        };
        let n = self.settings.ratio();
        let dt_plant = self.ctrl.dt_cur() as f64 / self.sc.plant.substeps as f64;
        for _ in 0..n {
            let i = self.plant.adc();
            let duty = if self.enabled {
                self.ctrl.current_step(i).duty
            } else {
                0.0
            };
            self.plant.set_duty(duty);
            for _ in 0..self.sc.plant.substeps {
                self.plant.step(dt_plant);
            }
        }
        self.t += dt as f64;
        let rpc = self.rpc();
        let reference = r.pos as f64 / SUB_PER_COUNT as f64 * rpc;
        let pos = count as f64 * rpc;
        self.last = Sample {
            t: self.t,
            pos,
            reference,
            error: reference - pos,
            ff: out.ff_friction as f64,
            current: self.plant.i,
            friction: self.plant.friction,
        };
        if self.history.len() == HISTORY {
            self.history.pop_front();
        }
        self.history.push_back(self.last);
    }

    /// Applies a validated parameter set (between two control steps); the controller keeps
    /// no state across it.
    pub fn apply(&mut self, s: Settings) -> Result<(), String> {
        let scale = self.ctrl.adaptive_scale();
        self.ctrl = Controller::try_new(s).map_err(|e| e.to_string())?;
        // What the adaptation learned is about the axis, not the settings: keep it.
        self.ctrl.set_adaptive_scale(scale);
        self.settings = s;
        Ok(())
    }
}

/// The device shared by the real-time thread and the client sessions.
pub struct Shared {
    axis: Mutex<Axis>,
    store: Option<PathBuf>,
    defaults: Settings,
}

impl Shared {
    fn lock(&self) -> MutexGuard<'_, Axis> {
        self.axis.lock().unwrap_or_else(|p| p.into_inner())
    }
}

/// The settings as TOML: one protocol path per key.
pub fn settings_toml(s: &Settings) -> String {
    let mut out = String::from("# gms device settings: protocol paths and values (SI units)\n");
    for p in PARAMS {
        let _ = match p.access {
            Access::Number { get, .. } => writeln!(out, "\"{}\" = {}", p.path, get(s)),
            Access::Mode => {
                let mut v = String::new();
                let _ = protocol::write_value(p, s, &mut v);
                writeln!(out, "\"{}\" = \"{v}\"", p.path)
            }
            // Estimates are the device's state, not settings.
            Access::Estimate(_) => Ok(()),
        };
    }
    out
}

/// Reads settings written by [`settings_toml`] (keys may be missing: `base` fills them).
pub fn settings_from_toml(text: &str, base: &Settings) -> Result<Settings, String> {
    let table: toml::Table = toml::from_str(text).map_err(|e| e.message().to_string())?;
    let mut s = *base;
    for (k, v) in &table {
        let value = match v {
            toml::Value::Float(f) => format!("{f}"),
            toml::Value::Integer(i) => format!("{i}"),
            toml::Value::String(t) => t.clone(),
            _ => return Err(format!("`{k}`: not a number or a name")),
        };
        let p = protocol::find(k).ok_or_else(|| format!("unknown parameter `{k}`"))?;
        // Set without validating the intermediate sets; the whole set is validated below.
        match p.access {
            Access::Number { set, min, max, .. } => {
                let x = protocol::parse_f32(&value)
                    .filter(|x| *x >= min && *x <= max)
                    .ok_or_else(|| format!("`{k}` = {value} is out of range"))?;
                set(&mut s, x);
            }
            Access::Mode => {
                s.ff.mode = FfMode::from_name(&value).ok_or_else(|| {
                    format!("`{k}` = {value} is not none, static, gms or gms-adaptive")
                })?;
            }
            Access::Estimate(_) => return Err(format!("`{k}` is read-only")),
        }
    }
    s.validate().map_err(|e| e.to_string())?;
    Ok(s)
}

/// The start-up settings: the store's when it is valid, else the defaults and a fault flag.
fn startup(store: Option<&Path>, defaults: &Settings) -> (Settings, u32, Option<String>) {
    let Some(path) = store else {
        return (*defaults, 0, None);
    };
    match std::fs::read_to_string(path) {
        Err(e) if e.kind() == ErrorKind::NotFound => (*defaults, 0, None),
        Err(e) => (*defaults, 1, Some(format!("{}: {e}", path.display()))),
        Ok(text) => match settings_from_toml(&text, defaults) {
            Ok(s) => (s, 0, None),
            Err(e) => (*defaults, 1, Some(format!("{}: {e}", path.display()))),
        },
    }
}

/// One client's view of the device.
struct Session<'a> {
    shared: &'a Shared,
    snapshot: Settings,
    stream: Option<(Vec<usize>, f64)>,
}

impl Device for Session<'_> {
    fn settings(&self) -> &Settings {
        &self.snapshot
    }
    fn apply(&mut self, new: Settings) {
        if self.shared.lock().apply(new).is_ok() {
            self.snapshot = new;
        }
    }
    fn save(&mut self) -> Result<(), &'static str> {
        let axis = self.shared.lock();
        if axis.enabled {
            return Err("disable before save");
        }
        let path = self
            .shared
            .store
            .as_ref()
            .ok_or("no store (start with --store FILE)")?;
        write_atomic(path, settings_toml(&axis.settings).as_bytes())
            .map_err(|_| "store write failed")
    }
    fn load(&mut self) -> Result<(), &'static str> {
        let path = self
            .shared
            .store
            .as_ref()
            .ok_or("no store (start with --store FILE)")?;
        let text = std::fs::read_to_string(path).map_err(|_| "nothing saved")?;
        let s = settings_from_toml(&text, &self.shared.defaults).map_err(|_| "store invalid")?;
        let mut axis = self.shared.lock();
        if axis.enabled {
            return Err("disable before load");
        }
        axis.apply(s).map_err(|_| "store invalid")?;
        self.snapshot = s;
        Ok(())
    }
    fn defaults(&mut self) {
        let d = self.shared.defaults;
        if self.shared.lock().apply(d).is_ok() {
            self.snapshot = d;
        }
    }
    fn enable(&mut self) -> Result<(), &'static str> {
        let mut axis = self.shared.lock();
        if axis.faults != 0 {
            return Err("fault latched (clear first)");
        }
        let s = axis.settings;
        axis.apply(s).map_err(|_| "invalid settings")?;
        let here = axis.plant.encoder() * SUB_PER_COUNT as i64;
        axis.motion.hold_at(here);
        axis.enabled = true;
        Ok(())
    }
    fn disable(&mut self) {
        let mut axis = self.shared.lock();
        axis.enabled = false;
        axis.motion.stop();
    }
    fn status(&self, out: &mut dyn std::fmt::Write) -> std::fmt::Result {
        let axis = self.shared.lock();
        let l = axis.last;
        let rpc = axis.rpc();
        write!(
            out,
            "mode={} enabled={} faults={} t={:.3} pos={:.9} error_counts={:.1} moving={}",
            axis.settings.ff.mode.name(),
            axis.enabled as u8,
            axis.faults,
            l.t,
            l.pos,
            l.error / rpc,
            axis.motion.is_moving() as u8
        )
    }
    fn clear(&mut self) {
        self.shared.lock().faults = 0;
    }
    fn move_to(&mut self, pos: f32, vel: Option<f32>) -> Result<(), &'static str> {
        let mut axis = self.shared.lock();
        if !axis.enabled {
            return Err("disabled (enable first)");
        }
        let r = Motion::plan(axis.motion.hold(), pos, vel, axis.rpc() as f32)
            .map_err(|_| "bad move")?;
        axis.motion.start(r);
        Ok(())
    }
    fn stream(&mut self, fields: &str, rate_hz: f32) -> Result<(), &'static str> {
        let idx: Option<Vec<usize>> = fields
            .split(',')
            .map(|f| FIELDS.iter().position(|x| *x == f))
            .collect();
        let idx = idx.ok_or("unknown field (t, pos, ref, error, ff, current, friction)")?;
        if rate_hz > 1000.0 {
            return Err("rate above 1000 Hz");
        }
        self.stream = Some((idx, rate_hz as f64));
        Ok(())
    }
    fn stream_off(&mut self) {
        self.stream = None;
    }
    fn estimate(&self, which: protocol::Estimate) -> f32 {
        match which {
            protocol::Estimate::AdaptScale => self.shared.lock().ctrl.adaptive_scale(),
        }
    }
}

fn telemetry(s: &Sample, fields: &[usize]) -> String {
    let mut line = String::from("#");
    for &f in fields {
        let v = match f {
            0 => s.t,
            1 => s.pos,
            2 => s.reference,
            3 => s.error,
            4 => s.ff,
            5 => s.current,
            _ => s.friction,
        };
        let _ = write!(line, " {}={v:e}", FIELDS[f]);
    }
    line.push('\n');
    line
}

/// Serves one client until it disconnects. `conn` reads must not block for long: a TCP
/// socket with a read timeout, or a non-blocking PTY master.
fn serve_client<C: Read + Write>(shared: &Shared, mut conn: C) {
    let mut session = Session {
        shared,
        snapshot: shared.lock().settings,
        stream: None,
    };
    let mut reader = LineReader::default();
    let mut buf = [0u8; 512];
    // Telemetry: the device's own samples, decimated to the requested rate, from the time
    // the stream started.
    let mut next_t = f64::NEG_INFINITY;
    loop {
        match conn.read(&mut buf) {
            Ok(0) => return,
            Ok(n) => {
                let mut reply = String::new();
                for &b in &buf[..n] {
                    if let Some(line) = reader.push(b) {
                        session.snapshot = shared.lock().settings;
                        let _ = protocol::execute(&mut session, line, &mut reply);
                    }
                }
                if conn.write_all(reply.as_bytes()).is_err() {
                    return;
                }
            }
            Err(e) if e.kind() == ErrorKind::WouldBlock => {
                std::thread::sleep(Duration::from_millis(2))
            }
            Err(e) if e.kind() == ErrorKind::TimedOut => {}
            Err(_) => return,
        }
        match &session.stream {
            Some((fields, rate)) => {
                let mut lines = String::new();
                {
                    let axis = shared.lock();
                    if next_t == f64::NEG_INFINITY {
                        next_t = axis.last.t;
                    }
                    for smp in axis.history.iter() {
                        if smp.t >= next_t {
                            lines += &telemetry(smp, fields);
                            next_t = smp.t + 1.0 / rate - 1e-9;
                        }
                    }
                }
                if !lines.is_empty() && conn.write_all(lines.as_bytes()).is_err() {
                    return;
                }
            }
            None => next_t = f64::NEG_INFINITY,
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

/// Runs the device: the axis in real time on its own thread, clients in turn. `on_ready`
/// receives the address (TCP address or PTY path) and any start-up fault before the first
/// client.
pub fn serve(
    sc: Scenario,
    endpoint: Endpoint,
    store: Option<PathBuf>,
    on_ready: impl FnOnce(&str, Option<&str>),
) -> Result<(), String> {
    let defaults = sc.controller_params()?;
    let (settings, faults, why) = startup(store.as_deref(), &defaults);
    let axis = Axis::new(sc, settings, faults)?;
    let shared = Arc::new(Shared {
        axis: Mutex::new(axis),
        store,
        defaults,
    });
    let rt = Arc::clone(&shared);
    std::thread::spawn(move || {
        // Real time: advance by as many position periods as wall time allows.
        let start = Instant::now();
        loop {
            let mut axis = rt.lock();
            let dt = axis.ctrl.dt_pos() as f64;
            let due = start.elapsed().as_secs_f64();
            let mut n = 0;
            while axis.t + dt <= due && n < 200 {
                axis.tick();
                n += 1;
            }
            if n == 200 {
                // Cannot keep up: skip ahead rather than fall ever further behind.
                axis.t = due;
            }
            drop(axis);
            std::thread::sleep(Duration::from_millis(1));
        }
    });
    match endpoint {
        Endpoint::Tcp(listener) => {
            let addr = listener
                .local_addr()
                .map_err(|e| e.to_string())?
                .to_string();
            on_ready(&addr, why.as_deref());
            for conn in listener.incoming() {
                let Ok(c) = conn else { continue };
                let _ = c.set_read_timeout(Some(Duration::from_millis(2)));
                let _ = c.set_nodelay(true);
                serve_client(&shared, c);
            }
            Ok(())
        }
        #[cfg(unix)]
        Endpoint::Pty => serve_pty(&shared, |path| on_ready(path, why.as_deref())),
    }
}

/// Serves the protocol on a pseudo-terminal. The device keeps the slave open too, so a client
/// that closes it does not end the session: the next one finds the device where it was.
#[cfg(unix)]
fn serve_pty(shared: &Shared, on_ready: impl FnOnce(&str)) -> Result<(), String> {
    use nix::fcntl::{FcntlArg, OFlag, fcntl};
    use nix::sys::termios::{SetArg, cfmakeraw, tcgetattr, tcsetattr};

    let pty = nix::pty::openpty(None, None).map_err(|e| format!("openpty: {e}"))?;
    let mut t = tcgetattr(&pty.slave).map_err(|e| format!("tcgetattr: {e}"))?;
    cfmakeraw(&mut t);
    tcsetattr(&pty.slave, SetArg::TCSANOW, &t).map_err(|e| format!("tcsetattr: {e}"))?;
    let path = nix::unistd::ttyname(&pty.slave).map_err(|e| format!("ttyname: {e}"))?;
    fcntl(&pty.master, FcntlArg::F_SETFL(OFlag::O_NONBLOCK)).map_err(|e| format!("fcntl: {e}"))?;
    on_ready(&path.display().to_string());
    let master = std::fs::File::from(pty.master);
    let _slave = pty.slave;
    loop {
        // serve_client returns only on an I/O error; start over after a pause.
        serve_client(shared, &master);
        std::thread::sleep(Duration::from_millis(10));
    }
}
