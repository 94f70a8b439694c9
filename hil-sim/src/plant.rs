//! The simulated axis: DC motor, gearhead and lead screw, slide on guideways, with the
//! sensors and actuators the firmware sees (quantised encoder, noisy quantised current sense,
//! quantised PWM applied one current-loop period late, supply limit).
//!
//! Values the paper does not give, and why (the defaults of `default_scenario.toml`):
//! - Motor: a small coreless DC motor whose torque constant is the paper's k_M = 6.6 mN·m/A
//!   (a 13 mm, 12 V precious-metal-brush class motor): R = 10 ohm, L = 0.25 mH (electrical time
//!   constant 25 us, typical of coreless windings), k_E = k_M in SI.
//! - Inertia 6e-8 kg·m^2 at the motor: rotor ~5e-8 plus gearhead; the slide (~0.2 kg) adds
//!   m r^2 ≈ 7e-11 through the transmission, negligible.
//! - Transmission: a 4.4:1 gearhead and a 0.5 mm lead screw, r = 18.1 um of slide per motor
//!   radian. Chosen so that the paper's two statements hold: the guideways' 0.9 N breakaway
//!   reflects to 16 uN·m at the motor, comparable to the actuator's ±15 % variability
//!   (±33 uN·m); and their 40 um pre-sliding range is 2.2 rad of motor rotation, so while the
//!   actuator slides (beyond its 7.8 mrad pre-sliding) the guideways stay in pre-sliding.
//! - Encoder 3.8 urad/count (paper), on the motor side as docs/design.md#reading-table-1 reads Table 1.
//! - Current sense: 12-bit ADC over ±0.5 A (0.24 mA/LSB), 0.15 mA rms noise: a shunt
//!   amplifier's ~0.6 mA rms averaged over 16 conversions per period. It matters: in
//!   pre-sliding the actuator's stiffness (1.25 N·m/rad) turns 0.7 mA into one encoder count,
//!   so with 0.5 mA of noise the axis dithers by ±2 counts at rest whatever the controller.
//! - PWM: 20 kHz center-aligned from a 168 MHz timer, 4200 duty steps (2.9 mV at 12 V).
//!
//! Integration: `substeps` (default 10, i.e. 200 kHz, 10× the current loop) steps per
//! current-loop period. The RL circuit is solved exactly for each step (constant voltage and
//! speed); the mechanics use semi-implicit (symplectic) Euler, stable for the stiffest
//! pre-sliding oscillation (sqrt(sum k / J) ≈ 4.6 krad/s, 0.023 rad per 5 us step); both
//! friction sources are gms-core models driven by each step's displacement. Energy is
//! accounted in f64 for the balance check.

use crate::Error;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

use crate::scenario::Plant as PlantSpec;
use gms_ident::paramfile::{AnyModel, FrictionSpec};

/// Energy ledger of a run \[J\], accumulated in f64.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Energy {
    /// Electrical energy delivered by the bridge, ∫ V i dt.
    pub input: f64,
    /// Copper loss, ∫ R i² dt.
    pub copper: f64,
    /// Energy converted to mechanical by the back-EMF, ∫ k_E ω i dt.
    pub converted: f64,
    /// Work done against friction (both sources), ∫ T_f dθ.
    pub friction: f64,
    /// Kinetic energy now, ½ J ω².
    pub kinetic: f64,
    /// Magnetic energy now, ½ L i².
    pub magnetic: f64,
}

/// The plant's state and models.
pub struct Plant {
    r: f64,
    l: f64,
    k_m: f64,
    k_e: f64,
    j: f64,
    ratio: f64,
    rad_per_count: f64,
    supply: f64,
    adc_lsb: f64,
    adc_max: f64,
    pwm_steps: f64,
    noise: Normal<f64>,
    rng: ChaCha8Rng,
    actuator: AnyModel,
    guideway: AnyModel,
    drift: crate::scenario::Drift,
    glitch: crate::scenario::Glitch,
    /// -1 when the encoder is wired the other way round, else 1.
    enc_sign: f64,
    /// -1 when the current sense is wired the other way round, else 1.
    sense_sign: f64,
    /// Time since the start \[s\].
    pub t: f64,
    /// Current \[A\].
    pub i: f64,
    /// Motor speed [rad/s].
    pub omega: f64,
    /// Motor angle \[rad\].
    pub theta: f64,
    /// Friction torque acting now (actuator + reflected guideway) [N·m].
    pub friction: f64,
    /// Voltage applied by the bridge now \[V\].
    pub voltage: f64,
    /// Duty waiting to be applied at the next current-loop period.
    pending_duty: f64,
    /// Energy ledger.
    pub energy: Energy,
}

/// Scales a friction table's parameters by independent uniform factors in [1-v, 1+v]
/// (fs, fc, vs, sigma, c and every k; the weights alpha stay), keeping fs >= fc.
pub fn draw_friction(spec: &FrictionSpec, v: f64, rng: &mut impl Rng) -> FrictionSpec {
    let mut s = spec.clone();
    if v <= 0.0 {
        return s;
    }
    let mut f = |x: Option<f64>| x.map(|x| x * rng.random_range(1.0 - v..=1.0 + v));
    s.fs = f(s.fs);
    s.fc = f(s.fc);
    s.vs = f(s.vs);
    s.sigma = f(s.sigma);
    s.c = f(s.c);
    s.sigma0 = f(s.sigma0);
    s.sigma1 = f(s.sigma1);
    if let Some(blocks) = &mut s.blocks {
        for b in blocks {
            b.k *= rng.random_range(1.0 - v..=1.0 + v);
        }
    }
    if let (Some(fs), Some(fc)) = (s.fs, s.fc) {
        s.fc = Some(fc.min(fs));
    }
    s
}

