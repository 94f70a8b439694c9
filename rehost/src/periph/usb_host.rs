//! The PC at the other end of the F405's USB cable: what a host does when the board is plugged
//! in (USB 2.0 §9.1.2 and §9.4; the order Linux's hub driver and cdc-acm use): the attach seen
//! and debounced, the bus reset, the enumeration (GET_DESCRIPTOR of the device, SET_ADDRESS,
//! the device, configuration, BOS and string descriptors, SET_CONFIGURATION), the CDC ACM
//! class requests a port's opening sends (SET_LINE_CODING, SET_CONTROL_LINE_STATE with DTR),
//! then the bulk endpoints the configuration names carrying a byte stream each way: OUT in
//! packets of the endpoint's size, IN polled while the port is read.
//!
//! Time: each transaction takes its bytes' time on the full-speed bus (12 Mbit/s, with
//! 16 bytes of token, handshake and gaps), a NAKed one is retried after 20 µs (control, OUT)
//! or 125 µs (the IN poll, a host controller's pace). The device side is [`super::otg`].

use std::collections::VecDeque;

use super::otg::{Handshake, OtgFs};

/// Core cycles per second.
const HZ: u64 = 168_000_000;
/// Cycles per millisecond.
const MS: u64 = HZ / 1000;
/// The attach's debounce and the reset's length, shortened from USB 2.0's 100 ms and 10 ms
/// (§7.1.7.3): the driver has no timing of its own there \[cycles\].
const DEBOUNCE: u64 = 5 * MS;
const RESET: u64 = 2 * MS;
/// After the reset, before the first request (§9.2.6.2: 10 ms; shortened) \[cycles\].
const RECOVERY: u64 = MS;
/// A NAKed control or OUT transaction retried after this \[cycles\].
const RETRY: u64 = 20 * HZ / 1_000_000;
/// The IN endpoint polled this often while it NAKs \[cycles\].
const IN_POLL: u64 = 125 * HZ / 1_000_000;
/// A control request not done in this long fails (Linux's USB_CTRL_GET_TIMEOUT: 5 s).
const CONTROL_TIMEOUT: u64 = 5 * HZ;
/// The address the host gives the device.
pub const ADDRESS: u8 = 7;

/// A transaction's time on the bus for `bytes` of data \[cycles\].
fn bus_time(bytes: usize) -> u64 {
    (bytes as u64 + 16) * 8 * HZ / 12_000_000
}

/// A control request.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Request {
    /// GET_DESCRIPTOR (type, index, length; 0: the length the earlier reply gave).
    GetDescriptor(u8, u8, u16),
    /// SET_ADDRESS.
    SetAddress(u8),
    /// SET_CONFIGURATION.
    SetConfiguration(u8),
    /// CDC SET_LINE_CODING (baud, 8N1).
    SetLineCoding(u32),
    /// CDC SET_CONTROL_LINE_STATE (bit 0 DTR, bit 1 RTS).
    SetControlLineState(u16),
}

impl Request {
    /// Its SETUP packet and, for a host-to-device data stage, the data.
    fn setup(&self, desc: &Descriptors, iface: u16) -> ([u8; 8], Vec<u8>) {
        let pkt = |rt: u8, req: u8, value: u16, index: u16, len: u16| {
            let (v, i, l) = (value.to_le_bytes(), index.to_le_bytes(), len.to_le_bytes());
            [rt, req, v[0], v[1], i[0], i[1], l[0], l[1]]
        };
        match *self {
            Request::GetDescriptor(ty, index, len) => {
                let len = if len > 0 {
                    len
                } else {
                    match ty {
                        2 => desc.total_length(&desc.config, 2),
                        15 => desc.total_length(&desc.bos, 2),
                        _ => 255,
                    }
                };
                let lang = if ty == 3 && index > 0 { 0x0409 } else { 0 };
                (
                    pkt(0x80, 6, (u16::from(ty) << 8) | u16::from(index), lang, len),
                    vec![],
                )
            }
            Request::SetAddress(a) => (pkt(0x00, 5, u16::from(a), 0, 0), vec![]),
            Request::SetConfiguration(c) => (pkt(0x00, 9, u16::from(c), 0, 0), vec![]),
            Request::SetLineCoding(baud) => {
                let mut d = baud.to_le_bytes().to_vec();
                d.extend_from_slice(&[0, 0, 8]);
                (pkt(0x21, 0x20, 0, iface, 7), d)
            }
            Request::SetControlLineState(v) => (pkt(0x21, 0x22, v, iface, 0), vec![]),
        }
    }
}

