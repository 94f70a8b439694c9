//! The paper's experiments run through the protocol on the device core (the bench abstraction
//! of `gms_bench`, here on `LocalDevice`: the simulated plant in simulated time) and
//! identified with the same fits as the simulated experiments: the bench sees the plant's
//! hidden friction.

use crate::common;
use common::{QUIET, identification_errors};
use gms_bench::{SlidingPlan, sliding};
use gms_ident::identify::fit_stribeck;
use hil_sim::device::LocalDevice;
use hil_sim::scenario::Scenario;

#[test]
fn the_sliding_experiment_on_the_device_finds_the_hidden_stribeck_curve() {
    let sc = Scenario::parse(QUIET, "test").unwrap();
    let mut dev = LocalDevice::new(&sc).unwrap();
    // 10 speeds from Vs/10 to 30 Vs (0.02 to 6 rad/s), each way.
    let plan = SlidingPlan::log_spaced(0.02, 6.0, 10);
    let mut data = Vec::new();
    sliding(&mut dev, &plan, &mut data).unwrap();
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

/// The virgin curve of blocks `(k, alpha)` for a breakaway `fs`: Σ min(k x, alpha fs).
fn virgin(blocks: &[(f64, f64)], fs: f64, x: f64) -> f64 {
    blocks.iter().map(|(k, a)| (k * x).min(a * fs)).sum()
}

/// Table 1's blocks (docs/design.md#reading-table-1).
const TABLE1_BLOCKS: [(f64, f64); 6] = [
    (1.159, 0.575),
    (64.417e-3, 0.160),
    (13.066e-3, 0.059),
    (8.027e-3, 0.12),
    (2.043e-3, 0.051),
    (0.961e-3, 0.034),
];

/// The pre-sliding staircase from power-up (then, `with_sliding`, the sliding sweep) on one
/// device with the plant of `scenario`, written as the CSVs `hil-sim identify` reads and
/// identified by the same pipeline. Returns the RMS of the data and of the identified virgin
/// curve (its blocks with its Fs) against the hidden one (Table 1's blocks, Fs 220 µN·m) over
/// the measured range, uniformly in x as the simulated round trip measures it, in % of Fs.
fn staircase(scenario: &str, with_sliding: bool) -> (f64, f64) {
    use gms_bench::{PreslidingPlan, presliding};
    use gms_ident::identify::{Inputs, identify_from};
    let sc = Scenario::parse(scenario, "test").unwrap();
    let mut dev = LocalDevice::new(&sc).unwrap();
    // Steps of Fs / 100 of torque (0.33 mA at k_M = 6.6 mN·m/A), from the virgin state.
    let plan = PreslidingPlan::new(220e-6 / 100.0 / 6.6e-3, 150);
    let mut pre = Vec::new();
    presliding(&mut dev, &plan, &mut pre).unwrap();
    // It broke away before 150 steps (near Fs: about 100).
    assert!(pre.len() > 80 && pre.len() < 150, "{} steps", pre.len());
    let dir = tempfile::tempdir().unwrap();
    let (pp, sp) = (dir.path().join("pre.csv"), dir.path().join("slide.csv"));
    std::fs::write(&pp, gms_bench::presliding_csv(&pre)).unwrap();
    if with_sliding {
        let mut slide = Vec::new();
        sliding(
            &mut dev,
            &SlidingPlan::log_spaced(0.02, 6.0, 10),
            &mut slide,
        )
        .unwrap();
        std::fs::write(&sp, gms_bench::sliding_csv(&slide)).unwrap();
    }
    let id = identify_from(&Inputs {
        presliding: Some(&pp),
        sliding: with_sliding.then_some(sp.as_path()),
        lag: None,
        blocks: 6,
        asymmetric: false,
    })
    .unwrap();
    for l in &id.report {
        eprintln!("{l}");
    }
    let fs = 220e-6;
    let found: Vec<(f64, f64)> = id
        .spec
        .blocks
        .iter()
        .flatten()
        .map(|b| (b.k, b.alpha))
        .collect();
    let fs_found = id.spec.fs.unwrap();
    let data_rms = (pre
        .iter()
        .map(|(x, f)| (f - virgin(&TABLE1_BLOCKS, fs, *x)).powi(2))
        .sum::<f64>()
        / pre.len() as f64)
        .sqrt();
    let n = 400;
    let xmax = pre.iter().map(|p| p.0).fold(0.0, f64::max);
    let rms = ((1..=n)
        .map(|i| {
            let xi = xmax * i as f64 / n as f64;
            (virgin(&found, fs_found, xi) - virgin(&TABLE1_BLOCKS, fs, xi)).powi(2)
        })
        .sum::<f64>()
        / n as f64)
        .sqrt();
    eprintln!(
        "{} steps to {:.2} mrad; data vs hidden curve {:.3} % of Fs; identified vs hidden {:.3} % of Fs",
        pre.len(),
        xmax * 1e3,
        data_rms / fs * 100.0,
        rms / fs * 100.0
    );
    (data_rms / fs * 100.0, rms / fs * 100.0)
}

/// On the default plant the staircase sees a virgin curve below the hidden one where the
/// first block has slipped: the drive's own torque ripple and current noise keep the axis
/// moving at micro-velocities, and with Table 1's Stribeck curve (delta 0.9, infinitely
/// steep at v = 0) the slipping blocks saturate at alpha_i s(v), below alpha_i Fs. The issue
/// aims at 2 %; measured 1.86 % (data 0.89 %) after the erase, asserted at 2.5 %.
#[test]
fn the_presliding_staircase_on_the_device_finds_the_hidden_virgin_curve() {
    let (data, id) = staircase(QUIET, true);
    assert!(data < 2.0, "data {data} % of Fs");
    assert!(id < 2.5, "virgin curve rms {id} % of Fs");
}

/// The cause of the shortfall above: with the Stribeck drop out of reach of micro-velocities
/// (Vs = 100 rad/s), the same staircase and pipeline meet the 2 % aim with room.
#[test]
fn without_a_stribeck_drop_the_staircase_meets_the_2_percent_aim() {
    let text = format!("{QUIET}\n[plant.actuator]\nvs = 100.0\n");
    let (data, id) = staircase(&text, false);
    assert!(data < 1.0, "data {data} % of Fs");
    assert!(id < 1.0, "virgin curve rms {id} % of Fs");
}

#[test]
fn the_frictional_lag_run_on_the_device_finds_the_hidden_c() {
    use gms_bench::{LagPlan, lag};
    use gms_ident::identify::fit_lag;
    use gms_ident::paramfile::ParamFile;
    let sc = Scenario::parse(QUIET, "test").unwrap();
    let mut dev = LocalDevice::new(&sc).unwrap();
    // Around 1.5 Vs, ± 1.2 Vs (0.06 to 0.54 rad/s), 0.2 to 20 Hz over 4 s, at 1 kHz.
    let plan = LagPlan {
        mean: 0.3,
        amp: 0.24,
        f0: 0.2,
        f1: 20.0,
        seconds: 4.0,
        every: (gms_core::device::default_settings().pos_rate_hz / 1000.0).round() as u32,
    };
    // The rest of the friction as the other fits give it (`identify` fits the lag against
    // the Stribeck curve the sliding runs measured on the same device): the blocks Table
    // 1's (the file the examples use), the curve measured here, C to be found. Against Table
    // 1's own curve the fit takes up the sense chain's reading of the friction level into C:
    // the real bridge's amplifier reads its current's decay 0.4 µs late, +0.5 % at speed,
    // and C came out 4.29e-3 (-14 %; the ideal bridge's 4.59e-3, -8 %).
    let mut data = Vec::new();
    sliding(&mut dev, &SlidingPlan::log_spaced(0.02, 6.0, 10), &mut data).unwrap();
    let (v, fv): (Vec<f64>, Vec<f64>) = data.iter().map(|(v, f)| (v.abs(), f.abs())).unzip();
    let curve = fit_stribeck(&v, &fv).unwrap();
    let (t, x, f) = lag(&mut dev, &plan).unwrap();
    assert_eq!(t.len(), 4000);
    let root = concat!(env!("CARGO_MANIFEST_DIR"), "/../examples/table1.toml");
    let mut spec = ParamFile::load(std::path::Path::new(root))
        .unwrap()
        .friction;
    (spec.fs, spec.fc, spec.vs, spec.delta, spec.sigma) = (
        Some(curve.fs),
        Some(curve.fc),
        Some(curve.vs),
        Some(curve.delta),
        Some(curve.sigma),
    );
    let fit = fit_lag(&spec, &t, &x, &f).unwrap();
    eprintln!(
        "C {:.4e} (hidden 5e-3), rel err {:?}, rms {:.3e}",
        fit.c, fit.rel_err, fit.rms
    );
    assert!((fit.c - 5e-3).abs() / 5e-3 < 0.15, "C {}", fit.c);
}

/// The sine test is repeatable (the same RMS twice on the same device and set) and sees the
/// compensation: without the feedforward the error is clearly larger.
#[test]
fn the_sine_test_repeats_and_sees_the_compensation() {
    use gms_bench::sine_test;
    let sc = Scenario::parse(QUIET, "test").unwrap();
    let mut dev = LocalDevice::new(&sc).unwrap();
    let a = sine_test(&mut dev, 2e-3, 1.0, 3.0).unwrap();
    let b = sine_test(&mut dev, 2e-3, 1.0, 3.0).unwrap();
    dev.console("set ff.mode none").unwrap();
    let none = sine_test(&mut dev, 2e-3, 1.0, 3.0).unwrap();
    let rpc = 3.8e-6;
    eprintln!(
        "sine RMS error: {:.3} and {:.3} counts with the GMS feedforward, {:.3} without",
        a / rpc,
        b / rpc,
        none / rpc
    );
    assert!((a - b).abs() < 0.1 * a, "{a} vs {b}");
    // Measured: 0.482 and 0.487 counts with, 0.832 without (the default 20 kHz loop is stiff
    // enough that friction costs it less than twice the compensated error here).
    assert!(none > 1.5 * a, "{none} vs {a}");
}

/// The hidden actuator friction of a property case: Table 1 with its parameters scaled.
#[derive(Debug, Clone, Copy)]
struct Hidden {
    fs: f64,
    fc: f64,
    vs: f64,
    delta: f64,
    sigma: f64,
    c: f64,
    /// Factor on every block stiffness.
    k: f64,
}

impl Hidden {
    const TABLE1: Hidden = Hidden {
        fs: 220e-6,
        fc: 125e-6,
        vs: 0.2,
        delta: 0.9,
        sigma: 10.5e-6,
        c: 5e-3,
        k: 1.0,
    };

    fn scenario(&self) -> String {
        let blocks: Vec<String> = TABLE1_BLOCKS
            .iter()
            .map(|(k, a)| format!("{{ k = {}, alpha = {a} }}", k * self.k))
            .collect();
        // The device's compensator stays at Table 1 whatever the plant: the tool derives its
        // experiments' ranges from it, and must not be told the hidden set.
        let mut table1 = String::from(
            "\n[controller.gms]\nfs = 220e-6\nfc = 125e-6\nvs = 0.2\ndelta = 0.9\nsigma = 10.5e-6\nc = 5e-3\n",
        );
        for (i, (k, a)) in TABLE1_BLOCKS.iter().enumerate() {
            table1 += &format!("k{} = {k}\na{} = {a}\n", i + 1, i + 1);
        }
        format!(
            "{QUIET}\n[plant.actuator]\nmodel = \"gms\"\nfs = {}\nfc = {}\nvs = {}\ndelta = {}\n\
             sigma = {}\nc = {}\nblocks = [{}]\n{table1}",
            self.fs,
            self.fc,
            self.vs,
            self.delta,
            self.sigma,
            self.c,
            blocks.join(", ")
        )
    }
}

/// A whole bench identification (`gms_bench::identify_on`, what `gms-tune identify`
/// runs) on a device with hidden friction `h`; returns the accuracy and the device.
fn identify_hidden(h: &Hidden) -> ([f64; 7], LocalDevice, gms_ident::paramfile::FrictionSpec) {
    use gms_bench::{DeviceInfo, Plans, Ranges, identify_on};
    let sc = Scenario::parse(&h.scenario(), "test").unwrap();
    let mut dev = LocalDevice::new(&sc).unwrap();
    let info = DeviceInfo::read(&mut dev).unwrap();
    let plans = Plans::new(&info, &Ranges::default()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let (g, id) = identify_on(&mut dev, &plans, dir.path(), 6, false, &mut |_, _, _| {}).unwrap();
    for l in &id.report {
        eprintln!("{l}");
    }
    for f in ["presliding.csv", "sliding.csv", "lag.csv"] {
        assert!(dir.path().join(f).exists(), "{f}");
    }
    let acc = identification_errors(&sc.plant.actuator, &g, &id.spec);
    eprintln!(
        "{h:?}\n  errors: fs {:.1} %, fc {:.1} %, vs {:.1} %, delta {:.1} %, sigma {:.1} %, c {:.1} %, virgin curve {:.2} % of Fs",
        acc[0] * 100.0,
        acc[1] * 100.0,
        acc[2] * 100.0,
        acc[3] * 100.0,
        acc[4] * 100.0,
        acc[5] * 100.0,
        acc[6] * 100.0
    );
    (acc, dev, id.spec)
}

/// Whether the errors are within `fs_fc` (Fs and Fc), 10 % (Vs, sigma), `delta`, 15 % (C) and
/// `virgin` (the curve's RMS, fraction of Fs).
fn within(acc: &[f64; 7], fs_fc: f64, delta: f64, c: f64, virgin: f64) -> bool {
    acc[0] < fs_fc
        && acc[1] < fs_fc
        && acc[2] < 0.10
        && acc[3] < delta
        && acc[4] < 0.10
        && acc[5] < c
        && acc[6] < virgin
}

#[test]
fn a_bench_identification_compensates_as_well_as_the_true_set() {
    use gms_bench::{load_params, sine_test};
    let (acc, mut dev, spec) = identify_hidden(&Hidden::TABLE1);
    // The bounds (Fs, Fc 3 %; Vs, delta, sigma 10 %; C 15 %) but the virgin curve's:
    // measured 2.39 % of Fs against the 2 % aimed at (see the staircase test above). Measured:
    // Fs 1.2 %, Fc 0.2 %, Vs 0.4 %, delta 3.9 %, sigma 0.7 %, C 2.7 %; the identified set's
    // sine RMS 0.476 counts against the true set's 0.490.
    assert!(within(&acc, 0.03, 0.10, 0.15, 0.03), "{acc:?}");
    // The device's compensator starts with Table 1, the hidden friction itself: the true set.
    let truth = sine_test(&mut dev, 2e-3, 1.0, 3.0).unwrap();
    let pf = gms_ident::paramfile::ParamFile {
        friction: spec,
        device: None,
    };
    load_params(&mut dev, &pf).unwrap();
    let identified = sine_test(&mut dev, 2e-3, 1.0, 3.0).unwrap();
    let rpc = 3.8e-6;
    eprintln!(
        "sine RMS error: true set {:.3} counts, identified set {:.3} counts ({:+.1} %)",
        truth / rpc,
        identified / rpc,
        (identified / truth - 1.0) * 100.0
    );
    assert!(identified < 1.10 * truth, "{identified} vs {truth}");
}

use proptest::prelude::*;

proptest! {
    // A fixed seed: the same ten cases on every run (the figures below are theirs).
    #![proptest_config(ProptestConfig {
        cases: 10,
        failure_persistence: None,
        rng_seed: proptest::test_runner::RngSeed::Fixed(17),
        ..ProptestConfig::default()
    })]
    /// Bench identifications of hidden frictions around Table 1 (each parameter scaled by
    /// 0.8-1.25, Fc 50-65 % of Fs; the device's compensator, from which the experiments'
    /// ranges are derived, stays at Table 1: the tool does not know the hidden set).
    #[test]
    fn random_hidden_frictions_are_identified_on_the_bench(
        fs in 0.8f64..1.25,
        ratio in 0.5f64..0.65,
        vs in 0.8f64..1.25,
        delta in 0.8f64..1.2,
        sigma in 0.8f64..1.25,
        c in 0.8f64..1.25,
        k in 0.8f64..1.25,
    ) {
        let t = Hidden::TABLE1;
        let h = Hidden {
            fs: t.fs * fs,
            fc: t.fs * fs * ratio,
            vs: t.vs * vs,
            delta: t.delta * delta,
            sigma: t.sigma * sigma,
            c: t.c * c,
            k: t.k * k,
        };
        // As in the simulated round trip (tests/tests/identification.rs): a staircase traces
        // the virgin curve only while creep is stable, the Stribeck drop per unit speed below
        // the damping critical for the initial stiffness and the inertia (Table 1 is at 0.86
        // of it); with a steeper drop the axis sticks and slips before Fs, physics that
        // `identify` reports.
        let k0: f64 = TABLE1_BLOCKS.iter().map(|b| b.0).sum::<f64>() * h.k;
        let damping = 2.0 * (k0 * 6e-8).sqrt();
        prop_assume!((h.fs - h.fc) / h.vs < damping);
        let (acc, _, _) = identify_hidden(&h);
        // Over these ten cases (seed 17), the sliding sweep and the erase in the measuring
        // loop (gms_ident::gains::measuring_loop): Fs 0.6-2.6 % high, Fc <= 0.2 %, Vs 0.5-2.7 %,
        // delta 1.1-5.0 %, sigma <= 0.7 %, C 0.2-5.8 %, the virgin curve 0.59-3.66 % of Fs.
        // (In the 20 kHz tracking loop instead: Fs up to 7.4 %, Vs 14 %; in the earlier 10 kHz
        // kp 0.2 one: Fs 3.9 %, delta 9.3 %, C 12.6 %.) The bounds but for the virgin
        // curve (2 %: early breakaway), docs/identification.md. Fs and Fc at 4 % on the default
        // plant's real sense chain: its reading at the counter's bottom is ahead of the
        // bridge's brake (the bridge's delay, the amplifier's lag) and reads the current
        // 0.5-1 % over its mean; the worst draw's Fs +3.44 % (+2.59 % on the ideal bridge;
        // docs/results.md).
        prop_assert!(within(&acc, 0.04, 0.10, 0.15, 0.05), "{acc:?}");
    }
}

