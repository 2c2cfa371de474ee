//! One kernel for several one-vs-all classifiers: the kernel hyper-parameters (σ², ℓ_m, γ_m)
//! are shared by every binary classifier of one or more labelled data sets ("kernel tasks")
//! and chosen by maximising the sum of their Laplace log marginal likelihoods (plus the
//! hyper-prior, counted once). Each classifier keeps its own latent function, labels, sources
//! and fixed λ.
//!
//! Why: a one-vs-all model's class posterior compares its classifiers' probabilities, which
//! is only meaningful when they use one kernel; and a kernel describes the feature space of one
//! sensor and action, so observations of other objects (earlier ones, with many repetitions)
//! inform it where a handful of new observations cannot.

use std::sync::OnceLock;

use rayon::prelude::*;

use crate::error::{GpError, GpResult};
use crate::kernel::{column_means, Data, Hyper, Layout};
use crate::memory;
use crate::model::{
    check_task, classifier_classes, fit_at, layout_for, log_prior, theta_box, BinaryProblem,
    ModelSpec, OneVsAll, PriorTerm, Source, Workspace,
};
use crate::optimize::minimize;
use crate::rng::SplitMix64;

/// One labelled data set whose classifiers share the kernel: rows, class indices in
/// `0..n_classes`, and each class's source tasks (empty: none).
#[derive(Debug, Clone, Copy)]
pub struct KernelTask<'a> {
    pub x: &'a Data,
    pub labels: &'a [usize],
    pub n_classes: usize,
    pub sources: &'a [Vec<Source>],
}

/// Every binary classifier of every task, with the λ entries that follow the shared part of its
/// theta (fixed: the shared fit never changes λ).
struct Classifier {
    problem: BinaryProblem,
    lambdas: Vec<f64>,
}

/// Number of shared entries at the front of theta: σ², one ℓ per modality and, with several
/// modalities, one weight logit each.
fn n_shared(layout: &Layout) -> usize {
    layout.len() - layout.n_lambdas
}

