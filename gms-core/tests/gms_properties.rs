//! Property tests of the GMS model over random valid parameter sets and random trajectories.
//! Every expectation is computed independently in f64 from the paper's equations or from a
//! physical law (docs/design.md#the-gms-model lists them).

use gms_core::{Block, FrictionModel, Gms, GmsParams, StribeckParams};
use proptest::prelude::*;

// ---------------------------------------------------------------------------------------------
// Random valid parameter sets.

/// A random GMS parameter set with `N` blocks, in scale-free but physical ranges: forces
/// around `fs` in [1e-4, 10], breakpoints D_i log-uniform over three decades, weights that sum
/// to 1, Stribeck velocity [1e-3, 1], shape factor [0.3, 3], slip time constant 1-100 ms.
fn params<const N: usize>() -> impl Strategy<Value = GmsParams<N>> {
    (
        -4.0f64..1.0,  // log10 fs
        0.0f64..0.95,  // fc / fs
        -3.0f64..0.0,  // log10 vs
        0.3f64..3.0,   // delta
        0.0f64..0.5,   // sigma * vs / fs
        -3.0f64..-1.0, // log10 (fs / c), the slip time constant [s]
        -6.0f64..-3.0, // log10 of the largest breakpoint
        prop::collection::vec((0.0f64..3.0, 0.05f64..1.0), N),
    )
        .prop_map(|(lfs, rc, lvs, delta, rsig, ltau, ld, blocks)| {
            let fs = 10f64.powf(lfs);
            let vs = 10f64.powf(lvs);
            let wsum: f64 = blocks.iter().map(|b| b.1).sum();
            let dmax = 10f64.powf(ld);
            GmsParams {
                stribeck: StribeckParams {
                    fs: fs as f32,
                    fc: (rc * fs) as f32,
                    vs: vs as f32,
                    delta: delta as f32,
                },
                negative: None,
                sigma: (rsig * fs / vs) as f32,
                c: (fs / 10f64.powf(ltau)) as f32,
                blocks: core::array::from_fn(|i| {
                    let alpha = blocks[i].1 / wsum;
                    let d = dmax / 10f64.powf(blocks[i].0);
                    Block {
                        k: (alpha * fs / d) as f32,
                        alpha: alpha as f32,
                    }
                }),
            }
        })
}

/// Parameter sets for the mass-spring simulations: like [`params`] but with the pre-sliding
/// range tied to the sliding scale (largest breakpoint 1-10 % of Vs·tau, tau = Fs/C the slip
/// time constant) so that one simulation resolves both in reasonable time, and Fs clearly
/// above Fc (no velocity weakening, no stick-slip).
fn dyn_params<const N: usize>() -> impl Strategy<Value = GmsParams<N>> {
    (
        -4.0f64..1.0,  // log10 fs
        0.3f64..0.8,   // fc / fs
        -3.0f64..0.0,  // log10 vs
        0.5f64..2.0,   // delta
        -3.0f64..-1.0, // log10 tau
        -2.0f64..-1.0, // log10 (dmax / (vs tau))
        prop::collection::vec((0.0f64..1.0, 0.05f64..1.0), N),
    )
        .prop_map(|(lfs, rc, lvs, delta, ltau, ld, blocks)| {
            let fs = 10f64.powf(lfs);
            let vs = 10f64.powf(lvs);
            let tau = 10f64.powf(ltau);
            let dmax = vs * tau * 10f64.powf(ld);
            let wsum: f64 = blocks.iter().map(|b| b.1).sum();
            GmsParams {
                stribeck: StribeckParams {
                    fs: fs as f32,
                    fc: (rc * fs) as f32,
                    vs: vs as f32,
                    delta: delta as f32,
                },
                negative: None,
                sigma: 0.0,
                c: (fs / tau) as f32,
                blocks: core::array::from_fn(|i| {
                    let alpha = blocks[i].1 / wsum;
                    Block {
                        k: (alpha * fs * 10f64.powf(blocks[i].0) / dmax) as f32,
                        alpha: alpha as f32,
                    }
                }),
            }
        })
}

