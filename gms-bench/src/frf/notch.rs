//! A notch suggested from a sweep of the open loop: the resonance above the crossover that
//! holds the margins down, and the notch that lifts them most.

use super::*;

/// A notch proposed for the largest resonance above the crossover, with the margins it
/// would give.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Suggestion {
    /// Which notch it goes in: 0 for `filt.notch1`, 1 for `filt.notch2` (the first one off).
    pub slot: usize,
    /// The notch.
    pub notch: gms_core::control::shaping::Notch,
    /// The resonance: its frequency \[Hz\] and the loop gain's level there \[dB\].
    pub resonance: (f64, f64),
    /// The margins measured.
    pub before: Margins,
    /// The margins with the notch: the measured loop gain times the notch's response.
    pub after: Margins,
}

impl Suggestion {
    /// The settings that apply it: `(path, value)`.
    pub fn sets(&self) -> [(String, String); 3] {
        let n = self.slot + 1;
        [
            (
                format!("filt.notch{n}.f_hz"),
                format!("{}", self.notch.f_hz),
            ),
            (format!("filt.notch{n}.q"), format!("{}", self.notch.q)),
            (
                format!("filt.notch{n}.depth_db"),
                format!("{}", self.notch.depth_db),
            ),
        ]
    }
}

/// How good a pair of margins is for the choice of a notch: the lesser of the phase margin
/// over 45° and the gain margin over 10 dB (a loop with neither crossing scores high).
pub(super) fn score(m: &Margins) -> f64 {
    let pm = if m.phase_margin_deg.is_nan() {
        90.0
    } else {
        m.phase_margin_deg
    };
    let gm = m.gain_margin_db.min(30.0);
    (pm / 45.0).min(gm / 10.0)
}

/// A notch for the largest resonance of the open loop `points` above 1.5 × its crossover:
/// centred on the resonance's peak, its quality and depth chosen from a grid (q 0.5 to 8,
/// 6 to 40 dB) for the best of the margins the measured loop gain would have with it (the
/// lesser of PM/45° and GM/10 dB, counted up to 1: among the notches that reach 45° and
/// 10 dB, the shallowest, then the narrowest). `shaping` is the device's
/// filters now (the first notch that is off takes it), `pos_hz` its position rate \[Hz\].
pub fn suggest_notch(
    points: &[Point],
    shaping: &gms_core::control::shaping::ShapingParams,
    pos_hz: f64,
) -> Result<Suggestion, String> {
    use gms_core::control::shaping::{Notch, Shaping, ShapingParams};
    let good: Vec<&Point> = points
        .iter()
        .filter(|p| p.coherence >= MIN_COHERENCE)
        .collect();
    let l: Vec<(f64, Complex64)> = good.iter().map(|p| (p.f_hz, p.value)).collect();
    let before = margins(&l);
    let fc = if before.crossover_hz.is_finite() {
        before.crossover_hz
    } else {
        l.first().map_or(0.0, |p| p.0)
    };
    let f: Vec<f64> = l.iter().map(|p| p.0).collect();
    let g: Vec<f64> = l.iter().map(|p| db(p.1)).collect();
    let peak = extrema(&f, &g)
        .into_iter()
        .filter(|e| e.peak && e.f_hz > 1.5 * fc)
        .max_by(|a, b| a.db.total_cmp(&b.db))
        .ok_or_else(|| format!("no resonance above the crossover ({fc:.0} Hz) in the band"))?;
    let slot = shaping
        .notch
        .iter()
        .position(|n| n.f_hz == 0.0)
        .ok_or("both notches are in use (set filt.notch1.f_hz or filt.notch2.f_hz to 0)")?;
    let f0 = peak.f_hz as f32;
    let mut best: Option<(f64, Notch, Margins)> = None;
    for q in [0.5f32, 0.7, 1.0, 1.4, 2.0, 3.0, 4.0, 6.0, 8.0] {
        for depth_db in [6.0f32, 10.0, 15.0, 20.0, 25.0, 30.0, 40.0] {
            let notch = Notch {
                f_hz: f0,
                q,
                depth_db,
            };
            let p = ShapingParams {
                notch: [notch, Notch::OFF],
                lp_hz: 0.0,
            };
            let Ok(sh) = Shaping::try_new(&p, pos_hz as f32) else {
                continue;
            };
            let l2: Vec<(f64, Complex64)> = l
                .iter()
                .map(|(f, z)| {
                    let (re, im) = sh.response(*f, pos_hz);
                    (*f, z * Complex64::new(re, im))
                })
                .collect();
            let m = margins(&l2);
            // Enough is enough (45°, 10 dB): among the notches that reach it, the least
            // invasive (the shallowest, then the narrowest) disturbs the loop least.
            let s = score(&m).min(1.0);
            let better = match &best {
                None => true,
                Some((bs, bn, _)) => {
                    s > bs + 1e-9
                        || ((s - bs).abs() <= 1e-9
                            && (depth_db < bn.depth_db || (depth_db == bn.depth_db && q > bn.q)))
                }
            };
            if better {
                best = Some((s, notch, m));
            }
        }
    }
    let (_, notch, after) = best.ok_or("no notch can run at this rate")?;
    Ok(Suggestion {
        slot,
        notch,
        resonance: (peak.f_hz, peak.db),
        before,
        after,
    })
}
