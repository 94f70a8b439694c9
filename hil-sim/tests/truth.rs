//! The plant is the truth, the compensator a model: `hil-sim run`, `compare` and `serve`
//! take a plant whose friction is any model the core has, and the compensator starts from
//! the device's model unless told otherwise.

use std::io::{BufRead, BufReader, Write};
use std::net::TcpStream;
use std::time::Duration;

use crate::common;
use common::hil;
use hil_sim::scenario::Scenario;

/// A short reference (a sine with reversals, then a step) for the CLI runs.
const SHORT: &str = r#"
[reference]
segments = [
  { kind = "hold", duration = 0.02 },
  { kind = "sine", amplitude = 0.02, freq = 2.0, cycles = 2.0 },
  { kind = "steps", counts = [10], dwell = 0.05 },
]
"#;

/// A LuGre actuator (Table 1's Stribeck curve, one bristle of Table 1's initial stiffness,
/// Fs 15 % above the device's default).
const LUGRE: &str = "[plant.actuator]\nmodel = \"lugre\"\nfs = 253e-6\nfc = 125e-6\nvs = 0.2\n\
                     delta = 0.9\nsigma = 10.5e-6\nsigma0 = 1.25\nsigma1 = 0.0\n";

/// A 4-block GMS actuator.
const FOUR: &str = "[plant.actuator]\nmodel = \"gms\"\nfs = 220e-6\nfc = 125e-6\nvs = 0.2\n\
                    delta = 0.9\nsigma = 10.5e-6\nc = 5e-3\nblocks = [{ k = 1.2, alpha = 0.6 }, \
                    { k = 0.05, alpha = 0.2 }, { k = 0.01, alpha = 0.1 }, \
                    { k = 0.002, alpha = 0.1 }]\n";

/// The sine RMS error of a run's metrics.json [rad].
fn sine_rms(dir: &std::path::Path) -> f64 {
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("metrics.json")).unwrap()).unwrap();
    m["metrics"]["sine_rms_error"].as_f64().unwrap()
}

/// `run` and `compare` accept a LuGre and a 4-block plant; against either, the device's GMS
/// feedforward (its default model, not the plant's) still tracks the sine better than no
/// feedforward.
#[test]
fn run_and_compare_take_any_plant_friction() {
    let d = tempfile::tempdir().unwrap();
    for (name, plant) in [("lugre", LUGRE), ("four", FOUR)] {
        for mode in ["none", "gms"] {
            let file = format!("{name}-{mode}.toml");
            std::fs::write(
                d.path().join(&file),
                format!("{SHORT}\n{plant}\n[controller.ff]\nmode = \"{mode}\"\n"),
            )
            .unwrap();
            let out = format!("out-{name}-{mode}");
            let (code, _, err) = hil(&["run", &file, "--out", &out], d.path());
            assert_eq!(code, 0, "{name} {mode}: {err}");
        }
        let (none, gms) = (
            sine_rms(&d.path().join(format!("out-{name}-none"))),
            sine_rms(&d.path().join(format!("out-{name}-gms"))),
        );
        println!("{name}: sine RMS none {none:e}, gms {gms:e}");
        assert!(gms < 0.6 * none, "{name}: gms {gms:e} none {none:e}");
        let (code, out, err) = hil(
            &[
                "compare",
                &format!("{name}-gms.toml"),
                "--runs",
                "2",
                "--json",
                "c.json",
            ],
            d.path(),
        );
        assert_eq!(code, 0, "{name}: {err}");
        assert!(out.contains("gms-adaptive"), "{out}");
    }
}

