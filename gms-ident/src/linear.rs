//! A linear model of the axis and its loops, derived from the plant's equations and the
//! controller's (not from any measurement): what the simulator checks a frequency-response
//! measurement against (with its plant's own constants, `hil_sim::plant::Plant::small_signal`),
//! and what commissioning models the loop with (with the constants it measured).
//!
//! The plant, linearised ([`SmallSignal`]): the winding `L di/dt = v − R i −
//! k_E ω_m`; the rotor `J_m ω̇_m = k_M i − K_a θ_m − σ_a ω_m − K (θ_m − θ_l) − c (ω_m − ω_l)`
//! and the slide `J_l ω̇_l = K (θ_m − θ_l) + c (ω_m − ω_l) − K_g θ_l − σ_g ω_l` (a rigid stage:
//! one inertia carrying both frictions). The frictions are their small-signal forms: at rest
//! the pre-sliding springs (`K_a`, `K_g`: the blocks' Σk of a GMS, every block sticking) and
//! the viscous terms; sliding, the viscous terms alone (the Stribeck slope, small well above
//! the Stribeck velocity, is left out). Noise, quantisation and the voltage limit are left out.
//!
//! The digital side as the device runs it: per current-loop period the current is sampled, the
//! PI with the resistance feedforward computes a voltage, and that voltage is applied during the
//! *next* period (the simulated bridge's one-period delay); the winding and the mechanics
//! between samples are solved exactly (zero-order hold, matrix exponential). Lifted over the
//! `ratio` current periods of one position period, this is a discrete state-space system from
//! the current command (held over the position period) to the position and current sampled at
//! the position steps: the plant `P(z)` a device's lock-in measures. The position controller
//! `C(z)` is the PID of `gms_core::control::controller` written as a transfer function (integral
//! including this step's error, derivative on the measured position's difference through the
//! first-order filter), times the loop-shaping filters' response; the loop gain is `C P`.

use nalgebra::{Complex, DMatrix, DVector};

use gms_core::control::shaping::Shaping;
use gms_core::protocol::Settings;

/// The plant's constants for a linear model (SI, everything at the motor).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SmallSignal {
    /// Winding resistance \[ohm\].
    pub r: f64,
    /// Winding inductance \[H\].
    pub l: f64,
    /// Torque constant \[N·m/A\].
    pub k_m: f64,
    /// Back-EMF constant \[V·s/rad\].
    pub k_e: f64,
    /// The whole inertia at the motor \[kg·m²\].
    pub j: f64,
    /// A compliant stage: rotor-side inertia, slide inertia \[kg·m²\], coupling stiffness
    /// \[N·m/rad\] and damping \[N·m·s/rad\], all reflected to the motor.
    pub two_mass: Option<(f64, f64, f64, f64)>,
    /// The actuator friction's stiffness at rest (pre-sliding) \[N·m/rad\].
    pub k_act: f64,
    /// The actuator friction's viscous coefficient \[N·m·s/rad\].
    pub sigma_act: f64,
    /// The guideway friction's stiffness at rest, reflected \[N·m/rad\].
    pub k_gw: f64,
    /// The guideway friction's viscous coefficient, reflected \[N·m·s/rad\].
    pub sigma_gw: f64,
    /// Encoder resolution \[rad/count\].
    pub rad_per_count: f64,
}

type C64 = Complex<f64>;

/// Where the axis is linearised.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Operating {
    /// At rest: the frictions are their pre-sliding springs and viscous terms.
    Rest,
    /// Sliding at a constant speed: the frictions' viscous terms alone.
    Sliding,
}

/// The axis and its loops as a linear model.
pub struct LinearAxis {
    /// Lifted state matrix (one position period).
    a: DMatrix<f64>,
    /// Lifted input (the current command held over the period).
    b: DVector<f64>,
    /// Index of the motor angle in the state.
    theta: usize,
    /// Index of the winding current in the state.
    current: usize,
    /// The position period \[s\].
    dt: f64,
    ctrl: PositionController,
}

