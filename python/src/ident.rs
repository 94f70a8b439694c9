//! The identification fits on arrays, and the whole identification from experiment data.

use super::*;

/// identify(presliding=None, sliding=None, lag=None, blocks=6, asymmetric=False) -> dict
///
/// The whole identification of `hil-sim identify` from its CSV files (pre-sliding `x,f`,
/// sliding `v,f`, lag `t,x,f`): {"params": the parameter file's text, "friction": its
/// [friction] table as a dict, "report": [lines], "virgin", "stribeck", "lag": the fits}.
#[pyfunction]
#[pyo3(signature = (presliding = None, sliding = None, lag = None, blocks = 6, asymmetric = false))]
pub(crate) fn identify<'py>(
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
pub(crate) fn fit_virgin<'py>(
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
pub(crate) fn fit_stribeck<'py>(
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
pub(crate) fn fit_lag<'py>(
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
