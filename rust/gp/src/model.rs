//! One-vs-all multi-class Laplace GPC: per-class binary classifiers with their own
//! hyper-parameters (and, for transfer, their own source task), fitted in parallel.

use std::sync::{Arc, OnceLock};

use faer::Mat;
use rayon::prelude::*;

use crate::error::{GpError, GpResult};
use crate::fastmath::exp_nonpositive_in_place;
use crate::kernel::{
    column_means, row_tasks, Coupling, Data, Hyper, KernelEval, Layout, Modalities, PairDistances,
};
use crate::laplace::{find_mode_with_jitter, lml_gradient_in, Jitter, Mode, NewtonConfig};
use crate::likelihood::{predictive_probability, Predictive};
use crate::linalg;
use crate::linalg::InverseScratch;
use crate::memory;
use crate::optimize::{minimize, LbfgsConfig, OptResult};
use crate::rng::SplitMix64;

/// Which hyper-parameter groups the optimiser may change.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Free {
    pub signal_variance: bool,
    pub length_scales: bool,
    pub weights: bool,
    pub lambda: bool,
}

impl Default for Free {
    fn default() -> Self {
        Free {
            signal_variance: true,
            length_scales: true,
            weights: true,
            lambda: false,
        }
    }
}

/// Weak hyper-priors for MAP-II: independent normal densities on log σ² and on each modality's
/// log ℓ_m (log-normal priors on σ² and ℓ_m). The optimiser then maximises
/// `log p(y | θ) + log p(θ)`; the reported log marginal likelihood stays `log p(y | θ)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HyperPrior {
    /// Centre (natural scale) and standard deviation of ln σ²; None: flat.
    pub signal_variance: Option<(f64, f64)>,
    /// Centre relative to each modality's data scale (the median pairwise distance of the
    /// target rows) and standard deviation of ln ℓ_m; None: flat.
    pub length_scale: Option<(f64, f64)>,
    /// Standard deviation of each modality-weight logit η_m (γ = softmax(η)), centred on 0:
    /// equal weights, each logit pinned so that the softmax's redundant direction is
    /// determined. None: flat. Ignored with a single modality (no weights).
    pub weight_logit: Option<f64>,
}

/// The constant prior mean `m` of each binary classifier's latent function, `f ~ GP(m, K)`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum LatentMean {
    /// `m = 0`: far from its training rows a classifier returns ½ whatever its labels.
    #[default]
    Zero,
    /// `m = logit ρ̃`, the log-odds of the classifier's share of positive labels over all its
    /// rows (source tasks' included) under the Jeffreys prior, `ρ̃ = (n₊ + ½) / (n + 1)`: far
    /// from its data a classifier returns the rate it was trained at, so that its probability
    /// carries that base rate everywhere, not only near its rows.
    BaseRate,
}

impl LatentMean {
    /// `m` for a classifier with ±1 labels `y`; for the base rate `logit ρ̃ = ln((n₊ + ½) /
    /// (n₋ + ½))`, finite for any counts (all one label included).
    pub fn offset(self, y: &[f64]) -> f64 {
        match self {
            LatentMean::Zero => 0.0,
            LatentMean::BaseRate => {
                let positives = y.iter().filter(|&&v| v > 0.0).count() as f64;
                let negatives = y.len() as f64 - positives;
                ((positives + 0.5) / (negatives + 0.5)).ln()
            }
        }
    }
}

/// One normal term of the log hyper-prior: theta index, mean and standard deviation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PriorTerm {
    pub index: usize,
    pub mean: f64,
    pub sd: f64,
}

/// `Σ log N(θ_i | mean, sd²)` and its gradient with respect to theta.
pub fn log_prior(terms: &[PriorTerm], theta: &[f64]) -> (f64, Vec<f64>) {
    let mut grad = vec![0.0; theta.len()];
    let mut value = 0.0;
    for t in terms {
        let z = (theta[t.index] - t.mean) / t.sd;
        value += -0.5 * z * z - t.sd.ln() - 0.5 * (2.0 * std::f64::consts::PI).ln();
        grad[t.index] += -z / t.sd;
    }
    (value, grad)
}

/// The most optimiser starts a fit may add to the first ([`ModelSpec::n_restarts`]): each is a
/// whole optimisation, and the starting points are held in memory together.
pub const MAX_RESTARTS: usize = 1000;

/// Everything that defines a model except the data.
#[derive(Debug, Clone)]
pub struct ModelSpec {
    pub modalities: Modalities,
    pub signal_variance: f64,
    /// One per modality; NaN means "scaled to the data" (median pairwise distance).
    pub length_scales: Vec<f64>,
    /// Modality weights γ (normalised internally).
    pub weights: Vec<f64>,
    pub free: Free,
    pub signal_variance_bounds: (f64, f64),
    pub length_scale_bounds: (f64, f64),
    pub optimize: bool,
    /// Additional starts after the initial hyper-parameters: the first is scaled to the data,
    /// the others random around the data scale.
    pub n_restarts: usize,
    pub seed: u64,
    pub lbfgs: LbfgsConfig,
    pub newton: NewtonConfig,
    /// Largest diagonal jitter, relative to the signal variance, before giving up.
    pub max_jitter: f64,
    pub predictive: Predictive,
    /// None: plain ML-II.
    pub hyper_prior: Option<HyperPrior>,
    pub latent_mean: LatentMean,
    /// One length-scale for every modality (the shared kernel of [`crate::fit_shared`] only):
    /// in a space where a unit means the same in every modality, how far apart two
    /// observations may lie and still be alike is one number.
    pub tie_length_scales: bool,
}

impl ModelSpec {
    pub fn new(modalities: Modalities) -> Self {
        let m = modalities.len();
        ModelSpec {
            modalities,
            signal_variance: 1.0,
            length_scales: vec![1.0; m],
            weights: vec![1.0 / m as f64; m],
            free: Free::default(),
            signal_variance_bounds: (1e-5, 1e5),
            length_scale_bounds: (1e-5, 1e5),
            optimize: true,
            n_restarts: 2,
            seed: 0,
            lbfgs: LbfgsConfig::default(),
            newton: NewtonConfig::default(),
            max_jitter: 1e-6,
            predictive: Predictive::ErfMixture,
            hyper_prior: None,
            latent_mean: LatentMean::Zero,
            tie_length_scales: false,
        }
    }