/// Fits one set of kernel hyper-parameters for every classifier of every task, then builds the
/// model of `tasks[target]` at them. The length-scale hyper-prior is centred on the target's
/// data scale, as a per-classifier fit's is. `spec.free.lambda` must be false.
pub fn fit_shared(tasks: &[KernelTask<'_>], target: usize, spec: &ModelSpec) -> GpResult<OneVsAll> {
    spec.validate()?;
    if spec.free.lambda {
        return Err(GpError::InvalidInput(
            "a shared kernel keeps each classifier's transfer lambda fixed".into(),
        ));
    }
    let Some(goal) = tasks.get(target) else {
        return Err(GpError::InvalidInput(format!(
            "target task {target} of {} tasks",
            tasks.len()
        )));
    };
    let d = goal.x.d;
    for (i, t) in tasks.iter().enumerate() {
        if t.x.d != d {
            return Err(GpError::InvalidInput(format!(
                "kernel task {i} has {} columns, the target has {d}",
                t.x.d
            )));
        }
        check_task(t.x, t.labels, t.n_classes, t.sources)?;
    }
    check_memory(tasks, spec)?;
    let m = spec.modalities.len();
    // The target's classifiers first, so that its first classifier sets the data scale.
    let mut order: Vec<usize> = vec![target];
    order.extend((0..tasks.len()).filter(|&i| i != target));
    let mut classifiers = Vec::new();
    for &i in &order {
        let t = &tasks[i];
        let layout = layout_for(spec, t.sources);
        let center = column_means(t.x);
        let shared_dist = OnceLock::new();
        for c in classifier_classes(t.n_classes, &layout) {
            let own = &t.sources[c];
            let mut lambdas: Vec<f64> = own.iter().map(|s| s.lambda).collect();
            lambdas.resize(layout.n_lambdas, 0.0);
            classifiers.push((
                layout,
                Classifier {
                    problem: BinaryProblem::new(t.x, t.labels, c, own, spec, &center, &shared_dist),
                    lambdas,
                },
            ));
        }
    }
    let plain = Layout {
        n_modalities: m,
        n_lambdas: 0,
    };
    let k = n_shared(&plain);
    let (lo, hi, free) = theta_box(&plain, spec, 0);
    let first = &classifiers[0].1.problem;
    let prior = first.prior_terms(&plain, spec);
    let medians: Vec<f64> = (0..m).map(|j| first.dist_median(j)).collect();
    let init = Hyper {
        signal_variance: spec.signal_variance,
        length_scales: spec
            .length_scales
            .iter()
            .zip(&medians)
            .map(|(&l, &med)| if l.is_nan() { med } else { l })
            .collect(),
        weights: spec.weights.clone(),
        lambdas: Vec::new(),
    };
    let mut theta0 = plain.encode(&init);
    theta0
        .iter_mut()
        .enumerate()
        .for_each(|(i, v)| *v = v.clamp(lo[i], hi[i]));
    let shared = if spec.optimize && free.iter().any(|&f| f) {
        let search = Search {
            classifiers: &classifiers,
            k,
            lo: &lo,
            hi: &hi,
            free: &free,
            prior: &prior,
            spec,
            medians: &medians,
        };
        search.run(&theta0)?
    } else {
        theta0
    };
    let goal_layout = layout_for(spec, goal.sources);
    let rows: Vec<Vec<f64>> = classifiers
        .iter()
        .take(classifier_classes(goal.n_classes, &goal_layout).len())
        .map(|(_, c)| {
            let mut row = shared.clone();
            row.extend_from_slice(&c.lambdas);
            row
        })
        .collect();
    fit_at(
        goal.x,
        goal.labels,
        goal.n_classes,
        goal.sources,
        spec,
        &rows,
    )
}

/// Refuses a shared fit whose n × n matrices cannot all be held at once, before any of them is
/// allocated (see [`crate::memory`]). Unlike a per-classifier fit, whose starts run a few at a
/// time, every classifier of every task keeps its distances and its working matrices (kernel,
/// per-modality parts, factor, inverse and scratch) through each start, whatever the threads;
/// the target's model is then built at the shared values beside them.
fn check_memory(tasks: &[KernelTask<'_>], spec: &ModelSpec) -> GpResult<()> {
    let m = spec.modalities.len();
    let (mut needed, mut total_rows, mut largest, mut n_classifiers) = (0u128, 0usize, 0, 0);
    for t in tasks {
        let layout = layout_for(spec, t.sources);
        let classes = classifier_classes(t.n_classes, &layout);
        let rows: Vec<usize> = classes
            .iter()
            .map(|&c| t.x.n + t.sources[c].iter().map(|s| s.x.n).sum::<usize>())
            .collect();
        let with_sources: Vec<usize> = classes
            .iter()
            .zip(&rows)
            .filter(|(&c, _)| !t.sources[c].is_empty())
            .map(|(_, &n)| n)
            .collect();
        needed += memory::fit_bytes(t.x.n, &rows, &with_sources, m, rows.len());
        total_rows += t.x.n;
        largest = rows.iter().copied().fold(largest, usize::max);
        n_classifiers += rows.len();
    }
    memory::check(
        &format!(
            "a shared-kernel fit on {total_rows} rows ({} task(s), {n_classifiers} \
             classifier(s) held at once, the largest on {largest} rows, {m} modalit{})",
            tasks.len(),
            if m == 1 { "y" } else { "ies" }
        ),
        largest,
        needed,
        memory::available_bytes(),
        "; share the kernel with fewer tasks, or fit on fewer rows (a subsample)",
    )
}

/// The search over the shared entries of theta: every classifier, the box, the free entries,
/// the hyper-prior and the data scale of each modality.
struct Search<'a> {
    classifiers: &'a [(Layout, Classifier)],
    k: usize,
    lo: &'a [f64],
    hi: &'a [f64],
    free: &'a [bool],
    prior: &'a [PriorTerm],
    spec: &'a ModelSpec,
    medians: &'a [f64],
}

impl Search<'_> {
    /// Minimises −(Σ log p(y | θ) + log p(θ)) over the shared entries from `theta0` and from
    /// `spec.n_restarts` random starts around the data scale; the best start wins (in start order,
    /// so the result does not depend on the number of threads).
    fn run(&self, theta0: &[f64]) -> GpResult<Vec<f64>> {
        let Search {
            classifiers,
            k,
            lo,
            hi,
            free,
            prior,
            spec,
            medians,
        } = *self;
        let m = spec.modalities.len();
        let mut starts = vec![theta0.to_vec()];
        let mut rng = SplitMix64::new(spec.seed);
        for _ in 0..spec.n_restarts {
            let mut t = theta0.to_vec();
            for j in 0..m {
                if free[1 + j] {
                    t[1 + j] = medians[j].ln() + rng.uniform_in(-(10f64.ln()), 10f64.ln());
                }
                if m > 1 && free[1 + m + j] {
                    t[1 + m + j] = rng.normal();
                }
            }
            if free[0] {
                t[0] = rng.uniform_in(0.1f64.ln(), 100f64.ln());
            }
            t.iter_mut()
                .enumerate()
                .for_each(|(i, v)| *v = v.clamp(lo[i], hi[i]));
            starts.push(t);
        }
        let mut best: Option<(f64, Vec<f64>)> = None;
        let mut last_error = None;
        for t0 in starts {
            let mut state: Vec<(Workspace, Option<Vec<f64>>)> = classifiers
                .iter()
                .map(|_| (Workspace::default(), None))
                .collect();
            let mut error = None;
            let mut objective = |t: &[f64]| -> Option<(f64, Vec<f64>)> {
                if spec.newton.cancelled() {
                    error = Some(GpError::Cancelled);
                    return None;
                }
                let parts: Vec<GpResult<(f64, Vec<f64>)>> = classifiers
                    .par_iter()
                    .zip(state.par_iter_mut())
                    .map(|((layout, c), (ws, warm))| {
                        let mut theta = t.to_vec();
                        theta.extend_from_slice(&c.lambdas);
                        let (ev, mode, _, g) =
                            c.problem
                                .evaluate(layout, spec, &theta, warm.as_deref(), true, ws)?;
                        let value = mode.lml;
                        *warm = Some(mode.a);
                        ws.recycle(ev, mode.l);
                        let mut g = g.unwrap_or_default();
                        g.truncate(k);
                        Ok((value, g))
                    })
                    .collect();
                let mut value = 0.0;
                let mut grad = vec![0.0; k];
                for p in parts {
                    match p {
                        Ok((v, g)) => {
                            value += v;
                            grad.iter_mut().zip(g).for_each(|(a, b)| *a += b);
                        }
                        Err(e) => {
                            error = Some(e);
                            return None;
                        }
                    }
                }
                let (lp, gp) = log_prior(prior, t);
                value += lp;
                grad.iter_mut().zip(gp).for_each(|(a, b)| *a += b);
                Some((-value, grad.into_iter().map(|v| -v).collect()))
            };
            let tie = Tie::new(spec.tie_length_scales, m);
            let (z0, z_lo, z_hi, z_free) = (
                tie.reduce(&t0),
                tie.reduce(lo),
                tie.reduce(hi),
                tie.reduce_free(free),
            );
            let mut reduced = |z: &[f64]| -> Option<(f64, Vec<f64>)> {
                let (value, grad) = objective(&tie.expand(z))?;
                Some((value, tie.contract(&grad)))
            };
            let result =
                minimize(&mut reduced, &z0, &z_lo, &z_hi, &z_free, &spec.lbfgs).map(|mut r| {
                    r.x = tie.expand(&r.x);
                    r
                });
            if spec.newton.cancelled() {
                return Err(GpError::Cancelled);
            }
            if error.is_some() {
                last_error = error;
            }
            if let Some(r) = result {
                if best.as_ref().is_none_or(|(f, _)| r.fx < *f) {
                    best = Some((r.fx, r.x));
                }
            }
        }
        best.map(|(_, x)| x).ok_or_else(|| {
            last_error.unwrap_or_else(|| {
                GpError::InvalidInput("no optimiser start could be evaluated".into())
            })
        })
    }
}

