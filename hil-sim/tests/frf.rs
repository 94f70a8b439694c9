//! Frequency response on the virtual device, against the simulator's own linear model
//! (`hil_sim::linear`, from the plant's and the controller's equations, told nothing of the
//! measurement): the plant at rest and sliding, a compliant stage's anti-resonance, the open
//! loop's margins, the pre-sliding stiffness. Run with `--nocapture` for the figures.

use gms_bench::frf::{self, Loop, Plan, Point};
use gms_bench::{Bench, settings};
use gms_ident::linear::{LinearAxis, Operating};
use hil_sim::device::LocalDevice;
use hil_sim::scenario::Scenario;
use num_complex::Complex64;

/// The default scenario with `extra` keys in `[plant]` and the tables `tables` after it, the
/// ideal bridge (the linear model's: the real bridge's dead time, a step of the voltage at
/// every zero crossing of the current, is not linear about rest; docs/results.md), the
/// plant's draw off (the truth is nominal) and 40 integration substeps: the plant's
/// semi-implicit Euler lags by half a substep (2.3° at 2.6 kHz with the default 10; 0.6° with
/// 40), which is the simulator's error, not the measurement's.
fn scenario(extra: &str, tables: &str) -> Scenario {
    Scenario::parse(
        &format!(
            "[plant]\nvariability = 0.0\nsubsteps = 40\n{extra}\n[plant.bridge]\nideal = true\n{tables}"
        ),
        "frf",
    )
    .unwrap()
}

/// Enables, lets the loop settle, sweeps.
fn sweep(dev: &mut LocalDevice, plan: &Plan) -> Vec<Point> {
    let mut pts = Vec::new();
    dev.console("enable").unwrap();
    dev.wait(0.2).unwrap();
    frf::sweep(dev, plan, &mut pts, |_, _| {}).unwrap();
    pts
}

/// The model's complex number as the bench's (the same `num_complex` type: a no-op kept
/// for clarity at the call sites).
fn c(z: Complex64) -> Complex64 {
    z
}

/// Prints the measured points beside the model's and returns the worst gain and phase
/// differences [dB, deg] over the points whose coherence is at least `min_coh`, and how many
/// those are.
fn compare(pts: &[Point], model: impl Fn(f64) -> Complex64, min_coh: f64) -> (f64, f64, usize) {
    let (mut worst_db, mut worst_deg, mut n) = (0.0f64, 0.0f64, 0);
    for p in pts {
        let m = model(p.f_hz);
        let d_db = p.gain_db() - frf::db(m);
        let d_deg = (p.value / m).arg().to_degrees();
        let used = p.coherence >= min_coh;
        println!(
            "{:8.1} Hz  {:8.2} dB {:8.2}°  model {:8.2} dB {:8.2}°  Δ {:6.2} dB {:6.2}°  coh {:.4}{}",
            p.f_hz,
            p.gain_db(),
            p.phase_deg(),
            frf::db(m),
            m.arg().to_degrees(),
            d_db,
            d_deg,
            p.coherence,
            if used { "" } else { "  (below the noise)" }
        );
        if used {
            worst_db = worst_db.max(d_db.abs());
            worst_deg = worst_deg.max(d_deg.abs());
            n += 1;
        }
    }
    (worst_db, worst_deg, n)
}

