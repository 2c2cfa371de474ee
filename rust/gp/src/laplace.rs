//! Binary Laplace-approximation GP classification with the logistic likelihood
//! (Rasmussen & Williams, GPML, Algorithms 3.1, 3.2 and 5.1). Labels are ±1.
//!
//! The latent function is `f = m + g` with a constant prior mean `m` (the `offset`; 0 for the
//! zero-mean GP) and `g ~ GP(0, K)`. The algorithms run on `g` unchanged, with the likelihood
//! `p(y | g + m)`: every derivative of `log p(y | g + m)` with respect to `g` is the one with
//! respect to `f`, so Algorithms 3.1 and 5.1 hold as written with `f` in the likelihood's place
//! and `g` in the prior's (GPML §2.7, mean functions).

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use faer::{Mat, MatRef};

use crate::error::{GpError, GpResult};
use crate::kernel::{Hyper, KernelEval, Layout, PairDistances};
use crate::likelihood::{log_sigmoid, sigmoid};
use crate::linalg::{self, InverseScratch};

/// Newton mode-finding settings.
#[derive(Debug, Clone)]
pub struct NewtonConfig {
    pub max_iter: usize,
    /// Stop when the objective Ψ(f) changes by less than this.
    pub tol: f64,
    /// Set from another thread to stop a fit between Newton iterations (e.g. on Ctrl-C).
    pub cancel: Option<Arc<AtomicBool>>,
    /// Take steps on an earlier factorisation of B while they converge fast enough (see
    /// [`find_mode`]), from [`REUSE_MIN_ROWS`] rows on; false: a factorisation per step (plain
    /// Newton).
    pub reuse_factorisation: bool,
}

impl NewtonConfig {
    pub fn cancelled(&self) -> bool {
        self.cancel
            .as_ref()
            .is_some_and(|c| c.load(Ordering::Relaxed))
    }
}

impl Default for NewtonConfig {
    fn default() -> Self {
        NewtonConfig {
            max_iter: 100,
            tol: 1e-10,
            cancel: None,
            reuse_factorisation: true,
        }
    }
}

/// Why mode finding stopped without a mode.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ModeFailure {
    /// The Cholesky factorisation of B failed at this pivot.
    Pivot(usize),
    /// The cancel flag was set.
    Cancelled,
}

/// The posterior mode and everything Algorithms 3.2 and 5.1 reuse.
pub struct Mode {
    /// The mode of `g = f - m` (the latent function less its prior mean).
    pub f: Vec<f64>,
    /// `a = K⁻¹ g`; at convergence it equals `∇ log p(y | f) = t - π`.
    pub a: Vec<f64>,
    pub pi: Vec<f64>,
    pub sw: Vec<f64>,
    /// Lower Cholesky factor of `B = I + W½ K W½`.
    pub l: Mat<f64>,
    pub lml: f64,
    /// Steps taken (exact Newton steps and steps on a reused factorisation).
    pub iterations: usize,
    /// Cholesky factorisations of B, the final one at the mode included.
    pub factorisations: usize,
    pub converged: bool,
}

/// `Ψ(g) = -½ aᵀ g + Σ log σ(y (g + m))`.
fn objective(a: &[f64], f: &[f64], y: &[f64], offset: f64) -> f64 {
    let quad: f64 = a.iter().zip(f).map(|(a, f)| a * f).sum();
    let lik: f64 = f
        .iter()
        .zip(y)
        .map(|(f, y)| log_sigmoid(y * (f + offset)))
        .sum();
    -0.5 * quad + lik
}

/// `W½` and the Cholesky factor of `B` at latent values `f`. Err carries the failing pivot.
/// The factor is written into `b` (n × n, reused across Newton iterations: one n × n buffer
/// per mode search instead of one per iteration).
fn factor_b(
    k: MatRef<'_, f64>,
    f: &[f64],
    offset: f64,
    b: &mut Mat<f64>,
) -> Result<(Vec<f64>, Vec<f64>), usize> {
    let n = f.len();
    let pi: Vec<f64> = f.iter().map(|&v| sigmoid(v + offset)).collect();
    let sw: Vec<f64> = pi.iter().map(|p| (p * (1.0 - p)).sqrt()).collect();
    // Only the lower triangle is read; the factorisation zeroes the strictly upper one.
    for j in 0..n {
        let (dst, src) = (b.col_as_slice_mut(j), k.col(j));
        for i in j..n {
            dst[i] = sw[i] * src[i] * sw[j];
        }
        dst[j] += 1.0;
    }
    linalg::cholesky_lower(b)?;
    Ok((pi, sw))
}