/// The default plant (the guideway present, its friction reflected to the motor through the
/// lead screw): the bench sees the sum of the two sources at the motor; the identified set
/// stands for both, so loading it while the device also compensates the guideway counts the
/// guideway twice. Measured: identified Fs 227.2 µN·m (actuator alone 220: +3.3 %; the sum
/// 236.3: -3.9 %), Fc 136.8 (125: +9.4 %; the sum 138.6: -1.3 %); sine RMS error 0.484 counts
/// with the true sets, 0.465 with the identified one and the guideway compensated again.
#[test]
fn on_the_default_plant_the_bench_sees_both_sources() {
    use gms_bench::{DeviceInfo, Plans, Ranges, identify_on, load_params, sine_test};
    let sc = Scenario::parse("[plant]\nvariability = 0.0\n", "test").unwrap();
    // The guideway's Fs and Fc (0.9 N, 0.75 N at the slide) at the motor: × lead / (2π gear).
    let r = sc.plant.lead / (2.0 * std::f64::consts::PI * sc.plant.gear_ratio);
    let (g_fs, g_fc) = (0.9 * r, 0.75 * r);
    let mut dev = LocalDevice::new(&sc).unwrap();
    let info = DeviceInfo::read(&mut dev).unwrap();
    let plans = Plans::new(&info, &Ranges::default()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let (_, id) = identify_on(&mut dev, &plans, dir.path(), 6, false, &mut |_, _, _| {}).unwrap();
    let (fs, fc) = (id.spec.fs.unwrap(), id.spec.fc.unwrap());
    let truth = sine_test(&mut dev, 2e-3, 1.0, 3.0).unwrap();
    let pf = gms_ident::paramfile::ParamFile {
        friction: id.spec.clone(),
        device: None,
    };
    load_params(&mut dev, &pf).unwrap();
    let twice = sine_test(&mut dev, 2e-3, 1.0, 3.0).unwrap();
    let rpc = 3.8e-6;
    eprintln!(
        "guideway at the motor: Fs {g_fs:.3e}, Fc {g_fc:.3e} N·m; identified Fs {fs:.4e} (actuator \
         220e-6: {:+.1} %, sum {:.4e}: {:+.1} %), Fc {fc:.4e} (actuator 125e-6: {:+.1} %, sum \
         {:.4e}: {:+.1} %); sine RMS: true sets {:.3} counts, identified set with the guideway \
         compensated again {:.3} counts",
        (fs / 220e-6 - 1.0) * 100.0,
        220e-6 + g_fs,
        (fs / (220e-6 + g_fs) - 1.0) * 100.0,
        (fc / 125e-6 - 1.0) * 100.0,
        125e-6 + g_fc,
        (fc / (125e-6 + g_fc) - 1.0) * 100.0,
        truth / rpc,
        twice / rpc
    );
    // Fc, the best-measured level, is the sum's, not the actuator's.
    assert!((fc / (125e-6 + g_fc) - 1.0).abs() < 0.03, "fc {fc}");
    assert!(fc > 125e-6 * 1.05, "fc {fc}");
}

/// The device's clock (`status` key `t`) \[s\].
fn device_time(dev: &mut LocalDevice) -> f64 {
    gms_bench::status(dev).unwrap().t
}

/// A bench that notes where the axis is after every wait.
struct Tracking<'a> {
    dev: &'a mut LocalDevice,
    lo: f64,
    hi: f64,
}

