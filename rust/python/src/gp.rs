//! Bindings of the Laplace GPC core (`aptkt-gp`). Argument checking that needs Python
//! knowledge (labels, defaults, names) lives in `aptkt.gp`; this layer converts arrays,
//! releases the GIL and maps errors.

use aptkt_gp::kernel::{KernelEval, PairDistances};
use aptkt_gp::{
    Data, Free, GpError, HyperPrior, LatentMean, Layout, Modalities, ModelSpec, OneVsAll,
    Predictive, Source,
};
use numpy::{PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use std::cell::RefCell;
use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::time::Duration;

use crate::errors::gp_error;

fn data_from(x: &PyReadonlyArray2<'_, f64>) -> Result<Data, GpError> {
    let view = x.as_array();
    let (n, d) = view.dim();
    Data::new(view.iter().copied().collect(), n, d)
}

fn matrix<'py>(
    py: Python<'py>,
    values: Vec<f64>,
    rows: usize,
    cols: usize,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    PyArray1::from_vec(py, values)
        .reshape([rows, cols])
        .map_err(|e| PyValueError::new_err(format!("internal shape error: {e}")))
}

/// Where the work of [`run_interruptible`] leaves its result (or its panic).
type Done<T> = (Mutex<Option<std::thread::Result<T>>>, Condvar);

/// Runs `work` on a thread of the `n_threads` pool with the GIL released while this thread
/// waits for it, and looks for Python signals every [`POLL`]. If a signal handler raises
/// (Ctrl-C: `KeyboardInterrupt`), `cancel` is set, the work (which checks the flag between
/// iterations) is waited for, and the handler's exception is returned. The work signals its end
/// on a condition variable, so a short fit returns as soon as it is done (no sleep
/// granularity). It runs as a task of the kept pool rather than on a thread started for it:
/// starting and joining a thread per fit cost more than a small fit itself.
fn run_interruptible<T: Send>(
    py: Python<'_>,
    cancel: &AtomicBool,
    n_threads: usize,
    work: impl FnOnce() -> T + Send,
) -> PyResult<T> {
    let done: Done<T> = (Mutex::new(None), Condvar::new());
    if n_threads == 0 {
        rayon::in_place_scope(|scope| spawn_and_poll(scope, py, cancel, &done, work))?;
    } else {
        let pool = pool(n_threads).map_err(gp_error)?;
        pool.in_place_scope(|scope| spawn_and_poll(scope, py, cancel, &done, work))?;
    }
    let out = done.0.lock().unwrap_or_else(|e| e.into_inner()).take();
    match out {
        Some(Ok(value)) => Ok(value),
        Some(Err(payload)) => {
            let why = payload
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| payload.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "no message".to_string());
            Err(PyValueError::new_err(format!(
                "internal error: the fit's thread panicked: {why}"
            )))
        }
        None => Err(PyValueError::new_err(
            "internal error: the fit's thread ended without a result",
        )),
    }
}

fn spawn_and_poll<'scope, T: Send + 'scope>(
    scope: &rayon::Scope<'scope>,
    py: Python<'_>,
    cancel: &AtomicBool,
    done: &'scope Done<T>,
    work: impl FnOnce() -> T + Send + 'scope,
) -> PyResult<()> {
    scope.spawn(move |_| {
        let out = std::panic::catch_unwind(std::panic::AssertUnwindSafe(work));
        *done.0.lock().unwrap_or_else(|e| e.into_inner()) = Some(out);
        done.1.notify_all();
    });
    // Whether the work has ended, waiting at most `timeout` (None: until it ends).
    let ended = |timeout: Option<Duration>| {
        py.detach(|| {
            let slot = done.0.lock().unwrap_or_else(|e| e.into_inner());
            let slot = match timeout {
                Some(t) => {
                    done.1
                        .wait_timeout_while(slot, t, |s| s.is_none())
                        .unwrap_or_else(|e| e.into_inner())
                        .0
                }
                None => done
                    .1
                    .wait_while(slot, |s| s.is_none())
                    .unwrap_or_else(|e| e.into_inner()),
            };
            slot.is_some()
        })
    };
    while !ended(Some(POLL)) {
        if let Err(e) = py.check_signals() {
            cancel.store(true, Ordering::Relaxed);
            // The result of a cancelled fit is of no use; only its end is waited for.
            ended(None);
            return Err(e);
        }
    }
    Ok(())
}

