//! The parameter file ↔ the device's settings, in one place: what a file makes of a device's
//! settings ([`settings_with`]: the protocol's own setters and validation, on the host, before
//! anything is sent), the file of a set of settings ([`file_of`]), and both on a device
//! ([`load`], [`dump`]). What the device cannot hold is refused with the reason, whole.

use crate::Error;
use gms_core::numtext::Num;
use gms_core::protocol::ParamId;
use gms_core::protocol::{self, Access, PARAMS, Settings};
use gms_ident::paramfile::{BlockSpec, FrictionSpec, ModelKind, ParamFile};

use crate::client::Bench;
use crate::settings;

/// The blocks the device's compensator holds.
pub const DEVICE_BLOCKS: usize = 6;

/// An f32 setting as the device writes it, read back as f64 (its shortest decimal).
fn wide(x: f32) -> f64 {
    Num(x).to_string().parse().unwrap_or(x as f64)
}

/// The `(path, value)` sets a parameter file asks of a device, in the order they apply (the
/// block count before the blocks), or why the device cannot hold the file.
pub fn sets_of(pf: &ParamFile) -> Result<Vec<(String, String)>, Error> {
    let f = &pf.friction;
    let n = f.blocks.as_ref().map_or(0, Vec::len);
    if f.negative.is_some() {
        return Err(Error::Params(
            "[friction.negative]: the device's compensator has one Stribeck curve for both \
             directions; nothing loaded (fit without --asymmetric, or remove the table)"
                .into(),
        ));
    }
    if f.model != ModelKind::Gms || !(1..=DEVICE_BLOCKS).contains(&n) {
        return Err(Error::Params(format!(
            "[friction] must be a gms model of 1 to {DEVICE_BLOCKS} blocks for the device's \
             compensator (it is {} with {n} blocks)",
            f.model
        )));
    }
    f.gms_params::<DEVICE_BLOCKS>()
        .map_err(|e| e.to_string())
        .and_then(|p| p.validate().map_err(|e| e.to_string()))
        .map_err(|e| Error::Params(format!("[friction] {e}")))?;
    let mut sets: Vec<(String, String)> = vec![(ParamId::GmsBlocks.path().into(), format!("{n}"))];
    for (k, v) in [
        ("fs", f.fs),
        ("fc", f.fc),
        ("vs", f.vs),
        ("delta", f.delta.or(Some(1.0))),
        ("sigma", f.sigma.or(Some(0.0))),
        ("c", f.c),
    ] {
        if let Some(v) = v {
            sets.push((format!("gms.{k}"), format!("{v}")));
        }
    }
    for (i, blk) in f.blocks.iter().flatten().enumerate() {
        sets.push((format!("gms.k{}", i + 1), format!("{}", blk.k)));
        sets.push((format!("gms.a{}", i + 1), format!("{}", blk.alpha)));
    }
    for (k, v) in pf.device.iter().flatten() {
        let v = match v {
            toml::Value::Float(x) => format!("{x}"),
            toml::Value::Integer(x) => format!("{x}"),
            toml::Value::String(s) => s.clone(),
            _ => return Err(Error::Params(format!("[device] `{k}` is not a value"))),
        };
        sets.push((k.clone(), v));
    }
    Ok(sets)
}

/// The settings `base` with the parameter file applied: each of its sets through the
/// protocol's own setter (ranges, names), then the whole set validated as the device would.
pub fn settings_with(pf: &ParamFile, base: &Settings) -> Result<Settings, Error> {
    let mut s = *base;
    for (path, value) in sets_of(pf)? {
        s = protocol::with_value_staged(&s, &path, &value)
            .map_err(|e| Error::Params(format!("{path} = {value}: {}", e.reason)))?;
    }
    s.validate()
        .map_err(|e| Error::Params(format!("the file's set would be invalid: {e}")))?;
    Ok(s)
}

/// The parameter file of a set of settings: `[friction]` (the compensator's GMS model, its
/// blocks in use) and `[device]` (every other settable parameter, by protocol path), values as
/// the device writes them.
pub fn file_of(s: &Settings) -> ParamFile {
    let g = &s.ff.actuator;
    let friction = FrictionSpec {
        model: ModelKind::Gms,
        fs: Some(wide(g.stribeck.fs)),
        fc: Some(wide(g.stribeck.fc)),
        vs: Some(wide(g.stribeck.vs)),
        delta: Some(wide(g.stribeck.delta)),
        sigma: Some(wide(g.sigma)),
        c: Some(wide(g.c)),
        blocks: Some(
            g.blocks
                .iter()
                .take(g.blocks_used())
                .map(|b| BlockSpec {
                    k: wide(b.k),
                    alpha: wide(b.alpha),
                })
                .collect(),
        ),
        ..FrictionSpec::default()
    };
    let mut device = toml::Table::new();
    for p in PARAMS {
        if p.path.starts_with("gms.") {
            continue;
        }
        let value = match p.access {
            Access::Number { get, .. } => toml::Value::Float(wide(get(s))),
            Access::Mode => toml::Value::String(s.ff.mode.name().into()),
            Access::Estimate(_) => continue,
        };
        device.insert(p.path.into(), value);
    }
    ParamFile {
        friction,
        device: Some(device),
    }
}

/// Loads a parameter file into a device: its settings read, the file applied and validated on
/// the host, the differences sent as one set. Returns how many parameters changed. Nothing
/// changes when the file cannot be held or the device refuses.
pub fn load(b: &mut impl Bench, pf: &ParamFile) -> Result<usize, Error> {
    let now = settings::read(b)?;
    let to = settings_with(pf, &now)?;
    settings::write(b, &to)
}

/// The device's settings as a parameter file.
pub fn dump(b: &mut impl Bench) -> Result<ParamFile, Error> {
    Ok(file_of(&settings::read(b)?))
}
