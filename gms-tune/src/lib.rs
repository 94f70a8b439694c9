//! The bench tool's link to a device (`gms-tune`): a serial port or TCP, one request line at
//! a time, replies read up to their `ok`/`err` line, telemetry (`#` lines) set aside.

pub mod jobs;
pub mod params;
pub mod run;
#[cfg(feature = "ui")]
pub mod ui;

use gms_core::device::StatusReply;
use gms_core::protocol::{Command, Reply};
use std::io::{ErrorKind, Read, Write};
use std::time::{Duration, Instant};

/// A byte stream to the device.
pub trait Stream: Read + Write + Send {}
impl<T: Read + Write + Send> Stream for T {}

/// The link: a stream, what has been read but not used, and the reply timeout.
pub struct Link {
    io: Box<dyn Stream>,
    pending: Vec<u8>,
    timeout: Duration,
    /// Telemetry lines received while waiting for replies (without the `#`).
    pub telemetry: Vec<(Instant, String)>,
    /// Device seconds per wall second, as last seen by [`Link::wait_device`] (1 on a board,
    /// F on `hil-sim serve --speed F`).
    pub speed: f64,
    /// Replies owed to requests that timed out: when they come late they are read and
    /// dropped, so that a later request never takes an earlier one's reply.
    owed: usize,
    /// When the last byte arrived.
    last_rx: Instant,
}

/// What went wrong talking to the device.
#[derive(Debug)]
pub enum LinkError {
    /// No reply within the timeout.
    Timeout(Duration),
    /// The device refused the request (`err CODE REASON`, read by
    /// [`gms_core::protocol::Reply`]).
    Device(gms_link::Refusal),
    /// The device answered, but not as the protocol reads (an `err` without a known code,
    /// a `status` that does not parse): the link is up, the reply is wrong.
    Reply(String),
    /// A bench step on the link failed (its own message: [`gms_bench::Error`]).
    Bench(gms_bench::Error),
    /// The connection failed or closed.
    Io(String),
}

impl std::fmt::Display for LinkError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            LinkError::Timeout(d) => write!(f, "timeout: no reply within {} ms", d.as_millis()),
            LinkError::Device(r) => r.fmt(f),
            LinkError::Reply(m) => write!(f, "unreadable reply: {m}"),
            LinkError::Bench(e) => e.fmt(f),
            LinkError::Io(e) => write!(f, "link: {e}"),
        }
    }
}

impl LinkError {
    /// As a link's failure ([`gms_link::Error`]): the device's `err` reply typed, an
    /// unreadable reply, or the link lost (a timeout, a failed connection, a bench step's
    /// failure with its message).
    pub fn into_link(self) -> gms_link::Error {
        match self {
            LinkError::Device(r) => gms_link::Error::Refused(r),
            LinkError::Reply(_) => gms_link::Error::Reply(self.to_string()),
            LinkError::Bench(_) | LinkError::Timeout(_) | LinkError::Io(_) => {
                gms_link::Error::Lost(self.to_string())
            }
        }
    }
}

impl Link {
    /// Opens `--tcp HOST:PORT`.
    pub fn tcp(addr: &str, timeout: Duration) -> Result<Link, String> {
        let s = std::net::TcpStream::connect(addr).map_err(|e| format!("--tcp {addr}: {e}"))?;
        s.set_read_timeout(Some(Duration::from_millis(10)))
            .map_err(|e| e.to_string())?;
        let _ = s.set_nodelay(true);
        Ok(Self::new(Box::new(s), timeout))
    }

    /// Opens a serial port: a board's USB CDC-ACM port (which ignores the baud rate), the
    /// NUCLEO's ST-LINK virtual COM port (a UART at gms-core's `protocol::UART_BAUD`, 8N1), or
    /// a PTY.
    pub fn serial(path: &str, timeout: Duration) -> Result<Link, String> {
        let p = serialport::new(path, gms_core::protocol::UART_BAUD)
            .timeout(Duration::from_millis(10))
            .open()
            .map_err(|e| format!("--port {path}: cannot open: {e}"))?;
        Ok(Self::new(Box::new(p), timeout))
    }

