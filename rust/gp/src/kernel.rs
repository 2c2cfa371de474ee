//! The multi-modal RBF kernel of docs/design.md §5 (paper Eq. 1) and its dependent (transfer)
//! variant (paper Eq. 2), with hyper-parameters in an unconstrained "theta" vector.
//!
//! `K(x, x') = σ² · Σ_m γ_m exp(-|x_m - x'_m|² / (2 ℓ_m²)) · B[task(x), task(x')]` where `x_m`
//! is modality m's block of feature columns, `γ = softmax(η)` lies on the simplex, and B is the
//! task coupling of [`Coupling`]: with S source tasks and the target task last,
//! `B = v vᵀ + diag(1 - λ_1², …, 1 - λ_S², 0)` with `v = (λ_1, …, λ_S, 1)`. B is PSD for every
//! λ_s ∈ [-1, 1] (a sum of PSD matrices), and the elementwise (Schur) product of two PSD
//! matrices is PSD, so K is PSD. With one source, B = [[1, λ], [λ, 1]]: the paper's Eq. 2.
//!
//! theta layout: `[log σ², log ℓ_1..ℓ_M, η_1..η_M (only if M > 1), λ_1..λ_L (with transfer)]`.
//! The reported logits are normalised (`η_m = log γ_m`), and each λ is kept on its natural scale.

use faer::linalg::matmul::matmul;
use faer::{Accum, Mat, Par};

use crate::fastmath::exp_nonpositive_in_place;

use crate::error::{GpError, GpResult};

/// Row-major feature matrix.
#[derive(Debug, Clone, PartialEq)]
pub struct Data {
    pub values: Vec<f64>,
    pub n: usize,
    pub d: usize,
}

impl Data {
    pub fn new(values: Vec<f64>, n: usize, d: usize) -> GpResult<Self> {
        if values.len() != n * d {
            return Err(GpError::InvalidInput(format!(
                "feature buffer has {} values, expected {n} x {d}",
                values.len()
            )));
        }
        Ok(Data { values, n, d })
    }

    #[inline]
    pub fn row(&self, i: usize) -> &[f64] {
        &self.values[i * self.d..(i + 1) * self.d]
    }

    /// Fails on the first NaN or infinity, naming `what`, the row and the column.
    pub fn check_finite(&self, what: &str) -> GpResult<()> {
        if let Some(pos) = self.values.iter().position(|v| !v.is_finite()) {
            return Err(GpError::NonFinite(format!(
                "{what} contains a non-finite value ({}) at row {}, column {}",
                self.values[pos],
                pos / self.d.max(1),
                pos % self.d.max(1)
            )));
        }
        Ok(())
    }

    /// Rows of `self` followed by the rows of `other`.
    pub fn stacked(&self, other: &Data) -> Data {
        let mut values = Vec::with_capacity(self.values.len() + other.values.len());
        values.extend_from_slice(&self.values);
        values.extend_from_slice(&other.values);
        Data {
            values,
            n: self.n + other.n,
            d: self.d,
        }
    }
}

/// Which hyper-parameters theta holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Layout {
    pub n_modalities: usize,
    /// Transfer relatedness entries (the most sources any classifier has; 0 without transfer).
    pub n_lambdas: usize,
}

/// Lowest logit stored for a weight of 0 (γ ≈ 1e-22 relative).
const MIN_LOGIT: f64 = -50.0;

impl Layout {
    pub fn has_weights(&self) -> bool {
        self.n_modalities > 1
    }
    pub fn len(&self) -> usize {
        1 + self.n_modalities
            + if self.has_weights() {
                self.n_modalities
            } else {
                0
            }
            + self.n_lambdas
    }
    pub fn transfer(&self) -> bool {
        self.n_lambdas > 0
    }
    pub fn is_empty(&self) -> bool {
        false
    }
    pub const SIGNAL: usize = 0;
    pub fn length_scale(&self, m: usize) -> usize {
        1 + m
    }
    pub fn weight(&self, m: usize) -> Option<usize> {
        self.has_weights().then(|| 1 + self.n_modalities + m)
    }
    /// Index of source s's λ in theta.
    pub fn lambda(&self, s: usize) -> Option<usize> {
        (s < self.n_lambdas).then(|| self.len() - self.n_lambdas + s)
    }

