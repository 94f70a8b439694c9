//! Frequency response on the virtual device, against the simulator's own linear model
//! (`hil_sim::linear`, from the plant's and the controller's equations): the plant at rest and
//! sliding, a compliant stage's anti-resonance, the open loop's margins.

use gms_bench::frf::{self, Loop, Plan, Point};
use gms_bench::{Bench, settings};
use hil_sim::device::LocalDevice;
use hil_sim::linear::{LinearAxis, Operating};
use hil_sim::scenario::Scenario;

/// The default scenario with `extra` keys in `[plant]` and the tables `tables` after it, the
/// plant's draw off (the truth is nominal).
fn scenario(extra: &str, tables: &str) -> Scenario {
    Scenario::parse(
        &format!("[plant]\nvariability = 0.0\n{extra}\n{tables}"),
        "frf",
    )
    .unwrap()
}

fn sweep(dev: &mut LocalDevice, plan: &Plan) -> Vec<Point> {
    let mut pts = Vec::new();
    dev.request("enable").unwrap();
    dev.wait(0.2).unwrap();
    frf::sweep(dev, plan, &mut pts, |_, _| {}).unwrap();
    pts
}

fn report(pts: &[Point], model: impl Fn(f64) -> nalgebra::Complex<f64>) -> (f64, f64) {
    let (mut worst_db, mut worst_deg) = (0.0f64, 0.0f64);
    for p in pts {
        let m = model(p.f_hz);
        let m = num_complex::Complex64::new(m.re, m.im);
        let d_db = p.gain_db() - frf::db(m);
        let d_deg = (p.value / m).arg().to_degrees();
        println!(
            "{:8.1} Hz  {:8.2} dB {:8.2}°  model {:8.2} dB {:8.2}°  Δ {:6.2} dB {:6.2}°  coh {:.4}",
            p.f_hz,
            p.gain_db(),
            p.phase_deg(),
            frf::db(m),
            m.arg().to_degrees(),
            d_db,
            d_deg,
            p.coherence
        );
        worst_db = worst_db.max(d_db.abs());
        worst_deg = worst_deg.max(d_deg.abs());
    }
    (worst_db, worst_deg)
}

#[test]
fn the_plant_at_rest_is_the_linear_model() {
    let sc = scenario("", "");
    let mut dev = LocalDevice::new(&sc).unwrap();
    let s = settings::read(&mut dev).unwrap();
    let amp: f64 = std::env::var("AMP").ok().and_then(|v| v.parse().ok()).unwrap_or(0.01);
    let mut plan = Plan::new(Loop::Plant, amp);
    plan.points = std::env::var("PTS").ok().and_then(|v| v.parse().ok()).unwrap_or(20);
    plan.from_hz = std::env::var("FROM").ok().and_then(|v| v.parse().ok()).unwrap_or(10.0);
    plan.to_hz = std::env::var("TO").ok().and_then(|v| v.parse().ok()).unwrap_or(3000.0);
    let pts = sweep(&mut dev, &plan);
    let lin = LinearAxis::new(&dev.plant().small_signal(), &s, Operating::Rest).unwrap();
    let (db, deg) = report(&pts, |f| lin.plant(f));
    println!("worst {db:.2} dB {deg:.2}°");
    panic!();
}