// ---------------------------------------------------------------------------------------------
// Independent f64 expectations.

/// The Stribeck magnitude |s(v)| in f64, straight from the paper's eq. 1 with delta.
fn s_abs(p: &StribeckParams, v: f64) -> f64 {
    let (fs, fc, vs, d) = (p.fs as f64, p.fc as f64, p.vs as f64, p.delta as f64);
    fc + (fs - fc) * (-(v.abs() / vs).powf(d)).exp()
}

/// The quasi-static virgin curve `sum_i min(k_i x, alpha_i Fs)` (odd in x), in f64.
fn virgin<const N: usize>(p: &GmsParams<N>, x: f64) -> f64 {
    let fs = p.stribeck.fs as f64;
    let f: f64 = p
        .blocks
        .iter()
        .map(|b| (b.k as f64 * x.abs()).min(b.alpha as f64 * fs))
        .sum();
    f * x.signum()
}

/// The largest breakpoint D_i = alpha_i Fs / k_i.
fn dmax<const N: usize>(p: &GmsParams<N>) -> f64 {
    p.blocks
        .iter()
        .map(|b| b.breakpoint(p.stribeck.fs) as f64)
        .fold(0.0, f64::max)
}

/// Quasi-static motion: a velocity so small that |s| is Fs to f32 precision for any delta in
/// the ranges above ((1e-20)^0.3 = 1e-6).
fn quasi_static_dt(p: &StribeckParams, dx: f64) -> f32 {
    (dx.abs() / (p.vs as f64 * 1e-20)) as f32
}

/// Moves the model quasi-statically from `from` to `to` in `steps` equal increments.
fn creep<const N: usize>(m: &mut Gms<N>, from: f64, to: f64, steps: usize) -> f32 {
    let dx = (to - from) / steps as f64;
    let dt = quasi_static_dt(&m.params().stribeck, dx);
    for _ in 0..steps {
        m.advance(dx as f32, dt);
    }
    m.force()
}

