//! `gms`: the project's Rust core in Python — the friction models (the same f32 code as the
//! firmware), the identification fits on arrays, the closed-loop simulator, and the bench
//! client. Every error is a `gms.GmsError` with the command line's one-line message.

use std::path::PathBuf;
use std::time::Duration;

use numpy::{PyArray1, PyReadonlyArray1};
use pyo3::create_exception;
use pyo3::exceptions::PyException;
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict, PyFloat, PyInt, PyList, PyString};

use gms_ident::paramfile::{AnyModel, ParamFile};

create_exception!(
    gms,
    GmsError,
    PyException,
    "A gms failure: bad input (arrays, parameters, files), a fit that does not converge, or a device that refused or went silent. The message is the command line's."
);

fn err(e: impl std::fmt::Display) -> PyErr {
    GmsError::new_err(e.to_string())
}

/// A Python value as TOML (dicts, lists, numbers, strings, booleans).
fn to_toml(v: &Bound<'_, PyAny>, at: &str) -> PyResult<toml::Value> {
    if v.is_instance_of::<PyBool>() {
        return Ok(toml::Value::Boolean(v.extract()?));
    }
    if v.is_instance_of::<PyInt>() {
        return Ok(toml::Value::Integer(v.extract()?));
    }
    if v.is_instance_of::<PyFloat>() {
        return Ok(toml::Value::Float(v.extract()?));
    }
    if v.is_instance_of::<PyString>() {
        return Ok(toml::Value::String(v.extract()?));
    }
    if let Ok(d) = v.cast::<PyDict>() {
        let mut t = toml::Table::new();
        for (k, val) in d.iter() {
            let key: String = k
                .extract()
                .map_err(|_| err(format!("{at}: keys must be strings")))?;
            let here = if at.is_empty() {
                key.clone()
            } else {
                format!("{at}.{key}")
            };
            t.insert(key, to_toml(&val, &here)?);
        }
        return Ok(toml::Value::Table(t));
    }
    if let Ok(l) = v.cast::<PyList>() {
        return Ok(toml::Value::Array(
            l.iter()
                .enumerate()
                .map(|(i, x)| to_toml(&x, &format!("{at}[{i}]")))
                .collect::<PyResult<_>>()?,
        ));
    }
    // numpy scalars and the like.
    if let Ok(x) = v.extract::<f64>() {
        return Ok(toml::Value::Float(x));
    }
    Err(err(format!("{at}: not a TOML value")))
}

/// A parameter file from a path (str or os.PathLike) or a dict with the file's keys.
fn param_file(params: &Bound<'_, PyAny>) -> PyResult<ParamFile> {
    if params.is_instance_of::<PyDict>() {
        let text = match to_toml(params, "")? {
            toml::Value::Table(t) => toml::to_string(&t).map_err(err)?,
            _ => unreachable!("a dict is a table"),
        };
        return ParamFile::parse(&text, "<dict>").map_err(err);
    }
    let path: PathBuf = params
        .extract()
        .map_err(|_| err("params: a path to a parameter file, or a dict"))?;
    ParamFile::load(&path).map_err(err)
}

/// A 1-D float array as a slice (copied when not contiguous).
fn floats(a: &PyReadonlyArray1<'_, f64>) -> Vec<f64> {
    a.as_array().iter().copied().collect()
}

/// A trajectory checked as `hil-sim friction` checks its file: equal lengths, finite values,
/// t strictly increasing.
fn trajectory(t: &[f64], x: &[f64]) -> PyResult<Vec<hil_sim::friction_cmd::Sample>> {
    if t.len() != x.len() {
        return Err(err(format!(
            "t and x have different lengths ({} and {})",
            t.len(),
            x.len()
        )));
    }
    let mut out = Vec::with_capacity(t.len());
    for (i, (&ti, &xi)) in t.iter().zip(x).enumerate() {
        if !(ti.is_finite() && xi.is_finite()) {
            return Err(err(format!("sample {i}: t and x must be finite numbers")));
        }
        if let Some(p) = out.last().map(|p: &hil_sim::friction_cmd::Sample| p.t)
            && ti <= p
        {
            return Err(err(format!(
                "sample {i}: t does not increase: {ti} after {p}"
            )));
        }
        out.push(hil_sim::friction_cmd::Sample { t: ti, x: xi });
    }
    Ok(out)
}

