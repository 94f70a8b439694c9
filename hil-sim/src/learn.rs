//! Learning from repetition in the simulator (`hil-sim learn`, Python's `gms.learn`): the
//! bench's learning (`gms_bench::learn`) on the in-process virtual device, over friction
//! draws, with the error against the simulated true position beside the device's — the truth
//! the device never sees.

use gms_bench::learn::{LearnPlan, Learned, Table};

use crate::Error;
use crate::device::{LocalDevice, Truth};
use crate::scenario::Scenario;

/// One iteration's figures \[counts\].
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct IterationTruth {
    /// The device's RMS error over the period's steps.
    pub rms: f64,
    /// The device's largest error.
    pub peak: f64,
    /// The device's RMS recomputed from the recording of every step (the device's figure,
    /// checked by another implementation).
    pub rms_recorded: f64,
    /// The RMS against the true position (`Truth::true_error`).
    pub true_rms: f64,
    /// The largest error against the true position.
    pub true_peak: f64,
}

/// One learning run on one friction draw.
#[derive(Debug, Clone, serde::Serialize)]
pub struct LearnRun {
    /// The draw's seed.
    pub seed: u64,
    /// Each iteration, from the first pass.
    pub iterations: Vec<IterationTruth>,
    /// Why it stopped early, if it did.
    pub stopped: Option<String>,
    /// The correction kept \[N·m at the table's points\].
    pub correction: Vec<f64>,
    /// The best correction played [`SCATTER_PERIODS`] more periods after the learning: what
    /// of the error repeats and what does not.
    pub scatter: Scatter,
    /// The same as the bench sees it, from the device's figures over the last iterations
    /// ([`gms_bench::learn::Learned::repeat`]): (repeating, not repeating) \[counts\].
    pub bench_repeat: Option<(f64, f64)>,
    /// Device time the run took \[s\].
    pub seconds: f64,
}

/// Periods the best correction is played after the learning, for [`Scatter`] (after one
/// more from rest).
pub const SCATTER_PERIODS: u32 = 5;

/// What of a repeated motion's error repeats from period to period and what does not
/// \[counts\], from consecutive periods of the same correction: the part that repeats is what
/// a learning can still take; the rest is its floor.
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize)]
pub struct Scatter {
    /// Periods it is taken over.
    pub periods: usize,
    /// The device's RMS error over all of them.
    pub rms: f64,
    /// The RMS of the error's mean over the periods, step by step, less the share of the
    /// scatter that mean still carries (see [`gms_bench::ilc::decompose`]).
    pub repeating: f64,
    /// The RMS of each step's scatter about that mean (the unbiased standard deviation over
    /// the periods, pooled over the steps).
    pub not_repeating: f64,
    /// [`Scatter::repeating`] against the true position.
    pub true_repeating: f64,
    /// [`Scatter::not_repeating`] against the true position.
    pub true_not_repeating: f64,
}

/// The best correction (left set by the learning) played [`SCATTER_PERIODS`] periods after
/// one from the table's start at rest (the learning's periodic state, as its first pass),
/// every step recorded, split by [`gms_bench::ilc::decompose`].
fn scatter(dev: &mut LocalDevice, t: &Table) -> Result<Scatter, Error> {
    use gms_bench::Bench;
    let per = u64::from(t.points) * u64::from(t.steps);
    let run = |e: gms_bench::Error| Error::Run(format!("scatter: {e}"));
    dev.record_truth();
    let periods = SCATTER_PERIODS + 1;
    dev.send(gms_core::protocol::Command::Table(
        gms_core::protocol::TableCmd::Run(periods),
    ))
    .map_err(run)?;
    let st = gms_bench::learn::table_status(dev).map_err(run)?;
    dev.wait(f64::from(periods) * t.period() + 0.05)
        .map_err(run)?;
    let end = gms_bench::learn::table_status(dev).map_err(run)?;
    if end.playing || end.period < periods {
        return Err(Error::Run(format!(
            "scatter: {} periods of {periods} played",
            end.period
        )));
    }
    let truth = dev.take_truth();
    let mut dev_e = Vec::new();
    let mut true_e = Vec::new();
    for p in 1..=u64::from(SCATTER_PERIODS) {
        let r = period_rows(&truth, st.started + p * per, per)
            .map_err(|e| Error::Run(format!("scatter: period {p}: {e}")))?;
        dev_e.push(r.iter().map(Truth::device_error).collect::<Vec<_>>());
        true_e.push(r.iter().map(Truth::true_error).collect::<Vec<_>>());
    }
    let bad = || Error::Run("scatter: no periods".into());
    let (rms, repeating, not_repeating) = gms_bench::ilc::decompose(&dev_e).ok_or_else(bad)?;
    let (_, true_repeating, true_not_repeating) =
        gms_bench::ilc::decompose(&true_e).ok_or_else(bad)?;
    Ok(Scatter {
        periods: dev_e.len(),
        rms,
        repeating,
        not_repeating,
        true_repeating,
        true_not_repeating,
    })
}

/// The `per` steps of `truth` (in step order) from the step `from`; an error unless all of
/// them are there.
fn period_rows(truth: &[Truth], from: u64, per: u64) -> Result<&[Truth], Error> {
    let lo = truth.partition_point(|r| r.steps < from);
    let hi = truth.partition_point(|r| r.steps < from + per);
    if (hi - lo) as u64 != per {
        return Err(Error::Run(format!("{} steps recorded of {per}", hi - lo)));
    }
    Ok(&truth[lo..hi])
}

