//! Commissioning's estimators as pure functions of recorded data (no device): the speed and
//! acceleration of a sampled position, the inertia from a current pulse and the coast after
//! it, the inductance from the current loop's step response. `commission` records the data
//! and calls these; the tests below feed them analytic motions and independently simulated
//! circuits.

use gms_core::protocol::Settings;

/// Speed and acceleration at each sample of a position record: a least-squares parabola over
/// the `2h + 1` samples around it (`t` \[s\] evenly spaced, as a capture's, `y` \[rad\]). Returns
/// `(t, speed [rad/s], acceleration [rad/s²], index)` for every sample with `h` neighbours on
/// each side.
pub fn local_parabolas(t: &[f64], y: &[f64], h: usize) -> Vec<(f64, f64, f64, usize)> {
    let n = t.len().min(y.len());
    let mut out = Vec::new();
    for k in h..n.saturating_sub(h) {
        let (mut s0, mut s1, mut s2, mut s3, mut s4) = (0.0, 0.0, 0.0, 0.0, 0.0);
        let (mut y0, mut y1, mut y2) = (0.0, 0.0, 0.0);
        for j in k - h..=k + h {
            let u = t[j] - t[k];
            let v = y[j];
            s0 += 1.0;
            s1 += u;
            s2 += u * u;
            s3 += u * u * u;
            s4 += u * u * u * u;
            y0 += v;
            y1 += u * v;
            y2 += u * u * v;
        }
        // The normal equations of y = p0 + p1 u + p2 u²; on evenly spaced samples the window
        // is symmetric (s1 = s3 = 0) and they separate.
        let det = s2 * (s0 * s4 - s2 * s2) - s1 * (s1 * s4 - s2 * s3) + s3 * (s1 * s3 - s2 * s2);
        if det.abs() < 1e-300 {
            continue;
        }
        let p1 = (y1 - s1 * y0 / s0) / (s2 - s1 * s1 / s0);
        let p2 = (s0 * y2 - s2 * y0) / (s0 * s4 - s2 * s2);
        out.push((t[k], p1, 2.0 * p2, k));
    }
    out
}

/// The least-squares slope of `y` against `x` (a line through the points' centroid):
/// `Σ(x − x̄)(y − ȳ) / max(Σ(x − x̄)², min_sxx)`. The speed of a constant-speed run from its
/// position samples (every sample, so that a coarse encoder's counts average out rather than
/// only the two ends'), the back-EMF constant from (speed, V − R i) points. `None` without
/// points.
pub fn ls_slope(x: &[f64], y: &[f64], min_sxx: f64) -> Option<f64> {
    let n = x.len().min(y.len());
    if n == 0 {
        return None;
    }
    let (mx, my) = (
        x[..n].iter().sum::<f64>() / n as f64,
        y[..n].iter().sum::<f64>() / n as f64,
    );
    let (mut sxx, mut sxy) = (0.0, 0.0);
    for i in 0..n {
        sxx += (x[i] - mx).powi(2);
        sxy += (x[i] - mx) * (y[i] - my);
    }
    Some(sxy / sxx.max(min_sxx))
}

/// The winding's resistance \[ohm\] and the bridge's voltage step \[V\] from currents held
/// at standstill, `points` of (current \[A\], voltage \[V\]): the least-squares fit of
/// `v = R i + c sign(i)` (the bridge loses `c = t_dead / T × V_supply` of each period's
/// voltage in the current's direction, so that the voltage needed steps by `2 c` through
/// zero). `None` unless both directions are held at two magnitudes at least (the two
/// unknowns apart).
pub fn resistance_and_step(points: &[(f64, f64)]) -> Option<(f64, f64)> {
    let (mut sii, mut sia, mut svi, mut svs) = (0.0, 0.0, 0.0, 0.0);
    let n = points.len() as f64;
    for &(i, v) in points {
        let s = if i > 0.0 {
            1.0
        } else if i < 0.0 {
            -1.0
        } else {
            0.0
        };
        sii += i * i;
        sia += i.abs();
        svi += v * i;
        svs += v * s;
    }
    // Normal equations: [Σi² Σ|i|; Σ|i| n] [R; c] = [Σ v i; Σ v sign(i)].
    let det = sii * n - sia * sia;
    let both = points.iter().any(|p| p.0 > 0.0) && points.iter().any(|p| p.0 < 0.0);
    if !(both && det.is_finite() && det > 1e-12 * sii * n) {
        return None;
    }
    Some(((svi * n - sia * svs) / det, (sii * svs - sia * svi) / det))
}

