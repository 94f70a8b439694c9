//! `rehost serve`: the image's USART2 bridged to a TCP port (see `main.rs`).

use std::io::{ErrorKind, Read, Write};
use std::net::{TcpListener, TcpStream};
use std::time::{Duration, Instant};

use rehost::Machine;

/// Device time run between two looks at the socket \[s\].
const SLICE: f64 = 0.5e-3;

/// Serves one client at a time on `listen`, the image running all along (between clients
/// too: a board does not stop when its host goes away). With `flash`, the chip's flash
/// outside the image is that file's (what an earlier run stored) and is written back to it
/// after every slice in which the image wrote flash, before its reply goes out.
pub fn run(
    mut m: Machine,
    listen: &str,
    speed: f64,
    flash: Option<&std::path::Path>,
) -> Result<(), String> {
    if let Some(f) = flash {
        restore_flash(&mut m, f)?;
    }
    let mut writes = m.chip().inject.flash_writes;
    let listener = TcpListener::bind(listen).map_err(|e| format!("listen on {listen}: {e}"))?;
    listener
        .set_nonblocking(true)
        .map_err(|e| format!("listen on {listen}: {e}"))?;
    let addr = listener
        .local_addr()
        .map_err(|e| format!("listen on {listen}: {e}"))?;
    let usb = m.board() == rehost::Board::F405;
    let link = if usb { "USB" } else { "USART2" };
    eprintln!("rehost: the image's {link} on {addr} (gms-tune --tcp {addr})");
    let mut enumerations = 0;
    let wall = Instant::now();
    let device0 = m.seconds();
    let mut client: Option<TcpStream> = None;
    let mut buf = [0u8; 4096];
    // REHOST_TRACE=1: every byte both ways on stderr.
    let trace = std::env::var_os("REHOST_TRACE").is_some();
    loop {
        if client.is_none()
            && let Ok((c, peer)) = listener.accept()
        {
            let _ = c.set_nonblocking(true);
            let _ = c.set_nodelay(true);
            eprintln!("rehost: client {peer}");
            client = Some(c);
            if usb {
                // The client is the application that opens the port (DTR up) …
                let (h, _, now) = m.usb();
                h.open_port(now);
            }
        }
        if let Some(c) = client.as_mut() {
            match c.read(&mut buf) {
                Ok(0) => client = None,
                Ok(n) => {
                    if trace {
                        eprintln!(
                            "rehost: {:.4} s host > {:?}",
                            m.seconds(),
                            String::from_utf8_lossy(&buf[..n])
                        );
                    }
                    m.send_to_image(&buf[..n]);
                }
                Err(e) if e.kind() == ErrorKind::WouldBlock => {}
                Err(_) => client = None,
            }
        }
        if usb && client.is_none() && m.usb_host().want_open {
            // … and closes it when it goes (DTR down: the image ends its session).
            let (h, _, now) = m.usb();
            h.close_port(now);
        }
        m.run_for(SLICE)
            .map_err(|e| format!("the image stopped: {e:?}"))?;
        if usb && m.usb_host().enumerations != enumerations {
            enumerations = m.usb_host().enumerations;
            for l in m.usb_host().desc.describe() {
                eprintln!("rehost: USB: {l}");
            }
            for e in &m.usb_host().errors {
                eprintln!("rehost: USB error: {e}");
            }
        }
        if let Some(f) = flash
            && m.chip().inject.flash_writes != writes
        {
            writes = m.chip().inject.flash_writes;
            let bytes = m.flash()?;
            std::fs::write(f, bytes).map_err(|e| format!("--flash {}: {e}", f.display()))?;
        }
        let out = m.take_from_image();
        if trace && !out.is_empty() {
            eprintln!(
                "rehost: {:.4} s image > {:?}",
                m.seconds(),
                String::from_utf8_lossy(&out)
            );
        }
        if !out.is_empty()
            && let Some(c) = client.as_mut()
        {
            let _ = c.set_nonblocking(false);
            if c.write_all(&out).is_err() {
                client = None;
            } else {
                let _ = c.set_nonblocking(true);
            }
        }
        // Never ahead of the wall clock × speed.
        let ahead = (m.seconds() - device0) / speed - wall.elapsed().as_secs_f64();
        if ahead > 0.0 {
            std::thread::sleep(Duration::from_secs_f64(ahead.min(0.05)));
        }
    }
}

/// The pages of `file` (a whole flash, as [`run`] writes it) that the image does not load
/// into: what the board had stored. No file yet: the flash as erased.
fn restore_flash(m: &mut Machine, file: &std::path::Path) -> Result<(), String> {
    let Ok(stored) = std::fs::read(file) else {
        return Ok(());
    };
    let mut now = m.flash()?;
    if stored.len() != now.len() {
        return Err(format!(
            "--flash {}: {} bytes, not this board's {}",
            file.display(),
            stored.len(),
            now.len()
        ));
    }
    for (page, (a, b)) in now.chunks_mut(4096).zip(stored.chunks(4096)).enumerate() {
        let at = page as u32 * 4096;
        if !m.image_covers(at, 4096) {
            a.copy_from_slice(b);
        }
    }
    m.set_flash(&now)
}