// ---------------------------------------------------------------------------------------------

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    /// Pre-sliding from the virgin state follows `sum_i min(k_i x, alpha_i Fs)` (paper eq. 3).
    #[test]
    fn virgin_curve_is_the_sum_of_saturating_blocks(
        p in params::<4>(),
        incs in prop::collection::vec(0.0f64..1.0, 1..60),
        neg in any::<bool>(),
    ) {
        let mut m = Gms::try_new(p).unwrap();
        let total: f64 = incs.iter().sum();
        let span = 2.5 * dmax(&p) / total.max(1e-9);
        let dir = if neg { -1.0 } else { 1.0 };
        let fs = p.stribeck.fs as f64;
        let mut x = 0.0f64;
        for inc in incs {
            let dx = dir * inc * span;
            x += dx;
            let dt = quasi_static_dt(&p.stribeck, dx);
            let f = m.advance(dx as f32, dt) as f64;
            let want = virgin(&p, x);
            prop_assert!((f - want).abs() <= 2e-5 * fs, "x={x:e}: {f:e} vs {want:e}");
        }
    }

    /// Masing's rule: after the first reversal from the virgin curve at (x_r, F_r) the branch is
    /// `F_r - 2 F_virgin((x_r - x)/2)`, down to where it meets the opposite virgin curve.
    #[test]
    fn masing_rule_after_first_reversal(
        p in params::<4>(),
        xr_frac in 0.05f64..3.0,
        steps in 5usize..80,
    ) {
        let mut m = Gms::try_new(p).unwrap();
        let xr = xr_frac * dmax(&p);
        let fr = creep(&mut m, 0.0, xr, 17) as f64;
        let fs = p.stribeck.fs as f64;
        let dx = -2.0 * xr / steps as f64;
        let dt = quasi_static_dt(&p.stribeck, dx);
        let mut x = xr;
        for _ in 0..steps {
            x += dx;
            let f = m.advance(dx as f32, dt) as f64;
            let want = fr - 2.0 * virgin(&p, (xr - x) / 2.0);
            prop_assert!((f - want).abs() <= 2e-5 * fs, "x={x:e}: {f:e} vs {want:e}");
        }
    }

    /// Wiping-out: an inner loop inside the outer one leaves no trace. Going up past the
    /// turning point x1 rejoins the virgin curve; a minor loop x2 -> x3 -> x2 on the way down
    /// leaves the same state as going to x2 directly.
    #[test]
    fn wiping_out_and_nonlocal_memory(
        p in params::<4>(),
        x1f in 0.1f64..3.0,
        x2f in -0.95f64..0.95,
        x3f in 0.05f64..0.95,
        x4f in 1.0f64..1.5,
    ) {
        let fs = p.stribeck.fs as f64;
        let x1 = x1f * dmax(&p);
        let x2 = x2f * x1;
        let x3 = x2 + x3f * (x1 - x2);
        let x4 = x4f * x1;
        // Outer branch with an inner loop, then back up beyond x1.
        let mut a = Gms::try_new(p).unwrap();
        creep(&mut a, 0.0, x1, 10);
        creep(&mut a, x1, x2, 10);
        creep(&mut a, x2, x3, 7);
        let fa = creep(&mut a, x3, x2, 7);
        // The same without the inner loop.
        let mut b = Gms::try_new(p).unwrap();
        creep(&mut b, 0.0, x1, 10);
        let fb = creep(&mut b, x1, x2, 10);
        prop_assert!((fa - fb).abs() as f64 <= 2e-5 * fs, "after inner loop {fa:e} vs {fb:e}");
        for (ba, bb) in a.block_forces().iter().zip(b.block_forces()) {
            prop_assert!((ba - bb).abs() as f64 <= 2e-5 * fs);
        }
        // Back up past x1: the virgin curve again.
        let f = creep(&mut a, x2, x4, 13) as f64;
        let want = virgin(&p, x4);
        prop_assert!((f - want).abs() <= 2e-5 * fs, "at x4 {f:e} vs virgin {want:e}");
    }

    /// Steady sliding at constant velocity gives `sum(alpha) s(v) + sigma v` (eq. 6), whatever
    /// the state before and however the time is cut into steps.
    #[test]
    fn steady_sliding_is_stribeck_plus_viscous(
        p in params::<4>(),
        lv in -3.0f64..3.0,
        neg in any::<bool>(),
        pre in prop::collection::vec((-1.0f64..1.0, -4.0f64..0.0), 0..10),
        steps in 1usize..20,
    ) {
        let mut m = Gms::try_new(p).unwrap();
        for (dxf, ldt) in pre {
            m.advance((dxf * 3.0 * dmax(&p)) as f32, 10f64.powf(ldt) as f32);
        }
        let sign = if neg { -1.0 } else { 1.0 };
        let v = sign * p.stribeck.vs as f64 * 10f64.powf(lv);
        // Long enough to pass every breakpoint twice and relax 40 slip time constants.
        let s = s_abs(&p.stribeck, v);
        let t = (4.0 * dmax(&p) / v.abs()).max(40.0 * s / p.c as f64);
        for _ in 0..steps {
            let dt = t / steps as f64;
            m.advance((v * dt) as f32, dt as f32);
        }
        let asum: f64 = p.blocks.iter().map(|b| b.alpha as f64).sum();
        let want = sign * asum * s + p.sigma as f64 * v;
        let f = m.force() as f64;
        prop_assert!((f - want).abs() <= 1e-5 * want.abs(), "v={v:e}: {f:e} vs {want:e}");
    }

    /// The scheme is exact for constant velocity within a step: one step or n sub-steps give
    /// the same state (up to f32 rounding), from any state.
    #[test]
    fn step_size_does_not_matter_at_constant_velocity(
        p in params::<4>(),
        pre in prop::collection::vec((-1.0f64..1.0, -5.0f64..0.0), 0..10),
        dxf in -3.0f64..3.0,
        ldt in -5.0f64..0.0,
        n in 2usize..50,
    ) {
        let mut a = Gms::try_new(p).unwrap();
        for (pdx, pdt) in pre {
            a.advance((pdx * 3.0 * dmax(&p)) as f32, 10f64.powf(pdt) as f32);
        }
        let mut b = a.clone();
        let dx = dxf * dmax(&p);
        let dt = 10f64.powf(ldt);
        a.advance(dx as f32, dt as f32);
        for _ in 0..n {
            b.advance((dx / n as f64) as f32, (dt / n as f64) as f32);
        }
        let fs = p.stribeck.fs as f64;
        for (fa, fb) in a.block_forces().iter().zip(b.block_forces()) {
            prop_assert!((fa - fb).abs() as f64 <= 1e-5 * fs, "{fa:e} vs {fb:e}");
        }
        prop_assert!((a.force() - b.force()).abs() as f64 <= 1e-5 * (fs + (p.sigma as f64 * dx / dt).abs()));
    }

    /// |F_i| never exceeds alpha_i max(Fs, Fc) and nothing is ever NaN, for any finite input:
    /// huge steps, dt -> 0, dt = 0, sign flips every step; non-finite input changes nothing.
    #[test]
    fn block_forces_bounded_and_never_nan(
        p in params::<4>(),
        steps in prop::collection::vec((
            prop_oneof![Just(0.0f32), -1e30f32..1e30, -1e-3f32..1e-3, -1e-9f32..1e-9,
                        Just(f32::MAX), Just(-f32::MAX), Just(f32::MIN_POSITIVE)],
            prop_oneof![Just(0.0f32), Just(1e-45f32), 0.0f32..1e-30, 0.0f32..1.0, Just(1e30f32),
                        Just(f32::MAX)],
            any::<bool>(),
        ), 1..200),
    ) {
        let mut m = Gms::try_new(p).unwrap();
        let smax = p.stribeck.fs.max(p.stribeck.fc);
        let mut flip = 1.0f32;
        for (dx, dt, alternate) in steps {
            if alternate { flip = -flip; }
            let before = m.force();
            let f = m.advance(dx * flip, dt);
            prop_assert!(!f.is_nan());
            for (fi, b) in m.block_forces().iter().zip(&p.blocks) {
                prop_assert!(!fi.is_nan());
                prop_assert!(fi.abs() <= b.alpha * smax * (1.0 + 1e-6), "{fi} > {}", b.alpha * smax);
            }
            // Non-finite input is ignored.
            let state = *m.block_forces();
            prop_assert_eq!(m.advance(f32::NAN, dt), f);
            prop_assert_eq!(m.advance(dx, f32::INFINITY), f);
            prop_assert_eq!(m.advance(dx, -1.0), f);
            prop_assert_eq!(*m.block_forces(), state);
            let _ = before;
        }
    }

    /// v = 0 (dx = 0) holds every block where it is, for any dt.
    #[test]
    fn zero_velocity_holds(
        p in params::<4>(),
        pre in prop::collection::vec((-1.0f64..1.0, -5.0f64..0.0), 1..10),
        ldt in -6.0f64..3.0,
    ) {
        let mut m = Gms::try_new(p).unwrap();
        for (pdx, pdt) in pre {
            m.advance((pdx * 3.0 * dmax(&p)) as f32, 10f64.powf(pdt) as f32);
        }
        let state = *m.block_forces();
        let f = m.advance(0.0, 10f64.powf(ldt) as f32);
        prop_assert_eq!(*m.block_forces(), state);
        prop_assert_eq!(f, state.iter().sum::<f32>());
    }
}