    pub fn names(&self, modality_names: &[String]) -> Vec<String> {
        let mut names = vec!["log_signal_variance".to_string()];
        for m in 0..self.n_modalities {
            names.push(format!("log_length_scale[{}]", modality_names[m]));
        }
        if self.has_weights() {
            for m in 0..self.n_modalities {
                names.push(format!("weight_logit[{}]", modality_names[m]));
            }
        }
        if self.n_lambdas == 1 {
            names.push("transfer_lambda".to_string());
        } else {
            names.extend((0..self.n_lambdas).map(|s| format!("transfer_lambda[{s}]")));
        }
        names
    }

    /// Natural-scale hyper-parameters from theta.
    pub fn decode(&self, theta: &[f64]) -> GpResult<Hyper> {
        if theta.len() != self.len() {
            return Err(GpError::InvalidInput(format!(
                "theta has {} entries, this model has {} hyper-parameters",
                theta.len(),
                self.len()
            )));
        }
        if let Some(bad) = theta.iter().position(|v| !v.is_finite()) {
            return Err(GpError::NonFinite(format!(
                "theta[{bad}] is not finite ({})",
                theta[bad]
            )));
        }
        let m = self.n_modalities;
        let signal_variance = theta[0].exp();
        let length_scales: Vec<f64> = theta[1..=m].iter().map(|v| v.exp()).collect();
        let weights = if self.has_weights() {
            softmax(&theta[1 + m..1 + 2 * m])
        } else {
            vec![1.0]
        };
        let lambdas = theta[self.len() - self.n_lambdas..].to_vec();
        if let Some(l) = lambdas.iter().find(|l| !(-1.0..=1.0).contains(*l)) {
            return Err(GpError::InvalidInput(format!(
                "transfer lambda must lie in [-1, 1] (the dependent kernel is indefinite otherwise), got {l}"
            )));
        }
        Ok(Hyper {
            signal_variance,
            length_scales,
            weights,
            lambdas,
        })
    }

    pub fn encode(&self, h: &Hyper) -> Vec<f64> {
        let mut theta = Vec::with_capacity(self.len());
        theta.push(h.signal_variance.ln());
        theta.extend(h.length_scales.iter().map(|l| l.ln()));
        if self.has_weights() {
            let total: f64 = h.weights.iter().sum();
            theta.extend(h.weights.iter().map(|w| (w / total).ln().max(MIN_LOGIT)));
        }
        theta.extend((0..self.n_lambdas).map(|s| h.lambdas.get(s).copied().unwrap_or(0.0)));
        theta
    }
}

pub fn softmax(logits: &[f64]) -> Vec<f64> {
    let max = logits.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
    let e: Vec<f64> = logits.iter().map(|v| (v - max).exp()).collect();
    let s: f64 = e.iter().sum();
    e.into_iter().map(|v| v / s).collect()
}

/// Natural-scale hyper-parameters.
#[derive(Debug, Clone, PartialEq)]
pub struct Hyper {
    pub signal_variance: f64,
    pub length_scales: Vec<f64>,
    pub weights: Vec<f64>,
    /// Relatedness of each source task to the target task.
    pub lambdas: Vec<f64>,
}

/// The task coupling matrix B (T × T, T = sources + 1, the target task last) and its
/// derivatives with respect to each λ_s.
#[derive(Debug, Clone)]
pub struct Coupling {
    pub n_tasks: usize,
    lambdas: Vec<f64>,
    b: Vec<f64>,
}

impl Coupling {
    /// Coupling of `n_sources` source tasks, using the first `n_sources` relatedness values.
    pub fn new(lambdas: &[f64], n_sources: usize) -> Self {
        let t = n_sources + 1;
        let mut v: Vec<f64> = lambdas[..n_sources].to_vec();
        v.push(1.0);
        let mut b = vec![0.0; t * t];
        for i in 0..t {
            for j in 0..t {
                b[i * t + j] = if i == j { 1.0 } else { v[i] * v[j] };
            }
        }
        Coupling {
            n_tasks: t,
            lambdas: v,
            b,
        }
    }

    #[inline]
    pub fn get(&self, ti: usize, tj: usize) -> f64 {
        self.b[ti * self.n_tasks + tj]
    }

    /// The whole matrix, row-major.
    pub fn matrix(&self) -> &[f64] {
        &self.b
    }

    /// `∂B[ti, tj] / ∂λ_s`: B's off-diagonal entries are products `v_i v_j` with v's last entry
    /// 1, so the derivative is `v_j` on row s, `v_i` on column s, 0 on the diagonal.
    #[inline]
    pub fn derivative(&self, s: usize, ti: usize, tj: usize) -> f64 {
        if ti == tj || s + 1 >= self.n_tasks {
            0.0
        } else if ti == s {
            self.lambdas[tj]
        } else if tj == s {
            self.lambdas[ti]
        } else {
            0.0
        }
    }
}

