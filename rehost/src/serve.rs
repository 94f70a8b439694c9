//! `rehost serve`: the image's USART2 bridged to a TCP port (see `main.rs`).

use std::io::{ErrorKind, Read, Write};
use std::net::{TcpListener, TcpStream};
use std::time::{Duration, Instant};

use rehost::Machine;

/// Device time run between two looks at the socket \[s\].
const SLICE: f64 = 0.5e-3;

/// Serves one client at a time on `listen`, the image running all along (between clients
/// too: a board does not stop when its host goes away).
pub fn run(mut m: Machine, listen: &str, speed: f64) -> Result<(), String> {
    let listener = TcpListener::bind(listen).map_err(|e| format!("listen on {listen}: {e}"))?;
    listener
        .set_nonblocking(true)
        .map_err(|e| format!("listen on {listen}: {e}"))?;
    let addr = listener
        .local_addr()
        .map_err(|e| format!("listen on {listen}: {e}"))?;
    eprintln!("rehost: the image's USART2 on {addr} (gms-tune --tcp {addr})");
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
        m.run_for(SLICE)
            .map_err(|e| format!("the image stopped: {e:?}"))?;
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
