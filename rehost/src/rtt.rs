//! The image's defmt log: the bytes defmt-rtt writes into the RTT control block's up channel 0
//! (`_SEGGER_RTT`: the id, the channel counts, then per up channel name, buffer, size, write
//! offset, read offset, flags), taken as a probe would (the read offset advanced) and decoded
//! with defmt-decoder against the ELF's table.

use defmt_decoder::{DecodeError, StreamDecoder, Table};

/// Where up channel 0's descriptor fields are, from the control block's address.
pub struct Channel {
    /// The buffer's address field.
    pub buffer: u32,
    /// The size field.
    pub size: u32,
    /// The write offset field.
    pub write: u32,
    /// The read offset field.
    pub read: u32,
}

impl Channel {
    /// Up channel 0 of the control block at `cb` (SEGGER's layout: 16 bytes of id, two i32
    /// counts, then 24-byte descriptors).
    pub fn up0(cb: u32) -> Channel {
        let d = cb + 24;
        Channel {
            buffer: d + 4,
            size: d + 8,
            write: d + 12,
            read: d + 16,
        }
    }
}

/// A decoded log line.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Line {
    /// Its level ("INFO", "WARN", …).
    pub level: String,
    /// Its text.
    pub text: String,
}

impl std::fmt::Display for Line {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{:<5} {}", self.level, self.text)
    }
}

/// The decoder of one image's log.
pub struct Log {
    decoder: Box<dyn StreamDecoder + Send + Sync + 'static>,
    /// Every line so far.
    pub lines: Vec<Line>,
}

impl Log {
    /// A decoder for the image `elf` (its `.defmt` table); `None` if it has none.
    pub fn new(elf: &[u8]) -> Result<Option<Log>, String> {
        let table = Table::parse(elf).map_err(|e| format!("the image's defmt table: {e}"))?;
        Ok(table.map(|t| {
            // The decoder borrows the table for the run's whole life.
            let t: &'static Table = Box::leak(Box::new(t));
            Log {
                decoder: t.new_stream_decoder(),
                lines: Vec::new(),
            }
        }))
    }

    /// Takes bytes read from the channel; returns the lines they completed.
    pub fn feed(&mut self, bytes: &[u8]) -> Vec<Line> {
        self.decoder.received(bytes);
        let mut out = Vec::new();
        loop {
            match self.decoder.decode() {
                Ok(frame) => {
                    let level = frame
                        .level()
                        .map(|l| l.as_str().to_uppercase())
                        .unwrap_or_else(|| "PRINT".into());
                    out.push(Line {
                        level,
                        text: frame.display_message().to_string(),
                    });
                }
                Err(DecodeError::UnexpectedEof) => break,
                Err(DecodeError::Malformed) => {
                    out.push(Line {
                        level: "ERROR".into(),
                        text: "(a malformed defmt frame)".into(),
                    });
                    break;
                }
            }
        }
        self.lines.extend(out.iter().cloned());
        out
    }
}
