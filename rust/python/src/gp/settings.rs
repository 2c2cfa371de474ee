//! Everything that defines a fit except the data, as frozen settings objects: where the
//! hyper-parameters start and which of them are free, the search, the Laplace approximation,
//! the hyper-priors (MAP-II), gathered in `FitSettings`. Defaults live in Python
//! (`aptkt.gp.DEFAULTS`), which passes every field.

use aptkt_gp::{Free, HyperPrior, LatentMean, Modalities, ModelSpec, Predictive};
use pyo3::prelude::*;

use crate::errors::{invalid_input, Result};
use crate::settings::settings_class;

settings_class! {
    /// Where the hyper-parameters start: the feature columns of each modality, the signal
    /// variance σ², a length-scale per modality (NaN: scaled to the data, the median pairwise
    /// distance) and the modality weights γ (normalised).
    KernelStart {
        modalities: Vec<Vec<usize>>,
        signal_variance: f64,
        length_scales: Vec<f64>,
        weights: Vec<f64>,
    }
}

/// Which hyper-parameter groups the optimiser may change: σ², the length-scales, the weights,
/// the transfer λ; and whether the length-scales move as one (`tie_length_scales`, with the
/// shared kernel only).
#[pyclass(module = "aptkt._core", frozen)]
pub struct FreeHyperparameters {
    free: Free,
    tie_length_scales: bool,
}

#[pymethods]
impl FreeHyperparameters {
    #[new]
    #[pyo3(signature = (signal_variance, length_scales, weights, transfer_lambda, tie_length_scales = false))]
    fn new(
        signal_variance: bool,
        length_scales: bool,
        weights: bool,
        transfer_lambda: bool,
        tie_length_scales: bool,
    ) -> Self {
        Self {
            free: Free {
                signal_variance,
                length_scales,
                weights,
                lambda: transfer_lambda,
            },
            tie_length_scales,
        }
    }

    fn __repr__(&self) -> String {
        format!(
            "{:?}, tie_length_scales={}",
            self.free, self.tie_length_scales
        )
    }
}

settings_class! {
    /// The search for the hyper-parameters: whether to optimise, the random restarts and
    /// their seed, L-BFGS's iterations and relative tolerance (it stops when the objective's
    /// relative decrease falls below it), and the box of σ² and of the length-scales.
    Search {
        optimize: bool,
        n_restarts: usize,
        seed: u64,
        max_iter: usize,
        optimizer_tol: f64,
        signal_variance_bounds: (f64, f64),
        length_scale_bounds: (f64, f64),
    }
}

settings_class! {
    /// The Laplace approximation: Newton's iteration limit and tolerance, the largest jitter,
    /// the predictive integral ("erf" or "quadrature") and the latent function's constant prior
    /// mean ("zero" or "base-rate": the log-odds of each classifier's Jeffreys-smoothed share of
    /// positive labels).
    Laplace {
        newton_max_iter: usize,
        newton_tol: f64,
        max_jitter: f64,
        approximation: String,
        latent_mean: String,
    }
}

settings_class! {
    /// MAP-II hyper-priors: on σ² (centre, sd of ln σ²), on each ℓ_m (centre relative to the
    /// modality's data scale, sd of ln ℓ_m), on each modality-weight logit (sd of a normal
    /// centred on 0, equal weights); None: flat.
    HyperPriors(HyperPrior) {
        signal_variance: Option<(f64, f64)>,
        length_scale: Option<(f64, f64)>,
        weight_logit: Option<f64>,
    }
}

/// Everything that defines a fit except the data, built with keywords only
/// (`FitSettings(start=..., free=..., search=..., laplace=..., n_threads=0)`); `n_threads`
/// threads for the per-class fits (0: rayon's default, all cores).
#[pyclass(module = "aptkt._core", frozen)]
pub struct FitSettings {
    start: KernelStart,
    free: Free,
    tie_length_scales: bool,
    search: Search,
    laplace: Laplace,
    hyper_prior: Option<HyperPrior>,
    pub n_threads: usize,
}

#[pymethods]
impl FitSettings {
    #[new]
    #[pyo3(signature = (*, start, free, search, laplace, n_threads, hyper_prior = None))]
    fn new(
        start: PyRef<'_, KernelStart>,
        free: PyRef<'_, FreeHyperparameters>,
        search: PyRef<'_, Search>,
        laplace: PyRef<'_, Laplace>,
        n_threads: usize,
        hyper_prior: Option<PyRef<'_, HyperPriors>>,
    ) -> Self {
        Self {
            start: start.clone(),
            free: free.free,
            tie_length_scales: free.tie_length_scales,
            search: search.clone(),
            laplace: laplace.clone(),
            hyper_prior: hyper_prior.map(|p| p.0),
            n_threads,
        }
    }

    fn __repr__(&self) -> String {
        format!(
            "FitSettings(start={:?}, free={:?}, tie_length_scales={}, search={:?}, laplace={:?}, \
             n_threads={}, hyper_prior={:?})",
            self.start,
            self.free,
            self.tie_length_scales,
            self.search,
            self.laplace,
            self.n_threads,
            self.hyper_prior
        )
    }
}

impl FitSettings {
    /// The core's model specification for data with `d` columns.
    pub fn spec(&self, d: usize) -> Result<ModelSpec> {
        let (start, search, laplace) = (&self.start, &self.search, &self.laplace);
        let modalities = Modalities::new(start.modalities.clone(), d)?;
        let mut spec = ModelSpec::new(modalities);
        spec.signal_variance = start.signal_variance;
        spec.length_scales = start.length_scales.clone();
        spec.weights = start.weights.clone();
        spec.free = self.free;
        spec.tie_length_scales = self.tie_length_scales;
        spec.signal_variance_bounds = search.signal_variance_bounds;
        spec.length_scale_bounds = search.length_scale_bounds;
        spec.optimize = search.optimize;
        spec.n_restarts = search.n_restarts;
        spec.seed = search.seed;
        spec.lbfgs.max_iter = search.max_iter;
        spec.lbfgs.ftol = search.optimizer_tol;
        spec.newton.max_iter = laplace.newton_max_iter;
        spec.newton.tol = laplace.newton_tol;
        spec.max_jitter = laplace.max_jitter;
        spec.predictive = parse_predictive(&laplace.approximation)?;
        spec.latent_mean = parse_latent_mean(&laplace.latent_mean)?;
        spec.hyper_prior = self.hyper_prior.filter(|p| {
            p.signal_variance.is_some() || p.length_scale.is_some() || p.weight_logit.is_some()
        });
        Ok(spec)
    }
}

fn parse_predictive(name: &str) -> Result<Predictive> {
    match name {
        "erf" => Ok(Predictive::ErfMixture),
        "quadrature" => Ok(Predictive::Quadrature),
        other => Err(invalid_input(format!(
            "approximation must be 'erf' or 'quadrature', got {other:?}"
        ))),
    }
}

fn parse_latent_mean(name: &str) -> Result<LatentMean> {
    match name {
        "zero" => Ok(LatentMean::Zero),
        "base-rate" => Ok(LatentMean::BaseRate),
        other => Err(invalid_input(format!(
            "latent_mean must be 'zero' or 'base-rate', got {other:?}"
        ))),
    }
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<KernelStart>()?;
    m.add_class::<FreeHyperparameters>()?;
    m.add_class::<Search>()?;
    m.add_class::<Laplace>()?;
    m.add_class::<HyperPriors>()?;
    m.add_class::<FitSettings>()
}
