//! The minimum of a noisy tuning curve with its uncertainty: a weighted least-squares parabola
//! through the mean-square errors measured at a parameter's values, its vertex, and the
//! vertex's standard error from the fit's covariance.
//!
//! Why the mean square: when a parameter `g` scales a correction, the error is close to
//! `e(t) = e0(t) + (g − g*) s(t)` (the part the correction leaves plus its misfit), so its mean
//! square is a parabola in `g` with its vertex at the best `g*`, and the RMS is not. The
//! weights are `1/y²`: the scatter of a repeated test is a roughly constant fraction of its
//! mean square.

/// A fitted minimum.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Optimum {
    /// The parameter at the vertex.
    pub at: f64,
    /// The vertex's standard error (from the fit's residuals and covariance).
    pub se: f64,
    /// The mean square at the vertex, in the data's units squared.
    pub min: f64,
    /// The parabola's curvature: the mean square rises by `curvature · d²` at a distance `d`.
    pub curvature: f64,
    /// The number of points fitted.
    pub n: usize,
}

impl Optimum {
    /// Half-width of the 95 % interval of the optimum: Student's t for the fit's `n − 3`
    /// degrees of freedom times the standard error.
    pub fn half_width(&self) -> f64 {
        t975(self.n.saturating_sub(3)) * self.se
    }

    /// Half-width of the interval in which a repeat of the same measurement and fit lands
    /// with 95 % probability (two independent estimates differ by √2 standard errors).
    pub fn repeat_half_width(&self) -> f64 {
        std::f64::consts::SQRT_2 * self.half_width()
    }
}

/// Student's t 97.5 % quantile for `dof` degrees of freedom (Cornish–Fisher expansion about
/// the normal 1.96: within 0.3 % from 5 degrees of freedom up; 1.96 at infinity).
pub fn t975(dof: usize) -> f64 {
    let z = 1.959_964f64;
    if dof == 0 {
        return f64::INFINITY;
    }
    let v = dof as f64;
    z + (z.powi(3) + z) / (4.0 * v)
        + (5.0 * z.powi(5) + 16.0 * z.powi(3) + 3.0 * z) / (96.0 * v * v)
        + (3.0 * z.powi(7) + 19.0 * z.powi(5) + 17.0 * z.powi(3) - 15.0 * z) / (384.0 * v.powi(3))
}

/// The vertex of the weighted least-squares parabola `y = a + b u + c u²` (u = x − mean x)
/// through `(x, rms)` points, fitted to `y = rms²`; `None` with fewer than four points, a
/// non-positive curvature (no minimum), or a degenerate design (fewer than three distinct
/// x).
pub fn fit_minimum(points: &[(f64, f64)]) -> Option<Optimum> {
    let pts: Vec<(f64, f64)> = points
        .iter()
        .filter(|(x, r)| x.is_finite() && r.is_finite() && *r > 0.0)
        .map(|&(x, r)| (x, r * r))
        .collect();
    let n = pts.len();
    if n < 4 {
        return None;
    }
    let xc = pts.iter().map(|p| p.0).sum::<f64>() / n as f64;
    // Iteratively reweighted: the weights from the fitted mean square (weights from the
    // measured values themselves would favour the points that happened to come out low).
    let mut fitted: Vec<f64> = pts.iter().map(|p| p.1).collect();
    let mut solution = None;
    for _ in 0..4 {
        let mut m = [[0.0f64; 3]; 3];
        let mut v = [0.0f64; 3];
        for (&(x, y), &f) in pts.iter().zip(&fitted) {
            let u = x - xc;
            let basis = [1.0, u, u * u];
            let w = 1.0 / (f * f);
            for i in 0..3 {
                for j in 0..3 {
                    m[i][j] += w * basis[i] * basis[j];
                }
                v[i] += w * basis[i] * y;
            }
        }
        let inv = invert3(&m)?;
        let coef: [f64; 3] = core::array::from_fn(|i| (0..3).map(|j| inv[i][j] * v[j]).sum());
        let floor = pts.iter().map(|p| p.1).fold(f64::INFINITY, f64::min) * 0.1;
        for (f, &(x, _)) in fitted.iter_mut().zip(&pts) {
            let u = x - xc;
            *f = (coef[0] + coef[1] * u + coef[2] * u * u).max(floor);
        }
        solution = Some((coef, inv));
    }
    let ([a, b, c], inv) = solution?;
    if !(c > 0.0 && c.is_finite()) {
        return None;
    }
    // Residual variance of unit weight, then the covariance of (a, b, c).
    let ssr: f64 = pts
        .iter()
        .zip(&fitted)
        .map(|(&(x, y), &f)| {
            let u = x - xc;
            (y - (a + b * u + c * u * u)).powi(2) / (f * f)
        })
        .sum();
    let s2 = ssr / (n - 3) as f64;
    let u0 = -b / (2.0 * c);
    // Gradient of the vertex u0 = -b / (2c) with respect to (a, b, c).
    let grad = [0.0, -1.0 / (2.0 * c), b / (2.0 * c * c)];
    let var: f64 = (0..3)
        .map(|i| {
            (0..3)
                .map(|j| grad[i] * s2 * inv[i][j] * grad[j])
                .sum::<f64>()
        })
        .sum();
    Some(Optimum {
        at: xc + u0,
        se: var.max(0.0).sqrt(),
        min: a + b * u0 + c * u0 * u0,
        curvature: c,
        n,
    })
}

