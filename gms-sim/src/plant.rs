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
//! - Current sense: 12-bit ADC over ±0.5 A (0.24 mA/LSB), 0.21 mA rms noise: a shunt
//!   amplifier's ~0.6 mA rms averaged over the board's 8 conversions per period. It matters: in
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
//!
//! The truth is the plant's: its friction (actuator and guideway) may be any model the core
//! has (GMS of up to 32 blocks, LuGre, a static map), whatever the compensator believes.
//! Two options make it a real stage (both off by default):
//! - `[plant.compliance]`: a two-mass stage. The rotor side (J_m = inertia − J_l: motor,
//!   gearhead, screw) and the slide (J_l = m r², r the slide travel per motor radian) are
//!   joined by the screw/nut's axial stiffness K = J_l (2π f_hz)² and damping
//!   c = 2 zeta J_l (2π f_hz), reflected to the motor. The encoder and the actuator friction
//!   are on the rotor, the guideway friction on the slide. Seen from the encoder: the
//!   rigid-body line of the whole inertia, an anti-resonance at f_hz, a resonance at
//!   f_hz √(J / J_m).
//! - `[plant.ripple]`: the cogging torque (conservative, periodic in the motor angle, its
//!   potential energy in the ledger) and the screw's once-per-revolution modulation of the
//!   actuator friction.

use crate::Error;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

use crate::scenario::Plant as PlantSpec;
use gms_ident::linear::SmallSignal;
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
    /// Kinetic energy now, ½ J ω² (both masses of a compliant stage).
    pub kinetic: f64,
    /// Magnetic energy now, ½ L i².
    pub magnetic: f64,
    /// Energy stored in the screw/nut's axial compliance now, ½ K (θ_m − θ_l)².
    pub spring: f64,
    /// Energy lost in the compliance's damping, ∫ c (ω_m − ω_l)² dt.
    pub damping: f64,
    /// The cogging's potential energy now, relative to the start (it is conservative).
    pub cogging: f64,
}

impl Energy {
    /// What the mechanics hold and have dissipated: friction work, kinetic, spring and
    /// cogging energy, damping loss \[J\] (equals [`converted`](Self::converted) when the
    /// integration is right).
    pub fn mechanical(&self) -> f64 {
        self.friction + self.kinetic + self.spring + self.damping + self.cogging
    }
}

/// The two-mass stage's constants at the motor (reflected).
#[derive(Debug, Clone, Copy)]
struct TwoMass {
    /// Rotor side inertia [kg·m^2].
    j_m: f64,
    /// Slide inertia reflected [kg·m^2].
    j_l: f64,
    /// Axial stiffness reflected [N·m/rad].
    k: f64,
    /// Axial damping reflected [N·m·s/rad].
    c: f64,
}

/// `f(dt)`, kept in `memo` with its `dt` \[s\]: a run's steps have one length and `f` (an
/// exponential decay over a step) depends on nothing else, so that it is computed once.
fn per_step(memo: &mut (f64, f64), dt: f64, f: impl FnOnce(f64) -> f64) -> f64 {
    if dt != memo.0 {
        *memo = (dt, f(dt));
    }
    memo.1
}

/// One drive pulse of the real bridge, in time from its period's start \[s\]: on from `on`
/// to `off`, in the direction `sign`. An edge is fixed (its dead time added by the current's
/// direction then) when the integration first reaches it.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Pulse {
    on: f64,
    off: f64,
    sign: f64,
    on_fixed: bool,
    off_fixed: bool,
    /// False for a full-period pulse (|duty| = 1): its outputs never switch, no dead time.
    edges: bool,
    /// With a node capacitance (`c_node_f`): the dead time's windows after the on-edge and
    /// after the off-edge, `(start, end, share)` with the share of the drive the slewing
    /// node gives over it; and the current's magnitude at the on-edge when it slewed the node
    /// towards the drive (else `None`).
    on_win: Option<(f64, f64, f64)>,
    off_win: Option<(f64, f64, f64)>,
    on_slew: Option<f64>,
}

