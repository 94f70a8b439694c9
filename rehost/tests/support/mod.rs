//! What the tests against the image share: the image `REHOST_ELF` names, and `rehost serve`
//! on it with its log kept.
#![allow(dead_code)]

use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, Mutex, mpsc};
use std::time::Duration;

/// The image `REHOST_ELF` names; a relative path from the workspace's root (cargo runs the
/// test in `rehost/`).
pub fn elf() -> String {
    let path = std::env::var("REHOST_ELF").unwrap_or_else(|_| {
        panic!(
            "REHOST_ELF is not set: name the Nucleo image (`cargo fw-f446`, then \
             REHOST_ELF=target/thumbv7em-none-eabihf/firmware/firmware)"
        )
    });
    let p = std::path::Path::new(&path);
    let p = if p.is_relative() {
        std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("..")
            .join(p)
    } else {
        p.to_path_buf()
    };
    assert!(p.is_file(), "REHOST_ELF: no file at {}", p.display());
    p.display().to_string()
}

/// The image's log so far, a line each (for a failure's message).
pub fn log(m: &rehost::Machine) -> String {
    m.log_lines
        .iter()
        .map(|l| l.text.clone())
        .collect::<Vec<_>>()
        .join("\n")
}

/// `line`'s reply line (the last), within 0.5 s of device time.
pub fn ask(m: &mut rehost::Machine, line: &str) -> String {
    let r = m
        .request(line, 0.5)
        .unwrap_or_else(|e| panic!("{e}\n{}", log(m)));
    r.last().cloned().unwrap_or_default()
}

/// `rehost serve` on the image from reset, on a free port.
pub struct Served {
    child: Child,
    /// Its TCP address.
    pub addr: String,
    /// The decoded log of the image (rehost's stderr), for a failure's message.
    pub log: Arc<Mutex<Vec<String>>>,
}

impl Served {
    /// Starts it, `extra` arguments added (`--scenario FILE`); waits until it listens
    /// (within `within` of wall time).
    pub fn start(extra: &[&str], within: Duration) -> Served {
        let mut child = Command::new(env!("CARGO_BIN_EXE_rehost"))
            .args(["serve", &elf(), "--listen", "127.0.0.1:0"])
            .args(extra)
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .expect("rehost serve");
        let log = Arc::new(Mutex::new(Vec::new()));
        let (tx, rx) = mpsc::channel();
        let stderr = child.stderr.take().unwrap();
        let keep = Arc::clone(&log);
        std::thread::spawn(move || {
            for line in BufReader::new(stderr).lines().map_while(Result::ok) {
                if let Some(addr) = line
                    .strip_prefix("rehost: the image's USART2 on ")
                    .or_else(|| line.strip_prefix("rehost: the image's USB on "))
                    .and_then(|r| r.split_whitespace().next())
                {
                    let _ = tx.send(addr.to_string());
                }
                keep.lock().unwrap().push(line);
            }
        });
        let addr = rx
            .recv_timeout(within)
            .unwrap_or_else(|_| panic!("rehost serve did not listen: {:?}", log.lock()));
        Served { child, addr, log }
    }

    /// Ends the process (as a power cut: what its flash file holds stays).
    pub fn stop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }

    /// The image's log so far, one line each.
    pub fn log_text(&self) -> String {
        self.log.lock().unwrap().join("\n")
    }
}

impl Drop for Served {
    fn drop(&mut self) {
        self.stop();
    }
}