/// friction(params, t, x) -> numpy.ndarray
///
/// The friction [N or N·m] along the trajectory x(t) [m or rad; s], from the virgin state at
/// rest: exactly what `hil-sim friction` computes for the same parameter file (the same f32
/// model, the same bits); element 0 is the virgin state's 0. `params`: a parameter file's
/// path or a dict with its keys ({"friction": {"model": "gms", ...}}).
#[pyfunction]
fn friction<'py>(
    py: Python<'py>,
    params: &Bound<'py, PyAny>,
    t: PyReadonlyArray1<'py, f64>,
    x: PyReadonlyArray1<'py, f64>,
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    let pf = param_file(params)?;
    let mut model = pf.friction.build().map_err(err)?;
    let traj = trajectory(&floats(&t), &floats(&x))?;
    let rows = hil_sim::friction_cmd::simulate(&mut model, &traj);
    Ok(PyArray1::from_vec(
        py,
        rows.iter().map(|r| r.f as f64).collect(),
    ))
}

/// A friction model of a parameter file (its `[friction]` table): stepped by displacements,
/// run along trajectories, its force read, reset to the virgin state.
#[pyclass(module = "gms", unsendable, subclass)]
struct Model {
    model: AnyModel,
    kind: String,
}

#[pymethods]
impl Model {
    /// Model(params): from a parameter file's path or a dict with its keys.
    #[new]
    fn new(params: &Bound<'_, PyAny>) -> PyResult<Model> {
        let pf = param_file(params)?;
        let kind = pf.friction.model.to_string();
        Ok(Model {
            model: pf.friction.build().map_err(err)?,
            kind,
        })
    }

    /// The model's kind: "gms", "lugre" or "static".
    #[getter]
    fn kind(&self) -> String {
        self.kind.clone()
    }

    /// The friction after the last step [N or N·m].
    #[getter]
    fn force(&self) -> f64 {
        self.model.force() as f64
    }

    /// step(dx, dt) -> float: moves by dx [m or rad] at constant velocity over dt [s];
    /// returns the friction after it. dx = 0 holds; non-finite input leaves the state.
    fn step(&mut self, dx: f64, dt: f64) -> PyResult<f64> {
        if !(dx.is_finite() && dt.is_finite() && dt >= 0.0) {
            return Err(err(format!("step({dx}, {dt}): finite dx, dt >= 0")));
        }
        Ok(self.model.advance(dx as f32, dt as f32) as f64)
    }

    /// run(t, x) -> numpy.ndarray: the friction along x(t) from the model's present state
    /// (element 0: its force before the first motion).
    fn run<'py>(
        &mut self,
        py: Python<'py>,
        t: PyReadonlyArray1<'py, f64>,
        x: PyReadonlyArray1<'py, f64>,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let traj = trajectory(&floats(&t), &floats(&x))?;
        let rows = hil_sim::friction_cmd::simulate(&mut self.model, &traj);
        Ok(PyArray1::from_vec(
            py,
            rows.iter().map(|r| r.f as f64).collect(),
        ))
    }

    /// Back to the virgin state at rest.
    fn reset(&mut self) {
        self.model.reset();
    }

    /// The internal state as an array: each Maxwell-slip block's force [N or N·m] (GMS),
    /// the bristle deflection z [m or rad] (LuGre), empty (static map).
    #[getter]
    fn state<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_vec(py, self.model.state().iter().map(|&v| v as f64).collect())
    }

    fn __repr__(&self) -> String {
        format!(
            "gms.Model(kind={:?}, force={})",
            self.kind,
            self.model.force()
        )
    }
}

