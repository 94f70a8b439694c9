//! The friction models in Python: the same f32 code as the firmware, stepped on arrays.

use super::*;

/// A trajectory checked as `hil-sim friction` checks its file: equal lengths, finite values,
/// t strictly increasing.
pub(crate) fn trajectory(
    t: &[f64],
    x: &[f64],
) -> PyResult<Vec<hil_sim::friction_cmd::TrajectoryPoint>> {
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
        if let Some(p) = out
            .last()
            .map(|p: &hil_sim::friction_cmd::TrajectoryPoint| p.t)
            && ti <= p
        {
            return Err(err(format!(
                "sample {i}: t does not increase: {ti} after {p}"
            )));
        }
        out.push(hil_sim::friction_cmd::TrajectoryPoint { t: ti, x: xi });
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
pub(crate) fn friction<'py>(
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
pub(crate) struct Model {
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
pub(crate) fn model_of(params: &Bound<'_, PyAny>, kind: &str) -> PyResult<Model> {
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
pub(crate) struct Gms;

#[pymethods]
impl Gms {
    #[new]
    fn new(params: &Bound<'_, PyAny>) -> PyResult<PyClassInitializer<Self>> {
        Ok(PyClassInitializer::from(model_of(params, "gms")?).add_subclass(Gms))
    }
}

/// LuGre(params): a LuGre model (the file's `model` must be "lugre").
#[pyclass(module = "gms", unsendable, extends = Model)]
pub(crate) struct LuGre;

#[pymethods]
impl LuGre {
    #[new]
    fn new(params: &Bound<'_, PyAny>) -> PyResult<PyClassInitializer<Self>> {
        Ok(PyClassInitializer::from(model_of(params, "lugre")?).add_subclass(LuGre))
    }
}

/// StaticMap(params): a static friction map (the file's `model` must be "static").
#[pyclass(module = "gms", unsendable, extends = Model)]
pub(crate) struct StaticMap;

#[pymethods]
impl StaticMap {
    #[new]
    fn new(params: &Bound<'_, PyAny>) -> PyResult<PyClassInitializer<Self>> {
        Ok(PyClassInitializer::from(model_of(params, "static")?).add_subclass(StaticMap))
    }
}
