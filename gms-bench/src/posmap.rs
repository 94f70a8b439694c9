//! Position-dependent compensation, measured (issue 29, the bench side): slow constant-speed
//! runs both ways over whole periods of the map (device-ended timed runs, captured whole),
//! the torque the motor gave at each angle (the capture's `friction`: k_M i − J a_ref, at
//! constant speed the torque needed), each direction smoothed by a least-squares harmonic fit
//! over the map's period, then split: the direction-even part is conservative torque (cogging,
//! a position-dependent preload's spring) — the map's **offset** — and the direction-odd part
//! is friction, expressed as a **scale** of the device's model's sliding friction at that
//! speed. A map measured one way only cannot tell the two apart.

use crate::Error;
use gms_core::protocol::ParamId;
use gms_core::protocol::{Command, MapCmd};
use nalgebra::{DMatrix, DVector};

use crate::client::{Bench, capture_rows, capture_status, check_faults, get_param, guarded};
use crate::settings::restoring;

/// What a map measurement runs.
#[derive(Debug, Clone, PartialEq)]
pub struct MapPlan {
    /// The runs' speed \[rad/s\] (slow: the loop follows the ripple; fast enough that the
    /// friction slides, well above the Stribeck velocity of a GMS model).
    pub speed: f64,
    /// Periods of the map run each way.
    pub periods: f64,
    /// The map's period \[rad\] (one motor revolution by default).
    pub period: f64,
    /// Bins of the map.
    pub bins: usize,
    /// Harmonics of the period in the fit (the smoothing: higher follows sharper ripple,
    /// lower averages more noise).
    pub order: usize,
}

impl Default for MapPlan {
    fn default() -> MapPlan {
        MapPlan {
            speed: 1.0,
            periods: 1.0,
            period: std::f64::consts::TAU,
            bins: 512,
            order: 64,
        }
    }
}

impl MapPlan {
    /// Checks the plan (a bad one changes nothing).
    pub fn check(&self) -> Result<(), Error> {
        let bad = |m: String| Err(Error::Params(m));
        if !(self.speed.is_finite() && self.speed > 0.0 && self.speed <= 20.0) {
            return bad(format!("--speed {}: above 0, at most 20 rad/s", self.speed));
        }
        if !(self.periods.is_finite() && self.periods >= 1.0 && self.periods <= 100.0) {
            return bad(format!("--revs {}: from 1 to 100 periods", self.periods));
        }
        if !(self.period.is_finite() && self.period > 0.0) {
            return bad(format!("the period {}: above 0 rad", self.period));
        }
        if !(8..=4096).contains(&self.bins) {
            return bad(format!("--bins {}: from 8 to 4096", self.bins));
        }
        if self.order == 0 || 2 * self.order >= self.bins {
            return bad(format!(
                "--order {}: at least 1, under half the bins ({})",
                self.order, self.bins
            ));
        }
        Ok(())
    }

    /// The constant-speed time of each run \[s\].
    pub fn run_seconds(&self) -> f64 {
        self.periods * self.period / self.speed
    }

    /// Device time of the whole measurement \[s\]: both runs with their ramps (50 rad/s²) and
    /// half a second each of settling.
    pub fn device_seconds(&self) -> f64 {
        2.0 * (self.run_seconds() + 2.0 * self.speed / crate::client::VELOCITY_ACC + 0.5)
    }
}

/// The samples of a map measurement: (absolute angle \[rad\], torque \[N·m\]) each way.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct MapData {
    /// The run in the positive direction.
    pub forward: Vec<(f64, f64)>,
    /// The run in the negative direction.
    pub backward: Vec<(f64, f64)>,
    /// The speed \[rad/s\].
    pub speed: f64,
}

/// Runs the measurement: from where the axis holds, a timed run forwards over the periods
/// and one back, each captured whole (`t,pos,friction`), the samples at constant speed (after
/// the ramp and half a second of settling) kept. The bridge is off and the settings as they
/// were after it, however it ended.
pub fn measure(b: &mut impl Bench, plan: &MapPlan) -> Result<MapData, Error> {
    plan.check()?;
    let dt = 1.0 / get_param(b, ParamId::RatePosHz)?;
    let acc = crate::client::VELOCITY_ACC;
    let t_acc = plan.speed / acc;
    // Half a second more than the periods: the settling before the samples kept.
    let seconds = plan.run_seconds() + 0.5;
    restoring(b, |b| {
        guarded(b, |b| {
            b.enable()?;
            b.wait(0.1)?;
            let mut data = MapData {
                speed: plan.speed,
                ..MapData::default()
            };
            for dir in [1.0, -1.0] {
                crate::client::timed_run(b, dir * plan.speed, seconds, "t,pos,friction", dt)?;
                let origin = capture_status(b)?.origin;
                let rows = capture_rows(b)?;
                let kept: Vec<(f64, f64)> = rows
                    .iter()
                    .filter(|r| r[0] >= t_acc + 0.5 && r[0] <= t_acc + seconds)
                    .map(|r| (origin + r[1], r[2]))
                    .collect();
                if kept.len() < 4 * plan.order + 8 {
                    return Err(Error::Device(format!(
                        "the run at {} rad/s gave {} samples at constant speed: too few for {} \
                         harmonics",
                        dir * plan.speed,
                        kept.len(),
                        plan.order
                    )));
                }
                if dir > 0.0 {
                    data.forward = kept;
                } else {
                    data.backward = kept;
                }
            }
            check_faults(b)?;
            b.disable()?;
            Ok(data)
        })
    })
}

