//! `gms-tune learn`: learning from repetition (`gms_bench::learn`): the motion played from
//! the device's tables, the correction learned after each period, a line per iteration, the
//! files written, the correction left playing on request.

use std::path::PathBuf;

use gms_bench::learn::LearnPlan;
use gms_tune::Link;
use gms_tune::jobs;

use crate::Fail;
use crate::tracked::{Bar, ctrl_c};

/// What `gms-tune learn` is asked.
pub struct Args {
    /// The motion and the learning.
    pub plan: LearnPlan,
    /// The directory written.
    pub out: PathBuf,
    /// Leave the learned correction playing for the next runs.
    pub apply: bool,
}

/// Learns, writes, applies.
pub fn run(link: &mut Link, a: &Args) -> Result<(), Fail> {
    a.plan.check().map_err(|e| Fail::Usage(e.to_string()))?;
    let what = match &a.plan.path {
        gms_bench::learn::Path::Sine { amplitude, freq } => {
            format!("a sine of {amplitude} rad at {freq} Hz (x = A (1 − cos 2πft))")
        }
        gms_bench::learn::Path::Trajectory(rows) => format!(
            "a trajectory of {} rows over {} s",
            rows.len(),
            rows.last().map_or(0.0, |r| r.0)
        ),
    };
    eprintln!(
        "learn: {what}; {} iterations, gain {}, Q {} Hz, lead {} s",
        a.plan.iterations, a.plan.gain, a.plan.q_hz, a.plan.lead_s
    );
    let mut bar = Bar::new();
    let mut ctl = jobs::Control {
        stop: ctrl_c(),
        why: "interrupted (Ctrl-C)",
        hooks: &mut bar,
    };
    println!("iteration  RMS [counts]  peak [counts]");
    let mut each = |it: &gms_bench::ilc::Iteration| {
        println!("{:9}  {:12.3}  {:13.2}", it.n, it.rms, it.peak);
    };
    let r = jobs::learn(link, &a.plan, Some(&a.out), a.apply, &mut ctl, &mut each);
    bar.bar.finish_and_clear();
    let l = match r {
        Ok(l) => l,
        Err(gms_bench::Error::Io(m)) => return Err(Fail::Usage(m)),
        Err(e) => {
            // Refused before anything moved, or stopped with the bridge off: the device says.
            let on = gms_bench::status(link).is_ok_and(|s| s.enabled);
            let state = if on {
                "the axis holds where it was"
            } else {
                "the bridge is off"
            };
            return Err(Fail::Device(format!("{e}; {state}")));
        }
    };
    if let Some(stop) = l.stopped {
        println!("stopped: {stop:?} (the error grew); the best correction kept");
    }
    let best = l
        .iterations
        .iter()
        .min_by(|a, b| a.rms.total_cmp(&b.rms))
        .copied();
    if let (Some(first), Some(last), Some(best)) = (l.iterations.first(), l.iterations.last(), best)
    {
        println!(
            "RMS {:.3} → {:.3} counts (best {:.3} at iteration {}), peak {:.2} → {:.2} counts",
            first.rms, last.rms, best.rms, best.n, first.peak, last.peak
        );
    }
    if let Some(r) = l.repeat() {
        println!("{}", r.line());
    }
    println!(
        "wrote {}/iterations.csv, correction.csv, learning.svg",
        a.out.display()
    );
    if a.apply {
        println!("the best correction plays from the next table run (table run PERIODS)");
    }
    Ok(())
}
