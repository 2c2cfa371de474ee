//! Bindings of the Laplace GPC core (`aptkt-gp`). Argument checking that needs Python
//! knowledge (labels, defaults, names) lives in `aptkt.gp`; this layer converts arrays,
//! releases the GIL and maps errors.

use aptkt_gp::kernel::{KernelEval, PairDistances};
use aptkt_gp::{Data, Free, GpError, Layout, Modalities, ModelSpec, OneVsAll, Predictive, Source};
use numpy::{PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

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

fn run_in_pool<T: Send>(n_threads: usize, f: impl FnOnce() -> T + Send) -> Result<T, GpError> {
    if n_threads == 0 {
        return Ok(f());
    }
    rayon::ThreadPoolBuilder::new()
        .num_threads(n_threads)
        .build()
        .map(|pool| pool.install(f))
        .map_err(|e| GpError::InvalidInput(format!("cannot start {n_threads} threads: {e}")))
}

/// A fitted one-vs-all Laplace GPC. Built by `fit_gpc`; opaque to Python except through its
/// methods and read-only properties.
#[pyclass(frozen, module = "aptkt._core")]
pub struct GpcModel {
    model: OneVsAll,
    n_threads: usize,
}

#[pyfunction]
#[pyo3(signature = (
    x, labels, n_classes, sources, modalities, signal_variance, length_scales, weights,
    free, signal_variance_bounds, length_scale_bounds, optimize, n_restarts, seed, max_iter,
    newton_max_iter, newton_tol, max_jitter, predictive, n_threads, thetas = None
))]
#[allow(clippy::too_many_arguments)]
fn fit_gpc(
    py: Python<'_>,
    x: PyReadonlyArray2<'_, f64>,
    labels: PyReadonlyArray1<'_, i64>,
    n_classes: usize,
    sources: Vec<Option<(PyReadonlyArray2<'_, f64>, f64)>>,
    modalities: Vec<Vec<usize>>,
    signal_variance: f64,
    length_scales: Vec<f64>,
    weights: Vec<f64>,
    free: (bool, bool, bool, bool),
    signal_variance_bounds: (f64, f64),
    length_scale_bounds: (f64, f64),
    optimize: bool,
    n_restarts: usize,
    seed: u64,
    max_iter: usize,
    newton_max_iter: usize,
    newton_tol: f64,
    max_jitter: f64,
    predictive: &str,
    n_threads: usize,
    thetas: Option<PyReadonlyArray2<'_, f64>>,
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
    let sources: Vec<Option<Source>> = sources
        .iter()
        .map(|s| match s {
            Some((sx, lambda)) => Ok(Some(Source {
                x: data_from(sx)?,
                lambda: *lambda,
            })),
            None => Ok(None),
        })
        .collect::<Result<_, GpError>>()
        .map_err(gp_error)?;
    let mut spec = ModelSpec::new(Modalities::new(modalities, data.d).map_err(gp_error)?);
    spec.signal_variance = signal_variance;
    spec.length_scales = length_scales;
    spec.weights = weights;
    spec.free = Free {
        signal_variance: free.0,
        length_scales: free.1,
        weights: free.2,
        lambda: free.3,
    };
    spec.signal_variance_bounds = signal_variance_bounds;
    spec.length_scale_bounds = length_scale_bounds;
    spec.optimize = optimize;
    spec.n_restarts = n_restarts;
    spec.seed = seed;
    spec.lbfgs.max_iter = max_iter;
    spec.newton.max_iter = newton_max_iter;
    spec.newton.tol = newton_tol;
    spec.max_jitter = max_jitter;
    spec.predictive = parse_predictive(predictive)?;
    let model = py
        .detach(|| {
            run_in_pool(n_threads, || match &thetas {
                Some(t) => aptkt_gp::fit_at(&data, &labels, n_classes, &sources, &spec, t),
                None => aptkt_gp::fit(&data, &labels, n_classes, &sources, &spec),
            })
        })
        .and_then(|r| r)
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
    /// gradient (n_classifiers, n_params) when asked.
    fn log_marginal_likelihood<'py>(
        &self,
        py: Python<'py>,
        theta: PyReadonlyArray2<'py, f64>,
        gradient: bool,
    ) -> PyResult<(Bound<'py, PyArray1<f64>>, Option<Bound<'py, PyArray2<f64>>>)> {
        let rows: Vec<Vec<f64>> = theta.as_array().outer_iter().map(|r| r.to_vec()).collect();
        let results = py
            .detach(|| {
                run_in_pool(self.n_threads, || {
                    self.model.log_marginal_likelihood(&rows, gradient)
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

    #[getter]
    fn n_classifiers(&self) -> usize {
        self.model.classifiers.len()
    }

    #[getter]
    fn transfer(&self) -> bool {
        self.model.layout.transfer
    }
}

/// The (dependent) multi-modal kernel matrix of `x` at `theta`; rows before `n_source` form
/// the source block.
#[pyfunction]
#[pyo3(signature = (x, theta, modalities, n_source = 0))]
fn kernel_matrix<'py>(
    py: Python<'py>,
    x: PyReadonlyArray2<'py, f64>,
    theta: Vec<f64>,
    modalities: Vec<Vec<usize>>,
    n_source: usize,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let data = data_from(&x).map_err(gp_error)?;
    data.check_finite("X").map_err(gp_error)?;
    if n_source > data.n {
        return Err(PyValueError::new_err(format!(
            "n_source = {n_source} exceeds the {} rows of X",
            data.n
        )));
    }
    let mods = Modalities::new(modalities, data.d).map_err(gp_error)?;
    let layout = Layout {
        n_modalities: mods.len(),
        transfer: n_source > 0,
    };
    let h = layout.decode(&theta).map_err(gp_error)?;
    let n = data.n;
    let k = py.detach(|| {
        let dist = PairDistances::new(
            &data,
            n_source,
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
    m.add_class::<GpcModel>()?;
    m.add_function(wrap_pyfunction!(fit_gpc, m)?)?;
    m.add_function(wrap_pyfunction!(kernel_matrix, m)?)?;
    Ok(())
}
