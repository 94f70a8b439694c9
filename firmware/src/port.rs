//! The byte link to the bench PC, one per board: USB CDC-ACM on the F405 board (its own USB
//! connector on PA11/PA12), the ST-LINK's virtual COM port on the NUCLEO-F446RE (USART2 on
//! PA2/PA3, UM1724 §6.8 "USART communication": the ST-LINK/V2-1 carries it to the PC over the
//! cable that also powers and flashes the board). The protocol above it is the same
//! (`comms.rs`); `gms-tune --port` opens either (the baud rate, gms-core's `protocol::UART_BAUD`, is what the
//! UART needs and what a CDC-ACM port ignores).

/// The host is gone (see `comms.rs`).
pub struct Gone;

/// What a read brought.
pub enum Read {
    /// So many bytes, at the start of the buffer.
    Bytes(usize),
    /// So many bytes, of which some were damaged or lost on the line (a UART's parity,
    /// framing, noise or overrun error): the lines they belong to are not run (`err 9`).
    #[cfg_attr(not(feature = "board-nucleo-f446"), allow(dead_code))]
    Damaged(usize),
    /// Bytes were lost (a UART's receive ring lapped or its stream stopped): answered `err 9`
    /// at once; the line in progress is dropped and, when `mid_line` (the lost bytes did not
    /// end with a LF, or nobody can tell), the rest of it too as it comes.
    #[cfg_attr(not(feature = "board-nucleo-f446"), allow(dead_code))]
    Lost {
        /// The lost bytes ended inside a line.
        mid_line: bool,
    },
}

/// A byte link to the host.
pub(crate) trait Port {
    /// The link's name, for the log.
    const NAME: &'static str;
    /// Waits until a host may be there (USB: the host configured the device; a UART: at
    /// once).
    async fn connected(&mut self);
    /// Waits for bytes from the host.
    async fn read(&mut self, buf: &mut [u8]) -> Result<Read, Gone>;
    /// Sends every byte of `bytes`.
    async fn send(&mut self, bytes: &[u8]) -> Result<(), Gone>;
    /// Looked at every [`crate::comms::DTR_POLL_MS`]: false once the host has closed the
    /// port (USB: DTR dropped after it was raised; a UART cannot tell: always true).
    fn host_here(&mut self) -> bool;
}

#[cfg(feature = "board-f405")]
mod usb {
    use core::sync::atomic::{AtomicBool, AtomicU32, Ordering};

    use embassy_futures::select::{Either, select};
    use embassy_stm32::peripherals::USB_OTG_FS;
    use embassy_stm32::usb::Driver;
    use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
    use embassy_sync::signal::Signal;
    use embassy_time::{Duration, with_timeout};
    use embassy_usb::class::cdc_acm::CdcAcmClass;

    use super::{Gone, Port, Read};

    /// How long a packet may wait for the host to take it \[ms\] before the session is taken
    /// as over (a reading host takes one every 1 ms USB frame).
    pub const WRITE_TIMEOUT_MS: u64 = 200;

    /// Bus events that end a session, counted: a bus reset (the cable pulled and put back,
    /// the host's re-enumeration), a suspend (the cable pulled: the bus idle), the
    /// configuration dropped.
    static BUS_EVENTS: AtomicU32 = AtomicU32::new(0);
    /// Raised with each of them (and a resume), for a write waiting for the host and a
    /// session waiting for the bus.
    static BUS_EVENT: Signal<CriticalSectionRawMutex, ()> = Signal::new();
    /// The bus is suspended (no session starts until it resumes or is reset).
    static SUSPENDED: AtomicBool = AtomicBool::new(false);

    /// embassy-usb's device-level callbacks (`Builder::handler`), counting the bus events
    /// that end a session: embassy-usb neither fails nor wakes a pending endpoint write at a
    /// bus reset, and once the host configured the device again the write went on into the
    /// new session with the rest of the old reply (found in rehost: a cable pulled in the
    /// middle of a `list`, `rehost/tests/usb.rs`).
    pub struct BusWatch;

    impl embassy_usb::Handler for BusWatch {
        fn reset(&mut self) {
            SUSPENDED.store(false, Ordering::Relaxed);
            bus_event();
        }
        fn suspended(&mut self, suspended: bool) {
            SUSPENDED.store(suspended, Ordering::Relaxed);
            if suspended {
                bus_event();
            } else {
                BUS_EVENT.signal(());
            }
        }
        fn configured(&mut self, configured: bool) {
            if !configured {
                bus_event();
            }
        }
    }

    fn bus_event() {
        BUS_EVENTS.fetch_add(1, Ordering::Relaxed);
        BUS_EVENT.signal(());
    }

    /// USB CDC-ACM (see `comms.rs` for how a session ends).
    pub struct UsbPort {
        /// The CDC-ACM class on the OTG FS driver.
        pub class: CdcAcmClass<'static, Driver<'static, USB_OTG_FS>>,
        /// The host raised DTR in this session.
        pub dtr_seen: bool,
        /// [`BUS_EVENTS`] when the session started.
        pub bus_events: u32,
    }