/// The compensator's model: the device's defaults whatever the plant (`ff.start = "device"`),
/// the plant's nominal where the device can hold it (`"plant"`), refused with the reason where
/// it cannot (12 blocks); `[controller.gms]` keys edit the starting model.
#[test]
fn the_compensator_starts_from_the_device_or_the_plant() {
    let defaults = gms_core::device::default_settings().ff.actuator;
    let four = Scenario::parse(FOUR, "t").unwrap();
    assert_eq!(four.controller_params().unwrap().ff.actuator, defaults);
    let from_plant = Scenario::parse(
        &format!("{FOUR}\n[controller.ff]\nstart = \"plant\"\n"),
        "t",
    )
    .unwrap();
    let a = from_plant.controller_params().unwrap().ff.actuator;
    assert_eq!(a.blocks_used(), 4);
    assert_eq!((a.blocks[0].k, a.blocks[3].alpha), (1.2, 0.1));
    // LuGre from the plant: its Stribeck curve and viscous term, the device's blocks and C.
    let lugre = Scenario::parse(
        &format!("{LUGRE}\n[controller.ff]\nstart = \"plant\"\n"),
        "t",
    )
    .unwrap();
    let l = lugre.controller_params().unwrap().ff.actuator;
    assert_eq!(l.stribeck.fs, 253e-6);
    assert_eq!((l.blocks, l.c), (defaults.blocks, defaults.c));
    // gms.* keys edit the starting model, whatever their order in the file.
    let edited = Scenario::parse(
        &format!("{FOUR}\n[controller.gms]\nfs = 2.5e-4\n[controller.ff]\nstart = \"plant\"\n"),
        "t",
    )
    .unwrap();
    let e = edited.controller_params().unwrap().ff.actuator;
    assert_eq!((e.stribeck.fs, e.blocks_used()), (2.5e-4, 4));
    // Twelve blocks cannot be the compensator's.
    let blocks: Vec<String> = (0..12)
        .map(|i| format!("{{ k = {}, alpha = {} }}", 1.0 / 2f64.powi(i), 1.0 / 12.0))
        .collect();
    let twelve = format!(
        "[plant.actuator]\nmodel = \"gms\"\nfs = 220e-6\nfc = 125e-6\nvs = 0.2\nc = 5e-3\n\
         blocks = [{}]\n",
        blocks.join(", ")
    );
    assert!(Scenario::parse(&twelve, "t").is_ok());
    let err = Scenario::parse(
        &format!("{twelve}[controller.ff]\nstart = \"plant\"\n"),
        "t",
    )
    .unwrap_err()
    .to_string();
    assert!(
        err.contains("12 blocks") && err.contains("at most 6"),
        "{err}"
    );
    let err = Scenario::parse("[controller.ff]\nstart = \"oracle\"\n", "t")
        .unwrap_err()
        .to_string();
    assert!(err.contains("controller.ff.start"), "{err}");
}