// ---------------------------------------------------------------------------------------------
// Dynamics: frictional lag, stick-slip, no drift. Fewer cases; each is a simulation.

/// Area of the force-velocity loop over one period of `v(t) = v0 (1 + 0.5 sin(w t))`, after
/// three periods to settle, by the trapezoidal rule on the closed sampled loop.
fn lag_loop_area<const N: usize>(p: &GmsParams<N>, v0: f64, w: f64) -> f64 {
    let mut m = Gms::try_new(*p).unwrap();
    let n = 2000;
    let period = 2.0 * std::f64::consts::PI / w;
    let dt = period / n as f64;
    // Settle at v0 first.
    let s = s_abs(&p.stribeck, v0);
    let t0 = (4.0 * dmax(p) / v0).max(40.0 * s / p.c as f64);
    m.advance((v0 * t0) as f32, t0 as f32);
    let mut pts = Vec::with_capacity(n);
    for i in 0..4 * n {
        let t = (i as f64 + 0.5) * dt;
        let v = v0 * (1.0 + 0.5 * (w * t).sin());
        let f = m.advance((v * dt) as f32, dt as f32) as f64 - p.sigma as f64 * v;
        if i >= 3 * n {
            pts.push((v, f));
        }
    }
    // The closed loop: the last point joins the first.
    pts.push(pts[0]);
    let area: f64 = pts
        .windows(2)
        .map(|w| 0.5 * (w[0].1 + w[1].1) * (w[1].0 - w[0].0))
        .sum();
    area.abs()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    /// Frictional lag: under oscillating sliding velocity, force and velocity trace a loop
    /// whose area grows with frequency (slow oscillation: the steady curve, no loop).
    #[test]
    fn frictional_lag_loop_widens_with_frequency(p in params::<4>(), lv in -0.5f64..0.5) {
        // The lag exists only where the Stribeck curve falls: need Fs clearly above Fc.
        prop_assume!(p.stribeck.fc < 0.8 * p.stribeck.fs);
        let v0 = p.stribeck.vs as f64 * 10f64.powf(lv);
        let tau = s_abs(&p.stribeck, v0) / p.c as f64;
        let areas: Vec<f64> = [0.01, 0.05, 0.2]
            .iter()
            .map(|k| lag_loop_area(&p, v0, k / tau))
            .collect();
        prop_assert!(areas[0] < areas[1] && areas[1] < areas[2], "areas {areas:?}");
        // The widest loop is a real effect: a sizeable fraction of (Fs - Fc) times the swing.
        let scale = (p.stribeck.fs - p.stribeck.fc) as f64 * v0;
        prop_assert!(areas[2] > 1e-3 * scale, "area {:e} vs scale {scale:e}", areas[2]);
    }
}

