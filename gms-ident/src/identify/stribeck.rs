//! Sliding: the Stribeck curve with a viscous term (paper eq. 1 + sigma v) by nonlinear least
//! squares (Levenberg-Marquardt), with the parameters' uncertainties.

use crate::Error;
use levenberg_marquardt::{LeastSquaresProblem, LevenbergMarquardt};
use nalgebra::{Dyn, Matrix, OMatrix, OVector, Owned, U5, Vector5};

/// The sliding fit: Stribeck + viscous parameters and their uncertainty.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
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
    /// Sigma held at 0 (the bound of a viscous term that cannot be negative).
    no_viscous: bool,
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
        if self.no_viscous {
            self.p[4] = 0.0;
        }
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
            j[(r, 4)] = if self.no_viscous { 0.0 } else { v };
        }
        Some(j)
    }
}

/// Fits `s(v) + sigma v` to steady sliding data (`v` > 0, `f` the friction at `v`) by
/// Levenberg–Marquardt (the `levenberg-marquardt` crate), from a start read off the data.
/// Errors: too few points, non-finite values, no speed beyond the knee of the curve.
pub fn fit_stribeck(v: &[f64], f: &[f64]) -> Result<StribeckFit, Error> {
    fit_stribeck_inner(v, f).map_err(Error::Data)
}

fn fit_stribeck_inner(v: &[f64], f: &[f64]) -> Result<StribeckFit, String> {
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
    let start = Vector5::new(slow, fc0, vs0.ln(), 0.0, sigma0);
    let mut fit = solve(v, f, start, false)?;
    if fit.sigma < 0.0 {
        // The unconstrained optimum has a negative viscous term (a curve still falling at
        // the fastest speed, or slow points low from stick-slip pulling the knee): the
        // constrained optimum is then on the bound, sigma = 0, fitted with it held there.
        let mut start = start;
        start[4] = 0.0;
        fit = solve(v, f, start, true)?;
    }
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

/// One Levenberg-Marquardt solve from `start`, sigma held at 0 if `no_viscous`.
fn solve(
    v: &[f64],
    f: &[f64],
    start: Vector5<f64>,
    no_viscous: bool,
) -> Result<StribeckFit, String> {
    let problem = Problem {
        v,
        f,
        p: start,
        no_viscous,
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
    let free = if no_viscous { 4 } else { 5 };
    let dof = (v.len() as f64 - free as f64).max(1.0);
    let s2 = res.norm_squared() / dof;
    // The standard errors over the free parameters (sigma's 0 when held).
    let std_err = solved.jacobian().and_then(|j| {
        let j = j.columns(0, free).into_owned();
        let jtj = j.transpose() * &j;
        jtj.try_inverse().map(|inv| {
            let (vs, d) = (p[2].exp(), p[3].exp());
            [
                (s2 * inv[(0, 0)]).sqrt(),
                (s2 * inv[(1, 1)]).sqrt(),
                (s2 * inv[(2, 2)]).sqrt() * vs,
                (s2 * inv[(3, 3)]).sqrt() * d,
                if no_viscous {
                    0.0
                } else {
                    (s2 * inv[(4, 4)]).sqrt()
                },
            ]
        })
    });
    Ok(StribeckFit {
        fs: p[0],
        fc: p[1],
        vs: p[2].exp(),
        delta: p[3].exp(),
        sigma: p[4],
        rms: (res.norm_squared() / v.len() as f64).sqrt(),
        std_err,
    })
}
