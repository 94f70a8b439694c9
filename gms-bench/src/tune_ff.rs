//! Tuning the feedforward's gain on the bench: the paper's sine test repeated over a sweep of
//! gains, the optimum and how sure it is.

use crate::Error;
use crate::client::velocity;
use crate::client::{
    Bench, DeviceInfo, capture_rows, capture_wait, check_faults, get_param, guarded, primitive,
    rad_per_count,
};
use gms_core::protocol::ParamId;

use crate::settings::restoring;

/// A sine test with reversals: the axis swings `amp` \\[rad\\] to and fro from where it is
/// (velocity mode, a sweep of one frequency `freq` \\[Hz\\] around zero speed) for `seconds`;
/// the position error is captured and its RMS \\[rad\\] returned, leaving out the first period.
/// The same test on the same device gives the same reference: compensations compare on it.
/// Ends holding.
pub fn sine_test(b: &mut impl Bench, amp: f64, freq: f64, seconds: f64) -> Result<f64, Error> {
    if !(amp > 0.0 && amp.is_finite() && freq > 0.0 && freq.is_finite() && seconds * freq >= 2.0) {
        return Err(Error::Params(format!(
            "sine test: amplitude {amp} rad, {freq} Hz, {seconds} s: positive, and at least two \
             periods"
        )));
    }
    guarded(b, |b| {
        let dev = DeviceInfo::read(b)?;
        // One field, within the buffer (192 spare: 8000 of the F405's 8192).
        let room = crate::client::capture_capacity(b)?.saturating_sub(192) as f64;
        let every = crate::client::decimation(seconds * dev.pos_hz, 1, room);
        let samples = (seconds * dev.pos_hz / every as f64).floor() as u32;
        let v_amp = amp * 2.0 * std::f64::consts::PI * freq;
        b.enable()?;
        b.capture("error", every, samples, true)?;
        primitive(b, velocity(0.0, Some((v_amp, freq, freq, seconds))))?;
        b.wait(seconds)?;
        capture_wait(b, 0.05, 400)?;
        check_faults(b)?;
        b.hold()?;
        let rows = capture_rows(b)?;
        let skip = ((dev.pos_hz / freq) / every as f64).ceil() as usize;
        let e: Vec<f64> = rows.iter().skip(skip).map(|r| r[0]).collect();
        if e.is_empty() {
            return Err(Error::Device("the sine test recorded nothing".into()));
        }
        Ok((e.iter().map(|v| v * v).sum::<f64>() / e.len() as f64).sqrt())
    })
}

/// The feedforward-gain tuning's settings: the sine test (amplitude \\[rad\\], frequency
/// \\[Hz\\], duration \\[s\\]); a coarse sweep of `steps` gains from `from` to `to` \\[-\\] (widened
/// when its lowest point is at an edge); then a refinement of `fine_steps` gains around the
/// coarse optimum, each tested `repeats` times.
#[derive(Debug, Clone, PartialEq)]
pub struct TuneFfPlan {
    /// Sine amplitude \\[rad\\].
    pub amp: f64,
    /// Sine frequency \\[Hz\\].
    pub freq: f64,
    /// Each test's duration \\[s\\].
    pub seconds: f64,
    /// The coarse sweep's lowest gain \\[-\\].
    pub from: f64,
    /// The coarse sweep's highest gain \\[-\\].
    pub to: f64,
    /// The coarse sweep's gains, evenly spaced (≥ 4).
    pub steps: usize,
    /// The refinement's gains (≥ 4).
    pub fine_steps: usize,
    /// Tests at each of the refinement's gains (≥ 1).
    pub repeats: usize,
}

impl Default for TuneFfPlan {
    /// 2 mrad at 1 Hz for 3 s; 0.5 to 1.3 in 9 gains; 9 gains twice around the optimum.
    fn default() -> Self {
        TuneFfPlan {
            amp: 2e-3,
            freq: 1.0,
            seconds: 3.0,
            from: 0.5,
            to: 1.3,
            steps: 9,
            fine_steps: 9,
            repeats: 2,
        }
    }
}

/// How far the coarse range may be widened, each time by half its span.
pub const TUNE_FF_WIDENINGS: usize = 3;

/// The standard error of the optimum above which the curve is too flat to choose \\[-\\].
pub const TUNE_FF_FLAT_SE: f64 = 0.05;