/// The bridge's loss at standstill as commissioning fits it: `v = R i + sign(i) (α − β / |i|)`
/// (see [`resistance_and_loss`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BridgeLoss {
    /// The current path's resistance \[ohm\].
    pub r: f64,
    /// The loss towards large currents \[V\]: `t_dead / T × V_supply`.
    pub alpha: f64,
    /// How much less it is at small currents \[V·A\]: the loss at `|i|` is `α − β / |i|`.
    /// A switching node of capacitance C, slewed by the current during the dead time, gives
    /// `β = V_supply² C / (2 T)` once it reaches the rail within it (`|i| > C V / t_dead`).
    pub beta: f64,
}

/// The winding's resistance and the bridge's loss from currents held at standstill, `points`
/// of (current \[A\], voltage \[V\]): the least-squares fit of `v = R i + α sign(i) − β / i`.
/// A bridge loses `t_dead / T × V` of each period's voltage in the current's direction, less
/// what the current gives back slewing its switching node during the dead time, which falls
/// as `1 / |i|` (with `v = R i + c sign(i)` instead, that fall is read as resistance: +25 %
/// on the default motor with a 100 pF node). `None` unless both directions are held and
/// three magnitudes at least (the three unknowns apart).
pub fn resistance_and_loss(points: &[(f64, f64)]) -> Option<BridgeLoss> {
    use nalgebra::{Matrix3, Vector3};
    // Normal equations A x = b, A = Σ φ φᵀ, b = Σ φ v, φ = (i, sign(i), −1 / i); solved as
    // `posmap::harmonic_fit` solves its own.
    let mut a = Matrix3::<f64>::zeros();
    let mut b = Vector3::<f64>::zeros();
    let mut mags: Vec<f64> = Vec::new();
    for &(i, v) in points {
        if i == 0.0 || !i.is_finite() || !v.is_finite() {
            return None;
        }
        let phi = Vector3::new(i, i.signum(), -1.0 / i);
        a += phi * phi.transpose();
        b += phi * v;
        if !mags.iter().any(|m| (m - i.abs()).abs() <= 1e-3 * m) {
            mags.push(i.abs());
        }
    }
    let both = points.iter().any(|p| p.0 > 0.0) && points.iter().any(|p| p.0 < 0.0);
    if !both || mags.len() < 3 {
        return None;
    }
    let x = a.cholesky()?.solve(&b);
    x.iter().all(|v| v.is_finite()).then(|| BridgeLoss {
        r: x[0],
        alpha: x[1],
        beta: x[2],
    })
}

/// The reflected inertia \[kg·m²\] from one current pulse of `pulse` \[s\] that starts at
/// t = 0 and the coast after it: `samples` are `(t [s], speed [rad/s], acceleration [rad/s²],
/// current [A])` along the motion's direction. Friction is the same during the pulse and the
/// coast at the same speed, so it cancels between them: J = k_m (i_pulse − i_coast) /
/// (a_pulse − a_coast), over the samples between 30 % and 80 % of the top speed, away from
/// the current's edges by `edge` \[s\] (plus 0.4 ms for the current to settle). `k_m`
/// \[N·m/A\].
pub fn inertia_from_pulse(
    samples: &[(f64, f64, f64, f64)],
    pulse: f64,
    edge: f64,
    k_m: f64,
) -> Result<f64, &'static str> {
    let top = samples.iter().map(|p| p.1).fold(0.0, f64::max);
    if top <= 0.0 {
        return Err("the current pulses did not move the axis");
    }
    let band = |p: &&(f64, f64, f64, f64)| p.1 > 0.3 * top && p.1 < 0.8 * top;
    let push: Vec<_> = samples
        .iter()
        .filter(|p| p.0 > 0.0004 + edge && p.0 < pulse - 0.0002 - edge)
        .filter(band)
        .collect();
    let coast: Vec<_> = samples
        .iter()
        .filter(|p| p.0 > pulse + 0.0004 + edge)
        .filter(band)
        .collect();
    if push.is_empty() || coast.is_empty() {
        return Err("the current pulses were too short to measure the inertia");
    }
    let mean = |v: &[&(f64, f64, f64, f64)], f: fn(&(f64, f64, f64, f64)) -> f64| {
        v.iter().map(|p| f(p)).sum::<f64>() / v.len() as f64
    };
    let (a_p, i_p) = (mean(&push, |p| p.2), mean(&push, |p| p.3));
    let (a_c, i_c) = (mean(&coast, |p| p.2), mean(&coast, |p| p.3));
    if a_p - a_c <= 0.0 {
        return Err("the current pulses gave no acceleration");
    }
    Ok(k_m * (i_p - i_c) / (a_p - a_c))
}

