//! The `run`, `compare` and `demo` commands.

use crate::Error;
use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};

use gms_core::control::controller::FfMode;
use indicatif::{ProgressBar, ProgressStyle};
use serde::Serialize;

use crate::scenario::{DriftKind, Scenario};
use crate::sim::{self, RunResult};
use gms_ident::io::write_atomic;
use gms_ident::plot;
use gms_ident::trace::{Metrics, TraceRow, trace_csv};

/// `hil-sim run`: one run of the scenario with its own feedforward mode and seed; writes
/// `trace.csv`, `metrics.json` and `plot.svg` into `out`.
pub fn run(sc: &Scenario, out: &Path) -> Result<RunResult, Error> {
    run_inner(sc, out).map_err(Error::Run)
}

fn run_inner(sc: &Scenario, out: &Path) -> Result<RunResult, String> {
    std::fs::create_dir_all(out).map_err(|e| format!("{}: cannot create: {e}", out.display()))?;
    let res = sim::run(sc, sc.mode(), sc.plant.seed)?;
    #[derive(Serialize)]
    struct Out<'a> {
        mode: &'a str,
        seed: u64,
        metrics: &'a Metrics,
        energy_balance: EnergyOut,
    }
    let mode = sc.mode().name();
    let e = res.energy;
    let json = serde_json::to_string_pretty(&Out {
        mode,
        seed: sc.plant.seed,
        metrics: &res.metrics,
        energy_balance: EnergyOut {
            input: e.input,
            copper: e.copper,
            friction: e.friction,
            kinetic: e.kinetic,
            magnetic: e.magnetic,
            spring: e.spring,
            damping: e.damping,
            cogging: e.cogging,
            residual: e.input - e.copper - e.magnetic - e.mechanical(),
        },
    })
    .map_err(|e| e.to_string())?;
    write_atomic(&out.join("trace.csv"), trace_csv(&res.trace).as_bytes())?;
    write_atomic(&out.join("metrics.json"), json.as_bytes())?;
    plot::run_plot(
        &out.join("plot.svg"),
        &format!("hil-sim run: feedforward {mode}, seed {}", sc.plant.seed),
        &res.trace,
        sc.plant.rad_per_count,
        plot::FrictionSource::True,
    )?;
    Ok(res)
}

/// The energy ledger in metrics.json \[J\].
#[derive(Serialize)]
struct EnergyOut {
    input: f64,
    copper: f64,
    friction: f64,
    kinetic: f64,
    magnetic: f64,
    /// Stored in the stage's compliance now (0 on a rigid stage).
    spring: f64,
    /// Lost in the compliance's damping.
    damping: f64,
    /// The cogging's potential energy now.
    cogging: f64,
    residual: f64,
}

/// Median and 95th percentile of one metric over the draws.
#[derive(Debug, Clone, Copy, Serialize, PartialEq)]
pub struct Summary {
    /// Median.
    pub median: f64,
    /// 95th percentile (nearest rank).
    pub p95: f64,
}

fn summarize(mut v: Vec<f64>) -> Summary {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n == 0 {
        return Summary {
            median: f64::NAN,
            p95: f64::NAN,
        };
    }
    let median = if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    };
    let rank = ((0.95 * n as f64).ceil() as usize).clamp(1, n);
    Summary {
        median,
        p95: v[rank - 1],
    }
}

/// One run's figures, and its trace when it is the first draw.
type JobResult = Result<(Metrics, Option<Vec<TraceRow>>), String>;

/// The result of `compare`: per mode, per metric, the median and p95 over the draws.
#[derive(Debug, Serialize)]
pub struct Comparison {
    /// mode → metric → summary.
    pub modes: BTreeMap<String, BTreeMap<String, Summary>>,
    /// Number of friction draws.
    pub runs: usize,
    /// First seed (draw i uses seed + i).
    pub seed: u64,
    /// The level oracle's figures (metric → summary), when the scenario's friction drifts
    /// ([`sim::run_oracle`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub oracle: Option<BTreeMap<String, Summary>>,
}

/// `f(0)`, …, `f(n − 1)` on `threads` threads (each takes the next index as it comes free),
/// in index order; `done` after each. An index whose run did not finish is `None`; a run that
/// panicked is an error.
pub fn par_map<T: Send>(
    n: usize,
    threads: usize,
    f: impl Fn(usize) -> T + Sync,
    done: impl Fn() + Sync,
) -> Result<Vec<Option<T>>, String> {
    let next = AtomicUsize::new(0);
    let results: Mutex<Vec<Option<T>>> = Mutex::new((0..n).map(|_| None).collect());
    std::thread::scope(|s| {
        for _ in 0..threads.max(1) {
            s.spawn(|| {
                loop {
                    let j = next.fetch_add(1, Ordering::Relaxed);
                    if j >= n {
                        break;
                    }
                    let r = f(j);
                    if let Ok(mut g) = results.lock() {
                        g[j] = Some(r);
                    }
                    done();
                }
            });
        }
    });
    results
        .into_inner()
        .map_err(|_| "a run panicked".to_string())
}

