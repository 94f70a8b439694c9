//! The window's device link, off the UI thread: a thread that owns the [`Link`], runs what
//! the window asks ([`Cmd`]) one request at a time, polls `status`, streams the telemetry, and
//! reports back ([`Event`]); a lost link is reported and the link reopened every second.

use gms_core::protocol::Command;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Receiver, Sender, TryRecvError, channel};
use std::time::{Duration, Instant};

use crate::params::{self, Listed};
use crate::{Link, LinkError, parse_telemetry};

/// Where the device is.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Endpoint {
    /// A serial port (USB CDC-ACM or a PTY).
    Serial(String),
    /// A TCP address (`hil-sim serve --tcp`).
    Tcp(String),
}

impl Endpoint {
    /// Opens a link to it with the reply timeout `timeout`.
    pub fn open(&self, timeout: Duration) -> Result<Link, String> {
        match self {
            Endpoint::Serial(p) => Link::serial(p, timeout),
            Endpoint::Tcp(a) => Link::tcp(a, timeout),
        }
    }
}

impl std::fmt::Display for Endpoint {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Endpoint::Serial(p) => write!(f, "--port {p}"),
            Endpoint::Tcp(a) => write!(f, "--tcp {a}"),
        }
    }
}

/// What the window asks of the device.
#[derive(Debug, Clone, PartialEq)]
pub enum Cmd {
    /// `set PATH VALUE`, then the value read back with `get` (accepted or not).
    Set {
        /// Protocol path.
        path: String,
        /// The value as typed.
        value: String,
    },
    /// A typed request (`enable`, `clear`, `move 0.1`, `save`, …).
    Send(gms_core::protocol::Command<'static>),
    /// The console passthrough: one request line as the user typed it.
    Console(String),
    /// Read `list` again.
    List,
    /// Write the device's parameters to a parameter file (`params dump`).
    Dump(PathBuf),
    /// Send a parameter file as one set (`params load`), then read `list` again.
    Load(PathBuf),
    /// Send a parameter set as one set (a result to apply), then read `list` again.
    Apply(Box<gms_ident::paramfile::ParamFile>),
    /// Write a position map into the device and switch it on, then read `list` again.
    WriteMap(Box<gms_bench::posmap::PosMap>),
    /// Leave a learned correction playing for the next runs of the device's table.
    UseCorrection(Vec<f64>),
    /// A long run; [`Worker::stop`] ends it.
    Run(Job),
    /// End the worker.
    Quit,
}

/// A long run of the bench's experiments, the command line's code.
#[derive(Debug, Clone, PartialEq)]
pub enum Job {
    /// `gms-tune commission --speed SPEED --out OUT`.
    Commission {
        /// The back-EMF runs' base speed \[rad/s\].
        speed: f64,
        /// The motor file written.
        out: PathBuf,
    },
    /// `gms-tune tune-ff`.
    TuneFf(gms_bench::TuneFfPlan),
    /// `gms-tune identify --report REPORT --out OUT`.
    Identify {
        /// The experiments' CSVs, report and plots.
        report: PathBuf,
        /// The identified parameter file.
        out: PathBuf,
    },
    /// `gms-tune frf` (with `--suggest` for the open loop).
    Frf(gms_bench::frf::Plan),
    /// `gms-tune map`.
    Map(gms_bench::posmap::MapPlan),
    /// `gms-tune learn` (nothing left playing).
    Learn(gms_bench::learn::LearnPlan),
}

/// What a long run gave.
#[derive(Debug, Clone, PartialEq)]
pub enum Outcome {
    /// The commissioning's lines and its motor file (not applied).
    Commissioned {
        /// A line per step.
        lines: Vec<String>,
        /// The device's parameters with the settings found.
        file: Box<gms_ident::paramfile::ParamFile>,
    },
    /// The feedforward sweep (not applied).
    TunedFf(gms_bench::TuneFf),
    /// The identification (not applied).
    Identified {
        /// The fits' report.
        report: Vec<String>,
        /// Pre-sliding points (x \[rad\], f \[N·m\]).
        presliding: Vec<(f64, f64)>,
        /// Sliding points (v \[rad/s\], f \[N·m\]).
        sliding: Vec<(f64, f64)>,
        /// The identified set.
        file: Box<gms_ident::paramfile::ParamFile>,
    },
    /// A position map (not applied).
    Map {
        /// The samples each way.
        data: Box<gms_bench::posmap::MapData>,
        /// The map fitted.
        map: Box<gms_bench::posmap::PosMap>,
    },
    /// Learning from repetition (the correction not left playing).
    Learned(Box<gms_bench::learn::Learned>),
    /// A frequency response, and for the open loop the notch proposed (not applied).
    Frf {
        /// The sweep.
        sweep: Box<gms_bench::frf::Sweep>,
        /// The notch proposed, or why none.
        suggestion: Option<Result<gms_bench::frf::Suggestion, String>>,
        /// The device's filters when it was measured.
        shaping: gms_core::control::shaping::ShapingParams,
    },
}

/// A telemetry sample (SI: s, rad, N·m, A).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct TelemetrySample {
    /// Device time \[s\].
    pub t: f64,
    /// Position \[rad\].
    pub pos: f64,
    /// Reference \[rad\].
    pub reference: f64,
    /// Position error \[rad\].
    pub error: f64,
    /// Friction feedforward \[N·m\].
    pub ff: f64,
    /// Measured current \[A\].
    pub current: f64,
    /// The friction estimate k_M·i − J·a_ref \[N·m\].
    pub friction: f64,
}

