//! `gms-tune tune-ff`: the feedforward gain by experiment (`gms_bench::tune_ff`: a
//! coarse sweep of the sine test with reversals, widened at an edge, then a repeated
//! refinement around the optimum, fitted with its uncertainty), printed, written (CSV and
//! plot), and applied or saved on request.

use gms_core::protocol::Command;
use std::path::PathBuf;

use gms_bench::{TUNE_FF_FLAT_SE, TuneFfPlan};
use gms_tune::Link;
use gms_tune::run::{tune_ff_json, tune_ff_summary};

use crate::Fail;
use crate::tracked::{Bar, ctrl_c};
use gms_tune::jobs;

/// What `gms-tune tune-ff` is asked.
pub struct Args {
    /// The sweep.
    pub plan: TuneFfPlan,
    /// Directory for `curve.csv` and `curve.svg`.
    pub out: PathBuf,
    /// Set the chosen gain.
    pub apply: bool,
    /// And save it.
    pub save: bool,
    /// Set the fitted optimum even when the curve is too flat to choose.
    pub force: bool,
    /// Print JSON instead of the readable summary.
    pub json: bool,
}

/// Runs the tuning; prints the plan, each test and the result; writes the files; applies or
/// saves.
pub fn run(link: &mut Link, a: &Args) -> Result<(), Fail> {
    a.plan.check().map_err(|e| Fail::Usage(e.to_string()))?;
    std::fs::create_dir_all(&a.out)
        .map_err(|e| Fail::Usage(format!("{}: cannot create: {e}", a.out.display())))?;
    let (tests, seconds) = a.plan.tests();
    eprintln!(
        "sine test {} mrad at {} Hz for {} s; ff.gain {} to {} in {} steps, then {} gains × {} \
         around the optimum: {tests} tests, about {seconds:.0} s of device time (more if the \
         range is widened)",
        a.plan.amp * 1e3,
        a.plan.freq,
        a.plan.seconds,
        a.plan.from,
        a.plan.to,
        a.plan.steps,
        a.plan.fine_steps,
        a.plan.repeats,
    );
    if !a.json {
        println!("test  ff.gain  RMS error [counts]");
    }
    let rpc = gms_bench::rad_per_count(link).map_err(|e| Fail::Device(e.to_string()))?;
    let mut bar = Bar::new();
    let quiet = a.json;
    let mut ctl = jobs::Control {
        stop: ctrl_c(),
        why: "interrupted (Ctrl-C)",
        hooks: &mut bar,
    };
    let r = jobs::tune_ff(link, &a.plan, Some(&a.out), &mut ctl, &mut |i, g, rms| {
        if !quiet {
            println!("{:4}  {g:7.3}  {:8.3}", i + 1, rms / rpc)
        }
    });
    bar.bar.finish_and_clear();
    let t = match r {
        Ok(t) => t,
        Err(gms_bench::Error::Io(m)) => return Err(Fail::Usage(m)),
        Err(e) => {
            return Err(Fail::Device(format!(
                "{e}; the bridge is off, ff.gain as it was"
            )));
        }
    };
    if a.json {
        println!("{}", tune_ff_json(&t));
    } else {
        for l in tune_ff_summary(&t) {
            println!("{l}");
        }
        println!("wrote {}/curve.csv and curve.svg", a.out.display());
    }
    if a.apply || a.save {
        let gain = match t.optimum {
            _ if t.decided => Some(t.chosen),
            Some(o) if a.force => Some(o.at.clamp(0.0, 2.0)),
            _ => None,
        };
        match gain {
            Some(g) => {
                // To the 3 decimals printed: the interval is a hundredth wide or more.
                let g = (g * 1e3).round() / 1e3;
                link.ask(Command::Set(
                    gms_core::protocol::ParamId::FfGain.path(),
                    &format!("{g}"),
                ))?;
                if !a.json {
                    println!("set ff.gain {g:.3}");
                }
                if a.save {
                    link.ask(Command::Disable)?;
                    link.ask(Command::Save)?;
                    if !a.json {
                        println!("saved");
                    }
                }
            }
            None => {
                return Err(Fail::Device(format!(
                    "nothing applied: no clear optimum (standard error over {TUNE_FF_FLAT_SE} \
                     or none); ff.gain stays {:.3} (--force sets the fitted one)",
                    t.before
                )));
            }
        }
    }
    Ok(())
}
