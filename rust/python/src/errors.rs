use pyo3::create_exception;
use pyo3::exceptions::{PyException, PyValueError};
use pyo3::prelude::*;

create_exception!(
    aptkt._core,
    AptktError,
    PyException,
    "Base class of every error raised on purpose by aptkt."
);
create_exception!(
    aptkt._core,
    KernelNotPositiveDefiniteError,
    AptktError,
    "A kernel matrix stayed non-positive-definite even after the largest permitted jitter."
);
create_exception!(
    aptkt._core,
    ProblemTooLargeError,
    AptktError,
    "The work needs more memory than this machine has; found before allocating it. The \
     message names the rows and the bytes needed."
);
create_exception!(
    aptkt._core,
    NonFiniteResultError,
    AptktError,
    "A computation on finite input overflowed to infinity or NaN (the input's values are too \
     large for float64 arithmetic); the message names the input."
);

/// Maps the Gaussian-process core's errors: bad input is a `ValueError`, a numerically
/// hopeless kernel has its own type.
pub fn gp_error(e: aptkt_gp::GpError) -> PyErr {
    match e {
        aptkt_gp::GpError::InvalidInput(_) | aptkt_gp::GpError::NonFinite(_) => {
            PyValueError::new_err(e.to_string())
        }
        aptkt_gp::GpError::NotPositiveDefinite { .. } => {
            KernelNotPositiveDefiniteError::new_err(e.to_string())
        }
        aptkt_gp::GpError::Cancelled => AptktError::new_err(e.to_string()),
        aptkt_gp::GpError::TooLarge { .. } => ProblemTooLargeError::new_err(e.to_string()),
    }
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("AptktError", py.get_type::<AptktError>())?;
    m.add(
        "KernelNotPositiveDefiniteError",
        py.get_type::<KernelNotPositiveDefiniteError>(),
    )?;
    m.add(
        "ProblemTooLargeError",
        py.get_type::<ProblemTooLargeError>(),
    )?;
    m.add(
        "NonFiniteResultError",
        py.get_type::<NonFiniteResultError>(),
    )?;
    Ok(())
}
