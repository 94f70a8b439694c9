//! The long bench runs as jobs, one API for the command line, the window and Python: each job
//! ([`identify`], [`tune_ff`], [`commission`], [`frf`]) runs its `gms_bench` workflow on a stoppable
//! bench ([`RunBench`]: a stop flag, progress hooks; the device's settings put back whatever
//! ends it) and writes its files. The callers only present the outcome, and apply it when
//! asked.

use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

use gms_bench::Error;
use gms_bench::{
    Commissioned, DeviceInfo, Gathered, Plans, Ranges, TuneFf, TuneFfPlan, identify_on,
};
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

/// Creates the output directory `out`, if one is given.
fn make_dir(out: Option<&Path>) -> Result<(), Error> {
    match out {
        Some(dir) => std::fs::create_dir_all(dir)
            .map_err(|e| Error::Io(format!("{}: cannot create: {e}", dir.display()))),
        None => Ok(()),
    }
}

/// The device's identification plans for `ranges`: what [`identify`] runs (a caller shows
/// them first).
pub fn identify_plans(link: &mut Link, ranges: &Ranges) -> Result<(DeviceInfo, Plans), Error> {
    let dev = DeviceInfo::read(link)?;
    let plans = Plans::new(&dev, ranges)?;
    plans.check_sliding()?;
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
    make_dir(out)?;
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
    let mut b = ctl.bench(link);
    b.stage("commission", 5.0);
    let before = gms_bench::paramfile::dump(&mut b)?;
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

/// A frequency response: `plan`'s sweep, each point told to `point` as it comes; in `out` if
/// given `frf.csv`, `bode.svg` and (the open loop) `margins.toml` — written with the points
/// measured so far when the sweep fails, and then the error says so. The bridge is off and the
/// settings as they were after it.
pub fn frf(
    link: &mut Link,
    plan: &gms_bench::frf::Plan,
    out: Option<&Path>,
    ctl: &mut Control<'_>,
    point: &mut dyn FnMut(usize, &gms_bench::frf::Point),
) -> Result<gms_bench::frf::Sweep, Error> {
    make_dir(out)?;
    let mut b = ctl.bench(link);
    b.stage(&format!("frf {}", plan.lp.name()), plan.device_seconds());
    let mut pts = Vec::new();
    let r = gms_bench::frf::run(&mut b, plan, &mut pts, point);
    match (r, out) {
        (Ok(sweep), Some(dir)) => {
            write_frf(&sweep, dir)?;
            Ok(sweep)
        }
        (Ok(sweep), None) => Ok(sweep),
        (Err(e), Some(dir)) if !pts.is_empty() => {
            gms_ident::io::write_atomic(
                &dir.join("frf.csv"),
                gms_bench::frf::csv(&pts).as_bytes(),
            )?;
            Err(e.with_note(&format!(
                "the {} points measured are in {}",
                pts.len(),
                dir.join("frf.csv").display()
            )))
        }
        (Err(e), _) => Err(e),
    }
}

/// The files of a sweep in `dir`: `frf.csv`, `bode.svg`, and `margins.toml` for the open
/// loop.
pub fn write_frf(sweep: &gms_bench::frf::Sweep, dir: &Path) -> Result<(), Error> {
    use gms_ident::plot::{BodeSeries, bode_plot};
    gms_ident::io::write_atomic(
        &dir.join("frf.csv"),
        gms_bench::frf::csv(&sweep.points).as_bytes(),
    )?;
    let mut marks = Vec::new();
    if let Some(m) = &sweep.margins {
        gms_ident::io::write_atomic(
            &dir.join("margins.toml"),
            gms_bench::frf::margins_toml(m).as_bytes(),
        )?;
        if m.crossover_hz.is_finite() {
            marks.push((
                m.crossover_hz,
                format!("crossover {:.0} Hz", m.crossover_hz),
            ));
        }
        if m.phase_margin_hz.is_finite() && m.phase_margin_hz != m.crossover_hz {
            marks.push((
                m.phase_margin_hz,
                format!(
                    "PM {:.0}° at {:.0} Hz",
                    m.phase_margin_deg, m.phase_margin_hz
                ),
            ));
        }
        if m.gain_margin_hz.is_finite() {
            marks.push((
                m.gain_margin_hz,
                format!(
                    "GM {:.1} dB at {:.0} Hz",
                    m.gain_margin_db, m.gain_margin_hz
                ),
            ));
        }
    }
    let (good, poor): (Vec<_>, Vec<_>) = sweep
        .points
        .iter()
        .partition(|p| p.coherence >= gms_bench::frf::MIN_COHERENCE);
    let tri = |v: Vec<&gms_bench::frf::Point>| -> Vec<(f64, f64, f64)> {
        v.iter()
            .map(|p| (p.f_hz, p.gain_db(), p.phase_deg()))
            .collect()
    };
    let (good, poor) = (tri(good), tri(poor));
    let unit = match sweep.plan.lp {
        gms_bench::frf::Loop::Plant => "position per current [dB rad/A]",
        gms_bench::frf::Loop::Open => "loop gain",
        gms_bench::frf::Loop::Closed => "position per reference",
    };
    let title = format!(
        "gms-tune frf --loop {}: {unit}{}",
        sweep.plan.lp.name(),
        match sweep.plan.velocity {
            Some(v) => format!(", sliding at {v} rad/s"),
            None => ", at rest".into(),
        }
    );
    bode_plot(
        &dir.join("bode.svg"),
        &title,
        &[
            BodeSeries {
                label: "measured",
                colour: plotters_blue(),
                data: &good,
                points: true,
            },
            BodeSeries {
                label: "below the noise (coherence < 0.9)",
                colour: plotters_grey(),
                data: &poor,
                points: true,
            },
        ],
        &marks,
    )
    .map_err(Error::Io)
}

fn plotters_blue() -> gms_ident::plot::RGBColor {
    gms_ident::plot::RGBColor(30, 90, 200)
}

fn plotters_grey() -> gms_ident::plot::RGBColor {
    gms_ident::plot::RGBColor(170, 170, 170)
}

/// A position map: `plan`'s runs both ways and the fit (the scale relative to the device's
/// model's sliding friction at the speed); `out` (a `map.csv` path) and the plots beside it
/// if given. The bridge is off and the settings as they were after it; the caller applies it.
pub fn map(
    link: &mut Link,
    plan: &gms_bench::posmap::MapPlan,
    out: Option<&Path>,
    ctl: &mut Control<'_>,
) -> Result<(gms_bench::posmap::MapData, gms_bench::posmap::PosMap), Error> {
    plan.check()?;
    // Every request through the stoppable bench: a Stop ends the job at its next request.
    let mut b = ctl.bench(link);
    b.stage("map", plan.device_seconds());
    let settings = gms_bench::settings::read(&mut b)?;
    let sliding = gms_bench::posmap::model_sliding_friction(&settings, plan.speed);
    let data = gms_bench::posmap::measure(&mut b, plan)?;
    let map = gms_bench::posmap::fit(&data, plan, sliding)?;
    if let Some(path) = out {
        write_map(&data, &map, path)?;
    }
    Ok((data, map))
}

/// The map's files: `path` (`angle_rad,torque_nm,friction_scale`), and beside it
/// `map.svg` (the torque each way, sample by sample, under the offset fitted) and
/// `map-scale.svg` (the friction's scale).
pub fn write_map(
    data: &gms_bench::posmap::MapData,
    map: &gms_bench::posmap::PosMap,
    path: &Path,
) -> Result<(), Error> {
    gms_ident::io::write_atomic(path, gms_bench::posmap::csv(map).as_bytes())?;
    let dir = path.parent().unwrap_or(Path::new("."));
    let wrap = |a: f64| a.rem_euclid(map.period);
    // At most about 1600 points drawn (the plot stays light; the CSV has the map).
    let every = (data.forward.len() + data.backward.len())
        .div_ceil(1600)
        .max(1);
    let pts: Vec<(f64, f64)> = data
        .forward
        .iter()
        .chain(&data.backward)
        .step_by(every)
        .map(|(a, t)| (wrap(*a), t * 1e6))
        .collect();
    let offset: Vec<(f64, f64)> = map
        .angle
        .iter()
        .zip(&map.offset)
        .map(|(a, o)| (*a, o * 1e6))
        .collect();
    gms_ident::plot::fit_plot(
        &dir.join("map.svg"),
        "gms-tune map: the torque each way (points) and the offset fitted (the even part)",
        ("angle [rad]", "torque [µN·m]"),
        &pts,
        &offset,
    )
    .map_err(Error::Io)?;
    let scale: Vec<(f64, f64)> = map
        .angle
        .iter()
        .zip(&map.scale)
        .map(|(a, k)| (*a, *k))
        .collect();
    gms_ident::plot::fit_plot(
        &dir.join("map-scale.svg"),
        "gms-tune map: the friction's scale (the odd part over the model's sliding friction)",
        ("angle [rad]", "friction scale [-]"),
        &[],
        &scale,
    )
    .map_err(Error::Io)
}

/// Learning from repetition: `plan`'s motion played from the device's tables, the correction
/// learned after each period (`each` told of every iteration as it comes); `iterations.csv`,
/// `correction.csv` and `learning.svg` in `out` if given. `apply` leaves the best correction
/// playing for the next runs of the table; otherwise the table plays none after. The axis
/// holds at the table's start after; the bridge is off on failure.
pub fn learn(
    link: &mut Link,
    plan: &gms_bench::learn::LearnPlan,
    out: Option<&Path>,
    apply: bool,
    ctl: &mut Control<'_>,
    each: &mut dyn FnMut(&gms_bench::ilc::Iteration),
) -> Result<gms_bench::learn::Learned, Error> {
    plan.check()?;
    make_dir(out)?;
    let mut b = ctl.bench(link);
    b.stage(
        "learn",
        plan.path.period_s() * (2 * plan.iterations + 3) as f64,
    );
    let l = gms_bench::learn::learn(&mut b, plan, each, apply)?;
    if let Some(dir) = out {
        write_learned(&l, dir)?;
    }
    Ok(l)
}

/// The learning's files in `dir`: `iterations.csv` (`iteration,rms_counts,peak_counts`),
/// `correction.csv` (`t_s,position_rad,correction_nm`) and `learning.svg` (the RMS and peak
/// per iteration; the error over the period at the first pass and the last iteration).
pub fn write_learned(l: &gms_bench::learn::Learned, dir: &Path) -> Result<(), Error> {
    use gms_bench::learn::{correction_csv, iterations_csv};
    gms_ident::io::write_atomic(&dir.join("iterations.csv"), iterations_csv(l).as_bytes())?;
    gms_ident::io::write_atomic(&dir.join("correction.csv"), correction_csv(l).as_bytes())?;
    let dt = l.table.as_ref().map_or(1e-3, |t| t.dt());
    let pts: Vec<(f64, f64, f64)> = l
        .iterations
        .iter()
        .map(|i| (i.n as f64, i.rms, i.peak))
        .collect();
    let trace = |e: &[f64]| -> Vec<(f64, f64)> {
        e.iter()
            .enumerate()
            .map(|(k, v)| (k as f64 * dt, *v))
            .collect()
    };
    let first = l.errors.first().map(|e| trace(e)).unwrap_or_default();
    let last = l.errors.last().map(|e| trace(e)).unwrap_or_default();
    let last_name = format!("iteration {}", l.errors.len().saturating_sub(1));
    gms_ident::plot::learn_plot(
        &dir.join("learning.svg"),
        "gms-tune learn: the error over the iterations",
        &pts,
        &[("first pass", &first), (&last_name, &last)],
    )
    .map_err(Error::Io)
}
