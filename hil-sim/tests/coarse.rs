//! A user's own axis end to end: a gear motor with a 2000 counts/rev encoder and a ±2 A
//! current sense (`examples/scenarios/gear-motor.toml`), not the paper's rig. The device takes
//! the plant's resolution and sense scale as its parameters (`enc.counts_per_rev`,
//! `sense.v_per_a`); commissioning and identification run on it in its own units, the motor
//! and the friction hidden from the device.

use crate::common;
use common::identification_errors;
use gms_bench::{DeviceInfo, Plans, Ranges, commission, get_param, identify_on};
use gms_core::protocol::ParamId;
use hil_sim::device::LocalDevice;
use hil_sim::scenario::Scenario;

const GEAR_MOTOR: &str = include_str!("../../examples/scenarios/gear-motor.toml");

/// The scenario with `extra` tables appended (the plant's draw off: the truth is nominal).
fn scenario(extra: &str) -> Scenario {
    let text = GEAR_MOTOR.replacen("[plant]\n", "[plant]\nvariability = 0.0\n", 1);
    Scenario::parse(&format!("{text}\n{extra}"), "gear-motor").unwrap()
}

#[test]
fn the_device_runs_in_the_plants_encoder_counts_and_sense_scale() {
    let sc = scenario("");
    let mut dev = LocalDevice::new(&sc).unwrap();
    assert_eq!(
        get_param(&mut dev, ParamId::EncCountsPerRev).unwrap(),
        2000.0
    );
    // 1.65 V over ±2 A.
    assert!((get_param(&mut dev, ParamId::SenseVPerA).unwrap() - 0.825).abs() < 1e-6);
    let (_, status) = dev.console("status").unwrap();
    assert!(status.contains(" configured=1"), "{status}");
    // A move of 100 counts ends within a count of 100 × 2π/2000 rad.
    let rpc = std::f64::consts::TAU / 2000.0;
    let bench = &mut dev;
    use gms_bench::Bench;
    bench.console("enable").unwrap();
    bench.console(&format!("move {}", 100.0 * rpc)).unwrap();
    bench.wait(2.0).unwrap();
    let (_, status) = bench.console("status").unwrap();
    let field = |k: &str| -> f64 {
        status
            .split_whitespace()
            .find_map(|w| w.strip_prefix(k)?.strip_prefix('='))
            .unwrap()
            .parse()
            .unwrap()
    };
    assert_eq!(field("faults"), 0.0, "{status}");
    // Within a few counts of the target (the default gains' integral, `pos.i_limit` 1 mN·m,
    // cannot push this motor's 3 mN·m of friction the last counts: commissioning sets them),
    // and position plus error is the target in counts.
    let pos = field("pos") / rpc;
    assert!((pos - 100.0).abs() <= 3.0, "{status}");
    assert!(
        (pos + field("error_counts") - 100.0).abs() < 1e-3,
        "{status}"
    );
    // The plant's true angle is where the device reads it, within the count.
    let truth = dev.plant().theta / rpc;
    assert!(
        (truth - pos).abs() <= 1.0,
        "true angle {truth} counts, read {pos}"
    );
}

