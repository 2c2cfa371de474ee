//! Binary and one-vs-all Gaussian-process classification with the Laplace approximation and
//! the logistic likelihood (Rasmussen & Williams, *Gaussian Processes for Machine Learning*,
//! Algorithms 3.1, 3.2, 5.1), with the kernels of the APTKT method: a convex combination of
//! per-modality RBF kernels (paper Eq. 1) and the dependent kernel that transfers a source
//! task's observations with relatedness λ (paper Eq. 2).

pub mod error;
pub mod fastmath;
pub mod kernel;
pub mod laplace;
pub mod likelihood;
pub mod linalg;
pub mod memory;
pub mod model;
pub mod optimize;
pub mod rng;
pub mod shared;
mod simd;

pub use error::{GpError, GpResult};
pub use kernel::{Data, Hyper, Layout, Modalities};
pub use likelihood::Predictive;
pub use model::{
    fit, fit_at, fit_from, layout_for, BinaryFit, Free, HyperPrior, LatentMean, ModelSpec,
    OneVsAll, PriorTerm, Source, MAX_RESTARTS,
};
pub use shared::{fit_shared, KernelTask};
