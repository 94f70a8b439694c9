//! A fixed workload whose f32 results are hashed, so that two builds (host and Cortex-M4F,
//! or two compilers) can be shown to compute the same bits.
//!
//! The workload drives `Gms<6>` (Table 1), LuGre and the static map through a pseudo-random
//! trajectory of reversals, pre-sliding dither, sliding bursts, dt = 0 steps and huge steps,
//! and runs the controller against a toy plant; every output's bit pattern goes into an
//! FNV-1a hash.

use crate::control::controller::{Controller, ControllerParams, FfMode};
use crate::control::reference::RefSample;
use crate::friction::gms::Gms;
use crate::friction::lugre::{LuGre, LugreParams};
use crate::friction::model::FrictionModel;
use crate::friction::presets;
use crate::friction::static_map::{StaticMap, StaticParams};

/// FNV-1a over 32-bit words.
#[derive(Debug, Clone, Copy)]
pub struct Fnv(u64);

impl Default for Fnv {
    fn default() -> Self {
        Fnv(0xcbf2_9ce4_8422_2325)
    }
}

impl Fnv {
    /// Adds the bit pattern of `x`.
    pub fn add(&mut self, x: f32) {
        for b in x.to_bits().to_le_bytes() {
            self.0 ^= b as u64;
            self.0 = self.0.wrapping_mul(0x0100_0000_01b3);
        }
    }

    /// The hash so far.
    pub fn value(&self) -> u64 {
        self.0
    }
}

/// A small deterministic generator (xorshift32).
#[derive(Debug, Clone, Copy)]
pub struct Rng(u32);

impl Rng {
    /// Seeded generator (a zero seed is replaced).
    pub fn new(seed: u32) -> Self {
        Rng(if seed == 0 { 0x9e37_79b9 } else { seed })
    }

    /// Next value in [0, 1).
    pub fn uniform(&mut self) -> f32 {
        let mut x = self.0;
        x ^= x << 13;
        x ^= x >> 17;
        x ^= x << 5;
        self.0 = x;
        (x >> 8) as f32 * (1.0 / 16_777_216.0)
    }
}

/// The increment (dx \[rad\], dt \[s\]) of step `i` of the friction workload.
pub fn friction_input(rng: &mut Rng, i: u32) -> (f32, f32) {
    let u = rng.uniform();
    let dt = if i % 97 == 0 { 0.0 } else { 1e-4 };
    let dx = match i % 400 {
        // Pre-sliding dither of a few counts around a slowly moving point.
        0..=149 => (u - 0.5) * 8.0 * 3.8e-6,
        // Sliding bursts, both directions, across the Stribeck velocity.
        150..=299 => {
            let dir = if (i / 400) % 2 == 0 { 1.0 } else { -1.0 };
            dir * (0.02 + u * 0.6) * 1e-4
        }
        // Reversal every step.
        300..=398 => (if i % 2 == 0 { 1.0 } else { -1.0 }) * u * 1e-5,
        // A huge step.
        _ => (u - 0.5) * 1e3,
    };
    (dx, dt)
}

/// Runs the friction workload for `n` steps; returns the hash of every force.
pub fn friction_hash(n: u32) -> u64 {
    let p = presets::table1();
    let mut h = Fnv::default();
    let (Ok(mut gms), Ok(mut lugre), Ok(mut map)) = (
        Gms::try_new(p),
        LuGre::try_new(LugreParams {
            stribeck: p.stribeck,
            negative: None,
            sigma0: 2.0,
            sigma1: 1e-3,
            sigma: p.sigma,
        }),
        StaticMap::try_new(StaticParams {
            stribeck: p.stribeck,
            negative: None,
            sigma: p.sigma,
        }),
    ) else {
        return 0;
    };
    let mut rng = Rng::new(12345);
    for i in 0..n {
        let (dx, dt) = friction_input(&mut rng, i);
        h.add(gms.advance(dx, dt));
        h.add(lugre.advance(dx, dt));
        h.add(map.advance(dx, dt));
    }
    h.value()
}

/// The controller's parameters of the workload: the device's defaults
/// ([`crate::device::default_settings`]).
pub fn controller_params() -> ControllerParams<6> {
    crate::device::default_settings()
}

/// Runs the controller for `n` position periods against a toy plant (pure inertia with
/// Coulomb-like damping, integrated in f32), once with the `gms` feedforward and once with
/// `gms-adaptive`; returns the hash of every command.
pub fn controller_hash(n: u32) -> u64 {
    let mut h = Fnv::default();
    for mode in [FfMode::Gms, FfMode::GmsAdaptive] {
        let mut p = controller_params();
        p.ff.mode = mode;
        let Ok(mut c) = Controller::try_new(p) else {
            return 0;
        };
        let mut rng = Rng::new(777);
        let (mut theta, mut omega, mut i) = (0.0f32, 0.0f32, 0.0f32);
        let mut ref_pos: i64 = 0;
        for k in 0..n {
            let vel = 0.3 * if (k / 2000) % 2 == 0 { 1.0 } else { -1.0 };
            ref_pos += (vel * 1e-4 / 3.8e-6 * 65536.0) as i64;
            let r = RefSample {
                pos: ref_pos,
                vel,
                acc: 0.0,
            };
            let count = (theta / 3.8e-6) as i64;
            let out = c.position_step(count, &r);
            h.add(out.i_cmd);
            h.add(out.ff_scale);
            for _ in 0..2 {
                let noise = (rng.uniform() - 0.5) * 1e-3;
                let v = c.current_step(i + noise);
                h.add(v.voltage);
                i += (v.voltage - 10.0 * i) * 0.2;
                let torque = 6.6e-3 * i - 150e-6 * if omega > 0.0 { 1.0 } else { -1.0 };
                omega += torque / 6e-8 * 5e-5;
                theta += omega * 5e-5;
            }
        }
    }
    h.value()
}
