//! `gms-tune identify`: the bench identification of `gms_bench` (the paper's three
//! experiments, shared with `hil-sim`; the same identification as `hil-sim identify`) on the
//! link, with progress bars and Ctrl-C; the parameter file, the report and, asked for, the set
//! loaded into the device and saved.

use gms_core::protocol::Command;
use std::path::PathBuf;
use std::time::Instant;

use gms_bench::Error;
use gms_bench::{self, LagPlan, Ranges, check_faults};
use gms_tune::Link;

use crate::Fail;
use crate::tracked::{Bar, ctrl_c};
use gms_tune::jobs;

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
    /// Print JSON instead of the readable report.
    pub json: bool,
}

/// Runs the experiments, writes the data, fits, writes the results; on any failure the bridge
/// is off, the stroke limits are back, and the data gathered so far is on disk.
pub fn run(link: &mut Link, a: &Args) -> Result<(), Fail> {
    if (a.apply || a.save) && a.asymmetric {
        return Err(Fail::Usage(
            "--asymmetric with --apply/--save: the device's compensator has one Stribeck curve \
             for both directions, so [friction.negative] could not be loaded (fit without \
             --asymmetric to apply)"
                .into(),
        ));
    }
    if (a.apply || a.save) && !(1..=6).contains(&a.blocks) {
        return Err(Fail::Usage(format!(
            "--apply/--save need --blocks 1 to 6: the device's compensator has at most 6 \
             blocks (asked for {})",
            a.blocks
        )));
    }
    check_faults(link).map_err(|e| Fail::Device(format!("{e}: `clear` it first")))?;
    let (dev, plans) = jobs::identify_plans(link, &a.ranges).map_err(|e| match e {
        Error::Params(m) => Fail::Usage(m),
        e => Fail::Device(e.to_string()),
    })?;
    let dt = dev.dt();
    let pre_steps = (dev.fs / (dev.k_m * plans.presliding.step)).ceil() as u32;
    let total = plans.presliding.duration(pre_steps, dt, dev.vs)
        + plans.sliding.duration(dt)
        + LagPlan::for_vs(dev.vs, dev.pos_hz).duration();
    eprintln!(
        "pre-sliding: the friction's memory erased, then torque steps of {:.3e} N·m from rest (about {pre_steps} to breakaway)\n\
         sliding:     {} speeds from {:.3e} to {:.3e} rad/s, each way\n\
         lag:         speed swept around 1.5 Vs, 0.2 to 20 Hz\n\
         stroke window ±{} rad; at least {total:.0} s of device time",
        plans.presliding.step * dev.k_m,
        plans.sliding.speeds.len(),
        plans.sliding.speeds[0],
        plans.sliding.speeds[plans.sliding.speeds.len() - 1],
        plans.window,
    );
    let started = Instant::now();
    let mut bar = Bar::new();
    let mut ctl = jobs::Control {
        stop: ctrl_c(),
        why: "interrupted (Ctrl-C)",
        hooks: &mut bar,
    };
    let r = jobs::identify(
        link,
        &plans,
        &a.report,
        Some(&a.out),
        a.blocks,
        a.asymmetric,
        &mut ctl,
    );
    bar.bar.finish_and_clear();
    let (g, id) = match r {
        Ok(j) => (j.gathered, j.identified),
        Err(Error::Params(m)) => return Err(Fail::Usage(m)),
        Err(e) => return Err(Fail::Device(e.to_string())),
    };
    eprintln!(
        "experiments done in {:.1} s: {} pre-sliding points, {} sliding points, {} lag samples",
        started.elapsed().as_secs_f64(),
        g.presliding.len(),
        g.sliding.len(),
        g.lag.as_ref().map_or(0, |l| l.0.len())
    );
    if a.json {
        let v = serde_json::json!({
            "friction": id.spec,
            "report": id.report,
            "file": a.out.display().to_string(),
        });
        println!("{v}");
    } else {
        for l in &id.report {
            println!("{l}");
        }
        println!("{}", summary(&id.spec));
        println!(
            "wrote {} and the report in {}",
            a.out.display(),
            a.report.display()
        );
    }
    if a.apply || a.save {
        let n = crate::load(link, &a.out)?;
        eprintln!("loaded into the device ({n} parameters changed)");
        if a.save {
            link.ask(Command::Save)?;
            eprintln!("saved");
        }
    }
    Ok(())
}

/// The identified set in one readable line, in the device's units (motor side: N·m, rad).
pub fn summary(f: &gms_ident::paramfile::FrictionSpec) -> String {
    use gms_ident::units::si;
    let v = |x: Option<f64>, unit: &str| x.map_or("-".to_string(), |x| si(x, unit));
    let blocks = f.blocks.as_ref().map_or(0, Vec::len);
    let k0: f64 = f.blocks.iter().flatten().map(|b| b.k).sum();
    format!(
        "identified: Fs {}, Fc {}, Vs {}, delta {}, sigma {}, C {}; {blocks} blocks, initial \
         stiffness {}, pre-sliding to {}",
        v(f.fs, "N·m"),
        v(f.fc, "N·m"),
        v(f.vs, "rad/s"),
        f.delta.map_or("-".to_string(), |d| format!("{d:.3}")),
        v(f.sigma, "N·m·s/rad"),
        v(f.c, "N·m/s"),
        si(k0, "N·m/rad"),
        si(f.largest_breakpoint(), "rad"),
    )
}