/// How often a long fit looks for Ctrl-C.
const POLL: Duration = Duration::from_millis(20);

thread_local! {
    /// This thread's pools by thread count, with the process they were built in.
    static POOLS: RefCell<(u32, HashMap<usize, Arc<rayon::ThreadPool>>)> =
        RefCell::new((std::process::id(), HashMap::new()));
}

/// The calling thread's pool of `n_threads` threads, built on first use and kept: building one
/// per call started and stopped its threads every time, ≈ 0.1 ms of CPU per call, and a
/// learning run makes hundreds of calls. One per calling thread, so that fits from several
/// Python threads (a Dask worker's) still run side by side; dropped with the thread. A forked
/// child has the map but not the pools' threads: it starts afresh (the old pools are leaked,
/// not dropped, since dropping would signal threads that do not exist there).
fn pool(n_threads: usize) -> Result<Arc<rayon::ThreadPool>, GpError> {
    // More threads than cores only share them, and each costs a stack: a huge count once
    // started threads without end.
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let n_threads = n_threads.min(cores);
    POOLS.with(|cell| {
        let mut pools = cell.borrow_mut();
        let pid = std::process::id();
        if pools.0 != pid {
            let inherited = std::mem::replace(&mut *pools, (pid, HashMap::new()));
            std::mem::forget(inherited);
        }
        if let Some(pool) = pools.1.get(&n_threads) {
            return Ok(pool.clone());
        }
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(n_threads)
            .build()
            .map(Arc::new)
            .map_err(|e| GpError::InvalidInput(format!("cannot start {n_threads} threads: {e}")))?;
        pools.1.insert(n_threads, pool.clone());
        Ok(pool)
    })
}

fn run_in_pool<T: Send>(n_threads: usize, f: impl FnOnce() -> T + Send) -> Result<T, GpError> {
    if n_threads == 0 {
        return Ok(f());
    }
    Ok(pool(n_threads)?.install(f))
}

/// A fitted one-vs-all Laplace GPC. Built by `fit_gpc`; opaque to Python except through its
/// methods and read-only properties.
#[pyclass(frozen, module = "aptkt._core")]
pub struct GpcModel {
    model: OneVsAll,
    n_threads: usize,
}

/// Everything that defines a fit except the data: the hyper-parameters' starting values, which
/// of them are free, their bounds, and the optimiser's and Newton iteration's limits. Built
/// with keywords only (`FitSettings(modalities=[[0, 1]], n_restarts=2, ...)`); every field is
/// a readable and writable attribute.
#[pyclass(module = "aptkt._core", get_all, set_all)]
#[derive(Clone)]
pub struct FitSettings {
    /// Feature columns of each modality.
    modalities: Vec<Vec<usize>>,
    /// Initial signal variance σ².
    signal_variance: f64,
    /// Initial length-scale per modality; NaN: scaled to the data (median pairwise distance).
    length_scales: Vec<f64>,
    /// Initial modality weights γ (normalised).
    weights: Vec<f64>,
    free_signal_variance: bool,
    free_length_scales: bool,
    free_weights: bool,
    free_lambda: bool,
    signal_variance_bounds: (f64, f64),
    length_scale_bounds: (f64, f64),
    optimize: bool,
    n_restarts: usize,
    seed: u64,
    max_iter: usize,
    /// The hyper-parameter search stops when the objective's relative decrease falls below it.
    optimizer_tol: f64,
    newton_max_iter: usize,
    newton_tol: f64,
    max_jitter: f64,
    /// Predictive integral: "erf" or "quadrature".
    approximation: String,
    /// Threads for the per-class fits; 0: rayon's default (all cores).
    n_threads: usize,
    /// MAP-II hyper-prior on σ²: (centre, sd of ln σ²); None: flat.
    prior_signal_variance: Option<(f64, f64)>,
    /// MAP-II hyper-prior on each ℓ_m: (centre relative to the modality's data scale, sd of
    /// ln ℓ_m); None: flat.
    prior_length_scale: Option<(f64, f64)>,
    /// MAP-II hyper-prior on each modality-weight logit: sd of a normal centred on 0 (equal
    /// weights); None: flat.
    prior_weight_logit: Option<f64>,
    /// The latent function's constant prior mean: "zero" or "base-rate" (the log-odds of each
    /// classifier's Jeffreys-smoothed share of positive labels).
    latent_mean: String,
}