/// A model of the kind `kind`, or a GmsError naming what the file holds.
fn model_of(params: &Bound<'_, PyAny>, kind: &str) -> PyResult<Model> {
    let m = Model::new(params)?;
    if m.kind != kind {
        return Err(err(format!(
            "the parameters are a {} model, not {kind}",
            m.kind
        )));
    }
    Ok(m)
}

/// Gms(params): a Generalized Maxwell-Slip model (the file's `model` must be "gms").
#[pyclass(module = "gms", unsendable, extends = Model)]
struct Gms;

#[pymethods]
impl Gms {
    #[new]
    fn new(params: &Bound<'_, PyAny>) -> PyResult<PyClassInitializer<Self>> {
        Ok(PyClassInitializer::from(model_of(params, "gms")?).add_subclass(Gms))
    }
}

/// LuGre(params): a LuGre model (the file's `model` must be "lugre").
#[pyclass(module = "gms", unsendable, extends = Model)]
struct LuGre;

#[pymethods]
impl LuGre {
    #[new]
    fn new(params: &Bound<'_, PyAny>) -> PyResult<PyClassInitializer<Self>> {
        Ok(PyClassInitializer::from(model_of(params, "lugre")?).add_subclass(LuGre))
    }
}

/// StaticMap(params): a static friction map (the file's `model` must be "static").
#[pyclass(module = "gms", unsendable, extends = Model)]
struct StaticMap;

#[pymethods]
impl StaticMap {
    #[new]
    fn new(params: &Bound<'_, PyAny>) -> PyResult<PyClassInitializer<Self>> {
        Ok(PyClassInitializer::from(model_of(params, "static")?).add_subclass(StaticMap))
    }
}

/// identify(presliding=None, sliding=None, lag=None, blocks=6, asymmetric=False) -> dict
///
/// The whole identification of `hil-sim identify` from its CSV files (pre-sliding `x,f`,
/// sliding `v,f`, lag `t,x,f`): {"params": the parameter file's text, "friction": its
/// [friction] table as a dict, "report": [lines], "virgin", "stribeck", "lag": the fits}.
#[pyfunction]
#[pyo3(signature = (presliding = None, sliding = None, lag = None, blocks = 6, asymmetric = false))]
fn identify<'py>(
    py: Python<'py>,
    presliding: Option<PathBuf>,
    sliding: Option<PathBuf>,
    lag: Option<PathBuf>,
    blocks: usize,
    asymmetric: bool,
) -> PyResult<Bound<'py, PyDict>> {
    let id = gms_ident::identify::identify_from(&gms_ident::identify::Inputs {
        presliding: presliding.as_deref(),
        sliding: sliding.as_deref(),
        lag: lag.as_deref(),
        blocks,
        asymmetric,
    })
    .map_err(err)?;
    let file = ParamFile {
        friction: id.spec.clone(),
        device: None,
    };
    let text = file.to_toml();
    let table: toml::Table = toml::from_str(&text).map_err(err)?;
    let d = PyDict::new(py);
    d.set_item("params", &text)?;
    d.set_item(
        "friction",
        json_to_py(py, &serde_json::to_value(&table["friction"]).map_err(err)?)?,
    )?;
    d.set_item("report", id.report.clone())?;
    d.set_item(
        "virgin",
        id.virgin.as_ref().map(|f| debug_dict(py, f)).transpose()?,
    )?;
    d.set_item(
        "stribeck",
        id.stribeck
            .as_ref()
            .map(|f| debug_dict(py, f))
            .transpose()?,
    )?;
    d.set_item(
        "lag",
        id.lag.as_ref().map(|f| debug_dict(py, f)).transpose()?,
    )?;
    Ok(d)
}