    pub(crate) fn validate(&self) -> GpResult<()> {
        let m = self.modalities.len();
        if self.length_scales.len() != m || self.weights.len() != m {
            return Err(GpError::InvalidInput(format!(
                "{m} modalities need {m} length-scales and {m} weights, got {} and {}",
                self.length_scales.len(),
                self.weights.len()
            )));
        }
        let positive = |v: f64| v.is_finite() && v > 0.0;
        if !positive(self.signal_variance) {
            return Err(GpError::InvalidInput(format!(
                "signal_variance must be > 0, got {}",
                self.signal_variance
            )));
        }
        if let Some(l) = self
            .length_scales
            .iter()
            .find(|l| !(l.is_nan() || positive(**l)))
        {
            return Err(GpError::InvalidInput(format!(
                "length-scales must be > 0, got {l}"
            )));
        }
        if self.weights.iter().any(|w| !w.is_finite() || *w < 0.0)
            || self.weights.iter().sum::<f64>() <= 0.0
        {
            return Err(GpError::InvalidInput(format!(
                "modality weights must be >= 0 with a positive sum, got {:?}",
                self.weights
            )));
        }
        if self.n_restarts > MAX_RESTARTS {
            return Err(GpError::InvalidInput(format!(
                "n_restarts must be at most {MAX_RESTARTS}, got {}",
                self.n_restarts
            )));
        }
        // NaN or a negative tolerance would never be met, and infinity always: a search
        // without end, or none.
        if !(self.newton.tol.is_finite() && self.newton.tol >= 0.0) {
            return Err(GpError::InvalidInput(format!(
                "newton_tol must be a finite number >= 0, got {}",
                self.newton.tol
            )));
        }
        if !(self.lbfgs.ftol.is_finite() && self.lbfgs.ftol >= 0.0) {
            return Err(GpError::InvalidInput(format!(
                "the optimiser's tolerance must be a finite number >= 0, got {}",
                self.lbfgs.ftol
            )));
        }
        for (name, (lo, hi)) in [
            ("signal_variance", self.signal_variance_bounds),
            ("length_scale", self.length_scale_bounds),
        ] {
            if !(positive(lo) && positive(hi) && lo < hi) {
                return Err(GpError::InvalidInput(format!(
                    "{name} bounds must satisfy 0 < low < high, got ({lo}, {hi})"
                )));
            }
        }
        if let Some(prior) = &self.hyper_prior {
            for (name, term) in [
                ("signal variance", prior.signal_variance),
                ("length-scale", prior.length_scale),
            ] {
                if let Some((centre, sd)) = term {
                    if !(positive(centre) && positive(sd)) {
                        return Err(GpError::InvalidInput(format!(
                            "the {name} hyper-prior needs a centre > 0 and a width > 0, got ({centre}, {sd})"
                        )));
                    }
                }
            }
            if let Some(sd) = prior.weight_logit {
                if !positive(sd) {
                    return Err(GpError::InvalidInput(format!(
                        "the modality-weight hyper-prior needs a width > 0, got {sd}"
                    )));
                }
            }
        }
        if !(self.max_jitter >= 0.0 && self.max_jitter.is_finite()) {
            return Err(GpError::InvalidInput(format!(
                "max_jitter must be >= 0, got {}",
                self.max_jitter
            )));
        }
        Ok(())
    }
}

/// A source task transferred into one class's binary classifier: its observations with ±1
/// labels (all +1 for positives-only) and its relatedness λ to the target task.
#[derive(Debug, Clone)]
pub struct Source {
    pub x: Data,
    pub y: Vec<f64>,
    pub lambda: f64,
}

impl Source {
    /// Every observation labelled +1 (the old object's own observations only).
    pub fn positives(x: Data, lambda: f64) -> Self {
        let y = vec![1.0; x.n];
        Source { x, y, lambda }
    }
}

/// A fitted binary classifier: the training rows (source first), the hyper-parameters and the
/// quantities Algorithm 3.2 needs.
pub struct BinaryFit {
    pub x: Data,
    pub y: Vec<f64>,
    pub n_source: usize,
    pub source_sizes: Vec<usize>,
    pub theta: Vec<f64>,
    pub hyper: Hyper,
    pub lml: f64,
    /// The hyper-prior's terms (empty for ML-II) and its log density at `theta`.
    pub prior: Vec<PriorTerm>,
    pub log_prior: f64,
    pub jitter: f64,
    /// The latent function's constant prior mean m (0 for [`LatentMean::Zero`]).
    pub latent_offset: f64,
    /// ∇ log p(y | f̂) = t - π̂.
    grad_log_lik: Vec<f64>,
    sw: Vec<f64>,
    l: Mat<f64>,
    pub newton_converged: bool,
    pub optimizer_converged: bool,
    pub evaluations: usize,
    /// Quasi-Newton iterations of the start that gave `theta` (0 without optimisation).
    pub iterations: usize,
}

/// The n × n buffers one optimiser start reuses from one evaluation to the next: the kernel
/// (and its per-modality parts), B's factor and the inverse with its scratch. Without them each
/// evaluation would allocate five n × n matrices afresh (page faults and zeroing: ~10 % of a fit
/// at n = 1,000).
#[derive(Default)]
pub(crate) struct Workspace {
    eval: Option<KernelEval>,
    factor: Option<Mat<f64>>,
    inverse: InverseScratch,
}

impl Workspace {
    pub(crate) fn recycle(&mut self, eval: KernelEval, factor: Mat<f64>) {
        self.eval = Some(eval);
        self.factor = Some(factor);
    }
}

pub(crate) struct BinaryProblem {
    x: Data,
    y: Vec<f64>,
    /// The latent prior mean m.
    offset: f64,
    /// Shared by every classifier without sources (their rows are the same target rows).
    dist: Arc<PairDistances>,
}

impl BinaryProblem {
    /// The training rows of one binary classifier: every source task's rows in order, then the
    /// target rows labelled +1 for class `positive` and -1 otherwise.
    pub(crate) fn new(
        target: &Data,
        labels: &[usize],
        positive: usize,
        sources: &[Source],
        spec: &ModelSpec,
        center: &[f64],
        target_dist: &OnceLock<Arc<PairDistances>>,
    ) -> Self {
        let modalities = &spec.modalities;
        let mut y: Vec<f64> = sources.iter().flat_map(|s| s.y.iter().copied()).collect();
        y.extend(
            labels
                .iter()
                .map(|&c| if c == positive { 1.0 } else { -1.0 }),
        );
        let x = if sources.is_empty() {
            target.clone()
        } else {
            let mut values = Vec::with_capacity(y.len() * target.d);
            for s in sources {
                values.extend_from_slice(&s.x.values);
            }
            values.extend_from_slice(&target.values);
            Data {
                values,
                n: y.len(),
                d: target.d,
            }
        };
        let dist = if sources.is_empty() {
            target_dist
                .get_or_init(|| Arc::new(PairDistances::new(target, &[], modalities, center)))
                .clone()
        } else {
            let sizes: Vec<usize> = sources.iter().map(|s| s.x.n).collect();
            Arc::new(PairDistances::new(&x, &sizes, modalities, center))
        };
        let offset = spec.latent_mean.offset(&y);
        BinaryProblem { x, y, offset, dist }
    }

    /// The hyper-prior's terms: centred on σ² = the given centre and on each modality's data
    /// scale (median pairwise distance of the target rows) times the given factor.
    /// The median pairwise distance of the target rows in modality `m` (the data scale).
    pub(crate) fn dist_median(&self, m: usize) -> f64 {
        self.dist.median_distance(m)
    }

