//! The parameter record kept in flash: version, layout id, every value, CRC-32.

use core::fmt;

use crate::protocol::{Access, PARAMS, Settings};

/// Version of the stored parameter record.
pub const RECORD_VERSION: u8 = 1;

/// Bytes of a stored parameter record: version (1), layout id (4), mode (1), one f32 per
/// numeric parameter of [`PARAMS`] (little-endian), CRC-32 (4).
pub const RECORD_LEN: usize = 1 + 4 + 1 + 4 * MAX_NUMBERS + 4;

/// The most numeric parameters a record holds (room for the table to grow).
pub const MAX_NUMBERS: usize = 64;

/// Why a stored record was not used.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum RecordError {
    /// Shorter or longer than [`RECORD_LEN`].
    Length,
    /// The checksum does not match.
    Checksum,
    /// Another record version.
    Version,
    /// Written for another parameter table (parameters added or renamed).
    Layout,
    /// A value is out of its range, or the whole set is invalid.
    Invalid,
}

impl fmt::Display for RecordError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            RecordError::Length => "stored parameters: wrong length",
            RecordError::Checksum => "stored parameters: checksum mismatch",
            RecordError::Version => "stored parameters: other version",
            RecordError::Layout => "stored parameters: other parameter table",
            RecordError::Invalid => "stored parameters: invalid set",
        })
    }
}

/// CRC-32 (IEEE 802.3, reflected, as zlib's) of `data`.
pub fn crc32(data: &[u8]) -> u32 {
    let mut crc = !0u32;
    for &b in data {
        crc ^= b as u32;
        for _ in 0..8 {
            let mask = (crc & 1).wrapping_neg();
            crc = (crc >> 1) ^ (0xEDB8_8320 & mask);
        }
    }
    !crc
}

/// An id of the parameter table: FNV-1a over every path and its kind, so that a record
/// written for another table is recognised.
pub fn layout_id() -> u32 {
    let mut h = 0x811c_9dc5u32;
    let mut eat = |b: u8| {
        h ^= b as u32;
        h = h.wrapping_mul(0x0100_0193);
    };
    for p in PARAMS {
        for b in p.path.bytes() {
            eat(b);
        }
        eat(match p.access {
            Access::Number { .. } => b'n',
            Access::Mode => b'm',
            Access::Estimate(_) => b'e',
        });
    }
    h
}

/// The record of `s` for flash.
pub fn encode_settings(s: &Settings) -> [u8; RECORD_LEN] {
    let mut out = [0u8; RECORD_LEN];
    let mut w = out.iter_mut();
    let mut put = |bytes: &[u8]| {
        for &b in bytes {
            if let Some(slot) = w.next() {
                *slot = b;
            }
        }
    };
    put(&[RECORD_VERSION]);
    put(&layout_id().to_le_bytes());
    put(&[mode_code(s)]);
    let mut n = 0;
    for p in PARAMS {
        if let Access::Number { get, .. } = p.access {
            if n < MAX_NUMBERS {
                put(&get(s).to_le_bytes());
                n += 1;
            }
        }
    }
    let body = RECORD_LEN - 4;
    let crc = crc32(out.get(..body).unwrap_or(&[]));
    if let Some(tail) = out.get_mut(body..) {
        tail.copy_from_slice(&crc.to_le_bytes());
    }
    out
}

fn mode_code(s: &Settings) -> u8 {
    use crate::controller::FfMode;
    match s.ff.mode {
        FfMode::None => 0,
        FfMode::Static => 1,
        FfMode::Gms => 2,
        FfMode::GmsAdaptive => 3,
    }
}

/// The settings in a record, filled into a copy of `base` (the fields the table does not
/// cover) and validated as a whole: either every value is applied or the error says why none
/// is.
pub fn decode_settings(rec: &[u8], base: &Settings) -> Result<Settings, RecordError> {
    use crate::controller::FfMode;
    if rec.len() != RECORD_LEN {
        return Err(RecordError::Length);
    }
    let (body, tail) = rec.split_at(RECORD_LEN - 4);
    let mut crc = [0u8; 4];
    crc.copy_from_slice(tail);
    if crc32(body) != u32::from_le_bytes(crc) {
        return Err(RecordError::Checksum);
    }
    let byte = |i: usize| body.get(i).copied().unwrap_or(0);
    if byte(0) != RECORD_VERSION {
        return Err(RecordError::Version);
    }
    if u32::from_le_bytes([byte(1), byte(2), byte(3), byte(4)]) != layout_id() {
        return Err(RecordError::Layout);
    }
    let mut s = *base;
    s.ff.mode = match byte(5) {
        0 => FfMode::None,
        1 => FfMode::Static,
        2 => FfMode::Gms,
        3 => FfMode::GmsAdaptive,
        _ => return Err(RecordError::Invalid),
    };
    let mut values = body.get(6..).unwrap_or(&[]).chunks_exact(4);
    for p in PARAMS {
        if let Access::Number { set, min, max, .. } = p.access {
            let Some(chunk) = values.next() else {
                return Err(RecordError::Layout);
            };
            let mut b = [0u8; 4];
            b.copy_from_slice(chunk);
            let v = f32::from_le_bytes(b);
            if !(v.is_finite() && v >= min && v <= max) {
                return Err(RecordError::Invalid);
            }
            set(&mut s, v);
        }
    }
    s.validate().map_err(|_| RecordError::Invalid)?;
    Ok(s)
}