    /// A link over any stream. CAN LF goes out first: the device drops whatever half line an
    /// earlier client left (gms-core's `protocol::CANCEL`), never running it, and the empty
    /// line has no reply (a firmware from before CAN answers the line `err`: not run either).
    pub fn new(mut io: Box<dyn Stream>, timeout: Duration) -> Link {
        let _ = io
            .write_all(&[gms_core::protocol::CANCEL, b'\n'])
            .and_then(|_| io.flush());
        let mut link = Link {
            io,
            pending: Vec::new(),
            timeout,
            telemetry: Vec::new(),
            speed: 1.0,
            owed: 0,
            last_rx: Instant::now(),
        };
        // Whatever that provokes (an `err` for the half line) is not ours: discard it.
        let _ = link.listen(Duration::from_millis(30));
        link.pending.clear();
        link.telemetry.clear();
        link
    }

    /// Sends one request line.
    pub fn send(&mut self, line: &str) -> Result<(), LinkError> {
        self.io
            .write_all(format!("{line}\n").as_bytes())
            .and_then(|_| self.io.flush())
            .map_err(|e| LinkError::Io(e.to_string()))
    }

    /// The next complete line (telemetry is collected, not returned), or `None` at the
    /// deadline.
    fn next_line(&mut self, deadline: Instant) -> Result<Option<String>, LinkError> {
        let mut buf = [0u8; 4096];
        loop {
            if let Some(pos) = self.pending.iter().position(|&b| b == b'\n') {
                let raw: Vec<u8> = self.pending.drain(..=pos).collect();
                let line = String::from_utf8_lossy(&raw).trim_end().to_string();
                if let Some(t) = line.strip_prefix('#') {
                    self.telemetry.push((Instant::now(), t.trim().to_string()));
                    continue;
                }
                return Ok(Some(line));
            }
            if Instant::now() >= deadline {
                return Ok(None);
            }
            match self.io.read(&mut buf) {
                Ok(0) => return Err(LinkError::Io("the device closed the connection".into())),
                Ok(n) => {
                    self.pending.extend_from_slice(&buf[..n]);
                    self.last_rx = Instant::now();
                }
                // A signal (Ctrl-C, whose handler decides what to do) is not a link failure.
                Err(e)
                    if matches!(
                        e.kind(),
                        ErrorKind::WouldBlock | ErrorKind::TimedOut | ErrorKind::Interrupted
                    ) => {}
                Err(e) => return Err(LinkError::Io(e.to_string())),
            }
        }
    }

    /// The console passthrough (the window's console, `gms-tune send`, tests): sends one raw
    /// `line` and returns the reply's lines before `ok` and the text after `ok`; every other
    /// request goes typed through [`Link::ask`]. A
    /// `save` gets at least [`gms_core::protocol::SAVE_REPLY_MS`] (a board erases flash); on a
    /// device slower than real time ([`Link::speed`] below 1) every request gets the timeout
    /// stretched by its pace. A reply that misses its timeout is owed: read and dropped when
    /// it comes, before the next request's.
    pub fn console(&mut self, line: &str) -> Result<(Vec<String>, String), LinkError> {
        self.send(line)?;
        let base = if gms_core::protocol::parse(line) == Ok(Command::Save) {
            self.timeout.max(Duration::from_millis(
                gms_core::protocol::SAVE_REPLY_MS as u64,
            ))
        } else {
            self.timeout
        };
        let wait = base.mul_f64(1.0 / self.speed.clamp(0.01, 1.0));
        let deadline = Instant::now() + wait;
        let mut body = Vec::new();
        loop {
            let Some(l) = self.next_line(deadline)? else {
                if self.owed > 0 {
                    // Two requests in a row unanswered: the device is gone, or the replies
                    // are out of step; either way the link must be opened again.
                    return Err(LinkError::Io(format!(
                        "no reply to two requests in a row (the last within {} ms)",
                        wait.as_millis()
                    )));
                }
                self.owed += 1;
                return Err(LinkError::Timeout(wait));
            };
            let reply = Reply::parse(&l);
            let end = !matches!(reply, Ok(None));
            if self.owed > 0 {
                // An earlier request's late reply (its lines, then its end): not ours.
                if end {
                    self.owed -= 1;
                    body.clear();
                }
                continue;
            }
            match gms_link::reply_line(&l) {
                Ok(None) => body.push(l),
                Ok(Some(text)) => return Ok((body, text.to_string())),
                Err(gms_link::Error::Refused(r)) => return Err(LinkError::Device(r)),
                Err(e) => return Err(LinkError::Reply(e.to_string())),
            }
        }
    }

