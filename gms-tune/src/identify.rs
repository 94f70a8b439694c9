//! `gms-tune identify`: the paper's three experiments on the device (the experiments of
//! `gms_ident::bench`, shared with `hil-sim`), their CSVs, the identification (the same
//! pipeline as `hil-sim identify`), the parameter file, the report and, asked for, the set
//! loaded into the device and saved.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use gms_ident::Error;
use gms_ident::bench::{
    self, Bench, DeviceInfo, LagPlan, Plans, Ranges, check_faults, get_param, position,
};
use gms_ident::identify::{Inputs, fit_stribeck, identify_from, write_report};
use gms_ident::paramfile::ParamFile;
use gms_tune::Link;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

use crate::Fail;

/// What `gms-tune identify` is asked.
pub struct Args {
    /// The parameter file written.
    pub out: PathBuf,
    /// The directory of the CSVs, the report and its plots.
    pub report: PathBuf,
    /// Maxwell-slip blocks fitted.
    pub blocks: usize,
    /// Fit each sliding direction separately.
    pub asymmetric: bool,
    /// Load the identified set into the device.
    pub apply: bool,
    /// And persist it.
    pub save: bool,
    /// The experiments' ranges.
    pub ranges: Ranges,
}

/// The link as a bench whose waits move a progress bar (in device milliseconds) and whose
/// requests stop once the user pressed Ctrl-C.
struct Tracked<'a> {
    link: &'a mut Link,
    bar: ProgressBar,
    stop: Arc<AtomicBool>,
}

impl Tracked<'_> {
    fn interrupted(&self) -> Result<(), Error> {
        if self.stop.load(Ordering::SeqCst) {
            Err(Error::Device("interrupted (Ctrl-C)".into()))
        } else {
            Ok(())
        }
    }

    /// A new bar for `what`, `seconds` of device time long.
    fn start(&mut self, what: &str, seconds: f64) {
        self.bar.finish_and_clear();
        let bar = ProgressBar::with_draw_target(
            Some((seconds * 1000.0).max(1.0) as u64),
            ProgressDrawTarget::stderr(),
        );
        if let Ok(style) = ProgressStyle::with_template(
            "{prefix:>11} [{bar:32}] {percent:>3} %  {elapsed_precise} elapsed, about {eta} left",
        ) {
            bar.set_style(style.progress_chars("=> "));
        }
        bar.set_prefix(what.to_string());
        bar.enable_steady_tick(Duration::from_millis(200));
        self.bar = bar;
    }
}

impl Bench for Tracked<'_> {
    fn request(&mut self, line: &str) -> Result<(Vec<String>, String), Error> {
        // `disable` goes out even after Ctrl-C: it is what an interrupted run sends.
        if line != "disable" {
            self.interrupted()?;
        }
        Bench::request(&mut *self.link, line)
    }

    fn wait(&mut self, seconds: f64) -> Result<(), Error> {
        self.interrupted()?;
        Bench::wait(&mut *self.link, seconds)?;
        if seconds.is_finite() && seconds > 0.0 {
            self.bar.inc((seconds * 1000.0) as u64);
        }
        self.interrupted()
    }
}

/// Writes `text` to `dir/name`, as a usage failure if it cannot.
fn write(dir: &Path, name: &str, text: &str) -> Result<PathBuf, Fail> {
    let p = dir.join(name);
    gms_ident::io::write_atomic(&p, text.as_bytes()).map_err(|e| Fail::Usage(e.to_string()))?;
    Ok(p)
}

/// The device's stroke limits narrowed to the window around where the axis is; returns the
/// previous ones.
fn narrow_limits(b: &mut impl Bench, window: f64) -> Result<(f64, f64), Error> {
    let (lo, hi) = (get_param(b, "lim.pos_min")?, get_param(b, "lim.pos_max")?);
    let x = position(b)?;
    let (nlo, nhi) = ((x - window).max(lo), (x + window).min(hi));
    // Widening first never crosses: pos_min < pos_max holds after each set.
    b.request(&format!("set lim.pos_min {nlo}"))?;
    b.request(&format!("set lim.pos_max {nhi}"))?;
    Ok((lo, hi))
}

