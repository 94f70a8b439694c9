//! Scenario files: plant, controller and reference of one simulated run.
//!
//! The complete default is `default_scenario.toml` (printed by
//! `hil-sim run --print-default-scenario`); a scenario file may leave out any key, which then
//! takes that default, and an unknown key is an error naming it.

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

/// The plant: motor, transmission, sensors, friction.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Plant {
    /// H-bridge supply \[V\].
    pub supply_v: f64,
    /// Winding resistance \[ohm\].
    pub resistance: f64,
    /// Winding inductance \[H\].
    pub inductance: f64,
    /// Torque constant [N·m/A].
    pub k_m: f64,
    /// Back-EMF constant [V·s/rad].
    pub k_e: f64,
    /// Inertia reflected to the motor [kg·m^2].
    pub inertia: f64,
    /// Gearhead reduction [-].
    pub gear_ratio: f64,
    /// Lead-screw lead [m/rev].
    pub lead: f64,
    /// Encoder resolution [rad/count].
    pub rad_per_count: f64,
    /// ADC resolution \[bits\].
    pub adc_bits: u32,
    /// ADC full scale, ± \[A\].
    pub adc_range: f64,
    /// Current-sense noise, standard deviation \[A\].
    pub adc_noise: f64,
    /// PWM duty resolution \[steps\].
    pub pwm_steps: u32,
    /// Plant steps per current-loop period.
    pub substeps: u32,
    /// Friction variability, ± fraction of nominal.
    pub variability: f64,
    /// Seed of the friction draw and the noise.
    pub seed: u64,
    /// Seed of the noise alone, drawn after the friction (0: the noise goes on from `seed`'s
    /// stream): the same plant with another realisation of its noise.
    pub noise_seed: u64,
    /// Actuator friction (motor side, N·m, rad).
    pub actuator: FrictionSpec,
    /// Guideway friction (slide, N, m).
    pub guideway: FrictionSpec,
    /// How the friction drifts during the run.
    pub drift: Drift,
    /// An injected encoder fault (none by default).
    pub encoder_glitch: Glitch,
    /// The encoder wired the other way round: it counts down when the motor turns forward
    /// (a wiring fault for the bench tools to detect).
    pub encoder_reversed: bool,
    /// The current sense wired the other way round: it reads the current negated (a wiring
    /// fault for the bench tools to detect).
    pub sense_reversed: bool,
    /// The screw/nut's axial compliance: a two-mass stage (rigid by default).
    pub compliance: Compliance,
    /// Position-dependent torque: cogging and the screw's once-per-revolution friction.
    pub ripple: Ripple,
}

/// The stage's structural mode: the rotor side (motor, gearhead, screw) and the slide joined
/// by the screw/nut's axial stiffness and damping. `inertia` stays the whole axis's inertia
/// at the motor; of it, the slide's share is `slide_mass` × (slide travel per motor radian)².
/// The encoder stays on the motor, the guideway friction acts on the slide.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Compliance {
    /// The anti-resonance seen from the motor's encoder \[Hz\]: the slide's natural frequency
    /// against the axial stiffness with the rotor held, `(1/2π) √(K / J_l)`; 0: rigid.
    pub f_hz: f64,
    /// Its damping ratio \[-\], in [0, 1).
    pub zeta: f64,
    /// The slide's mass (carriage and load) \[kg\], `> 0`.
    pub slide_mass: f64,
}

/// One harmonic of the cogging torque.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Harmonic {
    /// Its order: `order × per_rev` cycles per motor revolution \[-\], `>= 1`.
    pub order: u32,
    /// Its amplitude \[N·m\].
    pub amplitude: f64,
    /// Its phase \[rad\].
    #[serde(default)]
    pub phase: f64,
}

/// Position-dependent torque on the rotor: a conservative cogging torque periodic in the motor
/// angle, `amplitude sin(per_rev θ + phase) + Σ a_h sin(order_h per_rev θ + phase_h)` (the
/// torque the motor must supply to turn, positive against positive motion on the rising
/// half), and a once-per-screw-revolution modulation of the actuator friction,
/// `1 + screw_friction sin(θ / gear_ratio + screw_phase)`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Ripple {
    /// The cogging's fundamental amplitude \[N·m\]; 0: none.
    pub amplitude: f64,
    /// Cogging cycles per motor revolution \[-\], `>= 1`.
    pub per_rev: u32,
    /// Phase of the fundamental \[rad\].
    pub phase: f64,
    /// Further harmonics.
    pub harmonics: Vec<Harmonic>,
    /// The actuator friction's modulation once per screw revolution, ± fraction \[-\], in
    /// (-0.9, 0.9).
    pub screw_friction: f64,
    /// Its phase \[rad\].
    pub screw_phase: f64,
}

impl Ripple {
    /// The cogging torque at motor angle `theta` \[N·m\] and its potential energy relative
    /// to angle 0 \[J\] (the torque's integral from 0 to `theta`).
    pub fn cogging(&self, theta: f64) -> (f64, f64) {
        let n = self.per_rev as f64;
        let mut torque = 0.0;
        let mut energy = 0.0;
        let terms = core::iter::once((1.0, self.amplitude, self.phase)).chain(
            self.harmonics
                .iter()
                .map(|h| (h.order as f64, h.amplitude, h.phase)),
        );
        for (order, a, ph) in terms {
            if a == 0.0 {
                continue;
            }
            let w = order * n;
            torque += a * (w * theta + ph).sin();
            energy += a / w * (ph.cos() - (w * theta + ph).cos());
        }
        (torque, energy)
    }