/// Validated modality column groups.
#[derive(Debug, Clone, PartialEq)]
pub struct Modalities {
    pub groups: Vec<Vec<usize>>,
}

impl Modalities {
    pub fn new(groups: Vec<Vec<usize>>, d: usize) -> GpResult<Self> {
        if groups.is_empty() {
            return Err(GpError::InvalidInput(
                "at least one modality is needed".into(),
            ));
        }
        for (m, g) in groups.iter().enumerate() {
            if g.is_empty() {
                return Err(GpError::InvalidInput(format!(
                    "modality {m} has no feature columns"
                )));
            }
            if let Some(c) = g.iter().find(|&&c| c >= d) {
                return Err(GpError::InvalidInput(format!(
                    "modality {m} refers to column {c}, but the data have {d} columns"
                )));
            }
        }
        Ok(Modalities { groups })
    }

    pub fn all_columns(d: usize) -> Self {
        Modalities {
            groups: vec![(0..d).collect()],
        }
    }

    pub fn len(&self) -> usize {
        self.groups.len()
    }

    pub fn is_empty(&self) -> bool {
        self.groups.is_empty()
    }

    /// Squared distances `|a_i - b_j|²` over modality m's columns, shape (a.n, b.n).
    ///
    /// Computed as `|a|² + |b|² - 2 a·b` with one matrix product (the bulk of kernel
    /// construction). Rows are first centred by `center` (the training columns' means):
    /// distances do not change, and the expansion then loses no precision to large offsets.
    pub fn sq_distances(&self, m: usize, a: &Data, b: &Data, center: &[f64]) -> Mat<f64> {
        let cols = &self.groups[m];
        let block = |x: &Data| {
            Mat::<f64>::from_fn(x.n, cols.len(), |i, k| {
                x.values[i * x.d + cols[k]] - center[cols[k]]
            })
        };
        let (ab, bb) = (block(a), block(b));
        let norms = |x: &Mat<f64>| -> Vec<f64> {
            (0..x.nrows())
                .map(|i| (0..x.ncols()).map(|k| x[(i, k)] * x[(i, k)]).sum())
                .collect()
        };
        let (na, nb) = (norms(&ab), norms(&bb));
        let mut d = Mat::<f64>::zeros(a.n, b.n);
        matmul(
            d.as_mut(),
            Accum::Replace,
            ab.as_ref(),
            bb.as_ref().transpose(),
            -2.0,
            Par::Seq,
        );
        for j in 0..b.n {
            let col = d.col_as_slice_mut(j);
            for (i, v) in col.iter_mut().enumerate() {
                *v = (*v + na[i] + nb[j]).max(0.0);
            }
        }
        d
    }
}

/// Column means of the data: the centring used by [`Modalities::sq_distances`].
pub fn column_means(x: &Data) -> Vec<f64> {
    let mut mean = vec![0.0; x.d];
    for i in 0..x.n {
        for (m, v) in mean.iter_mut().zip(x.row(i)) {
            *m += v;
        }
    }
    let n = x.n.max(1) as f64;
    mean.iter_mut().for_each(|m| *m /= n);
    mean
}

/// Task index of every training row: the rows of source task s (sizes in order) come first,
/// then the target rows (task `source_sizes.len()`).
pub fn row_tasks(source_sizes: &[usize], n: usize) -> Vec<usize> {
    let mut task = Vec::with_capacity(n);
    for (s, &size) in source_sizes.iter().enumerate() {
        task.extend(std::iter::repeat_n(s, size));
    }
    task.resize(n, source_sizes.len());
    task
}

/// Squared distances per modality between all rows of a training set (source rows first).
pub struct PairDistances {
    pub n: usize,
    /// Rows of all source tasks together (the target rows start here).
    pub n_source: usize,
    pub source_sizes: Vec<usize>,
    /// Task index of every row (see [`row_tasks`]).
    pub task: Vec<usize>,
    pub per_modality: Vec<Mat<f64>>,
}

impl PairDistances {
    pub fn new(x: &Data, source_sizes: &[usize], modalities: &Modalities, center: &[f64]) -> Self {
        let n = x.n;
        let n_source: usize = source_sizes.iter().sum();
        assert!(n_source <= n, "source rows exceed the training rows");
        let per_modality = (0..modalities.len())
            .map(|m| {
                let mut d = modalities.sq_distances(m, x, x, center);
                // Exact symmetry and a zero diagonal, whatever the product's rounding.
                for j in 0..n {
                    d[(j, j)] = 0.0;
                    for i in (j + 1)..n {
                        d[(j, i)] = d[(i, j)];
                    }
                }
                d
            })
            .collect();
        PairDistances {
            n,
            n_source,
            source_sizes: source_sizes.to_vec(),
            task: row_tasks(source_sizes, n),
            per_modality,
        }
    }

