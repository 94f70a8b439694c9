//! The motion learned on: the path (a sine or a trajectory file) and its table for the
//! device (points, steps between them, origin).

use super::*;

/// The periodic motion learned.
#[derive(Debug, Clone, PartialEq)]
pub enum Path {
    /// `x = A (1 − cos 2π f t)` from where the axis holds: amplitude \[rad\], frequency \[Hz\]
    /// (the paper's sine test with its reversals).
    Sine {
        /// Amplitude A \[rad\].
        amplitude: f64,
        /// Frequency f \[Hz\].
        freq: f64,
    },
    /// One period of positions: `(t [s], x [rad])`, t from 0 rising, the last row the
    /// period's end (its position the first's: the motion repeats), x the protocol's
    /// position (from the power-up position, as `move` and the soft limits).
    Trajectory(Vec<(f64, f64)>),
}

/// What to learn and how.
#[derive(Debug, Clone, PartialEq)]
pub struct LearnPlan {
    /// The motion.
    pub path: Path,
    /// Learning updates (iterations after the first pass).
    pub iterations: usize,
    /// The learning gain γ [-] (on the controller's own response).
    pub gain: f64,
    /// The Q filter's corner \[Hz\] (0: none).
    pub q_hz: f64,
    /// The lead λ \[s\].
    pub lead_s: f64,
    /// Iterations of growing RMS that stop the learning.
    pub patience: usize,
    /// Add the friction's local stiffness along the path to the learning filter.
    pub stiffness: bool,
}

/// The default learning updates.
pub const ITERATIONS: usize = 10;

/// The default learning gain γ [-].
pub const GAIN: f64 = 0.3;

/// The default Q filter's corner \[Hz\].
pub const Q_HZ: f64 = 400.0;

/// The default sine: the paper's test, amplitude \[rad\] and frequency \[Hz\].
pub const SINE: (f64, f64) = (0.05, 1.0);

impl Path {
    /// One period \[s\] (a trajectory's: its last row's time).
    pub fn period_s(&self) -> f64 {
        match self {
            Path::Sine { freq, .. } => 1.0 / freq,
            Path::Trajectory(rows) => rows.last().map_or(0.0, |r| r.0),
        }
    }
}

impl Default for LearnPlan {
    fn default() -> Self {
        LearnPlan {
            path: Path::Sine {
                amplitude: SINE.0,
                freq: SINE.1,
            },
            iterations: ITERATIONS,
            gain: GAIN,
            q_hz: Q_HZ,
            lead_s: 0.0,
            patience: 5,
            stiffness: true,
        }
    }
}

impl LearnPlan {
    /// Checks the plan's numbers (not the path against the device: the device does that).
    pub fn check(&self) -> Result<(), Error> {
        let bad = |m: &str| Err(Error::Device(m.to_string()));
        if !(self.gain.is_finite() && self.gain > 0.0 && self.gain <= 2.0) {
            return bad("the learning gain must be in (0, 2]");
        }
        if !(self.q_hz.is_finite() && self.q_hz >= 0.0) {
            return bad("the Q filter's corner must be >= 0 Hz");
        }
        if !self.lead_s.is_finite() || self.lead_s.abs() > 0.1 {
            return bad("the lead must be within ±0.1 s");
        }
        if self.iterations == 0 || self.iterations > 10_000 {
            return bad("iterations from 1 to 10000");
        }
        match &self.path {
            Path::Sine { amplitude, freq } => {
                if !(amplitude.is_finite() && *amplitude > 0.0) {
                    return bad("the sine's amplitude must be > 0 rad");
                }
                if !(freq.is_finite() && *freq > 0.0) {
                    return bad("the sine's frequency must be > 0 Hz");
                }
            }
            Path::Trajectory(rows) => check_trajectory(rows)?,
        }
        Ok(())
    }
}

/// Checks a trajectory's rows: at least 4, finite, times from 0 strictly rising.
pub(super) fn check_trajectory(rows: &[(f64, f64)]) -> Result<(), Error> {
    let bad = |m: String| Err(Error::Device(m));
    if rows.len() < 4 {
        return bad(format!(
            "the trajectory has {} rows: at least 4",
            rows.len()
        ));
    }
    if rows.iter().any(|(t, x)| !t.is_finite() || !x.is_finite()) {
        return bad("the trajectory has a value that is not a number".into());
    }
    if rows[0].0 != 0.0 {
        return bad("the trajectory's first time must be 0 s".into());
    }
    for (i, w) in rows.windows(2).enumerate() {
        if w[1].0 <= w[0].0 {
            return bad(format!("the trajectory's times must rise (row {})", i + 2));
        }
    }
    Ok(())
}