    /// The factor on the actuator friction at motor angle `theta` \[-\], for a gearhead of
    /// `gear_ratio` (the screw turns once per `gear_ratio` motor revolutions).
    pub fn screw_factor(&self, theta: f64, gear_ratio: f64) -> f64 {
        1.0 + self.screw_friction * (theta / gear_ratio + self.screw_phase).sin()
    }
}

/// Fault injection for testing what the device does about a bad encoder signal (a burst of
/// noise counted as edges, a loose connector): from `at` on, the encoder reads `counts` away
/// from the true angle.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Glitch {
    /// When the reading jumps [s of simulated time from the start], `>= 0`.
    pub at: f64,
    /// By how much \[counts\]; 0: no glitch.
    pub counts: i64,
}

/// How the plant's friction drifts during a run: a factor on both sources' friction torque
/// (equivalently fs, fc, sigma, every k and c scaled together).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum DriftKind {
    /// Stationary: factor 1.
    None,
    /// Slow drift: the factor moves linearly from 1 to 1 + amount over `time` seconds, then
    /// stays.
    Ramp,
    /// Steps: 1 until `time`, then 1 + amount, 1 - amount, 1 + amount, … every `time` s.
    Steps,
    /// Along the stroke: 1 + amount sin(2 pi angle / period) (angle of the motor, rad).
    Position,
}

/// The friction drift of a run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Drift {
    /// Which drift.
    pub kind: DriftKind,
    /// Its size, a fraction [-], in (-0.9, 0.9); negative drifts the other way.
    pub amount: f64,
    /// Ramp duration or step interval \[s\], `> 0`.
    pub time: f64,
    /// Spatial period of the position-dependent drift [rad of motor angle], `> 0`.
    pub period: f64,
}

impl Drift {
    /// The friction factor at time `t` \[s\] and motor angle `theta` \[rad\].
    pub fn factor(&self, t: f64, theta: f64) -> f64 {
        match self.kind {
            DriftKind::None => 1.0,
            DriftKind::Ramp => 1.0 + self.amount * (t / self.time).clamp(0.0, 1.0),
            DriftKind::Steps => {
                let n = (t / self.time).floor();
                if n < 1.0 {
                    1.0
                } else if n % 2.0 == 1.0 {
                    1.0 + self.amount
                } else {
                    1.0 - self.amount
                }
            }
            DriftKind::Position => {
                1.0 + self.amount * (2.0 * std::f64::consts::PI * theta / self.period).sin()
            }
        }
    }
}

impl Plant {
    /// Slide travel per motor radian [m/rad].
    pub fn ratio(&self) -> f64 {
        self.lead / (2.0 * std::f64::consts::PI * self.gear_ratio)
    }
}

/// The reference trajectory.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Reference {
    /// The segments, in order.
    pub segments: Vec<SegmentSpec>,
}

/// One reference segment as written in the file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "lowercase", deny_unknown_fields)]
pub enum SegmentSpec {
    /// Rest.
    Hold {
        /// \[s\]
        duration: f32,
    },
    /// One step.
    Step {
        /// \[rad\]
        distance: f32,
        /// \[s\]
        dwell: f32,
    },
    /// Jerk-limited moves of the given numbers of encoder counts, each followed by a dwell.
    Steps {
        /// Step sizes \[counts\].
        counts: Vec<i64>,
        /// Rest after each move \[s\].
        dwell: f32,
        /// Speed limit [rad/s].
        #[serde(default = "default_vmax")]
        vmax: f32,
        /// Acceleration limit [rad/s^2].
        #[serde(default = "default_amax")]
        amax: f32,
        /// Jerk limit [rad/s^3].
        #[serde(default = "default_jmax")]
        jmax: f32,
    },
    /// Equal steps.
    Staircase {
        /// \[rad\]
        distance: f32,
        /// Number of steps.
        count: u32,
        /// \[s\]
        dwell: f32,
    },
    /// x = A (1 - cos 2 pi f t).
    Sine {
        /// \[rad\]
        amplitude: f32,
        /// \[Hz\]
        freq: f32,
        /// Periods.
        cycles: f32,
    },
    /// Jerk-limited move.
    Move {
        /// \[rad\]
        distance: f32,
        /// [rad/s]
        vmax: f32,
        /// [rad/s^2]
        amax: f32,
        /// [rad/s^3]
        jmax: f32,
        /// \[s\]
        dwell: f32,
    },
}

fn default_vmax() -> f32 {
    0.5
}
fn default_amax() -> f32 {
    50.0
}
fn default_jmax() -> f32 {
    1e4
}

/// The most segments a reference may expand to.
pub const MAX_SEGMENTS: usize = 64;

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
            ("plant.supply_v", p.supply_v),
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
    /// transmission ratio); the compensator's friction is the device's default model unless
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
        s.motor.r = p.resistance as f32;
        s.motor.k_e = p.k_e as f32;
        s.v_supply = p.supply_v as f32;
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
    match e {
        E::Invalid("ff.ratio") => "plant.lead / plant.gear_ratio out of range".into(),
        E::Invalid("enc.counts_per_rev") => {
            "plant.rad_per_count (plant.counts_per_rev) is out of range".into()
        }
        E::Invalid("sense.v_per_a") => "plant.adc_range is out of range".into(),
        E::Invalid(name) if name.starts_with("motor.") || name == "lim.v_supply" => {
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
