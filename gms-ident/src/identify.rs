//! Off-line identification of GMS parameters (paper §3): the pre-sliding virgin curve as a
//! piecewise-linear concave function (eq. 3) and the sliding Stribeck curve with a viscous
//! term (eq. 1 + sigma v) by nonlinear least squares.

use levenberg_marquardt::{LeastSquaresProblem, LevenbergMarquardt};
use nalgebra::{Dyn, Matrix, OMatrix, OVector, Owned, U5, Vector5};

use crate::paramfile::BlockSpec;

/// The result of the pre-sliding fit.
#[derive(Debug, Clone, PartialEq)]
pub struct VirginFit {
    /// The blocks: stiffness k_i and weight alpha_i, breakpoints in increasing order.
    pub blocks: Vec<BlockSpec>,
    /// The plateau, the static friction Fs the blocks saturate at [N or N·m].
    pub fs: f64,
    /// The breakpoints D_i [m or rad].
    pub breakpoints: Vec<f64>,
    /// RMS residual of the fit [N or N·m].
    pub rms: f64,
}

/// SSE of the straight line through (x[a], f[a]) and (x[b], f[b]) over the points a..=b.
fn chord_sse(x: &[f64], f: &[f64], a: usize, b: usize) -> f64 {
    let slope = (f[b] - f[a]) / (x[b] - x[a]);
    (a..=b)
        .map(|j| {
            let r = f[j] - (f[a] + slope * (x[j] - x[a]));
            r * r
        })
        .sum()
}