    pub fn coupling(&self, h: &Hyper) -> Coupling {
        Coupling::new(&h.lambdas, self.source_sizes.len())
    }

    /// Median of the non-zero pairwise distances of modality m among the target rows (all rows
    /// when there are too few): the data-scaled starting length-scale.
    pub fn median_distance(&self, m: usize) -> f64 {
        let start = if self.n - self.n_source >= 2 {
            self.n_source
        } else {
            0
        };
        let d = &self.per_modality[m];
        let mut v: Vec<f64> = Vec::new();
        for j in start..self.n {
            for i in (j + 1)..self.n {
                let x = d[(i, j)];
                if x > 0.0 {
                    v.push(x.sqrt());
                }
            }
        }
        if v.is_empty() {
            return 1.0;
        }
        let mid = v.len() / 2;
        let (_, median, _) = v.select_nth_unstable_by(mid, |a, b| a.total_cmp(b));
        *median
    }
}

/// The kernel matrix at given hyper-parameters, with the per-modality unit RBF matrices the
/// gradient needs.
pub struct KernelEval {
    pub k: Mat<f64>,
    pub parts: Vec<Mat<f64>>,
    /// Jitter added to the diagonal of `k`, relative to the signal variance.
    pub jitter: f64,
}

impl KernelEval {
    pub fn new(dist: &PairDistances, h: &Hyper) -> Self {
        let mut eval = KernelEval {
            k: Mat::<f64>::zeros(0, 0),
            parts: Vec::new(),
            jitter: 0.0,
        };
        eval.recompute(dist, h);
        eval
    }

    /// The kernel at other hyper-parameters, in the same buffers (an optimiser evaluates
    /// many; a fresh n × n allocation each time costs page faults and zeroing).
    pub fn recompute(&mut self, dist: &PairDistances, h: &Hyper) {
        let n = dist.n;
        let fresh = || Mat::<f64>::zeros(n, n);
        self.parts.truncate(dist.per_modality.len());
        self.parts.resize_with(dist.per_modality.len(), fresh);
        for ((part, d), &l) in self
            .parts
            .iter_mut()
            .zip(&dist.per_modality)
            .zip(&h.length_scales)
        {
            if part.nrows() != n || part.ncols() != n {
                *part = fresh();
            }
            // Only the lower triangle: the gradient reads no more of the parts.
            rbf_lower_into(part, d, l);
        }
        if self.k.nrows() != n || self.k.ncols() != n {
            self.k = fresh();
        }
        combine_parts_symmetric(&mut self.k, &self.parts, h, &dist.coupling(h), &dist.task);
        self.jitter = 0.0;
    }

    pub fn with_jitter(mut self, relative: f64, signal_variance: f64) -> Self {
        let add = (relative - self.jitter) * signal_variance;
        for i in 0..self.k.nrows() {
            self.k[(i, i)] += add;
        }
        self.jitter = relative;
        self
    }

