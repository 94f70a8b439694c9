//! An independent implementation of the paper's equations (eqs 1, 2, 4, 5, 6 with docs/design.md#the-gms-model's
//! reversal rule), integrated naively in f64 with tiny explicit-Euler steps, against what
//! `hil-sim friction` computes with gms-core in f32 at the trajectory's own sampling.

use std::path::Path;

use gms_ident::paramfile::{FrictionSpec, ParamFile};
use hil_sim::friction_cmd::{TrajectoryPoint, read_trajectory, simulate};
use proptest::prelude::*;

/// The paper's GMS in f64, straight from the equations.
struct Reference {
    fs: f64,
    fc: f64,
    vs: f64,
    delta: f64,
    sigma: f64,
    c: f64,
    k: Vec<f64>,
    alpha: Vec<f64>,
    f: Vec<f64>,
}

impl Reference {
    fn new(spec: &FrictionSpec) -> Self {
        let blocks = spec.blocks.clone().unwrap();
        Reference {
            fs: spec.fs.unwrap(),
            fc: spec.fc.unwrap(),
            vs: spec.vs.unwrap(),
            delta: spec.delta.unwrap_or(1.0),
            sigma: spec.sigma.unwrap_or(0.0),
            c: spec.c.unwrap(),
            k: blocks.iter().map(|b| b.k).collect(),
            alpha: blocks.iter().map(|b| b.alpha).collect(),
            f: vec![0.0; blocks.len()],
        }
    }

    /// Eq. 1 with the shape factor.
    fn s(&self, v: f64) -> f64 {
        v.signum() * (self.fc + (self.fs - self.fc) * (-(v.abs() / self.vs).powf(self.delta)).exp())
    }

    /// Moves at constant velocity v for a time dt; returns eq. 6.
    fn run(&mut self, v: f64, dt: f64) -> f64 {
        if v != 0.0 {
            let s = self.s(v);
            // Sub-steps: a thousandth of the smallest breakpoint, a thousandth of the slip
            // time constant.
            let dmin = self
                .k
                .iter()
                .zip(&self.alpha)
                .map(|(k, a)| a * self.fs / k)
                .fold(f64::INFINITY, f64::min);
            let h_max = (1e-3 * dmin / v.abs()).min(1e-3 * s.abs() / self.c);
            let n = (dt / h_max).ceil().max(1.0) as usize;
            let h = dt / n as f64;
            for _ in 0..n {
                for i in 0..self.f.len() {
                    let w = self.alpha[i] * s;
                    let fi = self.f[i];
                    let sticks = fi.abs() < w.abs() || fi * v < 0.0;
                    self.f[i] += if sticks {
                        self.k[i] * v * h // eq. 4
                    } else {
                        v.signum() * self.c * (self.alpha[i] - fi / s) * h // eq. 5
                    };
                }
            }
        }
        self.f.iter().sum::<f64>() + self.sigma * v
    }
}

/// Largest |hil-sim - reference| over the trajectory, relative to Fs.
fn worst_deviation(spec: &FrictionSpec, traj: &[TrajectoryPoint]) -> f64 {
    let mut model = spec.build().unwrap();
    let ours = simulate(&mut model, traj);
    let mut reference = Reference::new(spec);
    let mut worst = 0.0f64;
    for (i, row) in ours.iter().enumerate().skip(1) {
        let (p, s) = (traj[i - 1], traj[i]);
        let v = (s.x - p.x) / (s.t - p.t);
        let want = reference.run(v, s.t - p.t);
        worst = worst.max((row.f as f64 - want).abs() / reference.fs);
    }
    worst
}

fn example(name: &str) -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../examples")
        .join(name)
}

/// The shipped trajectory (pre-sliding loops, then sliding) with the shipped Table 1 file:
/// agreement within 0.2 % of Fs at every sample.
#[test]
fn shipped_example_agrees_with_the_paper_equations() {
    let spec = ParamFile::load(&example("table1.toml")).unwrap().friction;
    let traj = read_trajectory(&example("trajectory.csv")).unwrap();
    let worst = worst_deviation(&spec, &traj);
    eprintln!(
        "shipped example: worst deviation {:.5} % of Fs",
        worst * 100.0
    );
    assert!(worst < 2e-3, "worst deviation {:.4} % of Fs", worst * 100.0);
}

/// A random trajectory: segments of constant velocity, log-uniform speeds from 1e-4 to 10 Vs,
/// durations such that each segment moves up to a few largest breakpoints (so both pre-sliding
/// loops and sliding occur), at a random sampling interval.
fn trajectory(vs: f64, dmax: f64) -> impl Strategy<Value = Vec<TrajectoryPoint>> {
    prop::collection::vec(
        (-4.0f64..1.0, any::<bool>(), 0.05f64..4.0, 1usize..20),
        2..25,
    )
    .prop_map(move |segs| {
        let mut out = vec![TrajectoryPoint { t: 0.0, x: 0.0 }];
        for (lv, neg, dist, n) in segs {
            let v = vs * 10f64.powf(lv) * if neg { -1.0 } else { 1.0 };
            let dt = dist * dmax / v.abs() / n as f64;
            for _ in 0..n {
                let last = *out.last().unwrap();
                out.push(TrajectoryPoint {
                    t: last.t + dt,
                    x: last.x + v * dt,
                });
            }
        }
        out
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(16))]

    #[test]
    fn random_trajectories_agree_on_table1(traj in trajectory(0.2, 7.8e-3)) {
        let spec = ParamFile::load(&example("table1.toml")).unwrap().friction;
        let worst = worst_deviation(&spec, &traj);
        prop_assert!(worst < 2e-3, "worst deviation {:.4} % of Fs", worst * 100.0);
    }

    #[test]
    fn random_trajectories_agree_on_the_guideway(traj in trajectory(0.5e-3, 40e-6)) {
        let spec = ParamFile::load(&example("guideway.toml")).unwrap().friction;
        let worst = worst_deviation(&spec, &traj);
        prop_assert!(worst < 2e-3, "worst deviation {:.4} % of Fs", worst * 100.0);
    }
}