/// Largest number of steps on one factorisation of B before it is renewed.
const MAX_STEPS_PER_FACTOR: usize = 25;
/// Below this many rows a factorisation costs little more than a step on an old one, and
/// plain Newton is faster (measured: 4–8 % at n = 30–100, the reverse from n = 200 on).
pub const REUSE_MIN_ROWS: usize = 200;
/// A step on an older factorisation must shrink the change of Ψ at least this much relative to
/// the step before; otherwise B is factorised again at the current f.
const REUSE_CONTRACTION: f64 = 0.25;

/// Algorithm 3.1 with a step-halving safeguard (the plain Newton step can overshoot when the
/// kernel is large), warm-started from `warm_a` when given and better than f = 0.
/// Fails with the failing Cholesky pivot, or when the configuration's cancel flag is set.
///
/// **Steps on a reused factorisation.** Newton's step solves `(K⁻¹ + W) Δ = ∇Ψ` with W at the
/// current f, which costs one Cholesky factorisation (n³/3) per iteration. Any fixed positive
/// (semi-)definite W̃ in place of W gives an ascent direction of the concave Ψ whose fixed point
/// is still the mode (`(K⁻¹ + W̃) f = W̃ f + ∇log p(y|f)` ⇔ `f = K ∇log p(y|f)`), converging
/// linearly instead of quadratically: a "chord" (simplified Newton) step, O(n²) with the
/// factor of `I + W̃½ K W̃½` kept from an earlier iterate. B is factorised again when such a
/// step contracts too slowly, needed halving, or after [`MAX_STEPS_PER_FACTOR`] steps, and
/// always before the step that may end the search: the search stops only after an **exact**
/// Newton step changes Ψ by less than `tol`, as before, so the mode is as accurate as a pure
/// Newton search's. `max_iter` caps the factorisations (the exact Newton iterations).
pub fn find_mode(
    k: MatRef<'_, f64>,
    y: &[f64],
    offset: f64,
    warm_a: Option<&[f64]>,
    cfg: &NewtonConfig,
) -> Result<Mode, ModeFailure> {
    find_mode_in(k, y, offset, warm_a, cfg, Mat::zeros(0, 0))
}