/// The device told the motor as a datasheet gives it, 20 % off (R 3 Ω against 2.5, k 10 against
/// 12 mN·m/A, J 1.6e-6 against 2e-6 kg·m²): commissioning measures the gear motor in its own
/// units and reports the resolution it ran with (`gms-tune commission --speed 5`).
#[test]
fn commissioning_measures_the_gear_motor() {
    let sc = scenario(
        "[controller.motor]\nr = 3.0\nk_m = 10e-3\nk_e = 10e-3\n[controller.ff]\ninertia = 1.6e-6\n",
    );
    let mut dev = LocalDevice::new(&sc).unwrap();
    // The speed runs at 5, 10 and 15 rad/s: at the default 1 rad/s this motor's back-EMF
    // (12 mV) is 2 % of its R·i, and a 0.1 % error in R is 5 % in k_e.
    let c = commission(&mut dev, 5.0).unwrap();
    for l in &c.lines {
        eprintln!("  {l}");
    }
    let p = &sc.plant;
    eprintln!(
        "R {} -> {:.4} ({:+.2} %), k {} -> {:.4e} ({:+.2} %), J {} -> {:.3e} ({:+.1} %), \
         L {} -> {:.3e} ({:+.1} %)",
        p.path_resistance(),
        c.r,
        (c.r / p.path_resistance() - 1.0) * 100.0,
        p.k_e,
        c.k_e,
        (c.k_e / p.k_e - 1.0) * 100.0,
        p.inertia,
        c.inertia,
        (c.inertia / p.inertia - 1.0) * 100.0,
        p.inductance,
        c.inductance,
        (c.inductance / p.inductance - 1.0) * 100.0,
    );
    assert!(
        c.lines[0].starts_with("encoder: 2000 counts/rev (3.142 mrad/count)"),
        "{}",
        c.lines[0]
    );
    // The winding and the bridge's switches in its path.
    assert!((c.r / p.path_resistance() - 1.0).abs() < 0.05, "R {}", c.r);
    assert!((c.k_e / p.k_e - 1.0).abs() < 0.05, "k_e {}", c.k_e);
    assert!(
        (c.inertia / p.inertia - 1.0).abs() < 0.15,
        "J {}",
        c.inertia
    );
    assert!(
        (c.inductance / p.inductance - 1.0).abs() < 0.20,
        "L {}",
        c.inductance
    );
    // Applied, the gains move the axis 100 counts and hold it, without a fault.
    for (k, v) in c.settings() {
        dev.ask(&format!("set {k} {v}"));
    }
    let (pos, err, status) = move_counts(&mut dev, 100.0);
    eprintln!(
        "after commissioning: a 100-count move ends at {pos:.1} counts, error {err}: {status}"
    );
    assert!(status.contains(" faults=0 "), "{status}");
    assert!((pos - 100.0).abs() <= 1.0 && err.abs() <= 1.0, "{status}");
}

/// Enables, moves by `counts` of the gear motor's encoder, waits 2 s; the position and the
/// error \[counts\] and the status.
fn move_counts(dev: &mut LocalDevice, counts: f64) -> (f64, f64, String) {
    use gms_bench::Bench;
    let rpc = std::f64::consts::TAU / 2000.0;
    dev.console("enable").unwrap();
    let x0 = gms_bench::position(dev).unwrap();
    dev.console(&format!("move {}", x0 + counts * rpc)).unwrap();
    dev.wait(2.0).unwrap();
    let status = dev.ask("status");
    let field = |k: &str| -> f64 {
        status
            .split_whitespace()
            .find_map(|w| w.strip_prefix(k)?.strip_prefix('='))
            .unwrap()
            .parse()
            .unwrap()
    };
    ((field("pos") - x0) / rpc, field("error_counts"), status)
}

