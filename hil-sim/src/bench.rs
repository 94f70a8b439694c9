//! The bench's experiments on the virtual device: `hil-sim experiment --rig device` runs the
//! same workflows of `gms-bench` as `gms-tune identify` runs on a board.

use gms_core::protocol::ParamId;
use gms_ident::paramfile::FrictionSpec;

use crate::Error;
use crate::experiment::Kind;

/// Runs `kind` (pre-sliding, sliding or lag) on the device core with the actuator friction
/// `spec` of any model (drawn within ±variability with `seed`); returns the CSV text, in the
/// formats of [`crate::experiment::run`]. The experiments' ranges come from the device's parameters, as on a
/// bench from the values the user set: the device starts from the truth's nominal friction
/// where it can hold it (`ff.start = "plant"`: a GMS of up to 6 blocks exactly, otherwise
/// the Stribeck curve), and from its default model for a GMS of more blocks; `ranges` as
/// `gms-tune identify` takes them (`Ranges::default()`: from those parameters).
pub fn run_on_device(
    kind: Kind,
    spec: &FrictionSpec,
    variability: f64,
    seed: u64,
    ranges: &gms_bench::Ranges,
) -> Result<String, Error> {
    use gms_bench::{self, DeviceInfo, LagPlan, Plans};
    if kind == Kind::Guideway {
        return Err(Error::Run(
            "the guideway experiment needs the slide's rig (--rig ideal)".into(),
        ));
    }
    let mut sc = crate::scenario::Scenario::parse(
        "[plant.guideway]\nfs = 1e-6\nfc = 1e-6\n[controller.ff]\nguideway = false\n",
        "hil-sim experiment",
    )
    .map_err(|e| Error::Run(e.to_string()))?;
    sc.plant.actuator = spec.clone();
    sc.plant.variability = variability;
    sc.plant.seed = seed;
    sc.set_controller("ff.start", toml::Value::String("plant".into()));
    if sc.controller_params().is_err() {
        // A truth the device cannot hold (a GMS of more than 6 blocks): its Stribeck curve
        // on the device's blocks, as a user would enter what they know.
        let mut g = spec.clone();
        g.model = gms_ident::paramfile::ModelKind::Static;
        g.blocks = None;
        g.c = None;
        let base = gms_core::device::default_settings().ff.actuator;
        let p = crate::scenario::compensator_from_plant(&g, &base).map_err(Error::Run)?;
        for (path, v) in [
            (ParamId::GmsFs, p.stribeck.fs),
            (ParamId::GmsFc, p.stribeck.fc),
            (ParamId::GmsVs, p.stribeck.vs),
            (ParamId::GmsDelta, p.stribeck.delta),
            (ParamId::GmsSigma, p.sigma),
        ] {
            sc.set_controller(path.path(), toml::Value::Float(v as f64));
        }
        sc.set_controller("ff.start", toml::Value::String("device".into()));
    }
    let mut dev = crate::device::LocalDevice::new(&sc).map_err(|e| Error::Run(e.to_string()))?;
    let info = DeviceInfo::read(&mut dev).map_err(|e| Error::Run(e.to_string()))?;
    let plans = Plans::new(&info, ranges).map_err(|e| Error::Run(e.to_string()))?;
    if kind == Kind::Sliding {
        plans
            .check_sliding()
            .map_err(|e| Error::Run(e.to_string()))?;
    }
    let run = |e: gms_bench::Error| Error::Run(e.to_string());
    Ok(match kind {
        Kind::Presliding => {
            let mut out = Vec::new();
            gms_bench::presliding(&mut dev, &plans.presliding, &mut out).map_err(run)?;
            gms_bench::presliding_csv(&out)
        }
        Kind::Sliding => {
            let mut out = Vec::new();
            gms_bench::sliding(&mut dev, &plans.sliding, &mut out).map_err(run)?;
            gms_bench::sliding_csv(&out)
        }
        _ => {
            let (t, x, f) =
                gms_bench::lag(&mut dev, &LagPlan::for_vs(info.vs, info.pos_hz)).map_err(run)?;
            gms_bench::lag_csv(&t, &x, &f)
        }
    })
}
