//! Bindings of the simulation core (`aptkt-sim`), one concern a module:
//!
//! * `settings` — the frozen settings objects one trial's physics is built from (the patch,
//!   the object's surface, the sensors and their readings), each a core struct;
//! * `state` — the trial's physics state, the mechanics' samples and the trajectory's segments;
//! * `contact` — `SimContact` (one object in one trial: mechanics, force loop, readings) and the
//!   object's thermal operators, shared by its trials;
//! * `control` — the force loop: its settings, its phases, its queue of packets in flight;
//! * `kernels` — the heat, texture and stick-slip loops on their own (the tests compare them
//!   with numpy) and the subnormal switch around LAPACK.
//!
//! Arrays are converted once per call; the GIL is released around the loops.

use numpy::ndarray::{Array1, Array2};
use numpy::{Element, IntoPyArray, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::prelude::*;

use crate::errors::{internal, invalid_input, Result};

mod contact;
mod control;
mod kernels;
mod settings;
mod state;

/// The rows of an (n, W) array.
fn rows<const W: usize>(a: &PyReadonlyArray2<'_, f64>, name: &str) -> Result<Vec<[f64; W]>> {
    let v = a.as_array();
    if v.ncols() != W {
        return Err(invalid_input(format!("{name} must have {W} columns")));
    }
    Ok(v.rows()
        .into_iter()
        .map(|r| std::array::from_fn(|j| r[j]))
        .collect())
}

fn vec1<T: Element + Copy>(a: &PyReadonlyArray1<'_, T>) -> Vec<T> {
    a.as_array().iter().copied().collect()
}

/// A numpy column (n,) of `v`.
fn col<'py, T: Element>(py: Python<'py>, v: Vec<T>) -> Bound<'py, PyAny> {
    Array1::from_vec(v).into_pyarray(py).into_any()
}

/// A numpy matrix (n, W) of the rows `v`.
fn mat<'py, const W: usize>(py: Python<'py>, v: Vec<[f64; W]>) -> Result<Bound<'py, PyAny>> {
    let n = v.len();
    let flat: Vec<f64> = v.into_iter().flatten().collect();
    let a = Array2::from_shape_vec((n, W), flat).map_err(|e| internal(e.to_string()))?;
    Ok(a.into_pyarray(py).into_any())
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    settings::register(m)?;
    state::register(m)?;
    contact::register(m)?;
    control::register(m)?;
    kernels::register(m)
}