    /// For every hyper-parameter p: `s1[p] = Σ_ij G_ij ∂K_ij/∂θ_p` with
    /// `G = ½ (v vᵀ - Z)`, and `b[p] = (∂K/∂θ_p) v`. Neither G nor an n × n × p gradient
    /// tensor is ever stored.
    ///
    /// Every derivative is a combination of two matrices per modality, masked by the task
    /// coupling (constant on each block of rows and columns of one task pair):
    /// `∂K/∂log σ² = σ² Σ_m γ_m K_m ∘ B`, `∂K/∂log ℓ_m = σ² γ_m K_m ∘ D_m / ℓ_m² ∘ B`,
    /// `∂K/∂η_m = σ² γ_m (K_m - Σ_k γ_k K_k) ∘ B` and `∂K/∂λ_s = σ² Σ_m γ_m K_m ∘ ∂B/∂λ_s`. So
    /// one pass over the lower triangle gathers, per modality and task pair, the unmasked sums
    /// `Σ G K_m` and `Σ G K_m D_m`, and per modality and column task the products of the
    /// column blocks of `K_m` and `K_m ∘ D_m` with v; the couplings and scales are applied at
    /// the end. The pass runs on vector instructions (see [`column_pass`]).
    pub fn contract_gradients(
        &self,
        layout: &Layout,
        h: &Hyper,
        dist: &PairDistances,
        z: &Mat<f64>,
        v: &[f64],
    ) -> (Vec<f64>, Vec<Vec<f64>>) {
        let n = dist.n;
        let p_len = layout.len();
        let n_mod = layout.n_modalities;
        let coupling = dist.coupling(h);
        let nt = coupling.n_tasks;
        // Row range of each task (sources in order, the target last).
        let mut ranges = Vec::with_capacity(nt);
        let mut at = 0;
        for &size in &dist.source_sizes {
            ranges.push((at, at + size));
            at += size;
        }
        ranges.push((at, n));
        // e[m][a][b] = Σ G_ij K_m,ij and f[..] = Σ G_ij (K_m ∘ D_m)_ij over rows of task a and
        // columns of task b (both triangles); pk[m][b] = K_m[:, task b] v[task b], pq likewise
        // for K_m ∘ D_m.
        let mut e = vec![0.0; n_mod * nt * nt];
        let mut f = vec![0.0; n_mod * nt * nt];
        let mut pk = vec![vec![0.0; n]; n_mod * nt];
        let mut pq = vec![vec![0.0; n]; n_mod * nt];
        let mut g = vec![0.0; n];
        for j in 0..n {
            let tj = dist.task[j];
            let vj = v[j];
            let zj = z.col_as_slice(j);
            for i in j..n {
                g[i] = 0.5 * (v[i] * vj - zj[i]);
            }
            for m in 0..n_mod {
                let kj = self.parts[m].col_as_slice(j);
                let dj = dist.per_modality[m].col_as_slice(j);
                // The diagonal element once.
                let (k, kd) = (kj[j], kj[j] * dj[j]);
                e[(m * nt + tj) * nt + tj] += g[j] * k;
                f[(m * nt + tj) * nt + tj] += g[j] * kd;
                pk[m * nt + tj][j] += k * vj;
                pq[m * nt + tj][j] += kd * vj;
                // Below the diagonal, block by block: (i, j) and its mirror (j, i).
                for (a, &(lo, hi)) in ranges.iter().enumerate() {
                    let lo = lo.max(j + 1);
                    if lo >= hi {
                        continue;
                    }
                    let (pkb, pqb) = (m * nt + tj, m * nt + tj);
                    let sums = column_pass(
                        &kj[lo..hi],
                        &dj[lo..hi],
                        &g[lo..hi],
                        &v[lo..hi],
                        vj,
                        &mut pk[pkb][lo..hi],
                        &mut pq[pqb][lo..hi],
                    );
                    e[(m * nt + a) * nt + tj] += sums[0];
                    e[(m * nt + tj) * nt + a] += sums[0];
                    f[(m * nt + a) * nt + tj] += sums[1];
                    f[(m * nt + tj) * nt + a] += sums[1];
                    pk[m * nt + a][j] += sums[2];
                    pq[m * nt + a][j] += sums[3];
                }
            }
        }
        let sf2 = h.signal_variance;
        let inv_l2: Vec<f64> = h.length_scales.iter().map(|l| 1.0 / (l * l)).collect();
        let n_lambdas = layout.n_lambdas;
        let lambda_index = |s: usize| p_len - n_lambdas + s;
        // Masked sums per modality; per λ, the sums under ∂B/∂λ_s.
        let mut se = vec![0.0; n_mod];
        let mut sf = vec![0.0; n_mod];
        let mut s1 = vec![0.0; p_len];
        for m in 0..n_mod {
            for a in 0..nt {
                for b in 0..nt {
                    let idx = (m * nt + a) * nt + b;
                    se[m] += coupling.get(a, b) * e[idx];
                    sf[m] += coupling.get(a, b) * f[idx];
                    for s in 0..n_lambdas {
                        s1[lambda_index(s)] +=
                            sf2 * h.weights[m] * coupling.derivative(s, a, b) * e[idx];
                    }
                }
            }
        }
        let unit_e: f64 = (0..n_mod).map(|m| h.weights[m] * se[m]).sum();
        s1[Layout::SIGNAL] = sf2 * unit_e;
        for m in 0..n_mod {
            s1[layout.length_scale(m)] = sf2 * h.weights[m] * inv_l2[m] * sf[m];
            if let Some(w) = layout.weight(m) {
                s1[w] = sf2 * h.weights[m] * (se[m] - unit_e);
            }
        }
        // b[p][i]: the column-block products combined with row i's couplings.
        let mut b = vec![vec![0.0; n]; p_len];
        let mut bk = vec![0.0; n_mod];
        let mut bq = vec![0.0; n_mod];
        let mut bl = vec![0.0; n_lambdas];
        for i in 0..n {
            let ti = dist.task[i];
            bl.iter_mut().for_each(|x| *x = 0.0);
            for m in 0..n_mod {
                let (mut sk, mut sq) = (0.0, 0.0);
                for t in 0..nt {
                    let (kv, qv) = (pk[m * nt + t][i], pq[m * nt + t][i]);
                    sk += coupling.get(ti, t) * kv;
                    sq += coupling.get(ti, t) * qv;
                    for (s, x) in bl.iter_mut().enumerate() {
                        *x += h.weights[m] * coupling.derivative(s, ti, t) * kv;
                    }
                }
                bk[m] = sk;
                bq[m] = sq;
            }
            let unit_b: f64 = (0..n_mod).map(|m| h.weights[m] * bk[m]).sum();
            b[Layout::SIGNAL][i] = sf2 * unit_b;
            for m in 0..n_mod {
                b[layout.length_scale(m)][i] = sf2 * h.weights[m] * inv_l2[m] * bq[m];
                if let Some(w) = layout.weight(m) {
                    b[w][i] = sf2 * h.weights[m] * (bk[m] - unit_b);
                }
            }
            for (s, x) in bl.iter().enumerate() {
                b[lambda_index(s)][i] = sf2 * x;
            }
        }
        (s1, b)
    }
}

