//! The bench link: USB CDC-ACM at low priority (thread mode), speaking gms-core's protocol
//! (`LineReader` → `execute`) over gms-core's device [`Front`]: everything a command does is
//! decided there; this file carries bytes and reaches the loop through the mailbox.

use core::fmt::{self, Write};

use defmt::info;
use embassy_futures::select::{Either, select};
use embassy_stm32::peripherals::USB_OTG_FS;
use embassy_stm32::usb::Driver;
use embassy_time::Instant;
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
        info!("USB host disconnected");
        // A new client starts with no stream.
        dev.disconnected();
    }
}
