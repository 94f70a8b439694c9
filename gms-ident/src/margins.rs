//! A loop's stability margins from its loop gain given at a set of frequencies: the gain and
//! phase margins, the crossover and the sensitivity's peak (what `gms-tune frf --loop open`
//! reports from a measurement, and what commissioning computes from the linear model,
//! [`crate::linear`]), and where a sweep should add points to decide them.

use nalgebra::Complex;

type Complex64 = Complex<f64>;

/// 20 log10 |z| \[dB\].
pub fn db(z: Complex64) -> f64 {
    20.0 * z.norm().log10()
}

/// A loop's stability margins from its loop gain.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Margins {
    /// Gain margin \[dB\]: the least of −|L| over the frequencies where the phase crosses
    /// ±180° (infinite when there is no such crossing in the band). A crossing with |L| > 1
    /// below the crossover — a PID on a free mass has one at low frequency — bounds lowering
    /// the gain instead and is not counted; above the crossover it is a resonance that makes
    /// the loop unstable, and the margin is negative.
    pub gain_margin_db: f64,
    /// Where the gain margin is \[Hz\] (NaN without a phase crossover).
    pub gain_margin_hz: f64,
    /// Phase margin \[deg\]: the least of 180° − |∠L| over the frequencies where |L| crosses
    /// 1 (a loop whose gain rises through 1 again at a resonance has more than one).
    pub phase_margin_deg: f64,
    /// Where the phase margin is \[Hz\] (NaN without a crossover).
    pub phase_margin_hz: f64,
    /// The crossover frequency \[Hz\]: the lowest where |L| falls through 1, the loop's
    /// bandwidth (NaN without one).
    pub crossover_hz: f64,
    /// Peak of the sensitivity |1 / (1 + L)| over the points \[dB\].
    pub peak_sensitivity_db: f64,
    /// Where the sensitivity peaks \[Hz\].
    pub peak_sensitivity_hz: f64,
}

/// Where a loop gain's curve crosses: (index of the point before, fraction towards the next).
fn crossings(v: &[f64], level: impl Fn(f64) -> Option<f64>) -> Vec<(usize, f64)> {
    let mut out = Vec::new();
    for i in 0..v.len().saturating_sub(1) {
        if let Some(t) = level(v[i]).and_then(|l| {
            let (a, b) = (v[i] - l, v[i + 1] - l);
            ((a >= 0.0) != (b >= 0.0)).then(|| a / (a - b))
        }) {
            out.push((i, t));
        }
    }
    out
}

/// Phases \[deg\] unwrapped from the first.
fn unwrapped(z: &[Complex64]) -> Vec<f64> {
    let mut phase: Vec<f64> = Vec::with_capacity(z.len());
    for v in z {
        let mut p = v.arg().to_degrees();
        if let Some(prev) = phase.last() {
            while p - prev > 180.0 {
                p -= 360.0;
            }
            while p - prev < -180.0 {
                p += 360.0;
            }
        }
        phase.push(p);
    }
    phase
}

/// The margins of the loop gain `l` given at increasing frequencies `(f_hz, L)`: crossings
/// interpolated linearly in log frequency (gain in dB, phase unwrapped from the lowest
/// frequency).
pub fn margins(l: &[(f64, Complex64)]) -> Margins {
    let mut m = Margins {
        gain_margin_db: f64::INFINITY,
        gain_margin_hz: f64::NAN,
        phase_margin_deg: f64::NAN,
        phase_margin_hz: f64::NAN,
        crossover_hz: f64::NAN,
        peak_sensitivity_db: f64::NAN,
        peak_sensitivity_hz: f64::NAN,
    };
    let pts: Vec<(f64, Complex64)> = l
        .iter()
        .copied()
        .filter(|(f, z)| *f > 0.0 && z.re.is_finite() && z.im.is_finite())
        .collect();
    if pts.is_empty() {
        return m;
    }
    let z: Vec<Complex64> = pts.iter().map(|p| p.1).collect();
    let phase = unwrapped(&z);
    let gain: Vec<f64> = z.iter().map(|v| db(*v)).collect();
    let lf: Vec<f64> = pts.iter().map(|(f, _)| f.ln()).collect();
    let lerp = |i: usize, t: f64, v: &[f64]| v[i] + t * (v[i + 1] - v[i]);
    for (i, t) in crossings(&gain, |_| Some(0.0)) {
        let f = lerp(i, t, &lf).exp();
        if m.crossover_hz.is_nan() && gain[i] >= 0.0 {
            m.crossover_hz = f;
        }
        let pm = 180.0 - wrap180(lerp(i, t, &phase)).abs();
        if m.phase_margin_deg.is_nan() || pm < m.phase_margin_deg {
            m.phase_margin_deg = pm;
            m.phase_margin_hz = f;
        }
    }
    // Crossings of an odd multiple of 180°: the nearest to each point.
    let odd = |p: f64| Some(360.0 * ((p - 180.0) / 360.0).round() + 180.0);
    for (i, t) in crossings(&phase, odd) {
        let gm = -lerp(i, t, &gain);
        let f = lerp(i, t, &lf).exp();
        // Below the crossover a crossing with |L| > 1 is a conditionally stable loop's (a PID
        // on a free mass has one): a margin against lowering the gain, not counted. Above
        // it, |L| > 1 at ±180° is a resonance that destabilises: a negative margin.
        let below = m.crossover_hz.is_nan() || f < m.crossover_hz;
        if gm <= 0.0 && below {
            continue;
        }
        if gm < m.gain_margin_db {
            m.gain_margin_db = gm;
            m.gain_margin_hz = f;
        }
    }
    for (f, v) in &pts {
        let s = -db(1.0 + *v);
        if m.peak_sensitivity_db.is_nan() || s > m.peak_sensitivity_db {
            m.peak_sensitivity_db = s;
            m.peak_sensitivity_hz = *f;
        }
    }
    // Between the points: the parabola through the highest and its neighbours.
    let f: Vec<f64> = pts.iter().map(|p| p.0).collect();
    let sens: Vec<f64> = z.iter().map(|v| -db(1.0 + *v)).collect();
    if let Some(e) = extrema(&f, &sens)
        .into_iter()
        .filter(|e| e.peak)
        .max_by(|a, b| a.db.total_cmp(&b.db))
        && e.db > m.peak_sensitivity_db
    {
        m.peak_sensitivity_db = e.db;
        m.peak_sensitivity_hz = e.f_hz;
    }
    m
}

