//! The parameter record kept in flash: each setting under a stable id of its path, so that a
//! firmware with another parameter table loads every setting it still knows.
//!
//! Record (version 2, [`RECORD_LEN`] bytes, little-endian): version (1), the number of entries
//! `n` (1), `n` entries of (id (4), value (4)), zeros up to the CRC-32 (4) of everything before
//! it. An entry's id is [`param_id`] of its path (FNV-1a of the path's bytes: the same path
//! gives the same id in every firmware); its value is the setting as an f32, the feedforward
//! mode as its code (0 `none`, 1 `static`, 2 `gms`, 3 `gms-adaptive`).
//!
//! Loading ([`decode_settings_with`]): every entry whose id the table knows is set, clamped
//! into its range (and rounded if whole); an entry the table does not know is dropped; a
//! parameter the record does not hold keeps its default; the [`LoadReport`] names all three
//! for the log. The whole set is then validated: it runs whole or not at all. A version-1
//! record (one value per parameter in table order, behind a layout id of the table) still
//! loads when its layout is the table's.

use core::fmt;

use crate::control::controller::FfMode;
use crate::crc::crc32;
use crate::protocol::{Access, PARAMS, Param, Settings};

/// Version of the stored parameter record written now.
pub const RECORD_VERSION: u8 = 2;

/// The version of the records written before settings were kept by id: one value per number
/// of the table in order, behind a layout id of the table (read, not written).
const RECORD_VERSION_V1: u8 = 1;

/// The most entries a record holds (room for the table to grow).
pub const MAX_ENTRIES: usize = 64;

/// The most numeric parameters a record holds (the table's numbers and its mode fit in
/// [`MAX_ENTRIES`]).
pub const MAX_NUMBERS: usize = MAX_ENTRIES - 1;

/// Bytes of a stored parameter record: version (1), entry count (1), [`MAX_ENTRIES`] entries of
/// 8 bytes, CRC-32 (4).
pub const RECORD_LEN: usize = 1 + 1 + 8 * MAX_ENTRIES + 4;

/// Bytes of a version-1 record (one f32 per number of the table, 64 slots).
const RECORD_LEN_V1: usize = 1 + 4 + 1 + 4 * 64 + 4;

/// The most names each list of a [`LoadReport`] keeps (its counts go on).
pub const REPORT_MAX: usize = 8;

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
    /// A version-1 record written for another parameter table (version 1 kept no ids).
    Layout,
    /// The entries do not form a record (a count over [`MAX_ENTRIES`], an unknown mode), or
    /// the set they give is invalid as a whole.
    Invalid,
}

impl fmt::Display for RecordError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            RecordError::Length => "stored parameters: wrong length",
            RecordError::Checksum => "stored parameters: checksum mismatch",
            RecordError::Version => "stored parameters: other version",
            RecordError::Layout => "stored parameters: an old record of another parameter table",
            RecordError::Invalid => "stored parameters: invalid set",
        })
    }
}

/// What loading a record did beyond setting a value as stored: the settings clamped into
/// their range, the entries this table does not know (dropped), the parameters the record
/// did not hold (left at their defaults). Each list keeps its first [`REPORT_MAX`] names; the
/// counts are whole.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct LoadReport {
    /// Settings taken from the record (as stored or clamped).
    pub kept: u8,
    /// Settings clamped into their range (or rounded to a whole number).
    pub clamped: u8,
    /// Entries of the record this table does not know, or whose value is not a number.
    pub dropped: u8,
    /// Parameters of this table the record did not hold.
    pub missing: u8,
    clamped_paths: [&'static str; REPORT_MAX],
    dropped_ids: [u32; REPORT_MAX],
    missing_paths: [&'static str; REPORT_MAX],
}

/// One line of a [`LoadReport`], for the log.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ReportLine {
    /// A stored setting was out of this firmware's range and was clamped into it.
    Clamped(&'static str),
    /// A stored entry this firmware does not know (its id), or whose value is not a number.
    Dropped(u32),
    /// A parameter of this firmware not in the record: it runs at its default.
    Missing(&'static str),
}

impl fmt::Display for ReportLine {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ReportLine::Clamped(p) => write!(f, "stored {p}: clamped into its range"),
            ReportLine::Dropped(id) => {
                write!(
                    f,
                    "stored setting {id:#010x}: dropped (not a parameter here)"
                )
            }
            ReportLine::Missing(p) => write!(f, "{p}: not in the store, at its default"),
        }
    }
}

#[cfg(feature = "defmt")]
impl defmt::Format for ReportLine {
    fn format(&self, f: defmt::Formatter) {
        match self {
            ReportLine::Clamped(p) => defmt::write!(f, "stored {=str}: clamped into its range", p),
            ReportLine::Dropped(id) => defmt::write!(
                f,
                "stored setting {=u32:#010x}: dropped (not a parameter here)",
                id
            ),
            ReportLine::Missing(p) => {
                defmt::write!(f, "{=str}: not in the store, at its default", p)
            }
        }
    }
}