/// The telemetry fields the window streams, in [`TelemetrySample`]'s order.
pub const FIELDS: &str = "t,pos,ref,error,ff,current,friction";

impl TelemetrySample {
    /// From a telemetry line's `name=value` pairs; `None` without a time.
    pub fn parse(line: &str) -> Option<TelemetrySample> {
        let kv = parse_telemetry(line);
        let get = |k: &str| kv.iter().find(|(n, _)| n == k).map(|(_, v)| *v);
        Some(TelemetrySample {
            t: get("t")?,
            pos: get("pos").unwrap_or(f64::NAN),
            reference: get("ref").unwrap_or(f64::NAN),
            error: get("error").unwrap_or(f64::NAN),
            ff: get("ff").unwrap_or(f64::NAN),
            current: get("current").unwrap_or(f64::NAN),
            friction: get("friction").unwrap_or(f64::NAN),
        })
    }
}

/// What the worker reports.
#[derive(Debug, Clone, PartialEq)]
pub enum Event {
    /// The link is up (again).
    Connected,
    /// The link is lost (the message says how); the worker retries every second.
    Lost(String),
    /// A reply came late (the message says how late); the link is kept: the device is slow,
    /// not gone, and its late reply is dropped when it comes.
    Late(String),
    /// `list`, parsed.
    Listed(Vec<Listed>),
    /// A `set`'s outcome: `Err` with the device's `err` line; `value` is the device's value
    /// read back after it (`None` if that failed too).
    Set {
        /// Protocol path.
        path: String,
        /// `Ok` or the device's error.
        result: Result<(), String>,
        /// The device's value now.
        value: Option<String>,
    },
    /// A request's outcome (its reply text, or the error).
    Reply {
        /// The request line.
        line: String,
        /// The text after `ok`, or the error.
        result: Result<String, String>,
    },
    /// The `status` reply, read.
    Status(gms_core::device::StatusReply),
    /// Telemetry samples, in order.
    Samples(Vec<TelemetrySample>),
    /// A long run's progress: its stage, and the device time done of what the stage expects.
    Progress {
        /// The stage.
        stage: String,
        /// Device seconds waited in it.
        done: f64,
        /// Device seconds it expects.
        total: f64,
    },
    /// A point of the feedforward sweep as it is measured (gain, RMS error \[rad\]).
    FfPoint(f64, f64),
    /// A point of a frequency response as it is measured.
    FrfPoint(gms_bench::frf::Point),
    /// An iteration of the learning as it comes.
    LearnPoint(gms_bench::ilc::Iteration),
    /// A long run ended: what it gave, or why not (the bridge is off then).
    Done(Result<Outcome, String>),
}

/// The window's side of the worker.
pub struct Worker {
    /// Commands to the worker.
    pub tx: Sender<Cmd>,
    /// Set to end a long run (the window's Stop); cleared when a run starts.
    pub stop: Arc<AtomicBool>,
    /// Its reports.
    pub rx: Receiver<Event>,
    handle: Option<std::thread::JoinHandle<()>>,
}