impl TuneFfPlan {
    /// Checks the plan: a valid sine test, 0 ≤ from < to ≤ 2 (the protocol's range of
    /// `ff.gain`), 4 to 101 coarse and fine gains, 1 to 10 repeats.
    pub fn check(&self) -> Result<(), Error> {
        let sine_ok = self.amp > 0.0
            && self.amp.is_finite()
            && self.freq > 0.0
            && self.freq.is_finite()
            && self.seconds * self.freq >= 2.0
            && self.seconds <= 60.0;
        if !sine_ok {
            return Err(Error::Params(format!(
                "sine test {} rad, {} Hz, {} s: positive, at least two periods, at most 60 s",
                self.amp, self.freq, self.seconds
            )));
        }
        let range_ok = 0.0 <= self.from && self.from < self.to && self.to <= 2.0;
        if !(range_ok && (4..=101).contains(&self.steps)) {
            return Err(Error::Params(format!(
                "gains {} to {} in {} steps: 0 <= from < to <= 2, 4 to 101 steps",
                self.from, self.to, self.steps
            )));
        }
        if !((4..=101).contains(&self.fine_steps) && (1..=10).contains(&self.repeats)) {
            return Err(Error::Params(format!(
                "refinement of {} gains × {} repeats: 4 to 101 gains, 1 to 10 repeats",
                self.fine_steps, self.repeats
            )));
        }
        Ok(())
    }

    /// The coarse sweep's gains.
    pub fn gains(&self) -> Vec<f64> {
        spaced(self.from, self.to, self.steps)
    }

    /// The sine tests of a tuning without widening, and the device time they take (each test
    /// plus about 0.3 s of set-up) \\[s\\].
    pub fn tests(&self) -> (usize, f64) {
        let n = self.steps + self.fine_steps * self.repeats;
        (n, n as f64 * (self.seconds + 0.3))
    }
}

/// `n` evenly spaced values from `a` to `b`.
pub(crate) fn spaced(a: f64, b: f64, n: usize) -> Vec<f64> {
    (0..n)
        .map(|i| a + (b - a) * i as f64 / (n.max(2) - 1) as f64)
        .collect()
}

/// What the tuning found.
#[derive(Debug, Clone, PartialEq)]
pub struct TuneFf {
    /// `(gain, RMS error [rad])` of every test, in the order run (coarse, then refinement).
    pub curve: Vec<(f64, f64)>,
    /// The coarse sweep's range after any widening \\[-\\].
    pub range: (f64, f64),
    /// The refinement's window \\[-\\].
    pub window: (f64, f64),
    /// The optimum fitted to the refinement (mean-square parabola, its vertex and standard
    /// error: [`gms_ident::optimum::fit_minimum`]); `None` when the curve has no minimum there.
    pub optimum: Option<gms_ident::optimum::Optimum>,
    /// Whether the optimum is clear enough to choose: it exists, lies within the refinement's
    /// window, and its standard error is below [`TUNE_FF_FLAT_SE`].
    pub decided: bool,
    /// The gain to use \\[-\\]: the optimum when decided, else the device's gain as it was.
    pub chosen: f64,
    /// The gain the device had before \\[-\\].
    pub before: f64,
    /// What the tuning did or found beyond the plan, a sentence each (widening, flatness).
    pub notes: Vec<String>,
    /// The device's encoder resolution \[rad/count\] (for errors in counts).
    pub rad_per_count: f64,
}