/// `hil-sim compare`: every mode over `runs` friction draws (seeds `seed`, `seed+1`, …),
/// on `threads` threads, with a progress bar when `progress`. Returns the comparison and the
/// traces of the first draw (for the plot).
pub fn compare(
    sc: &Scenario,
    runs: usize,
    seed: u64,
    threads: usize,
    progress: bool,
) -> Result<(Comparison, Vec<Vec<TraceRow>>), String> {
    // Job (draw, column): columns are the modes, then the level oracle if the friction drifts.
    let oracle = sc.plant.drift.kind != DriftKind::None;
    let columns = FfMode::ALL.len() + usize::from(oracle);
    let jobs: Vec<(usize, usize)> = (0..runs)
        .flat_map(|r| (0..columns).map(move |m| (r, m)))
        .collect();
    let bar = if progress {
        let b = ProgressBar::new(jobs.len() as u64);
        b.set_style(
            ProgressStyle::with_template("{prefix} [{bar:40}] {pos}/{len} runs {elapsed}")
                .map_err(|e| e.to_string())?
                .progress_chars("=> "),
        );
        b.set_prefix("compare");
        b
    } else {
        ProgressBar::hidden()
    };
    let results: Vec<Option<JobResult>> = par_map(
        jobs.len(),
        threads,
        |j| {
            let (r, m) = jobs[j];
            let seed = seed.wrapping_add(r as u64);
            match FfMode::ALL.get(m) {
                Some(&mode) => sim::run(sc, mode, seed),
                None => sim::run_oracle(sc, seed),
            }
            .map(|res| {
                // The plot shows the modes' first draw; the oracle has no trace there.
                let keep = r == 0 && m < FfMode::ALL.len();
                (res.metrics, keep.then_some(res.trace))
            })
            .map_err(String::from)
        },
        || bar.inc(1),
    )?;
    bar.finish_and_clear();
    let mut per_mode: Vec<Vec<Metrics>> = vec![Vec::new(); columns];
    let mut traces: Vec<Vec<TraceRow>> = vec![Vec::new(); FfMode::ALL.len()];
    for (j, res) in results.into_iter().enumerate() {
        let (metrics, trace) = res.ok_or("a run did not finish")??;
        let m = jobs[j].1;
        per_mode[m].push(metrics);
        if let (Some(t), Some(slot)) = (trace, traces.get_mut(m)) {
            *slot = t;
        }
    }
    let column = |m: usize| {
        let mut table = BTreeMap::new();
        for (k, (metric, _)) in Metrics::default().named().iter().enumerate() {
            let vals = per_mode[m].iter().map(|x| x.named()[k].1).collect();
            table.insert(metric.to_string(), summarize(vals));
        }
        table
    };
    let mut modes = BTreeMap::new();
    for (m, mode) in FfMode::ALL.iter().enumerate() {
        modes.insert(mode.name().to_string(), column(m));
    }
    let oracle = oracle.then(|| column(FfMode::ALL.len()));
    Ok((
        Comparison {
            modes,
            runs,
            seed,
            oracle,
        },
        traces,
    ))
}

/// The median of `a` over `b`, two decimals; `-` when either is missing or `b` is not positive.
fn ratio_to(a: Option<&Summary>, b: f64) -> String {
    match a {
        Some(x) if b > 0.0 => format!("{:.2}", x.median / b),
        _ => "-".into(),
    }
}

/// The comparison as a text table (medians, p95 in brackets), in readable units.
pub fn table(c: &Comparison, rad_per_count: f64) -> String {
    let rows: [(&str, &str, f64); 8] = [
        ("rms_error", "counts", 1.0 / rad_per_count),
        ("sine_rms_error", "counts", 1.0 / rad_per_count),
        ("max_error", "counts", 1.0 / rad_per_count),
        ("reversal_error", "counts", 1.0 / rad_per_count),
        ("settle_time", "ms", 1e3),
        ("steady_state_error", "counts", 1.0 / rad_per_count),
        ("unsettled_steps", "", 1.0),
        ("hunting_crossings", "", 1.0),
    ];
    let mut s = format!("{} friction draws, median [p95]\n{:<28}", c.runs, "metric");
    for mode in FfMode::ALL {
        s += &format!("{:>22}", mode.name());
    }
    s.push('\n');
    for (metric, unit, scale) in rows {
        s += &format!("{:<28}", format!("{metric} [{unit}]").replace(" []", ""));
        for mode in FfMode::ALL {
            let v = c.modes.get(mode.name()).and_then(|t| t.get(metric));
            s += &match v {
                Some(v) => format!(
                    "{:>22}",
                    format!("{:.3} [{:.3}]", v.median * scale, v.p95 * scale)
                ),
                None => format!("{:>22}", "-"),
            };
        }
        s.push('\n');
    }
    let ratio = |metric: &str, a: &str, b: &str| {
        let g = |m: &str| c.modes.get(m).and_then(|t| t.get(metric));
        g(b).map_or("-".into(), |y| ratio_to(g(a), y.median))
    };
    s += &format!(
        "sine RMS ratio none/gms {}, static/gms {}; reversal peak ratio none/gms {}, static/gms {}\n",
        ratio("sine_rms_error", "none", "gms"),
        ratio("sine_rms_error", "static", "gms"),
        ratio("reversal_error", "none", "gms"),
        ratio("reversal_error", "static", "gms"),
    );
    s += &format!(
        "adaptation: RMS ratio gms/gms-adaptive {}, sine RMS ratio {}\n",
        ratio("rms_error", "gms", "gms-adaptive"),
        ratio("sine_rms_error", "gms", "gms-adaptive"),
    );
    if let Some(o) = c.oracle.as_ref().and_then(|t| t.get("rms_error")) {
        s += &format!(
            "level oracle (feedforward scaled by the true drift, simulation only): RMS {:.3} \
             counts, RMS ratio gms/oracle {}\n",
            o.median / rad_per_count,
            ratio_to(
                c.modes.get("gms").and_then(|t| t.get("rms_error")),
                o.median
            ),
        );
    }
    s
}