#[pymethods]
impl FitSettings {
    #[new]
    // No defaults here but those that switch an extension off (the hyper-priors, the latent
    // mean): aptkt.gp.DEFAULTS is the one source of the settings' defaults, and LaplaceGPC
    // passes every one of them.
    #[pyo3(signature = (
        *, modalities, signal_variance, length_scales, weights, free_signal_variance,
        free_length_scales, free_weights, free_lambda, signal_variance_bounds,
        length_scale_bounds, optimize, n_restarts, seed, max_iter, optimizer_tol, newton_max_iter,
        newton_tol, max_jitter, approximation, n_threads, prior_signal_variance = None,
        prior_length_scale = None, prior_weight_logit = None, latent_mean = "zero".to_string()
    ))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        modalities: Vec<Vec<usize>>,
        signal_variance: f64,
        length_scales: Vec<f64>,
        weights: Vec<f64>,
        free_signal_variance: bool,
        free_length_scales: bool,
        free_weights: bool,
        free_lambda: bool,
        signal_variance_bounds: (f64, f64),
        length_scale_bounds: (f64, f64),
        optimize: bool,
        n_restarts: usize,
        seed: u64,
        max_iter: usize,
        optimizer_tol: f64,
        newton_max_iter: usize,
        newton_tol: f64,
        max_jitter: f64,
        approximation: String,
        n_threads: usize,
        prior_signal_variance: Option<(f64, f64)>,
        prior_length_scale: Option<(f64, f64)>,
        prior_weight_logit: Option<f64>,
        latent_mean: String,
    ) -> Self {
        FitSettings {
            modalities,
            signal_variance,
            length_scales,
            weights,
            free_signal_variance,
            free_length_scales,
            free_weights,
            free_lambda,
            signal_variance_bounds,
            length_scale_bounds,
            optimize,
            n_restarts,
            seed,
            max_iter,
            optimizer_tol,
            newton_max_iter,
            newton_tol,
            max_jitter,
            approximation,
            n_threads,
            prior_signal_variance,
            prior_length_scale,
            prior_weight_logit,
            latent_mean,
        }
    }

    fn __repr__(&self) -> String {
        let b = |v: bool| if v { "True" } else { "False" };
        format!(
            "FitSettings(modalities={:?}, signal_variance={:?}, length_scales={:?}, \
             weights={:?}, free_signal_variance={}, free_length_scales={}, free_weights={}, \
             free_lambda={}, signal_variance_bounds={:?}, length_scale_bounds={:?}, \
             optimize={}, n_restarts={}, seed={}, max_iter={}, optimizer_tol={:?}, \
             newton_max_iter={}, newton_tol={:?}, max_jitter={:?}, approximation={:?}, n_threads={}, \
             prior_signal_variance={}, prior_length_scale={}, prior_weight_logit={}, \
             latent_mean={:?})",
            self.modalities,
            self.signal_variance,
            self.length_scales,
            self.weights,
            b(self.free_signal_variance),
            b(self.free_length_scales),
            b(self.free_weights),
            b(self.free_lambda),
            self.signal_variance_bounds,
            self.length_scale_bounds,
            b(self.optimize),
            self.n_restarts,
            self.seed,
            self.max_iter,
            self.optimizer_tol,
            self.newton_max_iter,
            self.newton_tol,
            self.max_jitter,
            self.approximation,
            self.n_threads,
            py_pair(self.prior_signal_variance),
            py_pair(self.prior_length_scale),
            self.prior_weight_logit
                .map_or_else(|| "None".to_string(), |sd| format!("{sd:?}")),
            self.latent_mean
        )
    }
}

fn py_pair(p: Option<(f64, f64)>) -> String {
    match p {
        Some((a, b)) => format!("({a:?}, {b:?})"),
        None => "None".to_string(),
    }
}