/// The feedforward gain by experiment. The same sine test with reversals at each gain; a
/// coarse sweep, widened by half its span on the side of its lowest point while that point
/// is at an edge (at most [`TUNE_FF_WIDENINGS`] times, within 0..2); then a refinement
/// around the coarse optimum, over the window where the fitted mean square rises to about
/// twice its minimum, every gain tested `repeats` times (alternately up and down the
/// window); the optimum is the vertex of the mean-square parabola fitted to the refinement,
/// with its standard error ([`gms_ident::optimum`]). Leaves the device at `before` (the caller
/// applies `chosen` if asked), holding; on a failure the gain goes back and the bridge off.
/// `progress(test, gain, rms)` after each test.
pub fn tune_ff(
    b: &mut impl Bench,
    plan: &TuneFfPlan,
    mut progress: impl FnMut(usize, f64, f64),
) -> Result<TuneFf, Error> {
    use gms_ident::optimum::fit_minimum;
    plan.check()?;
    let before = get_param(b, ParamId::FfGain)?;
    let rpc = rad_per_count(b)?;
    // The gain as it was after, whatever happens.
    let r = restoring(b, |b| {
        // The feedforward alone: the integral's friction level (`pos.ki_fric`) would take up
        // part of a gain's mismatch at every reversal and flatten the curve whose minimum
        // is sought (with the share at 0.5 a plant at 40 % of the model read 0.505, at the
        // edge of the range, where a dense sweep without it finds its optimum lower).
        b.set(ParamId::PosKiFric, 0.0)?;
        guarded(b, |b| {
            let mut curve: Vec<(f64, f64)> = Vec::new();
            let mut notes = Vec::new();
            let mut test = |b: &mut _, g: f64, curve: &mut Vec<(f64, f64)>| -> Result<(), Error> {
                b_set_gain(b, g)?;
                let rms = sine_test(b, plan.amp, plan.freq, plan.seconds)?;
                progress(curve.len(), g, rms);
                curve.push((g, rms));
                Ok(())
            };
            // The coarse sweep, widened while its lowest point sits at an edge.
            let (mut lo, mut hi) = (plan.from, plan.to);
            let step = (plan.to - plan.from) / (plan.steps - 1) as f64;
            for g in plan.gains() {
                test(b, g, &mut curve)?;
            }
            for _ in 0..TUNE_FF_WIDENINGS {
                let Some(&(g_min, _)) = curve.iter().min_by(|a, b| a.1.total_cmp(&b.1)) else {
                    break;
                };
                let half = 0.5 * (hi - lo);
                let n_new = ((half / step).round() as usize).max(1);
                let new: Vec<f64> = if g_min <= lo + 1e-9 && lo > 0.0 {
                    let from = (lo - n_new as f64 * step).max(0.0);
                    let gs: Vec<f64> = (1..=n_new)
                        .map(|i| lo - i as f64 * step)
                        .filter(|g| *g >= from - 1e-9)
                        .collect();
                    notes.push(format!(
                    "the lowest error was at the range's low end ({lo:.3}): widened down to {:.3}",
                    from.max(0.0)
                ));
                    lo = from.max(0.0);
                    gs
                } else if g_min >= hi - 1e-9 && hi < 2.0 {
                    let to = (hi + n_new as f64 * step).min(2.0);
                    let gs: Vec<f64> = (1..=n_new)
                        .map(|i| hi + i as f64 * step)
                        .filter(|g| *g <= to + 1e-9)
                        .collect();
                    notes.push(format!(
                    "the lowest error was at the range's high end ({hi:.3}): widened up to {to:.3}"
                ));
                    hi = to;
                    gs
                } else {
                    break;
                };
                for g in new {
                    test(b, g.clamp(0.0, 2.0), &mut curve)?;
                }
            }
            // The refinement: where the coarse parabola rises to about twice its minimum.
            let coarse = fit_minimum(&curve);
            let best = curve
                .iter()
                .min_by(|a, b| a.1.total_cmp(&b.1))
                .map_or(before, |p| p.0);
            let (centre, half) = match coarse {
                Some(o) if o.at >= lo && o.at <= hi => {
                    (o.at, (o.min / o.curvature).sqrt().clamp(0.1, 0.4))
                }
                _ => (best, 0.2),
            };
            let (w_lo, w_hi) = ((centre - half).max(0.0), (centre + half).min(2.0));
            let fine = spaced(w_lo, w_hi, plan.fine_steps);
            let start = curve.len();
            for r in 0..plan.repeats {
                let order: Vec<f64> = if r % 2 == 0 {
                    fine.clone()
                } else {
                    fine.iter().rev().copied().collect()
                };
                for g in order {
                    test(b, g, &mut curve)?;
                }
            }
            let optimum = fit_minimum(&curve[start..]);
            Ok((curve, (lo, hi), (w_lo, w_hi), optimum, notes))
        })
    });
    let (curve, range, window, optimum, mut notes) = r?;
    let (decided, note) = decide(optimum, window);
    notes.extend(note);
    let chosen = match optimum {
        Some(o) if decided => o.at,
        _ => before,
    };
    Ok(TuneFf {
        curve,
        range,
        window,
        optimum,
        decided,
        chosen,
        before,
        notes,
        rad_per_count: rpc,
    })
}

/// Whether a fitted optimum is clear enough to choose: it exists, lies within the
/// refinement's `window`, and its standard error is at most [`TUNE_FF_FLAT_SE`]; otherwise
/// the note that says why not.
pub fn decide(
    optimum: Option<gms_ident::optimum::Optimum>,
    window: (f64, f64),
) -> (bool, Option<String>) {
    match optimum {
        None => (
            false,
            Some(
                "the refinement's errors have no minimum (the curve is flat or falls): no gain \
                 chosen"
                    .into(),
            ),
        ),
        Some(o) if o.at < window.0 || o.at > window.1 => (
            false,
            Some(format!(
                "the fitted optimum {:.3} lies outside the refinement's window {:.3} to {:.3}: \
                 no gain chosen (try a range around it)",
                o.at, window.0, window.1
            )),
        ),
        Some(o) if o.se > TUNE_FF_FLAT_SE => (
            false,
            Some(format!(
                "the curve is too flat to choose: the optimum {:.3} has a standard error of \
                 {:.3} (over {TUNE_FF_FLAT_SE})",
                o.at, o.se
            )),
        ),
        Some(_) => (true, None),
    }
}

/// `set ff.gain G`.
pub(crate) fn b_set_gain(b: &mut impl Bench, g: f64) -> Result<(), Error> {
    b.set(ParamId::FfGain, g).map(|_| ())
}
