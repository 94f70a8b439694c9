//! The paper's experiments run through the protocol on the device core (the bench abstraction
//! of `gms_ident::bench`, here on `LocalDevice`: the simulated plant in simulated time) and
//! identified with the same fits as the simulated experiments: the bench sees the plant's
//! hidden friction.

use gms_ident::bench::{SlidingPlan, sliding};
use gms_ident::identify::fit_stribeck;
use hil_sim::device::LocalDevice;
use hil_sim::scenario::Scenario;

/// The default plant with its friction exactly nominal (no draw) and the guideway negligible:
/// the bench sees the actuator's Table 1 friction alone.
const QUIET: &str = "[plant]
variability = 0.0

[plant.guideway]
fs = 1e-6
fc = 1e-6
";

#[test]
fn the_sliding_experiment_on_the_device_finds_the_hidden_stribeck_curve() {
    let sc = Scenario::parse(QUIET, "test").unwrap();
    let mut dev = LocalDevice::new(&sc).unwrap();
    // 10 speeds from Vs/10 to 30 Vs (0.02 to 6 rad/s), each way.
    let plan = SlidingPlan::log_spaced(0.02, 6.0, 10);
    let data = sliding(&mut dev, &plan).unwrap();
    assert_eq!(data.len(), 20);
    // The motor's torque opposes the friction, so it has its speed's sign.
    assert!(
        data.iter().all(|(v, f)| v.signum() == f.signum()),
        "{data:?}"
    );
    let rel = |got: f64, want: f64| (got - want).abs() / want;
    for dir in [1.0, -1.0] {
        let (v, f): (Vec<f64>, Vec<f64>) = data
            .iter()
            .filter(|(v, _)| v.signum() == dir)
            .map(|(v, f)| (v.abs(), f.abs()))
            .unzip();
        let fit = fit_stribeck(&v, &f).unwrap();
        eprintln!("direction {dir}: {fit:?}");
        // Table 1 (docs/design.md#reading-table-1): fs 220e-6, fc 125e-6 N·m, vs 0.2 rad/s,
        // delta 0.9, sigma 10.5e-6 N·m·s/rad.
        assert!(rel(fit.fs, 220e-6) < 0.03, "fs {}", fit.fs);
        assert!(rel(fit.fc, 125e-6) < 0.03, "fc {}", fit.fc);
        assert!(rel(fit.vs, 0.2) < 0.10, "vs {}", fit.vs);
        assert!(rel(fit.delta, 0.9) < 0.10, "delta {}", fit.delta);
        assert!(rel(fit.sigma, 10.5e-6) < 0.10, "sigma {}", fit.sigma);
    }
}
