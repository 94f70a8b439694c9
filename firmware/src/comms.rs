//! The bench link: a byte link to the host (`port.rs`: USB CDC-ACM on the F405 board, the
//! ST-LINK's virtual COM port on the Nucleo) at low priority (thread mode), speaking gms-core's
//! protocol (`LineReader` → `execute`) over gms-core's device [`Front`]: everything a command
//! does is decided there; this file carries bytes and reaches the loop through the mailbox.
//!
//! On USB a session ends when the host goes away, which VBUS sensing cannot tell (it is off:
//! the port may be closed with the cable in): the USB endpoint fails (unplugged, bus reset),
//! the host drops DTR after having raised it (it closed the port: Linux and macOS drop DTR on
//! close, `ACM` control request SET_CONTROL_LINE_STATE), or a packet is not taken within
//! 200 ms (nobody reads: a closed port never polls the IN endpoint, and the write would wait
//! forever). Then the stream stops and the partial request line is dropped, so the next
//! session starts without a stream or a half line (a packet already handed to the USB FIFO
//! may still reach the next host: `gms-tune` discards what arrives in its first 30 ms); the
//! axis is not touched — it keeps holding or finishing its move, the bridge as it was, every
//! fault check running (`disable` is a request like any other). A UART cannot tell that the
//! host has gone: its session never ends; bytes damaged or lost on the line (the USART's
//! parity, framing, noise or overrun flags, a lapped or stopped receive ring: `port.rs`) make
//! the lines they touch end in `err 9`, not run. A host starts with CAN LF
//! (gms-core's `protocol::CANCEL`): the half line an earlier host left is dropped, and that
//! host's stream and experiment end (`Front::new_session`), on either link.

use core::fmt::{self, Write};

use defmt::{info, warn};
use embassy_futures::select::{Either, Either3, select, select3};
use embassy_time::{Duration, Instant, Ticker};
use gms_core::device::{Front, LoopLink, Mailbox, Status};
use gms_core::protocol::{self, Line, LineReader};

use crate::control::{MAILBOX, TelemetryRx};
use crate::port::{Port, Read};
use crate::storage::Store;

/// The firmware's way to the loop: the mailbox in a critical section; the loop is an
/// interrupt that preempts the comms task, so waiting is a busy poll.
pub struct IrqLink;

impl LoopLink for IrqLink {
    fn with_mailbox<R>(&mut self, f: impl FnOnce(&mut Mailbox) -> R) -> R {
        MAILBOX.lock(|m| {
            let mut m = m.borrow_mut();
            // A stall the deadman or the NMI found (they do not touch the mailbox), shown in
            // the status the front reads.
            crate::control::show_stall(&mut m.status);
            f(&mut m)
        })
    }
    fn now_us(&self) -> u64 {
        Instant::now().as_micros()
    }
    fn pause(&mut self) {}
    fn supply_code(&mut self) -> u32 {
        crate::board::supply_code()
    }
}

/// The firmware's side of the protocol.
pub type Dev = Front<IrqLink, Store>;