impl Worker {
    /// Starts the worker on `endpoint`; `wake` is called after each batch of events (the
    /// window's repaint request); `first` are request lines sent once, when the link first
    /// comes up (their replies reported).
    pub fn start(
        endpoint: Endpoint,
        timeout: Duration,
        first: Vec<String>,
        wake: impl Fn() + Send + 'static,
    ) -> Worker {
        let (tx, cmd_rx) = channel();
        let (ev_tx, rx) = channel();
        let stop = Arc::new(AtomicBool::new(false));
        let flag = stop.clone();
        let handle =
            std::thread::spawn(move || run(endpoint, timeout, first, cmd_rx, ev_tx, flag, wake));
        Worker {
            tx,
            stop,
            rx,
            handle: Some(handle),
        }
    }
}

impl Drop for Worker {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
        let _ = self.tx.send(Cmd::Quit);
        if let Some(h) = self.handle.take() {
            let _ = h.join();
        }
    }
}

/// How often `status` is read.
const STATUS_PERIOD: Duration = Duration::from_millis(100);

/// The worker's loop.
fn run(
    endpoint: Endpoint,
    timeout: Duration,
    mut first: Vec<String>,
    cmds: Receiver<Cmd>,
    events: Sender<Event>,
    stop: Arc<AtomicBool>,
    wake: impl Fn(),
) {
    let mut link: Option<Link> = None;
    let mut next_try = Instant::now();
    let mut next_status = Instant::now();
    let mut pace = Pace::new(1.0);
    let send = |e: Event| events.send(e).is_ok();
    loop {
        let Some(l) = link.as_mut() else {
            // Down: drain the commands (a quit ends it; the rest cannot run), retry each second.
            loop {
                match cmds.try_recv() {
                    Ok(Cmd::Quit) | Err(TryRecvError::Disconnected) => return,
                    Ok(c) => {
                        if !send(refused(&c, "no link to the device")) {
                            return;
                        }
                    }
                    Err(TryRecvError::Empty) => break,
                }
            }
            if Instant::now() >= next_try {
                next_try = Instant::now() + Duration::from_secs(1);
                let speed = pace.speed;
                match endpoint.open(timeout).and_then(|mut l| {
                    // The pace learnt before the link was lost (a device does not change it).
                    l.speed = speed;
                    start_session(&mut l).map_err(|e| e.to_string())?;
                    Ok(l)
                }) {
                    Ok(mut l) => {
                        pace = Pace::new(l.speed);
                        let listed = params::list(&mut l);
                        link = Some(l);
                        send(Event::Connected);
                        match listed {
                            Ok(v) => send(Event::Listed(v)),
                            Err(e) => send(Event::Lost(e.to_string())),
                        };
                        if let Some(l) = link.as_mut() {
                            for line in first.drain(..) {
                                if let Ok(evs) = execute(l, Cmd::Console(line)) {
                                    for e in evs {
                                        send(e);
                                    }
                                }
                            }
                        }
                        wake();
                    }
                    Err(e) => {
                        send(Event::Lost(e));
                        wake();
                    }
                }
            }
            std::thread::sleep(Duration::from_millis(20));
            continue;
        };
        let mut lost: Option<String> = None;
        let mut any = false;
        // The commands waiting.
        loop {
            match cmds.try_recv() {
                Ok(Cmd::Quit) | Err(TryRecvError::Disconnected) => {
                    let _ = l.ask(Command::StreamOff);
                    return;
                }
                Ok(Cmd::Run(job)) => {
                    stop.store(false, Ordering::SeqCst);
                    // The stream off during the run: its captures and waits need the link
                    // (on a virtual device faster than real time the stream alone can fill it).
                    let _ = l.ask(Command::StreamOff);
                    l.telemetry.clear();
                    let done = run_job(l, job, &stop, &events, &wake);
                    send(Event::Done(done));
                    wake();
                    if let Err(e) = start_session(l) {
                        lost = Some(e.to_string());
                        break;
                    }
                }
                Ok(c) => {
                    any = true;
                    match execute(l, c) {
                        Ok(evs) => {
                            for e in evs {
                                send(e);
                            }
                        }
                        Err(e) => {
                            lost = Some(e);
                            break;
                        }
                    }
                }
                Err(TryRecvError::Empty) => break,
            }
        }
        if lost.is_none() && Instant::now() >= next_status {
            next_status = Instant::now() + STATUS_PERIOD;
            match l.status() {
                Ok(st) => {
                    if let Some(rate) = pace.seen(st.t, l) {
                        // The device's pace changed: the stream at a rate the link carries.
                        if let Err(e) = stream(l, rate)
                            && gone(&e)
                        {
                            lost = Some(e.to_string());
                        }
                    }
                    send(Event::Status(st));
                    any = true;
                }
                // Late, not gone: the device still talks (or has not been silent long).
                Err(e @ LinkError::Timeout(_)) if l.silent_for() < SILENT_LOST => {
                    send(Event::Late(e.to_string()));
                    any = true;
                }
                // A reply that does not read: the device talks, the link is kept.
                Err(e) if !gone(&e) => {
                    send(Event::Reply {
                        line: "status".into(),
                        result: Err(e.to_string()),
                    });
                    any = true;
                }
                Err(e) => lost = Some(e.to_string()),
            }
        }
        if lost.is_none()
            && let Err(e) = l.listen(Duration::from_millis(10))
        {
            lost = Some(e.to_string());
        }
        let samples: Vec<TelemetrySample> = l
            .telemetry
            .drain(..)
            .filter_map(|(_, line)| TelemetrySample::parse(&line))
            .collect();
        if !samples.is_empty() {
            send(Event::Samples(samples));
            any = true;
        }
        if let Some(e) = lost {
            link = None;
            next_try = Instant::now() + Duration::from_secs(1);
            send(Event::Lost(e));
            any = true;
        }
        if any {
            wake();
        }
    }
}

