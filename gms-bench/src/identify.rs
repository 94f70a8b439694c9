//! The whole bench identification (the experiments, then the fits of `gms-ident` on their
//! data) and loading a parameter file into a device.

use crate::Error;
use crate::client::{Bench, DeviceInfo, move_to, narrow_limits, position};
use crate::experiments::{
    LAG_MIN_SWING_COUNTS, LagPlan, Plans, lag, lag_csv, presliding, presliding_csv, sliding,
    sliding_csv,
};
use crate::settings::restoring;

/// What a bench identification gathered.
#[derive(Debug, Clone, Default)]
pub struct Gathered {
    /// Pre-sliding `(x, f)` points.
    pub presliding: Vec<(f64, f64)>,
    /// Sliding `(v, f)` points.
    pub sliding: Vec<(f64, f64)>,
    /// The lag run `(t, x, f)`, once done.
    pub lag: Option<(Vec<f64>, Vec<f64>, Vec<f64>)>,
}

/// The whole bench identification: the stroke limits narrowed to the plans' window, the
/// pre-sliding staircase, a move back to the start, the sliding sweep, the lag run around the Vs just measured; then,
/// whatever happened, the bridge off, the limits back and the data written to `dir`
/// (`presliding.csv`, `sliding.csv`, `lag.csv`: what `hil-sim identify` reads), and on
/// success the identification of those files (`blocks`, `asymmetric` as `hil-sim identify`
/// takes them). `stage(b, name, seconds)` is called as each experiment starts, with its
/// expected device time (for progress). A failure says how much data was kept, and where.
pub fn identify_on<B: Bench>(
    b: &mut B,
    plans: &Plans,
    dir: &std::path::Path,
    blocks: usize,
    asymmetric: bool,
    stage: &mut dyn FnMut(&mut B, &str, f64),
) -> Result<(Gathered, gms_ident::identify::Identified), Error> {
    let mut g = Gathered::default();
    let dev = DeviceInfo::read(b)?;
    let dt = dev.dt();
    let mut lag_skipped: Option<f64> = None;
    // Whatever happens: the bridge off and the settings (the narrowed limits) back after.
    let result = restoring(b, |b| {
        narrow_limits(b, plans.window)?;
        let steps = (dev.fs / (dev.k_m * plans.presliding.step)).ceil() as u32;
        stage(
            b,
            "pre-sliding",
            plans.presliding.duration(steps, dt, dev.vs),
        );
        let x_start = position(b)?;
        presliding(b, &plans.presliding, &mut g.presliding)?;
        // Back to the start, so that the sliding runs have their planned stroke each way.
        move_to(b, x_start, 1.0)?;
        stage(b, "sliding", plans.sliding.duration(dt));
        sliding(b, &plans.sliding, &mut g.sliding)?;
        // The lag run around the Vs just measured.
        let (v, f): (Vec<f64>, Vec<f64>) =
            g.sliding.iter().map(|(v, f)| (v.abs(), f.abs())).unzip();
        let vs = gms_ident::identify::fit_stribeck(&v, &f)
            .map_err(|e| Error::Data(format!("the sliding data do not fit: {e}")))?
            .vs;
        let plan = LagPlan::for_vs(vs, dev.pos_hz);
        let swing = plan.swing_counts(dev.rad_per_count);
        if swing < LAG_MIN_SWING_COUNTS {
            // The lag shows at the sweep's top, where the encoder cannot see it: no run.
            lag_skipped = Some(swing);
            return Ok(());
        }
        if plan.stroke() > plans.window {
            return Err(Error::Params(format!(
                "the lag run needs {:.2} rad of stroke, more than the window {} rad: widen --window",
                plan.stroke(),
                plans.window
            )));
        }
        stage(b, "lag", plan.duration());
        g.lag = Some(lag(b, &plan)?);
        Ok(())
    });
    let written = (|| {
        std::fs::create_dir_all(dir)
            .map_err(|e| format!("{}: cannot create: {e}", dir.display()))?;
        let w = |name: &str, text: &str| {
            let p = dir.join(name);
            gms_ident::io::write_atomic(&p, text.as_bytes()).map(|_| p)
        };
        let pre = w("presliding.csv", &presliding_csv(&g.presliding))?;
        let slide = w("sliding.csv", &sliding_csv(&g.sliding))?;
        let lag = match &g.lag {
            Some((t, x, f)) => Some(w("lag.csv", &lag_csv(t, x, f))?),
            None => None,
        };
        Ok::<_, String>((pre, slide, lag))
    })();
    let kept = || {
        format!(
            "the bridge is off; the data so far ({} pre-sliding points, {} sliding points) is in {}",
            g.presliding.len(),
            g.sliding.len(),
            dir.display()
        )
    };
    if let Err(e) = result {
        let kept = match &written {
            Ok(_) => kept(),
            Err(w) => format!("the bridge is off; the data could not be written: {w}"),
        };
        return Err(e.with_note(&kept));
    }
    let (pre, slide, lag) = written.map_err(Error::Io)?;
    // The fits on the gathered arrays (the CSVs hold the same numbers: f64's shortest
    // decimal reads back exactly); their names in messages are the files'.
    use gms_ident::identify::{Data, Table, identify_data};
    let (xs, fs): (Vec<f64>, Vec<f64>) = g.presliding.iter().copied().unzip();
    let (vs, fv): (Vec<f64>, Vec<f64>) = g.sliding.iter().copied().unzip();
    // The load's direction, as `presliding_csv` writes it: the staircase's, positive.
    let dir: Vec<f64> = vec![1.0; fs.len()];
    let pre = Table {
        name: pre.display().to_string(),
        cols: vec![xs, fs, dir],
    };
    let slide = Table {
        name: slide.display().to_string(),
        cols: vec![vs, fv],
    };
    let lag = lag.zip(g.lag.as_ref()).map(|(p, (t, x, f))| Table {
        name: p.display().to_string(),
        cols: vec![t.clone(), x.clone(), f.clone()],
    });
    let mut id = identify_data(&Data {
        presliding: Some(&pre),
        sliding: Some(&slide),
        lag: lag.as_ref(),
        blocks,
        asymmetric,
    })?;
    if let Some(swing) = lag_skipped {
        id.report.push(format!(
            "frictional lag: not measured: the sweep's swing at its top frequency would be \
             {swing:.1} counts of this encoder (fewer than {LAG_MIN_SWING_COUNTS}), too few to \
             show the lag; C by the paper's rule"
        ));
    }
    Ok((g, id))
}

/// Loads a parameter file into a device (see [`crate::paramfile::load`]: the one mapping
/// between files and settings).
pub use crate::paramfile::load as load_params;