    pub(crate) fn prior_terms(&self, layout: &Layout, spec: &ModelSpec) -> Vec<PriorTerm> {
        let Some(prior) = spec.hyper_prior else {
            return Vec::new();
        };
        let mut terms = Vec::new();
        if let Some((centre, sd)) = prior.signal_variance {
            terms.push(PriorTerm {
                index: Layout::SIGNAL,
                mean: centre.ln(),
                sd,
            });
        }
        if let Some((factor, sd)) = prior.length_scale {
            for m in 0..layout.n_modalities {
                terms.push(PriorTerm {
                    index: layout.length_scale(m),
                    mean: (factor * self.dist.median_distance(m)).ln(),
                    sd,
                });
            }
        }
        if let Some(sd) = prior.weight_logit {
            for m in 0..layout.n_modalities {
                if let Some(index) = layout.weight(m) {
                    terms.push(PriorTerm {
                        index,
                        mean: 0.0,
                        sd,
                    });
                }
            }
        }
        terms
    }

    /// The mode and (optionally) the LML gradient at `theta`, in buffers drawn from `ws`
    /// (hand them back with [`Workspace::recycle`]).
    pub(crate) fn evaluate(
        &self,
        layout: &Layout,
        spec: &ModelSpec,
        theta: &[f64],
        warm: Option<&[f64]>,
        gradient: bool,
        ws: &mut Workspace,
    ) -> GpResult<(KernelEval, Mode, Hyper, Option<Vec<f64>>)> {
        let h = layout.decode(theta)?;
        let ev = match ws.eval.take() {
            Some(mut ev) => {
                ev.recompute(&self.dist, &h);
                ev
            }
            None => KernelEval::new(&self.dist, &h),
        };
        let jitter = Jitter {
            max: spec.max_jitter,
            signal_variance: h.signal_variance,
        };
        let (ev, mode) = find_mode_with_jitter(
            ev,
            &self.y,
            self.offset,
            warm,
            &spec.newton,
            jitter,
            ws.factor.take().unwrap_or_else(|| Mat::zeros(0, 0)),
        )?;
        let grad =
            gradient.then(|| lml_gradient_in(layout, &h, &self.dist, &ev, &mode, &mut ws.inverse));
        Ok((ev, mode, h, grad))
    }

    fn finish(
        self,
        layout: &Layout,
        spec: &ModelSpec,
        theta: Vec<f64>,
        prior: Vec<PriorTerm>,
        search: Search,
    ) -> GpResult<BinaryFit> {
        let (ev, mode, hyper, _) =
            self.evaluate(layout, spec, &theta, None, false, &mut Workspace::default())?;
        let log_prior = log_prior(&prior, &theta).0;
        let grad_log_lik: Vec<f64> = (0..self.y.len())
            .map(|i| 0.5 * (self.y[i] + 1.0) - mode.pi[i])
            .collect();
        Ok(BinaryFit {
            x: self.x,
            y: self.y,
            n_source: self.dist.n_source,
            source_sizes: self.dist.source_sizes.clone(),
            theta,
            hyper,
            lml: mode.lml,
            prior,
            log_prior,
            jitter: ev.jitter,
            latent_offset: self.offset,
            grad_log_lik,
            sw: mode.sw,
            l: mode.l,
            newton_converged: mode.converged,
            optimizer_converged: search.converged,
            evaluations: search.evaluations,
            iterations: search.iterations,
        })
    }
}

/// How the hyper-parameter search that found a classifier's theta went.
#[derive(Clone, Copy, Debug)]
struct Search {
    converged: bool,
    /// Objective evaluations over every start.
    evaluations: usize,
    /// Iterations of the start that gave theta.
    iterations: usize,
}

impl Search {
    /// Theta given, or nothing free to optimise: one evaluation, no iteration.
    const NOT_OPTIMISED: Search = Search {
        converged: true,
        evaluations: 1,
        iterations: 0,
    };
}

/// Per-entry bounds and free flags of theta.
pub(crate) fn theta_box(
    layout: &Layout,
    spec: &ModelSpec,
    n_sources: usize,
) -> (Vec<f64>, Vec<f64>, Vec<bool>) {
    let n = layout.len();
    let (mut lo, mut hi, mut free) = (vec![0.0; n], vec![0.0; n], vec![false; n]);
    lo[0] = spec.signal_variance_bounds.0.ln();
    hi[0] = spec.signal_variance_bounds.1.ln();
    free[0] = spec.free.signal_variance;
    for m in 0..layout.n_modalities {
        let i = layout.length_scale(m);
        lo[i] = spec.length_scale_bounds.0.ln();
        hi[i] = spec.length_scale_bounds.1.ln();
        free[i] = spec.free.length_scales;
        if let Some(w) = layout.weight(m) {
            lo[w] = -50.0;
            hi[w] = 50.0;
            free[w] = spec.free.weights;
        }
    }
    for s in 0..layout.n_lambdas {
        let li = layout.len() - layout.n_lambdas + s;
        lo[li] = 0.0;
        hi[li] = 1.0;
        free[li] = spec.free.lambda && s < n_sources;
    }
    (lo, hi, free)
}

/// Fails naming the first user-given entry of theta outside `[lo, hi]`.
fn check_in_bounds(
    layout: &Layout,
    theta: &[f64],
    given: &[bool],
    lo: &[f64],
    hi: &[f64],
) -> GpResult<()> {
    for i in 0..theta.len() {
        if !given[i] || (lo[i] <= theta[i] && theta[i] <= hi[i]) {
            continue;
        }
        let (name, value, lo, hi) = if i == Layout::SIGNAL {
            (
                "signal_variance".to_string(),
                theta[i].exp(),
                lo[i].exp(),
                hi[i].exp(),
            )
        } else if i <= layout.n_modalities {
            (
                format!("the length-scale of modality {}", i - 1),
                theta[i].exp(),
                lo[i].exp(),
                hi[i].exp(),
            )
        } else if layout
            .weight(0)
            .is_some_and(|w| i < w + layout.n_modalities)
        {
            (
                "a modality weight logit".to_string(),
                theta[i],
                lo[i],
                hi[i],
            )
        } else {
            ("transfer_lambda".to_string(), theta[i], lo[i], hi[i])
        };
        return Err(GpError::InvalidInput(format!(
            "{name} = {value:.4e} lies outside its bounds [{lo:.4e}, {hi:.4e}]; values given are used \
             as they are, so widen the bounds or change the value"
        )));
    }
    Ok(())
}

