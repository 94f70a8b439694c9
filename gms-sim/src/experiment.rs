//! The identification experiments of the paper (§3), simulated: what a user would measure on
//! the bench, with its resolution and noise, written as CSV for `hil-sim identify`.
//!
//! - `presliding`: the motor torque is raised in small increments from rest, waiting at each
//!   until the motion settles; recorded: the encoder angle (3.8 urad counts) and the torque
//!   (current × k_M, with current-sense noise, averaged over 100 samples of the settled
//!   dwell). Then the same from rest in the other direction.
//! - `sliding`: constant-velocity runs at log-spaced speeds in both directions, from 1/30 to
//!   30 × Vs; recorded: the mean velocity from the encoder and the mean torque.
//! - `guideway`: a tangential force raised in 10 mN increments through a compliant fibre;
//!   displacement from a 1 nm interferometer; a new increment once the slide is almost at rest.
//! - `lag`: frictional lag: a velocity-controlled run in sliding whose speed swings between
//!   0.3 and 2.7 × Vs at a frequency swept from 0.2 to 20 Hz; recorded at 1 kHz: time, the
//!   encoder angle and the torque. The friction lags the speed by the slip time constant
//!   |s(v)|/C, which is what identifies C.

use crate::Error;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::plant::draw_friction;
use gms_ident::paramfile::{AnyModel, FrictionSpec};

/// Which experiment.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// Actuator pre-sliding (torque increments, encoder).
    Presliding,
    /// Actuator sliding (constant-velocity runs).
    Sliding,
    /// Guideway pre-sliding (force increments through a fibre, interferometer).
    Guideway,
    /// Frictional lag in sliding (speed swept sinusoidally, encoder and torque over time).
    Lag,
}

/// The measurement set-up.
#[derive(Debug, Clone, Copy)]
pub struct Setup {
    /// Position resolution [m or rad] (3.8 urad encoder; 1 nm interferometer).
    pub resolution: f64,
    /// Load increment [N or N·m].
    pub increment: f64,
    /// Load noise, standard deviation [N or N·m] (current sense × k_M; load cell).
    pub noise: f64,
    /// Inertia or mass [kg·m^2 or kg].
    pub inertia: f64,
    /// Friction variability drawn per run (± fraction).
    pub variability: f64,
    /// Initial pre-sliding stiffness, for the time step [N/m or N·m/rad].
    pub stiffness: f64,
}

impl Setup {
    /// The paper's set-up for `kind` on the friction `spec`: 3.8 urad encoder and
    /// current × k_M with 0.5 mA of noise (k_M = 6.6 mN·m/A) for the actuator, 100 load steps
    /// to Fs; 10 mN steps, 2 mN load noise and a 1 nm interferometer for the guideway.
    pub fn paper(kind: Kind, spec: &FrictionSpec, variability: f64) -> Setup {
        let fs = spec.fs.unwrap_or(1.0);
        let stiffness: f64 = spec
            .blocks
            .iter()
            .flatten()
            .map(|b| b.k)
            .sum::<f64>()
            .max(1e-12);
        match kind {
            Kind::Presliding | Kind::Sliding | Kind::Lag => Setup {
                resolution: 3.8e-6,
                increment: fs / 100.0,
                noise: 0.5e-3 * 6.6e-3,
                inertia: 6e-8,
                variability,
                stiffness,
            },
            Kind::Guideway => Setup {
                resolution: 1e-9,
                increment: 0.01,
                noise: 2e-3,
                inertia: 0.2,
                variability,
                stiffness,
            },
        }
    }
}

