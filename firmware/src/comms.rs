//! The bench link: USB CDC-ACM at low priority (thread mode), speaking gms-core's protocol
//! (`LineReader` → `execute`) over gms-core's device [`Front`]: everything a command does is
//! decided there; this file carries bytes and reaches the loop through the mailbox.
//!
//! A session ends when the host goes away, which VBUS sensing cannot tell (it is off: the
//! port may be closed with the cable in): the USB endpoint fails (unplugged, bus reset), the
//! host drops DTR after having raised it (it closed the port: Linux and macOS drop DTR on
//! close, `ACM` control request SET_CONTROL_LINE_STATE), or a packet is not taken within
//! [`WRITE_TIMEOUT_MS`] (nobody reads: a closed port never polls the IN endpoint, and the
//! write would wait forever). Then the stream stops and the partial request line is dropped,
//! so the next session starts without a stream or a half line (a packet already handed to
//! the USB FIFO may still reach the next host: `gms-tune` discards what arrives in its first
//! 30 ms); the axis is not touched — it keeps holding or finishing
//! its move, the bridge as it was, every fault check running (`disable` is a request like any
//! other).

use core::fmt::{self, Write};

use defmt::info;
use embassy_futures::select::{Either3, select3};
use embassy_stm32::peripherals::USB_OTG_FS;
use embassy_stm32::usb::Driver;
use embassy_time::{Duration, Instant, Ticker, with_timeout};
use embassy_usb::class::cdc_acm::CdcAcmClass;
use embassy_usb::driver::EndpointError;
use gms_core::device::{Front, Link, Mailbox, Status};
use gms_core::protocol::{self, LineReader};

use crate::control::{MAILBOX, TELEMETRY};
use crate::storage::Store;

/// The firmware's way to the loop: the mailbox in a critical section; the loop is an
/// interrupt that preempts the comms task, so waiting is a busy poll.
pub struct IrqLink;

impl Link for IrqLink {
    fn with_mailbox<R>(&mut self, f: impl FnOnce(&mut Mailbox) -> R) -> R {
        MAILBOX.lock(|m| f(&mut m.borrow_mut()))
    }
    fn now_us(&self) -> u64 {
        Instant::now().as_micros()
    }
    fn pause(&mut self) {}
}

/// The firmware's side of the protocol.
pub type Dev = Front<IrqLink, Store>;

/// The latest status of the loop.
pub fn status() -> Status {
    MAILBOX.lock(|m| m.borrow().status)
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

/// How long a packet may wait for the host to take it \[ms\] before the session is taken as
/// over (a reading host takes one every 1 ms USB frame).
pub const WRITE_TIMEOUT_MS: u64 = 200;

/// How often the host's DTR is looked at \[ms\].
const DTR_POLL_MS: u64 = 50;

/// The host is gone (see the module's notes).
struct Gone;

impl From<EndpointError> for Gone {
    fn from(_: EndpointError) -> Gone {
        Gone
    }
}

/// Writes one packet, or gives up after [`WRITE_TIMEOUT_MS`].
async fn write(
    class: &mut CdcAcmClass<'static, Driver<'static, USB_OTG_FS>>,
    chunk: &[u8],
) -> Result<(), Gone> {
    match with_timeout(
        Duration::from_millis(WRITE_TIMEOUT_MS),
        class.write_packet(chunk),
    )
    .await
    {
        Ok(r) => Ok(r?),
        Err(_) => Err(Gone),
    }
}

/// Writes `bytes` in packets; a final full packet is followed by an empty one, so that the
/// host sees the end of the transfer.
async fn send(
    class: &mut CdcAcmClass<'static, Driver<'static, USB_OTG_FS>>,
    bytes: &[u8],
) -> Result<(), Gone> {
    let max = class.max_packet_size() as usize;
    for chunk in bytes.chunks(max) {
        write(class, chunk).await?;
    }
    if !bytes.is_empty() && bytes.len().is_multiple_of(max) {
        write(class, &[]).await?;
    }
    Ok(())
}

/// Replies of one request can be long (`list`: 1.3 KB today, room for the table to grow).
const REPLY: usize = 4096;

/// Serves the protocol to one host after another, forever.
pub async fn serve(
    mut class: CdcAcmClass<'static, Driver<'static, USB_OTG_FS>>,
    mut dev: Dev,
) -> ! {
    let mut reply = Buf::<REPLY>::new();
    let mut lines = Buf::<512>::new();
    let mut packet = [0u8; 64];
    loop {
        // Configured by the host (the port itself may not be open yet).
        class.wait_connection().await;
        info!("USB session start");
        // A new session: no partial line from the last one.
        let mut reader = LineReader::default();
        let mut dtr_seen = false;
        // One ticker for the session: a timer made anew in each select would never fire
        // while telemetry arrives faster than it.
        let mut dtr_poll = Ticker::every(Duration::from_millis(DTR_POLL_MS));
        loop {
            let event = select3(
                class.read_packet(&mut packet),
                TELEMETRY.receive(),
                dtr_poll.next(),
            )
            .await;
            match event {
                Either3::First(Ok(n)) => {
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
                Either3::First(Err(_)) => break,
                Either3::Third(()) => {
                    // DTR up then down: the host closed the port.
                    if class.dtr() {
                        dtr_seen = true;
                    } else if dtr_seen {
                        break;
                    }
                }
                Either3::Second(sample) => {
                    if !dev.streaming() {
                        continue;
                    }
                    lines.clear();
                    let mut next = Some(sample);
                    // Batch what is queued, a few lines per transfer.
                    while let Some(s) = next {
                        let mark = lines.len;
                        if dev.telemetry_line(&mut lines, &s).is_err() {
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
        info!("USB host gone: stream off, partial line dropped; the axis holds as it was");
        // A new client starts with no stream.
        dev.disconnected();
    }
}