impl LoadReport {
    /// True when every stored setting was loaded as stored and every parameter was stored.
    pub fn is_clean(&self) -> bool {
        self.clamped == 0 && self.dropped == 0 && self.missing == 0
    }

    /// The named lines: the clamped settings, the dropped ids, the missing parameters (the
    /// first [`REPORT_MAX`] of each).
    pub fn lines(&self) -> impl Iterator<Item = ReportLine> + '_ {
        let n = |c: u8| (c as usize).min(REPORT_MAX);
        let clamped = self.clamped_paths.iter().take(n(self.clamped));
        let dropped = self.dropped_ids.iter().take(n(self.dropped));
        let missing = self.missing_paths.iter().take(n(self.missing));
        clamped
            .map(|p| ReportLine::Clamped(p))
            .chain(dropped.map(|&id| ReportLine::Dropped(id)))
            .chain(missing.map(|p| ReportLine::Missing(p)))
    }

    fn note_clamped(&mut self, path: &'static str) {
        if let Some(slot) = self.clamped_paths.get_mut(self.clamped as usize) {
            *slot = path;
        }
        self.clamped = self.clamped.saturating_add(1);
    }

    fn note_dropped(&mut self, id: u32) {
        if let Some(slot) = self.dropped_ids.get_mut(self.dropped as usize) {
            *slot = id;
        }
        self.dropped = self.dropped.saturating_add(1);
    }

    fn note_missing(&mut self, path: &'static str) {
        if let Some(slot) = self.missing_paths.get_mut(self.missing as usize) {
            *slot = path;
        }
        self.missing = self.missing.saturating_add(1);
    }
}

/// A record loaded: the settings that run and what loading did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Loaded {
    /// The settings: the record's where it had them, the defaults elsewhere.
    pub settings: Settings,
    /// What was clamped, dropped or missing.
    pub report: LoadReport,
}

/// The stable id of a parameter's path in a record: FNV-1a (32 bits) of its bytes.
pub const fn param_id(path: &str) -> u32 {
    let b = path.as_bytes();
    let mut h = 0x811c_9dc5u32;
    let mut i = 0;
    while i < b.len() {
        h ^= b[i] as u32;
        h = h.wrapping_mul(0x0100_0193);
        i += 1;
    }
    h
}

/// The id of the parameter table of version-1 records: FNV-1a over every path and its kind.
pub fn layout_id() -> u32 {
    layout_id_of(PARAMS)
}