/// The descriptors the host read.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Descriptors {
    /// The device descriptor.
    pub device: Vec<u8>,
    /// The configuration descriptor with its interfaces and endpoints.
    pub config: Vec<u8>,
    /// The BOS descriptor.
    pub bos: Vec<u8>,
    /// String descriptors by index (0: the languages), decoded.
    pub strings: Vec<(u8, String)>,
}

/// The CDC ACM function a host's driver binds to, as the configuration describes it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct AcmPorts {
    /// The communication interface's number (the class requests' wIndex).
    pub comm_interface: u8,
    /// Its notification endpoint (IN, interrupt).
    pub notify_in: u8,
    /// The data interface's bulk OUT endpoint and its packet size.
    pub data_out: (u8, u16),
    /// The data interface's bulk IN endpoint and its packet size.
    pub data_in: (u8, u16),
}

impl Descriptors {
    fn total_length(&self, d: &[u8], at: usize) -> u16 {
        d.get(at..at + 2)
            .map_or(255, |b| u16::from_le_bytes([b[0], b[1]]))
    }

    /// The vendor and product ids.
    pub fn ids(&self) -> Option<(u16, u16)> {
        let d = self.device.get(8..12)?;
        Some((
            u16::from_le_bytes([d[0], d[1]]),
            u16::from_le_bytes([d[2], d[3]]),
        ))
    }

    /// A string by its index.
    pub fn string(&self, index: u8) -> Option<&str> {
        self.strings
            .iter()
            .find(|(i, _)| *i == index)
            .map(|(_, s)| s.as_str())
    }

    /// Checks the descriptors against what a host's CDC ACM driver needs (USB 2.0 §9.6;
    /// the Interface Association ECN; CDC 1.2 PSTN §5.3): an 18-byte device descriptor with
    /// EP0's size 8-64 and the IAD class triple EF/02/01 (or the CDC class 02 on the device);
    /// a configuration whose length is what it says; an IAD grouping a communication interface
    /// (02/02) with its interrupt IN endpoint and a data interface (0A) with a bulk IN and a
    /// bulk OUT endpoint. The ports found, or the first thing missing.
    pub fn acm(&self) -> Result<AcmPorts, String> {
        let d = &self.device;
        if d.len() != 18 || d[0] != 18 || d[1] != 1 {
            return Err(format!("device descriptor: {d:02X?}"));
        }
        if ![8, 16, 32, 64].contains(&d[7]) {
            return Err(format!("EP0's packet size {}", d[7]));
        }
        let iad_device = (d[4], d[5], d[6]) == (0xEF, 0x02, 0x01);
        if !iad_device && d[4] != 0x02 {
            return Err(format!(
                "device class {:02X}/{:02X}/{:02X}: neither an IAD device (EF/02/01) nor CDC (02)",
                d[4], d[5], d[6]
            ));
        }
        let c = &self.config;
        if c.len() < 9 || c[1] != 2 || usize::from(self.total_length(c, 2)) != c.len() {
            return Err(format!(
                "configuration descriptor of {} bytes: {c:02X?}",
                c.len()
            ));
        }
        let mut iad = None;
        let mut iface: Option<(u8, u8, u8)> = None;
        let mut comm = None;
        let mut data = None;
        let (mut notify, mut d_in, mut d_out) = (None, None, None);
        let mut at = 0;
        while at + 2 <= c.len() {
            let len = usize::from(c[at]);
            if len < 2 || at + len > c.len() {
                return Err(format!("a descriptor of length {len} at byte {at}"));
            }
            let b = &c[at..at + len];
            match b[1] {
                0x0B if len >= 8 => iad = Some((b[2], b[3], b[4], b[5])),
                0x04 if len >= 9 => {
                    iface = Some((b[2], b[5], b[6]));
                    if (b[5], b[6]) == (0x02, 0x02) {
                        comm = Some(b[2]);
                    }
                    if b[5] == 0x0A {
                        data = Some(b[2]);
                    }
                }
                0x05 if len >= 7 => {
                    let (addr, attr) = (b[2], b[3] & 3);
                    let mps = u16::from_le_bytes([b[4], b[5]]);
                    match (iface, addr & 0x80 != 0, attr) {
                        (Some((_, 0x02, 0x02)), true, 3) => notify = Some(addr),
                        (Some((_, 0x0A, _)), true, 2) => d_in = Some((addr, mps)),
                        (Some((_, 0x0A, _)), false, 2) => d_out = Some((addr, mps)),
                        _ => {}
                    }
                }
                _ => {}
            }
            at += len;
        }
        let comm = comm.ok_or("no communication interface (class 02, subclass 02: ACM)")?;
        let data_if = data.ok_or("no data interface (class 0A)")?;
        if iad_device {
            let (first, count, class, sub) =
                iad.ok_or("an IAD device class without an interface association")?;
            if first != comm || count < 2 || data_if != comm + 1 || (class, sub) != (2, 2) {
                return Err(format!(
                    "the association (first {first}, {count} interfaces, {class:02X}/{sub:02X}) \
                     does not group the ACM's interfaces {comm} and {data_if}"
                ));
            }
        }
        Ok(AcmPorts {
            comm_interface: comm,
            notify_in: notify.ok_or("no notification endpoint (interrupt IN)")?,
            data_out: d_out.ok_or("no bulk OUT endpoint")?,
            data_in: d_in.ok_or("no bulk IN endpoint")?,
        })
    }

