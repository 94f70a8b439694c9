//! The default loop's margins over the plant variations issue 41 names — the friction's
//! pre-sliding stiffness ×0.5 and ×2, the inertia ±20 %, the friction ±15 % (its forces, its
//! damping and its stiffness together) — with the device's gains left at its defaults (the
//! device told the nominal axis). For each plant: the linear model's margins at rest and
//! sliding (`gms_ident::linear`), and with `--measure` the device's own measurement, as
//! `gms-tune frf --loop open --amplitude 0.02` (and `--velocity 3`) runs it, on the simulated
//! axis (margins from the points above the noise). Then the same for the compliant stages of
//! issue 41 (the screw's axial mode under a 2 kg and a 50 kg slide).
//!
//! With `--cur-hz 20000`, the same at another current-loop rate (`rate.cur_hz`, the way out for
//! a board whose control step is too long: docs/bring-up.md), its PI as commissioning sets it
//! (`gms_ident::gains::current_pi` on the plant's path resistance and inductance), the
//! position loop's gains the defaults.
//!
//! `cargo run --release -p hil-sim --example robustness [--measure] [--stages-only]
//! [--cur-hz HZ] [--real-bridge] [--nominal]` (`--real-bridge`: the plant's bridge the
//! DRV8871's, not the ideal one; `--nominal`: the nominal plant alone, and no stages)

use gms_bench::frf::{self, Loop, Plan};
use gms_bench::settings;
use gms_ident::linear::{LinearAxis, Operating};
use gms_ident::margins::Margins;
use hil_sim::device::LocalDevice;
use hil_sim::scenario::Scenario;
use num_complex::Complex64;

/// (pre-sliding stiffness, inertia, friction) factors.
const PLANTS: [(f64, f64, f64); 11] = [
    (1.0, 1.0, 1.0),
    (0.5, 1.0, 1.0),
    (2.0, 1.0, 1.0),
    (1.0, 0.8, 1.0),
    (1.0, 1.2, 1.0),
    (0.5, 0.8, 1.0),
    (0.5, 1.2, 1.0),
    (2.0, 0.8, 1.0),
    (2.0, 1.2, 1.0),
    (1.0, 1.0, 0.85),
    (1.0, 1.0, 1.15),
];

/// Compliant stages (the screw's axial mode under the slide): anti-resonance \[Hz\],
/// damping ratio, slide \[kg\] — `examples/scenarios/real-stage.toml`'s, the same screw under
/// 50 kg, and a stiff screw under 50 kg.
const STAGES: [(f64, f64, f64); 3] = [
    (700.0, 0.03, 2.0),
    (700.0, 0.03, 50.0),
    (3000.0, 0.01, 50.0),
];

/// The simulated axis with its friction's stiffness ×`kx`, inertia ×`jx`, friction ×`fx`
/// (no random draw).
fn plant(kx: f64, jx: f64, fx: f64) -> Result<Scenario, String> {
    // 40 substeps, as the scenario asks of a 3 kHz stage's mode.
    let mut sc = Scenario::parse("[plant]\nvariability = 0.0\nsubsteps = 40\n", "robustness")
        .map_err(|e| e.to_string())?;
    // `--real-bridge`: the DRV8871's dead time, delay and switches (the device told them, as
    // commissioning would: its defaults follow the scenario's bridge).
    sc.plant.bridge.ideal = !std::env::args().any(|a| a == "--real-bridge");
    // The device told the nominal inertia (its feedforward's), the plant another.
    let told = sc.plant.inertia;
    sc.plant.inertia *= jx;
    if let toml::Value::Table(t) = sc
        .controller
        .entry("ff")
        .or_insert_with(|| toml::Value::Table(toml::Table::new()))
    {
        t.insert("inertia".into(), toml::Value::Float(told));
    }
    for f in [&mut sc.plant.actuator, &mut sc.plant.guideway] {
        for v in [&mut f.fs, &mut f.fc, &mut f.sigma, &mut f.c]
            .into_iter()
            .flatten()
        {
            *v *= fx;
        }
        for b in f.blocks.iter_mut().flatten() {
            b.k *= kx * fx;
        }
    }
    if let Some(hz) = cur_hz() {
        let (kp, ki) =
            gms_ident::gains::current_pi(sc.plant.path_resistance(), sc.plant.inductance, hz);
        for (table, key, v) in [("rate", "cur_hz", hz), ("cur", "kp", kp), ("cur", "ki", ki)] {
            if let toml::Value::Table(t) = sc
                .controller
                .entry(table)
                .or_insert_with(|| toml::Value::Table(toml::Table::new()))
            {
                t.insert(key.into(), toml::Value::Float(v));
            }
        }
    }
    Ok(sc)
}

