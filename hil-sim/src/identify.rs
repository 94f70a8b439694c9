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
/// origin is added), `f` the friction at each `x`. The breakpoints are chosen by dynamic
/// programming over the sample positions (least squares of the chord interpolation through
/// the knots, with the last knot the plateau), then the stiffnesses are refined by linear
/// least squares on the basis `min(x, D_i)`. Errors: too few points, non-finite values,
/// x not increasing, a curve that falls, a fit that is not concave.
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
    // Plateau after the last knot b: the points beyond it against F[b].
    let plateau: Vec<f64> = (0..m)
        .map(|b| (b + 1..m).map(|j| (fs[j] - fs[b]).powi(2)).sum())
        .collect();
    // best[k][b]: least SSE with k segments from knot 0 to knot b; from[k][b]: previous knot.
    let mut best = vec![vec![f64::INFINITY; m]; n + 1];
    let mut from = vec![vec![0usize; m]; n + 1];
    best[0][0] = 0.0;
    for k in 1..=n {
        for b in k..m {
            for a in (k - 1)..b {
                let c = best[k - 1][a] + cost[a][b];
                if c < best[k][b] {
                    best[k][b] = c;
                    from[k][b] = a;
                }
            }
        }
    }
    let (last, _) =
        (n..m)
            .map(|b| (b, best[n][b] + plateau[b]))
            .fold(
                (n, f64::INFINITY),
                |acc, (b, c)| if c < acc.1 { (b, c) } else { acc },
            );
    let mut knots = vec![last];
    let mut b = last;
    for k in (1..=n).rev() {
        b = from[k][b];
        knots.push(b);
    }
    knots.reverse(); // knots[0] = 0 (origin), knots[n] = last
    let d: Vec<f64> = knots[1..].iter().map(|&i| xs[i]).collect();
    // Linear least squares for k on the basis phi_i(x) = min(x, D_i).
    let rows = m;
    let a = OMatrix::<f64, Dyn, Dyn>::from_fn(rows, n, |r, c| xs[r].min(d[c]));
    let y = OVector::<f64, Dyn>::from_column_slice(&fs);
    let ata = a.transpose() * &a;
    let aty = a.transpose() * &y;
    let k = ata
        .lu()
        .solve(&aty)
        .ok_or("the pre-sliding fit is singular (breakpoints too close)")?;
    if let Some(i) = k.iter().position(|v| v.is_nan() || *v <= 0.0) {
        return Err(format!(
            "the virgin curve is not concave near breakpoint {} ({:.3e}): no positive stiffness fits",
            i + 1,
            d[i]
        ));
    }
    let fs_plateau: f64 = k.iter().zip(&d).map(|(k, d)| k * d).sum();
    let resid = &a * &k - &y;
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
