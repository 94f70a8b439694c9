//! The position map (issue 29): a table over the motor's angle of a torque offset \[N·m\]
//! (conservative torque: cogging) and a friction scale \[-\] (a screw's once-per-turn
//! friction), interpolated between bins at the reference position, the offset added to the
//! feedforward and the scale multiplying the friction feedforward.
//!
//! The table is the control loop's (a buffer the shell gives it, [`MAP_VALUES`] values:
//! offset and scale interleaved); its geometry — the period, the bins, the origin (the
//! device-frame angle of bin 0) — and `map.enable` are settings. The phase is kept in the
//! reference's fixed point (1/65536 count) by addition of each step's increment, so a step
//! has no 64-bit division; the bin and the fraction come from one f32 multiplication.

use crate::control::reference::SUB_PER_COUNT;

/// The most bins a map has.
pub const MAP_BINS_MAX: usize = 512;

/// The values of a map's table: offset and scale per bin, interleaved.
pub const MAP_VALUES: usize = 2 * MAP_BINS_MAX;

/// The largest torque offset a bin may hold \[N·m\].
pub const MAP_OFFSET_MAX: f32 = 10.0;

/// The range of a bin's friction scale \[-\].
pub const MAP_SCALE_RANGE: (f32, f32) = (0.0, 2.0);

/// The map's settings.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct MapParams {
    /// 1: the map acts; 0: it does not (`map.enable`).
    pub enable: f32,
    /// Its period \[rad\] (one motor revolution by default).
    pub period: f32,
    /// Its bins (8 … [`MAP_BINS_MAX`]).
    pub bins: f32,
    /// The device-frame angle of bin 0 \[rad\] (the device counts from its power-up position:
    /// after a homing or an index pulse, the angle where the map's 0 is).
    pub origin: f32,
}

impl MapParams {
    /// Off, one revolution, 512 bins, origin 0.
    pub const DEFAULT: MapParams = MapParams {
        enable: 0.0,
        period: core::f32::consts::TAU,
        bins: 512.0,
        origin: 0.0,
    };
}

/// Whether a bin's values may go in a table.
pub fn valid_bin(offset: f32, scale: f32) -> bool {
    offset.is_finite()
        && offset.abs() <= MAP_OFFSET_MAX
        && scale >= MAP_SCALE_RANGE.0
        && scale <= MAP_SCALE_RANGE.1
}

/// The map's geometry in the reference's fixed point: worked out once for a parameter set, on
/// the protocol side (it divides in double precision, soft on the M4F: about 1,700 cycles that
/// a control step taking the set must not spend).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MapGeometry {
    /// The period [1/65536 count].
    period: i64,
    /// Bins.
    bins: u32,
    /// Bins per 1/65536 count.
    per_sub: f32,
    /// The origin [1/65536 count].
    origin: i64,
}

impl MapGeometry {
    /// The geometry of the map `m` for an encoder of `rad_per_count` \[rad\].
    pub fn new(m: &MapParams, rad_per_count: f32) -> MapGeometry {
        let sub = SUB_PER_COUNT as f64;
        let period = ((m.period as f64 / rad_per_count as f64) * sub).max(1.0) as i64;
        let bins = (m.bins as u32).clamp(1, MAP_BINS_MAX as u32);
        let origin = (m.origin as f64 / rad_per_count as f64 * sub) as i64;
        MapGeometry {
            period,
            bins,
            per_sub: (bins as f64 / period as f64) as f32,
            origin,
        }
    }
}

/// The map's geometry, and where the reference is in it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MapCursor {
    /// The period [1/65536 count].
    period: i64,
    /// Bins.
    bins: u32,
    /// Bins per 1/65536 count.
    per_sub: f32,
    /// The origin [1/65536 count].
    origin: i64,
    /// The reference's phase in the period, 0 … period − 1 [1/65536 count].
    phase: i64,
    /// The reference it was last moved to.
    last: i64,
}