/// `--cur-hz HZ`: the current loop's rate, none for the default.
fn cur_hz() -> Option<f64> {
    let args: Vec<String> = std::env::args().collect();
    let at = args.iter().position(|a| a == "--cur-hz")?;
    args.get(at + 1)?.parse().ok()
}

/// The model's margins of the open loop, 10 Hz-4.4 kHz.
fn model(lin: &LinearAxis) -> Margins {
    let l: Vec<(f64, Complex64)> = (0..2000)
        .map(|i| {
            let f = 10.0 * (440.0f64).powf(i as f64 / 1999.0);
            let z = lin.open_loop(f);
            (f, Complex64::new(z.re, z.im))
        })
        .collect();
    gms_ident::margins::margins(&l)
}

/// The model's margins of the device's loop on `sc`'s axis, at rest and sliding.
fn models(sc: &Scenario) -> Result<(Margins, Margins), String> {
    let mut dev = LocalDevice::new(sc)?;
    let ss = dev.plant().small_signal();
    let s = settings::read(&mut dev).map_err(|e| e.to_string())?;
    let at = |op| {
        LinearAxis::new(&ss, &s, op)
            .map(|lin| model(&lin))
            .map_err(|e| e.to_string())
    };
    Ok((at(Operating::Rest)?, at(Operating::Sliding)?))
}

/// The device's measurement of its open loop (at rest, or sliding at `velocity`): the
/// margins of its points above the noise, and how many there were of how many.
fn measure(sc: &Scenario, velocity: Option<f64>) -> Result<(Margins, usize, usize), String> {
    let mut dev = LocalDevice::new(sc)?;
    measure_on(&mut dev, velocity)
}

/// [`measure`] on a device as it is set.
fn measure_on(
    dev: &mut LocalDevice,
    velocity: Option<f64>,
) -> Result<(Margins, usize, usize), String> {
    let mut plan = Plan::new(Loop::Open, 0.02);
    plan.velocity = velocity;
    let mut pts = Vec::new();
    let sweep = frf::run(dev, &plan, &mut pts, |_, _| {}).map_err(|e| e.to_string())?;
    let good: Vec<(f64, Complex64)> = sweep
        .points
        .iter()
        .filter(|p| p.coherence >= frf::MIN_COHERENCE)
        .map(|p| (p.f_hz, p.value))
        .collect();
    Ok((
        gms_ident::margins::margins(&good),
        good.len(),
        sweep.points.len(),
    ))
}

fn cell(m: &Margins) -> String {
    format!("{:.1}° / {:.1} dB", m.phase_margin_deg, m.gain_margin_db)
}