/// Fits `n` Maxwell-slip blocks to a measured virgin curve: `x` increasing from rest (the
/// origin is added), `f` the friction at each `x`, up to breakaway. The breakpoints are
/// chosen by dynamic programming over the sample positions: least squares of the chord
/// interpolation through the knots, each chord less steep than the one before (concave); the
/// last point is taken as breakaway (its level is Fs, the last block saturates where the last
/// chord reaches it); then the stiffnesses are refined by linear least squares on the
/// basis `min(x, D_i)` (kept from the chords when that would break concavity). Errors: too few points, non-finite values,
/// x not increasing, a curve that falls, a fit that is not concave.
#[allow(clippy::needless_range_loop)] // the dynamic programme reads best as indices
pub fn fit_virgin(x: &[f64], f: &[f64], n: usize) -> Result<VirginFit, String> {
    if x.len() != f.len() {
        return Err("x and F have different lengths".into());
    }
    if n == 0 || n > crate::paramfile::MAX_BLOCKS {
        return Err(format!(
            "blocks must be 1..={}",
            crate::paramfile::MAX_BLOCKS
        ));
    }
    if x.len() < 2 * n + 2 {
        return Err(format!(
            "{} pre-sliding points are too few for {n} blocks (need {})",
            x.len(),
            2 * n + 2
        ));
    }
    if x.iter().chain(f).any(|v| !v.is_finite()) {
        return Err("pre-sliding data has a non-finite value".into());
    }
    let mut xs = vec![0.0];
    let mut fs = vec![0.0];
    xs.extend_from_slice(x);
    fs.extend_from_slice(f);
    if xs.windows(2).any(|w| w[1] <= w[0]) {
        return Err(
            "pre-sliding displacement must increase from rest (x > 0, strictly increasing)".into(),
        );
    }
    let range = fs.iter().cloned().fold(f64::MIN, f64::max);
    if range <= 0.0 {
        return Err("pre-sliding friction never rises above zero".into());
    }
    let mut peak = f64::MIN;
    for &v in &fs {
        peak = peak.max(v);
        if peak - v > 0.1 * range {
            return Err(
                "the virgin curve is not monotonic (falls by more than 10 % of its range)".into(),
            );
        }
    }
    let m = xs.len();
    // cost[a][b]: chord SSE between knots a < b.
    let cost: Vec<Vec<f64>> = (0..m)
        .map(|a| {
            (0..m)
                .map(|b| {
                    if b > a {
                        chord_sse(&xs, &fs, a, b)
                    } else {
                        f64::INFINITY
                    }
                })
                .collect()
        })
        .collect();
    // Concave chords: best[k][a][b] is the least SSE of k chords from the origin to knot b
    // whose last chord starts at knot a, each chord less steep than the one before.
    let slope = |a: usize, b: usize| (fs[b] - fs[a]) / (xs[b] - xs[a]);
    let inf = f64::INFINITY;
    let mut best = vec![vec![vec![inf; m]; m]; n + 1];
    let mut from = vec![vec![vec![0usize; m]; m]; n + 1];
    for b in 1..m {
        if slope(0, b) > 0.0 {
            best[1][0][b] = cost[0][b];
        }
    }
    for k in 2..=n {
        for a in (k - 1)..m {
            for b in a + 1..m {
                let s_ab = slope(a, b);
                if s_ab <= 0.0 {
                    continue;
                }
                let mut bc = inf;
                let mut bp = 0;
                for p in (k - 2)..a {
                    let c = best[k - 1][p][a];
                    if c < bc && slope(p, a) > s_ab {
                        bc = c;
                        bp = p;
                    }
                }
                if bc < inf {
                    best[k][a][b] = bc + cost[a][b];
                    from[k][a][b] = bp;
                }
            }
        }
    }
    // A measured virgin curve stops at breakaway: its last point gives the plateau's level,
    // Fs, but not where the plateau starts (at breakaway the slide creeps on by an amount
    // set by how long one waits). So the chords run to the last-but-one point, and the
    // last block saturates where the last chord's line reaches the last point's level.
    let last = m - 2;
    let top = fs[m - 1];
    let end = best[n]
        .iter()
        .enumerate()
        .filter(|(_, row)| row[last] < inf)
        .min_by(|x, y| x.1[last].total_cmp(&y.1[last]))
        .map(|(a, _)| (a, last));
    let (mut a, mut b) =
        end.ok_or("the virgin curve admits no concave fit with that many blocks")?;
    let mut knots = vec![b];
    for k in (1..=n).rev() {
        knots.push(a);
        let p = from[k][a][b];
        b = a;
        a = p;
    }
    knots.reverse(); // knots[0] = 0 (origin), knots[n] = the last-but-one point
    let mut d: Vec<f64> = knots[1..].iter().map(|&i| xs[i]).collect();
    let (ka, kb) = (knots[n - 1], knots[n]);
    let reach = xs[ka] + (top - fs[ka]) / slope(ka, kb);
    d[n - 1] = reach.max(xs[kb]);
    // Chord slopes s_1 > … > s_n > 0 give k_i = s_i - s_(i+1) > 0.
    let slopes: Vec<f64> = knots.windows(2).map(|w| slope(w[0], w[1])).collect();
    let chord_k: Vec<f64> = (0..n)
        .map(|i| slopes[i] - slopes.get(i + 1).copied().unwrap_or(0.0))
        .collect();
    // Refine by linear least squares on the basis min(x, D_i) over the points up to the
    // last-but-one and the plateau level at the last breakpoint; keep the chords'
    // stiffnesses when that would break concavity.
    let rows = m;
    let a_mat = OMatrix::<f64, Dyn, Dyn>::from_fn(rows, n, |r, c| {
        let x = if r == m - 1 { d[n - 1] } else { xs[r] };
        x.min(d[c])
    });
    let y = OVector::<f64, Dyn>::from_column_slice(&fs);
    let ata = a_mat.transpose() * &a_mat;
    let aty = a_mat.transpose() * &y;
    let k = match ata.lu().solve(&aty) {
        Some(k) if k.iter().all(|v| *v > 0.0) => k,
        _ => OVector::<f64, Dyn>::from_vec(chord_k),
    };
    if let Some(i) = k.iter().position(|v| v.is_nan() || *v <= 0.0) {
        return Err(format!(
            "the virgin curve is not concave near breakpoint {} ({:.3e}): no positive stiffness fits",
            i + 1,
            d[i]
        ));
    }
    let fs_plateau: f64 = k.iter().zip(&d).map(|(k, d)| k * d).sum();
    let resid = &a_mat * &k - &y;
    let rms = (resid.norm_squared() / rows as f64).sqrt();
    let blocks = k
        .iter()
        .zip(&d)
        .map(|(k, d)| BlockSpec {
            k: *k,
            alpha: k * d / fs_plateau,
        })
        .collect();
    Ok(VirginFit {
        blocks,
        fs: fs_plateau,
        breakpoints: d,
        rms,
    })
}

