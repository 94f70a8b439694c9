//! The closed-loop simulator: one run, and the comparison of the compensators.

use super::*;

/// A scenario from None (the default), a path or a dict with the file's keys.
pub(crate) fn scenario(sc: Option<&Bound<'_, PyAny>>) -> PyResult<hil_sim::scenario::Scenario> {
    match sc {
        None => Ok(hil_sim::scenario::Scenario::default()),
        Some(s) if s.is_none() => Ok(hil_sim::scenario::Scenario::default()),
        Some(s) if s.is_instance_of::<PyDict>() => {
            let text = match to_toml(s, "")? {
                toml::Value::Table(t) => toml::to_string(&t).map_err(err)?,
                _ => unreachable!("a dict is a table"),
            };
            hil_sim::scenario::Scenario::parse(&text, "<dict>").map_err(err)
        }
        Some(s) => {
            let path: PathBuf = s
                .extract()
                .map_err(|_| err("scenario: None, a path to a scenario file, or a dict"))?;
            hil_sim::scenario::Scenario::load(&path).map_err(err)
        }
    }
}

/// run(scenario=None) -> dict
///
/// One closed-loop run, as `hil-sim run` does it (the scenario's mode and seed): {"trace":
/// {column: numpy array}, "metrics": {...}} — the trace's columns t, reference, position,
/// error, current, current_cmd, voltage, friction, feedforward, ff_scale, drift,
/// ref_velocity (SI), the metrics of metrics.json (SI).
#[pyfunction]
#[pyo3(signature = (scenario = None))]
pub(crate) fn run<'py>(
    py: Python<'py>,
    scenario: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyDict>> {
    let sc = self::scenario(scenario)?;
    let res = hil_sim::sim::run(&sc, sc.mode(), sc.plant.seed).map_err(err)?;
    let out = PyDict::new(py);
    let trace = PyDict::new(py);
    macro_rules! col {
        ($name:literal, $f:ident) => {
            trace.set_item(
                $name,
                PyArray1::from_vec(py, res.trace.iter().map(|r| r.$f).collect()),
            )?;
        };
    }
    col!("t", t);
    col!("reference", reference);
    col!("position", position);
    col!("error", error);
    col!("current", current);
    col!("current_cmd", current_cmd);
    col!("voltage", voltage);
    col!("friction", friction);
    col!("feedforward", feedforward);
    col!("ff_scale", ff_scale);
    col!("drift", drift);
    col!("ref_velocity", ref_velocity);
    out.set_item("trace", trace)?;
    out.set_item("metrics", debug_dict(py, &res.metrics)?)?;
    out.set_item("mode", sc.mode().name())?;
    out.set_item("seed", sc.plant.seed)?;
    Ok(out)
}

/// compare(scenario=None, runs=20, seed=1) -> dict
///
/// Every feedforward mode over `runs` friction draws (seeds seed … seed + runs − 1), as
/// `hil-sim compare` writes its JSON.
#[pyfunction]
#[pyo3(signature = (scenario = None, runs = 20, seed = 1))]
pub(crate) fn compare<'py>(
    py: Python<'py>,
    scenario: Option<&Bound<'py, PyAny>>,
    runs: usize,
    seed: u64,
) -> PyResult<Bound<'py, PyDict>> {
    if runs == 0 {
        return Err(err("runs: at least 1"));
    }
    let sc = self::scenario(scenario)?;
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    let (cmp, _) = hil_sim::commands::compare(&sc, runs, seed, threads, false).map_err(err)?;
    debug_dict(py, &cmp)
}

/// learn(scenario=None, runs=1, seed=1, amplitude=0.05, freq=1.0, iterations=10, gain=0.3,
/// q_filter=400.0, lead=0.0) -> dict
///
/// Learning from repetition on the virtual device in-process, as `hil-sim learn`, over `runs`
/// friction draws (seeds seed … seed + runs − 1): {"rms", "peak", "true_rms", "true_peak":
/// 2-D numpy arrays (run × iteration) [counts] — the device's figures and those against the
/// simulated true position —, "seeds", "stopped": per run None or why}.
#[pyfunction]
#[pyo3(signature = (scenario = None, runs = 1, seed = 1, amplitude = gms_bench::learn::SINE.0, freq = gms_bench::learn::SINE.1, iterations = gms_bench::learn::ITERATIONS, gain = gms_bench::learn::GAIN, q_filter = gms_bench::learn::Q_HZ, lead = 0.0))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn learn<'py>(
    py: Python<'py>,
    scenario: Option<&Bound<'py, PyAny>>,
    runs: usize,
    seed: u64,
    amplitude: f64,
    freq: f64,
    iterations: usize,
    gain: f64,
    q_filter: f64,
    lead: f64,
) -> PyResult<Bound<'py, PyDict>> {
    if runs == 0 {
        return Err(err("runs: at least 1"));
    }
    let sc = self::scenario(scenario)?;
    let plan = gms_bench::learn::LearnPlan {
        path: gms_bench::learn::Path::Sine { amplitude, freq },
        iterations,
        gain,
        q_hz: q_filter,
        lead_s: lead,
        ..gms_bench::learn::LearnPlan::default()
    };
    plan.check().map_err(err)?;
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    let rs = hil_sim::learn::learn_draws(&sc, runs, seed, &plan, threads).map_err(err)?;
    let out = PyDict::new(py);
    let grid = |f: &dyn Fn(&hil_sim::learn::IterationTruth) -> f64| -> Vec<Vec<f64>> {
        let n = rs.iter().map(|r| r.iterations.len()).max().unwrap_or(0);
        rs.iter()
            .map(|r| {
                (0..n)
                    .map(|i| r.iterations.get(i).map_or(f64::NAN, f))
                    .collect()
            })
            .collect()
    };
    for (name, f) in [
        (
            "rms",
            (|t| t.rms) as fn(&hil_sim::learn::IterationTruth) -> f64,
        ),
        ("peak", |t| t.peak),
        ("true_rms", |t| t.true_rms),
        ("true_peak", |t| t.true_peak),
    ] {
        out.set_item(
            name,
            numpy::PyArray2::from_vec2(py, &grid(&f)).map_err(err)?,
        )?;
    }
    // After the learning, the best correction played more periods: what repeats and what
    // does not, one value per run (hil_sim::learn::Scatter).
    for (name, f) in [
        (
            "scatter_rms",
            (|s| s.rms) as fn(&hil_sim::learn::Scatter) -> f64,
        ),
        ("repeating", |s| s.repeating),
        ("not_repeating", |s| s.not_repeating),
        ("true_repeating", |s| s.true_repeating),
        ("true_not_repeating", |s| s.true_not_repeating),
    ] {
        let v: Vec<f64> = rs.iter().map(|r| f(&r.scatter)).collect();
        out.set_item(name, numpy::PyArray1::from_vec(py, v))?;
    }
    out.set_item("seeds", rs.iter().map(|r| r.seed).collect::<Vec<_>>())?;
    out.set_item(
        "stopped",
        rs.iter().map(|r| r.stopped.clone()).collect::<Vec<_>>(),
    )?;
    Ok(out)
}
