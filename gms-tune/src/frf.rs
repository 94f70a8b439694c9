//! `gms-tune frf`: the frequency response of the plant, the open loop or the closed loop
//! (`gms_bench::frf`: a stepped-sine sweep of the device's own measurement), printed point by
//! point, written (`frf.csv`, `bode.svg`, `margins.toml`), and for the open loop a notch
//! proposed for the largest resonance above the crossover (`--suggest`) and set (`--apply`).

use gms_core::protocol::ParamId;
use std::path::PathBuf;

use gms_bench::frf::{Loop, MIN_COHERENCE, Plan, Point, suggest_notch};
use gms_tune::Link;
use gms_tune::jobs;
use gms_tune::run::{frf_json as json, frf_summary as summary};

use crate::Fail;
use crate::tracked::{Bar, ctrl_c};

/// What `gms-tune frf` is asked.
pub struct Args {
    /// The sweep (its amplitude `None`: the default for the loop).
    pub plan: Plan,
    /// Amplitude given.
    pub amplitude: Option<f64>,
    /// Directory for the files.
    pub out: PathBuf,
    /// Propose a notch (open loop).
    pub suggest: bool,
    /// Set the proposed notch.
    pub apply: bool,
    /// JSON instead of the readable output.
    pub json: bool,
}

/// Runs the sweep, prints and writes it; proposes and applies a notch on request.
pub fn run(link: &mut Link, a: &Args) -> Result<(), Fail> {
    if (a.suggest || a.apply) && a.plan.lp != Loop::Open {
        return Err(Fail::Usage(
            "--suggest and --apply need --loop open (the margins are the open loop's)".into(),
        ));
    }
    let dev = |e: gms_bench::Error| Fail::Device(e.to_string());
    let i_max = gms_bench::get_param(link, ParamId::LimIMax).map_err(dev)?;
    let rpc = gms_bench::rad_per_count(link).map_err(dev)?;
    let pos_hz = gms_bench::get_param(link, ParamId::RatePosHz).map_err(dev)?;
    let mut plan = a.plan.clone();
    // By default 1 % of the current limit at the current command, 20 counts at the reference.
    plan.amplitude = a.amplitude.unwrap_or(match plan.lp {
        Loop::Closed => 20.0 * rpc,
        _ => 0.01 * i_max,
    });
    plan.check(pos_hz, i_max)
        .map_err(|e| Fail::Usage(e.to_string()))?;
    let unit = if plan.lp == Loop::Closed { "rad" } else { "A" };
    eprintln!(
        "frf --loop {}: {} points from {} to {} Hz, amplitude {} {unit}{}, about {:.0} s of \
         device time",
        plan.lp.name(),
        plan.points,
        plan.from_hz,
        plan.to_hz,
        plan.amplitude,
        match plan.velocity {
            Some(v) => format!(", sliding at {v} rad/s"),
            None => ", at rest".into(),
        },
        plan.device_seconds()
    );
    if !a.json {
        println!("    f [Hz]   gain [dB]  phase [deg]  coherence");
    }
    let quiet = a.json;
    let mut bar = Bar::new();
    let mut ctl = jobs::Control {
        stop: ctrl_c(),
        why: "interrupted (Ctrl-C)",
        hooks: &mut bar,
    };
    let r = jobs::frf(link, &plan, Some(&a.out), &mut ctl, &mut |_, p: &Point| {
        if !quiet {
            println!(
                "{:10.1}  {:10.2}  {:11.2}  {:9.4}{}",
                p.f_hz,
                p.gain_db(),
                p.phase_deg(),
                p.coherence,
                if p.coherence < MIN_COHERENCE {
                    "  below the noise"
                } else {
                    ""
                }
            )
        }
    });
    bar.bar.finish_and_clear();
    let sweep = match r {
        Ok(s) => s,
        Err(gms_bench::Error::Io(m)) => return Err(Fail::Usage(m)),
        Err(e) => {
            return Err(Fail::Device(format!(
                "{e}; the bridge is off, the settings as they were"
            )));
        }
    };
    let suggestion = if a.suggest || a.apply {
        let settings = gms_bench::settings::read(link).map_err(dev)?;
        Some(suggest_notch(&sweep.points, &settings.shaping, pos_hz).map_err(Fail::Device)?)
    } else {
        None
    };
    if a.json {
        println!("{}", json(&sweep, suggestion.as_ref()));
    } else {
        for l in summary(&sweep, suggestion.as_ref()) {
            println!("{l}");
        }
        println!(
            "wrote {}/frf.csv, bode.svg{}",
            a.out.display(),
            if sweep.margins.is_some() {
                ", margins.toml"
            } else {
                ""
            }
        );
    }
    if a.apply
        && let Some(s) = &suggestion
    {
        let sets = s.sets();
        gms_bench::settings::apply(link, &sets, false).map_err(dev)?;
        if !a.json {
            let text: Vec<String> = sets.iter().map(|(k, v)| format!("{k} {v}")).collect();
            println!(
                "set {} (measure again: gms-tune frf --loop open)",
                text.join(", ")
            );
        }
    }
    Ok(())
}