fn layout_id_of(table: &[Param]) -> u32 {
    let mut h = 0x811c_9dc5u32;
    let mut eat = |b: u8| {
        h ^= b as u32;
        h = h.wrapping_mul(0x0100_0193);
    };
    for p in table {
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

/// The record of `s` for flash, under the firmware's table [`PARAMS`].
pub fn encode_settings(s: &Settings) -> [u8; RECORD_LEN] {
    encode_settings_with(s, PARAMS)
}

/// The record of `s` under the parameter table `table`: one entry per number and the mode
/// (the first [`MAX_ENTRIES`]; `the_table_fits_a_record` checks the firmware's fits).
// Not inlined: the record and its scratch stay in this frame, out of the frame of the task
// that saves (a task's poll frame must step the stack by less than the board's guard).
#[inline(never)]
pub fn encode_settings_with(s: &Settings, table: &[Param]) -> [u8; RECORD_LEN] {
    let mut out = [0u8; RECORD_LEN];
    let mut n = 0usize;
    for p in table {
        let value = match p.access {
            Access::Number { get, .. } => get(s),
            Access::Mode => mode_code(s.ff.mode) as f32,
            Access::Estimate(_) => continue,
        };
        let at = 2 + 8 * n;
        let Some(slot) = out.get_mut(at..at + 8) else {
            break;
        };
        slot[..4].copy_from_slice(&param_id(p.path).to_le_bytes());
        slot[4..].copy_from_slice(&value.to_le_bytes());
        n += 1;
    }
    out[0] = RECORD_VERSION;
    out[1] = n as u8;
    let body = RECORD_LEN - 4;
    let crc = crc32(&out[..body]);
    out[body..].copy_from_slice(&crc.to_le_bytes());
    out
}

fn mode_code(m: FfMode) -> u8 {
    match m {
        FfMode::None => 0,
        FfMode::Static => 1,
        FfMode::Gms => 2,
        FfMode::GmsAdaptive => 3,
    }
}

fn mode_of(code: u8) -> Option<FfMode> {
    Some(match code {
        0 => FfMode::None,
        1 => FfMode::Static,
        2 => FfMode::Gms,
        3 => FfMode::GmsAdaptive,
        _ => return None,
    })
}

/// The settings in a record under the firmware's table [`PARAMS`] (see
/// [`decode_settings_with`]).
pub fn decode_settings(rec: &[u8], base: &Settings) -> Result<Loaded, RecordError> {
    decode_settings_with(rec, base, PARAMS)
}

/// The settings in a record under the parameter table `table`, filled into a copy of `base`
/// (the defaults: what the record does not hold), and validated as a whole: either the set
/// runs or the error says why none of it does. Stored values out of their range are clamped
/// into it, entries the table does not know are dropped; the report names both, and the
/// parameters the record did not hold.
// Not inlined, as `encode_settings_with`.
#[inline(never)]
pub fn decode_settings_with(
    rec: &[u8],
    base: &Settings,
    table: &[Param],
) -> Result<Loaded, RecordError> {
    let Some((&version, _)) = rec.split_first() else {
        return Err(RecordError::Length);
    };
    let len = if version == RECORD_VERSION_V1 {
        RECORD_LEN_V1
    } else {
        RECORD_LEN
    };
    if rec.len() < len
        || rec
            .get(len..)
            .is_some_and(|rest| rest.iter().any(|&b| b != 0))
    {
        return Err(RecordError::Length);
    }
    let (body, tail) = rec.split_at(len - 4);
    let mut crc = [0u8; 4];
    crc.copy_from_slice(tail.get(..4).ok_or(RecordError::Length)?);
    if crc32(body) != u32::from_le_bytes(crc) {
        return Err(RecordError::Checksum);
    }
    let loaded = match version {
        RECORD_VERSION => decode_entries(body, base, table)?,
        RECORD_VERSION_V1 => decode_v1(body, base, table)?,
        _ => return Err(RecordError::Version),
    };
    loaded
        .settings
        .validate()
        .map_err(|_| RecordError::Invalid)?;
    Ok(loaded)
}

/// A version-2 body: entries by id, set in the table's order (a count before the values it
/// makes room for, as the protocol's `list`).
fn decode_entries(body: &[u8], base: &Settings, table: &[Param]) -> Result<Loaded, RecordError> {
    let n = body.get(1).copied().unwrap_or(0) as usize;
    if n > MAX_ENTRIES {
        return Err(RecordError::Invalid);
    }
    let entries = body.get(2..2 + 8 * n).ok_or(RecordError::Invalid)?;
    let entry = |e: &[u8]| {
        let word = |i: usize| {
            let mut b = [0u8; 4];
            b.copy_from_slice(e.get(i..i + 4).unwrap_or(&[0; 4]));
            b
        };
        (u32::from_le_bytes(word(0)), f32::from_le_bytes(word(4)))
    };
    let stored = |id: u32| {
        entries
            .chunks_exact(8)
            .map(entry)
            .find(|&(e, _)| e == id)
            .map(|(_, v)| v)
    };
    let mut s = *base;
    let mut report = LoadReport::default();
    for p in table {
        if matches!(p.access, Access::Estimate(_)) {
            continue;
        }
        let id = param_id(p.path);
        let Some(v) = stored(id) else {
            report.note_missing(p.path);
            continue;
        };
        if !v.is_finite() {
            report.note_dropped(id);
            continue;
        }
        match p.access {
            Access::Number {
                set,
                min,
                max,
                integer,
                ..
            } => {
                let whole = if integer { round(v) } else { v };
                let c = whole.max(min).min(max);
                if c != v {
                    report.note_clamped(p.path);
                }
                set(&mut s, c);
            }
            Access::Mode => {
                let code = if (0.0..=255.0).contains(&v) && v == round(v) {
                    mode_of(v as u8)
                } else {
                    None
                };
                let Some(m) = code else {
                    report.note_dropped(id);
                    continue;
                };
                s.ff.mode = m;
            }
            Access::Estimate(_) => continue,
        }
        report.kept = report.kept.saturating_add(1);
    }
    // The entries no parameter of this table stands for.
    let known = |id: u32| {
        table
            .iter()
            .any(|p| !matches!(p.access, Access::Estimate(_)) && param_id(p.path) == id)
    };
    for (id, _) in entries.chunks_exact(8).map(entry) {
        if !known(id) {
            report.note_dropped(id);
        }
    }
    Ok(Loaded {
        settings: s,
        report,
    })
}

/// A version-1 body: one value per number of the table in order, behind the table's layout
/// id; every value in range or none is used.
fn decode_v1(body: &[u8], base: &Settings, table: &[Param]) -> Result<Loaded, RecordError> {
    let byte = |i: usize| body.get(i).copied().unwrap_or(0);
    if u32::from_le_bytes([byte(1), byte(2), byte(3), byte(4)]) != layout_id_of(table) {
        return Err(RecordError::Layout);
    }
    let mut s = *base;
    s.ff.mode = mode_of(byte(5)).ok_or(RecordError::Invalid)?;
    let mut report = LoadReport {
        kept: 1,
        ..LoadReport::default()
    };
    let mut values = body.get(6..).unwrap_or(&[]).chunks_exact(4);
    for p in table {
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
            report.kept = report.kept.saturating_add(1);
        }
    }
    Ok(Loaded {
        settings: s,
        report,
    })
}

/// `x` rounded to the nearest whole number (halves away from zero), for the finite `x` of a
/// record.
fn round(x: f32) -> f32 {
    if x.abs() >= 8_388_608.0 {
        return x;
    }
    let t = x as i32 as f32;
    let f = x - t;
    if f >= 0.5 {
        t + 1.0
    } else if f <= -0.5 {
        t - 1.0
    } else {
        t
    }
}
