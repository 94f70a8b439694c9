//! `gms-tune frf`: the frequency response of the plant, the open loop or the closed loop
//! (`gms_bench::frf`: a stepped-sine sweep of the device's own measurement), printed point by
//! point, written (`frf.csv`, `bode.svg`, `margins.toml`), and for the open loop a notch
//! proposed for the largest resonance above the crossover (`--suggest`) and set (`--apply`).

use std::path::PathBuf;

use gms_bench::frf::{Loop, MIN_COHERENCE, Plan, Point, Suggestion, Sweep, suggest_notch};
use gms_tune::Link;
use gms_tune::jobs;

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
    let dev = |e: gms_ident::Error| Fail::Device(e.to_string());
    let i_max = gms_bench::get_param(link, "lim.i_max").map_err(dev)?;
    let rpc = gms_bench::rad_per_count(link).map_err(dev)?;
    let pos_hz = gms_bench::get_param(link, "rate.pos_hz").map_err(dev)?;
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
        Err(gms_ident::Error::Io(m)) => return Err(Fail::Usage(m)),
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

/// The readable result: margins, pre-sliding stiffness, the notch proposed.
pub fn summary(s: &Sweep, sug: Option<&Suggestion>) -> Vec<String> {
    let mut out = Vec::new();
    let good = s
        .points
        .iter()
        .filter(|p| p.coherence >= MIN_COHERENCE)
        .count();
    out.push(format!(
        "{good} of {} points above the noise (coherence ≥ {MIN_COHERENCE})",
        s.points.len()
    ));
    if let Some(m) = &s.margins {
        out.push(format!(
            "crossover {:.1} Hz; phase margin {:.1}° (at {:.0} Hz); gain margin {:.2} dB (at {:.0} Hz); peak sensitivity {:.2} dB (at {:.0} Hz)",
            m.crossover_hz,
            m.phase_margin_deg,
            m.phase_margin_hz,
            m.gain_margin_db,
            m.gain_margin_hz,
            m.peak_sensitivity_db,
            m.peak_sensitivity_hz
        ));
        if m.phase_margin_deg < 30.0 {
            out.push(format!(
                "warning: the phase margin {:.1}° is under 30°: the loop rings (--suggest \
                 proposes a notch; or lower pos.kp/pos.kd)",
                m.phase_margin_deg
            ));
        }
    }
    if let Some((k, j)) = s.presliding {
        out.push(format!(
            "pre-sliding stiffness {k:.4} N·m/rad (inertia {j:.3e} kg·m²); the device's GMS \
             model: Σk = {:.4} N·m/rad ({:+.1} %). At this amplitude; a larger one slips the \
             stiffest blocks and reads softer.",
            s.model_stiffness,
            100.0 * (k / s.model_stiffness - 1.0)
        ));
    }
    if let Some(g) = sug {
        out.push(format!(
            "resonance at {:.1} Hz ({:+.1} dB): notch {} at {:.1} Hz, q {}, {} dB deep",
            g.resonance.0,
            g.resonance.1,
            g.slot + 1,
            g.notch.f_hz,
            g.notch.q,
            g.notch.depth_db
        ));
        out.push(format!(
            "with it: phase margin {:.1}° (was {:.1}°), gain margin {:.2} dB (was {:.2} dB), \
             peak sensitivity {:.2} dB (was {:.2} dB)",
            g.after.phase_margin_deg,
            g.before.phase_margin_deg,
            g.after.gain_margin_db,
            g.before.gain_margin_db,
            g.after.peak_sensitivity_db,
            g.before.peak_sensitivity_db
        ));
    }
    out
}

fn num(x: f64) -> serde_json::Value {
    serde_json::Number::from_f64(x).map_or(serde_json::Value::Null, serde_json::Value::Number)
}

fn margins_json(m: &gms_bench::frf::Margins) -> serde_json::Value {
    serde_json::json!({
        "gain_margin_db": num(m.gain_margin_db),
        "gain_margin_hz": num(m.gain_margin_hz),
        "phase_margin_deg": num(m.phase_margin_deg),
        "phase_margin_hz": num(m.phase_margin_hz),
        "crossover_hz": num(m.crossover_hz),
        "peak_sensitivity_db": num(m.peak_sensitivity_db),
        "peak_sensitivity_hz": num(m.peak_sensitivity_hz),
    })
}

/// The result as JSON: the points, the margins, the pre-sliding fit, the notch proposed
/// (non-finite values as null).
pub fn json(s: &Sweep, sug: Option<&Suggestion>) -> serde_json::Value {
    serde_json::json!({
        "loop": s.plan.lp.name(),
        "points": s.points.iter().map(|p| serde_json::json!({
            "f_hz": num(p.f_hz),
            "gain_db": num(p.gain_db()),
            "phase_deg": num(p.phase_deg()),
            "coherence": num(p.coherence),
        })).collect::<Vec<_>>(),
        "margins": s.margins.as_ref().map(margins_json),
        "presliding": s.presliding.map(|(k, j)| serde_json::json!({
            "stiffness": num(k), "inertia": num(j), "model_stiffness": num(s.model_stiffness),
        })),
        "suggestion": sug.map(|g| serde_json::json!({
            "slot": g.slot + 1,
            "f_hz": num(g.notch.f_hz as f64),
            "q": num(g.notch.q as f64),
            "depth_db": num(g.notch.depth_db as f64),
            "before": margins_json(&g.before),
            "after": margins_json(&g.after),
        })),
    })
}