/// Reads a trajectory file's text: a header `t_s,position_rad` (or any header whose first
/// field is not a number), then one `t,x` row a line.
pub fn parse_trajectory(text: &str) -> Result<Vec<(f64, f64)>, Error> {
    let mut rows = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let mut f = line.split(',').map(str::trim);
        let (a, b) = (f.next().unwrap_or(""), f.next().unwrap_or(""));
        match (a.parse::<f64>(), b.parse::<f64>()) {
            (Ok(t), Ok(x)) if f.next().is_none() => rows.push((t, x)),
            _ if i == 0 && a.parse::<f64>().is_err() => {}
            _ => {
                return Err(Error::Device(format!(
                    "trajectory line {}: expected `t_s,position_rad`, found `{line}`",
                    i + 1
                )));
            }
        }
    }
    check_trajectory(&rows)?;
    Ok(rows)
}

/// A table as the device plays it.
#[derive(Debug, Clone, PartialEq)]
pub struct Table {
    /// Points in a period.
    pub points: u32,
    /// Position steps between points.
    pub steps: u32,
    /// The origin \[counts\].
    pub origin: i64,
    /// The reference at the points \[counts from the origin\].
    pub values: Vec<f64>,
    /// The position-loop rate \[Hz\].
    pub rate: f64,
    /// The encoder's resolution \[rad/count\].
    pub rad_per_count: f64,
}

impl Table {
    /// The period \[s\].
    pub fn period(&self) -> f64 {
        f64::from(self.points) * f64::from(self.steps) / self.rate
    }

    /// The time between points \[s\].
    pub fn dt(&self) -> f64 {
        f64::from(self.steps) / self.rate
    }

    /// The first point's position \[rad\] (the protocol's).
    pub fn start_rad(&self) -> f64 {
        (self.origin as f64 + self.values.first().copied().unwrap_or(0.0)) * self.rad_per_count
    }
}

/// The most points the device's table holds.
pub const POINTS: u32 = gms_core::control::table::TABLE_POINTS as u32;

/// The table for `path` at the position rate `rate` \[Hz\] with an encoder of `rpc`
/// \[rad/count\], a sine starting at `here` \[counts\]: as many points as the device holds at the
/// fewest steps apart (a period of whole steps, rounded to whole points).
pub fn plan_table(path: &Path, rate: f64, rpc: f64, here: f64) -> Result<Table, Error> {
    let period_s = path.period_s();
    let total = (period_s * rate).round();
    if !(total >= 4.0 && total <= 600.0 * rate) {
        return Err(Error::Device(format!(
            "a period of {period_s} s: from 4 position steps to 600 s"
        )));
    }
    let total = total as u64;
    let steps = total.div_ceil(u64::from(POINTS)).max(1);
    let points = ((total as f64 / steps as f64).round() as u32).clamp(4, POINTS);
    let dt = steps as f64 / rate;
    let (origin, values) = match path {
        Path::Sine { amplitude, .. } => {
            let a = amplitude / rpc;
            let w = std::f64::consts::TAU / f64::from(points);
            let v = (0..points)
                .map(|k| a * (1.0 - (w * f64::from(k)).cos()))
                .collect();
            (here.round() as i64, v)
        }
        Path::Trajectory(rows) => {
            let x0 = rows[0].1 / rpc;
            let origin = x0.round() as i64;
            // The file's period stretched onto the table's (they differ by under a step).
            let scale = rows.last().map_or(1.0, |r| r.0) / (f64::from(points) * dt);
            let v = (0..points)
                .map(|k| interpolate(rows, f64::from(k) * dt * scale) / rpc - origin as f64)
                .collect();
            (origin, v)
        }
    };
    Ok(Table {
        points,
        steps: steps as u32,
        origin,
        values,
        rate,
        rad_per_count: rpc,
    })
}

/// Linear interpolation of `rows` at `t` (held beyond the ends).
pub(super) fn interpolate(rows: &[(f64, f64)], t: f64) -> f64 {
    let i = rows.partition_point(|r| r.0 <= t);
    match (rows.get(i.wrapping_sub(1)), rows.get(i)) {
        (Some(a), Some(b)) => a.1 + (b.1 - a.1) * (t - a.0) / (b.0 - a.0),
        (Some(a), None) => a.1,
        (None, Some(b)) => b.1,
        (None, None) => 0.0,
    }
}