/// A least-squares fit of `a0 + Σ_k a_k cos(k θ') + b_k sin(k θ')`, θ' = 2π θ / `period`,
/// k = 1 … `order`, to `(θ, y)`; the coefficients `[a0, a1, b1, a2, b2, …]`.
pub fn harmonic_fit(samples: &[(f64, f64)], period: f64, order: usize) -> Option<Vec<f64>> {
    let m = 2 * order + 1;
    if samples.len() < m {
        return None;
    }
    let mut ata = DMatrix::<f64>::zeros(m, m);
    let mut aty = DVector::<f64>::zeros(m);
    let mut row = vec![0.0; m];
    for &(th, y) in samples {
        let w = std::f64::consts::TAU * th / period;
        row[0] = 1.0;
        for k in 1..=order {
            let (s, c) = (k as f64 * w).sin_cos();
            row[2 * k - 1] = c;
            row[2 * k] = s;
        }
        for i in 0..m {
            aty[i] += row[i] * y;
            for j in 0..m {
                ata[(i, j)] += row[i] * row[j];
            }
        }
    }
    let x = ata.cholesky()?.solve(&aty);
    Some(x.iter().copied().collect())
}

/// The fitted series' value at `theta` \[rad\].
pub fn harmonic_eval(coef: &[f64], period: f64, theta: f64) -> f64 {
    let w = std::f64::consts::TAU * theta / period;
    let mut y = coef.first().copied().unwrap_or(0.0);
    for (k, ab) in coef.get(1..).unwrap_or(&[]).chunks_exact(2).enumerate() {
        let (s, c) = (((k + 1) as f64) * w).sin_cos();
        y += ab[0] * c + ab[1] * s;
    }
    y
}

/// A position map: at each bin's angle the torque offset and the friction scale.
#[derive(Debug, Clone, PartialEq)]
pub struct PosMap {
    /// The period \[rad\].
    pub period: f64,
    /// Bin angles \[rad\], from 0 in steps of period / bins (the device's frame: from its
    /// power-up position, modulo the period).
    pub angle: Vec<f64>,
    /// The direction-even torque \[N·m\] (conservative: cogging).
    pub offset: Vec<f64>,
    /// The direction-odd torque over the model's sliding friction at the speed \[-\].
    pub scale: Vec<f64>,
    /// The model's sliding friction at the speed \[N·m\] the scale is relative to.
    pub friction: f64,
    /// RMS residual of each direction's fit \[N·m\] (the noise and what the order leaves).
    pub residual: (f64, f64),
}

/// The map from a measurement: each direction fitted with `plan.order` harmonics of the
/// period (those under four standard errors of the noise dropped), the even part the offset,
/// the odd part over `sliding` (the device's model's sliding friction at the speed \[N·m\],
/// > 0) the scale, sampled at `plan.bins` bins.
pub fn fit(data: &MapData, plan: &MapPlan, sliding: f64) -> Result<PosMap, Error> {
    plan.check()?;
    if !(sliding.is_finite() && sliding > 0.0) {
        return Err(Error::Params(format!(
            "the model's sliding friction {sliding} N·m: a scale needs one above 0"
        )));
    }
    let fit_one = |s: &[(f64, f64)]| {
        harmonic_fit(s, plan.period, plan.order).ok_or_else(|| {
            Error::Data(format!(
                "{} samples do not determine {} harmonics",
                s.len(),
                plan.order
            ))
        })
    };
    let (mut cf, mut cb) = (fit_one(&data.forward)?, fit_one(&data.backward)?);
    let rms = |s: &[(f64, f64)], c: &[f64]| {
        (s.iter()
            .map(|(th, y)| (y - harmonic_eval(c, plan.period, *th)).powi(2))
            .sum::<f64>()
            / s.len().max(1) as f64)
            .sqrt()
    };
    let residual = (rms(&data.forward, &cf), rms(&data.backward, &cb));
    // Only the harmonics that stand out of the noise: a coefficient's standard error is about
    // the residual × √(2/N); a harmonic whose amplitude is under 4 of them is dropped (on an
    // axis without ripple the map is then flat, not the noise of the run).
    for (c, r, n) in [
        (&mut cf, residual.0, data.forward.len()),
        (&mut cb, residual.1, data.backward.len()),
    ] {
        let floor = 4.0 * r * (2.0 / n.max(1) as f64).sqrt();
        for ab in c.get_mut(1..).unwrap_or(&mut []).chunks_exact_mut(2) {
            if ab[0].hypot(ab[1]) < floor {
                ab[0] = 0.0;
                ab[1] = 0.0;
            }
        }
    }
    let angle: Vec<f64> = (0..plan.bins)
        .map(|i| plan.period * i as f64 / plan.bins as f64)
        .collect();
    let (mut offset, mut scale) = (Vec::new(), Vec::new());
    for th in &angle {
        let (f, bk) = (
            harmonic_eval(&cf, plan.period, *th),
            harmonic_eval(&cb, plan.period, *th),
        );
        offset.push(0.5 * (f + bk));
        scale.push(0.5 * (f - bk) / sliding);
    }
    Ok(PosMap {
        period: plan.period,
        angle,
        offset,
        scale,
        friction: sliding,
        residual,
    })
}

