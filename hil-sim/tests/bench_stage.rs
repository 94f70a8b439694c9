//! The bench identification (`gms_bench::identify_on`, what `gms-tune identify` runs)
//! against plants that are not the compensator's model: a 4-block friction, applied to the
//! device as 4 blocks, and a compliant stage (`[plant.compliance]` 700 Hz, zeta 0.03). The
//! device starts from its defaults (Table 1): the tool is told nothing of the truth.

use crate::common;
use common::{QUIET, identification_errors};
use gms_bench::{DeviceInfo, Plans, Ranges, get_param, identify_on, load_params, sine_test};
use gms_core::protocol::ParamId;
use gms_ident::paramfile::{FrictionSpec, ParamFile};
use hil_sim::device::LocalDevice;
use hil_sim::scenario::Scenario;

/// A 4-block truth: Table 1's sliding friction, breakpoints 0.1, 0.8, 3 and 7 mrad.
const FOUR: &str = "[plant.actuator]\nmodel = \"gms\"\nfs = 220e-6\nfc = 125e-6\nvs = 0.2\n\
                    delta = 0.9\nsigma = 10.5e-6\nc = 5e-3\nblocks = [{ k = 1.21, alpha = 0.55 }, \
                    { k = 0.055, alpha = 0.2 }, { k = 0.011, alpha = 0.15 }, \
                    { k = 3.142857e-3, alpha = 0.1 }]\n";

/// Identifies `blocks` blocks on a device over the scenario `text`; prints and returns the
/// errors against the plant's actuator friction, the identified set and the device.
fn identify(text: &str, blocks: usize, what: &str) -> ([f64; 7], FrictionSpec, LocalDevice) {
    let sc = Scenario::parse(text, "test").unwrap();
    let mut dev = LocalDevice::new(&sc).unwrap();
    let info = DeviceInfo::read(&mut dev).unwrap();
    let plans = Plans::new(&info, &Ranges::default()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let (g, id) = identify_on(
        &mut dev,
        &plans,
        dir.path(),
        blocks,
        false,
        &mut |_, _, _| {},
    )
    .unwrap();
    let e = identification_errors(&sc.plant.actuator, &g, &id.spec);
    eprintln!(
        "{what}: errors fs {:.1} %, fc {:.1} %, vs {:.1} %, delta {:.1} %, sigma {:.1} %, \
         c {:.1} %, virgin curve {:.2} % of Fs",
        e[0] * 100.0,
        e[1] * 100.0,
        e[2] * 100.0,
        e[3] * 100.0,
        e[4] * 100.0,
        e[5] * 100.0,
        e[6] * 100.0
    );
    (e, id.spec, dev)
}

/// The bench-identification bounds (hil-sim/tests/bench_ident.rs, docs/identification.md):
/// Fs and Fc 4.5 %, Vs and sigma 10 %, delta 10 %, C 17 %, the virgin curve 5 % of Fs.
fn within_bench_bounds(e: &[f64; 7]) -> bool {
    e[0] < 0.045
        && e[1] < 0.045
        && e[2] < 0.10
        && e[3] < 0.10
        && e[4] < 0.10
        && e[5] < 0.17
        && e[6] < 0.05
}

/// A plant whose friction has 4 blocks, identified with 4 and applied: the device then holds 4
/// blocks (`gms.blocks` 4, blocks 5 and 6 unused) and tracks the sine test within 10 % of a
/// device that holds the true set.
#[test]
fn a_four_block_plant_is_identified_and_applied_as_four_blocks() {
    let text = format!("{QUIET}\n{FOUR}");
    let (e, spec, mut dev) = identify(&text, 4, "4-block plant, 4 blocks fitted");
    assert!(within_bench_bounds(&e), "{e:?}");
    load_params(
        &mut dev,
        &ParamFile {
            friction: spec,
            device: None,
        },
    )
    .unwrap();
    assert_eq!(get_param(&mut dev, ParamId::GmsBlocks).unwrap(), 4.0);
    assert_eq!(get_param(&mut dev, ParamId::GmsK5).unwrap(), 0.0);
    let identified = sine_test(&mut dev, 2e-3, 1.0, 3.0).unwrap();
    let truth_text = text.replace(
        "[controller.ff]\nguideway = false\n",
        "[controller.ff]\nguideway = false\nstart = \"plant\"\n",
    );
    let mut truth = LocalDevice::new(&Scenario::parse(&truth_text, "test").unwrap()).unwrap();
    assert_eq!(get_param(&mut truth, ParamId::GmsBlocks).unwrap(), 4.0);
    let true_set = sine_test(&mut truth, 2e-3, 1.0, 3.0).unwrap();
    eprintln!(
        "sine RMS error: true 4-block set {:.3} counts, identified {:.3} counts ({:+.1} %)",
        true_set / 3.8e-6,
        identified / 3.8e-6,
        (identified / true_set - 1.0) * 100.0
    );
    assert!(identified < 1.10 * true_set, "{identified} vs {true_set}");
}

/// A compliant stage (the screw/nut's mode at 700 Hz, zeta 0.03, the default 0.2 kg slide):
/// the identification of Table 1 is within the bench bounds, as on the rigid stage.
#[test]
fn a_compliant_stage_is_identified_within_the_bench_bounds() {
    let text = format!("{QUIET}\n[plant.compliance]\nf_hz = 700.0\nzeta = 0.03\n");
    let (e, _, _) = identify(&text, 6, "compliant stage 700 Hz, 0.2 kg slide");
    assert!(within_bench_bounds(&e), "{e:?}");
}

/// The same with a heavy load on the slide (20 kg: 11 % of the inertia at the motor; the
/// resonance at 740 Hz shows at the encoder): within the bench bounds too. Its Stribeck shape
/// factor delta came out 12.0 % off (bound 10 %) while the sliding runs went in the tracking
/// loop, whose speed ripple the slide's swing added to; in the measuring loop
/// (`gms_ident::gains::measuring_loop`) 4.3 %.
#[test]
fn a_compliant_stage_with_a_heavy_slide_is_identified_within_the_bench_bounds() {
    let text =
        format!("{QUIET}\n[plant.compliance]\nf_hz = 700.0\nzeta = 0.03\nslide_mass = 20.0\n");
    let (e, _, _) = identify(&text, 6, "compliant stage 700 Hz, 20 kg slide");
    assert!(within_bench_bounds(&e), "{e:?}");
}

/// A parameter file with `[friction.negative]` (an asymmetric fit) is refused by the device's
/// loader with the reason, and nothing is loaded (the device cannot hold a second curve).
#[test]
fn an_asymmetric_set_is_refused_whole() {
    let sc = Scenario::parse(QUIET, "test").unwrap();
    let mut dev = LocalDevice::new(&sc).unwrap();
    let mut spec = sc.plant.actuator.clone();
    spec.fs = Some(250e-6);
    spec.negative = Some(gms_ident::paramfile::NegativeSpec {
        fs: Some(240e-6),
        ..Default::default()
    });
    let err = load_params(
        &mut dev,
        &ParamFile {
            friction: spec,
            device: None,
        },
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("[friction.negative]"), "{err}");
    assert_eq!(get_param(&mut dev, ParamId::GmsFs).unwrap(), 220e-6);
}
