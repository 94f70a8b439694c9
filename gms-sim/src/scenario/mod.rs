//! Scenario files: plant, controller and reference of one simulated run.
//!
//! The complete default is `default_scenario.toml` (printed by
//! `hil-sim run --print-default-scenario`); a scenario file may leave out any key, which then
//! takes that default, and an unknown key is an error naming it.

mod plant;

mod reference;

pub use plant::*;

pub use reference::*;

use crate::Error;
use std::path::Path;
use std::sync::OnceLock;

use gms_core::GmsParams;
use gms_core::control::controller::{ControllerParams, FfMode};
use gms_core::control::reference::Segment;
use gms_core::protocol;
use serde::{Deserialize, Serialize};

use gms_ident::paramfile::{FileError, FrictionSpec, parse_toml, read_text};

/// The default scenario, with a comment on every key.
pub const DEFAULT_SCENARIO: &str = include_str!("default_scenario.toml");

/// Blocks of the compensator's GMS models (the controller is built for this many).
pub const FF_BLOCKS: usize = 6;

/// The default scenario as a TOML table (every key present).
fn default_table() -> &'static toml::Table {
    static D: OnceLock<toml::Table> = OnceLock::new();
    D.get_or_init(|| {
        toml::from_str(DEFAULT_SCENARIO).expect("the built-in default scenario parses")
    })
}

/// Merges `user` into `base`: tables key by key (recursively), everything else replaced.
fn merge(base: &mut toml::Table, user: toml::Table) {
    for (k, v) in user {
        match (base.get_mut(&k), v) {
            (Some(toml::Value::Table(b)), toml::Value::Table(u)) => merge(b, u),
            (_, v) => {
                base.insert(k, v);
            }
        }
    }
}

/// A whole scenario.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scenario {
    /// The simulated axis.
    pub plant: Plant,
    /// The controller: the device's parameters by their protocol paths (`pos.kp`, `ff.mode`,
    /// …, as nested tables: `[controller.pos] kp = 0.2`), plus two keys of the scenario only:
    /// `ff.guideway` (compensate the guideway too) and `ff.start` (`"device"`: the compensator
    /// starts from the device's default friction model; `"plant"`: from the plant's nominal
    /// friction). What is left out is the device's default
    /// ([`gms_core::device::default_settings`]); `motor.*` and the encoder resolution, supply
    /// and transmission default to the plant's values (the axis the user describes).
    pub controller: toml::Table,
    /// The reference trajectory.
    pub reference: Reference,
}

impl Default for Scenario {
    fn default() -> Self {
        Scenario::parse(DEFAULT_SCENARIO, "default scenario")
            .expect("the default scenario is valid")
    }
}

impl Scenario {
    /// Reads and checks a scenario file; errors are one line naming file, position and key.
    pub fn load(path: &Path) -> Result<Scenario, FileError> {
        let (file, text) = read_text(path)?;
        Self::parse(&text, &file)
    }

    /// Parses and checks scenario text; `file` names it in errors.
    pub fn parse(text: &str, file: &str) -> Result<Scenario, FileError> {
        let mut user: toml::Table = parse_toml(text, file)?;
        counts_to_radians(&mut user).map_err(|reason| FileError {
            file: file.to_string(),
            at: None,
            reason,
        })?;
        let mut merged = default_table().clone();
        merge(&mut merged, user);
        let sc: Scenario =
            serde_path_to_error::deserialize(toml::Value::Table(merged)).map_err(|e| {
                let path = e.path().to_string();
                let msg = e.inner().message().replace('\n', " ").trim().to_string();
                FileError {
                    file: file.to_string(),
                    at: None,
                    reason: if path == "." {
                        msg
                    } else {
                        format!("{path}: {msg}")
                    },
                }
            })?;
        sc.check().map_err(|e| FileError {
            file: file.to_string(),
            at: None,
            reason: e.to_string(),
        })?;
        Ok(sc)
    }

