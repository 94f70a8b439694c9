//! The frictional lag: the GMS attraction parameter C from a velocity oscillating through
//! sliding, by a one-dimensional search of the residual in ln C.

use crate::Error;
/// The frictional-lag fit of C.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct LagFit {
    /// The fitted slip rate C [N/s or N·m/s].
    pub c: f64,
    /// One-sigma relative uncertainty of C [-], from the curvature of the residual sum at
    /// the optimum (in ln C); `None` when the curvature is not positive.
    pub rel_err: Option<f64>,
    /// RMS residual of the fitted model over the record [N or N·m].
    pub rms: f64,
    /// RMS residual with the paper's rule C = 1/Vs (mN scale) instead, for comparison.
    pub rms_rule: f64,
    /// Samples used (after the first second, which is skipped as the start-up).
    pub samples: usize,
    /// For the plot: (t \[s\], measured, fitted model) over the half second where the lag
    /// matters most (the fitted model farthest from a lag-free one, C × 10^4).
    pub window: Vec<(f64, f64, f64)>,
}

/// The model's output with slip rate `c` along the record (0 at the first sample).
fn lag_trace(
    spec: &crate::paramfile::FrictionSpec,
    c: f64,
    t: &[f64],
    x: &[f64],
) -> Result<Vec<f64>, String> {
    let mut s = spec.clone();
    s.c = Some(c);
    let mut m = s.build()?;
    let mut out = vec![0.0];
    for i in 1..t.len() {
        out.push(m.advance((x[i] - x[i - 1]) as f32, (t[i] - t[i - 1]) as f32) as f64);
    }
    Ok(out)
}

/// Residual sum of squares of the friction `spec` with slip rate `c` driven by the recorded
/// angle `x` over the times `t`, against the recorded friction `f` from `skip` on.
fn lag_sse(
    spec: &crate::paramfile::FrictionSpec,
    c: f64,
    t: &[f64],
    x: &[f64],
    f: &[f64],
    skip: usize,
) -> Result<f64, String> {
    let out = lag_trace(spec, c, t, x)?;
    Ok(out[skip..]
        .iter()
        .zip(&f[skip..])
        .map(|(o, f)| (o - f).powi(2))
        .sum())
}

/// Fits C to a frictional-lag record (`t,x,f`: time \[s\], position, friction) with every
/// other parameter of `spec` fixed: the model is driven by the recorded positions and C
/// minimises the squared difference to the recorded friction (golden-section search over
/// ln C, from 10^-4 to 10^4 × the paper's rule). The first second is the start-up and is
/// not compared.
pub fn fit_lag(
    spec: &crate::paramfile::FrictionSpec,
    t: &[f64],
    x: &[f64],
    f: &[f64],
) -> Result<LagFit, Error> {
    fit_lag_inner(spec, t, x, f).map_err(Error::Data)
}

fn fit_lag_inner(
    spec: &crate::paramfile::FrictionSpec,
    t: &[f64],
    x: &[f64],
    f: &[f64],
) -> Result<LagFit, String> {
    if t.len() != x.len() || t.len() != f.len() {
        return Err("columns of unequal length".into());
    }
    if t.windows(2).any(|w| w[1] <= w[0]) {
        return Err("t must strictly increase".into());
    }
    let skip = t.iter().position(|&ti| ti - t[0] >= 1.0).unwrap_or(t.len());
    let samples = t.len() - skip;
    if samples < 100 {
        return Err(format!(
            "{} samples after the first second: at least 100 are needed",
            samples
        ));
    }
    let travel = (x[t.len() - 1] - x[skip]).abs();
    let dmax = spec.largest_breakpoint();
    if travel < 10.0 * dmax {
        return Err(
            "the record hardly moves beyond the pre-sliding range: it shows no sliding lag".into(),
        );
    }
    let vs = spec.vs.ok_or("no vs to start from")?;
    let rule = 1e-3 / vs;
    let sse = |lc: f64| lag_sse(spec, lc.exp(), t, x, f, skip);
    // Coarse scan (a decade apart), then golden section around the best.
    let (lo, hi) = (
        rule.ln() - 4.0 * std::f64::consts::LN_10,
        rule.ln() + 4.0 * std::f64::consts::LN_10,
    );
    let n = 17;
    let mut best = (f64::INFINITY, lo);
    for i in 0..n {
        let lc = lo + (hi - lo) * i as f64 / (n - 1) as f64;
        let e = sse(lc)?;
        if e < best.0 {
            best = (e, lc);
        }
    }
    let step = (hi - lo) / (n - 1) as f64;
    let (mut a, mut b) = (best.1 - step, best.1 + step);
    let g = (5f64.sqrt() - 1.0) / 2.0;
    let (mut c1, mut c2) = (b - g * (b - a), a + g * (b - a));
    let (mut e1, mut e2) = (sse(c1)?, sse(c2)?);
    while b - a > 1e-5 {
        if e1 < e2 {
            b = c2;
            (c2, e2) = (c1, e1);
            c1 = b - g * (b - a);
            e1 = sse(c1)?;
        } else {
            a = c1;
            (c1, e1) = (c2, e2);
            c2 = a + g * (b - a);
            e2 = sse(c2)?;
        }
    }
    let lc = (a + b) / 2.0;
    let e0 = sse(lc)?;
    if lc <= lo + 1e-3 || lc >= hi - 1e-3 {
        return Err(format!(
            "C runs to the edge of its range ({:.3e}): the record does not show the lag",
            lc.exp()
        ));
    }
    // Curvature in ln C: SSE ≈ e0 + H/2 (p - p*)^2, var(p) = 2 sigma^2 / H.
    let h = 0.02;
    let curv = (sse(lc + h)? - 2.0 * e0 + sse(lc - h)?) / (h * h);
    let var = e0 / (samples as f64 - 1.0);
    let rel_err = (curv > 0.0).then(|| (2.0 * var / curv).sqrt());
    // The plot window: the half second where the fitted lag differs most from no lag.
    let fitted = lag_trace(spec, lc.exp(), t, x)?;
    let no_lag = lag_trace(spec, lc.exp() * 1e4, t, x)?;
    let half = t[skip..]
        .iter()
        .position(|&ti| ti - t[skip] >= 0.5)
        .unwrap_or(samples - 1)
        .max(1);
    let mut acc: f64 = (skip..skip + half)
        .map(|i| (fitted[i] - no_lag[i]).powi(2))
        .sum();
    let mut best_start = (acc, skip);
    for i in skip + 1..t.len() - half + 1 {
        acc += (fitted[i + half - 1] - no_lag[i + half - 1]).powi(2)
            - (fitted[i - 1] - no_lag[i - 1]).powi(2);
        if acc > best_start.0 {
            best_start = (acc, i);
        }
    }
    let w0 = best_start.1;
    let window = (w0..w0 + half).map(|i| (t[i], f[i], fitted[i])).collect();
    Ok(LagFit {
        window,
        c: lc.exp(),
        rel_err,
        rms: (e0 / samples as f64).sqrt(),
        rms_rule: (sse(rule.ln())? / samples as f64).sqrt(),
        samples,
    })
}