crate::simd::widest_vectors! {
    /// One column block below the diagonal of one modality: returns `Σ g k`, `Σ g k d`, `Σ k v`
    /// and `Σ k d v` over the block and adds `k vj` to `pk` and `k d vj` to `pq`. Sums run in
    /// eight independent lanes so that they vectorise (a single running sum would pin the order of
    /// the additions); the widest instruction set the CPU offers is chosen at run time.
    fn column_pass(
        k: &[f64],
        d: &[f64],
        g: &[f64],
        v: &[f64],
        vj: f64,
        pk: &mut [f64],
        pq: &mut [f64],
    ) -> [f64; 4] = column_pass_lanes;
}

#[inline(always)]
fn column_pass_lanes(
    k: &[f64],
    d: &[f64],
    g: &[f64],
    v: &[f64],
    vj: f64,
    pk: &mut [f64],
    pq: &mut [f64],
) -> [f64; 4] {
    const L: usize = 8;
    let n = k.len();
    let (d, g, v) = (&d[..n], &g[..n], &v[..n]);
    let (pk, pq) = (&mut pk[..n], &mut pq[..n]);
    let mut acc = [[0.0; L]; 4];
    let full = n - n % L;
    for c in (0..full).step_by(L) {
        let (kc, dc, gc, vc) = (&k[c..c + L], &d[c..c + L], &g[c..c + L], &v[c..c + L]);
        let (pkc, pqc) = (&mut pk[c..c + L], &mut pq[c..c + L]);
        for l in 0..L {
            let kk = kc[l];
            let kd = kk * dc[l];
            acc[0][l] += gc[l] * kk;
            acc[1][l] += gc[l] * kd;
            acc[2][l] += kk * vc[l];
            acc[3][l] += kd * vc[l];
            pkc[l] += kk * vj;
            pqc[l] += kd * vj;
        }
    }
    for i in full..n {
        let kk = k[i];
        let kd = kk * d[i];
        acc[0][0] += g[i] * kk;
        acc[1][0] += g[i] * kd;
        acc[2][0] += kk * v[i];
        acc[3][0] += kd * v[i];
        pk[i] += kk * vj;
        pq[i] += kd * vj;
    }
    let mut out = [0.0; 4];
    for (o, a) in out.iter_mut().zip(&acc) {
        *o = a.iter().sum();
    }
    out
}

/// `exp(-D / (2 ℓ²))` elementwise.
pub fn rbf_from_sq_distances(d: &Mat<f64>, length_scale: f64) -> Mat<f64> {
    let mut out = Mat::<f64>::zeros(d.nrows(), d.ncols());
    rbf_into(&mut out, d, length_scale);
    out
}

/// `out = exp(-D / (2 ℓ²))` elementwise, `out` of D's shape.
fn rbf_into(out: &mut Mat<f64>, d: &Mat<f64>, length_scale: f64) {
    let c = -0.5 / (length_scale * length_scale);
    for j in 0..out.ncols() {
        let col = out.col_as_slice_mut(j);
        for (o, v) in col.iter_mut().zip(d.col_as_slice(j)) {
            *o = v * c;
        }
        exp_nonpositive_in_place(col);
    }
}

