//! Bindings of the Laplace GPC core (`aptkt-gp`). Argument checking that needs Python
//! knowledge (labels, defaults, names) lives in `aptkt.gp`; this layer converts arrays,
//! releases the GIL and maps errors.

use aptkt_gp::kernel::{KernelEval, PairDistances};
use aptkt_gp::{
    BinaryFit, Data, GpError, GpResult, KernelTask, Layout, Modalities, OneVsAll, Source,
};
use numpy::{PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::prelude::*;
use std::cell::RefCell;
use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::time::Duration;

use crate::errors::{internal, invalid_input, Result};

mod settings;

use settings::FitSettings;

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
) -> Result<Bound<'py, PyArray2<f64>>> {
    PyArray1::from_vec(py, values)
        .reshape([rows, cols])
        .map_err(|e| internal(format!("a result's shape: {e}")))
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
) -> Result<T> {
    let done: Done<T> = (Mutex::new(None), Condvar::new());
    if n_threads == 0 {
        rayon::in_place_scope(|scope| spawn_and_poll(scope, py, cancel, &done, work))?;
    } else {
        let pool = pool(n_threads)?;
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
            Err(internal(format!("the fit's thread panicked: {why}")))
        }
        None => Err(internal("the fit's thread ended without a result")),
    }
}

fn spawn_and_poll<'scope, T: Send + 'scope>(
    scope: &rayon::Scope<'scope>,
    py: Python<'_>,
    cancel: &AtomicBool,
    done: &'scope Done<T>,
    work: impl FnOnce() -> T + Send + 'scope,
) -> Result<()> {
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
            return Err(e.into());
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

/// One class's source tasks as (X, labels ±1, λ).
type PySources<'py> = Vec<(PyReadonlyArray2<'py, f64>, PyReadonlyArray1<'py, f64>, f64)>;

/// Fits a one-vs-all model: `labels` are class indices in `0..n_classes`, `sources` holds
/// one list of source tasks `(X, y, λ)` per class (empty: no transfer), `settings` everything
/// else. With `thetas` (one row per classifier) the model is built at those hyper-parameters
/// without optimising; `starts` gives per-classifier starting rows (None: the settings').
#[pyfunction]
#[pyo3(signature = (x, labels, n_classes, sources, settings, thetas = None, starts = None))]
fn fit_gpc(
    x: PyReadonlyArray2<'_, f64>,
    labels: PyReadonlyArray1<'_, i64>,
    n_classes: usize,
    sources: Vec<PySources<'_>>,
    settings: PyRef<'_, FitSettings>,
    thetas: Option<PyReadonlyArray2<'_, f64>>,
    starts: Option<Vec<Option<Vec<f64>>>>,
) -> Result<GpcModel> {
    let py = x.py();
    let thetas: Option<Vec<Vec<f64>>> =
        thetas.map(|t| t.as_array().outer_iter().map(|r| r.to_vec()).collect());
    let data = data_from(&x)?;
    let labels = class_indices(&labels)?;
    let sources = sources_from(&sources)?;
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
    })??;
    Ok(GpcModel { model, n_threads })
}

/// One kernel task as handed over from Python: rows, class indices, the number of classes and
/// one list of source tasks per class.
type PyKernelTask<'py> = (
    PyReadonlyArray2<'py, f64>,
    PyReadonlyArray1<'py, i64>,
    usize,
    Vec<PySources<'py>>,
);

fn class_indices(labels: &PyReadonlyArray1<'_, i64>) -> Result<Vec<usize>> {
    labels
        .as_array()
        .iter()
        .map(|&v| {
            usize::try_from(v).map_err(|_| invalid_input(format!("negative label index {v}")))
        })
        .collect()
}

fn sources_from(sources: &[PySources<'_>]) -> Result<Vec<Vec<Source>>, GpError> {
    sources
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
        .collect()
}

/// Fits one kernel shared by every one-vs-all classifier of every task (`(X, labels,
/// n_classes, sources)`, as for `fit_gpc`) and returns the model of `tasks[target]` at it.
#[pyfunction]
fn fit_gpc_shared(
    py: Python<'_>,
    tasks: Vec<PyKernelTask<'_>>,
    target: usize,
    settings: PyRef<'_, FitSettings>,
) -> Result<GpcModel> {
    let mut owned = Vec::with_capacity(tasks.len());
    for (x, labels, n_classes, sources) in &tasks {
        let data = data_from(x)?;
        let sources = sources_from(sources)?;
        owned.push((data, class_indices(labels)?, *n_classes, sources));
    }
    let d = owned.get(target).map_or(0, |t| t.0.d);
    let mut spec = settings.spec(d)?;
    let cancel = Arc::new(AtomicBool::new(false));
    spec.newton.cancel = Some(cancel.clone());
    let n_threads = settings.n_threads;
    let model = run_interruptible(py, &cancel, n_threads, || {
        let tasks: Vec<KernelTask<'_>> = owned
            .iter()
            .map(|(x, labels, n_classes, sources)| KernelTask {
                x,
                labels,
                n_classes: *n_classes,
                sources,
            })
            .collect();
        aptkt_gp::fit_shared(&tasks, target, &spec)
    })??;
    Ok(GpcModel { model, n_threads })
}

impl GpcModel {
    /// `predict(model, x)` (n × n_classes, row-major) on this model's pool, the GIL released.
    fn per_class<'py>(
        &self,
        py: Python<'py>,
        x: &PyReadonlyArray2<'py, f64>,
        predict: fn(&OneVsAll, &Data) -> GpResult<Vec<f64>>,
    ) -> Result<Bound<'py, PyArray2<f64>>> {
        let data = data_from(x)?;
        let probs = py
            .detach(|| run_in_pool(self.n_threads, || predict(&self.model, &data)))
            .and_then(|r| r)?;
        matrix(py, probs, data.n, self.model.n_classes)
    }

    /// One value per classifier.
    fn each<T>(&self, value: impl Fn(&BinaryFit) -> T) -> Vec<T> {
        self.model.classifiers.iter().map(value).collect()
    }
}

