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

mod device;
mod ident;
mod models;
mod sim;

use device::Device;
use ident::{fit_lag, fit_stribeck, fit_virgin, identify};
use models::{Gms, LuGre, Model, StaticMap, friction};
use sim::{compare, learn, run};

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
    m.add_function(wrap_pyfunction!(learn, m)?)?;
    m.add_function(wrap_pyfunction!(identify, m)?)?;
    m.add_class::<Model>()?;
    m.add_class::<Gms>()?;
    m.add_class::<LuGre>()?;
    m.add_class::<StaticMap>()?;
    m.add_class::<Device>()?;
    Ok(())
}