impl FitSettings {
    /// The core's model specification for data with `d` columns.
    fn spec(&self, d: usize) -> PyResult<ModelSpec> {
        let mut spec =
            ModelSpec::new(Modalities::new(self.modalities.clone(), d).map_err(gp_error)?);
        spec.signal_variance = self.signal_variance;
        spec.length_scales = self.length_scales.clone();
        spec.weights = self.weights.clone();
        spec.free = Free {
            signal_variance: self.free_signal_variance,
            length_scales: self.free_length_scales,
            weights: self.free_weights,
            lambda: self.free_lambda,
        };
        spec.signal_variance_bounds = self.signal_variance_bounds;
        spec.length_scale_bounds = self.length_scale_bounds;
        spec.optimize = self.optimize;
        spec.n_restarts = self.n_restarts;
        spec.seed = self.seed;
        spec.lbfgs.max_iter = self.max_iter;
        spec.lbfgs.ftol = self.optimizer_tol;
        spec.newton.max_iter = self.newton_max_iter;
        spec.newton.tol = self.newton_tol;
        spec.max_jitter = self.max_jitter;
        spec.predictive = parse_predictive(&self.approximation)?;
        spec.latent_mean = parse_latent_mean(&self.latent_mean)?;
        if self.prior_signal_variance.is_some()
            || self.prior_length_scale.is_some()
            || self.prior_weight_logit.is_some()
        {
            spec.hyper_prior = Some(HyperPrior {
                signal_variance: self.prior_signal_variance,
                length_scale: self.prior_length_scale,
                weight_logit: self.prior_weight_logit,
            });
        }
        Ok(spec)
    }
}

/// One class's source tasks as (X, labels ±1, λ).
type PySources<'py> = Vec<(PyReadonlyArray2<'py, f64>, PyReadonlyArray1<'py, f64>, f64)>;

/// Fits a one-vs-all model: `labels` are class indices in `0..n_classes`, `sources` holds
/// one list of source tasks `(X, y, λ)` per class (empty: no transfer), `settings` everything
/// else. With `thetas` (one row per classifier) the model is built at those hyper-parameters
/// without optimising; `starts` gives per-classifier starting rows (None: the settings').
#[pyfunction]
#[pyo3(signature = (x, labels, n_classes, sources, settings, thetas = None, starts = None))]
#[allow(clippy::too_many_arguments)]
fn fit_gpc(
    py: Python<'_>,
    x: PyReadonlyArray2<'_, f64>,
    labels: PyReadonlyArray1<'_, i64>,
    n_classes: usize,
    sources: Vec<PySources<'_>>,
    settings: PyRef<'_, FitSettings>,
    thetas: Option<PyReadonlyArray2<'_, f64>>,
    starts: Option<Vec<Option<Vec<f64>>>>,
) -> PyResult<GpcModel> {
    let thetas: Option<Vec<Vec<f64>>> =
        thetas.map(|t| t.as_array().outer_iter().map(|r| r.to_vec()).collect());
    let data = data_from(&x).map_err(gp_error)?;
    let labels: Vec<usize> = labels
        .as_array()
        .iter()
        .map(|&v| {
            usize::try_from(v)
                .map_err(|_| PyValueError::new_err(format!("negative label index {v}")))
        })
        .collect::<PyResult<_>>()?;
    let sources: Vec<Vec<Source>> = sources
        .iter()
        .map(|list| {
            list.iter()
                .map(|(sx, sy, lambda)| {
                    Ok(Source {
                        x: data_from(sx)?,
                        y: sy.as_array().to_vec(),
                        lambda: *lambda,
                    })
                })
                .collect::<Result<Vec<_>, GpError>>()
        })
        .collect::<Result<_, GpError>>()
        .map_err(gp_error)?;
    let mut spec = settings.spec(data.d)?;
    let cancel = Arc::new(AtomicBool::new(false));
    spec.newton.cancel = Some(cancel.clone());
    let n_threads = settings.n_threads;
    // The work runs on a thread of the calling thread's pool, so the per-class fits inside it
    // spread over that pool.
    let model = run_interruptible(py, &cancel, n_threads, || match (&thetas, &starts) {
        (Some(t), _) => aptkt_gp::fit_at(&data, &labels, n_classes, &sources, &spec, t),
        (None, Some(s)) => aptkt_gp::fit_from(&data, &labels, n_classes, &sources, &spec, s),
        (None, None) => aptkt_gp::fit(&data, &labels, n_classes, &sources, &spec),
    })?
    .map_err(gp_error)?;
    Ok(GpcModel { model, n_threads })
}