    /// Checks everything that the types do not: ranges, the friction models, the controller.
    pub fn check(&self) -> Result<(), Error> {
        self.check_inner().map_err(Error::Scenario)
    }

    fn check_inner(&self) -> Result<(), String> {
        let p = &self.plant;
        let pos = [
            ("plant.supply.volts", p.supply.volts),
            ("plant.resistance", p.resistance),
            ("plant.inductance", p.inductance),
            ("plant.k_m", p.k_m),
            ("plant.inertia", p.inertia),
            ("plant.gear_ratio", p.gear_ratio),
            ("plant.lead", p.lead),
            ("plant.rad_per_count", p.rad_per_count),
            ("plant.adc_range", p.adc_range),
        ];
        for (name, v) in pos {
            if !(v.is_finite() && v > 0.0) {
                return Err(format!("{name} must be a finite number > 0"));
            }
        }
        for (name, v) in [("plant.k_e", p.k_e), ("plant.adc_noise", p.adc_noise)] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(format!("{name} must be a finite number >= 0"));
            }
        }
        if !(p.variability.is_finite() && (0.0..0.9).contains(&p.variability)) {
            return Err("plant.variability must be in [0, 0.9)".into());
        }
        if !(p.drift.amount.is_finite() && p.drift.amount.abs() < 0.9) {
            return Err("plant.drift.amount must be in (-0.9, 0.9)".into());
        }
        for (name, v) in [
            ("plant.drift.time", p.drift.time),
            ("plant.drift.period", p.drift.period),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(format!("{name} must be a finite number > 0"));
            }
        }
        if !(p.encoder_glitch.at.is_finite() && p.encoder_glitch.at >= 0.0) {
            return Err("plant.encoder_glitch.at must be a finite number >= 0".into());
        }
        if p.encoder_glitch.counts.unsigned_abs() > 1 << 40 {
            return Err("plant.encoder_glitch.counts must be within ±2^40".into());
        }
        if !(2..=24).contains(&p.adc_bits) {
            return Err("plant.adc_bits must be in 2..=24".into());
        }
        if !(2..=1_000_000).contains(&p.pwm_steps) {
            return Err("plant.pwm_steps must be in 2..=1000000".into());
        }
        if !(10..=1000).contains(&p.substeps) {
            return Err("plant.substeps must be in 10..=1000".into());
        }
        let c = &p.compliance;
        if !(c.f_hz.is_finite() && c.f_hz >= 0.0) {
            return Err("plant.compliance.f_hz must be a finite number >= 0 (0: rigid)".into());
        }
        if !(c.zeta.is_finite() && (0.0..1.0).contains(&c.zeta)) {
            return Err("plant.compliance.zeta must be in [0, 1)".into());
        }
        if !(c.slide_mass.is_finite() && c.slide_mass > 0.0) {
            return Err("plant.compliance.slide_mass must be a finite number > 0".into());
        }
        if c.f_hz > 0.0 {
            let j_l = c.slide_mass * p.ratio() * p.ratio();
            if j_l >= 0.99 * p.inertia {
                return Err(format!(
                    "plant.compliance.slide_mass: the slide's {j_l:.3e} kg·m^2 at the motor \
                     leaves no rotor inertia of plant.inertia = {:.3e}",
                    p.inertia
                ));
            }
            // The resonance must be resolved by the integration step (symplectic Euler is
            // stable for ω dt < 2; keep it accurate).
            let f_r = c.f_hz * (p.inertia / (p.inertia - j_l)).sqrt();
            let f_step = 20_000.0 * p.substeps as f64;
            if 2.0 * std::f64::consts::PI * f_r / f_step > 0.1 {
                return Err(format!(
                    "plant.compliance.f_hz: the resonance at {f_r:.0} Hz is too fast for the \
                     integration step (1/{f_step:.0} s): raise plant.substeps"
                ));
            }
        }
        if !(p.sense.offset_codes.is_finite() && p.sense.offset_codes.abs() <= 1000.0) {
            return Err("plant.sense.offset_codes must be a finite number within ±1000".into());
        }
        let in_range = |x: f64, lo: f64, hi: f64| x.is_finite() && (lo..=hi).contains(&x);
        if !in_range(p.sense.bandwidth_hz, 0.0, 1e9) {
            return Err("plant.sense.bandwidth_hz must be a finite number >= 0 (0: none)".into());
        }
        if !(in_range(p.sense.swing_v, 0.0, 1.0) && p.sense.swing_v < 1.0) {
            return Err("plant.sense.swing_v must be a finite number in [0, 1) V".into());
        }
        if !in_range(p.sense.recovery_s, 0.0, 10e-6) {
            return Err("plant.sense.recovery_s must be a finite number in [0, 10e-6] s".into());
        }
        if !in_range(p.sense.edge_a, 0.0, 10.0) {
            return Err("plant.sense.edge_a must be a finite number in [0, 10] A".into());
        }
        let b = &p.bridge;
        for (key, v, hi) in [
            ("plant.bridge.dead_time_s", b.dead_time_s, 5e-6),
            ("plant.bridge.delay_s", b.delay_s, 5e-6),
            ("plant.bridge.r_on_ohm", b.r_on_ohm, 10.0),
            ("plant.bridge.c_node_f", b.c_node_f, 10e-9),
            ("plant.supply.r_source_ohm", p.supply.r_source_ohm, 10.0),
        ] {
            if !in_range(v, 0.0, hi) {
                return Err(format!("{key} must be a finite number in [0, {hi}]"));
            }
        }
        if p.supply.volts > 60.0 {
            return Err("plant.supply.volts must be at most 60 V".into());
        }
        let r = &p.ripple;
        if !(r.amplitude.is_finite() && r.phase.is_finite()) {
            return Err("plant.ripple.amplitude and phase must be finite numbers".into());
        }
        if r.per_rev == 0 {
            return Err("plant.ripple.per_rev must be >= 1".into());
        }
        for (i, h) in r.harmonics.iter().enumerate() {
            if h.order == 0 || !(h.amplitude.is_finite() && h.phase.is_finite()) {
                return Err(format!(
                    "plant.ripple.harmonics[{i}]: order >= 1, finite amplitude and phase"
                ));
            }
        }
        if !(r.screw_friction.is_finite() && r.screw_friction.abs() < 0.9) {
            return Err("plant.ripple.screw_friction must be in (-0.9, 0.9)".into());
        }
        if !r.screw_phase.is_finite() {
            return Err("plant.ripple.screw_phase must be a finite number".into());
        }
        p.actuator
            .build()
            .map_err(|e| format!("plant.actuator: {e}"))?;
        p.guideway
            .build()
            .map_err(|e| format!("plant.guideway: {e}"))?;
        self.controller_params()?;
        self.segments()?;
        Ok(())
    }

    /// Sets one controller parameter by its protocol path (e.g. `ff.mode`).
    pub fn set_controller(&mut self, path: &str, value: toml::Value) {
        let mut table = &mut self.controller;
        let mut parts = path.split('.').peekable();
        while let Some(part) = parts.next() {
            if parts.peek().is_none() {
                table.insert(part.to_string(), value);
                return;
            }
            let entry = table
                .entry(part.to_string())
                .or_insert_with(|| toml::Value::Table(toml::Table::new()));
            if !entry.is_table() {
                *entry = toml::Value::Table(toml::Table::new());
            }
            let Some(t) = entry.as_table_mut() else {
                return;
            };
            table = t;
        }
    }

    /// The feedforward mode the controller runs.
    pub fn mode(&self) -> FfMode {
        self.controller_params()
            .map(|p| p.ff.mode)
            .unwrap_or_default()
    }

    /// The controller's parameters: the device's defaults with the axis the user describes to
    /// the device taken from the plant (encoder resolution, motor constants, supply,
    /// transmission ratio; with a real bridge, its on-resistance in `motor.r` and its dead
    /// time in `drive.dead_time`, as commissioning measures them); the compensator's friction is the device's default model unless
    /// `[controller.ff] start = "plant"` (then the plant's nominal friction, where the device
    /// can hold it: see [`compensator_from_plant`]); then the `[controller]` table by protocol
    /// paths, each checked against the protocol's range table, and the whole set validated.
    /// The plant's friction is the truth, never read here otherwise. Errors name the scenario
    /// key.
    pub fn controller_params(&self) -> Result<ControllerParams<FF_BLOCKS>, Error> {
        self.controller_params_inner().map_err(Error::Scenario)
    }

    fn controller_params_inner(&self) -> Result<ControllerParams<FF_BLOCKS>, String> {
        let p = &self.plant;
        let mut s = gms_core::device::default_settings();
        s.counts_per_rev = device_counts_per_rev(p.rad_per_count);
        s.sense_v_per_a = crate::device::SIM_ADC_VREF / 2.0 / p.adc_range as f32;
        s.motor.k_m = p.k_m as f32;
        // The bridge as commissioning finds it: its switches in the winding's path, its dead
        // time compensated.
        s.motor.r = p.path_resistance() as f32;
        s.dead_time = p.real_bridge().map_or(0.0, |b| b.dead_time_s) as f32;
        s.motor.k_e = p.k_e as f32;
        s.v_supply = p.supply.volts as f32;
        s.ff.ratio = p.ratio() as f32;
        let mut guideway = true;
        let mut start = Start::Device;
        let mut keys = Vec::new();
        flatten("", &self.controller, &mut keys);
        // The starting model first, so that `gms.*` keys edit it whatever the key order.
        for (path, value) in &keys {
            let key = format!("controller.{path}");
            match path.as_str() {
                "ff.guideway" => {
                    guideway = value
                        .as_bool()
                        .ok_or_else(|| format!("{key}: true or false"))?;
                }
                "ff.start" => {
                    start = match value.as_str() {
                        Some("device") => Start::Device,
                        Some("plant") => Start::Plant,
                        _ => return Err(format!("{key}: \"device\" or \"plant\"")),
                    };
                }
                _ => {}
            }
        }
        let default_guideway = s.ff.guideway;
        if start == Start::Plant {
            s.ff.actuator = compensator_from_plant(&p.actuator, &s.ff.actuator)
                .map_err(|e| format!("plant.actuator: {e} (controller.ff.start = \"plant\")"))?;
        }
        for (path, value) in keys {
            let key = format!("controller.{path}");
            if path == "ff.guideway" || path == "ff.start" {
                continue;
            }
            let param = protocol::find(&path).ok_or_else(|| {
                format!(
                    "{key}: unknown key (the keys are the protocol's paths: `gms-tune send list`)"
                )
            })?;
            let text = match value {
                toml::Value::Float(f) => format!("{f:e}"),
                toml::Value::Integer(i) => format!("{i}"),
                toml::Value::String(t) => t.clone(),
                _ => return Err(format!("{key}: a number or a name")),
            };
            protocol::set_param(&mut s, param, &text).map_err(|e| match param.access {
                protocol::Access::Number { min, max, .. } => format!(
                    "{key} = {text}: not a finite number within [{min}, {max}] {}",
                    param.unit
                ),
                _ => format!("{key} = {text}: {}", e.reason),
            })?;
        }
        s.ff.guideway = match (guideway, start, default_guideway) {
            (false, _, _) => None,
            (true, Start::Plant, Some(d)) => {
                Some(compensator_from_plant(&p.guideway, &d).map_err(|e| {
                    format!("plant.guideway: {e} (controller.ff.start = \"plant\")")
                })?)
            }
            (true, _, d) => d,
        };
        s.validate()
            .map_err(|e| format!("controller: {}", controller_key(e)))?;
        Ok(s)
    }

    /// The reference segments expanded into gms-core's form.
    pub fn segments(&self) -> Result<Vec<Segment>, Error> {
        self.segments_inner().map_err(Error::Scenario)
    }

    fn segments_inner(&self) -> Result<Vec<Segment>, String> {
        let rpc = self.plant.rad_per_count as f32;
        let mut out = Vec::new();
        for s in &self.reference.segments {
            match s {
                SegmentSpec::Hold { duration } => out.push(Segment::Hold {
                    duration: *duration,
                }),
                SegmentSpec::Step { distance, dwell } => out.push(Segment::Step {
                    distance: *distance,
                    dwell: *dwell,
                }),
                SegmentSpec::Steps {
                    counts,
                    dwell,
                    vmax,
                    amax,
                    jmax,
                } => {
                    for c in counts {
                        out.push(Segment::Move {
                            distance: *c as f32 * rpc,
                            vmax: *vmax,
                            amax: *amax,
                            jmax: *jmax,
                            dwell: *dwell,
                        });
                    }
                }
                SegmentSpec::Staircase {
                    distance,
                    count,
                    dwell,
                } => out.push(Segment::Staircase {
                    distance: *distance,
                    count: *count,
                    dwell: *dwell,
                }),
                SegmentSpec::Sine {
                    amplitude,
                    freq,
                    cycles,
                } => out.push(Segment::Sine {
                    amplitude: *amplitude,
                    freq: *freq,
                    cycles: *cycles,
                }),
                SegmentSpec::Move {
                    distance,
                    vmax,
                    amax,
                    jmax,
                    dwell,
                } => out.push(Segment::Move {
                    distance: *distance,
                    vmax: *vmax,
                    amax: *amax,
                    jmax: *jmax,
                    dwell: *dwell,
                }),
            }
        }
        if out.is_empty() {
            return Err("reference.segments is empty".into());
        }
        if out.len() > MAX_SEGMENTS {
            return Err(format!(
                "reference.segments expands to {} segments, at most {MAX_SEGMENTS}",
                out.len()
            ));
        }
        for (i, s) in out.iter().enumerate() {
            s.validate(i).map_err(|e| e.to_string())?;
        }
        let total: f32 = out.iter().map(Segment::duration).sum();
        if total.is_nan() || total > 3600.0 {
            return Err(format!("the reference lasts {total} s, at most 3600 s"));
        }
        Ok(out)
    }
}