    /// What was read, for a person: ids, strings, the endpoints and their sizes.
    pub fn describe(&self) -> Vec<String> {
        let mut v = Vec::new();
        if let Some((vid, pid)) = self.ids() {
            let d = &self.device;
            v.push(format!(
                "device: {vid:04x}:{pid:04x}, USB {:x}.{:02x}, class {:02X}/{:02X}/{:02X}, EP0 {} bytes",
                d[3], d[2], d[4], d[5], d[6], d[7]
            ));
        }
        for (i, s) in &self.strings {
            if *i > 0 {
                v.push(format!("string {i}: {s:?}"));
            }
        }
        v.push(format!(
            "configuration: {} bytes, BOS {} bytes",
            self.config.len(),
            self.bos.len()
        ));
        match self.acm() {
            Ok(p) => v.push(format!(
                "CDC ACM: interface {}, notification 0x{:02x}, data OUT 0x{:02x} ({} bytes), IN 0x{:02x} ({} bytes)",
                p.comm_interface, p.notify_in, p.data_out.0, p.data_out.1, p.data_in.0, p.data_in.1
            )),
            Err(e) => v.push(format!("not a CDC ACM device a host would bind: {e}")),
        }
        v
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Stage {
    Setup,
    DataIn,
    DataOut(usize),
    StatusIn,
    StatusOut,
}

#[derive(Debug, Clone)]
struct ControlRun {
    req: Request,
    setup: [u8; 8],
    out: Vec<u8>,
    stage: Stage,
    data: Vec<u8>,
    deadline: u64,
}

/// Where the host is with the device.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Link {
    /// No cable, or the device not pulled up.
    Detached,
    /// Seen attached: debouncing.
    Attached,
    /// Driving the bus reset.
    Resetting,
    /// The reset over: the enumeration's requests.
    Enumerating,
    /// Configured: the port exists (the bulk stream runs while an application has it open).
    Open,
}

/// The emulated host.
#[derive(Debug, Clone)]
pub struct Host {
    /// The cable is in.
    pub plugged: bool,
    /// The host reads the port (polls the bulk IN endpoint); false: an application that
    /// stopped reading.
    pub reading: bool,
    /// Where it is.
    pub link: Link,
    /// The next time it acts \[cycles\].
    at: u64,
    queue: VecDeque<Request>,
    run: Option<ControlRun>,
    /// The descriptors read at the last enumeration.
    pub desc: Descriptors,
    /// The ports the configuration gave (after the enumeration).
    pub ports: Option<AcmPorts>,
    /// DTR as last set: the port open (the bulk endpoints carried).
    pub dtr: bool,
    /// An application wants the port open (it is opened again after each enumeration, as
    /// an application that reopens its port does).
    pub want_open: bool,
    /// Enumerations completed (each a new session of the port).
    pub enumerations: u32,
    /// Bytes for the device's bulk OUT endpoint.
    pub from_host: VecDeque<u8>,
    /// The packet being sent (retried while NAKed).
    out_packet: Option<Vec<u8>>,
    /// A zero-length packet owed after a transfer of whole packets.
    out_zlp: bool,
    /// Bytes the device sent on its bulk IN endpoint.
    pub to_host: Vec<u8>,
    /// Bulk IN packets received.
    pub in_packets: u64,
    /// What went wrong (a request stalled or timed out, a descriptor a driver refuses).
    pub errors: Vec<String>,
    /// Whether the next bulk slot tries OUT first (OUT and IN take turns).
    out_turn: bool,
    /// When the IN endpoint is next polled \[cycles\].
    in_at: u64,
    /// The bus is suspended: no transactions.
    pub suspended: bool,
}

impl Default for Host {
    fn default() -> Self {
        Host {
            plugged: false,
            reading: true,
            link: Link::Detached,
            at: 0,
            queue: VecDeque::new(),
            run: None,
            desc: Descriptors::default(),
            ports: None,
            dtr: false,
            want_open: false,
            enumerations: 0,
            from_host: VecDeque::new(),
            out_packet: None,
            out_zlp: false,
            to_host: Vec::new(),
            in_packets: 0,
            errors: Vec::new(),
            out_turn: true,
            in_at: 0,
            suspended: false,
        }
    }
}

impl Host {
    /// The next time the host acts \[cycles\] (none while unplugged).
    pub fn next_event(&self) -> Option<u64> {
        self.plugged.then_some(self.at)
    }