/// The friction identified on the coarse encoder after commissioning (which scales the
/// device's Table 1 model to the measured breakaway, so that the experiments plan from the
/// axis's level): the sliding curve (Fs, Fc) within bounds of the hidden truth; what a
/// 3.14 mrad count can say of the pre-sliding.
#[test]
fn identification_on_a_coarse_encoder() {
    let sc = scenario("");
    let mut dev = LocalDevice::new(&sc).unwrap();
    let c = commission(&mut dev, 5.0).unwrap();
    for l in &c.lines {
        eprintln!("  {l}");
    }
    for (k, v) in c.settings() {
        assert!(
            dev.ask(&format!("set {k} {v}")).starts_with("ok"),
            "{k} {v}"
        );
    }
    let info = DeviceInfo::read(&mut dev).unwrap();
    let plans = Plans::new(
        &info,
        &Ranges {
            window: Some(15.0),
            ..Ranges::default()
        },
    )
    .unwrap();
    let dir = tempfile::tempdir().unwrap();
    let (g, id) = identify_on(&mut dev, &plans, dir.path(), 4, false, &mut |_, _, _| {}).unwrap();
    let e = identification_errors(&sc.plant.actuator, &g, &id.spec);
    eprintln!(
        "gear motor: errors fs {:.1} %, fc {:.1} %, vs {:.1} %, delta {:.1} %, sigma {:.1} %, \
         c {:.1} %, virgin curve {:.2} % of Fs; {} pre-sliding points",
        e[0] * 100.0,
        e[1] * 100.0,
        e[2] * 100.0,
        e[3] * 100.0,
        e[4] * 100.0,
        e[5] * 100.0,
        e[6] * 100.0,
        g.presliding.len()
    );
    for l in &id.report {
        eprintln!("  {l}");
    }
    // What 3.14 mrad counts resolve: the Coulomb level within 25 %, the breakaway within 20 %
    // (the slowest runs stick and slip between counts), the virgin curve within 20 % of Fs
    // (pre-sliding spans ten counts). Vs, delta and sigma are not resolved (the loop's count
    // steps roughen the sliding at every speed), nor the lag (skipped, the paper's rule).
    // The sliding points scatter about the true curve by -20 % (below 0.14 rad/s: 6 to 40
    // counts a second, stick and slip) to +24 % (at 6 rad/s), in this loop and in the earlier
    // 10 kHz one alike; the fit's Fc came out 0.4 % off in that one (δ 11.8 ± 130: the fit
    // of such points lands where it lands), 19-21 % in the 20 kHz one, 6 % with the 40 kHz
    // current loop and the viscous term held at its bound 0 where least squares would make it
    // negative (the slow points' stick-slip pulls the knee; sliding data and fit in the note
    // of docs/identification.md on coarse encoders).
    assert!(e[1] < 0.25, "fc {e:?}");
    assert!(e[0] < 0.20, "fs {e:?}");
    assert!(e[6] < 0.20, "virgin {e:?}");
    assert!(
        id.report
            .iter()
            .any(|l| l.starts_with("frictional lag: not measured")),
        "{:?}",
        id.report
    );
}

#[test]
fn a_scenario_gives_its_encoder_in_counts_per_revolution_or_radians_per_count() {
    let sc = Scenario::parse("[plant]\ncounts_per_rev = 2000\n", "t").unwrap();
    assert_eq!(sc.plant.rad_per_count, std::f64::consts::TAU / 2000.0);
    assert_eq!(sc.controller_params().unwrap().counts_per_rev, 2000.0);
    // The default, 3.8 µrad: the device's 3.8e-6 in single precision exactly, as before.
    let p = Scenario::default().controller_params().unwrap();
    assert_eq!(p.rad_per_count(), 3.8e-6f32);
    for (text, why) in [
        (
            "[plant]\ncounts_per_rev = 2000\nrad_per_count = 1e-3\n",
            "not both",
        ),
        ("[plant]\ncounts_per_rev = 2\n", "counts_per_rev must be"),
        ("[plant]\ncounts_per_rev = \"many\"\n", "expected a number"),
    ] {
        let e = Scenario::parse(text, "t").unwrap_err().to_string();
        assert!(e.contains(why), "{text}: {e}");
    }
}

/// Sets `[controller.TABLE] KEY = value` in a scenario's controller table.
fn tell(sc: &mut Scenario, table: &str, key: &str, value: f64) {
    let t = sc
        .controller
        .entry(table)
        .or_insert_with(|| toml::Value::Table(toml::Table::new()));
    if let toml::Value::Table(t) = t {
        t.insert(key.into(), toml::Value::Float(value));
    }
}