/// At rest the plant is the motor on its pre-sliding springs: with an excitation of 3 mA
/// (motion within the stiffest block's elastic range even at the resonance), the measured
/// response is the linear model's within 1 dB and 5° wherever it stands above the noise
/// (coherence ≥ 0.9) and the axis moves by 2 counts or more, over the bench's default sweep
/// (40 points, 10 Hz to 5 kHz), in under 60 s of device time; the low-frequency plant gives
/// the pre-sliding stiffness. (Below ~30 Hz the loop holds the axis to a fraction of a count
/// against the spring: the encoder's quantisation, which the linear model leaves out,
/// distorts those points by up to 2 dB and 7° while their coherence stays above 0.999.)
#[test]
fn the_plant_at_rest_is_the_linear_model_and_shows_the_presliding_spring() {
    let sc = scenario("", "");
    let mut dev = LocalDevice::new(&sc).unwrap();
    let s = settings::read(&mut dev).unwrap();
    let plan = Plan::new(Loop::Plant, 0.003);
    let t0 = dev.plant().t;
    let pts = sweep(&mut dev, &plan);
    let took = dev.plant().t - t0;
    let ss = dev.plant().small_signal();
    let lin = LinearAxis::new(&ss, &s, Operating::Rest).unwrap();
    let rpc = s.rad_per_count() as f64;
    let moved: Vec<Point> = pts
        .iter()
        .filter(|p| p.reply.phasors[3].norm() >= 2.0 * rpc)
        .cloned()
        .collect();
    let (db, deg, n) = compare(&moved, |f| c(lin.plant(f)), 0.9);
    println!(
        "at rest: {n} of {} points above the noise and moving 2 counts or more, worst {db:.2} dB {deg:.2}°; sweep {took:.1} s of device time (planned {:.1} s)",
        pts.len(),
        plan.device_seconds()
    );
    assert_eq!(pts.len(), 40);
    assert!(n >= 20, "{n} points above the noise");
    assert!(db <= 1.0 && deg <= 5.0, "{db} dB {deg}°");
    assert!(took < 60.0, "{took} s");
    // The pre-sliding spring: the fit's stiffness against the true frictions' Σk (the
    // actuator's blocks and the guideway's, reflected), its inertia against the plant's.
    let (k, j) = frf::presliding(&pts, s.motor.k_m as f64).expect("a fit");
    let k_true = ss.k_act + ss.k_gw;
    println!(
        "pre-sliding stiffness {k:.4} N·m/rad against Σk {k_true:.4} ({:+.2} %); inertia {j:.3e} against {:.3e} kg·m² ({:+.2} %)",
        100.0 * (k / k_true - 1.0),
        ss.j,
        100.0 * (j / ss.j - 1.0)
    );
    assert!((k / k_true - 1.0).abs() < 0.03, "{k} against {k_true}");
    // The inertia is the fit's curvature over the points below half the resonance, where J ω²
    // is at most a fifth of the spring: the default loop holds the axis to under two counts
    // below 100 Hz, and the count's distortion there reads it 5-7 % low (3 % with the earlier,
    // softer loop at 20 kHz).
    assert!((j / ss.j - 1.0).abs() < 0.08, "{j} against {}", ss.j);
}

/// Sliding at 3 rad/s (well above the actuator's Stribeck velocity: its friction is the
/// viscous term), the plant is the rigid-body line: the linear model within 1 dB and 5°
/// wherever the response stands above the noise (coherence ≥ 0.99).
#[test]
fn the_plant_sliding_is_the_rigid_body_line() {
    let sc = scenario("", "");
    let mut dev = LocalDevice::new(&sc).unwrap();
    let s = settings::read(&mut dev).unwrap();
    let mut plan = Plan::new(Loop::Plant, 0.01);
    plan.velocity = Some(3.0);
    let pts = sweep(&mut dev, &plan);
    let lin = LinearAxis::new(&dev.plant().small_signal(), &s, Operating::Sliding).unwrap();
    let (_, _, n) = compare(&pts, |f| c(lin.plant(f)), 0.99);
    // The 1 dB and 5° bound over the points clear of the noise (coherence 0.995 or more): at
    // its edge the estimate scatters with the noise (67.7 Hz, at coherence 0.992, read
    // 1.01 dB off).
    let (db, deg, n_sure) = compare(&pts, |f| c(lin.plant(f)), 0.995);
    println!(
        "sliding at 3 rad/s: {n} of {} points above the noise, worst {db:.2} dB {deg:.2}° over \
         the {n_sure} at coherence 0.995",
        pts.len()
    );
    // Below ~100 Hz the loop's gain (hundreds, on a free mass) leaves microamperes of the
    // injected 10 mA in the command, under the noise: the band above it is measured (104 to
    // 2593 Hz with the default 20 kHz loop, kp 0.7; from 85 Hz with the earlier kp 0.2).
    // (23 of 40, or 22 when the run's noise falls otherwise: the band's lowest point, at
    // its edge, comes and goes — seen when the speed's start moved by a step; the band's
    // coverage is the check below.)
    assert!(n >= 22, "{n} points above the noise");
    assert!(n_sure >= 20, "{n_sure} points at coherence 0.995");
    assert!(
        pts.iter()
            .filter(|p| p.f_hz > 100.0 && p.f_hz < 2300.0)
            .all(|p| p.coherence >= 0.99)
    );
    assert!(db <= 1.0 && deg <= 5.0, "{db} dB {deg}°");
    // No reversal during a point: the sine's speed stayed below the run's.
    for p in &pts {
        let v = p.reply.phasors[3].norm() * std::f64::consts::TAU * p.f_hz;
        assert!(v < 3.0, "{} Hz: {v} rad/s", p.f_hz);
    }
}