/// The map between theta's shared entries and the variables the optimiser moves: the same
/// entries, or with tied length-scales one length-scale for every modality (its log the mean
/// of theirs at the start; its gradient the sum of theirs).
struct Tie {
    on: bool,
    m: usize,
}

impl Tie {
    fn new(on: bool, m: usize) -> Self {
        Tie { on: on && m > 1, m }
    }

    fn reduce(&self, t: &[f64]) -> Vec<f64> {
        if !self.on {
            return t.to_vec();
        }
        let mean = t[1..1 + self.m].iter().sum::<f64>() / self.m as f64;
        let mut z = vec![t[0], mean];
        z.extend_from_slice(&t[1 + self.m..]);
        z
    }

    fn reduce_free(&self, free: &[bool]) -> Vec<bool> {
        if !self.on {
            return free.to_vec();
        }
        let mut z = vec![free[0], free[1..1 + self.m].iter().any(|&f| f)];
        z.extend_from_slice(&free[1 + self.m..]);
        z
    }

    fn expand(&self, z: &[f64]) -> Vec<f64> {
        if !self.on {
            return z.to_vec();
        }
        let mut t = vec![z[0]];
        t.extend(std::iter::repeat_n(z[1], self.m));
        t.extend_from_slice(&z[2..]);
        t
    }