/// Where the compensator's friction model starts from (`[controller.ff] start`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Start {
    /// The device's defaults (Table 1 and the guideway preset): what a device fresh from the
    /// factory holds, whatever the plant's friction is.
    Device,
    /// The plant's nominal friction, where the device can hold it.
    Plant,
}

/// The compensator's GMS model (at most [`FF_BLOCKS`] blocks) for a plant friction `truth`,
/// where it can be represented: a GMS of up to [`FF_BLOCKS`] blocks exactly; LuGre or a
/// static map by their Stribeck curve (both directions) and viscous term, with the blocks and
/// `c` of `base` (those models have no Maxwell-slip blocks to copy); a GMS of more blocks is
/// refused (the device cannot hold it: start from the device's model instead).
pub fn compensator_from_plant(
    truth: &FrictionSpec,
    base: &GmsParams<FF_BLOCKS>,
) -> Result<GmsParams<FF_BLOCKS>, String> {
    use gms_ident::paramfile::ModelKind;
    let p = match truth.model {
        ModelKind::Gms => {
            let n = truth.blocks.as_ref().map_or(0, Vec::len);
            if n > FF_BLOCKS {
                return Err(format!(
                    "a gms model of {n} blocks cannot be the compensator's (it holds at most \
                     {FF_BLOCKS}): start from the device's model (ff.start = \"device\")"
                ));
            }
            truth.gms_params::<FF_BLOCKS>().map_err(|e| e.to_string())?
        }
        ModelKind::Lugre | ModelKind::Static => {
            let mut tmp = truth.clone();
            tmp.model = ModelKind::Gms;
            tmp.c = Some(base.c as f64);
            tmp.blocks = None;
            let mut g = tmp.gms_params::<FF_BLOCKS>().map_err(|e| e.to_string())?;
            g.blocks = base.blocks;
            g
        }
    };
    p.validate().map_err(|e| e.to_string())?;
    Ok(p)
}

