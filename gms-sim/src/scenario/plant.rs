//! A scenario's plant: the axis's friction and its variations (compliance, cogging and
//! screw ripple, glitches, drift), as the file writes them.

use super::*;

/// The plant: motor, transmission, sensors, friction.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Plant {
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
    /// The current-sense chain as built: where its zero lies, its bandwidth and its swing.
    pub sense: SenseSpec,
    /// The H-bridge as built: dead time, delay, on-resistance (or the ideal bridge).
    pub bridge: BridgeSpec,
    /// The motor supply: its voltage and its source resistance.
    pub supply: SupplySpec,
}

/// The H-bridge (`[plant.bridge]`): a DRV8871-class driver taking IN1/IN2 in slow-decay
/// sign-magnitude (drive, then brake with both low sides on), its outputs switching
/// `delay_s` after the timer's edges with `dead_time_s` of both switches off at each edge.
/// While both are off the current flows on through a body diode, so that the dead time
/// belongs to the brake when the current flows in the driven direction and to the drive when
/// it flows against it: the period's mean voltage is `(d − sign(i) t_dead / T) V`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BridgeSpec {
    /// The ideal bridge: `duty × volts` over the whole period, no dead time, no delay, no
    /// on-resistance (the plant before issue 55, kept for comparison).
    pub ideal: bool,
    /// Both switches of the switching half-bridge off at each of its edges \[s\], in
    /// [0, 5e-6] (DRV8870/DRV8871 t_DEAD 220 ns typical).
    pub dead_time_s: f64,
    /// From the timer's edge to the output's \[s\], in [0, 5e-6] (t_PD 0.7 µs typical, 1 µs
    /// at most).
    pub delay_s: f64,
    /// The on-resistance in the current's path, high side plus low side \[ohm\], in [0, 10]
    /// (307 + 258 mΩ typical at 24 V, 1 A).
    pub r_on_ohm: f64,
    /// The switching node's capacitance \[F\], in [0, 10e-9]: during the dead time the
    /// current slews the node at i / C instead of taking it to the diode's rail at once, so
    /// that the dead time's loss goes continuously through zero current, below about
    /// C × volts / dead_time_s. 0: the node follows the current's sign at once (the binary
    /// model). The DRV8871's datasheet gives no C_oss.
    #[serde(default)]
    pub c_node_f: f64,
}

/// The motor supply (`[plant.supply]`): its voltage sags by `r_source_ohm` times the current
/// the bridge draws from it (the supply's output resistance, its leads and connector).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SupplySpec {
    /// The open-circuit voltage \[V\], in (0, 60].
    pub volts: f64,
    /// The source resistance \[ohm\], in [0, 10].
    pub r_source_ohm: f64,
}

/// The current-sense chain's departures from its nominal design (`[plant.sense]`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SenseSpec {
    /// The amplifier's zero off the ADC's mid-scale \[ADC codes\] (its offset and the
    /// reference divider's tolerance): the device's start-up calibration finds it, and a
    /// board refuses one more than its window (150 codes on the F4 boards) away.
    pub offset_codes: f64,
    /// The amplifier's bandwidth \[Hz\], a first-order lag on the current it reads; 0: none
    /// (INA240: 400 kHz).
    pub bandwidth_hz: f64,
    /// How close to each rail of the ADC's 3.3 V span the amplifier's output can swing \[V\],
    /// in [0, 1): readings beyond are held there, short of the ADC's end codes.
    pub swing_v: f64,
    /// How long the amplifier's output is disturbed after each edge of the bridge's output
    /// (its common-mode step) \[s\], in [0, 10 µs]; 0: never (INA240, enhanced PWM rejection:
    /// about 1 µs).
    pub recovery_s: f64,
    /// The disturbance meanwhile, as a current \[A\], in [0, 10]: added to the reading after a
    /// rising edge of the bridge's output, taken off after a falling one (the INA240's
    /// residual coupling, about 50 mV at its output: 14.7 mA at the boards' 3.4 V/A).
    pub edge_a: f64,
}

impl SenseSpec {
    /// The lowest and highest ADC codes the amplifier's output reaches, for an ADC of
    /// `top` + 1 codes over `vref` \[V\] (`swing_v` short of each rail): a board's ADC model
    /// holds its conversions within them.
    pub fn code_limits(&self, vref: f64, top: f64) -> (f64, f64) {
        let swing = (self.swing_v / vref * top).clamp(0.0, top / 2.0);
        (swing, top - swing)
    }
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
        if self.screw_friction == 0.0 {
            // No modulation (the default): the sine's cost spared, the same 1.
            return 1.0;
        }
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

    /// The real bridge, `None` for the ideal one.
    pub fn real_bridge(&self) -> Option<BridgeSpec> {
        (!self.bridge.ideal).then_some(self.bridge)
    }

    /// The resistance in the current's path \[ohm\]: the winding's and, for the real bridge,
    /// its switches' (what commissioning measures).
    pub fn path_resistance(&self) -> f64 {
        self.resistance + self.real_bridge().map_or(0.0, |b| b.r_on_ohm)
    }
}