/// Runs the experiments, writes the data, fits, writes the results; on any failure the bridge
/// is off, the stroke limits are back, and the data gathered so far is on disk.
pub fn run(link: &mut Link, a: &Args) -> Result<(), Fail> {
    if (a.apply || a.save) && a.blocks != 6 {
        return Err(Fail::Usage(
            "--apply/--save need --blocks 6: the device's compensator has 6 blocks".into(),
        ));
    }
    let stop = Arc::new(AtomicBool::new(false));
    {
        let stop = stop.clone();
        // A second handler cannot be set (a second run in one process): the run then ends
        // only on its own.
        let _ = ctrlc::set_handler(move || stop.store(true, Ordering::SeqCst));
    }
    let dev = DeviceInfo::read(link).map_err(|e| Fail::Device(e.to_string()))?;
    check_faults(link).map_err(|e| Fail::Device(format!("{e}: `clear` it first")))?;
    let plans = Plans::new(&dev, &a.ranges).map_err(|e| Fail::Usage(e.to_string()))?;
    std::fs::create_dir_all(&a.report)
        .map_err(|e| Fail::Usage(format!("{}: cannot create: {e}", a.report.display())))?;
    let dt = dev.dt();
    let pre_steps = (dev.fs / (dev.k_m * plans.presliding.step)).ceil() as u32;
    let t_pre = plans.presliding.duration(pre_steps, dt);
    let t_slide = plans.sliding.duration(dt);
    let t_lag = LagPlan::for_vs(dev.vs, dev.pos_hz).duration();
    eprintln!(
        "pre-sliding: torque steps of {:.3e} N·m from rest (about {pre_steps} to breakaway)\n\
         sliding:     {} speeds from {:.3e} to {:.3e} rad/s, each way\n\
         lag:         speed swept around 1.5 Vs, 0.2 to 20 Hz\n\
         stroke window ±{} rad; about {:.0} s of device time",
        plans.presliding.step * dev.k_m,
        plans.sliding.speeds.len(),
        plans.sliding.speeds[0],
        plans.sliding.speeds[plans.sliding.speeds.len() - 1],
        plans.window,
        t_pre + t_slide + t_lag
    );
    let started = Instant::now();
    let mut pre = Vec::new();
    let mut slide = Vec::new();
    let mut lag_data = None;
    let mut bench = Tracked {
        link,
        bar: ProgressBar::hidden(),
        stop,
    };
    let limits = narrow_limits(&mut bench, plans.window);
    let result = match &limits {
        Ok(_) => Ok(()),
        Err(e) => Err(Fail::Device(e.to_string())),
    }
    .and_then(|_| {
        let b = &mut bench;
        let dev_err = |e: Error| Fail::Device(e.to_string());
        b.start("pre-sliding", t_pre);
        bench::presliding(b, &plans.presliding, &mut pre).map_err(dev_err)?;
        b.start("sliding", t_slide);
        bench::sliding(b, &plans.sliding, &mut slide).map_err(dev_err)?;
        // The lag run around the Vs just measured.
        let (v, f): (Vec<f64>, Vec<f64>) = slide.iter().map(|(v, f)| (v.abs(), f.abs())).unzip();
        let vs = fit_stribeck(&v, &f)
            .map_err(|e| Fail::Device(format!("the sliding data do not fit: {e}")))?
            .vs;
        let plan = LagPlan::for_vs(vs, dev.pos_hz);
        if plan.stroke() > plans.window {
            return Err(Fail::Usage(format!(
                "the lag run needs {:.2} rad of stroke, more than the window {} rad: widen it",
                plan.stroke(),
                plans.window
            )));
        }
        b.start("lag", plan.duration());
        lag_data = Some(bench::lag(b, &plan).map_err(dev_err)?);
        b.bar.finish_and_clear();
        Ok(())
    });
    bench.bar.finish_and_clear();
    // Whatever happened: the bridge off, the limits back (best effort: the link may be gone).
    let _ = Bench::request(&mut *bench.link, "disable");
    if let Ok((lo, hi)) = limits {
        let _ = Bench::request(&mut *bench.link, &format!("set lim.pos_min {lo}"));
        let _ = Bench::request(&mut *bench.link, &format!("set lim.pos_max {hi}"));
    }
    let link = bench.link;
    let pre_csv = write(&a.report, "presliding.csv", &bench::presliding_csv(&pre))?;
    let slide_csv = write(&a.report, "sliding.csv", &bench::sliding_csv(&slide))?;
    let lag_csv = match &lag_data {
        Some((t, x, f)) => Some(write(&a.report, "lag.csv", &bench::lag_csv(t, x, f))?),
        None => None,
    };
    if let Err(e) = result {
        let msg = |m: String| {
            format!(
                "{m}; the bridge is off; the data so far ({} pre-sliding points, {} sliding \
                 points) is in {}",
                pre.len(),
                slide.len(),
                a.report.display()
            )
        };
        return Err(match e {
            Fail::Device(m) => Fail::Device(msg(m)),
            Fail::Usage(m) => Fail::Usage(msg(m)),
        });
    }
    let wall = started.elapsed().as_secs_f64();
    eprintln!(
        "experiments done in {wall:.1} s: {} pre-sliding points, {} sliding points, {} lag samples",
        pre.len(),
        slide.len(),
        lag_data.as_ref().map_or(0, |l| l.0.len())
    );
    let id = identify_from(&Inputs {
        presliding: Some(&pre_csv),
        sliding: Some(&slide_csv),
        lag: lag_csv.as_deref(),
        blocks: a.blocks,
        asymmetric: a.asymmetric,
    })
    .map_err(|e| Fail::Device(format!("the identification failed: {e}")))?;
    for l in &id.report {
        println!("{l}");
    }
    write_report(&id, &a.report).map_err(|e| Fail::Usage(e.to_string()))?;
    let file = ParamFile {
        friction: id.spec.clone(),
        device: None,
    };
    let text = format!(
        "# identified by gms-tune identify (data in {})\n{}{}",
        a.report.display(),
        id.report
            .iter()
            .map(|l| format!("# {l}\n"))
            .collect::<String>(),
        file.to_toml()
    );
    gms_ident::io::write_atomic(&a.out, text.as_bytes()).map_err(|e| Fail::Usage(e.to_string()))?;
    println!(
        "wrote {} and the report in {}",
        a.out.display(),
        a.report.display()
    );
    if a.apply || a.save {
        let n = crate::load(link, &a.out)?;
        println!("loaded {n} parameters into the device");
        if a.save {
            link.request("save")?;
            println!("saved");
        }
    }
    Ok(())
}
