//! `hil-sim run`, `compare` and their contracts, as a user runs them.

use crate::common;
use common::hil;

/// A short scenario so that the tests run fast.
const SHORT: &str = r#"
[reference]
segments = [
  { kind = "sine", amplitude = 0.02, freq = 4.0, cycles = 1.0 },
  { kind = "steps", counts = [10], dwell = 0.05 },
]
"#;

#[test]
fn default_scenario_is_complete_and_documented() {
    let d = tempfile::tempdir().unwrap();
    let (code, text, _) = hil(&["run", "--print-default-scenario"], d.path());
    assert_eq!(code, 0);
    let parsed = hil_sim::scenario::Scenario::parse(&text, "printed").unwrap();
    assert_eq!(parsed, hil_sim::scenario::Scenario::default());
    // One default set: the default scenario's controller is the device's default (what does
    // not come from the plant: rates, gains, limits, feedforward settings).
    let (a, b) = (
        parsed.controller_params().unwrap(),
        gms_core::device::default_settings(),
    );
    assert_eq!(
        (a.pos_rate_hz, a.cur_rate_hz, a.pid, a.current),
        (b.pos_rate_hz, b.cur_rate_hz, b.pid, b.current)
    );
    assert_eq!(
        (a.i_max, a.motor.inertia, a.ff.mode, a.ff.gain),
        (b.i_max, b.motor.inertia, b.ff.mode, b.ff.gain)
    );
    assert_eq!(
        (a.ff.static_band, a.ff.adapt),
        (b.ff.static_band, b.ff.adapt)
    );
    // Units in comments on the physical keys.
    for key in [
        "resistance",
        "inductance",
        "inertia",
        "k_m",
        "rad_per_count",
    ] {
        let line = text
            .lines()
            .find(|l| l.trim_start().starts_with(key))
            .unwrap();
        assert!(line.contains('[') && line.contains('#'), "{line}");
    }
}

#[test]
fn run_writes_trace_metrics_and_plot() {
    let d = tempfile::tempdir().unwrap();
    std::fs::write(d.path().join("s.toml"), SHORT).unwrap();
    let (code, out, err) = hil(&["run", "s.toml", "--out", "res"], d.path());
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("rms error"));
    let trace = std::fs::read_to_string(d.path().join("res/trace.csv")).unwrap();
    let header = trace.lines().next().unwrap();
    for f in [
        "t",
        "reference",
        "position",
        "error",
        "current",
        "voltage",
        "friction",
        "feedforward",
    ] {
        assert!(header.split(',').any(|h| h == f), "{header}");
    }
    // 0.25 s + 0.05 s + move at 10 kHz.
    assert!(trace.lines().count() > 3000);
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.path().join("res/metrics.json")).unwrap())
            .unwrap();
    for k in [
        "rms_error",
        "max_error",
        "reversal_error",
        "settle_time",
        "steady_state_error",
    ] {
        assert!(m["metrics"][k].as_f64().unwrap().is_finite(), "{k}");
    }
    let svg = std::fs::read_to_string(d.path().join("res/plot.svg")).unwrap();
    assert!(svg.starts_with("<svg") && svg.contains("error [counts]"));
}

#[test]
fn compare_writes_the_json_contract() {
    let d = tempfile::tempdir().unwrap();
    std::fs::write(d.path().join("s.toml"), SHORT).unwrap();
    let (code, out, err) = hil(
        &[
            "compare", "s.toml", "--runs", "3", "--seed", "5", "--json", "c.json",
        ],
        d.path(),
    );
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("none") && out.contains("gms"));
    let c: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.path().join("c.json")).unwrap()).unwrap();
    for mode in ["none", "static", "gms"] {
        for k in [
            "rms_error",
            "max_error",
            "reversal_error",
            "settle_time",
            "steady_state_error",
        ] {
            let s = &c["modes"][mode][k];
            let (med, p95) = (s["median"].as_f64().unwrap(), s["p95"].as_f64().unwrap());
            assert!(med.is_finite() && p95 >= med, "{mode} {k}: {s}");
        }
    }
    assert!(d.path().join("c.svg").exists());
}

