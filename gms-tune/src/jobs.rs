//! The long bench runs as jobs, one API for the command line, the window and Python: each job
//! ([`identify`], [`tune_ff`], [`commission`]) runs its `gms_bench` workflow on a stoppable
//! bench ([`RunBench`]: a stop flag, progress hooks; the device's settings put back whatever
//! ends it) and writes its files. The callers only present the outcome, and apply it when
//! asked.

use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

use gms_bench::{
    Commissioned, DeviceInfo, Gathered, Plans, Ranges, TuneFf, TuneFfPlan, identify_on,
};
use gms_ident::Error;
use gms_ident::identify::Identified;
use gms_ident::paramfile::ParamFile;

use crate::Link;
use crate::run::{Hooks, RunBench, commissioned_file, write_identified};

/// How a job is run: a stop flag (`why` says by what it was set) and the hooks told of each
/// stage and wait.
pub struct Control<'a> {
    /// Set: the run ends at its next request or wait.
    pub stop: Arc<AtomicBool>,
    /// What stopped it, for the error (e.g. "interrupted (Ctrl-C)").
    pub why: &'static str,
    /// Told of each stage and each wait.
    pub hooks: &'a mut dyn Hooks,
}

impl Control<'_> {
    fn bench<'l, 'h>(&'h mut self, link: &'l mut Link) -> RunBench<'l, 'h> {
        RunBench::new(link, self.stop.clone(), self.why, self.hooks)
    }
}

/// What an identification found: the data gathered, the fits, the parameter file and its text.
pub struct Identification {
    /// The experiments' data.
    pub gathered: Gathered,
    /// The fits and their report.
    pub identified: Identified,
    /// The identified parameter file.
    pub file: ParamFile,
    /// Its text.
    pub text: String,
}

/// What a commissioning found, and the device's set with it as a parameter file.
pub struct Commissioning {
    /// The findings.
    pub commissioned: Commissioned,
    /// The device's settings with the findings, as a parameter file.
    pub file: ParamFile,
    /// Its text.
    pub text: String,
}

/// The device's identification plans for `ranges`: what [`identify`] runs (a caller shows
/// them first).
pub fn identify_plans(link: &mut Link, ranges: &Ranges) -> Result<(DeviceInfo, Plans), Error> {
    let dev = DeviceInfo::read(link)?;
    let plans = Plans::new(&dev, ranges)?;
    Ok((dev, plans))
}

/// The paper's identification with `plans`: the pre-sliding, sliding and lag experiments, the
/// fits of `blocks` blocks (`asymmetric`: each sliding direction on its own), the data, report
/// and plots in `report`, the parameter file in `out` if given. The bridge is off and the
/// device's settings as they were after it, however it ended.
pub fn identify(
    link: &mut Link,
    plans: &Plans,
    report: &Path,
    out: Option<&Path>,
    blocks: usize,
    asymmetric: bool,
    ctl: &mut Control<'_>,
) -> Result<Identification, Error> {
    let mut b = ctl.bench(link);
    let (gathered, identified) = identify_on(
        &mut b,
        plans,
        report,
        blocks,
        asymmetric,
        &mut |b: &mut RunBench<'_, '_>, name, seconds| b.stage(name, seconds),
    )?;
    let (file, text) = write_identified(&identified, report, out)?;
    Ok(Identification {
        gathered,
        identified,
        file,
        text,
    })
}

/// The feedforward gain from `plan`'s sine tests, `point(test, gain, rms)` told of each;
/// `curve.csv` and `curve.svg` in `out` if given. The gain is as it was after it.
pub fn tune_ff(
    link: &mut Link,
    plan: &TuneFfPlan,
    out: Option<&Path>,
    ctl: &mut Control<'_>,
    point: &mut dyn FnMut(usize, f64, f64),
) -> Result<TuneFf, Error> {
    plan.check()?;
    if let Some(dir) = out {
        std::fs::create_dir_all(dir)
            .map_err(|e| Error::Io(format!("{}: cannot create: {e}", dir.display())))?;
    }
    let (_, seconds) = plan.tests();
    let mut b = ctl.bench(link);
    b.stage("tune-ff", seconds);
    let t = gms_bench::tune_ff(&mut b, plan, point)?;
    if let Some(dir) = out {
        write_tune_ff(&t, dir)?;
    }
    Ok(t)
}

/// The motor's constants, the directions and the loops' gains (back-EMF runs at `speed`
/// \[rad/s\]); the device's set with them written to `out` if given. The device's settings are
/// as they were after it: the caller applies the file when asked.
pub fn commission(
    link: &mut Link,
    speed: f64,
    out: Option<&Path>,
    ctl: &mut Control<'_>,
) -> Result<Commissioning, Error> {
    let before = gms_bench::paramfile::dump(link)?;
    let mut b = ctl.bench(link);
    b.stage("commission", 5.0);
    let commissioned = gms_bench::commission(&mut b, speed)?;
    let (file, text) = commissioned_file(&commissioned, before);
    if let Some(out) = out {
        gms_ident::io::write_atomic(out, text.as_bytes())?;
    }
    Ok(Commissioning {
        commissioned,
        file,
        text,
    })
}

/// tune-ff's files in `dir`: `curve.csv` (gain, RMS \[rad\]) and `curve.svg` (the curve in
/// counts and the fitted parabola over the refinement's window).
pub fn write_tune_ff(t: &TuneFf, dir: &std::path::Path) -> Result<(), Error> {
    let rpc = t.rad_per_count;
    let mut csv = String::from("gain,rms_rad\n");
    for (g, r) in &t.curve {
        csv += &format!("{g},{r}\n");
    }
    gms_ident::io::write_atomic(&dir.join("curve.csv"), csv.as_bytes())?;
    let pts: Vec<(f64, f64)> = t.curve.iter().map(|(g, r)| (*g, r / rpc)).collect();
    // The fitted parabola (RMS = √(mean square)) over the refinement's window.
    let fit: Vec<(f64, f64)> = match t.optimum {
        Some(o) => (0..=60)
            .map(|i| {
                let g = t.window.0 + (t.window.1 - t.window.0) * i as f64 / 60.0;
                let ms = o.min + o.curvature * (g - o.at).powi(2);
                (g, ms.max(0.0).sqrt() / rpc)
            })
            .collect(),
        None => Vec::new(),
    };
    let title = match t.optimum {
        Some(o) if t.decided => format!(
            "tune-ff: sine RMS error against ff.gain; optimum {:.3} ± {:.3}",
            o.at,
            o.half_width()
        ),
        _ => "tune-ff: sine RMS error against ff.gain; no clear optimum".to_string(),
    };
    gms_ident::plot::fit_plot(
        &dir.join("curve.svg"),
        &title,
        ("ff.gain [-]", "RMS error [counts]"),
        &pts,
        &fit,
    )
    .map_err(Error::Io)
}