/// A compliant stage (the screw/nut's axial mode at 700 Hz under a 50 kg slide): sliding, the
/// plant relative to the rigid-body line dips at the anti-resonance, found within 3 % of
/// `[plant.compliance] f_hz`, and peaks at the resonance f √(J / J_m).
#[test]
fn a_compliant_stage_shows_its_anti_resonance() {
    let sc = scenario(
        "",
        "[plant.compliance]\nf_hz = 700.0\nzeta = 0.03\nslide_mass = 50.0\n",
    );
    let mut dev = LocalDevice::new(&sc).unwrap();
    let s = settings::read(&mut dev).unwrap();
    let mut plan = Plan::new(Loop::Plant, 0.003);
    plan.velocity = Some(3.0);
    plan.from_hz = 400.0;
    plan.to_hz = 1200.0;
    plan.points = 40;
    let pts = sweep(&mut dev, &plan);
    let ss = dev.plant().small_signal();
    let lin = LinearAxis::new(&ss, &s, Operating::Sliding).unwrap();
    let (db, deg, n) = compare(&pts, |f| c(lin.plant(f)), 0.99);
    let ext = frf::plant_extrema(&pts);
    let dip = ext.iter().find(|e| !e.peak).expect("a dip");
    let peak = ext.iter().find(|e| e.peak).expect("a peak");
    let (jm, _, _, _) = ss.two_mass.unwrap();
    let f_res = 700.0 * (ss.j / jm).sqrt();
    println!(
        "compliant stage: anti-resonance {:.1} Hz against 700 Hz ({:+.2} %, {:.1} dB deep); resonance {:.1} Hz against {f_res:.1} Hz ({:+.2} %); {n} points against the model: worst {db:.2} dB {deg:.2}°",
        dip.f_hz,
        100.0 * (dip.f_hz / 700.0 - 1.0),
        dip.prominence_db,
        peak.f_hz,
        100.0 * (peak.f_hz / f_res - 1.0)
    );
    assert!((dip.f_hz / 700.0 - 1.0).abs() < 0.03, "{dip:?}");
    assert!((peak.f_hz / f_res - 1.0).abs() < 0.03, "{peak:?}");
    assert!(n >= 36 && db <= 1.0 && deg <= 5.0, "{n} {db} {deg}");
}

/// The margins of the model's loop gain on a fine grid (2000 points, 10 Hz to 4.4 kHz).
fn model_margins(lin: &LinearAxis) -> frf::Margins {
    let l: Vec<(f64, Complex64)> = (0..2000)
        .map(|i| {
            let f = 10.0 * (440.0f64).powf(i as f64 / 1999.0);
            (f, c(lin.open_loop(f)))
        })
        .collect();
    frf::margins(&l)
}