impl Pulse {
    /// The same pulse in the time of a period starting `dt` \[s\] later.
    fn shifted(&self, dt: f64) -> Pulse {
        let w = |v: Option<(f64, f64, f64)>| v.map(|(a, b, f)| (a - dt, b - dt, f));
        Pulse {
            on: self.on - dt,
            off: self.off - dt,
            on_win: w(self.on_win),
            off_win: w(self.off_win),
            ..*self
        }
    }

    /// Its drive at the phase `x` \[s\], as a signed fraction of the supply.
    fn drive_at(&self, x: f64) -> f64 {
        let inside = |w: Option<(f64, f64, f64)>| w.filter(|w| w.0 <= x && x < w.1).map(|w| w.2);
        if let Some(f) = inside(self.on_win).or(inside(self.off_win)) {
            self.sign * f
        } else if self.on <= x && x < self.off {
            self.sign
        } else {
            0.0
        }
    }
}

/// The share of the drive rail's voltage over a window of `window` \[s\] that a node of
/// capacitance `c` \[F\] gives when a current of magnitude `amps` \[A\] slews it from the
/// other rail towards it across `volts` \[V\] (clamped at the rail): 1 at once (`c` 0), the
/// ramp's half while it lasts.
fn slew_share(amps: f64, c: f64, volts: f64, window: f64) -> f64 {
    if c <= 0.0 {
        return 1.0;
    }
    if window <= 0.0 || volts <= 0.0 {
        return 0.0;
    }
    // The window over the time to cross: past 1 the node reached the rail.
    let q = amps * window / (c * volts);
    if q >= 1.0 { 1.0 - 0.5 / q } else { 0.5 * q }
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
    /// The supply's open-circuit voltage \[V\] and source resistance \[ohm\].
    supply: f64,
    r_source: f64,
    /// The bridge's supply terminal \[V\] over the last step: the supply less its source
    /// resistance's drop (what a board's divider reads).
    bus: f64,
    /// The real bridge (`None`: the ideal one).
    bridge: Option<crate::scenario::BridgeSpec>,
    /// The PWM period now: the time since it started \[s\], its duty (quantised, \[-1, 1\])
    /// and the drive pulses that fall in it (this period's and the end of the last one's,
    /// delayed past its end).
    phase: f64,
    duty: f64,
    pulses: [Option<Pulse>; 2],
    /// Whether the bridge's outputs are on (off: no voltage, the current decays).
    outputs_on: bool,
    /// The sense amplifier's time constant \[s\] (0: none) and its output now \[A\].
    sense_tau: f64,
    sensed: f64,
    /// The amplifier's recovery after an edge of the bridge's output \[s\] and its
    /// disturbance meanwhile \[A\] (`[plant.sense] recovery_s`, `edge_a`).
    recovery: f64,
    edge_a: f64,
    /// The last edge of the bridge's output: its time \[s\] (as `t`) and direction (+1 rising:
    /// a drive's start; −1 falling: its end).
    last_edge: Option<(f64, f64)>,
    adc_lsb: f64,
    adc_max: f64,
    sense_offset_codes: f64,
    pwm_steps: f64,
    noise: Normal<f64>,
    rng: ChaCha8Rng,
    actuator: AnyModel,
    guideway: AnyModel,
    /// The friction tables drawn for this run (the truth's parameters).
    act_spec: FrictionSpec,
    gw_spec: FrictionSpec,
    drift: crate::scenario::Drift,
    ripple: crate::scenario::Ripple,
    gear_ratio: f64,
    two_mass: Option<TwoMass>,
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
    /// The slide's position as a motor angle (slide travel / travel per radian) \[rad\];
    /// equal to `theta` on a rigid stage.
    pub theta_slide: f64,
    /// The slide's speed as a motor speed [rad/s].
    pub omega_slide: f64,
    /// Friction torque acting now (actuator + reflected guideway) [N·m].
    pub friction: f64,
    /// The actuator's friction torque now (on the rotor) [N·m].
    friction_act: f64,
    /// The guideway's friction now, reflected to the motor (on the slide) [N·m].
    friction_gw: f64,
    /// The cogging torque now [N·m].
    pub cogging: f64,
    /// Voltage applied by the bridge now \[V\].
    pub voltage: f64,
    /// Duty waiting to be applied at the next current-loop period.
    pending_duty: f64,
    /// Energy ledger.
    pub energy: Energy,
    /// The last step's length \[s\] and its RL decay `exp(-R/L dt)`: the step length is
    /// constant in a run, and the exponential was a tenth of a simulation's time.
    decay_memo: (f64, f64),
    /// Likewise the sense amplifier's lag over a step, `exp(-dt / tau)`.
    sense_memo: (f64, f64),
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
        if spec.noise_seed != 0 {
            rng = ChaCha8Rng::seed_from_u64(spec.noise_seed);
        }
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
            supply: spec.supply.volts,
            r_source: spec.supply.r_source_ohm,
            bus: spec.supply.volts,
            bridge: spec.real_bridge(),
            phase: 0.0,
            duty: 0.0,
            pulses: [None; 2],
            outputs_on: true,
            sense_tau: if spec.sense.bandwidth_hz > 0.0 {
                1.0 / (2.0 * std::f64::consts::PI * spec.sense.bandwidth_hz)
            } else {
                0.0
            },
            sensed: 0.0,
            recovery: spec.sense.recovery_s,
            edge_a: spec.sense.edge_a,
            last_edge: None,
            adc_lsb: lsb,
            adc_max: spec.adc_range,
            sense_offset_codes: spec.sense.offset_codes,
            pwm_steps: spec.pwm_steps as f64,
            noise: Normal::new(0.0, spec.adc_noise).map_err(|e| format!("plant.adc_noise: {e}"))?,
            rng,
            actuator,
            guideway,
            act_spec: act,
            gw_spec: gw,
            drift: spec.drift.clone(),
            ripple: spec.ripple.clone(),
            gear_ratio: spec.gear_ratio,
            two_mass: (spec.compliance.f_hz > 0.0).then(|| {
                let r = spec.ratio();
                let j_l = spec.compliance.slide_mass * r * r;
                let w = 2.0 * std::f64::consts::PI * spec.compliance.f_hz;
                TwoMass {
                    j_m: spec.inertia - j_l,
                    j_l,
                    k: j_l * w * w,
                    c: 2.0 * spec.compliance.zeta * j_l * w,
                }
            }),
            glitch: spec.encoder_glitch,
            enc_sign: if spec.encoder_reversed { -1.0 } else { 1.0 },
            sense_sign: if spec.sense_reversed { -1.0 } else { 1.0 },
            t: 0.0,
            i: 0.0,
            omega: 0.0,
            theta: 0.0,
            theta_slide: 0.0,
            omega_slide: 0.0,
            friction: 0.0,
            friction_act: 0.0,
            friction_gw: 0.0,
            cogging: 0.0,
            voltage: 0.0,
            pending_duty: 0.0,
            energy: Energy::default(),
            decay_memo: (f64::NAN, 0.0),
            sense_memo: (f64::NAN, 0.0),
        })
    }

    /// The plant's constants for a small-signal linear model about its state now
    /// ([`gms_ident::linear`]): the electrical and mechanical constants as the plant runs them,
    /// and each friction's stiffness and viscous coefficient from the truth's drawn
    /// parameters (the blocks' Σk of a GMS, σ0 and σ1 of LuGre; scaled by the drift and the
    /// screw's factor now; the guideway's reflected to the motor).
    pub fn small_signal(&self) -> SmallSignal {
        let stiff = |f: &FrictionSpec| -> (f64, f64) {
            let k = match f.model {
                gms_ident::paramfile::ModelKind::Lugre => f.sigma0.unwrap_or(0.0),
                _ => f
                    .blocks
                    .as_ref()
                    .map_or(0.0, |b| b.iter().map(|b| b.k).sum::<f64>()),
            };
            let visc = f.sigma.unwrap_or(0.0)
                + match f.model {
                    gms_ident::paramfile::ModelKind::Lugre => f.sigma1.unwrap_or(0.0),
                    _ => 0.0,
                };
            (k, visc)
        };
        let drift = self.drift_factor();
        let screw = self.ripple.screw_factor(self.theta, self.gear_ratio);
        let (ka, sa) = stiff(&self.act_spec);
        let (kg, sg) = stiff(&self.gw_spec);
        let r2 = self.ratio * self.ratio;
        SmallSignal {
            r: self.r_path(),
            l: self.l,
            k_m: self.k_m,
            k_e: self.k_e,
            j: self.j,
            two_mass: self.two_mass.map(|m| (m.j_m, m.j_l, m.k, m.c)),
            k_act: drift * screw * ka,
            sigma_act: drift * screw * sa,
            k_gw: drift * r2 * kg,
            sigma_gw: drift * r2 * sg,
            rad_per_count: self.rad_per_count,
        }
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

    /// The sense chain's output now, before its ADC \[A\]: the current as wired, with the
    /// noise's standard deviation times `noise_scale` (the scenario's `adc_noise` is the
    /// board's average's: one of the n conversions averaged has √n times it).
    pub fn sense(&mut self, noise_scale: f64) -> f64 {
        let i = if self.sense_tau > 0.0 {
            self.sensed
        } else {
            self.i
        };
        self.sense_sign * i
            + self.edge_disturbance()
            + noise_scale * self.noise.sample(&mut self.rng)
    }

    /// The amplifier's disturbance now \[A\]: `edge_a` (+ after a rising edge of the bridge's
    /// output, − after a falling one) for `recovery_s` after the last edge, else 0. The
    /// edges are the real bridge's (after its delay and dead time); the ideal bridge has
    /// none.
    pub fn edge_disturbance(&self) -> f64 {
        match self.last_edge {
            Some((at, dir)) if self.t >= at && self.t - at < self.recovery => dir * self.edge_a,
            _ => 0.0,
        }
    }

    /// The current-sense chain's zero off the ADC's mid-scale \[codes\] (`[plant.sense]
    /// offset_codes`): a board's ADC model adds it to every conversion.
    pub fn sense_offset_codes(&self) -> f64 {
        self.sense_offset_codes
    }

    /// The current-sense reading now \[A\]: noise, then quantisation and clipping.
    pub fn adc(&mut self) -> f32 {
        let raw = self.sense(1.0);
        let q = (raw / self.adc_lsb).round() * self.adc_lsb;
        q.clamp(-self.adc_max, self.adc_max - self.adc_lsb) as f32
    }

    /// Starts a current-loop period: the duty computed in the previous period is applied now
    /// (one period of delay), and `duty` waits for the next. Duty is quantised to the PWM's
    /// steps and limited to ±1.
    pub fn set_duty(&mut self, duty: f32, period_s: f64) {
        let d = (duty as f64).clamp(-1.0, 1.0);
        let q = (d * self.pwm_steps).round() / self.pwm_steps;
        self.start_period(self.pending_duty, period_s);
        self.pending_duty = q;
    }

    /// Starts a PWM period of `period_s` \[s\] at the timer counter's bottom, the bridge
    /// driven at `duty` \[-1, 1\] (as the timer's compare values give it) until the next.
    /// Centre-aligned: the drive pulse is centred on the counter's top, half a period on, so
    /// that the brake is centred on the bottom, where the current is sensed. The real
    /// bridge's outputs follow `delay_s` later: the end of the last period's pulse can fall
    /// in this one.
    pub fn start_period(&mut self, duty: f64, period_s: f64) {
        let duty = if duty.is_finite() {
            duty.clamp(-1.0, 1.0)
        } else {
            0.0
        };
        let elapsed = self.phase;
        // The newest pulse still driving past the period's end (the delay) goes on into this
        // one; it cannot reach further (the delay is shorter than a period).
        let carried = self
            .pulses
            .iter()
            .flatten()
            .map(|p| p.shifted(elapsed))
            .rfind(|p| p.off > 0.0 || !p.off_fixed || p.off_win.is_some_and(|w| w.1 > 0.0));
        let new = match self.bridge {
            Some(b) if duty != 0.0 && period_s > 0.0 => {
                let half = 0.5 * duty.abs() * period_s;
                let centre = 0.5 * period_s + b.delay_s;
                Some(Pulse {
                    on: centre - half,
                    off: centre + half,
                    sign: duty.signum(),
                    on_fixed: false,
                    off_fixed: false,
                    edges: duty.abs() < 1.0,
                    on_win: None,
                    off_win: None,
                    on_slew: None,
                })
            }
            _ => None,
        };
        self.pulses = [carried, new];
        self.phase = 0.0;
        self.duty = duty;
    }

    /// The bridge's outputs on or off (the timer's outputs disabled, the pins taken from it):
    /// off, the bridge applies no voltage.
    pub fn set_outputs(&mut self, on: bool) {
        self.outputs_on = on;
    }

    /// The bridge's drive at the period's phase `x` \[s\], as a signed fraction of the
    /// supply \[-1, 1\]: the duty for the ideal bridge; for the real one ±1 inside a pulse
    /// (as its edges stand now), 0 in the brake; 0 with the outputs off.
    fn drive_at(&self, x: f64) -> f64 {
        if !self.outputs_on {
            return 0.0;
        }
        if self.bridge.is_none() {
            return self.duty;
        }
        let s: f64 = self.pulses.iter().flatten().map(|p| p.drive_at(x)).sum();
        s.clamp(-1.0, 1.0)
    }

    /// The first pulse edge after the phase `x` and before `end` \[s\] (else `end`): where
    /// the drive may change.
    fn next_edge(&self, x: f64, end: f64) -> f64 {
        let mut n = end;
        for p in self.pulses.iter().flatten() {
            let wins = [p.on_win, p.off_win].into_iter().flatten();
            for y in [p.on, p.off]
                .into_iter()
                .chain(wins.flat_map(|w| [w.0, w.1]))
            {
                if y > x && y < n {
                    n = y;
                }
            }
        }
        n
    }

    /// Fixes the real bridge's edges reached by the phase `x` \[s\], each with its dead time
    /// on the side the current's direction at that instant gives it (`t_at`: the time `t`
    /// of that phase). With the outputs off nothing switches.
    fn fix_edges(&mut self, x: f64, t_at: f64) {
        let Some(b) = self.bridge else {
            return;
        };
        if !self.outputs_on {
            return;
        }
        let i = self.i;
        let mut edge = self.last_edge;
        if b.c_node_f > 0.0 {
            let (c, v, td) = (b.c_node_f, self.supply, b.dead_time_s);
            for p in self.pulses.iter_mut().flatten() {
                fix_slewing(p, x, t_at, i, (c, v, td), &mut edge);
            }
            self.last_edge = edge;
            return;
        }
        for p in self.pulses.iter_mut().flatten() {
            // The current in the pulse's direction: during the dead time it flows on through
            // the low side's diode (the brake's voltage) and the pulse starts late; against
            // it, through the high side's (the drive's) and the pulse ends late.
            let along = p.sign * i >= 0.0;
            // The output's edges, for the amplifier's recovery: the drive's start lifts one
            // motor lead from the brake's ground to the supply (a rising common-mode step at
            // an inline shunt), its end brings it back (falling), whichever the direction.
            if !p.on_fixed && p.on <= x {
                if p.edges && along {
                    p.on += b.dead_time_s;
                }
                p.on_fixed = true;
                if p.edges {
                    edge = later(edge, (t_at + p.on - x, 1.0));
                }
            }
            if !p.off_fixed && p.off <= x {
                if p.edges && !along {
                    p.off += b.dead_time_s;
                }
                p.off_fixed = true;
                if p.edges {
                    edge = later(edge, (t_at + p.off - x, -1.0));
                }
            }
        }
        self.last_edge = edge;
    }

    /// The resistance in the current's path \[ohm\]: the winding's and, for the real bridge,
    /// its switches'.
    fn r_path(&self) -> f64 {
        self.r + self.bridge.map_or(0.0, |b| b.r_on_ohm)
    }

    /// The bridge's supply terminal \[V\] (the supply less its source resistance's drop
    /// under the current drawn in the last step): what a board's divider reads.
    pub fn supply_volts(&self) -> f64 {
        self.bus
    }

    /// Advances the plant by `dt` \[s\] at the applied voltage.
    pub fn step(&mut self, dt: f64) {
        // The electrical side exactly, piece by piece: within a step the bridge's voltage
        // changes only at its pulses' edges, and between them L di/dt = V - R i - k_E ω has
        // its closed form (ω held over the step); R the winding's and, for the real bridge,
        // the switches' in the current's path. Each edge is fixed with the current at its own
        // instant, so the dead time takes its side from the current's direction there (the
        // ripple's, near a zero crossing), and the sense amplifier's lag follows the
        // current's exponentials exactly. (Averaging each step's voltage instead, at 10
        // steps a period, moved a sub-step pulse's charge by up to a step: the reading at the
        // counter's bottom came out +0.74 % against the period's mean current on the default
        // motor, where the pieces give +0.27 %, the amplifier's lag.)
        let (a, end) = (self.phase, self.phase + dt);
        let r = self.r_path();
        let rate = r / self.l;
        let emf = self.k_e * self.omega;
        let k_s = if self.sense_tau > 0.0 {
            1.0 / self.sense_tau
        } else {
            0.0
        };
        let (mut i_int, mut i2_int, mut v_int, mut bus_int, mut vi_int) = (0.0, 0.0, 0.0, 0.0, 0.0);
        let mut x = a;
        loop {
            self.fix_edges(x, self.t + x - a);
            let y = self.next_edge(x, end);
            let h = y - x;
            if h > 0.0 {
                let drive = self.drive_at(0.5 * (x + y));
                // The supply's terminal sags by its source resistance times the current it
                // delivers (the drive's share of the motor's), at the piece's start.
                let bus = self.supply - self.r_source * drive * self.i;
                let v = drive * bus;
                let i_ss = (v - emf) / r;
                let d0 = self.i - i_ss;
                let whole = h == dt;
                let e = if whole {
                    per_step(&mut self.decay_memo, dt, |dt| (-rate * dt).exp())
                } else {
                    (-rate * h).exp()
                };
                let int = i_ss * h + d0 * (1.0 - e) / rate; // ∫ i dt
                i_int += int;
                i2_int += i_ss * i_ss * h
                    + 2.0 * i_ss * d0 * (1.0 - e) / rate
                    + d0 * d0 * (1.0 - e * e) / (2.0 * rate); // ∫ i² dt
                vi_int += v * int;
                v_int += v * h;
                bus_int += bus * h;
                if k_s > 0.0 {
                    // The amplifier, y' = (i - y) / tau, driven by i = i_ss + d0 e^(-rate t).
                    let es = if whole {
                        per_step(&mut self.sense_memo, dt, |dt| (-dt * k_s).exp())
                    } else {
                        (-h * k_s).exp()
                    };
                    let gap = k_s - rate;
                    let forced = if gap.abs() > 1e-9 * k_s {
                        d0 * k_s / gap * (e - es)
                    } else {
                        d0 * k_s * h * es
                    };
                    self.sensed = i_ss + (self.sensed - i_ss) * es + forced;
                }
                self.i = i_ss + d0 * e;
            }
            x = y;
            if x >= end {
                break;
            }
        }
        self.bus = bus_int / dt;
        self.voltage = v_int / dt;
        self.phase = end;
        let i_avg = i_int / dt;
        self.energy.input += vi_int;
        self.energy.copper += r * i2_int;
        self.energy.converted += emf * i_int;
        self.energy.magnetic = 0.5 * self.l * self.i * self.i;
        if k_s == 0.0 {
            self.sensed = self.i;
        }
        // Mechanics: semi-implicit Euler with the friction, cogging and coupling of the
        // current state.
        let torque = self.k_m * i_avg;
        let (dtheta, dslide) = match self.two_mass {
            None => {
                self.omega += (torque - self.friction - self.cogging) / self.j * dt;
                let d = self.omega * dt;
                self.omega_slide = self.omega;
                self.energy.friction += self.friction * d;
                (d, d)
            }
            Some(m) => {
                let dw = self.omega - self.omega_slide;
                let coupling = m.k * (self.theta - self.theta_slide) + m.c * dw;
                self.omega += (torque - self.friction_act - self.cogging - coupling) / m.j_m * dt;
                self.omega_slide += (coupling - self.friction_gw) / m.j_l * dt;
                let (d, dl) = (self.omega * dt, self.omega_slide * dt);
                // The damper's loss over the step at the new relative speed (the one that
                // moves the masses; the step's work of the coupling is c dw_new (d - dl)).
                let dw_new = self.omega - self.omega_slide;
                self.energy.damping += m.c * dw * dw_new * dt;
                self.energy.friction += self.friction_act * d + self.friction_gw * dl;
                (d, dl)
            }
        };
        self.theta += dtheta;
        self.theta_slide += dslide;
        let ta = self.actuator.advance(dtheta as f32, dt as f32) as f64;
        let fg = self
            .guideway
            .advance((self.ratio * dslide) as f32, dt as f32) as f64;
        self.t += dt;
        let drift = self.drift.factor(self.t, self.theta);
        let ta = self.ripple.screw_factor(self.theta, self.gear_ratio) * ta;
        self.friction = drift * (ta + self.ratio * fg);
        self.friction_act = drift * ta;
        self.friction_gw = drift * self.ratio * fg;
        let (cog, cog_energy) = self.ripple.cogging(self.theta);
        self.cogging = cog;
        self.energy.cogging = cog_energy;
        match self.two_mass {
            None => self.energy.kinetic = 0.5 * self.j * self.omega * self.omega,
            Some(m) => {
                let d = self.theta - self.theta_slide;
                self.energy.spring = 0.5 * m.k * d * d;
                self.energy.kinetic = 0.5 * m.j_m * self.omega * self.omega
                    + 0.5 * m.j_l * self.omega_slide * self.omega_slide;
            }
        }
    }
}