/// The sliding fit: Stribeck + viscous parameters and their uncertainty.
#[derive(Debug, Clone, PartialEq)]
pub struct StribeckFit {
    /// Static friction [N or N·m].
    pub fs: f64,
    /// Coulomb friction [N or N·m].
    pub fc: f64,
    /// Stribeck velocity [m/s or rad/s].
    pub vs: f64,
    /// Shape factor [-].
    pub delta: f64,
    /// Viscous coefficient [N·s/m or N·m·s/rad].
    pub sigma: f64,
    /// RMS residual [N or N·m].
    pub rms: f64,
    /// One-sigma standard errors of (fs, fc, vs, delta, sigma) from the Jacobian at the
    /// optimum (residual variance × (JᵀJ)⁻¹); `None` when JᵀJ is singular.
    pub std_err: Option<[f64; 5]>,
}

/// Parameters in the solver: fs, fc, ln vs, ln delta, sigma (logs keep vs, delta > 0).
struct Problem<'a> {
    v: &'a [f64],
    f: &'a [f64],
    p: Vector5<f64>,
}

impl Problem<'_> {
    fn model(p: &Vector5<f64>, v: f64) -> f64 {
        let (fs, fc, vs, d, sg) = (p[0], p[1], p[2].exp(), p[3].exp(), p[4]);
        fc + (fs - fc) * (-(v / vs).powf(d)).exp() + sg * v
    }
}

impl LeastSquaresProblem<f64, Dyn, U5> for Problem<'_> {
    type ResidualStorage = Owned<f64, Dyn>;
    type JacobianStorage = Owned<f64, Dyn, U5>;
    type ParameterStorage = Owned<f64, U5>;

    fn set_params(&mut self, p: &Vector5<f64>) {
        self.p = *p;
    }

    fn params(&self) -> Vector5<f64> {
        self.p
    }

    fn residuals(&self) -> Option<OVector<f64, Dyn>> {
        Some(OVector::<f64, Dyn>::from_iterator(
            self.v.len(),
            self.v
                .iter()
                .zip(self.f)
                .map(|(&v, &f)| Self::model(&self.p, v) - f),
        ))
    }

    fn jacobian(&self) -> Option<Matrix<f64, Dyn, U5, Self::JacobianStorage>> {
        let p = &self.p;
        let (fs, fc, vs, d) = (p[0], p[1], p[2].exp(), p[3].exp());
        let mut j = OMatrix::<f64, Dyn, U5>::zeros(self.v.len());
        for (r, &v) in self.v.iter().enumerate() {
            let u = (v / vs).max(1e-300);
            let ud = u.powf(d);
            let e = (-ud).exp();
            j[(r, 0)] = e;
            j[(r, 1)] = 1.0 - e;
            // d/d(ln vs): (fs - fc) e ud d ; d/d(ln delta): -(fs - fc) e ud ln(u) d
            j[(r, 2)] = (fs - fc) * e * ud * d;
            j[(r, 3)] = -(fs - fc) * e * ud * u.ln() * d;
            j[(r, 4)] = v;
        }
        Some(j)
    }
}