fn parse_predictive(name: &str) -> PyResult<Predictive> {
    match name {
        "erf" => Ok(Predictive::ErfMixture),
        "quadrature" => Ok(Predictive::Quadrature),
        other => Err(PyValueError::new_err(format!(
            "approximation must be 'erf' or 'quadrature', got {other:?}"
        ))),
    }
}

fn parse_latent_mean(name: &str) -> PyResult<LatentMean> {
    match name {
        "zero" => Ok(LatentMean::Zero),
        "base-rate" => Ok(LatentMean::BaseRate),
        other => Err(PyValueError::new_err(format!(
            "latent_mean must be 'zero' or 'base-rate', got {other:?}"
        ))),
    }
}

#[pymethods]
impl GpcModel {
    /// Class probabilities, shape (n, n_classes).
    fn predict_proba<'py>(
        &self,
        py: Python<'py>,
        x: PyReadonlyArray2<'py, f64>,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let data = data_from(&x).map_err(gp_error)?;
        let probs = py
            .detach(|| run_in_pool(self.n_threads, || self.model.predict_proba(&data)))
            .and_then(|r| r)
            .map_err(gp_error)?;
        matrix(py, probs, data.n, self.model.n_classes)
    }

    /// Each one-vs-all classifier's own p(y = +1 | x), shape (n, n_classes), not normalised.
    fn predict_proba_binary<'py>(
        &self,
        py: Python<'py>,
        x: PyReadonlyArray2<'py, f64>,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let data = data_from(&x).map_err(gp_error)?;
        let probs = py
            .detach(|| run_in_pool(self.n_threads, || self.model.predict_binary(&data)))
            .and_then(|r| r)
            .map_err(gp_error)?;
        matrix(py, probs, data.n, self.model.n_classes)
    }

    /// Latent predictive means and variances, each (n, n_classifiers).
    fn latent<'py>(
        &self,
        py: Python<'py>,
        x: PyReadonlyArray2<'py, f64>,
    ) -> PyResult<(Bound<'py, PyArray2<f64>>, Bound<'py, PyArray2<f64>>)> {
        let data = data_from(&x).map_err(gp_error)?;
        let (mean, var) = py
            .detach(|| run_in_pool(self.n_threads, || self.model.latent(&data)))
            .and_then(|r| r)
            .map_err(gp_error)?;
        let k = self.model.classifiers.len();
        Ok((matrix(py, mean, data.n, k)?, matrix(py, var, data.n, k)?))
    }

    /// Log marginal likelihood per classifier at `theta` (n_classifiers, n_params), and its
    /// gradient (n_classifiers, n_params) when asked; with `include_prior`, plus the log
    /// hyper-prior.
    #[pyo3(signature = (theta, gradient, include_prior = false))]
    fn log_marginal_likelihood<'py>(
        &self,
        py: Python<'py>,
        theta: PyReadonlyArray2<'py, f64>,
        gradient: bool,
        include_prior: bool,
    ) -> PyResult<(Bound<'py, PyArray1<f64>>, Option<Bound<'py, PyArray2<f64>>>)> {
        let rows: Vec<Vec<f64>> = theta.as_array().outer_iter().map(|r| r.to_vec()).collect();
        let results = py
            .detach(|| {
                run_in_pool(self.n_threads, || {
                    self.model
                        .log_marginal_likelihood(&rows, gradient, include_prior)
                })
            })
            .and_then(|r| r)
            .map_err(gp_error)?;
        let lml: Vec<f64> = results.iter().map(|(v, _)| *v).collect();
        let grad = if gradient {
            let p = self.model.layout.len();
            let flat: Vec<f64> = results
                .into_iter()
                .flat_map(|(_, g)| g.unwrap_or_default())
                .collect();
            Some(matrix(py, flat, lml.len(), p)?)
        } else {
            None
        };
        Ok((PyArray1::from_vec(py, lml), grad))
    }

    /// Fitted theta, one row per classifier.
    #[getter]
    fn theta<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let k = self.model.classifiers.len();
        let flat: Vec<f64> = self
            .model
            .classifiers
            .iter()
            .flat_map(|c| c.theta.clone())
            .collect();
        matrix(py, flat, k, self.model.layout.len())
    }

    #[getter]
    fn log_marginal_likelihood_value<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_vec(py, self.model.classifiers.iter().map(|c| c.lml).collect())
    }

    /// Each classifier's latent prior mean m (0 for the zero-mean GP).
    #[getter]
    fn latent_offset<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_vec(
            py,
            self.model
                .classifiers
                .iter()
                .map(|c| c.latent_offset)
                .collect(),
        )
    }

    /// Log hyper-prior density at the fitted theta per classifier (0 for ML-II).
    #[getter]
    fn log_hyper_prior<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_vec(
            py,
            self.model.classifiers.iter().map(|c| c.log_prior).collect(),
        )
    }

    #[getter]
    fn jitter<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_vec(
            py,
            self.model.classifiers.iter().map(|c| c.jitter).collect(),
        )
    }

    #[getter]
    fn optimizer_converged(&self) -> Vec<bool> {
        self.model
            .classifiers
            .iter()
            .map(|c| c.optimizer_converged)
            .collect()
    }

    #[getter]
    fn newton_converged(&self) -> Vec<bool> {
        self.model
            .classifiers
            .iter()
            .map(|c| c.newton_converged)
            .collect()
    }

    #[getter]
    fn evaluations(&self) -> Vec<usize> {
        self.model
            .classifiers
            .iter()
            .map(|c| c.evaluations)
            .collect()
    }

    /// Quasi-Newton iterations of the start that gave each classifier's theta.
    #[getter]
    fn iterations(&self) -> Vec<usize> {
        self.model
            .classifiers
            .iter()
            .map(|c| c.iterations)
            .collect()
    }

    #[getter]
    fn n_classifiers(&self) -> usize {
        self.model.classifiers.len()
    }

    #[getter]
    fn transfer(&self) -> bool {
        self.model.layout.transfer()
    }

    /// λ entries per theta row (the most sources any class has).
    #[getter]
    fn n_lambdas(&self) -> usize {
        self.model.layout.n_lambdas
    }
}

