//! One-vs-all multi-class Laplace GPC: per-class binary classifiers with their own
//! hyper-parameters (and, for transfer, their own source task), fitted in parallel.

use faer::Mat;
use rayon::prelude::*;

use crate::error::{GpError, GpResult};
use crate::fastmath::exp_nonpositive_in_place;
use crate::kernel::{column_means, Data, Hyper, KernelEval, Layout, Modalities, PairDistances};
use crate::laplace::{find_mode_with_jitter, lml_gradient, Mode, NewtonConfig};
use crate::likelihood::{predictive_probability, Predictive};
use crate::linalg;
use crate::optimize::{minimize, LbfgsConfig};
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
        }
    }

    fn validate(&self) -> GpResult<()> {
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
        if !(self.max_jitter >= 0.0 && self.max_jitter.is_finite()) {
            return Err(GpError::InvalidInput(format!(
                "max_jitter must be >= 0, got {}",
                self.max_jitter
            )));
        }
        Ok(())
    }
}

/// Source-task observations transferred into one class's binary classifier (labelled +1).
#[derive(Debug, Clone)]
pub struct Source {
    pub x: Data,
    pub lambda: f64,
}

/// A fitted binary classifier: the training rows (source first), the hyper-parameters and the
/// quantities Algorithm 3.2 needs.
pub struct BinaryFit {
    pub x: Data,
    pub y: Vec<f64>,
    pub n_source: usize,
    pub theta: Vec<f64>,
    pub hyper: Hyper,
    pub lml: f64,
    pub jitter: f64,
    /// ∇ log p(y | f̂) = t - π̂.
    grad_log_lik: Vec<f64>,
    sw: Vec<f64>,
    l: Mat<f64>,
    pub newton_converged: bool,
    pub optimizer_converged: bool,
    pub evaluations: usize,
}

struct BinaryProblem {
    x: Data,
    y: Vec<f64>,
    n_source: usize,
    dist: PairDistances,
}

impl BinaryProblem {
    fn new(
        target: &Data,
        labels: &[usize],
        positive: usize,
        source: Option<&Source>,
        modalities: &Modalities,
        center: &[f64],
    ) -> Self {
        let y_target = labels
            .iter()
            .map(|&c| if c == positive { 1.0 } else { -1.0 });
        let (x, y, n_source) = match source {
            Some(s) => {
                let y: Vec<f64> = std::iter::repeat_n(1.0, s.x.n).chain(y_target).collect();
                (s.x.stacked(target), y, s.x.n)
            }
            None => (target.clone(), y_target.collect(), 0),
        };
        let dist = PairDistances::new(&x, n_source, modalities, center);
        BinaryProblem {
            x,
            y,
            n_source,
            dist,
        }
    }

    fn evaluate(
        &self,
        layout: &Layout,
        spec: &ModelSpec,
        theta: &[f64],
        warm: Option<&[f64]>,
        gradient: bool,
    ) -> GpResult<(KernelEval, Mode, Hyper, Option<Vec<f64>>)> {
        let h = layout.decode(theta)?;
        let ev = KernelEval::new(&self.dist, &h);
        let (ev, mode) = find_mode_with_jitter(
            ev,
            h.signal_variance,
            &self.y,
            warm,
            &spec.newton,
            spec.max_jitter,
        )?;
        let grad = gradient.then(|| lml_gradient(layout, &h, &self.dist, &ev, &mode));
        Ok((ev, mode, h, grad))
    }

    fn finish(
        self,
        layout: &Layout,
        spec: &ModelSpec,
        theta: Vec<f64>,
        optimizer_converged: bool,
        evaluations: usize,
    ) -> GpResult<BinaryFit> {
        let (ev, mode, hyper, _) = self.evaluate(layout, spec, &theta, None, false)?;
        let grad_log_lik: Vec<f64> = (0..self.y.len())
            .map(|i| 0.5 * (self.y[i] + 1.0) - mode.pi[i])
            .collect();
        Ok(BinaryFit {
            x: self.x,
            y: self.y,
            n_source: self.n_source,
            theta,
            hyper,
            lml: mode.lml,
            jitter: ev.jitter,
            grad_log_lik,
            sw: mode.sw,
            l: mode.l,
            newton_converged: mode.converged,
            optimizer_converged,
            evaluations,
        })
    }
}

