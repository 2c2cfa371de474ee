use pyo3::create_exception;
use pyo3::exceptions::PyException;
use pyo3::prelude::*;

create_exception!(
    aptkt._core,
    AptktError,
    PyException,
    "Base class of every error raised by aptkt's compiled core."
);

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("AptktError", m.py().get_type::<AptktError>())?;
    Ok(())
}
