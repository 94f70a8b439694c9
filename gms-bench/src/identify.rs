//! The whole bench identification (the experiments, then the fits of `gms-ident` on their
//! data) and loading a parameter file into a device.

use crate::client::{Bench, DeviceInfo, move_to, narrow_limits, position};
use crate::experiments::{
    LAG_MIN_SWING_COUNTS, LagPlan, Plans, lag, lag_csv, presliding, presliding_csv, sliding,
    sliding_csv,
};
use crate::settings::restoring;
use gms_ident::Error;

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
                "the lag run needs {:.2} rad of stroke, more than the window {} rad: widen it",
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
        return Err(match e {
            Error::Device(m) => Error::Device(format!("{m}; {kept}")),
            Error::Params(m) => Error::Params(format!("{m}; {kept}")),
            Error::Data(m) => Error::Data(format!("{m}; {kept}")),
            Error::Io(m) => Error::Io(format!("{m}; {kept}")),
            Error::Link(m) => Error::Link(format!("{m}; {kept}")),
            Error::Faulted { faults, during } => Error::Faulted {
                faults,
                during: Some(match during {
                    Some(d) => format!("{d}; {kept}"),
                    None => kept,
                }),
            },
            e @ Error::Refused(_) => Error::Device(format!("{e}; {kept}")),
        });
    }
    let (pre, slide, lag) = written.map_err(Error::Io)?;
    let mut id = gms_ident::identify::identify_from(&gms_ident::identify::Inputs {
        presliding: Some(&pre),
        sliding: Some(&slide),
        lag: lag.as_deref(),
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

/// Sends a parameter file to the device: its `[friction]` (a GMS model of 1 to 6 blocks, the
/// compensator's) as `gms.*` (with `gms.blocks` when fewer than 6), its `[device]` table by protocol path, staged and committed as
/// one set (weights that must sum to 1 cannot change one `set` at a time), so the device
/// takes all or nothing. A firmware without staging gets one `set` at a time, retried while
/// that makes progress. Returns the number of parameters sent.
pub fn load_params(
    b: &mut impl Bench,
    pf: &gms_ident::paramfile::ParamFile,
) -> Result<usize, Error> {
    use gms_ident::paramfile::ModelKind;
    let f = &pf.friction;
    let n = f.blocks.as_ref().map_or(0, Vec::len);
    if f.negative.is_some() {
        return Err(Error::Params(
            "[friction.negative]: the device's compensator has one Stribeck curve for both \
             directions; nothing loaded (fit without --asymmetric, or remove the table)"
                .into(),
        ));
    }
    if f.model != ModelKind::Gms || !(1..=6).contains(&n) {
        return Err(Error::Params(format!(
            "[friction] must be a gms model of 1 to 6 blocks for the device's compensator \
             (it is {} with {n} blocks)",
            f.model
        )));
    }
    f.gms_params::<6>()
        .map_err(|e| e.to_string())
        .and_then(|p| p.validate().map_err(|e| e.to_string()))
        .map_err(|e| Error::Params(format!("[friction] {e}")))?;
    let mut sets: Vec<(String, String)> = Vec::new();
    if n < 6 {
        // First: the blocks past n become unused, then the n blocks are set.
        sets.push(("gms.blocks".into(), format!("{n}")));
    }
    for (k, v) in [
        ("fs", f.fs),
        ("fc", f.fc),
        ("vs", f.vs),
        ("delta", f.delta.or(Some(1.0))),
        ("sigma", f.sigma.or(Some(0.0))),
        ("c", f.c),
    ] {
        if let Some(v) = v {
            sets.push((format!("gms.{k}"), format!("{v}")));
        }
    }
    for (i, blk) in f.blocks.iter().flatten().enumerate() {
        sets.push((format!("gms.k{}", i + 1), format!("{}", blk.k)));
        sets.push((format!("gms.a{}", i + 1), format!("{}", blk.alpha)));
    }
    for (k, v) in pf.device.iter().flatten() {
        let v = match v {
            toml::Value::Float(x) => format!("{x}"),
            toml::Value::Integer(x) => format!("{x}"),
            toml::Value::String(s) => s.clone(),
            _ => return Err(Error::Params(format!("[device] `{k}` is not a value"))),
        };
        sets.push((k.clone(), v));
    }
    crate::settings::apply(b, &sets, false)
}