/// Fits `s(v) + sigma v` to steady sliding data (`v` > 0, `f` the friction at `v`) by
/// Levenberg–Marquardt (the `levenberg-marquardt` crate), from a start read off the data.
/// Errors: too few points, non-finite values, no speed beyond the knee of the curve.
pub fn fit_stribeck(v: &[f64], f: &[f64]) -> Result<StribeckFit, String> {
    if v.len() != f.len() {
        return Err("v and F have different lengths".into());
    }
    if v.len() < 8 {
        return Err(format!("{} sliding points are too few (need 8)", v.len()));
    }
    if v.iter().chain(f).any(|x| !x.is_finite()) {
        return Err("sliding data has a non-finite value".into());
    }
    if v.iter().any(|x| *x <= 0.0) {
        return Err("sliding speeds must be > 0 (give one direction's magnitudes)".into());
    }
    let mut idx: Vec<usize> = (0..v.len()).collect();
    idx.sort_by(|a, b| v[*a].total_cmp(&v[*b]));
    let (vmin, vmax) = (v[idx[0]], v[idx[idx.len() - 1]]);
    if vmax < 10.0 * vmin {
        return Err(
            "sliding speeds must span at least a decade (well below to well above Vs)".into(),
        );
    }
    // Start: fs from the slowest points, fc and sigma from a line through the fastest third,
    // vs where the curve is halfway down, delta 1.
    let n3 = (idx.len() / 3).max(2);
    let slow: f64 = idx[..n3].iter().map(|&i| f[i]).sum::<f64>() / n3 as f64;
    let fast: Vec<usize> = idx[idx.len() - n3..].to_vec();
    let (mv, mf) = (
        fast.iter().map(|&i| v[i]).sum::<f64>() / n3 as f64,
        fast.iter().map(|&i| f[i]).sum::<f64>() / n3 as f64,
    );
    let cov: f64 = fast.iter().map(|&i| (v[i] - mv) * (f[i] - mf)).sum();
    let var: f64 = fast.iter().map(|&i| (v[i] - mv).powi(2)).sum();
    let sigma0 = if var > 0.0 { (cov / var).max(0.0) } else { 0.0 };
    let fc0 = (mf - sigma0 * mv).max(0.0);
    let half = fc0 + 0.5 * (slow - fc0);
    let vs0 = idx
        .iter()
        .find(|&&i| f[i] - sigma0 * v[i] < half)
        .map_or((vmin * vmax).sqrt(), |&i| v[i]);
    if slow <= fc0 {
        return Err("no Stribeck drop: the friction does not fall from low to high speed".into());
    }
    let problem = Problem {
        v,
        f,
        p: Vector5::new(slow, fc0, vs0.ln(), 0.0, sigma0),
    };
    let (solved, report) = LevenbergMarquardt::new().minimize(problem);
    if !report.termination.was_successful() {
        return Err(format!(
            "the sliding fit did not converge ({:?})",
            report.termination
        ));
    }
    let p = solved.p;
    let res = solved.residuals().ok_or("fit residuals unavailable")?;
    let dof = (v.len() as f64 - 5.0).max(1.0);
    let s2 = res.norm_squared() / dof;
    let std_err = solved.jacobian().and_then(|j| {
        let jtj = j.transpose() * &j;
        jtj.try_inverse().map(|inv| {
            let (vs, d) = (p[2].exp(), p[3].exp());
            [
                (s2 * inv[(0, 0)]).sqrt(),
                (s2 * inv[(1, 1)]).sqrt(),
                (s2 * inv[(2, 2)]).sqrt() * vs,
                (s2 * inv[(3, 3)]).sqrt() * d,
                (s2 * inv[(4, 4)]).sqrt(),
            ]
        })
    });
    let fit = StribeckFit {
        fs: p[0],
        fc: p[1],
        vs: p[2].exp(),
        delta: p[3].exp(),
        sigma: p[4],
        rms: (res.norm_squared() / v.len() as f64).sqrt(),
        std_err,
    };
    if !(fit.fs >= fit.fc && fit.fc >= 0.0 && fit.sigma >= 0.0) {
        return Err(format!(
            "the sliding fit is not physical (fs {:.3e}, fc {:.3e}, sigma {:.3e})",
            fit.fs, fit.fc, fit.sigma
        ));
    }
    if vmax < 2.0 * fit.vs {
        return Err(format!(
            "no speed well above the fitted Vs ({:.3e}): measure faster",
            fit.vs
        ));
    }
    Ok(fit)
}

/// The frictional-lag fit of C.
#[derive(Debug, Clone, PartialEq)]
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

/// Reads a CSV with a header; returns the named columns (missing optional ones as `None`).
fn read_columns(
    path: &std::path::Path,
    names: &[&str],
    optional: &[&str],
) -> Result<Vec<Vec<f64>>, String> {
    let file = path.display().to_string();
    let mut rdr = csv::ReaderBuilder::new()
        .trim(csv::Trim::All)
        .from_path(path)
        .map_err(|e| format!("{file}: cannot read: {e}"))?;
    let headers = rdr
        .headers()
        .map_err(|e| format!("{file}: bad header: {e}"))?
        .clone();
    let mut idx = Vec::new();
    for n in names.iter().chain(optional) {
        let i = headers.iter().position(|h| h == *n);
        if i.is_none() && names.contains(n) {
            return Err(format!("{file}: the header has no `{n}` column"));
        }
        idx.push(i);
    }
    let mut cols = vec![Vec::new(); idx.len()];
    for (row, rec) in rdr.records().enumerate() {
        let rec = rec.map_err(|e| format!("{file}: row {}: {e}", row + 2))?;
        for (c, i) in idx.iter().enumerate() {
            if let Some(i) = i {
                let s = rec
                    .get(*i)
                    .ok_or(format!("{file}:{}: short row", row + 2))?;
                let v: f64 = s
                    .parse()
                    .map_err(|_| format!("{file}:{}: not a number: {s:?}", row + 2))?;
                if !v.is_finite() {
                    return Err(format!("{file}:{}: non-finite value", row + 2));
                }
                cols[c].push(v);
            }
        }
    }
    Ok(cols)
}

