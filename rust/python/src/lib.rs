//! The `aptkt._core` extension: a thin layer over the pure-Rust crates. It converts numpy
//! arrays to and from Rust types, releases the GIL around numerical work and maps core errors
//! to typed Python exceptions. No numerics live here.

use pyo3::prelude::*;

mod errors;
mod features;
mod gp;
mod sim;
mod skin;

#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    errors::register(m)?;
    features::register(m)?;
    gp::register(m)?;
    sim::register(m)?;
    skin::register(m)?;
    Ok(())
}