/// Optimises one binary classifier. `lambdas`: the starting relatedness of every λ entry of
/// the layout (its sources' values, zero-padded); `start`: a starting theta whose non-NaN
/// entries replace the specification's initial values.
fn fit_binary(
    problem: BinaryProblem,
    layout: &Layout,
    spec: &ModelSpec,
    lambdas: Vec<f64>,
    start: Option<&[f64]>,
    seed: u64,
) -> GpResult<BinaryFit> {
    let m = layout.n_modalities;
    if spec.newton.cancelled() {
        return Err(GpError::Cancelled);
    }
    let prior = problem.prior_terms(layout, spec);
    let needs_scale = spec.optimize || spec.length_scales.iter().any(|l| l.is_nan());
    let medians: Vec<f64> = (0..m)
        .map(|k| {
            if needs_scale {
                problem.dist.median_distance(k)
            } else {
                1.0
            }
        })
        .collect();
    let init_ls: Vec<f64> = spec
        .length_scales
        .iter()
        .zip(&medians)
        .map(|(&l, &med)| if l.is_nan() { med } else { l })
        .collect();
    let init = Hyper {
        signal_variance: spec.signal_variance,
        length_scales: init_ls.clone(),
        weights: spec.weights.clone(),
        lambdas,
    };
    let (lo, hi, free) = theta_box(layout, spec, problem.dist.source_sizes.len());
    let clip = |t: &mut Vec<f64>| {
        t.iter_mut()
            .enumerate()
            .for_each(|(i, v)| *v = v.clamp(lo[i], hi[i]))
    };
    // A given start overrides the initial values entry by entry (NaN: keep the initial one).
    let mut theta0 = layout.encode(&init);
    // Which entries the user gave: those are used as given, so one outside its bounds is an
    // error rather than silently clamped. Data-scaled ("auto") starts are clamped.
    let mut given = vec![false; layout.len()];
    given[Layout::SIGNAL] = true;
    for (k, l) in spec.length_scales.iter().enumerate() {
        given[layout.length_scale(k)] = !l.is_nan();
    }
    if let Some(t) = start {
        for ((v, s), g) in theta0.iter_mut().zip(t).zip(given.iter_mut()) {
            if !s.is_nan() {
                *v = *s;
                *g = true;
            }
        }
    }
    check_in_bounds(layout, &theta0, &given, &lo, &hi)?;
    clip(&mut theta0);
    if !spec.optimize || !free.iter().any(|&f| f) {
        return problem.finish(layout, spec, theta0, prior, Search::NOT_OPTIMISED);
    }

    // Starting points: the given hyper-parameters, then one scaled to the data (unless the
    // given ones already are), then random ones around the data scale.
    let mut starts = vec![theta0.clone()];
    let auto_given = spec.length_scales.iter().all(|l| l.is_nan());
    let mut rng = SplitMix64::new(seed);
    for r in 0..spec.n_restarts {
        let mut t = theta0.clone();
        for k in 0..m {
            let i = layout.length_scale(k);
            if free[i] {
                let jitter = if r == 0 && !auto_given {
                    0.0
                } else {
                    rng.uniform_in(-(10f64.ln()), 10f64.ln())
                };
                t[i] = medians[k].ln() + jitter;
            }
            if let Some(w) = layout.weight(k) {
                if free[w] && (r > 0 || auto_given) {
                    t[w] = rng.normal();
                }
            }
        }
        if free[0] && (r > 0 || auto_given) {
            t[0] = rng.uniform_in(0.1f64.ln(), 100f64.ln());
        }
        for s in 0..layout.n_lambdas {
            let li = layout.len() - layout.n_lambdas + s;
            if free[li] && (r > 0 || auto_given) {
                t[li] = rng.uniform();
            }
        }
        clip(&mut t);
        starts.push(t);
    }

    // The starts are independent: they run in parallel when the pool has threads to spare
    // (each with its own buffers and warm start), and the best is chosen in start order, so
    // the result does not depend on the number of threads.
    let runs: Vec<(Option<OptResult>, Option<GpError>)> = starts
        .par_iter()
        .map(|t0| {
            let mut warm: Option<Vec<f64>> = None;
            let mut ws = Workspace::default();
            let mut last_error = None;
            // Minimises -(log p(y | θ) + log p(θ)); the prior term is absent for ML-II.
            let objective = |t: &[f64]| -> Option<(f64, Vec<f64>)> {
                if spec.newton.cancelled() {
                    last_error = Some(GpError::Cancelled);
                    return None;
                }
                match problem.evaluate(layout, spec, t, warm.as_deref(), true, &mut ws) {
                    Ok((ev, mode, _, Some(mut g))) => {
                        let mut value = mode.lml;
                        warm = Some(mode.a);
                        ws.recycle(ev, mode.l);
                        if !prior.is_empty() {
                            let (lp, gp) = log_prior(&prior, t);
                            value += lp;
                            g.iter_mut().zip(gp).for_each(|(a, b)| *a += b);
                        }
                        Some((-value, g.into_iter().map(|v| -v).collect()))
                    }
                    Ok(_) => None,
                    Err(e) => {
                        last_error = Some(e);
                        None
                    }
                }
            };
            let result = minimize(objective, t0, &lo, &hi, &free, &spec.lbfgs);
            (result, last_error)
        })
        .collect();
    if spec.newton.cancelled() {
        return Err(GpError::Cancelled);
    }
    let mut best: Option<(f64, Vec<f64>, bool, usize)> = None;
    let mut evaluations = 0;
    let mut last_error = None;
    for (result, error) in runs {
        if error.is_some() {
            last_error = error;
        }
        if let Some(r) = result {
            evaluations += r.evaluations;
            if best.as_ref().is_none_or(|(f, _, _, _)| r.fx < *f) {
                best = Some((r.fx, r.x, r.converged, r.iterations));
            }
        }
    }
    match best {
        Some((_, theta, converged, iterations)) => problem.finish(
            layout,
            spec,
            theta,
            prior,
            Search {
                converged,
                evaluations,
                iterations,
            },
        ),
        None => Err(last_error.unwrap_or_else(|| {
            GpError::InvalidInput("no optimiser start could be evaluated".into())
        })),
    }
}

