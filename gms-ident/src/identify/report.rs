//! The identification's report and plots.

use super::Identified;
use crate::Error;

/// Writes `report.txt`, `virgin.svg` (the averaged virgin curve against the identified
/// blocks, as the paper's Fig. 1 right and Fig. 2) and `stribeck.svg` (the sliding data against
/// the fitted curve, over log10 of the speed) into `dir`; with a lag fit, `lag.svg` (the
/// recorded friction against the fitted model over time).
pub fn write_report(id: &Identified, dir: &std::path::Path) -> Result<(), Error> {
    write_report_inner(id, dir).map_err(Error::Io)
}

fn write_report_inner(id: &Identified, dir: &std::path::Path) -> Result<(), String> {
    std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let text: String = id.report.iter().map(|l| format!("{l}\n")).collect();
    crate::io::write_atomic(&dir.join("report.txt"), text.as_bytes())?;
    if let Some(v) = &id.virgin {
        let xmax = id.virgin_data.last().map_or(1.0, |p| p.0) * 1.2;
        let curve: Vec<(f64, f64)> = (0..=400)
            .map(|i| {
                let x = xmax * i as f64 / 400.0;
                let f: f64 = v
                    .blocks
                    .iter()
                    .zip(&v.breakpoints)
                    .map(|(b, d)| b.k * x.min(*d))
                    .sum();
                (x, f)
            })
            .collect();
        let mut pts = vec![(0.0, 0.0)];
        pts.extend_from_slice(&id.virgin_data);
        crate::plot::fit_plot(
            &dir.join("virgin.svg"),
            &format!(
                "pre-sliding virgin curve, {} blocks (RMS residual {:.2} % of Fs)",
                v.blocks.len(),
                100.0 * v.rms / v.fs
            ),
            ("displacement [m or rad]", "friction [N or N·m]"),
            &pts,
            &curve,
        )?;
    }
    if let Some(s) = &id.stribeck {
        let (lo, hi) = id
            .sliding_data
            .iter()
            .fold((f64::MAX, f64::MIN), |(a, b), p| (a.min(p.0), b.max(p.0)));
        let curve: Vec<(f64, f64)> = (0..=400)
            .map(|i| {
                let lv = lo.log10() + (hi.log10() - lo.log10()) * i as f64 / 400.0;
                let v = 10f64.powf(lv);
                (
                    lv,
                    s.fc + (s.fs - s.fc) * (-(v / s.vs).powf(s.delta)).exp() + s.sigma * v,
                )
            })
            .collect();
        let pts: Vec<(f64, f64)> = id
            .sliding_data
            .iter()
            .map(|&(v, f)| (v.log10(), f))
            .collect();
        crate::plot::fit_plot(
            &dir.join("stribeck.svg"),
            &format!(
                "sliding: Stribeck + viscous fit (Vs {:.3e}, delta {:.3})",
                s.vs, s.delta
            ),
            ("log10 speed [m/s or rad/s]", "friction [N or N·m]"),
            &pts,
            &curve,
        )?;
    }
    if let Some(l) = &id.lag {
        let pts: Vec<(f64, f64)> = l.window.iter().map(|w| (w.0, w.1)).collect();
        let curve: Vec<(f64, f64)> = l.window.iter().map(|w| (w.0, w.2)).collect();
        crate::plot::fit_plot(
            &dir.join("lag.svg"),
            &format!("frictional lag: C {:.3e} (RMS residual {:.2e})", l.c, l.rms),
            ("time [s]", "friction [N or N·m]"),
            &pts,
            &curve,
        )?;
    }
    Ok(())
}