/// The inverse of a symmetric 3×3 matrix, or `None` when it is (nearly) singular.
fn invert3(m: &[[f64; 3]; 3]) -> Option<[[f64; 3]; 3]> {
    let det = m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
        - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
        + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
    let scale = m.iter().flatten().fold(0.0f64, |s, x| s.max(x.abs()));
    if !(det.is_finite() && det.abs() > 1e-12 * scale.powi(3)) {
        return None;
    }
    let mut out = [[0.0; 3]; 3];
    for (i, row) in out.iter_mut().enumerate() {
        for (j, cell) in row.iter_mut().enumerate() {
            // The cofactor of (j, i), for the adjugate.
            let (r0, r1) = ((j + 1) % 3, (j + 2) % 3);
            let (c0, c1) = ((i + 1) % 3, (i + 2) % 3);
            *cell = (m[r0][c0] * m[r1][c1] - m[r0][c1] * m[r1][c0]) / det;
        }
    }
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An exact parabola in the mean square: the vertex where it was put, zero error.
    #[test]
    fn an_exact_parabola_gives_its_vertex() {
        let pts: Vec<(f64, f64)> = (0..9)
            .map(|i| {
                let g = 0.5 + 0.1 * i as f64;
                (g, (1.7 + 28.0 * (g - 0.78f64).powi(2)).sqrt())
            })
            .collect();
        let o = fit_minimum(&pts).unwrap();
        assert!((o.at - 0.78).abs() < 1e-9, "{o:?}");
        assert!((o.curvature - 28.0).abs() < 1e-6 && (o.min - 1.7).abs() < 1e-9);
        assert!(o.se < 1e-6, "{o:?}");
    }

    /// Noise of a known size: over many noisy repeats the vertex scatters as its standard
    /// error says (the ratio of the observed spread to the mean reported error within 20 %),
    /// and the 95 % interval covers the truth about 95 % of the time.
    #[test]
    fn the_standard_error_matches_the_scatter() {
        // A small deterministic generator (xorshift) and Box–Muller.
        let mut s = 0x9e37_79b9_7f4a_7c15u64;
        let mut uniform = || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut gauss = || {
            let (u1, u2) = (uniform().max(1e-12), uniform());
            (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
        };
        let trials = 400;
        let (mut sum, mut sum2, mut se_sum, mut covered) = (0.0, 0.0, 0.0, 0);
        for _ in 0..trials {
            let pts: Vec<(f64, f64)> = (0..18)
                .map(|i| {
                    let g = 0.55 + 0.05 * (i % 9) as f64;
                    let ms = (1.7 + 28.0 * (g - 0.78f64).powi(2)) * (1.0 + 0.1 * gauss());
                    (g, ms.sqrt())
                })
                .collect();
            let o = fit_minimum(&pts).unwrap();
            sum += o.at;
            sum2 += o.at * o.at;
            se_sum += o.se;
            if (o.at - 0.78).abs() <= o.half_width() {
                covered += 1;
            }
        }
        let mean = sum / trials as f64;
        let sd = (sum2 / trials as f64 - mean * mean).sqrt();
        let se = se_sum / trials as f64;
        assert!((mean - 0.78).abs() < 0.2 * sd + 1e-3, "mean {mean}");
        assert!((sd / se - 1.0).abs() < 0.2, "spread {sd} vs reported {se}");
        let rate = covered as f64 / trials as f64;
        assert!((0.90..=0.99).contains(&rate), "coverage {rate}");
    }

    /// Student's t against tabulated values (97.5 %).
    #[test]
    fn t_quantiles() {
        for (dof, want) in [
            (5, 2.571),
            (10, 2.228),
            (15, 2.131),
            (30, 2.042),
            (120, 1.980),
        ] {
            assert!(
                (t975(dof) / want - 1.0).abs() < 0.003,
                "{dof}: {}",
                t975(dof)
            );
        }
    }

    /// No minimum: a falling concave curve, a hump, too few points.
    #[test]
    fn no_minimum_is_none() {
        let falling: Vec<(f64, f64)> = (0..6)
            .map(|i| (i as f64, (40.0 - (i as f64).powi(2)).sqrt()))
            .collect();
        assert_eq!(fit_minimum(&falling), None);
        let hump: Vec<(f64, f64)> = (0..7)
            .map(|i| (i as f64, (20.0 - (i as f64 - 3.0).powi(2)).sqrt()))
            .collect();
        assert_eq!(fit_minimum(&hump), None);
        assert_eq!(fit_minimum(&[(0.0, 1.0), (1.0, 0.5), (2.0, 1.0)]), None);
    }
}