fn main() -> Result<(), String> {
    let measuring = std::env::args().any(|a| a == "--measure");
    // The compliant stages alone (their measurement is the long part).
    let stages_only = std::env::args().any(|a| a == "--stages-only");
    println!(
        "| Σk | J | friction | rest, model | sliding, model |{}",
        if measuring {
            " rest, measured | sliding (3 rad/s), measured |"
        } else {
            ""
        }
    );
    println!(
        "|---|---|---|---|---|{}",
        if measuring { "---|---|" } else { "" }
    );
    let mut worst: Option<(f64, String)> = None;
    // `--nominal`: the nominal plant alone.
    let nominal = std::env::args().any(|a| a == "--nominal");
    let plants = if nominal { &PLANTS[..1] } else { &PLANTS[..] };
    for (kx, jx, fx) in plants.iter().copied().filter(|_| !stages_only) {
        let sc = plant(kx, jx, fx)?;
        let (rest, slide) = models(&sc)?;
        let name = format!("×{kx} | ×{jx} | ×{fx}");
        for (what, m) in [("rest", &rest), ("sliding", &slide)] {
            // The least of PM/45° and GM/8 dB: the aim.
            let score = (m.phase_margin_deg / 45.0).min(m.gain_margin_db / 8.0);
            if worst.as_ref().is_none_or(|w| score < w.0) {
                worst = Some((score, format!("{name} {what}: {}", cell(m))));
            }
        }
        let mut line = format!("| {name} | {} | {} |", cell(&rest), cell(&slide));
        if measuring {
            for v in [None, Some(3.0)] {
                let (m, n, of) = measure(&sc, v)?;
                line += &format!(" {} ({n}/{of} coherent) |", cell(&m));
            }
        }
        println!("{line}");
    }
    if let Some((_, w)) = worst {
        println!("worst (the model's, against 45° and 8 dB): {w}");
    }
    if nominal {
        return Ok(());
    }
    println!();
    println!(
        "| stage | rest, model | sliding, model |{}",
        if measuring {
            " rest, measured | sliding (3 rad/s), measured |"
        } else {
            ""
        }
    );
    println!("|---|---|---|{}", if measuring { "---|---|" } else { "" });
    for (f_hz, zeta, kg) in STAGES {
        let mut sc = plant(1.0, 1.0, 1.0)?;
        sc.plant.compliance.f_hz = f_hz;
        sc.plant.compliance.zeta = zeta;
        sc.plant.compliance.slide_mass = kg;
        let (rest, slide) = models(&sc)?;
        let mut line = format!(
            "| {f_hz} Hz, ζ {zeta}, {kg} kg | {} | {} |",
            cell(&rest),
            cell(&slide)
        );
        if measuring {
            let mut short = false;
            for v in [None, Some(3.0)] {
                line += &match measure(&sc, v) {
                    Ok((m, n, of)) => {
                        short |= m.phase_margin_deg < 40.0 || m.gain_margin_db < 6.0;
                        format!(" {} ({n}/{of} coherent) |", cell(&m))
                    }
                    Err(e) => {
                        short = true;
                        format!(" {e} |")
                    }
                };
            }
            if short {
                line += &with_notch(&sc)?;
            }
        }
        println!("{line}");
    }
    Ok(())
}

/// Under the floor: the notch `gms-tune frf --loop open --suggest` would set (from a sliding
/// sweep of 0.003 A, 100 Hz-4.4 kHz), set, and the loop measured again at rest and sliding.
fn with_notch(sc: &Scenario) -> Result<String, String> {
    let mut dev = LocalDevice::new(sc)?;
    let s = settings::read(&mut dev).map_err(|e| e.to_string())?;
    let mut plan = Plan::new(Loop::Open, 0.003);
    plan.velocity = Some(3.0);
    plan.from_hz = 100.0;
    plan.to_hz = 4400.0;
    let mut pts = Vec::new();
    let before = match frf::run(&mut dev, &plan, &mut pts, |_, _| {}) {
        Ok(b) => b,
        Err(e) => return Ok(format!(" no notch: {e} |")),
    };
    let sug = match frf::suggest_notch(&before.points, &s.shaping, s.pos_rate_hz as f64) {
        Ok(g) => g,
        Err(e) => return Ok(format!(" no notch: {e} |")),
    };
    settings::apply(&mut dev, &sug.sets(), false).map_err(|e| e.to_string())?;
    let mut out = format!(
        " with a notch at {:.0} Hz (q {}, {} dB):",
        sug.notch.f_hz, sug.notch.q, sug.notch.depth_db
    );
    for v in [None, Some(3.0)] {
        out += &match measure_on(&mut dev, v) {
            Ok((m, n, of)) => format!(" {} ({n}/{of});", cell(&m)),
            Err(e) => format!(" {e};"),
        };
    }
    out.push_str(" |");
    Ok(out)
}