/// fit_virgin(x, f, blocks=6) -> dict
///
/// The virgin-curve fit of `hil-sim identify` on arrays: pre-sliding displacement x [m or
/// rad] and friction f [N or N·m] from rest; returns {"fs", "blocks": [(k, alpha)], "rms",
/// ...} as the identification's report gives them.
#[pyfunction]
#[pyo3(signature = (x, f, blocks = 6))]
fn fit_virgin<'py>(
    py: Python<'py>,
    x: PyReadonlyArray1<'py, f64>,
    f: PyReadonlyArray1<'py, f64>,
    blocks: usize,
) -> PyResult<Bound<'py, PyDict>> {
    let fit = gms_ident::identify::fit_virgin(&floats(&x), &floats(&f), blocks).map_err(err)?;
    debug_dict(py, &fit)
}

/// fit_stribeck(v, f) -> dict
///
/// The Stribeck fit of `hil-sim identify` on arrays of steady sliding speed v [m/s or rad/s,
/// > 0] and friction f: {"fs", "fc", "vs", "delta", "sigma", "rms", "std_err": [...]}.
#[pyfunction]
fn fit_stribeck<'py>(
    py: Python<'py>,
    v: PyReadonlyArray1<'py, f64>,
    f: PyReadonlyArray1<'py, f64>,
) -> PyResult<Bound<'py, PyDict>> {
    let fit = gms_ident::identify::fit_stribeck(&floats(&v), &floats(&f)).map_err(err)?;
    debug_dict(py, &fit)
}

/// fit_lag(params, t, x, f) -> dict
///
/// The frictional-lag fit of C on arrays (t [s], x, f) with the rest of the model from
/// `params` (a path or a dict): {"c", "rel_err", "rms"}.
#[pyfunction]
fn fit_lag<'py>(
    py: Python<'py>,
    params: &Bound<'py, PyAny>,
    t: PyReadonlyArray1<'py, f64>,
    x: PyReadonlyArray1<'py, f64>,
    f: PyReadonlyArray1<'py, f64>,
) -> PyResult<Bound<'py, PyDict>> {
    let pf = param_file(params)?;
    let fit = gms_ident::identify::fit_lag(&pf.friction, &floats(&t), &floats(&x), &floats(&f))
        .map_err(err)?;
    debug_dict(py, &fit)
}

/// A fit's fields as a dict, through its serde form.
fn debug_dict<'py, T: serde::Serialize>(py: Python<'py>, v: &T) -> PyResult<Bound<'py, PyDict>> {
    let json = serde_json::to_value(v).map_err(err)?;
    match json_to_py(py, &json)?.cast_into::<PyDict>() {
        Ok(d) => Ok(d),
        Err(_) => Err(err("not a record")),
    }
}

fn json_to_py<'py>(py: Python<'py>, v: &serde_json::Value) -> PyResult<Bound<'py, PyAny>> {
    use serde_json::Value;
    Ok(match v {
        Value::Null => py.None().into_bound(py),
        Value::Bool(b) => PyBool::new(py, *b).to_owned().into_any(),
        Value::Number(n) => match n.as_i64() {
            Some(i) if !n.is_f64() => i.into_pyobject(py)?.into_any(),
            _ => n.as_f64().unwrap_or(f64::NAN).into_pyobject(py)?.into_any(),
        },
        Value::String(s) => s.into_pyobject(py)?.into_any(),
        Value::Array(a) => {
            let l = PyList::empty(py);
            for x in a {
                l.append(json_to_py(py, x)?)?;
            }
            l.into_any()
        }
        Value::Object(o) => {
            let d = PyDict::new(py);
            for (k, x) in o {
                d.set_item(k, json_to_py(py, x)?)?;
            }
            d.into_any()
        }
    })
}