impl gms_link::DeviceLink for Tracking<'_> {
    fn request(
        &mut self,
        c: gms_core::protocol::Command<'_>,
    ) -> Result<(Vec<String>, String), gms_link::Error> {
        self.dev.request(c)
    }
    fn pass(&mut self, seconds: f64) -> Result<(), gms_link::Error> {
        // In slices, so that a run's far end is seen.
        let mut left = seconds;
        while left > 0.0 {
            let s = left.min(0.01);
            self.dev.pass(s)?;
            left -= s;
            let x = gms_bench::position(&mut *self.dev)
                .map_err(|e| gms_link::Error::Lost(e.to_string()))?;
            self.lo = self.lo.min(x);
            self.hi = self.hi.max(x);
        }
        Ok(())
    }
}

/// The stroke a bench identification uses stays within what its plans say (and so within
/// the window the device's limits are narrowed to); the figure for the docs.
#[test]
fn a_bench_identification_stays_within_its_planned_stroke() {
    use gms_bench::{DeviceInfo, LagPlan, Plans, Ranges, identify_on};
    let sc = Scenario::parse(QUIET, "test").unwrap();
    let mut dev = LocalDevice::new(&sc).unwrap();
    let info = DeviceInfo::read(&mut dev).unwrap();
    let plans = Plans::new(&info, &Ranges::default()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let t0 = device_time(&mut dev);
    let mut b = Tracking {
        dev: &mut dev,
        lo: 0.0,
        hi: 0.0,
    };
    identify_on(&mut b, &plans, dir.path(), 6, false, &mut |_, _, _| {}).unwrap();
    let (lo, hi) = (b.lo, b.hi);
    let t1 = device_time(&mut dev);
    let planned = plans
        .sliding
        .stroke(info.dt())
        .max(LagPlan::for_vs(info.vs, info.pos_hz).stroke());
    eprintln!(
        "stroke used: {lo:.3} to {hi:.3} rad from the start (planned at most ±{planned:.2} rad, \
         window ±{} rad); device time {:.1} s",
        plans.window,
        t1 - t0
    );
    assert!(lo > -planned && hi < planned, "{lo} {hi} vs {planned}");
}

/// A host that stalls: every `status` request (the staircase's fault check after each step)
/// first lets `stall` seconds of device time pass, as a loaded PC or a slow link would.
struct Stalling {
    dev: LocalDevice,
    stall: f64,
    /// The request that stalls.
    on: &'static str,
    /// The device time every request costs \[s\]: a link's round trip.
    latency: f64,
    /// Whether a `hold` was accepted.
    held: bool,
    /// A current \[A\] set just before the stall, if any: an axis that broke away and runs
    /// on under it, whatever the plant's edge between creep and runaway.
    push: Option<f64>,
    /// How many requests stalled.
    stalls: u32,
}

impl gms_link::DeviceLink for Stalling {
    fn request(
        &mut self,
        c: gms_core::protocol::Command<'_>,
    ) -> Result<(Vec<String>, String), gms_link::Error> {
        if c.to_string() == self.on {
            if let Some(amps) = self.push {
                self.dev.request(gms_core::protocol::Command::Current {
                    amps: amps as f32,
                    seconds: None,
                })?;
            }
            self.dev.pass(self.stall)?;
            self.stalls += 1;
        }
        if self.latency > 0.0 {
            self.dev.pass(self.latency)?;
        }
        let hold = c.to_string() == "hold";
        let r = self.dev.request(c);
        self.held |= hold && r.is_ok();
        r
    }
    fn pass(&mut self, seconds: f64) -> Result<(), gms_link::Error> {
        self.dev.pass(seconds)
    }
}

/// The quiet plant with the sense noise of 16 conversions (0.15 mA), for the guard's tests:
/// they need a breakaway that runs away under the staircase's held current. With the
/// default 8 conversions' 0.21 mA the dither lets the axis creep off at 87 % of Fs, where
/// the staircase sees the creep and holds after 0.024 rad, before any runaway.
fn runaway_plant() -> String {
    QUIET.replacen("[plant]\n", "[plant]\nadc_noise = 0.15e-3\n", 1)
}

/// The staircase's guard: with the host stalling 0.2 s after each step, the current is still
/// held long after breakaway; the device's narrowed stroke limits stop the axis (bridge off),
/// which the staircase takes as its end: the data before it kept, the fault cleared, the
/// limits put back. Without the guard the same stall runs the axis far beyond it.
#[test]
fn a_stalling_host_cannot_run_the_staircase_away() {
    use gms_bench::{Bench, PreslidingPlan, position, presliding};
    let sc = Scenario::parse(&runaway_plant(), "test").unwrap();
    let run = |guard: f64| {
        let mut b = Stalling {
            dev: LocalDevice::new(&sc).unwrap(),
            stall: 0.2,
            on: "status",
            latency: 0.0,
            held: false,
            push: None,
            stalls: 0,
        };
        let mut plan = PreslidingPlan::new(220e-6 / 100.0 / 6.6e-3, 150);
        plan.guard = guard;
        let mut pre = Vec::new();
        let r = presliding(&mut b, &plan, &mut pre);
        let (_, st) = b.dev.console("status").unwrap();
        // The axis at rest where it stopped.
        b.wait(0.5).unwrap();
        (r, pre.len(), position(&mut b).unwrap(), st, b)
    };
    let (r, n, x, st, mut b) = run(0.5);
    eprintln!("guard 0.5 rad: {n} steps, stopped at {x:.3} rad; {st}");
    r.unwrap();
    assert!(n > 80 && n < 150, "{n} steps");
    // Stopped at the guard, give or take the coast with the bridge off.
    assert!(x > 0.5 && x < 0.55, "x {x}");
    assert!(st.contains("faults=0") && st.contains("enabled=0"), "{st}");
    let lim = |b: &mut Stalling, p: &str| {
        let (_, v) = b.dev.console(&format!("get {p}")).unwrap();
        v.trim().parse::<f64>().unwrap()
    };
    assert_eq!(
        (lim(&mut b, "lim.pos_min"), lim(&mut b, "lim.pos_max")),
        (-50.0, 50.0)
    );
    // The same stall with the guard out of reach.
    let (r, n2, x2, _, _) = run(40.0);
    eprintln!("guard 40 rad: {n2} steps, stopped at {x2:.3} rad");
    r.unwrap();
    // The same staircase; the guarded run may end a step earlier (a step whose check found
    // the guard reached is not recorded, though its dwell may have come before breakaway).
    assert!(n2 == n || n2 == n + 1, "{n2} vs {n}");
    assert!(x2 > 1.0, "x {x2}");
}

/// A host late with the hold after it saw the breakaway (1 s of device time: a loaded host
/// against `hil-sim serve --speed 20`, as once in CI): the axis, still under current, runs on
/// to the guard, the hold is refused (the bridge is off) — the staircase's end, as when the
/// guard is reached during a step: its data kept, the fault cleared. On this plant the
/// staircase may see its "breakaway" in pre-sliding (the Table 1 blocks' last breakpoints
/// lie beyond the 20 mrad window: 24 mrad at 82 % of Fs, creeping at 30 µrad/s), where the
/// staircase's current does not run the axis away; so the late host holds 1.5 × Fs / k_M
/// over its stall, as an axis that had broken away would run under it.
#[test]
fn a_host_late_with_the_hold_ends_the_staircase_at_the_guard() {
    use gms_bench::{Bench, position, presliding};
    let sc = Scenario::parse(&runaway_plant(), "test").unwrap();
    let mut b = Stalling {
        dev: LocalDevice::new(&sc).unwrap(),
        stall: 2.0,
        on: "hold",
        latency: 0.0,
        held: false,
        push: None,
        stalls: 0,
    };
    // The identification's own staircase (the erase first, the measuring loop, its guard).
    let info = gms_bench::DeviceInfo::read(&mut b).unwrap();
    b.push = Some(1.5 * info.fs / info.k_m);
    let plan = gms_bench::Plans::new(&info, &gms_bench::Ranges::default())
        .unwrap()
        .presliding;
    let mut pre = Vec::new();
    let r = presliding(&mut b, &plan, &mut pre);
    b.dev.wait(0.5).unwrap();
    let x = position(&mut b).unwrap();
    let (_, st) = b.dev.console("status").unwrap();
    eprintln!(
        "{} steps, a hold asked {} time(s), accepted {}; stopped at {x:.3} rad; {st}",
        pre.len(),
        b.stalls,
        b.held
    );
    r.unwrap();
    // The staircase ended by its hold, which came after the guard: refused.
    assert!(b.stalls == 1 && !b.held, "{} {}", b.stalls, b.held);
    assert!(pre.len() > 80 && pre.len() < 150, "{} steps", pre.len());
    assert!(x > 0.5 && x < 0.6, "x {x}");
    assert!(st.contains("faults=0") && st.contains("enabled=0"), "{st}");
}

/// A hold that lands just inside the guard with the axis still running: the position loop
/// brakes it past the guard after the hold was accepted (seen in CI on the image on emulated
/// silicon, where the next experiment was then refused). The host's stall is bisected to the
/// edge between a hold that stops the axis inside the guard and one that comes after the
/// guard stopped it; on both sides, and at the edge, the staircase ends cleanly: no fault
/// left latched once the axis has come to rest.
#[test]
fn a_hold_at_the_guards_edge_leaves_no_fault() {
    use gms_bench::{Bench, PreslidingPlan, position, presliding};
    let sc = Scenario::parse(&runaway_plant(), "test").unwrap();
    let run = |stall: f64| {
        let mut b = Stalling {
            dev: LocalDevice::new(&sc).unwrap(),
            stall,
            on: "hold",
            latency: 2e-3,
            held: false,
            push: None,
            stalls: 0,
        };
        let mut plan = PreslidingPlan::new(220e-6 / 100.0 / 6.6e-3, 150);
        plan.erase = false;
        let mut pre = Vec::new();
        let r = presliding(&mut b, &plan, &mut pre);
        // The axis at rest, wherever it stopped.
        b.wait(0.5).unwrap();
        let x = position(&mut b).unwrap();
        let (_, st) = b.dev.console("status").unwrap();
        assert!(
            r.is_ok() && st.contains("faults=0"),
            "stall {stall:.4} s: {r:?}, stopped at {x:.4} rad; {st}"
        );
        (x, b.held)
    };
    // Stalls of 0 and 2 s: the axis stops inside the guard (0.5 rad), and at it.
    let (mut lo, mut hi) = (0.0, 2.0);
    assert!(run(lo).0 < 0.5 && run(hi).0 > 0.5);
    // The case CI met: a hold accepted, the axis stopped beyond the guard.
    let mut braked_past = false;
    for _ in 0..22 {
        let mid = 0.5 * (lo + hi);
        let (x, held) = run(mid);
        braked_past |= held && x > 0.5;
        if x < 0.5 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    assert!(braked_past, "no hold braked the axis past the guard");
    eprintln!("the edge: a stall of {lo:.4}-{hi:.4} s");
}
