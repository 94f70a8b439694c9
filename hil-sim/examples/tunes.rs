//! Issue 41's trade as a table of tunes: for each position tune on the default axis, the
//! linear model's margins (`gms_ident::gains::robust_margins`: at rest and sliding, on the
//! nominal plant and the least over the pre-sliding stiffness ×0.5…×2 and the inertia
//! ±20 %) beside the demo's precision (`hil-sim compare`'s run on the default scenario:
//! the median and 95th percentile over the friction draws of the sine's RMS error and the
//! reversal peak, GMS and adaptive GMS).
//!
//! `cargo run --release -p hil-sim --example tunes [RUNS]` (20 draws by default; `TUNES="a;b"`
//! runs only the tunes of those names). The
//! margins measured on the device itself (`gms-tune frf --loop open`) agree with the model's
//! within a few degrees and a dB (docs/results.md).

use gms_ident::gains::{Axis, SlidingCurve, robust_margins};
use hil_sim::commands;
use hil_sim::scenario::Scenario;

/// A tune: its name, `pos.kp` [N·m/rad], `pos.ki` [N·m/(rad·s)], `pos.kd` [N·m·s/rad],
/// `ff.gain` [-], `pos.ki_fric` [-].
type Tune = (&'static str, f64, f64, f64, f64, f64);

const TUNES: [Tune; 14] = [
    ("default", 0.49, 700.0, 2.45e-4, 0.94, 0.5),
    ("plain integral", 0.49, 700.0, 2.45e-4, 0.94, 0.0),
    ("ki_fric 0.25", 0.49, 700.0, 2.45e-4, 0.94, 0.25),
    ("ki_fric 1", 0.49, 700.0, 2.45e-4, 0.94, 1.0),
    ("ff 0.88", 0.49, 700.0, 2.45e-4, 0.88, 0.5),
    ("plain, ff 0.88", 0.49, 700.0, 2.45e-4, 0.88, 0.0),
    ("ki x1.25", 0.49, 875.0, 2.45e-4, 0.94, 0.0),
    ("ki x1.25, ff 0.88", 0.49, 875.0, 2.45e-4, 0.88, 0.0),
    ("ki x1.5", 0.49, 1050.0, 2.45e-4, 0.94, 0.0),
    ("ki x2", 0.49, 1400.0, 2.45e-4, 0.94, 0.0),
    ("kp 0.6", 0.6, 860.0, 2.45e-4, 0.94, 0.0),
    ("kp 0.6, ki x2", 0.6, 1720.0, 2.45e-4, 0.94, 0.0),
    ("20 kHz round's pos loop", 0.7, 600.0, 2.7e-4, 0.94, 0.0),
    ("kd 3e-4", 0.49, 700.0, 3.0e-4, 0.94, 0.0),
];

fn main() -> Result<(), String> {
    let runs: usize = std::env::args()
        .nth(1)
        .map(|a| a.parse().map_err(|_| format!("runs: not a number: {a}")))
        .transpose()?
        .unwrap_or(20);
    // The device's derivative filter (9 kHz, 0.45 of the position rate), as the rule sets it.
    let axis = Axis {
        d_filter_hz: 9000.0,
        ..Axis::default_motor()
    };
    let sigma = SlidingCurve::TABLE1.sigma;
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    println!(
        "| tune | kp | ki | kd | ff.gain | ki_fric | rest PM/GM (worst) | sliding PM/GM (worst) | GMS sine RMS | GMS \
         reversal | adaptive sine RMS | adaptive reversal |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|");
    let only: Option<Vec<String>> = std::env::var("TUNES")
        .ok()
        .map(|v| v.split(';').map(str::to_string).collect());
    for (name, kp, ki, kd, ff, share) in TUNES {
        if only.as_ref().is_some_and(|o| !o.iter().any(|n| n == name)) {
            continue;
        }
        let (nom, worst) = robust_margins(&axis, sigma, kp, ki, kd)
            .ok_or_else(|| format!("{name}: no linear model"))?;
        let mut sc = Scenario::default();
        let mut pos = toml::Table::new();
        pos.insert("kp".into(), toml::Value::Float(kp));
        pos.insert("ki".into(), toml::Value::Float(ki));
        pos.insert("kd".into(), toml::Value::Float(kd));
        pos.insert("ki_fric".into(), toml::Value::Float(share));
        sc.controller.insert("pos".into(), toml::Value::Table(pos));
        let ff_table = sc
            .controller
            .entry("ff")
            .or_insert_with(|| toml::Value::Table(toml::Table::new()));
        if let toml::Value::Table(t) = ff_table {
            t.insert("gain".into(), toml::Value::Float(ff));
        }
        let (cmp, _) = commands::compare(&sc, runs, 1, threads, false)?;
        // In counts (the comparison holds radians).
        let c = sc.plant.rad_per_count;
        let cell = |mode: &str, metric: &str| {
            cmp.modes
                .get(mode)
                .and_then(|m| m.get(metric))
                .map_or("-".to_string(), |s| {
                    format!("{:.3} [{:.3}]", s.median / c, s.p95 / c)
                })
        };
        println!(
            "| {name} | {kp} | {ki} | {kd:e} | {ff} | {share} | {:.1}°/{:.1} dB ({:.1}°/{:.1} dB) | {:.1}°/{:.1} dB \
             ({:.1}°/{:.1} dB) | {} | {} | {} | {} |",
            nom.rest.0,
            nom.rest.1,
            worst.rest.0,
            worst.rest.1,
            nom.sliding.0,
            nom.sliding.1,
            worst.sliding.0,
            worst.sliding.1,
            cell("gms", "sine_rms_error"),
            cell("gms", "reversal_error"),
            cell("gms-adaptive", "sine_rms_error"),
            cell("gms-adaptive", "reversal_error"),
        );
    }
    Ok(())
}