/// A seeded standard normal sample (Box–Muller).
fn gauss(rng: &mut ChaCha8Rng) -> f64 {
    let u1: f64 = rng.random_range(1e-12..1.0);
    let u2: f64 = rng.random_range(0.0..1.0);
    (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
}

/// Samples of the load sensor averaged at each settled increment of a pre-sliding run (the
/// current over 5 ms at 20 kHz; the load cell likewise).
pub const PRESLIDING_AVERAGE: usize = 100;

/// Raises the load from rest in `dir` until the displacement passes `x_max` or the load
/// reaches `f_max`, recording the settled (x, load) pairs.
fn load_steps(
    model: &mut AnyModel,
    s: &Setup,
    dir: f64,
    f_max: f64,
    x_max: f64,
    rng: &mut ChaCha8Rng,
) -> Vec<(f64, f64)> {
    model.reset();
    let (mut x, mut v) = (0.0f64, 0.0f64);
    let mut out = Vec::new();
    let mut load = 0.0;
    // Time step: resolve the stiff pre-sliding oscillation and damp it with a little viscous
    // drag of the surroundings (the paper waits for rest).
    let stiffness = s.stiffness;
    let dt = 0.05 / (stiffness / s.inertia).sqrt();
    let damping = 2.0 * (stiffness * s.inertia).sqrt();
    while load < f_max {
        let start = load;
        load += s.increment;
        let mut t = 0.0;
        let mut still = 0.0;
        let mut friction = model.force() as f64;
        let settle_time = 200.0 * (s.inertia / stiffness).sqrt();
        // The machine ramps each increment in slowly (a micro-tensile machine, a slow current
        // ramp), so that the slide creeps rather than jumps.
        let ramp = 20.0 * settle_time;
        let mut settled = false;
        while t < 400.0 * settle_time {
            let applied = start + (load - start) * (t / ramp).min(1.0);
            let a = (dir * applied - friction - damping * v) / s.inertia;
            v += a * dt;
            let dx = v * dt;
            x += dx;
            friction = model.advance(dx as f32, dt as f32) as f64;
            t += dt;
            // At rest: moving less than one resolution step per settle time.
            still = if t >= ramp && v.abs() * settle_time < s.resolution {
                still + dt
            } else {
                0.0
            };
            if still > settle_time {
                settled = true;
                break;
            }
        }
        // Almost at rest (the paper's criterion) when still creeping below 100 resolution
        // steps per settle time; faster than that, the slide has broken away.
        let creeping = v.abs() * settle_time < 100.0 * s.resolution;
        if !(settled || creeping) || x.abs() > x_max {
            // Gross sliding: the virgin curve ends here.
            break;
        }
        let measured_x = (x / s.resolution).round() * s.resolution;
        // The load is read as the mean of PRESLIDING_AVERAGE samples over the settled dwell.
        let noise = s.noise / (PRESLIDING_AVERAGE as f64).sqrt();
        out.push((measured_x, dir * load + noise * gauss(rng)));
    }
    out
}

/// Runs one experiment on the friction `spec` (drawn within ±variability with `seed`);
/// returns the CSV text.
pub fn run(kind: Kind, spec: &FrictionSpec, setup: &Setup, seed: u64) -> Result<String, Error> {
    run_inner(kind, spec, setup, seed).map_err(Error::Run)
}

fn run_inner(kind: Kind, spec: &FrictionSpec, setup: &Setup, seed: u64) -> Result<String, String> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let drawn = draw_friction(spec, setup.variability, &mut rng);
    let mut model = drawn.build()?;
    let fs = spec.fs.ok_or("the parameter file has no fs")?;
    match kind {
        Kind::Presliding | Kind::Guideway => {
            // Out to 3 × the largest breakpoint (saturation), or just beyond Fs.
            let dmax = spec.largest_breakpoint();
            let mut text = String::from("x,f,dir\n");
            for dir in [1.0, -1.0] {
                let pts = load_steps(
                    &mut model,
                    setup,
                    dir,
                    1.02 * fs,
                    3.0 * dmax.max(setup.resolution * 10.0),
                    &mut rng,
                );
                for (x, f) in pts {
                    text += &format!("{x},{f},{dir}\n");
                }
            }
            Ok(text)
        }
        Kind::Sliding => {
            let vs = spec.vs.ok_or("the parameter file has no vs")?;
            let c = spec.c.unwrap_or(fs / 0.03);
            let dmax = spec.largest_breakpoint();
            let mut text = String::from("v,f\n");
            for dir in [1.0, -1.0] {
                for i in 0..25 {
                    let v = dir * vs / 30.0 * 900f64.powf(i as f64 / 24.0);
                    model.reset();
                    // Run through the pre-sliding range and 20 slip time constants, then
                    // average over a measurement window.
                    let settle = (5.0 * dmax / v.abs()).max(20.0 * fs / c);
                    model.advance((v * settle) as f32, settle as f32);
                    let n = 200;
                    let window = (100.0 * setup.resolution / v.abs()).max(0.05);
                    let dt = window / n as f64;
                    let mut sum = 0.0;
                    for _ in 0..n {
                        sum += model.advance((v * dt) as f32, dt as f32) as f64
                            + setup.noise * gauss(&mut rng);
                    }
                    // Velocity from encoder counts over the window.
                    let counts = (v.abs() * window / setup.resolution).floor();
                    let v_meas = dir * counts * setup.resolution / window;
                    text += &format!("{v_meas},{}\n", sum / n as f64);
                }
            }
            Ok(text)
        }
        Kind::Lag => {
            let vs = spec.vs.ok_or("the parameter file has no vs")?;
            Ok(lag_run(&mut model, vs, setup, &mut rng))
        }
    }
}