impl BinaryFit {
    /// Latent predictive mean and variance for target-task test rows (Algorithm 3.2), given the
    /// per-modality squared distances from the shared target rows to the test rows.
    ///
    /// One pass per test column builds k*, its mean contribution and `W½ k*` in a buffer that
    /// stays in cache; one triangular solve then gives every variance.
    fn latent(
        &self,
        test: &Data,
        target_dists: &[Mat<f64>],
        modalities: &Modalities,
        center: &[f64],
    ) -> (Vec<f64>, Vec<f64>) {
        let (n, ns) = (self.x.n, self.n_source);
        let source_dists: Vec<Mat<f64>> = if ns == 0 {
            Vec::new()
        } else {
            let source = Data {
                values: self.x.values[..ns * self.x.d].to_vec(),
                n: ns,
                d: self.x.d,
            };
            (0..modalities.len())
                .map(|m| modalities.sq_distances(m, &source, test, center))
                .collect()
        };
        let h = &self.hyper;
        // Each source row couples to the (target-task) test rows through its task's λ.
        let coupling = Coupling::new(&h.lambdas, self.source_sizes.len());
        let target_task = self.source_sizes.len();
        let source_scale: Vec<f64> = row_tasks(&self.source_sizes, ns)
            .into_iter()
            .map(|t| coupling.get(t, target_task))
            .collect();
        let coef: Vec<f64> = h.length_scales.iter().map(|l| -0.5 / (l * l)).collect();
        let mut v = Mat::<f64>::zeros(n, test.n);
        let mut mean = vec![0.0; test.n];
        let mut buf = vec![0.0; n];
        for j in 0..test.n {
            let col = v.col_as_slice_mut(j);
            for m in 0..modalities.len() {
                if ns > 0 {
                    for (b, d) in buf[..ns].iter_mut().zip(source_dists[m].col_as_slice(j)) {
                        *b = coef[m] * d;
                    }
                }
                for (b, d) in buf[ns..].iter_mut().zip(target_dists[m].col_as_slice(j)) {
                    *b = coef[m] * d;
                }
                exp_nonpositive_in_place(&mut buf);
                let scale = h.signal_variance * h.weights[m];
                for (c, b) in col.iter_mut().zip(&buf) {
                    *c += scale * b;
                }
            }
            col[..ns]
                .iter_mut()
                .zip(&source_scale)
                .for_each(|(c, s)| *c *= s);
            mean[j] = self.latent_offset
                + col
                    .iter()
                    .zip(&self.grad_log_lik)
                    .map(|(k, g)| k * g)
                    .sum::<f64>();
            for (c, s) in col.iter_mut().zip(&self.sw) {
                *c *= s;
            }
        }
        linalg::solve_lower_mat(self.l.as_ref(), v.as_mut());
        let prior_var = h.signal_variance * (1.0 + self.jitter);
        let var = (0..test.n)
            .map(|j| {
                let vv: f64 = v.col_as_slice(j).iter().map(|a| a * a).sum();
                (prior_var - vv).max(0.0)
            })
            .collect();
        (mean, var)
    }
}

/// A fitted one-vs-all model.
pub struct OneVsAll {
    pub classifiers: Vec<BinaryFit>,
    /// The target training rows shared by every classifier, and their column means.
    pub x: Data,
    pub center: Vec<f64>,
    pub n_classes: usize,
    pub layout: Layout,
    pub spec: ModelSpec,
}

/// Fits the model. `labels` are class indices in `0..n_classes`; `sources[c]` lists class c's
/// source tasks (empty: none). With two classes and no sources a single binary classifier
/// (class 1 positive) serves both classes.
pub fn fit(
    x: &Data,
    labels: &[usize],
    n_classes: usize,
    sources: &[Vec<Source>],
    spec: &ModelSpec,
) -> GpResult<OneVsAll> {
    fit_impl(x, labels, n_classes, sources, spec, Hypers::Optimise(None))
}

/// As [`fit`], with a starting theta per classifier (None: the specification's values) whose
/// non-NaN entries replace the specification's initial hyper-parameters; fixed entries stay
/// at them.
pub fn fit_from(
    x: &Data,
    labels: &[usize],
    n_classes: usize,
    sources: &[Vec<Source>],
    spec: &ModelSpec,
    starts: &[Option<Vec<f64>>],
) -> GpResult<OneVsAll> {
    fit_impl(
        x,
        labels,
        n_classes,
        sources,
        spec,
        Hypers::Optimise(Some(starts)),
    )
}

/// Builds the model at given hyper-parameters, one theta row per classifier, without
/// optimising (e.g. to restore a saved model).
pub fn fit_at(
    x: &Data,
    labels: &[usize],
    n_classes: usize,
    sources: &[Vec<Source>],
    spec: &ModelSpec,
    thetas: &[Vec<f64>],
) -> GpResult<OneVsAll> {
    fit_impl(x, labels, n_classes, sources, spec, Hypers::At(thetas))
}

