//! Pre-sliding: the virgin curve (paper eq. 3) as a piecewise-linear concave function whose
//! segments give the GMS blocks' stiffnesses and weights.

use crate::Error;
use nalgebra::{Dyn, OMatrix, OVector};

use crate::paramfile::BlockSpec;

/// The result of the pre-sliding fit.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
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

/// The most blocks [`fit_virgin`] fits to `points` measured points: two points a block, and
/// two more.
pub fn blocks_held(points: usize) -> usize {
    points.saturating_sub(2) / 2
}

/// Fits `n` Maxwell-slip blocks to a measured virgin curve: `x` increasing from rest (the
/// origin is added), `f` the friction at each `x`, up to breakaway. The breakpoints are
/// chosen by dynamic programming over the sample positions: least squares of the chord
/// interpolation through the knots, each chord less steep than the one before (concave); the
/// last point is taken as breakaway (its level is Fs, the last block saturates where the last
/// chord reaches it); then the stiffnesses are refined by linear least squares on the
/// basis `min(x, D_i)` (kept from the chords when that would break concavity). Errors: too few points, non-finite values,
/// x not increasing, a curve that falls, a fit that is not concave.
pub fn fit_virgin(x: &[f64], f: &[f64], n: usize) -> Result<VirginFit, Error> {
    fit_virgin_inner(x, f, n).map_err(Error::Data)
}

#[allow(clippy::needless_range_loop)] // the dynamic programme reads best as indices
fn fit_virgin_inner(x: &[f64], f: &[f64], n: usize) -> Result<VirginFit, String> {
    if x.len() != f.len() {
        return Err("x and F have different lengths".into());
    }
    if n == 0 || n > crate::paramfile::MAX_BLOCKS {
        return Err(format!(
            "blocks must be 1..={}",
            crate::paramfile::MAX_BLOCKS
        ));
    }
    if n > blocks_held(x.len()) {
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