/// The device's position controller as a transfer function: the PID of
/// `gms_core::control::controller` (integral including this step's error, derivative on the measured
/// position's difference through the first-order filter) times the loop-shaping filters.
pub struct PositionController {
    s: Settings,
    shaping: Option<Shaping>,
}

impl PositionController {
    /// The controller of the settings `s`.
    pub fn new(s: &Settings) -> Result<PositionController, String> {
        let shaping = if s.shaping == gms_core::control::shaping::ShapingParams::OFF {
            None
        } else {
            Some(
                Shaping::try_new(&s.shaping, s.pos_rate_hz)
                    .map_err(|e| format!("the filters: {}", e.reason()))?,
            )
        };
        Ok(PositionController { s: *s, shaping })
    }

    /// The torque commanded per position error \[N·m/rad\] at `f_hz` (the PID and the
    /// filters; the command is `−C θ` for the measured angle θ).
    pub fn torque(&self, f_hz: f64) -> C64 {
        let p = &self.s;
        let dt = 1.0 / p.pos_rate_hz as f64;
        let zi = C64::from_polar(1.0, -std::f64::consts::TAU * f_hz * dt);
        let alpha = 1.0 - (-std::f64::consts::TAU * p.pid.d_filter_hz as f64 * dt).exp();
        let one = C64::new(1.0, 0.0);
        let pid = C64::new(p.pid.kp as f64, 0.0)
            + p.pid.ki as f64 * dt / (one - zi)
            + p.pid.kd as f64 * alpha * (one - zi) / (dt * (one - (1.0 - alpha) * zi));
        let filt = self.shaping.as_ref().map_or(one, |sh| {
            let (re, im) = sh.response(f_hz, p.pos_rate_hz as f64);
            C64::new(re, im)
        });
        pid * filt
    }
}

