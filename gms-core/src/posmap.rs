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

use crate::reference::SUB_PER_COUNT;

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

/// The map's geometry in the reference's fixed point, and where the reference is in it.
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
    /// `reference` [1/65536 count] (one 64-bit division: outside the steps).
    pub fn new(m: &MapParams, rad_per_count: f32, reference: i64) -> MapCursor {
        let sub = SUB_PER_COUNT as f64;
        let period = ((m.period as f64 / rad_per_count as f64) * sub).max(1.0) as i64;
        let bins = (m.bins as u32).clamp(1, MAP_BINS_MAX as u32);
        let origin = (m.origin as f64 / rad_per_count as f64 * sub) as i64;
        MapCursor {
            period,
            bins,
            per_sub: (bins as f64 / period as f64) as f32,
            origin,
            phase: reference
                .saturating_sub(origin)
                .checked_rem_euclid(period)
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

    /// The bin the reference is in now, and the fraction towards the next.
    pub fn position(&self) -> (u32, f32) {
        let u = self.phase as f32 * self.per_sub;
        let i = (u as u32).min(self.bins.saturating_sub(1));
        (i, u - i as f32)
    }
}