/// A property over coarse-encoder motors commissioning is not told (proptest, a fixed seed,
/// ten cases): gear motors of R 1.5-5 Ω, k 8-20 mN·m/A, J 1-4e-6 kg·m², L/R 0.1-0.4 ms and a
/// breakaway of 2-5 mN·m (Coulomb two thirds of it), behind the gear motor's 2000 counts/rev
/// encoder and ±2 A sense; the device told a datasheet's R, k and J each 0.8-1.25 times the
/// truth, and its current loop made from them (docs/bring-up.md). Commissioning (`--speed 5`)
/// finds R and k_e within 5 %, J within 15 %, L within 20 % (k_e read 4-18 % low before its
/// runs averaged the current and the voltage over each sample's steps).
///
/// Worst of the ten: R −0.16 %, k_e +0.91 %, J −1.4 %, L +7.3 % (with 0.1 s of each back-EMF
/// run averaged: k_e −2.66 %, and the R 4.19 Ω motor's k_e moved between +1 % and −6 % with
/// a one-ulp change of the duty's arithmetic; now 0.3 s: `KE_RUN`). One case read k_e +5.2 % and
/// J +7.0 % before (R 4.19 Ω, k 9.56 mN·m/A, J 2.69e-6 kg·m², L/R 385 µs, Fs 2.2 mN·m; now
/// +1.03 % and +2.3 %): the k_e runs alternate their direction under a soft loop (ki / 8), and
/// a plain integral, holding the last run's friction (ten times the device's model of it),
/// was presumably still unwinding it into the samples the next run is measured over.
/// Commissioning now carries half the integral as a friction level during those runs
/// (`pos.ki_fric` 0.5, put back after), which turns over with the direction.
#[test]
fn commissioning_holds_on_random_coarse_encoder_motors() {
    use proptest::test_runner::{Config, RngSeed, TestRunner};
    let mut runner = TestRunner::new(Config {
        cases: 10,
        failure_persistence: None,
        rng_seed: RngSeed::Fixed(41),
        ..Config::default()
    });
    let motor = (
        (
            1.5f64..5.0,
            8e-3f64..20e-3,
            1e-6f64..4e-6,
            0.1e-3f64..0.4e-3,
        ),
        2e-3f64..5e-3,
        (0.8f64..1.25, 0.8f64..1.25, 0.8f64..1.25),
    );
    runner
        .run(&motor, |((r, k, j, tau), fs, (fr, fk, fj))| {
            let mut sc = scenario("");
            let p = &mut sc.plant;
            (p.resistance, p.k_m, p.k_e, p.inertia, p.inductance) = (r, k, k, j, r * tau);
            p.actuator.fs = Some(fs);
            p.actuator.fc = Some(fs * 2.0 / 3.0);
            let (rt, lt) = (r * fr, r * tau * fr);
            let cur_hz = f64::from(gms_core::device::default_settings().cur_rate_hz);
            let (kp, ki) = gms_ident::gains::current_pi(rt, lt, cur_hz);
            tell(&mut sc, "motor", "r", rt);
            tell(&mut sc, "motor", "k_m", k * fk);
            tell(&mut sc, "motor", "k_e", k * fk);
            tell(&mut sc, "ff", "inertia", j * fj);
            tell(&mut sc, "cur", "kp", kp);
            tell(&mut sc, "cur", "ki", ki);
            let mut dev = LocalDevice::new(&sc).unwrap();
            let c = commission(&mut dev, 5.0)
                .unwrap_or_else(|e| panic!("R {r} k {k} J {j} L/R {tau}: {e}"));
            let rel = |a: f64, b: f64| a / b - 1.0;
            let (er, ek, ej, el) = (
                rel(c.r, sc.plant.path_resistance()),
                rel(c.k_e, k),
                rel(c.inertia, j),
                rel(c.inductance, r * tau),
            );
            eprintln!(
                "R {r:.2} k {k:.2e} J {j:.2e} L/R {:.0} µs Fs {fs:.1e}: R {:+.2} %, k_e {:+.2} %, \
                 J {:+.1} %, L {:+.1} %",
                tau * 1e6,
                er * 100.0,
                ek * 100.0,
                ej * 100.0,
                el * 100.0
            );
            proptest::prop_assert!(er.abs() < 0.05, "R {}", c.r);
            proptest::prop_assert!(ek.abs() < 0.05, "k_e {}", c.k_e);
            proptest::prop_assert!(ej.abs() < 0.15, "J {}", c.inertia);
            proptest::prop_assert!(el.abs() < 0.20, "L {}", c.inductance);
            Ok(())
        })
        .unwrap();
}