/// Per-entry bounds and free flags of theta.
fn theta_box(
    layout: &Layout,
    spec: &ModelSpec,
    has_source: bool,
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
    if let Some(li) = layout.lambda() {
        lo[li] = 0.0;
        hi[li] = 1.0;
        free[li] = spec.free.lambda && has_source;
    }
    (lo, hi, free)
}

fn fit_binary(
    problem: BinaryProblem,
    layout: &Layout,
    spec: &ModelSpec,
    lambda: f64,
    seed: u64,
) -> GpResult<BinaryFit> {
    let m = layout.n_modalities;
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
        lambda,
    };
    let (lo, hi, free) = theta_box(layout, spec, problem.n_source > 0);
    let clip = |t: &mut Vec<f64>| {
        t.iter_mut()
            .enumerate()
            .for_each(|(i, v)| *v = v.clamp(lo[i], hi[i]))
    };
    let mut theta0 = layout.encode(&init);
    clip(&mut theta0);
    if !spec.optimize || !free.iter().any(|&f| f) {
        return problem.finish(layout, spec, theta0, true, 1);
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
        if let Some(li) = layout.lambda() {
            if free[li] && (r > 0 || auto_given) {
                t[li] = rng.uniform();
            }
        }
        clip(&mut t);
        starts.push(t);
    }

    let mut best: Option<(f64, Vec<f64>, bool)> = None;
    let mut evaluations = 0;
    let mut last_error = None;
    for start in starts {
        let mut warm: Option<Vec<f64>> = None;
        let objective = |t: &[f64]| -> Option<(f64, Vec<f64>)> {
            match problem.evaluate(layout, spec, t, warm.as_deref(), true) {
                Ok((_, mode, _, Some(g))) => {
                    warm = Some(mode.a);
                    Some((-mode.lml, g.into_iter().map(|v| -v).collect()))
                }
                Ok(_) => None,
                Err(e) => {
                    last_error = Some(e);
                    None
                }
            }
        };
        if let Some(r) = minimize(objective, &start, &lo, &hi, &free, &spec.lbfgs) {
            evaluations += r.evaluations;
            if best.as_ref().is_none_or(|(f, _, _)| r.fx < *f) {
                best = Some((r.fx, r.x, r.converged));
            }
        }
    }
    match best {
        Some((_, theta, converged)) => problem.finish(layout, spec, theta, converged, evaluations),
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
            col[..ns].iter_mut().for_each(|c| *c *= h.lambda);
            mean[j] = col.iter().zip(&self.grad_log_lik).map(|(k, g)| k * g).sum();
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

/// Fits the model. `labels` are class indices in `0..n_classes`; with two classes and no
/// sources a single binary classifier (class 1 positive) serves both classes.
pub fn fit(
    x: &Data,
    labels: &[usize],
    n_classes: usize,
    sources: &[Option<Source>],
    spec: &ModelSpec,
) -> GpResult<OneVsAll> {
    fit_impl(x, labels, n_classes, sources, spec, None)
}

/// Builds the model at given hyper-parameters, one theta row per classifier, without
/// optimising (e.g. to restore a saved model).
pub fn fit_at(
    x: &Data,
    labels: &[usize],
    n_classes: usize,
    sources: &[Option<Source>],
    spec: &ModelSpec,
    thetas: &[Vec<f64>],
) -> GpResult<OneVsAll> {
    fit_impl(x, labels, n_classes, sources, spec, Some(thetas))
}

fn fit_impl(
    x: &Data,
    labels: &[usize],
    n_classes: usize,
    sources: &[Option<Source>],
    spec: &ModelSpec,
    thetas: Option<&[Vec<f64>]>,
) -> GpResult<OneVsAll> {
    spec.validate()?;
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
    if sources.len() != n_classes {
        return Err(GpError::InvalidInput(format!(
            "expected one source entry per class ({n_classes}), got {}",
            sources.len()
        )));
    }
    x.check_finite("X")?;
    for (c, s) in sources.iter().enumerate() {
        if let Some(s) = s {
            if s.x.d != x.d {
                return Err(GpError::InvalidInput(format!(
                    "the source data of class {c} have {} columns, X has {}",
                    s.x.d, x.d
                )));
            }
            s.x.check_finite(&format!("the source data of class {c}"))?;
            if !(0.0..=1.0).contains(&s.lambda) {
                return Err(GpError::InvalidInput(format!(
                    "the transfer lambda of class {c} must lie in [0, 1], got {}",
                    s.lambda
                )));
            }
        }
    }
    let transfer = sources.iter().any(|s| s.is_some());
    let center = column_means(x);
    let layout = Layout {
        n_modalities: spec.modalities.len(),
        transfer,
    };
    let positives: Vec<usize> = if n_classes == 2 && !transfer {
        vec![1]
    } else {
        (0..n_classes).collect()
    };
    if let Some(t) = thetas {
        if t.len() != positives.len() {
            return Err(GpError::InvalidInput(format!(
                "expected {} theta rows (one per classifier), got {}",
                positives.len(),
                t.len()
            )));
        }
    }
    let classifiers = positives
        .par_iter()
        .enumerate()
        .map(|(k, &c)| {
            let source = sources[c].as_ref();
            let problem = BinaryProblem::new(x, labels, c, source, &spec.modalities, &center);
            match thetas {
                Some(t) => problem.finish(&layout, spec, t[k].clone(), true, 1),
                None => {
                    let lambda = source.map_or(0.0, |s| s.lambda);
                    fit_binary(
                        problem,
                        &layout,
                        spec,
                        lambda,
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

    /// Class probabilities `(n_test × n_classes)` row-major: the one-vs-all probabilities
    /// normalised to sum to one.
    pub fn predict_proba(&self, x: &Data) -> GpResult<Vec<f64>> {
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
                let row = &mut out[i * c..(i + 1) * c];
                for j in 0..c {
                    row[j] = predictive_probability(
                        mean[i * k + j],
                        var[i * k + j],
                        self.spec.predictive,
                    );
                }
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

    /// Log marginal likelihood (and its gradient) of each classifier at the given theta rows.
    pub fn log_marginal_likelihood(
        &self,
        thetas: &[Vec<f64>],
        gradient: bool,
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
                    dist: PairDistances::new(&c.x, c.n_source, &self.spec.modalities, &self.center),
                    x: c.x.clone(),
                    y: c.y.clone(),
                    n_source: c.n_source,
                };
                let (_, mode, _, g) =
                    problem.evaluate(&self.layout, &self.spec, t, None, gradient)?;
                Ok((mode.lml, g))
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
        let model = fit(&x, &y, 3, &[None, None, None], &spec).unwrap();
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
        let fixed = fit(&x, &y, 2, &[None, None], &spec).unwrap();
        spec.optimize = true;
        let opt = fit(&x, &y, 2, &[None, None], &spec).unwrap();
        assert_eq!(opt.classifiers.len(), 1);
        assert!(opt.classifiers[0].lml >= fixed.classifiers[0].lml - 1e-9);
    }

    #[test]
    fn same_seed_same_model() {
        let (x, y) = blobs(10, &[[0.0, 0.0], [2.0, 0.0], [1.0, 2.0]], 8);
        let mut spec = ModelSpec::new(Modalities::all_columns(2));
        spec.seed = 42;
        spec.n_restarts = 3;
        let a = fit(&x, &y, 3, &[None, None, None], &spec).unwrap();
        let b = fit(&x, &y, 3, &[None, None, None], &spec).unwrap();
        for (ca, cb) in a.classifiers.iter().zip(&b.classifiers) {
            assert_eq!(ca.theta, cb.theta);
        }
    }

    #[test]
    fn bad_inputs_are_rejected() {
        let (x, y) = blobs(5, &[[0.0, 0.0], [2.0, 0.0]], 1);
        let spec = ModelSpec::new(Modalities::all_columns(2));
        assert!(matches!(
            fit(&x, &y, 1, &[None], &spec),
            Err(GpError::InvalidInput(_))
        ));
        assert!(matches!(
            fit(&x, &y[1..], 2, &[None, None], &spec),
            Err(GpError::InvalidInput(_))
        ));
        let mut xn = x.clone();
        xn.values[3] = f64::NAN;
        assert!(matches!(
            fit(&xn, &y, 2, &[None, None], &spec),
            Err(GpError::NonFinite(_))
        ));
        let src = Source {
            x: Data::new(vec![0.0, 0.0], 1, 2).unwrap(),
            lambda: 1.5,
        };
        assert!(matches!(
            fit(&x, &y, 2, &[Some(src), None], &spec),
            Err(GpError::InvalidInput(_))
        ));
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
        let plain = fit(&x, &y, 2, &[None, None], &spec)
            .unwrap()
            .predict_proba(&probe)
            .unwrap();
        let source = Source {
            x: src_x,
            lambda: 1.0,
        };
        let with = fit(&x, &y, 2, &[Some(source), None], &spec)
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
}