/// The latest status of the loop.
pub fn status() -> Status {
    IrqLink.with_mailbox(|m| m.status)
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

/// How often the host's presence (USB: DTR) is looked at \[ms\].
pub const DTR_POLL_MS: u64 = 50;

/// Replies of one request can be long (`list`: 1.3 KB today, room for the table to grow).
const REPLY: usize = 4096;

/// Serves the protocol to one host after another, forever.
pub async fn serve<P: Port>(mut port: P, dev: &'static mut Dev, telemetry: TelemetryRx) -> ! {
    let mut reply = Buf::<REPLY>::new();
    let mut lines = Buf::<512>::new();
    let mut packet = [0u8; 64];
    // The supply's supervision between sessions too (a hold stays on without a host).
    let mut idle = Ticker::every(Duration::from_millis(gms_core::device::SUPERVISE_MS));
    loop {
        // USB: configured by the host (the port itself may not be open yet). Cancel-safe:
        // `connected` starts its wait over each time.
        while let Either::Second(()) = select(port.connected(), idle.next()).await {
            dev.supervise();
        }
        info!("{} session start", P::NAME);
        // A new session: no partial line from the last one.
        let mut reader = LineReader::default();
        // One ticker for the session: a timer made anew in each select would never fire
        // while telemetry arrives faster than it.
        let mut dtr_poll = Ticker::every(Duration::from_millis(DTR_POLL_MS));
        let mut stream_poll = Ticker::every(Duration::from_millis(1));
        loop {
            // The telemetry queue is polled every millisecond while streaming (the loop never
            // wakes this task: `control.rs`); it holds 64 samples, 64 ms of the 1 kHz stream.
            let streaming = dev.streaming();
            if !streaming {
                // Samples from before a `stream off` are not sent later.
                while telemetry.dequeue().is_some() {}
            }
            let poll = async {
                if streaming {
                    stream_poll.next().await
                } else {
                    core::future::pending::<()>().await
                }
            };
            let event = select3(port.read(&mut packet), poll, dtr_poll.next()).await;
            match event {
                Either3::First(Ok(read)) => {
                    let (n, damaged) = match read {
                        Read::Bytes(n) => (n, false),
                        Read::Damaged(n) => {
                            warn!("link: a byte damaged on the line; its line is refused");
                            reader.damage();
                            (n, true)
                        }
                        Read::Lost { mid_line } => {
                            warn!("link: bytes lost (the receive ring lapped or stopped)");
                            reader.drop_line(mid_line);
                            reply.clear();
                            let _ = protocol::execute(&mut *dev, Line::Damaged, &mut reply);
                            if port.send(reply.as_bytes()).await.is_err() {
                                break;
                            }
                            (0, false)
                        }
                    };
                    let mut link_ok = true;
                    for &b in packet.get(..n).unwrap_or(&[]) {
                        if damaged {
                            // Every line a damaged chunk touches is refused (`err 9`).
                            reader.damage();
                        }
                        let Some(line) = reader.push(b) else {
                            continue;
                        };
                        // One reply per request line, sent before the next line is read.
                        reply.clear();
                        if protocol::execute(&mut *dev, line, &mut reply).is_err() {
                            // The buffer overflowed: say so instead of a cut reply.
                            reply.clear();
                            let _ = writeln!(reply, "err 8 reply too long");
                        }
                        if port.send(reply.as_bytes()).await.is_err() {
                            link_ok = false;
                            break;
                        }
                    }
                    if !link_ok {
                        break;
                    }
                }
                Either3::First(Err(_)) => break,
                Either3::Third(()) => {
                    // The motor supply's supervision (thread mode's: gms-core's
                    // `Front::supervise`), at the DTR poll's pace.
                    dev.supervise();
                    if !port.host_here() {
                        break;
                    }
                }
                Either3::Second(()) => {
                    // One batch of what is queued (a few lines per transfer), then back to the
                    // select: requests are read between batches. Draining the queue here
                    // instead never ended while the stream outran the link (1 kHz of six
                    // fields is ~100 kB/s, the UART carries 92 kB/s): `stream off` was never
                    // read (found running the image under `gms-tune step-test`, docs/rehost.md).
                    // Samples the link cannot carry are dropped where the queue is full.
                    lines.clear();
                    while lines.len < 384 {
                        let Some(s) = telemetry.dequeue() else {
                            break;
                        };
                        let mark = lines.len;
                        if dev.telemetry_line(&mut lines, &s).is_err() {
                            lines.len = mark;
                            break;
                        }
                    }
                    if lines.len > 0 && port.send(lines.as_bytes()).await.is_err() {
                        break;
                    }
                }
            }
        }
        info!("host gone: stream off, partial line dropped; the axis holds as it was");
        // A new client starts with no stream.
        dev.disconnected();
    }
}
