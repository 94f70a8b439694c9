//! Off-line identification of GMS parameters (paper §3): the pre-sliding virgin curve as a
//! piecewise-linear concave function (eq. 3) and the sliding Stribeck curve with a viscous
//! term (eq. 1 + sigma v) by nonlinear least squares.

use crate::Error;
mod lag;
mod report;
mod stribeck;
mod virgin;

pub use lag::{LagFit, fit_lag};
pub use report::write_report;
pub use stribeck::{StribeckFit, fit_stribeck};
pub use virgin::{VirginFit, blocks_held, fit_virgin};

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
/// C follows the paper's rule C = 1/Vs (in mN·m/s, docs/design.md#reading-table-1), printed as an assumption.
pub fn identify(
    pre: Option<&std::path::Path>,
    slide: Option<&std::path::Path>,
    blocks: usize,
) -> Result<Identified, Error> {
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
) -> Result<Identified, Error> {
    identify_from(&Inputs {
        presliding: pre,
        sliding: slide,
        lag: None,
        blocks,
        asymmetric,
    })
}

/// The virgin fit's blocks for a model whose static friction is `fs` (from the sliding fit):
/// where the measured curve ends below `fs` (it broke away early), each measured block keeps
/// its saturation force `alpha_i F_virgin` and the last block takes the rest, so the model
/// reproduces the measured curve and reaches `fs` beyond it on the last block's stiffness;
/// where it ends above, the weights are kept (the curve scaled to `fs`).
pub fn blocks_for(vf: &VirginFit, fs: f64) -> Vec<crate::paramfile::BlockSpec> {
    let mut blocks = vf.blocks.clone();
    if fs > vf.fs && vf.fs > 0.0 && fs.is_finite() {
        let r = vf.fs / fs;
        for b in &mut blocks {
            b.alpha *= r;
        }
        if let Some(last) = blocks.last_mut() {
            last.alpha += 1.0 - r;
        }
    }
    blocks
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
pub fn identify_from(inp: &Inputs<'_>) -> Result<Identified, Error> {
    let read = |p: Option<&std::path::Path>, names: &[&str], optional: &[&str]| {
        p.map(|p| {
            read_columns(p, names, optional).map(|cols| Table {
                name: p.display().to_string(),
                cols,
            })
        })
        .transpose()
    };
    let pre = read(inp.presliding, &["x", "f"], &["dir"]).map_err(Error::Data)?;
    let slide = read(inp.sliding, &["v", "f"], &[]).map_err(Error::Data)?;
    let lag = read(inp.lag, &["t", "x", "f"], &[]).map_err(Error::Data)?;
    identify_data(&Data {
        presliding: pre.as_ref(),
        sliding: slide.as_ref(),
        lag: lag.as_ref(),
        blocks: inp.blocks,
        asymmetric: inp.asymmetric,
    })
}

/// One experiment's data as columns, and its name for messages (a file's path, or what the
/// data is).
#[derive(Debug, Clone, PartialEq)]
pub struct Table {
    /// For messages: where the data came from.
    pub name: String,
    /// The columns: pre-sliding `x [rad], f [N·m][, dir]`; sliding `v [rad/s], f [N·m]`; lag
    /// `t [s], x [rad], f [N·m]`.
    pub cols: Vec<Vec<f64>>,
}

/// The whole identification on arrays (what [`identify_from`] reads from files).
#[derive(Debug, Clone, Copy)]
pub struct Data<'a> {
    /// Pre-sliding data.
    pub presliding: Option<&'a Table>,
    /// Sliding data.
    pub sliding: Option<&'a Table>,
    /// A frictional-lag record: C is fitted to it (needs both of the above).
    pub lag: Option<&'a Table>,
    /// Number of Maxwell-slip blocks (1..=32).
    pub blocks: usize,
    /// Fit each sliding direction separately.
    pub asymmetric: bool,
}

/// The whole identification on arrays: as [`identify_from`], the data given as columns.
pub fn identify_data(d: &Data<'_>) -> Result<Identified, Error> {
    identify_data_inner(d).map_err(Error::Data)
}