/// A scenario from None (the default), a path or a dict with the file's keys.
fn scenario(sc: Option<&Bound<'_, PyAny>>) -> PyResult<hil_sim::scenario::Scenario> {
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
fn run<'py>(py: Python<'py>, scenario: Option<&Bound<'py, PyAny>>) -> PyResult<Bound<'py, PyDict>> {
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
fn compare<'py>(
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

/// A device over a serial port or TCP, speaking the protocol as `gms-tune` does.
#[pyclass(module = "gms", unsendable)]
struct Device {
    link: gms_tune::Link,
}

fn link_err(e: gms_tune::LinkError) -> PyErr {
    err(e)
}

#[pymethods]
impl Device {
    /// Device(port=None, tcp=None, timeout=1.0): a board's serial port, or a TCP address
    /// (`hil-sim serve --tcp`); `timeout` is the reply timeout [s].
    #[new]
    #[pyo3(signature = (port = None, tcp = None, timeout = 1.0))]
    fn new(port: Option<String>, tcp: Option<String>, timeout: f64) -> PyResult<Device> {
        if !(timeout.is_finite() && timeout > 0.0) {
            return Err(err(format!("timeout {timeout}: seconds, above 0")));
        }
        let d = Duration::from_secs_f64(timeout);
        let link = match (port, tcp) {
            (Some(p), None) => gms_tune::Link::serial(&p, d),
            (None, Some(a)) => gms_tune::Link::tcp(&a, d),
            _ => Err("give port or tcp (one of them)".into()),
        }
        .map_err(err)?;
        Ok(Device { link })
    }

    /// request(line) -> str: one protocol line; the text after `ok` (with the lines before it,
    /// newline-separated); an `err` reply raises GmsError with the device's line.
    fn request(&mut self, line: &str) -> PyResult<String> {
        self.link.request_text(line).map_err(link_err)
    }

    /// get(path) -> float | str: a parameter's value (a number where it is one).
    fn get<'py>(&mut self, py: Python<'py>, path: &str) -> PyResult<Bound<'py, PyAny>> {
        let (_, v) = self
            .link
            .request(&format!("get {path}"))
            .map_err(link_err)?;
        let v = v.trim().to_string();
        Ok(match v.parse::<f64>() {
            Ok(x) => x.into_pyobject(py)?.into_any(),
            Err(_) => v.into_pyobject(py)?.into_any(),
        })
    }

    /// set(path, value): sets a parameter; a refusal raises GmsError and changes nothing.
    fn set(&mut self, path: &str, value: &Bound<'_, PyAny>) -> PyResult<()> {
        let v: String = match value.extract::<f64>() {
            Ok(x) if value.is_instance_of::<PyBool>() => {
                return Err(err(format!("{path}: {x}: not a number or a name")));
            }
            Ok(x) => format!("{x}"),
            Err(_) => value.extract::<String>()?,
        };
        self.link
            .request(&format!("set {path} {v}"))
            .map_err(link_err)?;
        Ok(())
    }

    /// list() -> list[dict]: every parameter as {"path", "value", "unit", "range"}.
    fn list<'py>(&mut self, py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
        let rows = gms_tune::params::list(&mut self.link).map_err(link_err)?;
        let l = PyList::empty(py);
        for r in rows {
            let d = PyDict::new(py);
            d.set_item("path", r.path)?;
            d.set_item("value", r.value)?;
            d.set_item("unit", r.unit)?;
            d.set_item("range", r.range)?;
            l.append(d)?;
        }
        Ok(l)
    }

    /// status() -> dict: the `status` reply's keys (numbers where they are).
    fn status<'py>(&mut self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let st = self.link.status().map_err(link_err)?;
        let d = PyDict::new(py);
        for (k, v) in st.entries() {
            match v {
                gms_core::device::StatusValue::Number(x) => d.set_item(k, x)?,
                gms_core::device::StatusValue::Text(t) => d.set_item(k, t)?,
                gms_core::device::StatusValue::Faults(f) => {
                    let mut names = String::new();
                    let _ = f.write_names(&mut names);
                    d.set_item(k, names)?
                }
            }
        }
        Ok(d)
    }

    /// record(fields="t,pos,error,current", rate=1000.0, seconds=1.0) -> dict: the telemetry
    /// stream for `seconds` (wall time) as {field: numpy array}, as `gms-tune record`.
    #[pyo3(signature = (fields = "t,pos,error,current", rate = 1000.0, seconds = 1.0))]
    fn record<'py>(
        &mut self,
        py: Python<'py>,
        fields: &str,
        rate: f64,
        seconds: f64,
    ) -> PyResult<Bound<'py, PyDict>> {
        if !(seconds > 0.0 && seconds <= 3600.0 && rate > 0.0 && rate <= 1000.0) {
            return Err(err("seconds in (0, 3600], rate in (0, 1000]"));
        }
        let rows = self.link.record(fields, rate, seconds).map_err(link_err)?;
        let d = PyDict::new(py);
        for (c, n) in fields.split(',').map(str::trim).enumerate() {
            d.set_item(
                n,
                PyArray1::from_vec(py, rows.iter().map(|r| r[c]).collect()),
            )?;
        }
        Ok(d)
    }

    /// step_test(distance=2e-4, seconds=0.5) -> dict: `gms-tune step-test` — the bridge on,
    /// a move by `distance` [rad], `seconds` recorded: {"trace": {t, ref, pos, error, ff,
    /// friction: arrays}, "metrics": the figures of hil-sim run, "rad_per_count": the
    /// device's encoder resolution [rad/count] that the figures in counts use}.
    #[pyo3(signature = (distance = 2e-4, seconds = 0.5))]
    fn step_test<'py>(
        &mut self,
        py: Python<'py>,
        distance: f64,
        seconds: f64,
    ) -> PyResult<Bound<'py, PyDict>> {
        if !(distance.is_finite() && seconds > 0.0 && seconds <= 60.0) {
            return Err(err("distance finite, seconds in (0, 60]"));
        }
        let (rows, _, m, rad_per_count) =
            gms_tune::run::step_test(&mut self.link, distance, seconds).map_err(link_err)?;
        let trace = PyDict::new(py);
        for (c, n) in gms_tune::run::STEP_FIELDS.split(',').enumerate() {
            trace.set_item(
                n,
                PyArray1::from_vec(py, rows.iter().map(|r| r[c]).collect()),
            )?;
        }
        let d = PyDict::new(py);
        d.set_item("trace", trace)?;
        d.set_item("metrics", debug_dict(py, &m)?)?;
        d.set_item("rad_per_count", rad_per_count)?;
        Ok(d)
    }

    /// tune_ff(amplitude=2e-3, freq=1.0, seconds=3.0, start=0.5, stop=1.3, steps=9) -> dict:
    /// `gms-tune tune-ff` — the sine test at each ff.gain of a coarse sweep (widened at an
    /// edge), then twice at 9 gains around its optimum: {"curve": [(gain, RMS [rad])],
    /// "optimum", "standard_error" (None without a minimum), "decided", "chosen" (the optimum
    /// when decided, else "before"), "before", "notes"}; the device keeps `before` (set
    /// ff.gain to apply).
    #[pyo3(signature = (amplitude = 2e-3, freq = 1.0, seconds = 3.0, start = 0.5, stop = 1.3, steps = 9))]
    #[allow(clippy::too_many_arguments)]
    fn tune_ff<'py>(
        &mut self,
        py: Python<'py>,
        amplitude: f64,
        freq: f64,
        seconds: f64,
        start: f64,
        stop: f64,
        steps: usize,
    ) -> PyResult<Bound<'py, PyDict>> {
        let plan = gms_ident::bench::TuneFfPlan {
            amp: amplitude,
            freq,
            seconds,
            from: start,
            to: stop,
            steps,
            ..Default::default()
        };
        plan.check().map_err(err)?;
        let t = self.run_bench(|b| gms_ident::bench::tune_ff(b, &plan, |_, _, _| {}))?;
        let d = PyDict::new(py);
        d.set_item("curve", t.curve.clone())?;
        d.set_item("chosen", t.chosen)?;
        d.set_item("before", t.before)?;
        d.set_item("decided", t.decided)?;
        d.set_item("optimum", t.optimum.map(|o| o.at))?;
        d.set_item("standard_error", t.optimum.map(|o| o.se))?;
        d.set_item("notes", t.notes.clone())?;
        Ok(d)
    }

    /// commission(speed=1.0) -> dict: `gms-tune commission` — {"lines": a line per step,
    /// "settings": {protocol path: value}}; nothing applied (send the settings to apply).
    #[pyo3(signature = (speed = 1.0))]
    fn commission<'py>(&mut self, py: Python<'py>, speed: f64) -> PyResult<Bound<'py, PyDict>> {
        let c = self.run_bench(|b| gms_ident::bench::commission(b, speed))?;
        let d = PyDict::new(py);
        d.set_item("lines", c.lines.clone())?;
        let s = PyDict::new(py);
        for (k, v) in c.settings() {
            s.set_item(k, v)?;
        }
        d.set_item("settings", s)?;
        Ok(d)
    }

    /// identify(report="identify-report", blocks=6) -> dict: `gms-tune identify` — the
    /// experiments on the device (CSVs in `report`), the fits: {"params": the parameter
    /// file's text, "report": lines, "presliding": [(x, f)], "sliding": [(v, f)]}; nothing
    /// applied.
    #[pyo3(signature = (report = PathBuf::from("identify-report"), blocks = 6))]
    fn identify<'py>(
        &mut self,
        py: Python<'py>,
        report: PathBuf,
        blocks: usize,
    ) -> PyResult<Bound<'py, PyDict>> {
        use gms_ident::bench;
        let dev = bench::DeviceInfo::read(&mut self.link).map_err(err)?;
        let plans = bench::Plans::new(&dev, &bench::Ranges::default()).map_err(err)?;
        let (g, id) = self.run_bench(|b| {
            bench::identify_on(b, &plans, &report, blocks, false, &mut |_, _, _| {})
        })?;
        let (_, text) = gms_tune::run::write_identified(&id, &report, None).map_err(err)?;
        let d = PyDict::new(py);
        d.set_item("params", text)?;
        d.set_item("report", id.report.clone())?;
        d.set_item("presliding", g.presliding)?;
        d.set_item("sliding", g.sliding)?;
        Ok(d)
    }
}