impl MapCursor {
    /// The cursor of the map `m` for an encoder of `rad_per_count` \[rad\], at the reference
    /// `reference` [1/65536 count]: [`MapGeometry::new`], then [`MapCursor::at`].
    pub fn new(m: &MapParams, rad_per_count: f32, reference: i64) -> MapCursor {
        MapCursor::at(&MapGeometry::new(m, rad_per_count), reference)
    }

    /// The cursor of the map of geometry `g` at the reference `reference` [1/65536 count]
    /// (one 64-bit remainder: cheap enough for the step that takes a parameter set).
    pub fn at(g: &MapGeometry, reference: i64) -> MapCursor {
        MapCursor {
            period: g.period,
            bins: g.bins,
            per_sub: g.per_sub,
            origin: g.origin,
            phase: reference
                .saturating_sub(g.origin)
                .checked_rem_euclid(g.period)
                .unwrap_or(0),
            last: reference,
        }
    }

    /// Moves to the reference `reference` [1/65536 count] (by the increment since the last:
    /// a step's is far less than a period, so one correction keeps the phase in it; a larger
    /// jump is reduced by a division) and returns the table's interpolated `(offset, scale)`
    /// there. `table`: offset and scale interleaved, `2 × bins` values (a shorter one gives
    /// `(0, 1)`).
    pub fn sample(&mut self, reference: i64, table: &[f32]) -> (f32, f32) {
        let d = reference.wrapping_sub(self.last);
        self.last = reference;
        let mut p = self.phase.wrapping_add(d);
        if p >= self.period {
            p -= self.period;
        } else if p < 0 {
            p += self.period;
        }
        if !(0..self.period).contains(&p) {
            p = reference
                .saturating_sub(self.origin)
                .checked_rem_euclid(self.period)
                .unwrap_or(0);
        }
        self.phase = p;
        let u = p as f32 * self.per_sub;
        // 0 <= u < bins (float to int casts saturate).
        let i = (u as u32).min(self.bins.saturating_sub(1));
        let frac = u - i as f32;
        let j = if i.saturating_add(1) >= self.bins {
            0
        } else {
            i + 1
        };
        let at = |k: u32| {
            let k = 2 * k as usize;
            match (table.get(k), table.get(k.wrapping_add(1))) {
                (Some(o), Some(s)) => (*o, *s),
                _ => (0.0, 1.0),
            }
        };
        let (a, b) = (at(i), at(j));
        (a.0 + frac * (b.0 - a.0), a.1 + frac * (b.1 - a.1))
    }
}

/// Bytes of a stored map: version (1), period (f32), bins (u16), the table's values (f32,
/// little-endian, [`MAP_VALUES`] of them, unused bins 0), CRC-32 (4).
pub const MAP_RECORD_LEN: usize = 1 + 4 + 2 + 4 * MAP_VALUES + 4;

/// Version of the stored map.
pub const MAP_RECORD_VERSION: u8 = 1;

/// Why a stored map was not used.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum MapRecordError {
    /// Not one record long.
    Length,
    /// The checksum does not match.
    Checksum,
    /// Another record version.
    Version,
    /// Written for another period or bin count than the settings have.
    Geometry,
    /// A bin out of its range.
    Invalid,
}

impl MapRecordError {
    /// The one-line reason.
    pub fn reason(self) -> &'static str {
        match self {
            MapRecordError::Length => "stored map: wrong length",
            MapRecordError::Checksum => "stored map: checksum mismatch",
            MapRecordError::Version => "stored map: other version",
            MapRecordError::Geometry => {
                "stored map: another period or bin count than map.period and map.bins"
            }
            MapRecordError::Invalid => "stored map: a bin out of range",
        }
    }
}

/// Puts value `k` of a table (offset and scale interleaved) into the record `out`.
pub fn map_record_put(out: &mut [u8], k: usize, v: f32) {
    for (slot, b) in out.iter_mut().skip(7 + 4 * k).zip(v.to_le_bytes()) {
        *slot = b;
    }
}