    /// How long since the device last sent anything (a reply or telemetry).
    pub fn silent_for(&self) -> Duration {
        self.last_rx.elapsed()
    }

    /// Sends a typed request (its line is the one the device's parser reads back as the same
    /// command) and waits for its reply, as [`Link::console`].
    pub fn ask(&mut self, c: Command<'_>) -> Result<(Vec<String>, String), LinkError> {
        self.console(&c.to_string())
    }

    /// [`Link::console`]'s reply as one text: the lines before `ok`, then the text after it,
    /// newline-separated (empty parts left out).
    pub fn console_text(&mut self, line: &str) -> Result<String, LinkError> {
        let (body, text) = self.console(line)?;
        Ok(reply_text(body, &text))
    }

    /// [`Link::ask`]'s reply as one text, as [`Link::console_text`].
    pub fn ask_text(&mut self, c: Command<'_>) -> Result<String, LinkError> {
        let (body, text) = self.ask(c)?;
        Ok(reply_text(body, &text))
    }

    /// The device's `status`, read (the device core's own format).
    pub fn status(&mut self) -> Result<StatusReply, LinkError> {
        let (_, text) = self.ask(Command::Status)?;
        StatusReply::parse(&text).map_err(|e| LinkError::Reply(format!("status: {e}: {text}")))
    }

    /// The device's clock (`status` key `t`) \[s\].
    pub fn device_time(&mut self) -> Result<f64, LinkError> {
        Ok(self.status()?.t)
    }

    /// Waits until `seconds` of device time have passed, reading the device's clock: on a
    /// board that is wall time, on a faster virtual device less (its speed is learnt as it
    /// goes, [`Link::speed`]). Sleeps at most 50 ms between looks.
    pub fn wait_device(&mut self, seconds: f64) -> Result<(), LinkError> {
        self.wait_device_with(seconds, &mut |_| true)
    }

    /// [`Link::wait_device`], telling `on` of the device time passed at each look (the
    /// seconds since the last); `on` returning false ends the wait early (a Stop), with
    /// `Ok`: the caller knows why.
    pub fn wait_device_with(
        &mut self,
        seconds: f64,
        on: &mut dyn FnMut(f64) -> bool,
    ) -> Result<(), LinkError> {
        if !(seconds.is_finite() && seconds > 0.0) {
            return Ok(());
        }
        let t0 = self.device_time()?;
        let (mut wall, mut dev) = (Instant::now(), t0);
        loop {
            let left = seconds - (dev - t0);
            if left <= 0.0 {
                return Ok(());
            }
            let nap = (left / self.speed).clamp(0.0002, 0.05);
            std::thread::sleep(Duration::from_secs_f64(nap));
            let now = self.device_time()?;
            let el = wall.elapsed().as_secs_f64();
            if el > 0.0 && now > dev {
                // Smoothed, and kept within what `hil-sim serve --speed` allows.
                self.speed = (0.5 * self.speed + 0.5 * (now - dev) / el).clamp(0.01, 1000.0);
            }
            let passed = (now - dev).clamp(0.0, left);
            (wall, dev) = (Instant::now(), now);
            if !on(passed) {
                return Ok(());
            }
        }
    }

    /// The telemetry stream of `fields` (comma-separated) at `rate` \[Hz\] for `seconds` of
    /// wall time, as rows of the fields (NaN where one is missing); the stream is off after.
    pub fn record(
        &mut self,
        fields: &str,
        rate: f64,
        seconds: f64,
    ) -> Result<Vec<Vec<f64>>, LinkError> {
        self.telemetry.clear();
        self.ask(Command::Stream {
            fields,
            rate_hz: rate as f32,
        })?;
        let listened = self.listen(Duration::from_secs_f64(seconds));
        let off = self.ask(Command::StreamOff);
        listened?;
        off?;
        // The samples that arrive until `stream off` is answered, or in a burst from a device
        // catching up after a stall, would stretch the record past `seconds` of device time.
        self.telemetry.truncate((seconds * rate).ceil() as usize);
        Ok(self.telemetry_rows(fields))
    }