/// The telemetry's rate \[Hz of device time\] on a device that runs in real time.
const STREAM_HZ: f64 = 1000.0;

/// A device silent this long (no reply, no telemetry) is taken as lost.
const SILENT_LOST: Duration = Duration::from_secs(5);

/// A new session: the telemetry stream at the rate for the device's pace.
fn start_session(l: &mut Link) -> Result<(), LinkError> {
    stream(l, Pace::rate(l.speed))
}

/// The telemetry stream at `rate_hz` \[Hz of device time\].
fn stream(l: &mut Link, rate_hz: f64) -> Result<(), LinkError> {
    l.ask(Command::Stream {
        fields: FIELDS,
        rate_hz: rate_hz as f32,
    })?;
    Ok(())
}

/// The device's pace (device seconds per wall second: 1 on a board, about F on `hil-sim serve
/// --speed F`, less on a host that cannot keep up), from the clock in its `status` replies.
/// The telemetry's rate follows it, so that the stream stays within what the link and the
/// window carry (about [`STREAM_HZ`] lines a wall second): on a virtual device twenty times
/// faster than real time a stream of 1 kHz of device time would be 20 000 lines a second,
/// and every reply would queue behind them.
struct Pace {
    last: Option<(f64, Instant)>,
    /// The pace last learnt.
    speed: f64,
    /// The rate the stream was set to \[Hz of device time\].
    streamed: f64,
}

impl Pace {
    /// At the pace `speed`, the stream at its rate.
    fn new(speed: f64) -> Pace {
        Pace {
            last: None,
            speed,
            streamed: Pace::rate(speed),
        }
    }

    /// The stream's rate \[Hz of device time\] at the pace `speed`.
    fn rate(speed: f64) -> f64 {
        (STREAM_HZ / speed.max(1.0)).max(10.0)
    }

    /// The device's clock `t` \[s\] read now: the pace learnt (into [`Link::speed`], which
    /// also stretches the replies' timeout on a slow device); a new stream rate when it has
    /// moved by more than half.
    fn seen(&mut self, t: f64, l: &mut Link) -> Option<f64> {
        let now = Instant::now();
        let Some((t0, w0)) = self.last else {
            self.last = Some((t, now));
            return None;
        };
        let wall = now.duration_since(w0).as_secs_f64();
        if wall < 0.5 {
            return None;
        }
        self.last = Some((t, now));
        if t <= t0 {
            // The device restarted (its clock from 0) or stood still: nothing learnt.
            return None;
        }
        l.speed = ((t - t0) / wall).clamp(0.01, 1000.0);
        self.speed = l.speed;
        let want = Pace::rate(l.speed);
        if !(0.5..=2.0).contains(&(want / self.streamed)) {
            self.streamed = want;
            return Some(want);
        }
        None
    }
}

/// The report for a command that could not run.
fn refused(c: &Cmd, why: &str) -> Event {
    match c {
        Cmd::Set { path, .. } => Event::Set {
            path: path.clone(),
            result: Err(why.to_string()),
            value: None,
        },
        other => Event::Reply {
            line: format!("{other:?}"),
            result: Err(why.to_string()),
        },
    }
}