/// A mass on the friction, pulled through a spring whose far end moves at `v_pull`.
/// Returns, over the second half of the run, the mass's lowest and highest velocity and the
/// range (max - min) of the spring force.
///
/// Sized from the friction so that one stick-slip cycle is visible: a slip travels
/// A = 20 Vs tau (tau = Fs / C, the slip time constant), the spring k_s = 2 (Fs - Fc) / A, the
/// natural period is 4 tau, so a slip reaches ~15 Vs. Semi-implicit Euler, 0.1 rad of the
/// stiffest (pre-sliding) oscillation per step.
fn pulled_mass<const N: usize>(
    p: &GmsParams<N>,
    zeta: f64,
    v_pull: f64,
    cycles: f64,
) -> (f64, f64, f64) {
    let st = &p.stribeck;
    let (fs, fc, vs) = (st.fs as f64, st.fc as f64, st.vs as f64);
    let tau = fs / p.c as f64;
    let a = 20.0 * vs * tau;
    let ks = 2.0 * (fs - fc) / a;
    let wn = std::f64::consts::PI / (2.0 * tau);
    let m = ks / (wn * wn);
    // Damping by the viscous term only: zeta = sigma / (2 m wn).
    let mut p = *p;
    p.sigma = (zeta * 2.0 * m * wn) as f32;
    let ktot: f64 = p.blocks.iter().map(|b| b.k as f64).sum::<f64>() + ks;
    let dt = 0.1 / (ktot / m).sqrt();
    // Time to break away, then the given number of stick-slip cycles (a stick lasts at most
    // A / v_pull), and at least 40 natural periods.
    let t_end = fs / (ks * v_pull) + (cycles * a / v_pull).max(40.0 * 4.0 * tau);
    let steps = (t_end / dt) as usize;
    let mut model = Gms::try_new(p).unwrap();
    let (mut x, mut v) = (0.0f64, 0.0f64);
    let (mut vmin, mut vmax) = (f64::INFINITY, f64::NEG_INFINITY);
    let (mut smin, mut smax) = (f64::INFINITY, f64::NEG_INFINITY);
    for i in 0..steps {
        let t = i as f64 * dt;
        let spring = ks * (v_pull * t - x);
        // The friction for the step about to be taken, at the current velocity.
        let dx = v * dt;
        let f = model.advance(dx as f32, dt as f32) as f64;
        v += (spring - f) / m * dt;
        x += dx;
        if i > steps / 2 {
            vmin = vmin.min(v);
            vmax = vmax.max(v);
            smin = smin.min(spring);
            smax = smax.max(spring);
        }
    }
    (vmin, vmax, smax - smin)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(12))]

    /// Stick-slip: a mass-spring pulled slowly (v << Vs) alternates between sticking and fast
    /// slips; pulled fast (v >> Vs) it slides and never sticks. (Some damping is needed for the
    /// latter: undamped, the start-up oscillation from rest to the pulling speed never decays.)
    #[test]
    fn stick_slip_at_low_speed_vanishes_at_high_speed(
        p in dyn_params::<4>(),
        zeta in 0.05f64..0.2,
    ) {
        let vs = p.stribeck.vs as f64;
        let dfs = (p.stribeck.fs - p.stribeck.fc) as f64;
        // Slow: the mass stops, then slips fast; the spring force saws by about 2 (Fs - Fc).
        let (vmin, vmax, range) = pulled_mass(&p, zeta, 0.05 * vs, 3.0);
        prop_assert!(vmin <= 0.0, "slow pull: never stops, lowest velocity {vmin:e}");
        prop_assert!(vmax > 5.0 * vs, "slow pull: slips reach only {vmax:e}");
        prop_assert!(range > dfs, "slow pull: spring force range {range:e} vs Fs-Fc {dfs:e}");
        // Fast: it keeps sliding, never slower than half the pulling speed.
        let v_fast = 100.0 * vs;
        let (vmin, _, _) = pulled_mass(&p, zeta, v_fast, 3.0);
        prop_assert!(vmin > 0.5 * v_fast, "fast pull: lowest velocity {vmin:e} of {v_fast:e}");
    }

    /// No drift: an oscillating force below breakaway makes the mass cycle in pre-sliding,
    /// on a closed hysteresis loop, without creeping away.
    #[test]
    fn no_drift_under_oscillating_force_below_breakaway(
        p in dyn_params::<4>(),
        amp in 0.2f64..0.8,
        bias in -0.1f64..0.1,
    ) {
        let fs = p.stribeck.fs as f64;
        let ktot: f64 = p.blocks.iter().map(|b| b.k as f64).sum();
        let kmin = p.blocks.iter().map(|b| b.k as f64).fold(f64::INFINITY, f64::min);
        // Some damping of the pre-sliding ringing (ratio 0.1 at the initial stiffness) and a
        // quasi-static drive: the force period is at least 200 pre-sliding periods and 20
        // viscous creep times at the softest block.
        let m = 1.0;
        let wpre = (ktot / m).sqrt();
        let sigma = 0.1 * 2.0 * (ktot * m).sqrt();
        let w = (wpre / 200.0).min(kmin / (20.0 * sigma));
        let mut p = p;
        p.sigma = sigma as f32;
        // A whole number of steps per period, so that the samples below are at the same phase.
        let per = (2.0 * std::f64::consts::PI / w / (0.1 / wpre)).round() as usize;
        let dt = 2.0 * std::f64::consts::PI / w / per as f64;
        let mut model = Gms::try_new(p).unwrap();
        let (mut x, mut v) = (0.0f64, 0.0f64);
        let mut at_phase = Vec::new();
        let mut xmax = 0.0f64;
        for i in 0..12 * per {
            let t = i as f64 * dt;
            let load = fs * (bias + amp * (w * t).sin());
            let dx = v * dt;
            let f = model.advance(dx as f32, dt as f32) as f64;
            v += (load - f) / m * dt;
            x += dx;
            xmax = xmax.max(x.abs());
            if i % per == 0 {
                at_phase.push(x);
            }
        }
        // Pre-sliding only: never beyond the largest breakpoint.
        prop_assert!(xmax < dmax(&p), "x reached {xmax:e}, breakpoint {:e}", dmax(&p));
        // The same position at the same phase from the third cycle on, within the model's f32
        // round-off: a creeping model moves by a good part of the amplitude per cycle; f32
        // state near breakaway (0.78 Fs) left 8.8e-5 of it over the nine cycles once (CI, the
        // case in gms_properties.proptest-regressions), beyond the 1e-5 this asked before.
        let drift = (at_phase[at_phase.len() - 1] - at_phase[2]).abs();
        prop_assert!(drift < 1e-3 * xmax, "drift {drift:e} over 9 cycles, amplitude {xmax:e}");
    }
}