/// The (dependent) multi-modal kernel matrix of `x` at `theta`; the first rows form source
/// tasks of `source_sizes` rows each, the rest the target task.
#[pyfunction]
#[pyo3(signature = (x, theta, modalities, source_sizes = Vec::new()))]
fn kernel_matrix<'py>(
    py: Python<'py>,
    x: PyReadonlyArray2<'py, f64>,
    theta: Vec<f64>,
    modalities: Vec<Vec<usize>>,
    source_sizes: Vec<usize>,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let data = data_from(&x).map_err(gp_error)?;
    data.check_finite("X").map_err(gp_error)?;
    let n_source: usize = source_sizes.iter().sum();
    if n_source > data.n {
        return Err(PyValueError::new_err(format!(
            "the source tasks' {n_source} rows exceed the {} rows of X",
            data.n
        )));
    }
    if source_sizes.contains(&0) {
        return Err(PyValueError::new_err(
            "every source task needs at least one row",
        ));
    }
    let mods = Modalities::new(modalities, data.d).map_err(gp_error)?;
    // The distances per modality, the kernel, and its copy handed to numpy.
    let n_big = data.n as u128;
    aptkt_gp::memory::check(
        &format!("a kernel matrix of {} rows", data.n),
        data.n,
        n_big * n_big * 8 * (mods.len() as u128 + 2),
        aptkt_gp::memory::available_bytes(),
        "; compute it on fewer rows",
    )
    .map_err(gp_error)?;
    let layout = Layout {
        n_modalities: mods.len(),
        n_lambdas: source_sizes.len(),
    };
    let h = layout.decode(&theta).map_err(gp_error)?;
    let n = data.n;
    let k = py.detach(|| {
        let dist = PairDistances::new(
            &data,
            &source_sizes,
            &mods,
            &aptkt_gp::kernel::column_means(&data),
        );
        let ev = KernelEval::new(&dist, &h);
        let mut flat = Vec::with_capacity(n * n);
        for i in 0..n {
            for j in 0..n {
                flat.push(ev.k[(i, j)]);
            }
        }
        flat
    });
    matrix(py, k, n, n)
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<FitSettings>()?;
    m.add_class::<GpcModel>()?;
    m.add_function(wrap_pyfunction!(fit_gpc, m)?)?;
    m.add_function(wrap_pyfunction!(kernel_matrix, m)?)?;
    Ok(())
}
