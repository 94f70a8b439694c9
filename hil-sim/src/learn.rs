//! Learning from repetition in the simulator (`hil-sim learn`, Python's `gms.learn`): the
//! bench's learning (`gms_bench::learn`) on the in-process virtual device, over friction
//! draws, with the error against the simulated true position beside the device's — the truth
//! the device never sees.

use gms_bench::learn::{LearnPlan, Learned};

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
    /// Device time the run took \[s\].
    pub seconds: f64,
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
            let from = l.started + u64::from(*p) * per;
            // The recording is in step order: the period's rows by two searches.
            let lo = truth.partition_point(|r| r.steps < from);
            let hi = truth.partition_point(|r| r.steps < from + per);
            let rows: Vec<&Truth> = truth[lo..hi].iter().collect();
            if rows.len() as u64 != per {
                return Err(Error::Run(format!(
                    "period {p}: {} steps recorded of {per}",
                    rows.len()
                )));
            }
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
    let l = gms_bench::learn::learn(&mut dev, plan, |_| {}, false)
        .map_err(|e| Error::Run(format!("seed {seed}: {e}")))?;
    let seconds = dev.plant().t - t0;
    let truth = dev.take_truth();
    Ok(LearnRun {
        seed,
        iterations: iteration_truths(&l, &truth)?,
        stopped: l.stopped.map(|s| format!("{s:?}")),
        correction: l.correction,
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
        let median = |v: &[f64]| v.get(v.len() / 2).copied().unwrap_or(f64::NAN);
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
