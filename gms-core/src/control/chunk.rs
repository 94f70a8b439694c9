//! The chunk a long read is copied in between the control loop and the protocol side
//! (capture, position map and table reads): a fixed buffer, filled a chunk at a time.

/// Values one read chunk carries at most.
pub const CHUNK_VALUES: usize = 128;

/// A chunk of recorded values, sample-major (`nfields` values per sample).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Chunk {
    /// The first sample's index.
    pub start: u32,
    /// Samples in the chunk.
    pub samples: u32,
    /// Values per sample.
    pub nfields: u8,
    /// The values; the first `samples × nfields` used.
    pub values: [f32; CHUNK_VALUES],
}

impl Chunk {
    /// An empty chunk of rows from `start`, `nfields` values a row.
    pub const fn new(start: u32, nfields: u8) -> Chunk {
        Chunk {
            start,
            samples: 0,
            nfields,
            values: [0.0; CHUNK_VALUES],
        }
    }

    /// The chunk started over in place as an empty one of rows from `start`, `nfields`
    /// values a row (its values are left: only the first `samples × nfields` are read).
    pub fn restart(&mut self, start: u32, nfields: u8) {
        self.start = start;
        self.nfields = nfields;
        self.samples = 0;
    }
}