/// The outcome of `identify`: the friction table, a text report and the data used.
pub struct Identified {
    /// The averaged virgin-curve points that were fitted (x, F).
    pub virgin_data: Vec<(f64, f64)>,
    /// The sliding points that were fitted (|v|, |F|).
    pub sliding_data: Vec<(f64, f64)>,
    /// The identified `[friction]` table.
    pub spec: crate::paramfile::FrictionSpec,
    /// Parameters, uncertainties, residuals and assumptions, one per line.
    pub report: Vec<String>,
    /// The virgin-curve fit, if pre-sliding data was given.
    pub virgin: Option<VirginFit>,
    /// The sliding fit, if sliding data was given.
    pub stribeck: Option<StribeckFit>,
    /// The frictional-lag fit of C, if a lag record was given.
    pub lag: Option<LagFit>,
}

/// `hil-sim identify`: fits the pre-sliding data (`x,f[,dir]`: the virgin curves, averaged
/// over both directions as the paper does) and the sliding data (`v,f`, both directions
/// pooled by magnitude) into a parameter table. With pre-sliding data only, the sliding
/// values are placeholders (fc = fs: no Stribeck drop), with sliding only, a static map.
/// C follows the paper's rule C = 1/Vs (in mN·m/s, DESIGN §3), printed as an assumption.
pub fn identify(
    pre: Option<&std::path::Path>,
    slide: Option<&std::path::Path>,
    blocks: usize,
) -> Result<Identified, String> {
    identify_with(pre, slide, blocks, false)
}

/// [`identify`], with `asymmetric`: the sliding data of each direction fitted separately, the
/// negative one written as `[friction.negative]` (fs, fc, vs, delta; sigma is the positive
/// fit's).
pub fn identify_with(
    pre: Option<&std::path::Path>,
    slide: Option<&std::path::Path>,
    blocks: usize,
    asymmetric: bool,
) -> Result<Identified, String> {
    identify_from(&Inputs {
        presliding: pre,
        sliding: slide,
        lag: None,
        blocks,
        asymmetric,
    })
}

/// What `hil-sim identify` is given.
#[derive(Debug, Clone, Copy)]
pub struct Inputs<'a> {
    /// Pre-sliding data (`x,f[,dir]`).
    pub presliding: Option<&'a std::path::Path>,
    /// Sliding data (`v,f`).
    pub sliding: Option<&'a std::path::Path>,
    /// A frictional-lag record (`t,x,f`): C is fitted to it (needs both of the above).
    pub lag: Option<&'a std::path::Path>,
    /// Number of Maxwell-slip blocks (1..=32).
    pub blocks: usize,
    /// Fit each sliding direction separately.
    pub asymmetric: bool,
}