    fn contract(&self, g: &[f64]) -> Vec<f64> {
        if !self.on {
            return g.to_vec();
        }
        let mut z = vec![g[0], g[1..1 + self.m].iter().sum()];
        z.extend_from_slice(&g[1 + self.m..]);
        z
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kernel::Modalities;
    use crate::model::fit;

    fn blobs(n_per: usize, centers: &[[f64; 2]], spread: f64, seed: u64) -> (Data, Vec<usize>) {
        let mut rng = SplitMix64::new(seed);
        let mut v = Vec::new();
        let mut y = Vec::new();
        for (c, ctr) in centers.iter().enumerate() {
            for _ in 0..n_per {
                v.push(ctr[0] + spread * rng.normal());
                v.push(ctr[1] + spread * rng.normal());
                y.push(c);
            }
        }
        (Data::new(v, y.len(), 2).unwrap(), y)
    }

    fn spec(modalities: Modalities) -> ModelSpec {
        let mut spec = ModelSpec::new(modalities);
        spec.length_scales = vec![f64::NAN; spec.modalities.len()];
        spec.n_restarts = 0;
        spec.lbfgs.ftol = 1e-12;
        spec
    }

    fn no_sources(n: usize) -> Vec<Vec<Source>> {
        vec![Vec::new(); n]
    }

    #[test]
    fn one_binary_classifier_is_the_per_classifier_fit() {
        // Two classes without transfer have one classifier: sharing changes nothing.
        let (x, y) = blobs(12, &[[0.0, 0.0], [2.0, 1.0]], 0.8, 3);
        let spec = spec(Modalities::new(vec![vec![0], vec![1]], 2).unwrap());
        let sources = no_sources(2);
        let own = fit(&x, &y, 2, &sources, &spec).unwrap();
        let task = KernelTask {
            x: &x,
            labels: &y,
            n_classes: 2,
            sources: &sources,
        };
        let shared = fit_shared(&[task], 0, &spec).unwrap();
        let (a, b) = (&own.classifiers[0], &shared.classifiers[0]);
        assert!((a.lml - b.lml).abs() < 1e-6, "{} vs {}", a.lml, b.lml);
        for (u, v) in a.theta.iter().zip(&b.theta) {
            assert!((u - v).abs() < 1e-3, "{:?} vs {:?}", a.theta, b.theta);
        }
    }

    #[test]
    fn every_classifier_gets_the_same_kernel_at_a_stationary_point() {
        let (x, y) = blobs(6, &[[0.0, 0.0], [2.0, 1.0], [0.0, 2.5]], 0.7, 5);
        let spec = spec(Modalities::new(vec![vec![0], vec![1]], 2).unwrap());
        let sources = no_sources(3);
        let task = KernelTask {
            x: &x,
            labels: &y,
            n_classes: 3,
            sources: &sources,
        };
        let model = fit_shared(&[task], 0, &spec).unwrap();
        let thetas: Vec<Vec<f64>> = model.classifiers.iter().map(|c| c.theta.clone()).collect();
        assert!(thetas.windows(2).all(|w| w[0] == w[1]));
        // The summed objective's gradient vanishes (the weight logits' sum is the softmax's
        // redundant direction, held by the weak prior's absence only up to that direction).
        let grads = model.log_marginal_likelihood(&thetas, true, false).unwrap();
        let mut total = vec![0.0; thetas[0].len()];
        for (_, g) in grads {
            total.iter_mut().zip(g.unwrap()).for_each(|(a, b)| *a += b);
        }
        for (i, g) in total.iter().enumerate().take(3) {
            assert!(g.abs() < 1e-3, "entry {i}: gradient {g} in {total:?}");
        }
        // And it is a maximum along each coordinate: a step either way lowers the sum.
        let sum_at = |t: &[f64]| -> f64 {
            let rows = vec![t.to_vec(); thetas.len()];
            model
                .log_marginal_likelihood(&rows, false, false)
                .unwrap()
                .iter()
                .map(|(v, _)| v)
                .sum()
        };
        let best = sum_at(&thetas[0]);
        for i in 0..3 {
            for step in [-0.2, 0.2] {
                let mut t = thetas[0].clone();
                t[i] += step;
                assert!(sum_at(&t) < best + 1e-9, "entry {i} step {step}");
            }
        }
    }

    #[test]
    fn a_large_kernel_task_pins_the_kernel_of_a_tiny_target() {
        // 3 objects observed 30 times inform the kernel of 3 other objects observed once.
        let centres = [[0.0, 0.0], [3.0, 0.0], [0.0, 3.0]];
        let (big, big_y) = blobs(30, &centres, 1.2, 11);
        let others = [[6.0, 6.0], [9.0, 6.0], [6.0, 9.0]];
        let (tiny, tiny_y) = blobs(1, &others, 1.2, 12);
        let spec = spec(Modalities::new(vec![vec![0, 1]], 2).unwrap());
        let sources = no_sources(3);
        let alone = fit_shared(
            &[KernelTask {
                x: &big,
                labels: &big_y,
                n_classes: 3,
                sources: &sources,
            }],
            0,
            &spec,
        )
        .unwrap();
        let tasks = [
            KernelTask {
                x: &tiny,
                labels: &tiny_y,
                n_classes: 3,
                sources: &sources,
            },
            KernelTask {
                x: &big,
                labels: &big_y,
                n_classes: 3,
                sources: &sources,
            },
        ];
        let joint = fit_shared(&tasks, 0, &spec).unwrap();
        assert_eq!(joint.x.n, 3, "the model is the target's");
        let tiny_alone = fit_shared(&tasks[..1], 0, &spec).unwrap();
        let (a, b, c) = (
            &alone.classifiers[0].theta,
            &joint.classifiers[0].theta,
            &tiny_alone.classifiers[0].theta,
        );
        // The joint kernel lies near the large task's own, far nearer than the tiny task's.
        let dist = |u: &[f64], v: &[f64]| -> f64 {
            u.iter()
                .zip(v)
                .map(|(p, q)| (p - q).powi(2))
                .sum::<f64>()
                .sqrt()
        };
        assert!(
            dist(a, b) < 0.25 * dist(c, b),
            "large {a:?}, joint {b:?}, tiny {c:?}"
        );
    }

    #[test]
    fn tied_length_scales_are_one_length_scale_at_a_stationary_point() {
        let (x, y) = blobs(6, &[[0.0, 0.0], [2.0, 1.0], [0.0, 2.5]], 0.7, 9);
        let mut spec = spec(Modalities::new(vec![vec![0], vec![1]], 2).unwrap());
        spec.tie_length_scales = true;
        spec.free.weights = false;
        let sources = no_sources(3);
        let task = KernelTask {
            x: &x,
            labels: &y,
            n_classes: 3,
            sources: &sources,
        };
        let model = fit_shared(&[task], 0, &spec).unwrap();
        let theta = model.classifiers[0].theta.clone();
        assert_eq!(theta[1], theta[2], "{theta:?}");
        // Along the tied direction (both length-scales together) and σ² the summed gradient
        // vanishes; each length-scale alone need not.
        let rows = vec![theta.clone(); model.classifiers.len()];
        let mut total = vec![0.0; theta.len()];
        for (_, g) in model.log_marginal_likelihood(&rows, true, false).unwrap() {
            total.iter_mut().zip(g.unwrap()).for_each(|(a, b)| *a += b);
        }
        assert!(total[0].abs() < 1e-3, "{total:?}");
        assert!((total[1] + total[2]).abs() < 1e-3, "{total:?}");
        // A per-classifier fit cannot tie them.
        let sources2 = no_sources(3);
        assert!(crate::model::fit(&x, &y, 3, &sources2, &spec).is_err());
    }

    #[test]
    fn bad_tasks_are_refused() {
        let (x, y) = blobs(3, &[[0.0, 0.0], [2.0, 1.0]], 0.5, 1);
        let (x3, _) = blobs(2, &[[0.0, 0.0]], 0.5, 1);
        let narrow = Data::new(x3.values[..2].to_vec(), 2, 1).unwrap();
        let spec = spec(Modalities::new(vec![vec![0, 1]], 2).unwrap());
        let sources = no_sources(2);
        let good = KernelTask {
            x: &x,
            labels: &y,
            n_classes: 2,
            sources: &sources,
        };
        assert!(fit_shared(&[good], 1, &spec).is_err());
        let wrong = KernelTask {
            x: &narrow,
            labels: &[0, 1],
            n_classes: 2,
            sources: &sources,
        };
        assert!(fit_shared(&[good, wrong], 0, &spec).is_err());
        let mut free_lambda = spec.clone();
        free_lambda.free.lambda = true;
        assert!(fit_shared(&[good], 0, &free_lambda).is_err());
    }

    #[test]
    fn every_tasks_matrices_count_against_the_memory() {
        // A small target beside a kernel task of 3 million rows (48 MB of data): that task's
        // n x n matrices (72 TB each) are refused before any is allocated.
        let (x, y) = blobs(6, &[[0.0, 0.0], [2.0, 1.0]], 0.7, 2);
        let n = 3_000_000;
        let big = Data::new(vec![0.5; 2 * n], n, 2).unwrap();
        let big_y: Vec<usize> = (0..n).map(|i| i % 2).collect();
        let spec = spec(Modalities::new(vec![vec![0, 1]], 2).unwrap());
        let sources = no_sources(2);
        let small = KernelTask {
            x: &x,
            labels: &y,
            n_classes: 2,
            sources: &sources,
        };
        let large = KernelTask {
            x: &big,
            labels: &big_y,
            n_classes: 2,
            sources: &sources,
        };
        assert!(fit_shared(&[small], 0, &spec).is_ok());
        match fit_shared(&[small, large], 0, &spec) {
            Err(GpError::TooLarge {
                rows,
                bytes,
                message,
            }) => {
                assert_eq!(rows, n);
                assert!(bytes > 72_000_000_000_000);
                assert!(
                    message.contains(&format!("shared-kernel fit on {} rows", n + 12)),
                    "{message}"
                );
            }
            other => panic!("expected TooLarge, got {:?}", other.err()),
        }
    }
}
