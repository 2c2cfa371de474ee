/// Errors of the Gaussian-process core. Messages are written for the user of the Python API.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GpError {
    /// Wrong shapes, too few classes, out-of-range hyper-parameters.
    #[error("{0}")]
    InvalidInput(String),
    /// NaN or infinity in the data or the hyper-parameters.
    #[error("{0}")]
    NonFinite(String),
    /// The kernel stayed non-positive-definite even with the largest permitted jitter.
    #[error(
        "the kernel matrix is not positive definite (Cholesky failed at pivot {pivot} even with \
         jitter {jitter:e} x signal variance added to its diagonal); check the hyper-parameters \
         (a transfer lambda outside [0, 1] makes the dependent kernel indefinite) or raise max_jitter"
    )]
    NotPositiveDefinite { pivot: usize, jitter: f64 },
    /// The fit was cancelled through its cancel flag.
    #[error("the fit was cancelled")]
    Cancelled,
    /// The work needs more memory than the machine has: found before allocating it.
    #[error("{message}")]
    TooLarge {
        rows: usize,
        bytes: u128,
        message: String,
    },
}

pub type GpResult<T> = Result<T, GpError>;