/// Frequencies to measure between the points of a loop gain where its margins are decided:
/// `per` more in each interval where |L| crosses 1 or the phase crosses ±180°, and around the
/// sensitivity's peak (log-spaced inside the interval).
pub fn refinement(l: &[(f64, Complex64)], per: usize) -> Vec<f64> {
    let z: Vec<Complex64> = l.iter().map(|p| p.1).collect();
    let phase = unwrapped(&z);
    let gain: Vec<f64> = z.iter().map(|v| db(*v)).collect();
    let odd = |p: f64| Some(360.0 * ((p - 180.0) / 360.0).round() + 180.0);
    let mut at: Vec<usize> = crossings(&gain, |_| Some(0.0))
        .into_iter()
        .chain(crossings(&phase, odd))
        .map(|(i, _)| i)
        .collect();
    if let Some((k, _)) = z
        .iter()
        .enumerate()
        .max_by(|a, b| (-db(1.0 + *a.1)).total_cmp(&-db(1.0 + *b.1)))
    {
        at.extend([k.saturating_sub(1), k]);
    }
    at.sort_unstable();
    at.dedup();
    let mut out = Vec::new();
    for i in at {
        let (Some(a), Some(b)) = (l.get(i), l.get(i + 1)) else {
            continue;
        };
        let (la, lb) = (a.0.ln(), b.0.ln());
        for k in 1..=per {
            out.push((la + (lb - la) * k as f64 / (per + 1) as f64).exp());
        }
    }
    out
}

fn wrap180(d: f64) -> f64 {
    let mut x = d % 360.0;
    if x > 180.0 {
        x -= 360.0;
    }
    if x <= -180.0 {
        x += 360.0;
    }
    x
}

/// A local extreme of a response.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Extremum {
    /// Its frequency \[Hz\], refined between the points.
    pub f_hz: f64,
    /// Its level \[dB\] (of the response it was found in).
    pub db: f64,
    /// How far it stands out of the line through its two neighbours \[dB\] (positive for a
    /// peak and for a dip alike).
    pub prominence_db: f64,
    /// A peak (resonance) or a dip (anti-resonance).
    pub peak: bool,
}

/// The local maxima and minima of `level_db` over the frequencies `f_hz` (increasing), each
/// refined by the parabola through it and its two neighbours in log frequency, strongest
/// first.
pub fn extrema(f_hz: &[f64], level_db: &[f64]) -> Vec<Extremum> {
    let n = f_hz.len().min(level_db.len());
    let mut out = Vec::new();
    for i in 1..n.saturating_sub(1) {
        let (a, b, c) = (level_db[i - 1], level_db[i], level_db[i + 1]);
        let peak = b > a && b > c;
        let dip = b < a && b < c;
        if !(peak || dip) {
            continue;
        }
        let (x0, x1, x2) = (f_hz[i - 1].ln(), f_hz[i].ln(), f_hz[i + 1].ln());
        // The parabola through the three points: its vertex.
        let d1 = (b - a) / (x1 - x0);
        let d2 = (c - b) / (x2 - x1);
        let curv = (d2 - d1) / (x2 - x0);
        let (x, y) = if curv != 0.0 {
            let xv = 0.5 * (x0 + x1) - d1 / (2.0 * curv);
            let xv = xv.clamp(x0, x2);
            (xv, b + d1 * (xv - x1) + curv * (xv - x0) * (xv - x1))
        } else {
            (x1, b)
        };
        let line = a + (c - a) * (x1 - x0) / (x2 - x0);
        out.push(Extremum {
            f_hz: x.exp(),
            db: y,
            prominence_db: (b - line).abs(),
            peak,
        });
    }
    out.sort_by(|p, q| q.prominence_db.total_cmp(&p.prominence_db));
    out
}