/// As [`find_mode`], writing B's factor into `buffer` (resized to n × n if needed), so that a
/// caller evaluating many hyper-parameters reuses one allocation.
pub fn find_mode_in(
    k: MatRef<'_, f64>,
    y: &[f64],
    offset: f64,
    warm_a: Option<&[f64]>,
    cfg: &NewtonConfig,
    buffer: Mat<f64>,
) -> Result<Mode, ModeFailure> {
    let n = y.len();
    let mut a = vec![0.0; n];
    let mut f = vec![0.0; n];
    let mut psi = objective(&a, &f, y, offset);
    if let Some(w) = warm_a {
        let mut fw = vec![0.0; n];
        linalg::matvec(k, w, &mut fw);
        let psi_w = objective(w, &fw, y, offset);
        if psi_w > psi {
            a.copy_from_slice(w);
            f = fw;
            psi = psi_w;
        }
    }
    let mut l = buffer;
    if l.nrows() != n || l.ncols() != n {
        l = Mat::<f64>::zeros(n, n);
    }
    let reuse = cfg.reuse_factorisation && n >= REUSE_MIN_ROWS;
    let mut converged = false;
    let mut iterations = 0;
    let mut factorisations = 0;
    let mut kb = vec![0.0; n];
    let mut f_new = vec![0.0; n];
    // W̃½ of the factor held in `l`; valid once `factorisations > 0`.
    let mut sw_fac = vec![0.0; n];
    let mut refactor = true;
    let mut steps_on_factor = 0;
    let mut last_change = f64::INFINITY;
    loop {
        if cfg.cancelled() {
            return Err(ModeFailure::Cancelled);
        }
        if refactor {
            if factorisations == cfg.max_iter {
                break;
            }
            let (_, sw) = factor_b(k, &f, offset, &mut l).map_err(ModeFailure::Pivot)?;
            sw_fac = sw;
            factorisations += 1;
            steps_on_factor = 0;
        }
        let exact = steps_on_factor == 0;
        steps_on_factor += 1;
        iterations += 1;
        // b = W̃ g + ∇log p(y|f), with ∇log p = t - π(f), f = g + m and t = (y + 1) / 2.
        let b: Vec<f64> = (0..n)
            .map(|i| sw_fac[i] * sw_fac[i] * f[i] + (0.5 * (y[i] + 1.0) - sigmoid(f[i] + offset)))
            .collect();
        linalg::matvec(k, &b, &mut kb);
        let mut v: Vec<f64> = (0..n).map(|i| sw_fac[i] * kb[i]).collect();
        linalg::solve_lower(l.as_ref(), &mut v);
        linalg::solve_lower_transpose(l.as_ref(), &mut v);
        let a_full: Vec<f64> = (0..n).map(|i| b[i] - sw_fac[i] * v[i]).collect();
        // Halve the step in a-space until the objective does not decrease.
        let mut step = 1.0;
        let mut a_new = a_full.clone();
        let mut psi_new;
        loop {
            linalg::matvec(k, &a_new, &mut f_new);
            psi_new = objective(&a_new, &f_new, y, offset);
            if psi_new >= psi - 1e-12 * psi.abs().max(1.0) || step < 1e-6 {
                break;
            }
            step *= 0.5;
            for i in 0..n {
                a_new[i] = a[i] + step * (a_full[i] - a[i]);
            }
        }
        let change = (psi_new - psi).abs();
        a = a_new;
        std::mem::swap(&mut f, &mut f_new);
        psi = psi_new;
        if change < cfg.tol {
            if exact {
                converged = true;
                break;
            }
            // Only an exact Newton step may end the search.
            refactor = true;
        } else {
            refactor = !reuse
                || step < 1.0
                || (!exact && change > REUSE_CONTRACTION * last_change)
                || steps_on_factor >= MAX_STEPS_PER_FACTOR;
        }
        last_change = change;
    }
    let (pi, sw) = factor_b(k, &f, offset, &mut l).map_err(ModeFailure::Pivot)?;
    let log_det_half: f64 = (0..n).map(|i| l[(i, i)].ln()).sum();
    let lml = objective(&a, &f, y, offset) - log_det_half;
    Ok(Mode {
        f,
        a,
        pi,
        sw,
        l,
        lml,
        iterations,
        factorisations: factorisations + 1,
        converged,
    })
}

/// The jitter policy of [`find_mode_with_jitter`]: up to `max`, in units of the signal
/// variance σ².
#[derive(Clone, Copy, Debug)]
pub struct Jitter {
    pub max: f64,
    pub signal_variance: f64,
}

/// Mode-finding with the jitter policy: if `B` cannot be factorised, add
/// `jitter · σ²` to K's diagonal for jitter = 1e-10, 1e-8, ... up to `jitter.max`, then fail.
/// `factor_buffer` (any size; resized if needed) receives B's factor, see [`find_mode_in`].
pub fn find_mode_with_jitter(
    eval: KernelEval,
    y: &[f64],
    offset: f64,
    warm_a: Option<&[f64]>,
    cfg: &NewtonConfig,
    policy: Jitter,
    factor_buffer: Mat<f64>,
) -> GpResult<(KernelEval, Mode)> {
    if let Some(bad) = eval
        .k
        .col_iter()
        .flat_map(|c| c.iter())
        .find(|v| !v.is_finite())
    {
        return Err(GpError::NonFinite(format!(
            "the kernel matrix contains a non-finite value ({bad}); the hyper-parameters are out of range"
        )));
    }
    let mut eval = eval;
    let mut jitter = 0.0;
    let mut buffer = Some(factor_buffer);
    loop {
        let buffer = buffer.take().unwrap_or_else(|| Mat::<f64>::zeros(0, 0));
        match find_mode_in(eval.k.as_ref(), y, offset, warm_a, cfg, buffer) {
            Ok(mode) => return Ok((eval, mode)),
            Err(ModeFailure::Cancelled) => return Err(GpError::Cancelled),
            Err(ModeFailure::Pivot(pivot)) => {
                let next = if jitter == 0.0 { 1e-10 } else { jitter * 100.0 };
                if next > policy.max * (1.0 + 1e-12) {
                    return Err(GpError::NotPositiveDefinite { pivot, jitter });
                }
                jitter = next;
                eval = eval.with_jitter(jitter, policy.signal_variance);
            }
        }
    }
}

