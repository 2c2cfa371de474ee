//! The one place where an error of a core crate becomes a Python exception.
//!
//! The exception classes live in Python (`aptkt.errors`), not here: each derives from
//! `AptktError` *and* from the builtin a Python user catches (`ValueError`, `MemoryError`, ...),
//! and `create_exception!` allows a single base. The binding fetches a class from that module
//! the first time it raises one and keeps it for the interpreter's life.
//!
//! The orphan rule forbids `impl From<GpError> for PyErr` in this crate (both types are
//! foreign), so the binding's functions return [`Result`], whose error [`Error`] takes every
//! core error and any `PyErr` through `?`, and converts to the Python exception on the way out
//! (polars' `PyPolarsErr` does the same). The conversion waits until pyo3 hands the error to
//! Python, where the GIL is held, so `?` also works inside `py.detach`.

use aptkt_features::FeatureError;
use aptkt_gp::GpError;
use aptkt_sim::SimError;
use aptkt_skin::{ColumnsError, EncodeError, QuantizeError};
use pyo3::exceptions::PyRuntimeError;
use pyo3::prelude::*;
use pyo3::sync::PyOnceLock;
use pyo3::types::PyType;
use pyo3::CastError;

/// An exception class of `aptkt.errors`, imported on first use.
pub struct ErrorType {
    name: &'static str,
    class: PyOnceLock<Py<PyType>>,
}

impl ErrorType {
    const fn new(name: &'static str) -> Self {
        Self {
            name,
            class: PyOnceLock::new(),
        }
    }

    /// The exception with `message`.
    pub fn err(&'static self, message: impl Into<String>) -> PyErr {
        let message = message.into();
        Python::attach(
            |py| match self.class.import(py, "aptkt.errors", self.name) {
                Ok(class) => PyErr::from_type(class.clone(), message),
                // Only a broken installation lacks aptkt.errors; its ImportError or AttributeError
                // says so better than a panic would.
                Err(e) => e,
            },
        )
    }
}

pub static APTKT_ERROR: ErrorType = ErrorType::new("AptktError");
pub static INVALID_INPUT: ErrorType = ErrorType::new("InvalidInputError");
pub static INVALID_TYPE: ErrorType = ErrorType::new("InvalidTypeError");
pub static NON_FINITE_RESULT: ErrorType = ErrorType::new("NonFiniteResultError");
pub static KERNEL_NOT_POSITIVE_DEFINITE: ErrorType =
    ErrorType::new("KernelNotPositiveDefiniteError");
pub static PROBLEM_TOO_LARGE: ErrorType = ErrorType::new("ProblemTooLargeError");

/// The binding's own check of an argument's value (`InvalidInputError`, a `ValueError`).
pub fn invalid_input(message: impl Into<String>) -> Error {
    Error::InvalidInput(message.into())
}

/// The binding's own check of an argument's type (`InvalidTypeError`, a `TypeError`).
pub fn invalid_type(message: impl Into<String>) -> Error {
    Error::InvalidType(message.into())
}

/// A fault of the binding itself, never of the input (a `RuntimeError` saying "internal
/// error": not an `AptktError`, since no user action causes or avoids it).
pub fn internal(message: impl Into<String>) -> Error {
    Error::Internal(message.into())
}

/// An error of a core crate, of the binding's own checks, or one Python already raised (a
/// failed extraction, Ctrl-C).
#[derive(Debug)]
pub enum Error {
    Python(PyErr),
    InvalidInput(String),
    InvalidType(String),
    Internal(String),
    Gp(GpError),
    Features(FeatureError),
    Sim(SimError),
    Encode(EncodeError),
    Quantize(QuantizeError),
    Columns(ColumnsError),
}

pub type Result<T, E = Error> = std::result::Result<T, E>;

macro_rules! from_error {
    ($($variant:ident($ty:ty)),* $(,)?) => {
        $(impl From<$ty> for Error {
            fn from(e: $ty) -> Self {
                Error::$variant(e)
            }
        })*
    };
}

from_error!(
    Python(PyErr),
    Gp(GpError),
    Features(FeatureError),
    Sim(SimError),
    Encode(EncodeError),
    Quantize(QuantizeError),
    Columns(ColumnsError),
);

impl From<CastError<'_, '_>> for Error {
    fn from(e: CastError<'_, '_>) -> Self {
        Error::Python(e.into())
    }
}

impl From<Error> for PyErr {
    fn from(e: Error) -> PyErr {
        match e {
            Error::Python(e) => e,
            Error::InvalidInput(message) => INVALID_INPUT.err(message),
            Error::InvalidType(message) => INVALID_TYPE.err(message),
            Error::Internal(message) => {
                PyRuntimeError::new_err(format!("internal error: {message}"))
            }
            Error::Gp(e) => match e {
                GpError::InvalidInput(_) | GpError::NonFinite(_) => {
                    INVALID_INPUT.err(e.to_string())
                }
                GpError::NotPositiveDefinite { .. } => {
                    KERNEL_NOT_POSITIVE_DEFINITE.err(e.to_string())
                }
                GpError::TooLarge { .. } => PROBLEM_TOO_LARGE.err(e.to_string()),
                // Only a cancel flag set by the binding itself ends a fit this way, and it
                // raises the signal's exception (KeyboardInterrupt) instead; this is a fallback.
                GpError::Cancelled => APTKT_ERROR.err(e.to_string()),
            },
            Error::Features(e) => match e {
                FeatureError::NonFiniteResult { .. } => NON_FINITE_RESULT.err(e.to_string()),
                FeatureError::NonFinite { .. } | FeatureError::Shape { .. } => {
                    INVALID_INPUT.err(e.to_string())
                }
            },
            Error::Sim(SimError::InvalidInput(message)) => INVALID_INPUT.err(message),
            Error::Encode(e) => INVALID_INPUT.err(e.to_string()),
            Error::Quantize(e) => INVALID_INPUT.err(e.to_string()),
            Error::Columns(e) => INVALID_INPUT.err(e.to_string()),
        }
    }
}