    impl UsbPort {
        /// A bus event since the session started.
        fn bus_changed(&self) -> bool {
            BUS_EVENTS.load(Ordering::Relaxed) != self.bus_events
        }

        /// Writes one packet, or gives up after [`WRITE_TIMEOUT_MS`] or at a bus event.
        async fn write(&mut self, chunk: &[u8]) -> Result<(), Gone> {
            if self.bus_changed() {
                return Err(Gone);
            }
            let write = with_timeout(
                Duration::from_millis(WRITE_TIMEOUT_MS),
                self.class.write_packet(chunk),
            );
            match select(write, BUS_EVENT.wait()).await {
                Either::First(Ok(Ok(()))) if !self.bus_changed() => Ok(()),
                _ => Err(Gone),
            }
        }
    }

    impl Port for UsbPort {
        const NAME: &'static str = "USB";

        /// Configured and not suspended: a session that started on a suspended bus (the
        /// cable pulled, the configuration kept) would take the next host's first bytes and
        /// end at its bus reset, unanswered.
        async fn connected(&mut self) {
            loop {
                BUS_EVENT.reset();
                self.bus_events = BUS_EVENTS.load(Ordering::Relaxed);
                self.class.wait_connection().await;
                if !SUSPENDED.load(Ordering::Relaxed) && !self.bus_changed() {
                    break;
                }
                if SUSPENDED.load(Ordering::Relaxed) {
                    BUS_EVENT.wait().await;
                }
            }
            self.dtr_seen = false;
        }

        async fn read(&mut self, buf: &mut [u8]) -> Result<Read, Gone> {
            self.class
                .read_packet(buf)
                .await
                .map(Read::Bytes)
                .map_err(|_| Gone)
        }

        /// In packets; a final full packet is followed by an empty one, so that the host sees
        /// the end of the transfer.
        async fn send(&mut self, bytes: &[u8]) -> Result<(), Gone> {
            let max = self.class.max_packet_size() as usize;
            for chunk in bytes.chunks(max) {
                self.write(chunk).await?;
            }
            if !bytes.is_empty() && bytes.len().is_multiple_of(max) {
                self.write(&[]).await?;
            }
            Ok(())
        }

        fn host_here(&mut self) -> bool {
            if self.bus_changed() {
                return false;
            }
            if self.class.dtr() {
                self.dtr_seen = true;
                true
            } else {
                !self.dtr_seen
            }
        }
    }
}

#[cfg(feature = "board-f405")]
pub use usb::{BusWatch, UsbPort as HostPort};

#[cfg(feature = "board-nucleo-f446")]
mod uart {
    use embassy_stm32::mode::Async;
    use embassy_stm32::pac;
    use embassy_stm32::usart::{UartRx, UartTx};
    use embassy_time::Timer;
    use f4_regs::uart_rx::{self, Ring, RxStream};
    use f4_regs::uart_tx::{self, TxStream};
    use gms_core::protocol::RingWatch;

    use super::{Gone, Port, Read};

    /// The UART's settings: gms-core's `protocol::UART_BAUD`, 8 data bits, no parity, one stop
    /// bit.
    pub fn config() -> embassy_stm32::usart::Config {
        let mut c = embassy_stm32::usart::Config::default();
        c.baudrate = gms_core::protocol::UART_BAUD;
        c
    }

    /// How often the reader looks at the ring while nothing has come \[µs\]: 46 bytes at
    /// 921,600 Bd, against a ring of 1024 (11 ms).
    pub const RX_POLL_US: u64 = 500;

    /// The transmit buffer \[bytes\]: what one transfer carries (4.7 ms of the line).
    pub const TX_BUF: usize = 512;

    /// One byte on the line \[µs\], rounded up: 10 bits at 921,600 Bd.
    const BYTE_US: u64 = 11;

    /// A transfer that has not ended this long after it should have \[µs\]: the stream is
    /// taken as stuck and the session as gone.
    const TX_STALL_US: u64 = 50_000;

    /// USART2 to the ST-LINK's virtual COM port, both ways by DMA (RM0390 table 28: DMA1
    /// stream 5 channel 4 receives, stream 6 channel 4 sends); reception into a ring the
    /// stream fills on its own (`f4_regs::uart_rx`: the data register is never read by the
    /// CPU). A host sends one request and waits for its reply, so the ring never laps; each
    /// look checks that it did not all the same (gms-core's `RingWatch`), that the stream
    /// still runs and that the USART saw no error on the line (`uart_rx::look`).
    /// Transmission from the port's own buffer (`f4_regs::uart_tx`): `send` copies and
    /// starts the transfer and returns, so the next batch is formatted while this one is on
    /// the line.
    pub struct UartPort {
        /// embassy's sending side, kept alive (the pin, the stream) and never written.
        pub _tx: UartTx<'static, Async>,
        /// The sending stream.
        pub tx_stream: TxStream,
        /// What it sends from.
        pub tx_buf: &'static mut [u8; TX_BUF],
        /// embassy's receiving side, kept alive (the pins, the stream) and never read.
        pub _rx: UartRx<'static, Async>,
        /// The receiving stream.
        pub stream: RxStream,
        /// Its ring.
        pub ring: Ring,
        /// Where the next byte to read is in the ring.
        pub at: u16,
        /// The ring's check for laps.
        pub watch: RingWatch,
        /// The last look saw a line error flag.
        pub error_seen: bool,
        /// Unread bytes, from `at` on, among which a damaged one is \[bytes\].
        pub suspect: u16,
        /// A session has begun (a UART has no connection: the first `connected` returns at
        /// once, so does every later one).
        pub started: bool,
    }

