//! `gms-tune map`: the position map measured (`gms_bench::posmap`: runs both ways, a harmonic
//! fit, the even part the torque offset, the odd part the friction's scale), written
//! (`map.csv`, plots), and applied on request.

use std::path::PathBuf;

use gms_bench::posmap::MapPlan;
use gms_tune::Link;
use gms_tune::jobs;

use crate::Fail;
use crate::tracked::{Bar, ctrl_c};

/// What `gms-tune map` is asked.
pub struct Args {
    /// The runs and the fit.
    pub plan: MapPlan,
    /// The CSV written (the plots beside it).
    pub out: PathBuf,
    /// Write the map into the device and switch it on.
    pub apply: bool,
    /// And save it (with the parameters, in flash).
    pub save: bool,
}

/// Measures, fits, writes, applies.
pub fn run(link: &mut Link, a: &Args) -> Result<(), Fail> {
    a.plan.check().map_err(|e| Fail::Usage(e.to_string()))?;
    if let Some(dir) = a.out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)
            .map_err(|e| Fail::Usage(format!("{}: cannot create: {e}", dir.display())))?;
    }
    eprintln!(
        "map: {} period(s) of {:.4} rad each way at {} rad/s, {} bins, {} harmonics: about {:.0} s \
         of device time",
        a.plan.periods,
        a.plan.period,
        a.plan.speed,
        a.plan.bins,
        a.plan.order,
        a.plan.device_seconds()
    );
    let mut bar = Bar::new();
    let mut ctl = jobs::Control {
        stop: ctrl_c(),
        why: "interrupted (Ctrl-C)",
        hooks: &mut bar,
    };
    let r = jobs::map(link, &a.plan, Some(&a.out), &mut ctl);
    bar.bar.finish_and_clear();
    let (data, map) = match r {
        Ok(v) => v,
        Err(gms_bench::Error::Io(m)) => return Err(Fail::Usage(m)),
        Err(e) => {
            return Err(Fail::Device(format!(
                "{e}; the bridge is off, the settings as they were"
            )));
        }
    };
    let rms = |v: &[f64]| (v.iter().map(|x| x * x).sum::<f64>() / v.len().max(1) as f64).sqrt();
    let mean = map.offset.iter().sum::<f64>() / map.offset.len().max(1) as f64;
    let ripple: Vec<f64> = map.offset.iter().map(|o| o - mean).collect();
    let (lo, hi) = map
        .scale
        .iter()
        .fold((f64::MAX, f64::MIN), |(a, b), k| (a.min(*k), b.max(*k)));
    println!(
        "{} + {} samples; torque offset: ripple {:.3} µN·m RMS (mean {:.3} µN·m); friction scale \
         {lo:.3} … {hi:.3} of the model's {:.3} µN·m at {} rad/s; fit residuals {:.3} / {:.3} µN·m",
        data.forward.len(),
        data.backward.len(),
        rms(&ripple) * 1e6,
        mean * 1e6,
        map.friction * 1e6,
        a.plan.speed,
        map.residual.0 * 1e6,
        map.residual.1 * 1e6
    );
    println!(
        "wrote {} and map.svg, map-scale.svg beside it",
        a.out.display()
    );
    if a.apply {
        let n =
            gms_bench::posmap::write(link, &map, true).map_err(|e| Fail::Device(e.to_string()))?;
        println!("wrote the {n} bins into the device; map.enable 1");
        if a.save {
            link.ask(gms_core::protocol::Command::Disable)?;
            link.ask(gms_core::protocol::Command::Save)?;
            println!("saved (the bridge is off)");
        }
    }
    Ok(())
}