enum Hypers<'a> {
    Optimise(Option<&'a [Option<Vec<f64>>]>),
    At(&'a [Vec<f64>]),
}

/// The layout shared by every classifier of a one-vs-all model with these sources.
pub fn layout_for(spec: &ModelSpec, sources: &[Vec<Source>]) -> Layout {
    Layout {
        n_modalities: spec.modalities.len(),
        n_lambdas: sources.iter().map(Vec::len).max().unwrap_or(0),
    }
}

fn check_sources(x: &Data, sources: &[Vec<Source>], n_classes: usize) -> GpResult<()> {
    if sources.len() != n_classes {
        return Err(GpError::InvalidInput(format!(
            "expected one source list per class ({n_classes}), got {}",
            sources.len()
        )));
    }
    for (c, list) in sources.iter().enumerate() {
        for (k, s) in list.iter().enumerate() {
            let what = format!("source {k} of class {c}");
            if s.x.d != x.d {
                return Err(GpError::InvalidInput(format!(
                    "the data of {what} have {} columns, X has {}",
                    s.x.d, x.d
                )));
            }
            if s.x.n == 0 {
                return Err(GpError::InvalidInput(format!("{what} has no rows")));
            }
            s.x.check_finite(&format!("the data of {what}"))?;
            if s.y.len() != s.x.n {
                return Err(GpError::InvalidInput(format!(
                    "{what} has {} rows but {} labels",
                    s.x.n,
                    s.y.len()
                )));
            }
            if let Some(bad) = s.y.iter().find(|&&v| v != 1.0 && v != -1.0) {
                return Err(GpError::InvalidInput(format!(
                    "the labels of {what} must be +1 or -1, got {bad}"
                )));
            }
            if !(0.0..=1.0).contains(&s.lambda) {
                return Err(GpError::InvalidInput(format!(
                    "the transfer lambda of {what} must lie in [0, 1], got {}",
                    s.lambda
                )));
            }
        }
    }
    Ok(())
}

/// Refuses a fit whose n × n matrices cannot fit in the memory this process has, before any of
/// them is allocated (see [`crate::memory`]).
fn check_memory(
    x: &Data,
    sources: &[Vec<Source>],
    spec: &ModelSpec,
    positives: &[usize],
    optimise: bool,
) -> GpResult<()> {
    let rows: Vec<usize> = positives
        .iter()
        .map(|&c| x.n + sources[c].iter().map(|s| s.x.n).sum::<usize>())
        .collect();
    let with_sources: Vec<usize> = positives
        .iter()
        .zip(&rows)
        .filter(|(&c, _)| !sources[c].is_empty())
        .map(|(_, &n)| n)
        .collect();
    let starts = if optimise && spec.optimize {
        1 + spec.n_restarts
    } else {
        1
    };
    // The fit runs on the calling pool: that many starts at most run at once.
    let concurrent = rayon::current_num_threads().min(positives.len() * starts);
    let m = spec.modalities.len();
    let needed = memory::fit_bytes(x.n, &rows, &with_sources, m, concurrent);
    let available = memory::available_bytes();
    let alone = memory::fit_bytes(x.n, &rows, &with_sources, m, 1);
    let hint = if concurrent > 1 && available.is_some_and(|a| alone <= a as u128) {
        format!(
            "; one thread at a time (n_jobs=1) would need {}",
            memory::human(alone)
        )
    } else {
        "; fit on fewer rows (a subsample)".to_string()
    };
    let largest = rows.iter().copied().max().unwrap_or(x.n);
    memory::check(
        &format!(
            "a fit on {largest} rows ({} classifier(s), {m} modalit{}, {concurrent} at a time)",
            positives.len(),
            if m == 1 { "y" } else { "ies" }
        ),
        largest,
        needed,
        available,
        &hint,
    )
}

/// Checks one labelled data set and its sources: labels per row and in range, at least two
/// classes, finite data, well-formed sources.
pub(crate) fn check_task(
    x: &Data,
    labels: &[usize],
    n_classes: usize,
    sources: &[Vec<Source>],
) -> GpResult<()> {
    if labels.len() != x.n {
        return Err(GpError::InvalidInput(format!(
            "X has {} rows but y has {} labels",
            x.n,
            labels.len()
        )));
    }
    if n_classes < 2 {
        return Err(GpError::InvalidInput(format!(
            "classification needs at least two classes, got {n_classes}"
        )));
    }
    if let Some(bad) = labels.iter().find(|&&c| c >= n_classes) {
        return Err(GpError::InvalidInput(format!(
            "label index {bad} is out of range for {n_classes} classes"
        )));
    }
    x.check_finite("X")?;
    check_sources(x, sources, n_classes)?;
    Ok(())
}

/// The class whose labels are +1 in each binary classifier: one classifier (class 1) for two
/// classes without transfer, one per class otherwise.
pub(crate) fn classifier_classes(n_classes: usize, layout: &Layout) -> Vec<usize> {
    if n_classes == 2 && !layout.transfer() {
        vec![1]
    } else {
        (0..n_classes).collect()
    }
}

fn fit_impl(
    x: &Data,
    labels: &[usize],
    n_classes: usize,
    sources: &[Vec<Source>],
    spec: &ModelSpec,
    hypers: Hypers<'_>,
) -> GpResult<OneVsAll> {
    spec.validate()?;
    check_task(x, labels, n_classes, sources)?;
    if spec.tie_length_scales && spec.optimize && matches!(hypers, Hypers::Optimise(_)) {
        return Err(GpError::InvalidInput(
            "tied length-scales are fitted with the shared kernel only".into(),
        ));
    }
    let layout = layout_for(spec, sources);
    let positives = classifier_classes(n_classes, &layout);
    check_memory(
        x,
        sources,
        spec,
        &positives,
        matches!(hypers, Hypers::Optimise(_)),
    )?;
    let center = column_means(x);
    let rows = match &hypers {
        Hypers::At(t) => Some(t.len()),
        Hypers::Optimise(Some(s)) => Some(s.len()),
        Hypers::Optimise(None) => None,
    };
    if let Some(r) = rows {
        if r != positives.len() {
            return Err(GpError::InvalidInput(format!(
                "expected {} theta rows (one per classifier), got {r}",
                positives.len()
            )));
        }
    }
    let check_row = |t: &[f64]| -> GpResult<()> {
        if t.len() != layout.len() {
            return Err(GpError::InvalidInput(format!(
                "theta has {} entries, this model has {} hyper-parameters",
                t.len(),
                layout.len()
            )));
        }
        layout.decode(t).map(|_| ())
    };
    match &hypers {
        Hypers::At(t) => t.iter().try_for_each(|r| check_row(r))?,
        Hypers::Optimise(Some(s)) => s.iter().flatten().try_for_each(|r| {
            // NaN entries stand for "the initial value"; check the rest.
            let filled: Vec<f64> = r
                .iter()
                .map(|v| if v.is_nan() { 0.0 } else { *v })
                .collect();
            check_row(&filled)
        })?,
        Hypers::Optimise(None) => {}
    }
    let target_dist = OnceLock::new();
    let classifiers = positives
        .par_iter()
        .enumerate()
        .map(|(k, &c)| {
            let own = &sources[c];
            let problem = BinaryProblem::new(x, labels, c, own, spec, &center, &target_dist);
            match &hypers {
                Hypers::At(t) => {
                    let prior = problem.prior_terms(&layout, spec);
                    problem.finish(&layout, spec, t[k].clone(), prior, Search::NOT_OPTIMISED)
                }
                Hypers::Optimise(starts) => {
                    let mut lambdas: Vec<f64> = own.iter().map(|s| s.lambda).collect();
                    lambdas.resize(layout.n_lambdas, 0.0);
                    let start = starts.and_then(|s| s[k].as_deref());
                    fit_binary(
                        problem,
                        &layout,
                        spec,
                        lambdas,
                        start,
                        SplitMix64::derive(spec.seed, c as u64).next_u64(),
                    )
                }
            }
        })
        .collect::<GpResult<Vec<_>>>()?;
    Ok(OneVsAll {
        classifiers,
        x: x.clone(),
        center,
        n_classes,
        layout,
        spec: spec.clone(),
    })
}

impl OneVsAll {
    fn check_test(&self, x: &Data) -> GpResult<()> {
        let d = self.classifiers[0].x.d;
        if x.d != d {
            return Err(GpError::InvalidInput(format!(
                "X has {} columns, the model was fitted on {d}",
                x.d
            )));
        }
        x.check_finite("X")
    }

    /// Latent means and variances, `(n_test × n_classifiers)` row-major each.
    pub fn latent(&self, x: &Data) -> GpResult<(Vec<f64>, Vec<f64>)> {
        self.check_test(x)?;
        let k = self.classifiers.len();
        let mods = &self.spec.modalities;
        let shared: Vec<Mat<f64>> = (0..mods.len())
            .into_par_iter()
            .map(|m| mods.sq_distances(m, &self.x, x, &self.center))
            .collect();
        let per: Vec<(Vec<f64>, Vec<f64>)> = self
            .classifiers
            .par_iter()
            .map(|c| c.latent(x, &shared, mods, &self.center))
            .collect();
        let mut mean = vec![0.0; x.n * k];
        let mut var = vec![0.0; x.n * k];
        for (c, (m, v)) in per.into_iter().enumerate() {
            for i in 0..x.n {
                mean[i * k + c] = m[i];
                var[i * k + c] = v[i];
            }
        }
        Ok((mean, var))
    }

    /// Each one-vs-all classifier's own `p(y = +1 | x)` per class, `(n_test × n_classes)`
    /// row-major, not normalised across classes. With a single classifier for two classes the
    /// first column is its complement.
    pub fn predict_binary(&self, x: &Data) -> GpResult<Vec<f64>> {
        let (mean, var) = self.latent(x)?;
        let k = self.classifiers.len();
        let c = self.n_classes;
        let mut out = vec![0.0; x.n * c];
        for i in 0..x.n {
            if k == 1 {
                let p = predictive_probability(mean[i], var[i], self.spec.predictive);
                out[i * c] = 1.0 - p;
                out[i * c + 1] = p;
            } else {
                for j in 0..c {
                    out[i * c + j] = predictive_probability(
                        mean[i * k + j],
                        var[i * k + j],
                        self.spec.predictive,
                    );
                }
            }
        }
        Ok(out)
    }

    /// Class probabilities `(n_test × n_classes)` row-major: the one-vs-all probabilities
    /// normalised to sum to one.
    pub fn predict_proba(&self, x: &Data) -> GpResult<Vec<f64>> {
        let mut out = self.predict_binary(x)?;
        let c = self.n_classes;
        if self.classifiers.len() > 1 {
            for row in out.chunks_mut(c) {
                let s: f64 = row.iter().sum();
                if s > 0.0 {
                    row.iter_mut().for_each(|v| *v /= s);
                } else {
                    row.iter_mut().for_each(|v| *v = 1.0 / c as f64);
                }
            }
        }
        Ok(out)
    }

    /// Log marginal likelihood (and its gradient) of each classifier at the given theta rows;
    /// with `include_prior`, plus the log hyper-prior (the MAP-II objective).
    pub fn log_marginal_likelihood(
        &self,
        thetas: &[Vec<f64>],
        gradient: bool,
        include_prior: bool,
    ) -> GpResult<Vec<(f64, Option<Vec<f64>>)>> {
        if thetas.len() != self.classifiers.len() {
            return Err(GpError::InvalidInput(format!(
                "expected {} theta rows (one per classifier), got {}",
                self.classifiers.len(),
                thetas.len()
            )));
        }
        self.classifiers
            .par_iter()
            .zip(thetas.par_iter())
            .map(|(c, t)| {
                let problem = BinaryProblem {
                    dist: Arc::new(PairDistances::new(
                        &c.x,
                        &c.source_sizes,
                        &self.spec.modalities,
                        &self.center,
                    )),
                    x: c.x.clone(),
                    y: c.y.clone(),
                    offset: c.latent_offset,
                };
                let (_, mode, _, mut g) = problem.evaluate(
                    &self.layout,
                    &self.spec,
                    t,
                    None,
                    gradient,
                    &mut Workspace::default(),
                )?;
                let mut value = mode.lml;
                if include_prior {
                    let (lp, gp) = log_prior(&c.prior, t);
                    value += lp;
                    if let Some(g) = g.as_mut() {
                        g.iter_mut().zip(gp).for_each(|(a, b)| *a += b);
                    }
                }
                Ok((value, g))
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn blobs(n_per: usize, centers: &[[f64; 2]], seed: u64) -> (Data, Vec<usize>) {
        let mut rng = SplitMix64::new(seed);
        let mut v = Vec::new();
        let mut y = Vec::new();
        for (c, ctr) in centers.iter().enumerate() {
            for _ in 0..n_per {
                v.push(ctr[0] + 0.6 * rng.normal());
                v.push(ctr[1] + 0.6 * rng.normal());
                y.push(c);
            }
        }
        (Data::new(v, y.len(), 2).unwrap(), y)
    }

    #[test]
    fn separable_blobs_are_learned() {
        let centers = [[0.0, 0.0], [3.0, 0.0], [0.0, 3.0]];
        let (x, y) = blobs(15, &centers, 3);
        let spec = ModelSpec::new(Modalities::all_columns(2));
        let model = fit(&x, &y, 3, &[vec![], vec![], vec![]], &spec).unwrap();
        let (xt, yt) = blobs(20, &centers, 99);
        let p = model.predict_proba(&xt).unwrap();
        let correct = (0..xt.n)
            .filter(|&i| {
                let row = &p[i * 3..i * 3 + 3];
                let arg = (0..3).max_by(|&a, &b| row[a].total_cmp(&row[b])).unwrap();
                arg == yt[i]
            })
            .count();
        assert!(
            correct as f64 / xt.n as f64 > 0.9,
            "accuracy {}",
            correct as f64 / xt.n as f64
        );
        for i in 0..xt.n {
            let s: f64 = p[i * 3..i * 3 + 3].iter().sum();
            assert!((s - 1.0).abs() < 1e-12);
        }
    }

    #[test]
    fn optimisation_does_not_lower_the_likelihood_of_the_start() {
        let (x, y) = blobs(12, &[[0.0, 0.0], [1.5, 1.0]], 5);
        let mut spec = ModelSpec::new(Modalities::all_columns(2));
        spec.optimize = false;
        let fixed = fit(&x, &y, 2, &[vec![], vec![]], &spec).unwrap();
        spec.optimize = true;
        let opt = fit(&x, &y, 2, &[vec![], vec![]], &spec).unwrap();
        assert_eq!(opt.classifiers.len(), 1);
        assert!(opt.classifiers[0].lml >= fixed.classifiers[0].lml - 1e-9);
    }

    #[test]
    fn weight_prior_is_a_normal_density_on_each_logit_and_keeps_weights_balanced() {
        // Five classes with one observation each: the likelihood barely depends on how the two
        // modalities (one column each) are weighted.
        let centers = [[0.0, 0.0], [2.0, 0.3], [0.4, 2.2], [2.5, 2.5], [1.2, 1.0]];
        let (x, y) = blobs(1, &centers, 21);
        let modalities = Modalities::new(vec![vec![0], vec![1]], 2).unwrap();
        let sources = vec![vec![]; 5];
        let sd = 1.6;
        let mut spec = ModelSpec::new(modalities);
        spec.n_restarts = 2;
        spec.seed = 4;
        let flat = fit(&x, &y, 5, &sources, &spec).unwrap();
        spec.hyper_prior = Some(HyperPrior {
            signal_variance: None,
            length_scale: None,
            weight_logit: Some(sd),
        });
        let map = fit(&x, &y, 5, &sources, &spec).unwrap();
        let normal =
            |v: f64| -0.5 * (v / sd).powi(2) - sd.ln() - 0.5 * (2.0 * std::f64::consts::PI).ln();
        let spread = |theta: &[f64]| (theta[3] - theta[4]).abs();
        for c in &map.classifiers {
            // theta = [ln σ², ln ℓ_0, ln ℓ_1, η_0, η_1]: only the logits carry a prior here.
            assert_eq!(c.prior.len(), 2);
            let want = normal(c.theta[3]) + normal(c.theta[4]);
            assert!(
                (c.log_prior - want).abs() < 1e-12,
                "{} vs {want}",
                c.log_prior
            );
        }
        let widest = |m: &OneVsAll| {
            m.classifiers
                .iter()
                .map(|c| spread(&c.theta))
                .fold(0.0, f64::max)
        };
        // Without it the optimiser drifts to weights of e^-8 on one modality (measured: a
        // logit spread of 18.5 here, against 0.24 with the prior).
        assert!(widest(&flat) > 8.0, "flat weights spread {}", widest(&flat));
        assert!(widest(&map) < 2.0, "weak prior spread {}", widest(&map));
        spec.hyper_prior.as_mut().unwrap().weight_logit = Some(0.0);
        assert!(matches!(
            fit(&x, &y, 5, &sources, &spec),
            Err(GpError::InvalidInput(_))
        ));
    }

    #[test]
    fn same_seed_same_model() {
        let (x, y) = blobs(10, &[[0.0, 0.0], [2.0, 0.0], [1.0, 2.0]], 8);
        let mut spec = ModelSpec::new(Modalities::all_columns(2));
        spec.seed = 42;
        spec.n_restarts = 3;
        let a = fit(&x, &y, 3, &[vec![], vec![], vec![]], &spec).unwrap();
        let b = fit(&x, &y, 3, &[vec![], vec![], vec![]], &spec).unwrap();
        for (ca, cb) in a.classifiers.iter().zip(&b.classifiers) {
            assert_eq!(ca.theta, cb.theta);
        }
    }

    #[test]
    fn bad_inputs_are_rejected() {
        let (x, y) = blobs(5, &[[0.0, 0.0], [2.0, 0.0]], 1);
        let spec = ModelSpec::new(Modalities::all_columns(2));
        assert!(matches!(
            fit(&x, &y, 1, &[vec![]], &spec),
            Err(GpError::InvalidInput(_))
        ));
        assert!(matches!(
            fit(&x, &y[1..], 2, &[vec![], vec![]], &spec),
            Err(GpError::InvalidInput(_))
        ));
        let mut xn = x.clone();
        xn.values[3] = f64::NAN;
        assert!(matches!(
            fit(&xn, &y, 2, &[vec![], vec![]], &spec),
            Err(GpError::NonFinite(_))
        ));
        let src = Source::positives(Data::new(vec![0.0, 0.0], 1, 2).unwrap(), 1.5);
        assert!(matches!(
            fit(&x, &y, 2, &[vec![src], vec![]], &spec),
            Err(GpError::InvalidInput(_))
        ));
        // A tolerance never met (NaN, negative) or always met (infinity), and restarts without
        // bound, are settings errors, not fits that never end.
        for tol in [f64::NAN, -1.0, f64::INFINITY] {
            let mut bad = spec.clone();
            bad.newton.tol = tol;
            assert!(matches!(
                fit(&x, &y, 2, &[vec![], vec![]], &bad),
                Err(GpError::InvalidInput(m)) if m.contains("newton_tol")
            ));
        }
        let mut bad = spec.clone();
        bad.n_restarts = MAX_RESTARTS + 1;
        assert!(matches!(
            fit(&x, &y, 2, &[vec![], vec![]], &bad),
            Err(GpError::InvalidInput(m)) if m.contains("n_restarts")
        ));
    }

    #[test]
    fn a_fit_beyond_the_memory_is_refused_before_allocating() {
        // 3 million rows (24 MB of data): each n x n matrix would take 72 TB.
        let n = 3_000_000;
        let x = Data::new(vec![0.5; n], n, 1).unwrap();
        let y: Vec<usize> = (0..n).map(|i| i % 2).collect();
        let spec = ModelSpec::new(Modalities::all_columns(1));
        match fit(&x, &y, 2, &[vec![], vec![]], &spec) {
            Err(GpError::TooLarge { rows, bytes, .. }) => {
                assert_eq!(rows, n);
                assert!(bytes > 72_000_000_000_000);
            }
            other => panic!("expected TooLarge, got {:?}", other.err()),
        }
    }

    #[test]
    fn transfer_from_a_matching_source_helps_with_few_targets() {
        // Class 0 has a single target observation; its source task has many observations
        // around the same centre. With λ = 1 the classifier for class 0 knows the whole blob.
        let (src_x, _) = blobs(20, &[[0.0, 0.0]], 11);
        let (x, y) = {
            let (a, ya) = blobs(1, &[[0.0, 0.0]], 12);
            let (b, yb) = blobs(15, &[[2.5, 0.0]], 13);
            let x = a.stacked(&b);
            let y: Vec<usize> = ya.into_iter().chain(yb.into_iter().map(|_| 1)).collect();
            (x, y)
        };
        let mut spec = ModelSpec::new(Modalities::all_columns(2));
        spec.optimize = false;
        spec.signal_variance = 4.0;
        let probe = Data::new(vec![-1.0, 0.8], 1, 2).unwrap();
        let plain = fit(&x, &y, 2, &[vec![], vec![]], &spec)
            .unwrap()
            .predict_proba(&probe)
            .unwrap();
        let source = Source::positives(src_x, 1.0);
        let with = fit(&x, &y, 2, &[vec![source], vec![]], &spec)
            .unwrap()
            .predict_proba(&probe)
            .unwrap();
        assert!(
            with[0] > plain[0] + 0.05,
            "transfer {} vs plain {}",
            with[0],
            plain[0]
        );
    }

    #[test]
    fn base_rate_mean_returns_each_classifier_to_its_rate_far_from_its_data() {
        // Four classes of 1, 2, 3 and 6 observations, with a 4-row source task on class 0.
        let centers = [[0.0, 0.0], [3.0, 0.0], [0.0, 3.0], [3.0, 3.0]];
        let mut v = Vec::new();
        let mut y = Vec::new();
        for (c, n) in [1usize, 2, 3, 6].into_iter().enumerate() {
            let (b, _) = blobs(n, &centers[c..c + 1], 40 + c as u64);
            v.extend(b.values);
            y.extend(std::iter::repeat_n(c, n));
        }
        let x = Data::new(v, y.len(), 2).unwrap();
        let (src_x, _) = blobs(4, &[[0.0, 0.0]], 50);
        let src = Source {
            x: src_x,
            y: vec![1.0, -1.0, -1.0, -1.0],
            lambda: 0.5,
        };
        let mut spec = ModelSpec::new(Modalities::all_columns(2));
        spec.optimize = false;
        spec.latent_mean = LatentMean::BaseRate;
        let sources = [vec![src], vec![], vec![], vec![]];
        let model = fit(&x, &y, 4, &sources, &spec).unwrap();
        // Class 0: 1 of 12 target rows plus 1 of 4 source rows; the others k of 12.
        let expected = [
            (2.5f64 / 14.5).ln(),
            (2.5f64 / 10.5).ln(),
            (3.5f64 / 9.5).ln(),
            (6.5f64 / 6.5).ln(),
        ];
        let far = Data::new(vec![1e3, -1e3], 1, 2).unwrap();
        let (mean, var) = model.latent(&far).unwrap();
        for c in 0..4 {
            let m = model.classifiers[c].latent_offset;
            assert!(
                (m - expected[c]).abs() < 1e-12,
                "class {c}: {m} vs {}",
                expected[c]
            );
            // k* = 0 far away: the latent prior N(m, σ²) itself.
            assert!((mean[c] - m).abs() < 1e-12, "class {c}: mean {}", mean[c]);
            assert!((var[c] - spec.signal_variance).abs() < 1e-9);
        }
        // The zero mean returns every classifier to ½ there instead.
        spec.latent_mean = LatentMean::Zero;
        let zero = fit(&x, &y, 4, &sources, &spec).unwrap();
        assert!(zero.latent(&far).unwrap().0.iter().all(|m| m.abs() < 1e-12));
        assert!(zero.classifiers.iter().all(|c| c.latent_offset == 0.0));
    }
}