/// The open loop at rest with the default gains: the measured loop gain is the model's, and
/// so are its margins (within 1 dB and 3°), from the points above the noise (coherence ≥
/// 0.99). The default loop's phase crosses −180° near 3.4 kHz, where 3 mA moves the axis by
/// under half a count: there the encoder's count hides the response (coherence under 0.3),
/// and the gain margin is the model's alone — the measurement must then end below it.
#[test]
fn the_open_loop_margins_are_the_models() {
    let sc = scenario("", "");
    let mut dev = LocalDevice::new(&sc).unwrap();
    let s = settings::read(&mut dev).unwrap();
    let plan = Plan::new(Loop::Open, 0.003);
    let pts = sweep(&mut dev, &plan);
    let lin = LinearAxis::new(&dev.plant().small_signal(), &s, Operating::Rest).unwrap();
    let (db, deg, n) = compare(&pts, |f| c(lin.open_loop(f)), 0.99);
    let coherent: Vec<(f64, Complex64)> = pts
        .iter()
        .filter(|p| p.coherence >= 0.99)
        .map(|p| (p.f_hz, p.value))
        .collect();
    let top = coherent.last().map_or(0.0, |p| p.0);
    let measured = frf::margins(&coherent);
    let model = model_margins(&lin);
    println!("open loop: {n} points, worst {db:.2} dB {deg:.2}°");
    println!("measured {measured:?}");
    println!("model    {model:?}");
    assert!(
        (measured.phase_margin_deg - model.phase_margin_deg).abs() <= 3.0,
        "phase margin"
    );
    if measured.gain_margin_db.is_finite() {
        assert!(
            (measured.gain_margin_db - model.gain_margin_db).abs() <= 1.0,
            "gain margin"
        );
    } else {
        assert!(
            model.gain_margin_hz > top,
            "{} Hz against {top} Hz",
            model.gain_margin_hz
        );
    }
    assert!(
        (measured.peak_sensitivity_db - model.peak_sensitivity_db).abs() <= 1.0,
        "peak sensitivity"
    );
    assert!((measured.crossover_hz / model.crossover_hz - 1.0).abs() <= 0.03);
}

/// The step's overshoot [counts] and the peak-to-peak ringing after the first 20 ms
/// [counts]: a move of `counts` from where the axis holds, recorded at the position rate.
fn step_overshoot(dev: &mut LocalDevice, counts: f64) -> (f64, f64) {
    let rpc = gms_bench::rad_per_count(dev).unwrap();
    dev.console("enable").unwrap();
    dev.wait(0.3).unwrap();
    let x0 = gms_bench::position(dev).unwrap();
    dev.capture("t,pos", 1, 1000, true).unwrap();
    dev.console(&format!("move {}", x0 + counts * rpc)).unwrap();
    dev.wait(0.12).unwrap();
    let rows = gms_bench::capture_rows(dev).unwrap();
    dev.console("disable").unwrap();
    // Positions relative to the trigger [counts].
    let pos: Vec<f64> = rows.iter().map(|r| r[1] / rpc).collect();
    let over = pos.iter().fold(f64::MIN, |a, p| a.max(*p)) - counts;
    let tail = &pos[200..];
    let (lo, hi) = tail
        .iter()
        .fold((f64::MAX, f64::MIN), |(a, b), p| (a.min(*p), b.max(*p)));
    (over, hi - lo)
}

