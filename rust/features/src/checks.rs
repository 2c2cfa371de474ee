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
}

impl FeatureError {
    pub(crate) fn shape(name: &str, message: impl Into<String>) -> Self {
        FeatureError::Shape {
            name: name.to_string(),
            message: message.into(),
        }
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
