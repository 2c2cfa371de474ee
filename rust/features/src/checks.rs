use ndarray::{ArrayViewD, Dimension};

use crate::Sample;

/// Errors of the feature kernels. Messages name the offending input so a user can find it.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FeatureError {
    #[error("{name} contains a non-finite value ({value}) at index ({})", index.iter().map(|i| i.to_string()).collect::<Vec<_>>().join(", "))]
    NonFinite {
        name: String,
        index: Vec<usize>,
        value: f64,
    },
    #[error("{name}: {message}")]
    Shape { name: String, message: String },
    /// Finite input whose result overflowed: values too large for float64 arithmetic (their
    /// squares or differences exceed 1.8e308).
    #[error("{name}: the {what} overflows to {value} (the values are too large: their squares or differences exceed float64's range); rescale the input")]
    NonFiniteResult {
        name: String,
        what: String,
        value: f64,
    },
}

impl FeatureError {
    pub(crate) fn shape(name: &str, message: impl Into<String>) -> Self {
        FeatureError::Shape {
            name: name.to_string(),
            message: message.into(),
        }
    }

    pub(crate) fn overflow(name: &str, what: &str, value: f64) -> Self {
        FeatureError::NonFiniteResult {
            name: name.to_string(),
            what: what.to_string(),
            value,
        }
    }
}

/// `values` of a computation on input already known to be finite: any NaN or infinity in them
/// is an overflow, reported as [`FeatureError::NonFiniteResult`].
pub(crate) fn finite_result<'a>(
    name: &str,
    what: &str,
    values: impl IntoIterator<Item = &'a f64>,
) -> Result<(), FeatureError> {
    match values.into_iter().find(|v| !v.is_finite()) {
        Some(&v) => Err(FeatureError::overflow(name, what, v)),
        None => Ok(()),
    }
}

/// Fails on the first NaN or infinity, reporting its multi-index.
pub fn check_finite<T: Sample>(name: &str, x: &ArrayViewD<'_, T>) -> Result<(), FeatureError> {
    if !T::CAN_BE_NON_FINITE {
        return Ok(());
    }
    if x.iter().all(|v| v.to_f64().is_finite()) {
        return Ok(());
    }
    let found = x
        .indexed_iter()
        .find(|(_, v)| !v.to_f64().is_finite())
        .map(|(i, v)| (i.slice().to_vec(), v.to_f64()));
    match found {
        Some((index, value)) => Err(FeatureError::NonFinite {
            name: name.to_string(),
            index,
            value,
        }),
        None => Ok(()),
    }
}

/// Resolves a possibly negative axis against `ndim`.
pub(crate) fn resolve_axis(name: &str, axis: isize, ndim: usize) -> Result<usize, FeatureError> {
    let resolved = if axis < 0 { axis + ndim as isize } else { axis };
    if resolved < 0 || resolved as usize >= ndim {
        return Err(FeatureError::shape(
            name,
            format!("axis {axis} is out of bounds for an array of dimension {ndim}"),
        ));
    }
    Ok(resolved as usize)
}
