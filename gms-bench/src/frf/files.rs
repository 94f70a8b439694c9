//! A sweep's files: its points as CSV, its margins as TOML.

use super::*;

/// `frf.csv`: `f_hz,gain_db,phase_deg,coherence`, one line per point.
pub fn csv(points: &[Point]) -> String {
    let mut s = String::from("f_hz,gain_db,phase_deg,coherence\n");
    for p in points {
        s += &format!(
            "{},{},{},{}\n",
            p.f_hz,
            p.gain_db(),
            p.phase_deg(),
            p.coherence
        );
    }
    s
}

/// `margins.toml`: `gain_margin_db`, `phase_margin_deg`, `crossover_hz`,
/// `peak_sensitivity_db` (and where each is); `inf` and `nan` where a crossing is not in the
/// band.
pub fn margins_toml(m: &Margins) -> String {
    let v = |x: f64| {
        if x.is_nan() {
            "nan".to_string()
        } else if x.is_infinite() {
            if x > 0.0 { "inf".into() } else { "-inf".into() }
        } else {
            format!("{x}")
        }
    };
    format!(
        "# gms-tune frf --loop open: the loop's stability margins\n\
         gain_margin_db = {}\n\
         phase_margin_deg = {}\n\
         crossover_hz = {}\n\
         peak_sensitivity_db = {}\n\
         gain_margin_hz = {}\n\
         phase_margin_hz = {}\n\
         peak_sensitivity_hz = {}\n",
        v(m.gain_margin_db),
        v(m.phase_margin_deg),
        v(m.crossover_hz),
        v(m.peak_sensitivity_db),
        v(m.gain_margin_hz),
        v(m.phase_margin_hz),
        v(m.peak_sensitivity_hz),
    )
}