fn identify_data_inner(inp: &Data<'_>) -> Result<Identified, String> {
    let (pre, slide, blocks, asymmetric) =
        (inp.presliding, inp.sliding, inp.blocks, inp.asymmetric);
    for t in [pre, slide, inp.lag].into_iter().flatten() {
        let n = t.cols.first().map_or(0, Vec::len);
        if t.cols.iter().any(|c| c.len() != n && !c.is_empty()) {
            return Err(format!("{}: columns of different lengths", t.name));
        }
        if t.cols.iter().flatten().any(|v| !v.is_finite()) {
            return Err(format!("{}: non-finite value", t.name));
        }
    }
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
            let cols = &p.cols;
            if cols.len() < 2 {
                return Err(format!("{}: pre-sliding data needs x and f", p.name));
            }
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
            // The encoder reads the same count for several small loads, and on a bench a
            // later load can read a count less (noise, creep): points are pooled until the
            // displacements increase (pool-adjacent-violators on x: means of x and of the
            // load). Rest (x = 0) is the origin the fit adds itself.
            let mut xm: Vec<f64> = Vec::new();
            let mut fm: Vec<f64> = Vec::new();
            let mut nm: Vec<f64> = Vec::new();
            for (&x, &f) in xa.iter().zip(&fa) {
                if x <= 0.0 {
                    continue;
                }
                xm.push(x);
                fm.push(f);
                nm.push(1.0);
                while xm.len() >= 2 && xm[xm.len() - 1] <= xm[xm.len() - 2] {
                    let (x1, f1, n1) = (xm.pop(), fm.pop(), nm.pop());
                    let (Some(x1), Some(f1), Some(n1)) = (x1, f1, n1) else {
                        break;
                    };
                    let i = xm.len() - 1;
                    let n = nm[i] + n1;
                    xm[i] = (xm[i] * nm[i] + x1 * n1) / n;
                    fm[i] = (fm[i] * nm[i] + f1 * n1) / n;
                    nm[i] = n;
                }
            }
            let (xa, fa) = (xm, fm);
            virgin_data = xa.iter().copied().zip(fa.iter().copied()).collect();
            // A coarse encoder resolves the virgin curve in few distinct positions: as many
            // blocks as they hold (two points a block, and two more), at least one, with a
            // warning, rather than no result after the whole run.
            let fitted = blocks.min(blocks_held(xa.len())).max(1);
            if fitted < blocks {
                report.push(format!(
                    "warning: {} distinct pre-sliding positions hold {fitted} of the {blocks} \
                     blocks asked for (two points a block and two more; a finer encoder \
                     resolves more)",
                    xa.len()
                ));
            }
            let fit = fit_virgin(&xa, &fa, fitted).map_err(|e| format!("{}: {e}", p.name))?;
            report.push(format!(
                "pre-sliding: {} points, {} blocks, plateau Fs {:.4e}, RMS residual {:.3e} ({:.2} % of Fs)",
                xa.len(),
                fitted,
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
            let cols = &p.cols;
            if cols.len() < 2 {
                return Err(format!("{}: sliding data needs v and f", p.name));
            }
            if asymmetric {
                let (vn, fn_): (Vec<f64>, Vec<f64>) = cols[0]
                    .iter()
                    .zip(&cols[1])
                    .filter(|(v, _)| **v < 0.0)
                    .map(|(v, f)| (-v, f.abs()))
                    .unzip();
                let fit = fit_stribeck(&vn, &fn_)
                    .map_err(|e| format!("{} (negative direction): {e}", p.name))?;
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
            let fit = fit_stribeck(&v, &f).map_err(|e| format!("{}: {e}", p.name))?;
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
                    if vf.fs < s.fs {
                        report.push(format!(
                            "the measured blocks keep their saturation forces; the last block takes the remaining {:.1} % of Fs with its own stiffness (its breakpoint moves out)",
                            100.0 * (1.0 - vf.fs / s.fs)
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
                "assumed: C = 1/Vs in mN·m/s (paper, docs/design.md#reading-table-1): c = {c:.4e}"
            ));
            FrictionSpec {
                model: ModelKind::Gms,
                fs: Some(fs),
                fc: Some(fc),
                vs: Some(vs),
                delta: Some(delta),
                sigma: Some(sigma),
                c: Some(c),
                blocks: Some(blocks_for(vf, fs)),
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
        let cols = &p.cols;
        if cols.len() < 3 {
            return Err(format!("{}: a lag record needs t, x and f", p.name));
        }
        let fit =
            fit_lag(&spec, &cols[0], &cols[1], &cols[2]).map_err(|e| format!("{}: {e}", p.name))?;
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