    /// Acts now (from `now`): something due was asked for (bytes to send, a request).
    pub fn kick(&mut self, now: u64) {
        self.at = self.at.min(now);
        self.in_at = self.in_at.min(now);
    }

    /// The cable pulled: the host forgets the device (the bus idle: the device sees a
    /// suspend).
    pub fn unplug(&mut self, dev: &mut OtgFs) {
        self.plugged = false;
        self.reset_state();
        dev.suspend(true);
    }

    /// The host suspends the bus (a PC going to sleep: no traffic, the device sees the
    /// bus idle for 3 ms: USBSUSP) or resumes it (resume signalling: WKUPINT), the port kept.
    pub fn set_suspended(&mut self, suspended: bool, now: u64, dev: &mut OtgFs) {
        self.suspended = suspended;
        dev.suspend(suspended);
        self.kick(now);
    }

    /// The cable in again (the attach seen at `now`).
    pub fn plug(&mut self, now: u64) {
        self.plugged = true;
        self.link = Link::Detached;
        self.at = now;
    }

    fn reset_state(&mut self) {
        self.link = Link::Detached;
        self.suspended = false;
        self.queue.clear();
        self.run = None;
        self.ports = None;
        self.dtr = false;
        self.out_packet = None;
        self.out_zlp = false;
        self.from_host.clear();
    }

    /// Queues a control request (a class request on an open port: DTR, the line coding).
    pub fn request(&mut self, r: Request, now: u64) {
        self.queue.push_back(r);
        self.kick(now);
    }

    /// An application opens the port: the line coding set and DTR raised (now if the device
    /// is configured, else after its enumeration).
    pub fn open_port(&mut self, now: u64) {
        self.want_open = true;
        if self.link == Link::Open {
            self.queue_open();
            self.kick(now);
        }
    }

    /// The application closes the port: DTR dropped, the bulk stream no longer carried.
    pub fn close_port(&mut self, now: u64) {
        self.want_open = false;
        if self.link == Link::Open {
            self.request(Request::SetControlLineState(0), now);
        }
    }

    fn queue_open(&mut self) {
        self.queue.push_back(Request::SetLineCoding(115_200));
        self.queue.push_back(Request::SetControlLineState(3));
    }