/// The winding's inductance \[H\] from the current loop's response to a step of `amps` \[A\]
/// from rest: `response` is the measured current \[A\] at each position period from the step
/// on, `p` the device's settings (its current loop's gains and rates, the supply), `r` the
/// winding's resistance \[Ω\]. The device's own current loop is run on a winding of
/// inductance L (exact between the periods: the voltage computed in one period drives the
/// next), and L chosen to fit the response in least squares (golden-section search over ln L
/// from 1 µH to 1 H).
pub fn inductance_from_step(
    response: &[f64],
    amps: f64,
    r: f64,
    p: &Settings,
) -> Result<f64, &'static str> {
    let ratio = (p.cur_rate_hz / p.pos_rate_hz).round().max(1.0) as usize;
    let h = 1.0 / p.cur_rate_hz as f64;
    let sse = |l: f64| -> Option<f64> {
        let mut ctrl = gms_core::control::controller::Controller::<6>::try_new(*p).ok()?;
        ctrl.hold_current(amps as f32);
        let (mut i, mut v_prev) = (0.0f64, 0.0f64);
        let mut sse = 0.0;
        for k in 0..(response.len() * ratio) {
            if k % ratio == 0 {
                sse += (i - response[k / ratio]).powi(2);
            }
            let v = ctrl.current_step(i as f32).voltage as f64;
            let e = (-r * h / l).exp();
            let i_ss = v_prev / r;
            i = i_ss + (i - i_ss) * e;
            v_prev = v;
        }
        Some(sse)
    };
    let (mut lo, mut hi) = (1e-6f64.ln(), 1.0f64.ln());
    let g = 0.5 * (5f64.sqrt() - 1.0);
    let f = |x: f64| sse(x.exp()).unwrap_or(f64::INFINITY);
    let (mut x1, mut x2) = (hi - g * (hi - lo), lo + g * (hi - lo));
    let (mut f1, mut f2) = (f(x1), f(x2));
    for _ in 0..80 {
        if f1 < f2 {
            hi = x2;
            (x2, f2) = (x1, f1);
            x1 = hi - g * (hi - lo);
            f1 = f(x1);
        } else {
            lo = x1;
            (x1, f1) = (x2, f2);
            x2 = lo + g * (hi - lo);
            f2 = f(x2);
        }
    }
    let l = (0.5 * (lo + hi)).exp();
    if !l.is_finite() || f1.is_infinite() {
        return Err("the current steps could not be fitted");
    }
    Ok(l)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Exact points of `v = R i + c sign(i)` give R and c back; one direction alone, or one
    /// magnitude both ways (R and c not apart), gives none.
    #[test]
    fn resistance_and_the_bridges_step() {
        let (r, c) = (10.565, 0.1056);
        let v = |i: f64| r * i + c * i.signum();
        let pts: Vec<(f64, f64)> = [0.013, -0.013, 0.026, -0.026, 0.02]
            .iter()
            .map(|&i| (i, v(i)))
            .collect();
        let (rr, cc) = resistance_and_step(&pts).unwrap();
        assert!((rr - r).abs() < 1e-9 && (cc - c).abs() < 1e-9, "{rr} {cc}");
        // The old two-point estimate, (v+ − v−) / (i+ − i−), reads R + c / |i|: 18.7 Ω here.
        let two = (v(0.013) - v(-0.013)) / 0.026;
        assert!((two - (r + c / 0.013)).abs() < 1e-9);
        assert!(resistance_and_step(&pts[..1]).is_none());
        assert!(resistance_and_step(&[(0.01, 0.2), (0.02, 0.3)]).is_none());
        assert!(resistance_and_step(&pts[..2]).is_none());
    }

    /// Exact points of the slewing node's loss (the plant's closed form past the rail,
    /// `α (1 − i_c / (2 |i|))`, i_c = C V / t_dead) give R, α and β = α i_c / 2 back;
    /// `v = R i + c sign(i)` on the same points reads R high; two magnitudes, or one
    /// direction, give none.
    #[test]
    fn resistance_and_the_bridges_loss_with_a_slewing_node() {
        let (r, td, c_node, v_s, t) = (10.565, 220e-9, 100e-12, 12.0, 25e-6);
        let alpha = td / t * v_s;
        let i_c = c_node * v_s / td;
        let v = |i: f64| r * i + i.signum() * alpha * (1.0 - i_c / (2.0 * i.abs()));
        let mags = [0.3, 0.55, 0.8].map(|s| s * 0.02);
        let pts: Vec<(f64, f64)> = mags
            .iter()
            .flat_map(|m| [(*m, v(*m)), (-*m, v(-*m))])
            .collect();
        let f = resistance_and_loss(&pts).unwrap();
        let beta = v_s * v_s * c_node / (2.0 * t);
        assert!((f.r - r).abs() < 1e-9, "{f:?}");
        assert!((f.alpha - alpha).abs() < 1e-9, "{f:?}");
        assert!((f.beta - beta).abs() < 1e-12 && (beta - alpha * i_c / 2.0).abs() < 1e-15);
        let (r2, _) = resistance_and_step(&pts).unwrap();
        assert!(r2 > 1.05 * r, "{r2}");
        assert!(resistance_and_loss(&pts[..4]).is_none());
        let one_way: Vec<_> = pts.iter().copied().filter(|p| p.0 > 0.0).collect();
        assert!(resistance_and_loss(&one_way).is_none());
        assert!(resistance_and_loss(&[(0.0, 0.1), (0.1, 1.0), (-0.2, -2.0)]).is_none());
    }

    /// A line's slope exactly; with noise, the slope of the least-squares line (checked
    /// against the normal equations solved independently); no points, none.
    #[test]
    fn least_squares_slopes() {
        let x: Vec<f64> = (0..50).map(|i| 0.1 + i as f64 * 2e-3).collect();
        let y: Vec<f64> = x.iter().map(|x| 3.0 - 0.75 * x).collect();
        assert!((ls_slope(&x, &y, 0.0).unwrap() + 0.75).abs() < 1e-12);
        let yn: Vec<f64> = y
            .iter()
            .enumerate()
            .map(|(i, y)| y + 1e-3 * ((i * 7919 % 13) as f64 - 6.0))
            .collect();
        // Normal equations of y = a + b x: [n Σx; Σx Σx²] [a b] = [Σy Σxy].
        let n = x.len() as f64;
        let (sx, sxx) = (x.iter().sum::<f64>(), x.iter().map(|x| x * x).sum::<f64>());
        let (sy, sxy) = (
            yn.iter().sum::<f64>(),
            x.iter().zip(&yn).map(|(x, y)| x * y).sum::<f64>(),
        );
        let b = (n * sxy - sx * sy) / (n * sxx - sx * sx);
        assert!((ls_slope(&x, &yn, 0.0).unwrap() - b).abs() < 1e-9 * b.abs());
        assert_eq!(ls_slope(&[], &[], 0.0), None);
        // A single instant: the floor keeps the slope finite.
        assert_eq!(ls_slope(&[1.0, 1.0], &[0.0, 2.0], 1e-8), Some(0.0));
    }

    /// A parabola's speed and acceleration are found exactly at every sample.
    #[test]
    fn local_parabolas_are_exact_on_a_parabola() {
        let t: Vec<f64> = (0..60).map(|k| 0.01 + k as f64 * 1e-4).collect();
        let (p0, v0, a) = (0.3, -2.0, 150.0);
        let y: Vec<f64> = t.iter().map(|t| p0 + v0 * t + 0.5 * a * t * t).collect();
        let va = local_parabolas(&t, &y, 4);
        assert_eq!(va.len(), 60 - 8);
        for (tk, v, acc, k) in va {
            assert_eq!(tk, t[k]);
            assert!((v - (v0 + a * tk)).abs() < 1e-8, "{v}");
            assert!((acc - a).abs() < 1e-5, "{acc}");
        }
    }

    /// A rigid body with Coulomb friction pushed by a pulse, then coasting (analytic): the
    /// inertia comes back exactly, whatever the friction.
    #[test]
    fn the_inertia_of_an_analytic_pulse_and_coast() {
        let (j, k_m, fc, amps, pulse) = (2e-6, 0.012, 1.5e-3, 0.5, 0.02);
        let (a_push, a_coast) = ((k_m * amps - fc) / j, -fc / j);
        let dt = 1e-4;
        let samples: Vec<(f64, f64, f64, f64)> = (0..400)
            .map(|k| {
                let t = k as f64 * dt;
                if t <= pulse {
                    (t, a_push * t, a_push, amps)
                } else {
                    let v = a_push * pulse + a_coast * (t - pulse);
                    (t, v.max(0.0), if v > 0.0 { a_coast } else { 0.0 }, 0.0)
                }
            })
            .collect();
        let est = inertia_from_pulse(&samples, pulse, 0.0, k_m).unwrap();
        assert!((est / j - 1.0).abs() < 1e-9, "{est}");
        // No motion, or a pulse too short for the band: a clear error.
        let still: Vec<_> = samples.iter().map(|s| (s.0, 0.0, 0.0, s.3)).collect();
        assert!(inertia_from_pulse(&still, pulse, 0.0, k_m).is_err());
        assert!(inertia_from_pulse(&samples[..150], pulse, 0.0, k_m).is_err());
    }

    /// The device's current loop on an RL winding simulated independently (Runge-Kutta with
    /// 200 sub-steps per period, the voltage held for the period after it is computed): the
    /// inductance comes back within 1 % from 50 µH to 20 mH.
    #[test]
    fn the_inductance_of_a_simulated_winding() {
        let mut p = gms_core::device::default_settings();
        let r = 2.5;
        p.motor.r = r as f32;
        for l_true in [50e-6, 0.6e-3, 20e-3] {
            // The loop set for this winding (1 kHz), as commissioning would.
            p.current.kp = (2.0 * std::f64::consts::PI * 1000.0 * l_true) as f32;
            p.current.ki = (2.0 * std::f64::consts::PI * 1000.0 * r) as f32;
            let amps = 0.2;
            let ratio = (p.cur_rate_hz / p.pos_rate_hz).round() as usize;
            let h = 1.0 / p.cur_rate_hz as f64;
            let mut ctrl = gms_core::control::controller::Controller::<6>::try_new(p).unwrap();
            ctrl.hold_current(amps as f32);
            let (mut i, mut v_prev) = (0.0f64, 0.0f64);
            let mut response = Vec::new();
            for k in 0..20 * ratio {
                if k % ratio == 0 {
                    response.push(i);
                }
                let v = ctrl.current_step(i as f32).voltage as f64;
                let sub = h / 200.0;
                for _ in 0..200 {
                    let d = |i: f64| (v_prev - r * i) / l_true;
                    let k1 = d(i);
                    let k2 = d(i + 0.5 * sub * k1);
                    let k3 = d(i + 0.5 * sub * k2);
                    let k4 = d(i + sub * k3);
                    i += sub / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4);
                }
                v_prev = v;
            }
            let l = inductance_from_step(&response, amps, r, &p).unwrap();
            assert!((l / l_true - 1.0).abs() < 0.01, "{l} vs {l_true}");
        }
    }
}