/// A compliant stage on which a loop rings: a heavy slide (50 kg) on a stiff screw (the
/// axial mode's anti-resonance at 3 kHz, ζ 0.01; its resonance at 3.5 kHz), where a 10 kHz
/// loop with kp 0.2 over a 1 kHz current loop at 20 kHz (the device's defaults before the
/// 20 kHz tune) leaves under 2° of phase margin: the axis
/// rings at 3.4 kHz. The open loop
/// measured sliding (at rest the pre-sliding spring's own resonance near 700 Hz is in the
/// loop too); the notch `--suggest` proposes restores ≥ 30°, a measurement with it set
/// confirms the margins predicted, and a step rings less.
#[test]
fn the_suggested_notch_restores_the_phase_margin() {
    let sc = scenario(
        "",
        "[plant.compliance]\nf_hz = 3000.0\nzeta = 0.01\nslide_mass = 50.0\n\
         [controller.rate]\npos_hz = 10000.0\ncur_hz = 20000.0\n\
         [controller.cur]\nkp = 1.5\nki = 6e4\n\
         [controller.pos]\nkp = 0.2\nki = 100.0\nkd = 2.5e-4\nd_filter_hz = 2000.0\n",
    );
    let mut dev = LocalDevice::new(&sc).unwrap();
    let s = settings::read(&mut dev).unwrap();
    let (over0, ring0) = step_overshoot(&mut dev, 200.0);
    let mut plan = Plan::new(Loop::Open, 0.003);
    plan.velocity = Some(3.0);
    plan.from_hz = 100.0;
    plan.to_hz = 4400.0;
    let mut pts = Vec::new();
    let before = frf::run(&mut dev, &plan, &mut pts, |_, _| {}).unwrap();
    let sug = frf::suggest_notch(&before.points, &s.shaping, s.pos_rate_hz as f64).unwrap();
    gms_bench::settings::apply(&mut dev, &sug.sets(), false).unwrap();
    let mut pts = Vec::new();
    let after = frf::run(&mut dev, &plan, &mut pts, |_, _| {}).unwrap();
    let (m0, m1) = (before.margins.unwrap(), after.margins.unwrap());
    let (over1, ring1) = step_overshoot(&mut dev, 200.0);
    println!(
        "notch {} at {:.1} Hz, q {}, {} dB for the resonance at {:.1} Hz ({:+.1} dB)",
        sug.slot + 1,
        sug.notch.f_hz,
        sug.notch.q,
        sug.notch.depth_db,
        sug.resonance.0,
        sug.resonance.1
    );
    println!(
        "phase margin {:.1}° → predicted {:.1}°, measured {:.1}°; gain margin {:.2} → {:.2} / {:.2} dB; peak sensitivity {:.2} → {:.2} / {:.2} dB",
        m0.phase_margin_deg,
        sug.after.phase_margin_deg,
        m1.phase_margin_deg,
        m0.gain_margin_db,
        sug.after.gain_margin_db,
        m1.gain_margin_db,
        m0.peak_sensitivity_db,
        sug.after.peak_sensitivity_db,
        m1.peak_sensitivity_db
    );
    println!(
        "200-count step: overshoot {over0:.1} → {over1:.1} counts, ringing after 20 ms {ring0:.1} → {ring1:.1} counts peak to peak"
    );
    assert!(m0.phase_margin_deg < 30.0);
    assert!(m1.phase_margin_deg >= 30.0, "{m1:?}");
    assert!((m1.phase_margin_deg - sug.after.phase_margin_deg).abs() < 5.0);
    assert!(
        over1 < over0 && ring1 < ring0,
        "{over0} {over1} {ring0} {ring1}"
    );
}

/// A measurement ends with `disable` and with a lost link (the position loop holding on), and
/// what it summed stands; it is refused in current mode.
#[test]
fn disable_and_a_lost_link_end_a_measurement() {
    let sc = scenario("", "");
    let mut dev = LocalDevice::new(&sc).unwrap();
    let state = |dev: &mut LocalDevice| {
        let (_, text) = dev.console("frf").unwrap();
        frf::Reply::parse(&text).unwrap()
    };
    dev.console("enable").unwrap();
    dev.console("frf current 100 0.003 1000 2").unwrap();
    dev.wait(0.1).unwrap();
    assert_eq!(
        state(&mut dev).state,
        gms_core::control::frf::FrfState::Measuring
    );
    dev.console("disable").unwrap();
    dev.wait(0.01).unwrap();
    let r = state(&mut dev);
    assert_eq!(r.state, gms_core::control::frf::FrfState::Stopped);
    assert!(r.groups > 0 && r.phasors[0].norm() > 0.0029, "{r:?}");
    dev.console("enable").unwrap();
    dev.console("frf current 100 0.003 1000 2").unwrap();
    dev.wait(0.1).unwrap();
    dev.disconnect();
    dev.wait(0.01).unwrap();
    assert_eq!(
        state(&mut dev).state,
        gms_core::control::frf::FrfState::Stopped
    );
    let st = gms_bench::status(&mut dev).unwrap();
    assert!(st.enabled, "the position loop goes on holding");
    dev.console("current 0").unwrap();
    let e = dev.console("frf current 100 0.003 8 2").unwrap_err();
    assert!(e.to_string().contains("current mode"), "{e}");
}