/// Length of the frictional-lag run \[s\].
pub const LAG_DURATION: f64 = 8.0;
/// Sample period of the frictional-lag record \[s\].
pub const LAG_SAMPLE: f64 = 1e-3;

/// The frictional-lag run: speed `vs (1.5 + 1.2 sin φ(t))` with the frequency swept
/// logarithmically from 0.2 to 20 Hz over [`LAG_DURATION`], integrated at 10 kHz, recorded at
/// 1 kHz as `t,x,f` (angle quantised to the encoder, torque with its noise).
fn lag_run(model: &mut AnyModel, vs: f64, s: &Setup, rng: &mut ChaCha8Rng) -> String {
    model.reset();
    let (f0, f1) = (0.2f64, 20.0f64);
    let rate = (f1 / f0).ln() / LAG_DURATION;
    // Phase of a logarithmic sweep: φ(t) = 2π f0 (e^{rate t} - 1) / rate.
    let phase = |t: f64| 2.0 * std::f64::consts::PI * f0 * ((rate * t).exp() - 1.0) / rate;
    // Position: the integral of the speed, exact at every sub-step (no drift in x).
    let sub = 10;
    let dt = LAG_SAMPLE / sub as f64;
    let mut text = String::from("t,x,f\n");
    let (mut x, mut f) = (0.0f64, 0.0f64);
    let n = (LAG_DURATION / LAG_SAMPLE).round() as usize;
    text += "0,0,0\n";
    for i in 1..=n {
        for j in 0..sub {
            let t = (i - 1) as f64 * LAG_SAMPLE + (j as f64 + 0.5) * dt;
            let v = vs * (1.5 + 1.2 * phase(t).sin());
            let dx = v * dt;
            x += dx;
            f = model.advance(dx as f32, dt as f32) as f64;
        }
        let t = i as f64 * LAG_SAMPLE;
        let xm = (x / s.resolution).round() * s.resolution;
        text += &format!("{t},{xm},{}\n", f + s.noise * gauss(rng));
    }
    text
}

/// Where `hil-sim experiment` runs an experiment.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Rig {
    /// On the device core driving the simulated axis (the default plant with the actuator
    /// friction of the parameter file, the guideway negligible), through the protocol: the
    /// bench experiments of `gms_bench`, exactly what `gms-tune identify` runs on a
    /// board.
    Device,
    /// On the friction model alone, the paper's idealised set-up (`run`): an imposed torque
    /// or velocity, the rig's damping, no control loop. What the fits' accuracy figures are
    /// measured on; the guideway experiment is always this.
    Ideal,
}