/// Fixes `p`'s edges reached by the phase `x` \[s\] (`t_at` the time `t` of that phase) with
/// the current `i` \[A\] now, the switching node of capacitance `c` \[F\] slewed by it during
/// the dead time `td` \[s\] across `volts` \[V\]; the output's edges into `edge`.
///
/// At the on-edge the low side turns off: a current along the drive holds the node at the
/// brake's rail through the low side's diode until the high side comes on `td` later; one
/// against it slews the node towards the drive's rail. At the off-edge the high side turns
/// off: a current against the drive holds the node at the drive's rail through the high
/// side's diode until the low side comes on; one along it slews the node towards the brake's.
/// A pulse shorter than `td` never turns the high side on: both switches stay off from its
/// on-edge to `td` after its off-edge, the node slewed by the on-edge's current throughout.
fn fix_slewing(
    p: &mut Pulse,
    x: f64,
    t_at: f64,
    i: f64,
    (c, volts, td): (f64, f64, f64),
    edge: &mut Option<(f64, f64)>,
) {
    let along = p.sign * i >= 0.0;
    let at = |y: f64| t_at + y - x;
    if !p.on_fixed && p.on <= x {
        p.on_fixed = true;
        if p.edges {
            let x0 = p.on;
            p.on = x0 + td;
            if along {
                *edge = later(*edge, (at(x0 + td), 1.0));
            } else {
                p.on_slew = Some(i.abs());
                p.on_win = Some((x0, x0 + td, slew_share(i.abs(), c, volts, td)));
                *edge = later(*edge, (at(x0), 1.0));
            }
        }
    }
    if !p.off_fixed && p.off <= x {
        p.off_fixed = true;
        if p.edges {
            let x1 = p.off;
            if x1 < p.on {
                // The high side never came on.
                let x0 = p.on - td;
                p.on = x1 + td;
                p.off = x1 + td;
                p.on_win = p
                    .on_slew
                    .map(|amps| (x0, x1 + td, slew_share(amps, c, volts, x1 + td - x0)));
                *edge = later(*edge, (at(x1 + td), -1.0));
            } else if along {
                p.off_win = Some((x1, x1 + td, 1.0 - slew_share(i.abs(), c, volts, td)));
                *edge = later(*edge, (at(x1), -1.0));
            } else {
                p.off = x1 + td;
                *edge = later(*edge, (at(x1 + td), -1.0));
            }
        }
    }
}

/// The later of the last edge `last` and a new one `(time, direction)`.
fn later(last: Option<(f64, f64)>, new: (f64, f64)) -> Option<(f64, f64)> {
    match last {
        Some(l) if l.0 > new.0 => Some(l),
        _ => Some(new),
    }
}