// ---------------------------------------------------------------------------------------------
// Unused blocks: a set of 6 that uses 4 is the 4-block model.

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// A 6-block set whose last two blocks are unused (k = alpha = 0) gives, on any
    /// trajectory, the same force bit for bit as the 4-block model of its used blocks, and
    /// its state is the 4 used blocks' forces.
    #[test]
    fn unused_blocks_are_the_smaller_model_bit_for_bit(
        p in params::<4>(),
        steps in prop::collection::vec((-1.0f64..1.0, 1e-5f64..1e-2), 1..400),
    ) {
        let mut six = GmsParams::<6> {
            stribeck: p.stribeck,
            negative: p.negative,
            sigma: p.sigma,
            c: p.c,
            blocks: [gms_core::UNUSED_BLOCK; 6],
        };
        six.blocks[..4].copy_from_slice(&p.blocks);
        prop_assert_eq!(six.blocks_used(), 4);
        let mut a = Gms::try_new(p).unwrap();
        let mut b = Gms::try_new(six).unwrap();
        // Steps up to a few times the largest breakpoint: pre-sliding and sliding.
        let scale = p.blocks.iter().map(|b| b.breakpoint(p.stribeck.fs)).fold(0.0f32, f32::max);
        for (dx, dt) in steps {
            let dx = (dx * 3.0) as f32 * scale;
            let (fa, fb) = (a.advance(dx, dt as f32), b.advance(dx, dt as f32));
            prop_assert_eq!(fa.to_bits(), fb.to_bits());
        }
        prop_assert_eq!(a.state(), b.state());
    }
}