/// `map.csv`: `angle_rad,torque_nm,friction_scale`, a line per bin.
pub fn csv(m: &PosMap) -> String {
    let mut s = String::from("angle_rad,torque_nm,friction_scale\n");
    for ((a, o), k) in m.angle.iter().zip(&m.offset).zip(&m.scale) {
        s += &format!("{a},{o},{k}\n");
    }
    s
}

/// The device's model's sliding friction at `speed` \[rad/s\] \[N·m\]: the Stribeck curve and
/// viscous term of its GMS model (`gms.*`, what `list` shows: the actuator's), as the
/// controller's static map computes them.
pub fn model_sliding_friction(s: &gms_core::protocol::Settings, speed: f64) -> f64 {
    gms_core::friction::static_map::StaticMap::try_new(s.ff.actuator.static_params())
        .map_or(0.0, |m| m.force_at(speed.abs() as f32) as f64)
}

/// Writes `map` into the device's table (its geometry set first, the map off while it is
/// written: the device refuses writes while it acts), 3 bins a request; leaves `map.enable`
/// as it was unless `enable`. Returns the bins written.
pub fn write(b: &mut impl Bench, map: &PosMap, enable: bool) -> Result<usize, Error> {
    let n = map.offset.len();
    if !(8..=gms_core::control::posmap::MAP_BINS_MAX).contains(&n) || map.scale.len() != n {
        return Err(Error::Params(format!(
            "a map of {n} bins: the device holds 8 to {}",
            gms_core::control::posmap::MAP_BINS_MAX
        )));
    }
    b.set(ParamId::MapEnable, 0.0)?;
    crate::settings::apply(
        b,
        &[
            (ParamId::MapBins.path().to_string(), format!("{n}")),
            (
                ParamId::MapPeriod.path().to_string(),
                format!("{}", map.period),
            ),
        ],
        false,
    )?;
    let mut start = 0;
    while start < n {
        // Three bins a line (a line is at most 120 characters), each value f32's shortest
        // round trip with an exponent (at most 14 characters).
        let end = (start + 3).min(n);
        let pairs: Vec<String> = (start..end)
            .map(|i| format!("{:e},{:e}", map.offset[i] as f32, map.scale[i] as f32))
            .collect();
        b.send(Command::Map(MapCmd::Write {
            start: start as u32,
            pairs: &pairs.join(" "),
        }))?;
        start = end;
    }
    if enable {
        b.set(ParamId::MapEnable, 1.0)?;
    }
    Ok(n)
}

/// The device's table: `(offset [N·m], scale [-])` per bin of its `map.bins`.
pub fn read(b: &mut impl Bench) -> Result<Vec<(f64, f64)>, Error> {
    let bins = get_param(b, ParamId::MapBins)? as u32;
    let rows = crate::client::read_rows(b, bins, "map", |start, count| {
        Command::Map(MapCmd::Read { start, count })
    })?;
    rows.iter()
        .map(|r| match r.as_slice() {
            [o, s] => Ok((*o, *s)),
            _ => Err(Error::Device(format!("bad map line: {r:?}"))),
        })
        .collect()
}

/// The position error's RMS \[rad\] while the axis runs at `speed` \[rad/s\] for `seconds` (a
/// timed run from where it holds, captured whole; the ramp and half a second after it left
/// out). The bridge is off after it.
pub fn run_error_rms(b: &mut impl Bench, speed: f64, seconds: f64) -> Result<f64, Error> {
    let dt = 1.0 / get_param(b, ParamId::RatePosHz)?;
    let t_acc = speed.abs() / crate::client::VELOCITY_ACC;
    guarded(b, |b| {
        b.enable()?;
        b.wait(0.1)?;
        crate::client::timed_run(b, speed, seconds + 0.5, "t,error", dt)?;
        let rows = capture_rows(b)?;
        let e: Vec<f64> = rows
            .iter()
            .filter(|r| r[0] >= t_acc + 0.5 && r[0] <= t_acc + seconds + 0.5)
            .map(|r| r[1])
            .collect();
        b.disable()?;
        if e.is_empty() {
            return Err(Error::Device("no samples at constant speed".into()));
        }
        Ok((e.iter().map(|x| x * x).sum::<f64>() / e.len() as f64).sqrt())
    })
}