impl Plant {
    /// Builds the plant at rest with friction drawn around the nominal (seed `seed`).
    pub fn new(spec: &PlantSpec, seed: u64) -> Result<Plant, Error> {
        Self::new_inner(spec, seed).map_err(Error::Scenario)
    }

    fn new_inner(spec: &PlantSpec, seed: u64) -> Result<Plant, String> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let act = draw_friction(&spec.actuator, spec.variability, &mut rng);
        let gw = draw_friction(&spec.guideway, spec.variability, &mut rng);
        let actuator = act.build().map_err(|e| format!("plant.actuator: {e}"))?;
        let guideway = gw.build().map_err(|e| format!("plant.guideway: {e}"))?;
        let lsb = 2.0 * spec.adc_range / (1u64 << spec.adc_bits) as f64;
        Ok(Plant {
            r: spec.resistance,
            l: spec.inductance,
            k_m: spec.k_m,
            k_e: spec.k_e,
            j: spec.inertia,
            ratio: spec.ratio(),
            rad_per_count: spec.rad_per_count,
            supply: spec.supply_v,
            adc_lsb: lsb,
            adc_max: spec.adc_range,
            pwm_steps: spec.pwm_steps as f64,
            noise: Normal::new(0.0, spec.adc_noise).map_err(|e| format!("plant.adc_noise: {e}"))?,
            rng,
            actuator,
            guideway,
            drift: spec.drift.clone(),
            glitch: spec.encoder_glitch,
            enc_sign: if spec.encoder_reversed { -1.0 } else { 1.0 },
            sense_sign: if spec.sense_reversed { -1.0 } else { 1.0 },
            t: 0.0,
            i: 0.0,
            omega: 0.0,
            theta: 0.0,
            friction: 0.0,
            voltage: 0.0,
            pending_duty: 0.0,
            energy: Energy::default(),
        })
    }

    /// The friction drift factor now [-].
    pub fn drift_factor(&self) -> f64 {
        self.drift.factor(self.t, self.theta)
    }

    /// The encoder count now (floor of angle / resolution, negated for an encoder wired the
    /// other way, plus the injected glitch once it is due).
    pub fn encoder(&self) -> i64 {
        let glitch = if self.t >= self.glitch.at {
            self.glitch.counts
        } else {
            0
        };
        ((self.enc_sign * self.theta / self.rad_per_count).floor() as i64).saturating_add(glitch)
    }

    /// The current-sense reading now \[A\]: noise, then quantisation and clipping.
    pub fn adc(&mut self) -> f32 {
        let raw = self.sense_sign * self.i + self.noise.sample(&mut self.rng);
        let q = (raw / self.adc_lsb).round() * self.adc_lsb;
        q.clamp(-self.adc_max, self.adc_max - self.adc_lsb) as f32
    }

    /// Starts a current-loop period: the duty computed in the previous period is applied now
    /// (one period of delay), and `duty` waits for the next. Duty is quantised to the PWM's
    /// steps and limited to ±1.
    pub fn set_duty(&mut self, duty: f32) {
        let d = (duty as f64).clamp(-1.0, 1.0);
        let q = (d * self.pwm_steps).round() / self.pwm_steps;
        self.voltage = self.pending_duty * self.supply;
        self.pending_duty = q;
    }

    /// Advances the plant by `dt` \[s\] at the applied voltage.
    pub fn step(&mut self, dt: f64) {
        // Electrical: L di/dt = V - R i - k_E ω, exact for constant V and ω over the step.
        let a = self.r / self.l;
        let i_ss = (self.voltage - self.k_e * self.omega) / self.r;
        let d0 = self.i - i_ss;
        let e = (-a * dt).exp();
        let i_int = i_ss * dt + d0 * (1.0 - e) / a; // ∫ i dt
        let i2_int = i_ss * i_ss * dt
            + 2.0 * i_ss * d0 * (1.0 - e) / a
            + d0 * d0 * (1.0 - e * e) / (2.0 * a); // ∫ i² dt
        self.i = i_ss + d0 * e;
        let i_avg = i_int / dt;
        self.energy.input += self.voltage * i_int;
        self.energy.copper += self.r * i2_int;
        self.energy.converted += self.k_e * self.omega * i_int;
        self.energy.magnetic = 0.5 * self.l * self.i * self.i;
        // Mechanics: semi-implicit Euler with the friction of the current state.
        let torque = self.k_m * i_avg;
        self.omega += (torque - self.friction) / self.j * dt;
        let dtheta = self.omega * dt;
        self.energy.friction += self.friction * dtheta;
        self.theta += dtheta;
        let ta = self.actuator.advance(dtheta as f32, dt as f32) as f64;
        let fg = self
            .guideway
            .advance((self.ratio * dtheta) as f32, dt as f32) as f64;
        self.t += dt;
        self.friction = self.drift.factor(self.t, self.theta) * (ta + self.ratio * fg);
        self.energy.kinetic = 0.5 * self.j * self.omega * self.omega;
    }
}