/// Hooks that report nothing (Python's caller waits for the result).
struct Quiet;

impl gms_tune::run::Hooks for Quiet {
    fn stage(&mut self, _: &str, _: f64) {}
    fn waited(&mut self, _: f64) {}
}

impl Device {
    /// Runs `f` on the link as the command line's run bench.
    fn run_bench<T>(
        &mut self,
        f: impl FnOnce(&mut gms_tune::run::RunBench<'_, '_>) -> Result<T, gms_ident::Error>,
    ) -> PyResult<T> {
        let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
        let mut quiet = Quiet;
        let mut b = gms_tune::run::RunBench::new(&mut self.link, stop, "stopped", &mut quiet);
        f(&mut b).map_err(|e| err(format!("{e}; the bridge is off")))
    }
}

/// The module.
#[pymodule]
fn gms(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("GmsError", m.py().get_type::<GmsError>())?;
    m.add_function(wrap_pyfunction!(friction, m)?)?;
    m.add_function(wrap_pyfunction!(fit_virgin, m)?)?;
    m.add_function(wrap_pyfunction!(fit_stribeck, m)?)?;
    m.add_function(wrap_pyfunction!(fit_lag, m)?)?;
    m.add_function(wrap_pyfunction!(run, m)?)?;
    m.add_function(wrap_pyfunction!(compare, m)?)?;
    m.add_function(wrap_pyfunction!(identify, m)?)?;
    m.add_class::<Model>()?;
    m.add_class::<Gms>()?;
    m.add_class::<LuGre>()?;
    m.add_class::<StaticMap>()?;
    m.add_class::<Device>()?;
    Ok(())
}