/// A drifting scenario adds the level oracle to the table and the JSON.
#[test]
fn compare_reports_the_level_oracle_when_friction_drifts() {
    let d = tempfile::tempdir().unwrap();
    let drift = format!("[plant.drift]\nkind = \"ramp\"\namount = -0.15\ntime = 0.1\n{SHORT}");
    for (text, oracle) in [(SHORT.to_string(), false), (drift, true)] {
        std::fs::write(d.path().join("s.toml"), text).unwrap();
        let (code, out, err) = hil(
            &["compare", "s.toml", "--runs", "2", "--json", "c.json"],
            d.path(),
        );
        assert_eq!(code, 0, "{err}");
        assert_eq!(out.contains("level oracle"), oracle, "{out}");
        let c: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(d.path().join("c.json")).unwrap())
                .unwrap();
        assert_eq!(c["oracle"]["rms_error"]["median"].is_f64(), oracle, "{c}");
    }
}

/// Every example scenario is a valid scenario file.
#[test]
fn the_example_scenarios_parse() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/scenarios");
    let mut n = 0;
    for e in std::fs::read_dir(&dir).unwrap() {
        let path = e.unwrap().path();
        let text = std::fs::read_to_string(&path).unwrap();
        let sc = hil_sim::scenario::Scenario::parse(&text, &path.display().to_string())
            .map_err(|e| e.to_string());
        assert!(sc.is_ok(), "{:?}", sc.err());
        n += 1;
    }
    assert!(n >= 5, "{n} scenarios");
}

#[test]
fn bad_scenarios_and_arguments_exit_2_with_one_line() {
    let d = tempfile::tempdir().unwrap();
    let cases: [(&str, &str); 9] = [
        ("[plant]\nresistence = 3\n", "resistence"),
        // The scenario's controller keys are the protocol's paths, with its ranges.
        (
            "[controller.ff.adapt]\nvmin = -1\n",
            "controller.ff.adapt.vmin",
        ),
        (
            "[controller.pos]\nkp = 5000\n",
            "controller.pos.kp = 5000: not a finite number within [0, 1000] N·m/rad",
        ),
        (
            "[controller.pid]\nkp = 0.2\n",
            "controller.pid.kp: unknown key",
        ),
        ("[controller.pos]\nkp = \"high\"\n", "controller.pos.kp"),
        ("[controller.pos]\nkp = -1\n", "controller.pos.kp"),
        ("[plant.actuator]\nfs = 1e-6\n", "plant.actuator"),
        (
            "[reference]\nsegments = [{ kind = \"sine\", amplitude = 0.1, freq = 0, cycles = 1 }]\n",
            "segment 0",
        ),
        ("[plant\n", "bad.toml:1"),
    ];
    for (text, want) in cases {
        std::fs::write(d.path().join("bad.toml"), text).unwrap();
        let (code, _, err) = hil(&["run", "bad.toml", "--out", "o"], d.path());
        assert_eq!(code, 2, "{text}: {err}");
        assert_eq!(err.trim_end().lines().count(), 1, "{err}");
        assert!(err.contains(want), "{err:?} should name {want:?}");
        assert!(!d.path().join("o").exists(), "{text}: wrote output");
        let (code, _, _) = hil(
            &["compare", "bad.toml", "--runs", "1", "--json", "c.json"],
            d.path(),
        );
        assert_eq!(code, 2);
        assert!(!d.path().join("c.json").exists());
    }
    let (code, _, err) = hil(&["run", "missing.toml", "--out", "o"], d.path());
    assert_eq!(code, 2);
    assert!(err.contains("missing.toml"));
    let (code, _, _) = hil(&["compare", "--runs", "0", "--json", "c.json"], d.path());
    assert_eq!(code, 2);
    let (code, _, _) = hil(&["compare", "--runs", "x", "--json", "c.json"], d.path());
    assert_eq!(code, 2);
}
