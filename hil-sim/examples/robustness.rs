//! The default loop's margins over the plant variations issue 41 names — the friction's
//! pre-sliding stiffness ×0.5 and ×2, the inertia ±20 %, the friction ±15 % (its forces, its
//! damping and its stiffness together) — with the device's gains left at its defaults (the
//! device told the nominal axis). For each plant: the linear model's margins at rest and
//! sliding (`gms_ident::linear`), and with `--measure` the device's own measurement, as
//! `gms-tune frf --loop open --amplitude 0.02` (and `--velocity 3`) runs it, on the simulated
//! axis (margins from the points above the noise).
//!
//! `cargo run --release -p hil-sim --example robustness [--measure]`

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

/// The simulated axis with its friction's stiffness ×`kx`, inertia ×`jx`, friction ×`fx`
/// (no random draw).
fn plant(kx: f64, jx: f64, fx: f64) -> Result<Scenario, String> {
    let mut sc =
        Scenario::parse("[plant]\nvariability = 0.0\n", "robustness").map_err(|e| e.to_string())?;
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
    Ok(sc)
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

/// The device's measurement of its open loop (at rest, or sliding at `velocity`): the
/// margins of its points above the noise, and how many there were of how many.
fn measure(sc: &Scenario, velocity: Option<f64>) -> Result<(Margins, usize, usize), String> {
    let mut dev = LocalDevice::new(sc)?;
    let mut plan = Plan::new(Loop::Open, 0.02);
    plan.velocity = velocity;
    let mut pts = Vec::new();
    let sweep = frf::run(&mut dev, &plan, &mut pts, |_, _| {}).map_err(|e| e.to_string())?;
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
    for (kx, jx, fx) in PLANTS {
        let sc = plant(kx, jx, fx)?;
        let mut dev = LocalDevice::new(&sc)?;
        let ss = dev.plant().small_signal();
        let s = settings::read(&mut dev).map_err(|e| e.to_string())?;
        let rest = model(&LinearAxis::new(&ss, &s, Operating::Rest).map_err(|e| e.to_string())?);
        let slide =
            model(&LinearAxis::new(&ss, &s, Operating::Sliding).map_err(|e| e.to_string())?);
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
    Ok(())
}
