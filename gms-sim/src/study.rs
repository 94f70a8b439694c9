//! The mismatch study (`hil-sim mismatch`): the device's GMS compensation, starting from its
//! default model (Table 1, six blocks), against plants whose actuator friction is another
//! model: what the mismatch between the truth and the compensator's model costs.
//!
//! Every truth has Table 1's sliding friction (Stribeck curve, viscous term, C) and differs in
//! its pre-sliding: Table 1's six blocks (the compensator's own model, the reference), the
//! best four-block fit of the same virgin curve, twelve blocks fitted to a smooth virgin curve
//! (`Fs (1 - exp(-k0 x / Fs))`, the same initial stiffness k0), LuGre (one bristle of the same
//! initial stiffness) and a static map (no pre-sliding at all). Each is drawn within the
//! scenario's ±15 % like the default plant, and run with every feedforward mode on the demo's
//! reference.

use gms_ident::identify::fit_virgin;
use gms_ident::paramfile::{FrictionSpec, ModelKind};

use crate::Error;
use crate::commands::{Comparison, compare};
use crate::scenario::Scenario;

/// One plant of the study: its name and actuator friction.
pub struct Truth {
    /// What it is, for the table.
    pub name: String,
    /// The plant's actuator friction.
    pub spec: FrictionSpec,
}

/// The study's truths, from the default scenario's actuator (Table 1).
pub fn truths(base: &FrictionSpec) -> Result<Vec<Truth>, Error> {
    let fs = base.fs.unwrap_or(0.0);
    let k0: f64 = base.blocks.iter().flatten().map(|b| b.k).sum();
    let dmax = base.largest_breakpoint();
    let fit = |x: Vec<f64>, f: Vec<f64>, n: usize| {
        fit_virgin(&x, &f, n)
            .map(|v| v.blocks)
            .map_err(|e| Error::Run(format!("the study's {n}-block truth: {e}")))
    };
    // Table 1's curve, log-spaced from a tenth of the first breakpoint to the last.
    let n_pts = 200;
    let x0 = 0.1 * fs * 0.575
        / base
            .blocks
            .iter()
            .flatten()
            .map(|b| b.k)
            .fold(0.0, f64::max);
    let xs: Vec<f64> = (0..n_pts)
        .map(|i| x0 * (dmax / x0).powf(i as f64 / (n_pts - 1) as f64))
        .collect();
    let four = fit(xs.clone(), xs.iter().map(|&x| base.virgin(x)).collect(), 4)?;
    // A smooth curve of the same initial stiffness, to breakaway at 7 Fs/k0 (99.9 % of Fs).
    let xe = 7.0 * fs / k0;
    let xs2: Vec<f64> = (0..n_pts)
        .map(|i| x0 * (xe / x0).powf(i as f64 / (n_pts - 1) as f64))
        .collect();
    let mut fe: Vec<f64> = xs2
        .iter()
        .map(|&x| fs * (1.0 - (-k0 * x / fs).exp()))
        .collect();
    if let Some(last) = fe.last_mut() {
        *last = fs;
    }
    let twelve = fit(xs2, fe, 12)?;
    let gms = |blocks| FrictionSpec {
        blocks: Some(blocks),
        ..base.clone()
    };
    let lugre = FrictionSpec {
        model: ModelKind::Lugre,
        c: None,
        blocks: None,
        sigma0: Some(k0),
        sigma1: Some(0.0),
        ..base.clone()
    };
    let stat = FrictionSpec {
        model: ModelKind::Static,
        c: None,
        blocks: None,
        ..base.clone()
    };
    Ok(vec![
        Truth {
            name: "gms, 6 blocks: Table 1 (the compensator's model)".into(),
            spec: base.clone(),
        },
        Truth {
            name: "gms, 4 blocks: Table 1's virgin curve fitted".into(),
            spec: gms(four),
        },
        Truth {
            name: "gms, 12 blocks: a smooth virgin curve".into(),
            spec: gms(twelve),
        },
        Truth {
            name: format!("lugre: one bristle, sigma0 {k0:.3} N·m/rad"),
            spec: lugre,
        },
        Truth {
            name: "static map: no pre-sliding".into(),
            spec: stat,
        },
    ])
}

/// Runs the study: every truth in the default scenario (the device's compensator at its
/// defaults), `runs` friction draws from `seed`, every mode.
pub fn mismatch(
    runs: usize,
    seed: u64,
    threads: usize,
    progress: bool,
) -> Result<Vec<(Truth, Comparison)>, Error> {
    let base = Scenario::default();
    let mut out = Vec::new();
    for t in truths(&base.plant.actuator)? {
        let mut sc = base.clone();
        sc.plant.actuator = t.spec.clone();
        sc.check()?;
        if progress {
            eprintln!("{}", t.name);
        }
        let (c, _) = compare(&sc, runs, seed, threads, progress).map_err(Error::Run)?;
        out.push((t, c));
    }
    Ok(out)
}

/// The study as a markdown table: per truth, the sine RMS error (median and 95th
/// percentile, in counts) without compensation, with the static map, the GMS and the adaptive
/// GMS feedforward; the peak after reversals without and with the GMS feedforward; and the
/// GMS figures relative to those against its own model.
pub fn table(rows: &[(Truth, Comparison)], rad_per_count: f64) -> String {
    let get = |c: &Comparison, mode: &str, metric: &str| {
        c.modes
            .get(mode)
            .and_then(|t| t.get(metric))
            .map(|s| (s.median / rad_per_count, s.p95 / rad_per_count))
    };
    let cell = |v: Option<(f64, f64)>| v.map_or("-".into(), |(m, p)| format!("{m:.2} [{p:.2}]"));
    let own = rows.first().map(|(_, c)| {
        (
            get(c, "gms", "sine_rms_error").map_or(f64::NAN, |v| v.0),
            get(c, "gms", "reversal_error").map_or(f64::NAN, |v| v.0),
        )
    });
    let mut s = format!(
        "{} friction draws, median [p95], counts\n\n\
         | plant's actuator friction | sine RMS, none | static | gms | gms-adaptive | \
         reversal peak, none | gms | gms vs own model (RMS, peak) |\n\
         |---|---|---|---|---|---|---|---|\n",
        rows.first().map_or(0, |r| r.1.runs)
    );
    for (t, c) in rows {
        let (g_rms, g_peak) = (
            get(c, "gms", "sine_rms_error"),
            get(c, "gms", "reversal_error"),
        );
        let rel = match (own, g_rms, g_peak) {
            (Some((r0, p0)), Some((r, _)), Some((p, _))) => {
                format!("×{:.2}, ×{:.2}", r / r0, p / p0)
            }
            _ => "-".into(),
        };
        s += &format!(
            "| {} | {} | {} | {} | {} | {} | {} | {} |\n",
            t.name,
            cell(get(c, "none", "sine_rms_error")),
            cell(get(c, "static", "sine_rms_error")),
            cell(g_rms),
            cell(get(c, "gms-adaptive", "sine_rms_error")),
            cell(get(c, "none", "reversal_error")),
            cell(g_peak),
            rel
        );
    }
    s
}
