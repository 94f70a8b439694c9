//! The virtual device in-process: the loop and the front stepped by the caller, for tests and
//! the bench workflows run without a link.

use super::*;
use gms_link::DeviceLink;

/// The virtual device in-process and in simulated time: the same core, plant and store as
/// [`serve`], with the protocol's waits driving the simulation instead of a real-time thread
/// (deterministic: every run of the same requests gives the same numbers). For tests and
/// scripted experiments.
pub struct LocalDevice {
    dev: Front<LocalLink, FlashStore<HostFlash>>,
    /// The simulated time of the next supply supervision \[s\] (every
    /// [`gms_core::device::SUPERVISE_MS`], as a board's shell).
    next_supervise: f64,
}

/// The in-process link: waiting on the loop runs it one position period.
struct LocalLink {
    sim: Sim,
    mailbox: Mailbox,
    queue: Mutex<VecDeque<Sample>>,
}

impl LoopLink for LocalLink {
    fn with_mailbox<R>(&mut self, f: impl FnOnce(&mut Mailbox) -> R) -> R {
        f(&mut self.mailbox)
    }
    fn now_us(&self) -> u64 {
        (self.sim.t * 1e6) as u64
    }
    fn pause(&mut self) {
        self.tick();
    }
    fn supply_code(&mut self) -> u32 {
        self.sim.supply_code
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
            dev: Front::new(
                link, p.store, p.board, p.settings, p.defaults, p.requests, p.spare,
            )
            .with_configured(true, true)
            .with_table(),
            next_supervise: 0.0,
        })
    }

    /// The console passthrough, typed: one raw request line (a test's, a console's: host
    /// code sends [`gms_core::protocol::Command`]s through [`DeviceLink::request`]); the
    /// lines before its `ok` and the text after it, or the device's `err` as
    /// [`gms_link::Error::Refused`].
    pub fn console(&mut self, line: &str) -> Result<(Vec<String>, String), gms_link::Error> {
        let reply = self.ask(line);
        let mut lines: Vec<String> = reply.lines().map(String::from).collect();
        let last = lines.pop().unwrap_or_default();
        match gms_link::reply_line(&last)? {
            Some(text) => Ok((lines, text.to_string())),
            None => Err(gms_link::Error::Reply(format!(
                "the reply did not end with `ok` or `err`: {last:?}"
            ))),
        }
    }

    /// The console passthrough, raw: one request line; the reply as the device wrote it (its
    /// lines, the last `ok …` or `err …`).
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

    /// Starts recording the truth at every position step (dropping what was recorded).
    pub fn record_truth(&mut self) {
        self.dev.link_mut().sim.truth = Some(Vec::new());
    }

    /// The truth recorded since [`LocalDevice::record_truth`] (recording stops).
    pub fn take_truth(&mut self) -> Vec<Truth> {
        self.dev.link_mut().sim.truth.take().unwrap_or_default()
    }

    /// Runs the device for `seconds` of simulated time.
    pub fn run(&mut self, seconds: f64) {
        let end = self.dev.link_mut().sim.t + seconds;
        loop {
            let link = self.dev.link_mut();
            if link.sim.t >= end {
                break;
            }
            link.tick();
            let t = link.sim.t;
            if t >= self.next_supervise {
                self.next_supervise = t + gms_core::device::SUPERVISE_MS as f64 * 1e-3;
                self.dev.supervise();
            }
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

/// The device as a link to a device (`gms_link`): the bench's workflows run on it in
/// simulated time, through the same protocol as on a board.
impl DeviceLink for LocalDevice {
    fn request(
        &mut self,
        c: gms_core::protocol::Command<'_>,
    ) -> Result<(Vec<String>, String), gms_link::Error> {
        self.console(&c.to_string())
    }

    fn pass(&mut self, seconds: f64) -> Result<(), gms_link::Error> {
        if seconds.is_finite() && seconds > 0.0 {
            self.run(seconds);
        }
        Ok(())
    }
}