    /// Acts at `now`: one transaction (or a link state change), the next time set.
    pub fn fire(&mut self, now: u64, dev: &mut OtgFs) {
        if !self.plugged || now < self.at {
            return;
        }
        match self.link {
            Link::Detached => {
                if dev.pulled_up() {
                    self.link = Link::Attached;
                    self.at = now + DEBOUNCE;
                } else {
                    self.at = now + MS;
                }
            }
            Link::Attached => {
                if let (true, Err(e)) = (dev.pulled_up(), dev.signalling()) {
                    // D+ pulled up, but nothing the device sends can be read: Linux's "device
                    // descriptor read/64, error -71" and no device.
                    if !self.errors.contains(&e) {
                        self.errors.push(e);
                    }
                    self.link = Link::Detached;
                    self.at = now + 100 * MS;
                } else if dev.pulled_up() {
                    dev.bus_reset();
                    self.link = Link::Resetting;
                    self.at = now + RESET;
                } else {
                    self.link = Link::Detached;
                    self.at = now + MS;
                }
            }
            Link::Resetting => {
                dev.enumeration_done();
                self.desc = Descriptors::default();
                self.queue.clear();
                self.queue.extend([
                    Request::GetDescriptor(1, 0, 64),
                    Request::SetAddress(ADDRESS),
                    Request::GetDescriptor(1, 0, 18),
                    Request::GetDescriptor(2, 0, 9),
                    Request::GetDescriptor(2, 0, 0),
                    Request::GetDescriptor(15, 0, 5),
                    Request::GetDescriptor(15, 0, 0),
                    Request::GetDescriptor(3, 0, 255),
                ]);
                self.link = Link::Enumerating;
                self.at = now + RECOVERY;
            }
            Link::Enumerating | Link::Open => {
                if !dev.pulled_up() {
                    // The device let go of D+ (a soft disconnect).
                    self.reset_state();
                    self.at = now + MS;
                    return;
                }
                if self.suspended {
                    self.at = now + MS;
                    return;
                }
                self.transact(now, dev);
            }
        }
    }

    /// One transaction: a control stage first, else the bulk stream.
    fn transact(&mut self, now: u64, dev: &mut OtgFs) {
        if self.run.is_none()
            && let Some(req) = self.queue.pop_front()
        {
            let iface = self.ports.map_or(0, |p| u16::from(p.comm_interface));
            let (setup, out) = req.setup(&self.desc, iface);
            self.run = Some(ControlRun {
                req,
                setup,
                out,
                stage: Stage::Setup,
                data: Vec::new(),
                deadline: now + CONTROL_TIMEOUT,
            });
        }
        if self.run.is_some() {
            self.control(now, dev);
            return;
        }
        if self.link != Link::Open || !self.dtr {
            self.at = now + MS;
            return;
        }
        self.bulk(now, dev);
    }

    fn control(&mut self, now: u64, dev: &mut OtgFs) {
        let Some(mut run) = self.run.take() else {
            return;
        };
        if now > run.deadline {
            self.errors
                .push(format!("{:?}: no answer in 5 s ({:?})", run.req, run.stage));
            self.at = now + RETRY;
            return;
        }
        let wlen = usize::from(u16::from_le_bytes([run.setup[6], run.setup[7]]));
        let to_host = run.setup[0] & 0x80 != 0;
        let (hs, bytes) = match run.stage {
            Stage::Setup => (dev.setup(run.setup), 8),
            Stage::DataIn | Stage::StatusIn => (dev.in_token(0), 0),
            Stage::DataOut(off) => {
                let end = (off + 64).min(run.out.len());
                (dev.out(0, &run.out[off..end]), end - off)
            }
            Stage::StatusOut => (dev.out(0, &[]), 0),
        };
        let mut done = false;
        match hs {
            Handshake::Ack(data) => {
                self.at = now + bus_time(bytes + data.len());
                run.stage = match run.stage {
                    Stage::Setup if wlen == 0 => Stage::StatusIn,
                    Stage::Setup if to_host => Stage::DataIn,
                    Stage::Setup => Stage::DataOut(0),
                    Stage::DataIn => {
                        let short = data.len() < 64;
                        run.data.extend_from_slice(&data);
                        if short || run.data.len() >= wlen {
                            Stage::StatusOut
                        } else {
                            Stage::DataIn
                        }
                    }
                    Stage::DataOut(off) => {
                        let next = off + 64;
                        if next >= run.out.len() {
                            Stage::StatusIn
                        } else {
                            Stage::DataOut(next)
                        }
                    }
                    Stage::StatusIn | Stage::StatusOut => {
                        done = true;
                        run.stage
                    }
                };
            }
            Handshake::Nak | Handshake::Silent => self.at = now + RETRY,
            Handshake::Stall => {
                self.errors.push(format!("{:?}: stalled", run.req));
                self.at = now + RETRY;
                return;
            }
        }
        if done {
            self.at = now + RETRY;
            self.completed(run.req, run.data, dev);
        } else {
            self.run = Some(run);
        }
    }