/// The used blocks come first; a set uses at least one.
#[test]
fn unused_blocks_only_at_the_end() {
    let mut p = gms_core::friction::presets::table1();
    assert_eq!(p.blocks_used(), 6);
    let four = p.with_blocks_used(4);
    assert_eq!(four.blocks_used(), 4);
    assert_eq!(four.blocks[4], gms_core::UNUSED_BLOCK);
    // Weights no longer sum to 1: the set is invalid until they are given again.
    assert_eq!(four.validate(), Err(gms_core::ParamError::AlphaSum));
    // A gap: block 3 unused, block 4 in use.
    p.blocks[3] = gms_core::UNUSED_BLOCK;
    assert_eq!(p.validate(), Err(gms_core::ParamError::AfterUnused(4)));
    assert_eq!(
        p.validate().unwrap_err().to_string(),
        "blocks[4] follows an unused block (k = alpha = 0): the used blocks come first"
    );
    // Half a block (k = 0, alpha > 0) is not unused.
    let mut q = gms_core::friction::presets::table1();
    q.blocks[5].k = 0.0;
    assert_eq!(q.validate(), Err(gms_core::ParamError::KNotPositive(5)));
    // None used.
    let none = q.with_blocks_used(0);
    assert_eq!(none.validate(), Err(gms_core::ParamError::KNotPositive(0)));
}