/// Gradient of the Laplace log marginal likelihood with respect to every entry of theta
/// (Algorithm 5.1).
pub fn lml_gradient(
    layout: &Layout,
    h: &Hyper,
    dist: &PairDistances,
    eval: &KernelEval,
    mode: &Mode,
) -> Vec<f64> {
    lml_gradient_in(layout, h, dist, eval, mode, &mut InverseScratch::default())
}

/// As [`lml_gradient`], with the n × n working matrices kept in `scratch` for the next call.
pub fn lml_gradient_in(
    layout: &Layout,
    h: &Hyper,
    dist: &PairDistances,
    eval: &KernelEval,
    mode: &Mode,
    scratch: &mut InverseScratch,
) -> Vec<f64> {
    let n = mode.f.len();
    let k = &eval.k;
    linalg::inverse_from_cholesky_in(mode.l.as_ref(), scratch);
    let z = &mut scratch.out;
    // s2 = ∂LML/∂f̂ = -½ diag(Σ) ∘ ∂W/∂f, with Σ = (K⁻¹ + W)⁻¹ and, for the logistic,
    // ∂W_ii/∂f_i = π(1-π)(1-2π) (= -∇³ log p; GPML writes this factor as ∇³ log p).
    // Since W½ K W½ = B - I, Σ = W^-½ (I - B⁻¹) W^-½: diag(Σ)_j = (1 - B⁻¹_jj) / w_j, and w_j
    // cancels against ∂W/∂f's factor π(1-π) = w_j. This needs only B⁻¹'s diagonal instead of
    // the n³ solve C = L⁻¹ W½ K of GPML's Algorithm 5.1, and it stays exact when w_j → 0.
    let s2: Vec<f64> = (0..n)
        .map(|j| {
            let p = mode.pi[j];
            -0.5 * (1.0 - z[(j, j)]) * (1.0 - 2.0 * p)
        })
        .collect();
    // Z = W½ B⁻¹ W½ (GPML's R), in place.
    for j in 0..n {
        let swj = mode.sw[j];
        for (i, v) in z.col_as_slice_mut(j).iter_mut().enumerate() {
            *v *= mode.sw[i] * swj;
        }
    }
    // ∂LML/∂θ = ½ aᵀ C a - ½ tr(Z C) + s2ᵀ (b - K Z b), b = C ∇log p = C a at the mode, with
    // C = ∂K/∂θ; the first two terms are Σ_ij G_ij C_ij with G = ½ (a aᵀ - Z), formed on the fly.
    // K and Z are symmetric, so s2ᵀ K Z b = (Z K s2)ᵀ b: one vector u = Z K s2 serves every θ
    // (two matrix-vector products instead of two per hyper-parameter).
    let (s1, bs) = eval.contract_gradients(layout, h, dist, z, &mode.a);
    let mut ks2 = vec![0.0; n];
    let mut u = vec![0.0; n];
    linalg::matvec(k.as_ref(), &s2, &mut ks2);
    linalg::matvec(z.as_ref(), &ks2, &mut u);
    s1.iter()
        .zip(bs.iter())
        .map(|(s1p, b)| s1p + (0..n).map(|i| (s2[i] - u[i]) * b[i]).sum::<f64>())
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kernel::{Data, Modalities};

    #[test]
    fn mode_satisfies_the_fixed_point() {
        // At the mode, g = K ∇log p(y | g + m), for the zero mean and for a constant mean m.
        let x = Data::new(
            (0..20).map(|i| (i as f64 * 0.37).sin() * 2.0).collect(),
            10,
            2,
        )
        .unwrap();
        let y: Vec<f64> = (0..10)
            .map(|i| if i % 3 == 0 { 1.0 } else { -1.0 })
            .collect();
        let mods = Modalities::all_columns(2);
        let dist = PairDistances::new(&x, &[], &mods, &crate::kernel::column_means(&x));
        let h = Hyper {
            signal_variance: 4.0,
            length_scales: vec![0.7],
            weights: vec![1.0],
            lambdas: vec![],
        };
        let ev = KernelEval::new(&dist, &h);
        for offset in [0.0, -1.3, 2.1] {
            let mode =
                find_mode(ev.k.as_ref(), &y, offset, None, &NewtonConfig::default()).unwrap();
            assert!(mode.converged);
            let grad: Vec<f64> = (0..10)
                .map(|i| 0.5 * (y[i] + 1.0) - sigmoid(mode.f[i] + offset))
                .collect();
            let mut kg = vec![0.0; 10];
            linalg::matvec(ev.k.as_ref(), &grad, &mut kg);
            for i in 0..10 {
                assert!(
                    (kg[i] - mode.f[i]).abs() < 1e-6,
                    "offset {offset}: {} vs {}",
                    kg[i],
                    mode.f[i]
                );
                assert!((mode.pi[i] - sigmoid(mode.f[i] + offset)).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn a_constant_mean_is_the_zero_mean_problem_with_a_shifted_likelihood() {
        // With a kernel far smaller than the offset's effect the mode stays near g = 0, so the
        // probabilities at the data are σ(m) and the LML tends to Σ log σ(y m).
        let y = [1.0, -1.0, -1.0, -1.0];
        let k = Mat::<f64>::from_fn(4, 4, |i, j| if i == j { 1e-9 } else { 0.0 });
        let m = (1.5f64 / 3.5).ln();
        let mode = find_mode(k.as_ref(), &y, m, None, &NewtonConfig::default()).unwrap();
        let expected: f64 = y.iter().map(|v| log_sigmoid(v * m)).sum();
        assert!(
            (mode.lml - expected).abs() < 1e-8,
            "{} vs {expected}",
            mode.lml
        );
        for p in &mode.pi {
            assert!((p - 1.5 / 5.0).abs() < 1e-8);
        }
    }

    #[test]
    fn reused_factorisations_reach_the_plain_newton_mode_with_fewer_factorisations() {
        let rows = REUSE_MIN_ROWS + 40;
        let x = Data::new(
            (0..rows * 3)
                .map(|i| ((i * 13) as f64 * 0.23).sin() * 2.0)
                .collect(),
            rows,
            3,
        )
        .unwrap();
        let y: Vec<f64> = (0..rows)
            .map(|i| if (i * 7) % 5 < 2 { 1.0 } else { -1.0 })
            .collect();
        let mods = Modalities::all_columns(3);
        let dist = PairDistances::new(&x, &[], &mods, &crate::kernel::column_means(&x));
        let layout = Layout {
            n_modalities: 1,
            n_lambdas: 0,
        };
        for theta in [[0.0, 0.0], [4.0, 0.5], [6.0, -0.5], [2.0, 1.5]] {
            let ev = KernelEval::new(&dist, &layout.decode(&theta).unwrap());
            let warm = find_mode(ev.k.as_ref(), &y, 0.0, None, &NewtonConfig::default())
                .unwrap()
                .a
                .iter()
                .map(|v| v * 0.7)
                .collect::<Vec<_>>();
            for start in [None, Some(warm.as_slice())] {
                let run = |reuse| {
                    let cfg = NewtonConfig {
                        reuse_factorisation: reuse,
                        ..NewtonConfig::default()
                    };
                    find_mode(ev.k.as_ref(), &y, 0.0, start, &cfg).unwrap()
                };
                let (plain, reused) = (run(false), run(true));
                assert!(plain.converged && reused.converged);
                assert_eq!(plain.factorisations, plain.iterations + 1);
                assert!(reused.factorisations <= plain.factorisations, "{theta:?}");
                // Steps on a kept factor were taken (not plain Newton in disguise).
                assert!(reused.iterations + 1 > reused.factorisations, "{theta:?}");
                assert!(
                    (plain.lml - reused.lml).abs() < 1e-9 * plain.lml.abs(),
                    "{theta:?}: {} vs {}",
                    plain.lml,
                    reused.lml
                );
                let scale = plain.f.iter().fold(1.0f64, |m, v| m.max(v.abs()));
                for (p, r) in plain.f.iter().zip(&reused.f) {
                    assert!((p - r).abs() < 1e-6 * scale, "{theta:?}: f {p} vs {r}");
                }
            }
        }
    }

    #[test]
    fn gradient_matches_finite_differences() {
        let x = Data::new(
            (0..36)
                .map(|i| ((i * 7) as f64 * 0.31).cos() * 1.5)
                .collect(),
            12,
            3,
        )
        .unwrap();
        let y: Vec<f64> = (0..12)
            .map(|i| if (i * 5) % 7 < 3 { 1.0 } else { -1.0 })
            .collect();
        let mods = Modalities::new(vec![vec![0, 1], vec![2]], 3).unwrap();
        // Two source tasks of 2 rows each: every λ's derivative, including the source-source
        // coupling λ_1 λ_2, is checked.
        let dist = PairDistances::new(&x, &[2, 2], &mods, &crate::kernel::column_means(&x));
        let layout = Layout {
            n_modalities: 2,
            n_lambdas: 2,
        };
        let theta = vec![1.1, -0.2, 0.4, 0.3, -0.5, 0.35, -0.6];
        let cfg = NewtonConfig {
            max_iter: 200,
            tol: 1e-14,
            cancel: None,
            reuse_factorisation: true,
        };
        // The zero mean and a constant mean (the gradient treats it as fixed).
        for offset in [0.0, -1.7] {
            let lml = |t: &[f64]| {
                let h = layout.decode(t).unwrap();
                let ev = KernelEval::new(&dist, &h);
                find_mode(ev.k.as_ref(), &y, offset, None, &cfg)
                    .unwrap()
                    .lml
            };
            let h = layout.decode(&theta).unwrap();
            let ev = KernelEval::new(&dist, &h);
            let mode = find_mode(ev.k.as_ref(), &y, offset, None, &cfg).unwrap();
            let grad = lml_gradient(&layout, &h, &dist, &ev, &mode);
            for p in 0..theta.len() {
                let e = 1e-5;
                let mut tp = theta.clone();
                let mut tm = theta.clone();
                tp[p] += e;
                tm[p] -= e;
                let fd = (lml(&tp) - lml(&tm)) / (2.0 * e);
                assert!(
                    (fd - grad[p]).abs() < 1e-6 * (1.0 + fd.abs()),
                    "offset {offset}, param {p}: fd {fd} vs analytic {}",
                    grad[p]
                );
            }
        }
    }

    /// The mode of labels (+1, -1) on the 2 × 2 kernel `k`, with jitter up to 1e-6 σ².
    fn mode_with_jitter(k: Mat<f64>, cfg: &NewtonConfig) -> GpResult<(KernelEval, Mode)> {
        let ev = KernelEval {
            k,
            parts: vec![],
            jitter: 0.0,
        };
        let policy = Jitter {
            max: 1e-6,
            signal_variance: 1.0,
        };
        find_mode_with_jitter(ev, &[1.0, -1.0], 0.0, None, cfg, policy, Mat::zeros(0, 0))
    }

    #[test]
    fn indefinite_kernel_raises_after_jitter() {
        // A kernel with a large negative eigenvalue cannot be rescued by small jitter.
        let k = Mat::<f64>::from_fn(2, 2, |i, j| if i == j { 1.0 } else { 30.0 });
        let r = mode_with_jitter(k, &NewtonConfig::default());
        assert!(
            matches!(r, Err(GpError::NotPositiveDefinite { .. })),
            "{:?}",
            r.err()
        );
    }

    #[test]
    fn slightly_indefinite_kernel_is_rescued_by_jitter() {
        // B = I + W½KW½ with W = 1/4 at f = 0 has an exact zero pivot when K_00 = -4; the
        // smallest jitter makes it factorisable again.
        let k = Mat::<f64>::from_fn(2, 2, |i, j| match (i, j) {
            (0, 0) => -4.0,
            (1, 1) => 1.0,
            _ => 0.0,
        });
        let cfg = NewtonConfig {
            max_iter: 1,
            tol: 1e-10,
            cancel: None,
            reuse_factorisation: true,
        };
        let r = mode_with_jitter(k, &cfg);
        match r {
            Ok((ev, _)) => assert!(ev.jitter > 0.0 && ev.jitter <= 1e-6),
            Err(e) => panic!("expected jitter to rescue the factorisation: {e}"),
        }
    }
}