/// `hil-sim serve` on a LuGre plant: the virtual device starts at its own defaults (it is not
/// told the plant's friction), answers, and moves.
#[test]
fn serve_takes_a_lugre_plant_and_is_not_told_its_friction() {
    let d = tempfile::tempdir().unwrap();
    let scenario = d.path().join("s.toml");
    std::fs::write(&scenario, LUGRE).unwrap();
    let srv = common::serve(
        &[
            "--tcp",
            "127.0.0.1:0",
            "--scenario",
            scenario.to_str().unwrap(),
        ],
        &d.path().join("flash.img"),
    );
    let s = TcpStream::connect(&srv.addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
    let mut w = s.try_clone().unwrap();
    let mut r = BufReader::new(s);
    let mut ask = |q: &str| {
        w.write_all(format!("{q}\n").as_bytes()).unwrap();
        let mut l = String::new();
        r.read_line(&mut l).unwrap();
        l.trim().to_string()
    };
    assert_eq!(ask("get gms.fs"), "ok 0.00022");
    assert_eq!(ask("get gms.blocks"), "ok 6");
    assert_eq!(ask("enable"), "ok");
    assert_eq!(ask("move 0.01"), "ok");
}

/// The mismatch study's plants: five valid models sharing Table 1's sliding friction; the
/// 4-block plant's virgin curve within 3 % of Fs of Table 1's (RMS over its range), the
/// 12-block plant's within 1 % of the smooth curve it stands for.
#[test]
fn the_mismatch_studys_plants_are_what_they_say() {
    let base = Scenario::default().plant.actuator;
    let truths = hil_sim::study::truths(&base).unwrap();
    assert_eq!(truths.len(), 5);
    let fs = base.fs.unwrap();
    let k0: f64 = base.blocks.iter().flatten().map(|b| b.k).sum();
    let rms = |spec: &gms_ident::paramfile::FrictionSpec, want: &dyn Fn(f64) -> f64, xmax: f64| {
        let n = 500;
        ((1..=n)
            .map(|i| {
                let x = xmax * i as f64 / n as f64;
                (spec.virgin(x) - want(x)).powi(2)
            })
            .sum::<f64>()
            / n as f64)
            .sqrt()
            / fs
    };
    for t in &truths {
        let mut sc = Scenario::default();
        sc.plant.actuator = t.spec.clone();
        sc.check().unwrap();
        assert_eq!(
            (t.spec.fs, t.spec.fc, t.spec.vs, t.spec.delta, t.spec.sigma),
            (base.fs, base.fc, base.vs, base.delta, base.sigma),
            "{}",
            t.name
        );
    }
    let four = &truths[1].spec;
    assert_eq!(four.blocks.as_ref().unwrap().len(), 4);
    let e4 = rms(four, &|x| base.virgin(x), base.largest_breakpoint());
    let twelve = &truths[2].spec;
    assert_eq!(twelve.blocks.as_ref().unwrap().len(), 12);
    let e12 = rms(
        twelve,
        &|x| fs * (1.0 - (-k0 * x / fs).exp()),
        7.0 * fs / k0,
    );
    println!(
        "virgin curves: 4 blocks {:.2} % of Fs, 12 blocks {:.2} %",
        e4 * 100.0,
        e12 * 100.0
    );
    assert!(e4 < 0.03, "{e4}");
    assert!(e12 < 0.01, "{e12}");
}

/// `hil-sim mismatch`: the study's table, one row per plant; against every plant with
/// pre-sliding the device's GMS feedforward beats no feedforward on the sine, against its own
/// model it is the reference (×1.00), and a plant whose pre-sliding has another shape (12
/// blocks of a smooth curve, LuGre) costs it more than 30 %. Against a plant without
/// pre-sliding (a static map, its friction switching at the reversal) the model's pre-sliding
/// costs it more than three times its own error, and with the default 20 kHz loop it no
/// longer beats no feedforward there (2 draws: 2.54 counts against 2.36; the earlier 10 kHz
/// loop's feedback was weak enough for it to win).
#[test]
fn the_mismatch_command_prints_the_studys_table() {
    let d = tempfile::tempdir().unwrap();
    let (code, out, err) = hil(&["mismatch", "--runs", "2"], d.path());
    assert_eq!(code, 0, "{err}");
    let rows: Vec<Vec<String>> = out
        .lines()
        .filter(|l| l.starts_with("| ") && !l.starts_with("| plant"))
        .map(|l| l.split('|').map(|c| c.trim().to_string()).collect())
        .collect();
    assert_eq!(rows.len(), 5, "{out}");
    let median = |cell: &str| -> f64 { cell.split_whitespace().next().unwrap().parse().unwrap() };
    // The sine RMS's ratio to the plant's own model, the last column's first figure.
    let own = |r: &[String]| -> f64 {
        r[8].trim_start_matches('×')
            .split(',')
            .next()
            .unwrap()
            .parse()
            .unwrap()
    };
    for r in &rows[..4] {
        // Columns: name, none, static, gms, gms-adaptive, reversal none, reversal gms, ratio.
        assert!(median(&r[4]) < median(&r[2]), "{r:?}");
    }
    assert!(rows[4][1].starts_with("static map"), "{:?}", rows[4]);
    assert!(own(&rows[4]) > 3.0, "{:?}", rows[4]);
    assert!(rows[0][8].starts_with("×1.00, ×1.00"), "{:?}", rows[0]);
    for r in &rows[2..4] {
        assert!(own(r) > 1.3, "{r:?}");
    }
}