/// Whether a request changes the settings wholesale (`load`, `defaults`, `commit`): `list` is
/// read again after it.
fn wholesale(c: Command<'_>) -> bool {
    matches!(c, Command::Load | Command::Defaults | Command::Commit)
}

/// A request's reply as an event, and `list` read again after one that changed the settings
/// wholesale; `Err` when the link is lost.
fn replied(
    l: &mut Link,
    out: &mut Vec<Event>,
    line: String,
    result: Result<String, LinkError>,
    changes: bool,
) -> Result<(), String> {
    let result = match result {
        Ok(t) => Ok(t),
        Err(e) if gone(&e) => return Err(e.to_string()),
        Err(e) => Err(e.to_string()),
    };
    let reread = result.is_ok() && changes;
    out.push(Event::Reply { line, result });
    if reread {
        out.push(Event::Listed(params::list(l).map_err(|e| e.to_string())?));
    }
    Ok(())
}

/// Whether a link error means the link is gone (not just a refusal).
fn gone(e: &LinkError) -> bool {
    matches!(
        e,
        LinkError::Io(_) | LinkError::Timeout(_) | LinkError::Bench(gms_bench::Error::Link(_))
    )
}

/// Runs one command; `Err` when the link is lost on the way.
fn execute(l: &mut Link, c: Cmd) -> Result<Vec<Event>, String> {
    let mut out = Vec::new();
    match c {
        Cmd::Set { path, value } => {
            let result = match l.ask(Command::Set(&path, &value)) {
                Ok(_) => Ok(()),
                Err(e) if gone(&e) => return Err(e.to_string()),
                Err(e) => Err(e.to_string()),
            };
            // The device's value, whatever happened: nothing is assumed changed.
            let value = match l.ask(Command::Get(&path)) {
                Ok((_, v)) => Some(v.trim().to_string()),
                Err(e) if gone(&e) => return Err(e.to_string()),
                Err(_) => None,
            };
            out.push(Event::Set {
                path,
                result,
                value,
            });
        }
        Cmd::Send(c) => {
            let result = l.ask_text(c);
            replied(l, &mut out, c.to_string(), result, wholesale(c))?;
        }
        Cmd::Console(line) => {
            let result = l.console_text(&line);
            let changes = gms_core::protocol::parse(&line).is_ok_and(wholesale);
            replied(l, &mut out, line, result, changes)?;
        }
        Cmd::List => out.push(Event::Listed(params::list(l).map_err(|e| e.to_string())?)),
        Cmd::Dump(path) => {
            let result = match params::read(l) {
                Ok(pf) => {
                    std::fs::write(&path, format!("# gms-tune params dump\n{}", pf.to_toml()))
                        .map(|_| format!("written to {}", path.display()))
                        .map_err(|e| format!("{}: {e}", path.display()))
                }
                Err(e) if gone(&e) => return Err(e.to_string()),
                Err(e) => Err(e.to_string()),
            };
            out.push(Event::Reply {
                line: format!("params dump {}", path.display()),
                result,
            });
        }
        Cmd::Load(path) => {
            let result = params::load(l, &path)
                .map(|n| format!("{n} parameters loaded from {}", path.display()))
                .map_err(|e| e.to_string());
            out.push(Event::Reply {
                line: format!("params load {}", path.display()),
                result,
            });
            out.push(Event::Listed(params::list(l).map_err(|e| e.to_string())?));
        }
        Cmd::Apply(pf) => {
            let result = gms_bench::load_params(l, &pf)
                .map(|n| format!("{n} parameters loaded"))
                .map_err(|e| e.to_string());
            out.push(Event::Reply {
                line: "apply".into(),
                result,
            });
            out.push(Event::Listed(params::list(l).map_err(|e| e.to_string())?));
        }
        Cmd::WriteMap(m) => {
            let result = gms_bench::posmap::write(l, &m, true)
                .map(|n| format!("{n} bins written, map.enable 1"))
                .map_err(|e| e.to_string());
            out.push(Event::Reply {
                line: "map write".into(),
                result,
            });
            out.push(Event::Listed(params::list(l).map_err(|e| e.to_string())?));
        }
        Cmd::UseCorrection(u) => {
            let result = gms_bench::learn::use_correction(l, &u)
                .map(|_| "the correction plays from the next table run".to_string())
                .map_err(|e| e.to_string());
            out.push(Event::Reply {
                line: "table use".into(),
                result,
            });
        }
        Cmd::Run(_) | Cmd::Quit => {}
    }
    Ok(out)
}

