//! The long bench runs as jobs, one API for the command line, the window and Python: each job
//! reads what it needs from the device, plans, runs its `gms_bench` workflow on a stoppable
//! bench ([`RunBench`]: a stop flag, progress hooks; the device's settings put back
//! whatever ends it) and writes its files. The callers only present the outcome, and apply it
//! when asked.

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

use gms_bench::{
    Commissioned, DeviceInfo, Gathered, Plans, Ranges, TuneFf, TuneFfPlan, commission, identify_on,
    tune_ff,
};
use gms_ident::Error;
use gms_ident::identify::Identified;
use gms_ident::paramfile::ParamFile;

use crate::Link;
use crate::run::{Hooks, RunBench, commissioned_file, write_identified};

/// A long run.
#[derive(Debug, Clone)]
pub enum Job {
    /// The paper's identification: pre-sliding, sliding and lag experiments, then the fits.
    Identify {
        /// The experiments' ranges (`None`s: from the device's model).
        ranges: Ranges,
        /// Directory for the data, the report and the plots.
        report: PathBuf,
        /// The identified parameter file, if one is to be written.
        out: Option<PathBuf>,
        /// GMS blocks to fit.
        blocks: usize,
        /// Fit each sliding direction on its own.
        asymmetric: bool,
    },
    /// The feedforward gain from repeated sine tests.
    TuneFf {
        /// The sweep.
        plan: TuneFfPlan,
        /// Directory for `curve.csv` and `curve.svg`, if they are to be written.
        out: Option<PathBuf>,
    },
    /// The motor's constants, the directions and the loops' gains.
    Commission {
        /// The back-EMF runs' speed \[rad/s\].
        speed: f64,
        /// The parameter file to write (the device's set with the results), if any.
        out: Option<PathBuf>,
    },
}

/// What a job found.
pub enum Outcome {
    /// An identification: the data gathered, the fits, the parameter file and its text.
    Identified {
        /// The experiments' data.
        gathered: Box<Gathered>,
        /// The fits and their report.
        identified: Box<Identified>,
        /// The identified parameter file.
        file: Box<ParamFile>,
        /// Its text.
        text: String,
    },
    /// A feedforward tuning.
    TunedFf(Box<TuneFf>),
    /// A commissioning: its findings, the device's set with them as a parameter file, its text.
    Commissioned {
        /// The findings.
        commissioned: Box<Commissioned>,
        /// The parameter file.
        file: Box<ParamFile>,
        /// Its text.
        text: String,
    },
}

/// The device's identification plans for `ranges` (what `Job::Identify` will run; for a
/// caller that shows the plan first).
pub fn identify_plans(link: &mut Link, ranges: &Ranges) -> Result<(DeviceInfo, Plans), Error> {
    let dev = DeviceInfo::read(link)?;
    let plans = Plans::new(&dev, ranges)?;
    Ok((dev, plans))
}

/// Runs `job` on `link`: `stop` set ends it (`why` says by what), `hooks` hear each stage and
/// wait, `point(test, gain, rms)` each tune-ff test. The bridge is off and the device's
/// settings are as they were after it, however it ended.
pub fn run(
    link: &mut Link,
    job: Job,
    stop: Arc<AtomicBool>,
    why: &'static str,
    hooks: &mut dyn Hooks,
    point: &mut dyn FnMut(usize, f64, f64),
) -> Result<Outcome, Error> {
    match job {
        Job::Identify {
            ranges,
            report,
            out,
            blocks,
            asymmetric,
        } => {
            let (_, plans) = identify_plans(link, &ranges)?;
            let mut b = RunBench::new(link, stop, why, hooks);
            let (gathered, identified) = identify_on(
                &mut b,
                &plans,
                &report,
                blocks,
                asymmetric,
                &mut |b: &mut RunBench<'_, '_>, name, seconds| b.stage(name, seconds),
            )?;
            let (file, text) = write_identified(&identified, &report, out.as_deref())?;
            Ok(Outcome::Identified {
                gathered: Box::new(gathered),
                identified: Box::new(identified),
                file: Box::new(file),
                text,
            })
        }
        Job::TuneFf { plan, out } => {
            plan.check()?;
            if let Some(dir) = &out {
                std::fs::create_dir_all(dir)
                    .map_err(|e| Error::Io(format!("{}: cannot create: {e}", dir.display())))?;
            }
            let (_, seconds) = plan.tests();
            let mut b = RunBench::new(link, stop, why, hooks);
            b.stage("tune-ff", seconds);
            let t = tune_ff(&mut b, &plan, point)?;
            if let Some(dir) = &out {
                write_tune_ff(&t, dir)?;
            }
            Ok(Outcome::TunedFf(Box::new(t)))
        }
        Job::Commission { speed, out } => {
            let before = gms_bench::paramfile::dump(link)?;
            let mut b = RunBench::new(link, stop, why, hooks);
            b.stage("commission", 5.0);
            let c = commission(&mut b, speed)?;
            let (file, text) = commissioned_file(&c, before);
            if let Some(out) = &out {
                gms_ident::io::write_atomic(out, text.as_bytes())?;
            }
            Ok(Outcome::Commissioned {
                commissioned: Box::new(c),
                file: Box::new(file),
                text,
            })
        }
    }
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