/// The whole identification: [`identify_with`] plus, when a frictional-lag record is given,
/// C fitted to it by [`fit_lag`] (else the paper's rule, printed as an assumption).
pub fn identify_from(inp: &Inputs<'_>) -> Result<Identified, String> {
    let (pre, slide, blocks, asymmetric) =
        (inp.presliding, inp.sliding, inp.blocks, inp.asymmetric);
    if inp.lag.is_some() && (pre.is_none() || slide.is_none()) {
        return Err(
            "--lag needs --presliding and --sliding: C is fitted with the other parameters fixed"
                .into(),
        );
    }
    let mut negative_fit: Option<StribeckFit> = None;
    use crate::paramfile::{FrictionSpec, ModelKind};
    if pre.is_none() && slide.is_none() {
        return Err("give --presliding and/or --sliding data".into());
    }
    let mut report = Vec::new();
    let mut virgin_data = Vec::new();
    let mut sliding_data = Vec::new();
    let virgin = match pre {
        None => None,
        Some(p) => {
            let cols = read_columns(p, &["x", "f"], &["dir"])?;
            let (x, f) = (&cols[0], &cols[1]);
            let dir = cols.get(2).filter(|d| !d.is_empty());
            let side = |want: f64| -> (Vec<f64>, Vec<f64>) {
                x.iter()
                    .zip(f)
                    .enumerate()
                    .filter(|(i, _)| dir.is_none_or(|d| d[*i] * want > 0.0))
                    .map(|(_, (x, f))| (x.abs(), f.abs()))
                    .unzip()
            };
            let (xp, fp) = side(1.0);
            let (xn, fn_) = side(-1.0);
            // The paper's average of both directions, point by point (same load steps).
            let (xa, fa): (Vec<f64>, Vec<f64>) = if dir.is_some() && !xn.is_empty() {
                let n = xp.len().min(xn.len());
                (0..n)
                    .map(|i| ((xp[i] + xn[i]) / 2.0, (fp[i] + fn_[i]) / 2.0))
                    .unzip()
            } else {
                (xp, fp)
            };
            // The encoder reads the same count for several small loads: one point per
            // count (mean load); rest (x = 0) is the origin the fit adds itself.
            let mut xm: Vec<f64> = Vec::new();
            let mut fm: Vec<f64> = Vec::new();
            let mut nm: Vec<f64> = Vec::new();
            for (&x, &f) in xa.iter().zip(&fa) {
                if x <= 0.0 {
                    continue;
                }
                match xm.last() {
                    Some(&last) if x == last => {
                        let i = xm.len() - 1;
                        fm[i] += f;
                        nm[i] += 1.0;
                    }
                    _ => {
                        xm.push(x);
                        fm.push(f);
                        nm.push(1.0);
                    }
                }
            }
            for (f, n) in fm.iter_mut().zip(&nm) {
                *f /= n;
            }
            let (xa, fa) = (xm, fm);
            virgin_data = xa.iter().copied().zip(fa.iter().copied()).collect();
            let fit = fit_virgin(&xa, &fa, blocks).map_err(|e| format!("{}: {e}", p.display()))?;
            report.push(format!(
                "pre-sliding: {} points, {} blocks, plateau Fs {:.4e}, RMS residual {:.3e} ({:.2} % of Fs)",
                xa.len(),
                blocks,
                fit.fs,
                fit.rms,
                100.0 * fit.rms / fit.fs
            ));
            for (i, (b, d)) in fit.blocks.iter().zip(&fit.breakpoints).enumerate() {
                report.push(format!(
                    "  block {}: k {:.4e}, alpha {:.4}, D {:.4e}",
                    i + 1,
                    b.k,
                    b.alpha,
                    d
                ));
            }
            Some(fit)
        }
    };
    let stribeck = match slide {
        None => None,
        Some(p) => {
            let cols = read_columns(p, &["v", "f"], &[])?;
            if asymmetric {
                let (vn, fn_): (Vec<f64>, Vec<f64>) = cols[0]
                    .iter()
                    .zip(&cols[1])
                    .filter(|(v, _)| **v < 0.0)
                    .map(|(v, f)| (-v, f.abs()))
                    .unzip();
                let fit = fit_stribeck(&vn, &fn_)
                    .map_err(|e| format!("{} (negative direction): {e}", p.display()))?;
                report.push(format!(
                    "sliding, v < 0: {} points; fs {:.4e}, fc {:.4e}, vs {:.4e}, delta {:.4}, sigma {:.4e}",
                    vn.len(), fit.fs, fit.fc, fit.vs, fit.delta, fit.sigma
                ));
                negative_fit = Some(fit);
            }
            let (v, f): (Vec<f64>, Vec<f64>) = cols[0]
                .iter()
                .zip(&cols[1])
                .filter(|(v, _)| !asymmetric || **v > 0.0)
                .map(|(v, f)| (v.abs(), f.abs()))
                .unzip();
            let keep: Vec<usize> = (0..v.len()).filter(|&i| v[i] > 0.0).collect();
            let v: Vec<f64> = keep.iter().map(|&i| v[i]).collect();
            let f: Vec<f64> = keep.iter().map(|&i| f[i]).collect();
            sliding_data = v.iter().copied().zip(f.iter().copied()).collect();
            let fit = fit_stribeck(&v, &f).map_err(|e| format!("{}: {e}", p.display()))?;
            let se = fit.std_err.unwrap_or([f64::NAN; 5]);
            report.push(format!(
                "sliding: {} points, RMS residual {:.3e}; fs {:.4e} ± {:.1e}, fc {:.4e} ± {:.1e}, vs {:.4e} ± {:.1e}, delta {:.4} ± {:.1e}, sigma {:.4e} ± {:.1e} (one sigma)",
                v.len(), fit.rms, fit.fs, se[0], fit.fc, se[1], fit.vs, se[2], fit.delta, se[3], fit.sigma, se[4]
            ));
            Some(fit)
        }
    };
    let spec = match (&virgin, &stribeck) {
        (Some(vf), s) => {
            let (fs, fc, vs, delta, sigma) = match s {
                Some(s) => {
                    if vf.fs < 0.95 * s.fs {
                        report.push(format!(
                            "warning: the virgin curve ends at {:.0} % of the sliding Fs: the pre-sliding run broke away early (stick-slip; a steep Stribeck drop needs a stiffer or better damped set-up); the blocks beyond it are unknown",
                            100.0 * vf.fs / s.fs
                        ));
                    }
                    (s.fs, s.fc, s.vs, s.delta, s.sigma)
                }
                None => {
                    report.push("assumed: no sliding data, so fc = fs (no Stribeck drop), vs = 1, delta = 1, sigma = 0".into());
                    (vf.fs, vf.fs, 1.0, 1.0, 0.0)
                }
            };
            let c = 1e-3 / vs;
            report.push(format!(
                "assumed: C = 1/Vs in mN·m/s (paper, DESIGN §3): c = {c:.4e}"
            ));
            FrictionSpec {
                model: ModelKind::Gms,
                fs: Some(fs),
                fc: Some(fc),
                vs: Some(vs),
                delta: Some(delta),
                sigma: Some(sigma),
                c: Some(c),
                blocks: Some(vf.blocks.clone()),
                ..FrictionSpec::default()
            }
        }
        (None, Some(s)) => {
            report.push("no pre-sliding data: a static map (Stribeck + Coulomb + viscous)".into());
            FrictionSpec {
                model: ModelKind::Static,
                fs: Some(s.fs),
                fc: Some(s.fc),
                vs: Some(s.vs),
                delta: Some(s.delta),
                sigma: Some(s.sigma),
                ..FrictionSpec::default()
            }
        }
        (None, None) => return Err("give --presliding and/or --sliding data".into()),
    };
    let mut spec = spec;
    if let Some(n) = &negative_fit {
        spec.negative = Some(crate::paramfile::NegativeSpec {
            fs: Some(n.fs),
            fc: Some(n.fc),
            vs: Some(n.vs),
            delta: Some(n.delta),
        });
    }
    spec.build()
        .map_err(|e| format!("the identified set is invalid: {e}"))?;
    let mut lag = None;
    if let Some(p) = inp.lag {
        let cols = read_columns(p, &["t", "x", "f"], &[])?;
        let fit = fit_lag(&spec, &cols[0], &cols[1], &cols[2])
            .map_err(|e| format!("{}: {e}", p.display()))?;
        // Replace the rule's line.
        report.retain(|l| !l.starts_with("assumed: C = "));
        report.push(format!(
            "frictional lag: {} samples; c {:.4e} ± {:.1} % (one sigma), RMS residual {:.3e} (with the paper's rule c = {:.4e}: {:.3e})",
            fit.samples,
            fit.c,
            100.0 * fit.rel_err.unwrap_or(f64::NAN),
            fit.rms,
            spec.c.unwrap_or(f64::NAN),
            fit.rms_rule
        ));
        spec.c = Some(fit.c);
        lag = Some(fit);
    }
    Ok(Identified {
        lag,
        virgin_data,
        sliding_data,
        spec,
        report,
        virgin,
        stribeck,
    })
}

/// Writes `report.txt`, `virgin.svg` (the averaged virgin curve against the identified
/// blocks, as the paper's Fig. 1 right and Fig. 2) and `stribeck.svg` (the sliding data against
/// the fitted curve, over log10 of the speed) into `dir`; with a lag fit, `lag.svg` (the
/// recorded friction against the fitted model over time).
pub fn write_report(id: &Identified, dir: &std::path::Path) -> Result<(), String> {
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