/// `plant.counts_per_rev` (counts per motor revolution after quadrature), the usual way to
/// give an encoder, as the plant's `rad_per_count` (2π / counts); both given is an error.
fn counts_to_radians(user: &mut toml::Table) -> Result<(), String> {
    let Some(toml::Value::Table(plant)) = user.get_mut("plant") else {
        return Ok(());
    };
    let Some(v) = plant.remove("counts_per_rev") else {
        return Ok(());
    };
    if plant.contains_key("rad_per_count") {
        return Err("plant: give counts_per_rev or rad_per_count, not both".into());
    }
    let counts = match v {
        toml::Value::Integer(i) => i as f64,
        toml::Value::Float(x) => x,
        _ => return Err("plant.counts_per_rev: expected a number".into()),
    };
    if !(counts.is_finite() && counts >= 4.0) {
        return Err("plant.counts_per_rev must be a finite number >= 4".into());
    }
    plant.insert(
        "rad_per_count".into(),
        toml::Value::Float(std::f64::consts::TAU / counts),
    );
    Ok(())
}

/// The device's `enc.counts_per_rev` for a plant of `rad_per_count` \[rad\]: of the two
/// single-precision neighbours of 2π / `rad_per_count` (from the exact and from the
/// single-precision resolution), the one whose derived radians per count come nearest the
/// plant's; the paper's 3.8 µrad gives 1653469.75, whose radians per count are 3.8e-6 in
/// single precision exactly, as the device had them before the resolution was a parameter.
pub fn device_counts_per_rev(rad_per_count: f64) -> f32 {
    let tau = std::f64::consts::TAU;
    let candidates = [
        (tau / rad_per_count) as f32,
        (tau / rad_per_count as f32 as f64) as f32,
    ];
    let err = |c: f32| ((tau / c as f64) as f32 as f64 - rad_per_count).abs();
    if err(candidates[1]) < err(candidates[0]) {
        candidates[1]
    } else {
        candidates[0]
    }
}