    /// A control request done: what it read kept, what follows queued.
    fn completed(&mut self, req: Request, data: Vec<u8>, dev: &OtgFs) {
        match req {
            Request::GetDescriptor(1, _, 18) => {
                self.desc.device = data;
                // The strings the device names, in Linux's order (product, manufacturer,
                // serial).
                for at in [15, 14, 16] {
                    let i = self.desc.device.get(at).copied().unwrap_or(0);
                    if i > 0 {
                        self.queue.push_back(Request::GetDescriptor(3, i, 255));
                    }
                }
                self.queue.push_back(Request::SetConfiguration(1));
            }
            Request::GetDescriptor(2, _, 0) => self.desc.config = data,
            Request::GetDescriptor(15, _, 0) => self.desc.bos = data,
            Request::GetDescriptor(3, i, _) => {
                let s = if i == 0 {
                    data.get(2..)
                        .unwrap_or(&[])
                        .chunks(2)
                        .map(|c| format!("{:02x}{:02x}", c.get(1).unwrap_or(&0), c[0]))
                        .collect::<Vec<_>>()
                        .join(",")
                } else {
                    let u: Vec<u16> = data
                        .get(2..)
                        .unwrap_or(&[])
                        .chunks(2)
                        .map(|c| u16::from_le_bytes([c[0], *c.get(1).unwrap_or(&0)]))
                        .collect();
                    String::from_utf16_lossy(&u)
                };
                self.desc.strings.retain(|(j, _)| *j != i);
                self.desc.strings.push((i, s));
            }
            Request::SetAddress(a) if dev.address() != a => {
                self.errors.push(format!(
                    "SET_ADDRESS {a}: the device's address is {} after its status stage",
                    dev.address()
                ));
            }
            Request::SetConfiguration(_) => match self.desc.acm() {
                Ok(p) => {
                    if !dev.in_active(usize::from(p.data_in.0 & 0x7F)) {
                        self.errors.push(
                            "the bulk IN endpoint is not active after SET_CONFIGURATION".into(),
                        );
                    }
                    self.ports = Some(p);
                    self.link = Link::Open;
                    self.enumerations += 1;
                    if self.want_open {
                        self.queue_open();
                    }
                }
                Err(e) => self.errors.push(format!("no driver binds: {e}")),
            },
            Request::SetControlLineState(v) => self.dtr = v & 1 != 0,
            _ => {}
        }
    }