    /// The telemetry collected so far as rows of `fields` (comma-separated; NaN where
    /// missing).
    pub fn telemetry_rows(&self, fields: &str) -> Vec<Vec<f64>> {
        let names: Vec<&str> = fields.split(',').map(str::trim).collect();
        self.telemetry
            .iter()
            .map(|(_, l)| {
                let kv = parse_telemetry(l);
                names
                    .iter()
                    .map(|n| kv.iter().find(|(k, _)| k == n).map_or(f64::NAN, |x| x.1))
                    .collect()
            })
            .collect()
    }

    /// Collects telemetry for `d`.
    pub fn listen(&mut self, d: Duration) -> Result<(), LinkError> {
        let deadline = Instant::now() + d;
        while let Some(l) = self.next_line(deadline)? {
            // A reply while listening: one owed (a late one) is paid; any other is stray.
            if self.owed > 0 && !matches!(Reply::parse(&l), Ok(None)) {
                self.owed -= 1;
            }
        }
        Ok(())
    }
}

/// The link as an abstract bench, for the experiments of `gms_bench` (captures read
/// back with `gms_bench::capture_rows`, the sliding experiment, …). Waiting is in
/// device time ([`Link::wait_device`]).
impl gms_link::DeviceLink for Link {
    fn request(&mut self, c: Command<'_>) -> Result<(Vec<String>, String), gms_link::Error> {
        Link::ask(self, c).map_err(LinkError::into_link)
    }

    fn pass(&mut self, seconds: f64) -> Result<(), gms_link::Error> {
        self.wait_device(seconds).map_err(LinkError::into_link)
    }
}

/// A reply as one text: the lines before `ok`, then the text after it, newline-separated
/// (empty parts left out).
fn reply_text(body: Vec<String>, text: &str) -> String {
    let mut out = body.join("\n");
    if !text.is_empty() {
        if !out.is_empty() {
            out.push('\n');
        }
        out.push_str(text);
    }
    out
}

/// Parses a telemetry line `name=value name=value …` ([`gms_core::protocol::telemetry`]).
pub fn parse_telemetry(line: &str) -> Vec<(String, f64)> {
    gms_core::protocol::telemetry(line)
        .map(|(k, v)| (k.to_string(), v))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::{BufRead, BufReader};

    /// A device on loopback TCP that answers each line `L` with `ok L` after the delay
    /// `delay(L)` \[ms\] (`None`: never), in order.
    fn device(delay: fn(&str) -> Option<u64>) -> String {
        let l = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
        let addr = l.local_addr().unwrap().to_string();
        std::thread::spawn(move || {
            let (s, _) = l.accept().unwrap();
            let mut w = s.try_clone().unwrap();
            for line in BufReader::new(s).lines() {
                let Ok(line) = line else { return };
                if line.is_empty() {
                    continue;
                }
                match delay(&line) {
                    Some(ms) => std::thread::sleep(Duration::from_millis(ms)),
                    None => continue,
                }
                if w.write_all(format!("ok {line}\n").as_bytes()).is_err() {
                    return;
                }
            }
        });
        addr
    }

    /// A reply that misses its timeout is owed: when it comes it is dropped, and the next
    /// request gets its own reply, whether the late one came during that request or while
    /// the link was listening.
    #[test]
    fn a_late_reply_is_never_taken_for_the_next_ones() {
        // A device answers in order: "get b" comes right after the late "slow 1" (at 300 ms),
        // within its own timeout (from 200 ms to 400 ms).
        let addr = device(|l| Some(if l.starts_with("slow") { 300 } else { 0 }));
        let mut link = Link::tcp(&addr, Duration::from_millis(200)).unwrap();
        assert!(matches!(link.console("slow 1"), Err(LinkError::Timeout(_))));
        assert_eq!(link.console("get b").unwrap().1, "get b");
        assert!(matches!(link.console("slow 2"), Err(LinkError::Timeout(_))));
        link.listen(Duration::from_millis(600)).unwrap();
        assert_eq!(link.console("get c").unwrap().1, "get c");
    }

    /// Two requests in a row unanswered: the link is out of step or the device gone, an I/O
    /// error (the window then opens the link again) rather than a second timeout.
    #[test]
    fn two_unanswered_requests_are_a_lost_link() {
        let addr = device(|l| (!l.starts_with("lost")).then_some(0));
        let mut link = Link::tcp(&addr, Duration::from_millis(50)).unwrap();
        assert!(matches!(link.console("lost 1"), Err(LinkError::Timeout(_))));
        assert!(matches!(link.console("lost 2"), Err(LinkError::Io(_))));
    }
}