/// Completes the record in `out` whose first `2 × bins` values were put
/// ([`map_record_put`]): the version, the period \[rad\] and the bins, the unused values 0,
/// the checksum. Returns its length.
pub fn map_record_finish(period: f32, bins: u32, out: &mut [u8]) -> usize {
    let bins = bins.min(MAP_BINS_MAX as u32);
    let head = [MAP_RECORD_VERSION]
        .into_iter()
        .chain(period.to_le_bytes())
        .chain((bins as u16).to_le_bytes());
    for (slot, b) in out.iter_mut().zip(head) {
        *slot = b;
    }
    for k in 2 * bins as usize..MAP_VALUES {
        map_record_put(out, k, 0.0);
    }
    let body = MAP_RECORD_LEN - 4;
    let crc = crate::crc::crc32(out.get(..body).unwrap_or(&[]));
    for (slot, b) in out.iter_mut().skip(body).zip(crc.to_le_bytes()) {
        *slot = b;
    }
    MAP_RECORD_LEN
}

/// Writes the record of a table (`values`: offset and scale interleaved, the first
/// `2 × bins` used) of period `period` \[rad\] into `out` (at least [`MAP_RECORD_LEN`] bytes);
/// returns the bytes written.
pub fn encode_map(period: f32, bins: u32, values: &[f32], out: &mut [u8]) -> usize {
    for (k, v) in values
        .iter()
        .enumerate()
        .take(2 * bins.min(MAP_BINS_MAX as u32) as usize)
    {
        map_record_put(out, k, *v);
    }
    map_record_finish(period, bins, out)
}

/// Value `k` of the table in a record (0 outside it).
pub fn map_record_value(rec: &[u8], k: usize) -> f32 {
    let mut b = [0u8; 4];
    for (d, v) in b.iter_mut().zip(rec.iter().skip(7 + 4 * k)) {
        *d = *v;
    }
    f32::from_le_bytes(b)
}

/// A table with no effect: offsets 0, scales 1.
pub fn clear(table: &mut [f32]) {
    for pair in table.chunks_exact_mut(2) {
        if let [o, k] = pair {
            (*o, *k) = (0.0, 1.0);
        }
    }
}

/// The table in a stored map, for the settings' map `p`: checked whole (length, checksum,
/// version, the same period and bins as `p`, every bin in range) before anything is written
/// into `out` (offset and scale interleaved, `2 × bins` values).
pub fn decode_map(rec: &[u8], p: &MapParams, out: &mut [f32]) -> Result<(), MapRecordError> {
    if rec.len() != MAP_RECORD_LEN {
        return Err(MapRecordError::Length);
    }
    let (body, tail) = rec.split_at(MAP_RECORD_LEN - 4);
    let mut crc = [0u8; 4];
    crc.copy_from_slice(tail);
    if crate::crc::crc32(body) != u32::from_le_bytes(crc) {
        return Err(MapRecordError::Checksum);
    }
    let byte = |i: usize| body.get(i).copied().unwrap_or(0);
    if byte(0) != MAP_RECORD_VERSION {
        return Err(MapRecordError::Version);
    }
    let period = f32::from_le_bytes([byte(1), byte(2), byte(3), byte(4)]);
    let bins = u16::from_le_bytes([byte(5), byte(6)]) as u32;
    if period.to_bits() != p.period.to_bits() || bins as f32 != p.bins {
        return Err(MapRecordError::Geometry);
    }
    let value = |k: usize| map_record_value(rec, k);
    for i in 0..bins as usize {
        if !valid_bin(value(2 * i), value(2 * i + 1)) {
            return Err(MapRecordError::Invalid);
        }
    }
    for (k, o) in out.iter_mut().enumerate().take(2 * bins as usize) {
        *o = value(k);
    }
    Ok(())
}