    impl Port for UartPort {
        const NAME: &'static str = "ST-LINK virtual COM port (USART2)";

        async fn connected(&mut self) {
            self.started = true;
        }

        async fn read(&mut self, buf: &mut [u8]) -> Result<Read, Gone> {
            // Cancel-safe: `at` and the watch move only when the look's result is returned.
            let len = self.ring.len;
            loop {
                let look = uart_rx::look(self.stream, pac::USART2, len);
                if look.stopped {
                    // A stopped stream (a transfer error) is started again from the ring's
                    // start; what it had not delivered is lost.
                    if !uart_rx::start(self.stream, pac::USART2, self.ring) {
                        return Err(Gone);
                    }
                    (self.at, self.watch) = (0, RingWatch::new());
                    (self.error_seen, self.suspect) = (false, 0);
                    return Ok(Read::Lost { mid_line: true });
                }
                let new_bytes = look.to != self.watch.last();
                if !self
                    .watch
                    .intact(len, self.at, look.to, look.half, look.full)
                {
                    // Lapped: the unread bytes are not the ones received; all dropped. The
                    // last byte received (just written, intact) says whether a line goes on.
                    (self.at, self.suspect) = (look.to, 0);
                    self.error_seen = look.line_error;
                    let last = (look.to as usize + len as usize - 1) % len as usize;
                    // SAFETY: `last` < len: within the ring the stream writes (`board.rs`).
                    let byte = unsafe { core::ptr::read_volatile(self.ring.addr.add(last)) };
                    return Ok(Read::Lost {
                        mid_line: byte != b'\n',
                    });
                }
                // A flag still set from the last look with nothing received since is the
                // same error; with new bytes it is a new one (the stream's DR read of them,
                // after the last look's SR read, cleared the old).
                let fresh = look.line_error && (new_bytes || !self.error_seen);
                self.error_seen = look.line_error;
                let unread = ((look.to as u32 + len as u32 - self.at as u32) % len as u32) as u16;
                if fresh {
                    if unread == 0 {
                        // Damaged in a byte already read: the line in progress, if any.
                        self.suspect = 0;
                        return Ok(Read::Damaged(0));
                    }
                    self.suspect = unread;
                }
                if unread != 0 {
                    // SAFETY: the ring is the one the stream writes (`board.rs`), and the
                    // bytes from `at` to `to` are written and not yet reached again (the watch
                    // found no lap).
                    let n = unsafe { uart_rx::copy_out(self.ring, self.at, look.to, buf) };
                    self.at = ((self.at as usize + n) % len as usize) as u16;
                    if self.suspect > 0 {
                        self.suspect = self.suspect.saturating_sub(n as u16);
                        return Ok(Read::Damaged(n));
                    }
                    return Ok(Read::Bytes(n));
                }
                Timer::after_micros(RX_POLL_US).await;
            }
        }

        async fn send(&mut self, bytes: &[u8]) -> Result<(), Gone> {
            // Nothing to send is nothing sent (no chunk; `uart_tx::start` refuses a length of
            // 0, as embassy-stm32 0.6's DMA write asserted one, `dma/dma_bdma.rs`: an empty
            // line's empty reply reached it, a panic found running the image).
            // A UART always sends, at its baud rate, whether or not anyone listens.
            for chunk in bytes.chunks(TX_BUF) {
                // The last transfer ends at the line's rate: wait for what it has left.
                let mut waited = 0;
                while uart_tx::busy(self.tx_stream) {
                    let us = (uart_tx::left(self.tx_stream) as u64 * BYTE_US).max(20);
                    Timer::after_micros(us).await;
                    waited += us;
                    if waited > TX_STALL_US + TX_BUF as u64 * BYTE_US {
                        return Err(Gone);
                    }
                }
                let Some(buf) = self.tx_buf.get_mut(..chunk.len()) else {
                    return Err(Gone);
                };
                buf.copy_from_slice(chunk);
                // SAFETY: the buffer is the port's own static, written again only here, once
                // the stream is no longer busy (the wait above).
                let started = unsafe {
                    uart_tx::start(
                        self.tx_stream,
                        pac::USART2,
                        self.tx_buf.as_ptr(),
                        chunk.len() as u16,
                    )
                };
                if !started {
                    return Err(Gone);
                }
            }
            Ok(())
        }

        fn host_here(&mut self) -> bool {
            true
        }
    }
}

#[cfg(feature = "board-nucleo-f446")]
pub use uart::{TX_BUF, UartPort as HostPort, config as uart_config};