/// The lower triangle (i ≥ j) of [`rbf_into`]: half the `exp` calls for a symmetric D.
fn rbf_lower_into(out: &mut Mat<f64>, d: &Mat<f64>, length_scale: f64) {
    let c = -0.5 / (length_scale * length_scale);
    for j in 0..out.ncols() {
        let col = &mut out.col_as_slice_mut(j)[j..];
        for (o, v) in col.iter_mut().zip(&d.col_as_slice(j)[j..]) {
            *o = v * c;
        }
        exp_nonpositive_in_place(col);
    }
}

/// [`combine_parts`] for the symmetric training kernel from the parts' lower triangles: the
/// lower triangle computed as there (the same operations in the same order, so the same
/// values), the upper one copied from it. D and B are exactly symmetric, so this is the very
/// matrix the full computation gives.
fn combine_parts_symmetric(
    out: &mut Mat<f64>,
    parts: &[Mat<f64>],
    h: &Hyper,
    coupling: &Coupling,
    task: &[usize],
) {
    let n = out.ncols();
    for j in 0..n {
        let col = &mut out.col_as_slice_mut(j)[j..];
        col.iter_mut().for_each(|v| *v = 0.0);
        for (part, w) in parts.iter().zip(&h.weights) {
            let scale = h.signal_variance * w;
            for (o, p) in col.iter_mut().zip(&part.col_as_slice(j)[j..]) {
                *o += scale * p;
            }
        }
        if coupling.n_tasks > 1 {
            let tj = task[j];
            for (o, &ti) in col.iter_mut().zip(&task[j..]) {
                *o *= coupling.get(ti, tj);
            }
        }
    }
    crate::linalg::mirror_lower(out);
}

/// `out[i, j] = σ² Σ_m γ_m parts_m[i, j] · B[row_task[i], col_task[j]]`.
pub fn combine_parts(
    out: &mut Mat<f64>,
    parts: &[Mat<f64>],
    h: &Hyper,
    coupling: &Coupling,
    row_task: &[usize],
    col_task: &[usize],
) {
    for j in 0..out.ncols() {
        let col = out.col_as_slice_mut(j);
        col.iter_mut().for_each(|v| *v = 0.0);
        for (part, w) in parts.iter().zip(&h.weights) {
            let scale = h.signal_variance * w;
            for (o, p) in col.iter_mut().zip(part.col_as_slice(j)) {
                *o += scale * p;
            }
        }
        if coupling.n_tasks > 1 {
            let tj = col_task[j];
            for (o, &ti) in col.iter_mut().zip(row_task) {
                *o *= coupling.get(ti, tj);
            }
        }
    }
}

/// Cross-kernel `K(X_train, X*)` (n_train × m) for test rows that belong to the target task,
/// given the per-modality squared distances between the training rows (source rows first, in
/// tasks of `source_sizes`) and the test rows.
pub fn cross_kernel_from_distances(
    dists: &[Mat<f64>],
    source_sizes: &[usize],
    h: &Hyper,
) -> Mat<f64> {
    let parts: Vec<Mat<f64>> = dists
        .iter()
        .zip(&h.length_scales)
        .map(|(d, &l)| rbf_from_sq_distances(d, l))
        .collect();
    let (n, m) = (dists[0].nrows(), dists[0].ncols());
    let mut out = Mat::<f64>::zeros(n, m);
    let coupling = Coupling::new(&h.lambdas, source_sizes.len());
    let rows = row_tasks(source_sizes, n);
    let cols = vec![source_sizes.len(); m];
    combine_parts(&mut out, &parts, h, &coupling, &rows, &cols);
    out
}