    /// One bulk transaction: OUT when bytes wait, IN when it is time to poll; they take turns.
    fn bulk(&mut self, now: u64, dev: &mut OtgFs) {
        let Some(p) = self.ports else {
            self.at = now + MS;
            return;
        };
        let want_out = self.out_packet.is_some() || self.out_zlp || !self.from_host.is_empty();
        let want_in = self.reading && now >= self.in_at;
        if want_out && (self.out_turn || !want_in) {
            self.out_turn = false;
            let mps = usize::from(p.data_out.1.max(1));
            let pkt = match self.out_packet.take() {
                Some(pkt) => pkt,
                None if !self.from_host.is_empty() => {
                    let n = self.from_host.len().min(mps);
                    let pkt: Vec<u8> = self.from_host.drain(..n).collect();
                    // A transfer ends with a short packet: one of whole packets owes a
                    // zero-length one when nothing follows it.
                    self.out_zlp = n == mps && self.from_host.is_empty();
                    pkt
                }
                None => {
                    self.out_zlp = false;
                    Vec::new()
                }
            };
            match dev.out(usize::from(p.data_out.0 & 0x7F), &pkt) {
                Handshake::Ack(_) => self.at = now + bus_time(pkt.len()),
                Handshake::Nak => {
                    self.out_packet = Some(pkt);
                    self.at = now + RETRY;
                }
                Handshake::Stall | Handshake::Silent => {
                    self.errors.push("bulk OUT: stalled or no answer".into());
                    self.at = now + RETRY;
                }
            }
        } else if want_in {
            self.out_turn = true;
            match dev.in_token(usize::from(p.data_in.0 & 0x7F)) {
                Handshake::Ack(data) => {
                    self.in_packets += 1;
                    self.at = now + bus_time(data.len());
                    self.in_at = self.at;
                    self.to_host.extend_from_slice(&data);
                }
                Handshake::Nak => {
                    self.in_at = now + IN_POLL;
                    self.at = if want_out { now + RETRY } else { self.in_at };
                }
                Handshake::Stall | Handshake::Silent => {
                    self.errors.push("bulk IN: stalled or no answer".into());
                    self.in_at = now + IN_POLL;
                    self.at = self.in_at;
                }
            }
        } else {
            self.at = if self.reading {
                self.in_at.max(now + 1)
            } else {
                now + MS
            };
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The configuration a CDC ACM function with an interface association presents (USB
    /// 2.0 §9.6.3, the IAD ECN, CDC PSTN §5.3): 70 bytes.
    fn acm_config() -> Vec<u8> {
        let mut c = vec![0x09, 0x02, 70, 0x00, 0x02, 0x01, 0x00, 0x80, 0x32];
        c.extend([0x08, 0x0B, 0x00, 0x02, 0x02, 0x02, 0x00, 0x00]);
        c.extend([0x09, 0x04, 0x00, 0x00, 0x01, 0x02, 0x02, 0x00, 0x00]);
        c.extend([0x05, 0x24, 0x00, 0x10, 0x01]);
        c.extend([0x04, 0x24, 0x02, 0x02]);
        c.extend([0x05, 0x24, 0x06, 0x00, 0x01]);
        c.extend([0x07, 0x05, 0x81, 0x03, 0x08, 0x00, 0xFF]);
        c.extend([0x09, 0x04, 0x01, 0x00, 0x02, 0x0A, 0x00, 0x00, 0x00]);
        c.extend([0x07, 0x05, 0x01, 0x02, 0x40, 0x00, 0x00]);
        c.extend([0x07, 0x05, 0x82, 0x02, 0x40, 0x00, 0x00]);
        assert_eq!(c.len(), 70);
        c
    }

    fn descriptors() -> Descriptors {
        Descriptors {
            device: vec![
                0x12, 0x01, 0x10, 0x02, 0xEF, 0x02, 0x01, 0x40, 0x09, 0x12, 0x01, 0x00, 0x10, 0x00,
                0x01, 0x02, 0x03, 0x01,
            ],
            config: acm_config(),
            ..Descriptors::default()
        }
    }

    #[test]
    fn a_cdc_acm_function_is_found_with_its_endpoints() {
        let d = descriptors();
        assert_eq!(d.ids(), Some((0x1209, 0x0001)));
        assert_eq!(
            d.acm(),
            Ok(AcmPorts {
                comm_interface: 0,
                notify_in: 0x81,
                data_out: (0x01, 64),
                data_in: (0x82, 64),
            })
        );
    }

    /// What a driver would not bind: the IAD missing on an EF/02/01 device, a data interface
    /// without its bulk IN, a configuration shorter than its wTotalLength, EP0 of 7 bytes.
    #[test]
    fn descriptors_a_driver_would_refuse_are_refused() {
        let mut d = descriptors();
        d.config.drain(9..17);
        d.config[2] = d.config.len() as u8;
        assert!(d.acm().unwrap_err().contains("interface association"));
        let mut d = descriptors();
        d.config.truncate(63);
        d.config[2] = 63;
        assert!(d.acm().unwrap_err().contains("bulk IN"));
        let mut d = descriptors();
        d.config.pop();
        assert!(d.acm().unwrap_err().contains("configuration descriptor"));
        let mut d = descriptors();
        d.device[7] = 7;
        assert!(d.acm().unwrap_err().contains("EP0"));
    }

    /// The bus time of a 64-byte packet at 12 Mbit/s with 16 bytes of overhead: 53.3 µs.
    #[test]
    fn a_full_packet_takes_its_bits_time() {
        assert_eq!(bus_time(64), 80 * 8 * 14);
    }
}