/// The figures of each iteration of `l` from the recording `truth`.
pub fn iteration_truths(l: &Learned, truth: &[Truth]) -> Result<Vec<IterationTruth>, Error> {
    let t = l
        .table
        .as_ref()
        .ok_or_else(|| Error::Run("no table".into()))?;
    let per = u64::from(t.points) * u64::from(t.steps);
    l.iterations
        .iter()
        .zip(&l.periods)
        .map(|(it, p)| {
            let rows = period_rows(truth, l.started + u64::from(*p) * per, per)
                .map_err(|e| Error::Run(format!("period {p}: {e}")))?;
            let rms = |f: &dyn Fn(&Truth) -> f64| {
                (rows.iter().map(|r| f(r).powi(2)).sum::<f64>() / rows.len() as f64).sqrt()
            };
            Ok(IterationTruth {
                rms: it.rms,
                peak: it.peak,
                rms_recorded: rms(&|r| r.device_error()),
                true_rms: rms(&|r| r.true_error()),
                true_peak: rows
                    .iter()
                    .map(|r| r.true_error().abs())
                    .fold(0.0, f64::max),
            })
        })
        .collect()
}

/// The learning on the virtual device of `sc` (its friction drawn with `seed`), the truth
/// recorded.
pub fn learn_once(sc: &Scenario, seed: u64, plan: &LearnPlan) -> Result<LearnRun, Error> {
    let mut sc = sc.clone();
    sc.plant.seed = seed;
    let mut dev = LocalDevice::new(&sc)?;
    dev.record_truth();
    let t0 = dev.plant().t;
    // `apply`: the best correction stays set, for the scatter's periods after.
    let l = gms_bench::learn::learn(&mut dev, plan, |_| {}, true)
        .map_err(|e| Error::Run(format!("seed {seed}: {e}")))?;
    let seconds = dev.plant().t - t0;
    let truth = dev.take_truth();
    let iterations = iteration_truths(&l, &truth)?;
    let t = l
        .table
        .as_ref()
        .ok_or_else(|| Error::Run("no table".into()))?;
    let scatter = scatter(&mut dev, t)?;
    let bench_repeat = l.repeat().map(|r| (r.repeating, r.not_repeating));
    Ok(LearnRun {
        seed,
        iterations,
        stopped: l.stopped.map(|s| format!("{s:?}")),
        correction: l.correction,
        scatter,
        bench_repeat,
        seconds,
    })
}

/// [`learn_once`] on `runs` draws (seeds `seed`, `seed + 1`, …) on `threads` threads.
pub fn learn_draws(
    sc: &Scenario,
    runs: usize,
    seed: u64,
    plan: &LearnPlan,
    threads: usize,
) -> Result<Vec<LearnRun>, Error> {
    crate::commands::par_map(
        runs,
        threads,
        |j| learn_once(sc, seed.wrapping_add(j as u64), plan),
        || {},
    )
    .map_err(Error::Run)?
    .into_iter()
    .map(|r| r.unwrap_or_else(|| Err(Error::Run("a run did not finish".into()))))
    .collect()
}

/// The median of sorted values (the upper one of an even count; NaN of none).
fn median(sorted: &[f64]) -> f64 {
    sorted.get(sorted.len() / 2).copied().unwrap_or(f64::NAN)
}

/// A markdown table: per iteration, the median and the largest over the draws of the RMS
/// (device and true) and the median peak \[counts\].
pub fn table(runs: &[LearnRun]) -> String {
    let n = runs.iter().map(|r| r.iterations.len()).max().unwrap_or(0);
    let mut s = String::from(
        "| iteration | RMS median | RMS max | true RMS median | peak median |\n|---|---|---|---|---|\n",
    );
    for i in 0..n {
        let col = |f: &dyn Fn(&IterationTruth) -> f64| -> Vec<f64> {
            let mut v: Vec<f64> = runs
                .iter()
                .filter_map(|r| r.iterations.get(i))
                .map(f)
                .collect();
            v.sort_by(f64::total_cmp);
            v
        };
        let rms = col(&|t| t.rms);
        s.push_str(&format!(
            "| {i} | {:.3} | {:.3} | {:.3} | {:.2} |\n",
            median(&rms),
            rms.last().copied().unwrap_or(f64::NAN),
            median(&col(&|t| t.true_rms)),
            median(&col(&|t| t.peak)),
        ));
    }
    s
}

/// One line: the draws' medians of [`LearnRun::scatter`] \[counts\].
pub fn scatter_line(runs: &[LearnRun]) -> String {
    let of = |f: &dyn Fn(&Scatter) -> f64| -> f64 {
        let mut v: Vec<f64> = runs.iter().map(|r| f(&r.scatter)).collect();
        v.sort_by(f64::total_cmp);
        median(&v)
    };
    format!(
        "the best correction played {SCATTER_PERIODS} periods more (medians): RMS {:.3} counts, \
         repeating {:.3}, not repeating {:.3}; against the true position repeating {:.3}, not \
         repeating {:.3}",
        of(&|s| s.rms),
        of(&|s| s.repeating),
        of(&|s| s.not_repeating),
        of(&|s| s.true_repeating),
        of(&|s| s.true_not_repeating),
    )
}