impl LinearAxis {
    /// The model of the plant `p` under the controller settings `s`, linearised at `op`.
    pub fn new(p: &SmallSignal, s: &Settings, op: Operating) -> Result<LinearAxis, String> {
        let rest = op == Operating::Rest;
        let (ka, kg) = if rest { (p.k_act, p.k_gw) } else { (0.0, 0.0) };
        // Continuous plant: x = [i, θm, ωm, θl, ωl] (rigid: [i, θ, ω]), input v.
        let (n, ac) = match p.two_mass {
            Some((jm, jl, k, c)) => {
                let mut a = DMatrix::<f64>::zeros(5, 5);
                a[(0, 0)] = -p.r / p.l;
                a[(0, 2)] = -p.k_e / p.l;
                a[(1, 2)] = 1.0;
                a[(2, 0)] = p.k_m / jm;
                a[(2, 1)] = (-ka - k) / jm;
                a[(2, 2)] = (-p.sigma_act - c) / jm;
                a[(2, 3)] = k / jm;
                a[(2, 4)] = c / jm;
                a[(3, 4)] = 1.0;
                a[(4, 1)] = k / jl;
                a[(4, 2)] = c / jl;
                a[(4, 3)] = (-k - kg) / jl;
                a[(4, 4)] = (-c - p.sigma_gw) / jl;
                (5, a)
            }
            None => {
                let mut a = DMatrix::<f64>::zeros(3, 3);
                a[(0, 0)] = -p.r / p.l;
                a[(0, 2)] = -p.k_e / p.l;
                a[(1, 2)] = 1.0;
                a[(2, 0)] = p.k_m / p.j;
                a[(2, 1)] = -(ka + kg) / p.j;
                a[(2, 2)] = -(p.sigma_act + p.sigma_gw) / p.j;
                (3, a)
            }
        };
        let ratio = s.ratio().max(1) as usize;
        let dt_cur = 1.0 / (ratio as f64 * s.pos_rate_hz as f64);
        // Zero-order hold over one current period: exp([[A, B], [0, 0]] dt).
        let mut aug = DMatrix::<f64>::zeros(n + 1, n + 1);
        aug.view_mut((0, 0), (n, n)).copy_from(&(&ac * dt_cur));
        aug[(0, n)] = dt_cur / p.l;
        let e = aug.exp();
        let ad = e.view((0, 0), (n, n)).into_owned();
        let bd = e.view((0, n), (n, 1)).into_owned();
        // One current period on s = [x, integ, v_pending] with input i_cmd:
        //   e = i_cmd − i; integ' = integ + ki dt e; v = kp e + integ' + R_model i_cmd;
        //   x' = Ad x + Bd v_pending (the voltage computed a period ago); v_pending' = v.
        let (kp, ki) = (s.current.kp as f64, s.current.ki as f64);
        let r_ff = s.motor.r as f64;
        let m = n + 2;
        let mut sa = DMatrix::<f64>::zeros(m, m);
        let mut sb = DVector::<f64>::zeros(m);
        sa.view_mut((0, 0), (n, n)).copy_from(&ad);
        for r in 0..n {
            sa[(r, n + 1)] = bd[(r, 0)];
        }
        // integ' = integ + ki dt (i_cmd − i)
        sa[(n, n)] = 1.0;
        sa[(n, 0)] = -ki * dt_cur;
        sb[n] = ki * dt_cur;
        // v' = kp (i_cmd − i) + integ + ki dt (i_cmd − i) + R i_cmd
        sa[(n + 1, 0)] = -(kp + ki * dt_cur);
        sa[(n + 1, n)] = 1.0;
        sb[n + 1] = kp + ki * dt_cur + r_ff;
        // Lifted over `ratio` current periods, the command held.
        let mut a = DMatrix::<f64>::identity(m, m);
        let mut b = DVector::<f64>::zeros(m);
        for _ in 0..ratio {
            b = &sa * b + &sb;
            a = &sa * a;
        }
        Ok(LinearAxis {
            a,
            b,
            theta: 1,
            current: 0,
            dt: 1.0 / s.pos_rate_hz as f64,
            ctrl: PositionController::new(s)?,
        })
    }

    /// z = e^{jωT} at `f_hz`.
    fn z(&self, f_hz: f64) -> C64 {
        C64::from_polar(1.0, std::f64::consts::TAU * f_hz * self.dt)
    }

    /// (zI − A)⁻¹ B at `f_hz`: the state's response per unit current command.
    fn state_response(&self, f_hz: f64) -> Option<DVector<C64>> {
        let z = self.z(f_hz);
        let m = self.a.nrows();
        let mut za = self.a.map(|v| C64::new(-v, 0.0));
        for i in 0..m {
            za[(i, i)] += z;
        }
        za.lu().solve(&self.b.map(|v| C64::new(v, 0.0)))
    }

    /// The plant: motor angle per current command \[rad/A\] at `f_hz`, as sampled at the
    /// position steps.
    pub fn plant(&self, f_hz: f64) -> C64 {
        self.state_response(f_hz)
            .map_or(C64::new(f64::NAN, f64::NAN), |x| x[self.theta])
    }

    /// The current measured per current command at `f_hz` (the current loop's response).
    pub fn current(&self, f_hz: f64) -> C64 {
        self.state_response(f_hz)
            .map_or(C64::new(f64::NAN, f64::NAN), |x| x[self.current])
    }

    /// The position controller with its filters, from the measured angle to the current
    /// command (the command is `−C θ`) \[A/rad\] at `f_hz`.
    pub fn controller(&self, f_hz: f64) -> C64 {
        self.ctrl.torque(f_hz) / self.ctrl.s.motor.k_m as f64
    }

    /// The loop gain `C P` at `f_hz`.
    pub fn open_loop(&self, f_hz: f64) -> C64 {
        self.controller(f_hz) * self.plant(f_hz)
    }
}
