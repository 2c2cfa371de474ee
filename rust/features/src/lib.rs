//! Tactile feature kernels of the APTKT pipeline (paper §3.2, docs/design.md §4).
//!
//! * [`hjorth`]: Hjorth activity, mobility and complexity of a signal (texture).
//! * [`pearson`] / [`axis_pair_correlations`]: linear correlation of acceleration axes (texture).
//! * [`texture_descriptor`]: the paper's `TD = [A, M, C, L]` of a multi-cell accelerometer recording.
//! * [`mean_all`]: mean normal force over sensors and time steps (stiffness).
//! * [`gradient`] / [`thermal_curve`]: the mean temperature sequence and its gradient (thermal).
//!
//! Kernels accept any [`Sample`] type (f64, f32, i16 raw values) and arbitrarily strided
//! `ndarray` views, so numpy arrays reach them without copies. Inputs are checked for NaN and
//! infinity up front: a feature computed from a corrupt sample would silently poison a model.

mod checks;
mod hjorth;
mod reductions;
mod texture;

pub use checks::{check_finite, FeatureError};
pub use hjorth::{hjorth, hjorth_along, Hjorth, HjorthArrays};
pub use reductions::{gradient, gradient_along, mean_all, thermal_curve};
pub use texture::{axis_pair_correlations, pearson, texture_descriptor, TEXTURE_DIM};

/// A numeric sample type the kernels accept; values are widened to f64 before any arithmetic.
pub trait Sample: Copy + Send + Sync + 'static {
    /// Whether the type can hold NaN or infinity at all (integers cannot).
    const CAN_BE_NON_FINITE: bool;
    fn to_f64(self) -> f64;
}

impl Sample for f64 {
    const CAN_BE_NON_FINITE: bool = true;
    #[inline(always)]
    fn to_f64(self) -> f64 {
        self
    }
}

impl Sample for f32 {
    const CAN_BE_NON_FINITE: bool = true;
    #[inline(always)]
    fn to_f64(self) -> f64 {
        f64::from(self)
    }
}

impl Sample for i16 {
    const CAN_BE_NON_FINITE: bool = false;
    #[inline(always)]
    fn to_f64(self) -> f64 {
        f64::from(self)
    }
}