/// Cross-kernel `K(X_train, X*)` computed from scratch.
pub fn cross_kernel(
    train: &Data,
    source_sizes: &[usize],
    test: &Data,
    modalities: &Modalities,
    h: &Hyper,
    center: &[f64],
) -> Mat<f64> {
    let dists: Vec<Mat<f64>> = (0..modalities.len())
        .map(|m| modalities.sq_distances(m, train, test, center))
        .collect();
    cross_kernel_from_distances(&dists, source_sizes, h)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn data() -> Data {
        Data::new(
            vec![0.0, 1.0, 2.0, 0.5, -1.0, 0.3, 1.5, 2.5, 0.0, 0.2, 0.1, 0.9],
            4,
            3,
        )
        .unwrap()
    }

    #[test]
    fn theta_round_trip() {
        let layout = Layout {
            n_modalities: 2,
            n_lambdas: 1,
        };
        let h = Hyper {
            signal_variance: 2.5,
            length_scales: vec![0.3, 4.0],
            weights: vec![0.25, 0.75],
            lambdas: vec![0.4],
        };
        let back = layout.decode(&layout.encode(&h)).unwrap();
        assert!((back.signal_variance - 2.5).abs() < 1e-12);
        assert!((back.weights[1] - 0.75).abs() < 1e-12);
        assert_eq!(back.lambdas, vec![0.4]);
        assert_eq!(layout.len(), 6);
        assert!(layout.decode(&[0.0; 5]).is_err());
        let mut bad = layout.encode(&h);
        bad[5] = 1.5;
        assert!(matches!(layout.decode(&bad), Err(GpError::InvalidInput(_))));
    }

    #[test]
    fn kernel_matches_direct_formula() {
        let x = data();
        let mods = Modalities::new(vec![vec![0, 1], vec![2]], 3).unwrap();
        let center = column_means(&x);
        let dist = PairDistances::new(&x, &[1], &mods, &center);
        let h = Hyper {
            signal_variance: 1.7,
            length_scales: vec![0.8, 2.0],
            weights: vec![0.6, 0.4],
            lambdas: vec![0.3],
        };
        let ev = KernelEval::new(&dist, &h);
        for i in 0..4 {
            for j in 0..4 {
                let (a, b) = (x.row(i), x.row(j));
                let d0 = (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2);
                let d1 = (a[2] - b[2]).powi(2);
                let k = 0.6 * (-d0 / (2.0 * 0.64)).exp() + 0.4 * (-d1 / 8.0).exp();
                let mask = if (i < 1) != (j < 1) { 0.3 } else { 1.0 };
                assert!((ev.k[(i, j)] - 1.7 * k * mask).abs() < 1e-13);
            }
        }
        // The cross-kernel of the training rows against the target rows equals the block of K.
        let target = Data::new(x.values[3..].to_vec(), 3, 3).unwrap();
        let kx = cross_kernel(&x, &[1], &target, &mods, &h, &center);
        for i in 0..4 {
            for j in 0..3 {
                assert!((kx[(i, j)] - ev.k[(i, j + 1)]).abs() < 1e-13);
            }
        }
    }

    #[test]
    fn multi_source_coupling_has_the_documented_entries_and_derivatives() {
        // Sources of 1 and 2 rows, then 1 target row: B_ss = 1, B_st = λ_s, B_ss' = λ_s λ_s'.
        let x = data();
        let mods = Modalities::all_columns(3);
        let dist = PairDistances::new(&x, &[1, 2], &mods, &column_means(&x));
        assert_eq!(dist.task, vec![0, 1, 1, 2]);
        let lambdas = vec![0.3, -0.8];
        let h = Hyper {
            signal_variance: 1.0,
            length_scales: vec![1.5],
            weights: vec![1.0],
            lambdas: lambdas.clone(),
        };
        let ev = KernelEval::new(&dist, &h);
        let b = [
            [1.0, 0.3 * -0.8, 0.3],
            [0.3 * -0.8, 1.0, -0.8],
            [0.3, -0.8, 1.0],
        ];
        for i in 0..4 {
            for j in 0..4 {
                let (a, c) = (x.row(i), x.row(j));
                let d: f64 = a.iter().zip(c).map(|(p, q)| (p - q).powi(2)).sum();
                let want = (-d / (2.0 * 2.25)).exp() * b[dist.task[i]][dist.task[j]];
                assert!((ev.k[(i, j)] - want).abs() < 1e-13);
            }
        }
        let coupling = Coupling::new(&lambdas, 2);
        for s in 0..2 {
            let e = 1e-6;
            let (mut up, mut down) = (lambdas.clone(), lambdas.clone());
            up[s] += e;
            down[s] -= e;
            let (cu, cd) = (Coupling::new(&up, 2), Coupling::new(&down, 2));
            for ti in 0..3 {
                for tj in 0..3 {
                    let fd = (cu.get(ti, tj) - cd.get(ti, tj)) / (2.0 * e);
                    assert!((fd - coupling.derivative(s, ti, tj)).abs() < 1e-8);
                }
            }
        }
    }

    #[test]
    fn modalities_are_validated() {
        assert!(Modalities::new(vec![], 3).is_err());
        assert!(Modalities::new(vec![vec![]], 3).is_err());
        assert!(Modalities::new(vec![vec![0, 3]], 3).is_err());
    }
}
