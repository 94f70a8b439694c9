//! `gms-tune tune-ff`: the feedforward gain by experiment (`gms_ident::bench::tune_ff`, the
//! same sine test with reversals at each gain), printed, written (CSV and plot), and applied
//! or saved on request.

use std::path::PathBuf;

use gms_ident::bench::{TuneFfPlan, tune_ff};
use gms_tune::Link;

use crate::Fail;
use crate::tracked::{Bar, ctrl_c};
use gms_tune::run::RunBench;

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
}

/// Runs the sweep; prints the curve and the choice; writes the files; applies or saves.
pub fn run(link: &mut Link, a: &Args) -> Result<(), Fail> {
    a.plan.check().map_err(|e| Fail::Usage(e.to_string()))?;
    std::fs::create_dir_all(&a.out)
        .map_err(|e| Fail::Usage(format!("{}: cannot create: {e}", a.out.display())))?;
    let rpc = 3.8e-6;
    eprintln!(
        "sine test {} rad at {} Hz for {} s, ff.gain {} to {} in {} steps: about {:.0} s of device time",
        a.plan.amp,
        a.plan.freq,
        a.plan.seconds,
        a.plan.from,
        a.plan.to,
        a.plan.steps,
        a.plan.steps as f64 * (a.plan.seconds + 0.2)
    );
    println!("ff.gain  RMS error [rad]  [counts of 3.8 µrad]");
    let mut bar = Bar::new();
    let mut bench = RunBench::new(link, ctrl_c(), "interrupted (Ctrl-C)", &mut bar);
    bench.stage("tune-ff", a.plan.steps as f64 * a.plan.seconds);
    let r = tune_ff(&mut bench, &a.plan, |_, g, rms| {
        println!("{g:7.4}  {rms:.4e}  {:.3}", rms / rpc)
    });
    let link = bench.link;
    bar.bar.finish_and_clear();
    let t = r.map_err(|e| Fail::Device(format!("{e}; the bridge is off, ff.gain as it was")))?;
    println!("chosen ff.gain {:.4} (was {})", t.chosen, t.before);
    let mut csv = String::from("gain,rms\n");
    for (g, r) in &t.curve {
        csv += &format!("{g},{r}\n");
    }
    gms_ident::io::write_atomic(&a.out.join("curve.csv"), csv.as_bytes())
        .map_err(|e| Fail::Usage(e.to_string()))?;
    let pts: Vec<(f64, f64)> = t.curve.iter().map(|(g, r)| (*g, r / rpc)).collect();
    let (lo, hi) = pts
        .iter()
        .fold((f64::MAX, f64::MIN), |(l, h), p| (l.min(p.1), h.max(p.1)));
    let marker = vec![(t.chosen, lo), (t.chosen, hi)];
    gms_ident::plot::fit_plot(
        &a.out.join("curve.svg"),
        &format!(
            "tune-ff: sine RMS error against ff.gain; chosen {:.4}",
            t.chosen
        ),
        ("ff.gain [-]", "RMS error [counts]"),
        &pts,
        &marker,
    )
    .map_err(Fail::Usage)?;
    println!("wrote {}/curve.csv and curve.svg", a.out.display());
    if a.apply || a.save {
        link.request(&format!("set ff.gain {}", t.chosen))?;
        println!("set ff.gain {:.4}", t.chosen);
        if a.save {
            link.request("disable")?;
            link.request("save")?;
            println!("saved");
        }
    }
    Ok(())
}