/// The scenario key of a controller error (the protocol path under `[controller]`, or the
/// plant's key a value came from).
fn controller_key(e: gms_core::control::controller::ControllerError) -> String {
    use gms_core::control::controller::ControllerError as E;
    use gms_core::protocol::ParamId;
    match e {
        E::Invalid("ff.ratio") => "plant.lead / plant.gear_ratio out of range".into(),
        E::Invalid(p) if p == ParamId::EncCountsPerRev.path() => {
            "plant.rad_per_count (plant.counts_per_rev) is out of range".into()
        }
        E::Invalid(p) if p == ParamId::SenseVPerA.path() => {
            "plant.adc_range is out of range".into()
        }
        E::Invalid(name) if name.starts_with("motor.") || name == ParamId::LimVSupply.path() => {
            format!("controller.{name} (from [plant] unless set) is out of range")
        }
        E::Invalid(name) => format!("controller.{name} is out of range"),
        other => other.to_string(),
    }
}

/// The leaves of a TOML table as dotted paths.
fn flatten(prefix: &str, t: &toml::Table, out: &mut Vec<(String, toml::Value)>) {
    for (k, v) in t {
        let path = if prefix.is_empty() {
            k.clone()
        } else {
            format!("{prefix}.{k}")
        };
        match v {
            toml::Value::Table(sub) => flatten(&path, sub, out),
            other => out.push((path, other.clone())),
        }
    }
}
