//! Bindings of the feature kernels (`aptkt-features`). The Python wrappers in
//! `aptkt.features` normalise arguments; this layer only dispatches on dtype and releases the GIL.

use aptkt_features as core;
use numpy::{IntoPyArray, PyArray1, PyArrayDyn, PyReadonlyArrayDyn};
use pyo3::prelude::*;

use crate::errors::{invalid_type, Result};

/// A numpy array of one of the sample types the kernels accept.
pub enum SampleArray<'py> {
    F64(PyReadonlyArrayDyn<'py, f64>),
    F32(PyReadonlyArrayDyn<'py, f32>),
    I16(PyReadonlyArrayDyn<'py, i16>),
}

impl<'py> SampleArray<'py> {
    pub fn extract(ob: &Bound<'py, PyAny>, name: &str) -> Result<Self> {
        if let Ok(a) = ob.extract::<PyReadonlyArrayDyn<'py, f64>>() {
            return Ok(Self::F64(a));
        }
        if let Ok(a) = ob.extract::<PyReadonlyArrayDyn<'py, f32>>() {
            return Ok(Self::F32(a));
        }
        if let Ok(a) = ob.extract::<PyReadonlyArrayDyn<'py, i16>>() {
            return Ok(Self::I16(a));
        }
        Err(invalid_type(format!(
            "{name} must be a numpy array of float64, float32 or int16"
        )))
    }
}

/// Runs `$body` with `$view` bound to the array's `ArrayViewD` of its own element type, with
/// the GIL released.
macro_rules! with_view {
    ($py:expr, $arr:expr, |$view:ident| $body:expr) => {
        match &$arr {
            SampleArray::F64(a) => {
                let $view = a.as_array();
                $py.detach(|| $body)
            }
            SampleArray::F32(a) => {
                let $view = a.as_array();
                $py.detach(|| $body)
            }
            SampleArray::I16(a) => {
                let $view = a.as_array();
                $py.detach(|| $body)
            }
        }
    };
}

type ArrayTriple<'py> = (
    Bound<'py, PyArrayDyn<f64>>,
    Bound<'py, PyArrayDyn<f64>>,
    Bound<'py, PyArrayDyn<f64>>,
);

#[pyfunction]
#[pyo3(signature = (x, axis, name = "x"))]
fn hjorth<'py>(
    py: Python<'py>,
    x: &Bound<'py, PyAny>,
    axis: isize,
    name: &str,
) -> Result<ArrayTriple<'py>> {
    let arr = SampleArray::extract(x, name)?;
    let r = with_view!(py, arr, |v| core::hjorth_along(name, v, axis))?;
    Ok((
        r.activity.into_pyarray(py),
        r.mobility.into_pyarray(py),
        r.complexity.into_pyarray(py),
    ))
}

#[pyfunction]
#[pyo3(signature = (acc, channel_axis, time_axis, name = "acc"))]
fn axis_pair_correlations<'py>(
    py: Python<'py>,
    acc: &Bound<'py, PyAny>,
    channel_axis: isize,
    time_axis: isize,
    name: &str,
) -> Result<Bound<'py, PyArrayDyn<f64>>> {
    let arr = SampleArray::extract(acc, name)?;
    let r = with_view!(py, arr, |v| core::axis_pair_correlations(
        name,
        v,
        channel_axis,
        time_axis
    ))?;
    Ok(r.into_pyarray(py))
}

#[pyfunction]
#[pyo3(signature = (acc, name = "acc"))]
fn texture_descriptor<'py>(
    py: Python<'py>,
    acc: &Bound<'py, PyAny>,
    name: &str,
) -> Result<Bound<'py, PyArray1<f64>>> {
    let arr = SampleArray::extract(acc, name)?;
    let r = with_view!(py, arr, |v| core::texture_descriptor(name, v))?;
    Ok(r.into_pyarray(py))
}

#[pyfunction]
#[pyo3(signature = (x, name = "x"))]
fn mean_all(py: Python<'_>, x: &Bound<'_, PyAny>, name: &str) -> Result<f64> {
    let arr = SampleArray::extract(x, name)?;
    Ok(with_view!(py, arr, |v| core::mean_all(name, v))?)
}

#[pyfunction]
#[pyo3(signature = (x, axis, name = "x"))]
fn gradient<'py>(
    py: Python<'py>,
    x: &Bound<'py, PyAny>,
    axis: isize,
    name: &str,
) -> Result<Bound<'py, PyArrayDyn<f64>>> {
    let arr = SampleArray::extract(x, name)?;
    let r = with_view!(py, arr, |v| core::gradient_along(name, v, axis))?;
    Ok(r.into_pyarray(py))
}

#[pyfunction]
#[pyo3(signature = (temp, axis, name = "temp"))]
fn thermal_curve<'py>(
    py: Python<'py>,
    temp: &Bound<'py, PyAny>,
    axis: isize,
    name: &str,
) -> Result<Bound<'py, PyArray1<f64>>> {
    let arr = SampleArray::extract(temp, name)?;
    let r = with_view!(py, arr, |v| core::thermal_curve(name, v, axis))?;
    Ok(r.into_pyarray(py))
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(hjorth, m)?)?;
    m.add_function(wrap_pyfunction!(axis_pair_correlations, m)?)?;
    m.add_function(wrap_pyfunction!(texture_descriptor, m)?)?;
    m.add_function(wrap_pyfunction!(mean_all, m)?)?;
    m.add_function(wrap_pyfunction!(gradient, m)?)?;
    m.add_function(wrap_pyfunction!(thermal_curve, m)?)?;
    m.add("TEXTURE_DIM", core::TEXTURE_DIM)?;
    Ok(())
}