/// The window's hooks for a long run: its progress (the stream is off during a run).
struct Reporter<'e> {
    events: &'e Sender<Event>,
    wake: &'e dyn Fn(),
    stage: String,
    done: f64,
    total: f64,
    last: Instant,
}

impl crate::run::Hooks for Reporter<'_> {
    fn stage(&mut self, what: &str, seconds: f64) {
        (self.stage, self.done, self.total) = (what.to_string(), 0.0, seconds);
        self.report();
    }

    fn waited(&mut self, seconds: f64) {
        self.done += seconds;
        if self.last.elapsed() >= Duration::from_millis(50) {
            self.report();
        }
    }
}

impl Reporter<'_> {
    fn report(&mut self) {
        self.last = Instant::now();
        let _ = self.events.send(Event::Progress {
            stage: self.stage.clone(),
            done: self.done,
            total: self.total,
        });
        (self.wake)();
    }
}

/// Runs a long job with the command line's code; the stop flag ends it.
fn run_job(
    l: &mut Link,
    job: Job,
    stop: &Arc<AtomicBool>,
    events: &Sender<Event>,
    wake: &dyn Fn(),
) -> Result<Outcome, String> {
    let mut rep = Reporter {
        events,
        wake,
        stage: String::new(),
        done: 0.0,
        total: 0.0,
        last: Instant::now(),
    };
    let mut ctl = crate::jobs::Control {
        stop: stop.clone(),
        why: "stopped (the window's Stop)",
        hooks: &mut rep,
    };
    match job {
        Job::Commission { speed, out } => {
            let c = crate::jobs::commission(l, speed, Some(&out), &mut ctl)
                .map_err(|e| format!("{e}; the bridge is off, nothing changed"))?;
            let mut lines = c.commissioned.lines;
            lines.push(format!("wrote {}", out.display()));
            Ok(Outcome::Commissioned {
                lines,
                file: Box::new(c.file),
            })
        }
        Job::TuneFf(plan) => {
            let t = crate::jobs::tune_ff(l, &plan, None, &mut ctl, &mut |_, g, rms| {
                let _ = events.send(Event::FfPoint(g, rms));
            })
            .map_err(|e| format!("{e}; the bridge is off, ff.gain as it was"))?;
            Ok(Outcome::TunedFf(t))
        }
        Job::Map(plan) => {
            let (data, map) = crate::jobs::map(l, &plan, None, &mut ctl)
                .map_err(|e| format!("{e}; the bridge is off, the settings as they were"))?;
            Ok(Outcome::Map {
                data: Box::new(data),
                map: Box::new(map),
            })
        }
        Job::Learn(plan) => {
            let learned = crate::jobs::learn(l, &plan, None, false, &mut ctl, &mut |it| {
                let _ = events.send(Event::LearnPoint(*it));
                wake();
            })
            .map_err(|e| format!("{e}; the bridge is off"))?;
            Ok(Outcome::Learned(Box::new(learned)))
        }
        Job::Frf(plan) => {
            let sweep = crate::jobs::frf(l, &plan, None, &mut ctl, &mut |_, p| {
                let _ = events.send(Event::FrfPoint(*p));
            })
            .map_err(|e| format!("{e}; the bridge is off, the settings as they were"))?;
            let settings = gms_bench::settings::read(l).map_err(|e| e.to_string())?;
            let suggestion = (plan.lp == gms_bench::frf::Loop::Open).then(|| {
                gms_bench::frf::suggest_notch(
                    &sweep.points,
                    &settings.shaping,
                    settings.pos_rate_hz as f64,
                )
            });
            Ok(Outcome::Frf {
                sweep: Box::new(sweep),
                suggestion,
                shaping: settings.shaping,
            })
        }
        Job::Identify { report, out } => {
            let (_, plans) = crate::jobs::identify_plans(l, &gms_bench::Ranges::default())
                .map_err(|e| e.to_string())?;
            let id = crate::jobs::identify(l, &plans, &report, Some(&out), 6, false, &mut ctl)
                .map_err(|e| e.to_string())?;
            let mut lines = id.identified.report;
            lines.push(format!(
                "wrote {} and the report in {}",
                out.display(),
                report.display()
            ));
            Ok(Outcome::Identified {
                report: lines,
                presliding: id.gathered.presliding,
                sliding: id.gathered.sliding,
                file: Box::new(id.file),
            })
        }
    }
}