#[pymethods]
impl GpcModel {
    /// Class probabilities, shape (n, n_classes).
    fn predict_proba<'py>(
        &self,
        py: Python<'py>,
        x: PyReadonlyArray2<'py, f64>,
    ) -> Result<Bound<'py, PyArray2<f64>>> {
        self.per_class(py, &x, OneVsAll::predict_proba)
    }

    /// Each one-vs-all classifier's own p(y = +1 | x), shape (n, n_classes), not normalised.
    fn predict_proba_binary<'py>(
        &self,
        py: Python<'py>,
        x: PyReadonlyArray2<'py, f64>,
    ) -> Result<Bound<'py, PyArray2<f64>>> {
        self.per_class(py, &x, OneVsAll::predict_binary)
    }

    /// Latent predictive means and variances, each (n, n_classifiers).
    fn latent<'py>(
        &self,
        py: Python<'py>,
        x: PyReadonlyArray2<'py, f64>,
    ) -> Result<(Bound<'py, PyArray2<f64>>, Bound<'py, PyArray2<f64>>)> {
        let data = data_from(&x)?;
        let (mean, var) = py
            .detach(|| run_in_pool(self.n_threads, || self.model.latent(&data)))
            .and_then(|r| r)?;
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
    ) -> Result<(Bound<'py, PyArray1<f64>>, Option<Bound<'py, PyArray2<f64>>>)> {
        let rows: Vec<Vec<f64>> = theta.as_array().outer_iter().map(|r| r.to_vec()).collect();
        let results = py
            .detach(|| {
                run_in_pool(self.n_threads, || {
                    self.model
                        .log_marginal_likelihood(&rows, gradient, include_prior)
                })
            })
            .and_then(|r| r)?;
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
    fn theta<'py>(&self, py: Python<'py>) -> Result<Bound<'py, PyArray2<f64>>> {
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
        PyArray1::from_vec(py, self.each(|c| c.lml))
    }

    /// Each classifier's latent prior mean m (0 for the zero-mean GP).
    #[getter]
    fn latent_offset<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_vec(py, self.each(|c| c.latent_offset))
    }

    /// Log hyper-prior density at the fitted theta per classifier (0 for ML-II).
    #[getter]
    fn log_hyper_prior<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_vec(py, self.each(|c| c.log_prior))
    }

    #[getter]
    fn jitter<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_vec(py, self.each(|c| c.jitter))
    }

    #[getter]
    fn optimizer_converged(&self) -> Vec<bool> {
        self.each(|c| c.optimizer_converged)
    }

    #[getter]
    fn newton_converged(&self) -> Vec<bool> {
        self.each(|c| c.newton_converged)
    }

    #[getter]
    fn evaluations(&self) -> Vec<usize> {
        self.each(|c| c.evaluations)
    }

    /// Quasi-Newton iterations of the start that gave each classifier's theta.
    #[getter]
    fn iterations(&self) -> Vec<usize> {
        self.each(|c| c.iterations)
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
) -> Result<Bound<'py, PyArray2<f64>>> {
    let data = data_from(&x)?;
    data.check_finite("X")?;
    let n_source: usize = source_sizes.iter().sum();
    if n_source > data.n {
        return Err(invalid_input(format!(
            "the source tasks' {n_source} rows exceed the {} rows of X",
            data.n
        )));
    }
    if source_sizes.contains(&0) {
        return Err(invalid_input("every source task needs at least one row"));
    }
    let mods = Modalities::new(modalities, data.d)?;
    // The distances per modality, the kernel, and its copy handed to numpy.
    let n_big = data.n as u128;
    aptkt_gp::memory::check(
        &format!("a kernel matrix of {} rows", data.n),
        data.n,
        n_big * n_big * 8 * (mods.len() as u128 + 2),
        aptkt_gp::memory::available_bytes(),
        "; compute it on fewer rows",
    )?;
    let layout = Layout {
        n_modalities: mods.len(),
        n_lambdas: source_sizes.len(),
    };
    let h = layout.decode(&theta)?;
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

/// Bytes this process may still allocate (the system's available memory, or a control
/// group's limit), as the fits' own checks read it; None where it cannot be read.
#[pyfunction]
fn available_memory() -> Option<u64> {
    aptkt_gp::memory::available_bytes()
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    settings::register(m)?;
    m.add_function(wrap_pyfunction!(available_memory, m)?)?;
    m.add_class::<GpcModel>()?;
    m.add_function(wrap_pyfunction!(fit_gpc, m)?)?;
    m.add_function(wrap_pyfunction!(fit_gpc_shared, m)?)?;
    m.add_function(wrap_pyfunction!(kernel_matrix, m)?)?;
    Ok(())
}
