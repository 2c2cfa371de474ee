//! Bound-constrained quasi-Newton minimisation (projected L-BFGS with backtracking) for the
//! handful of kernel hyper-parameters. Variables at a bound whose gradient points outwards are
//! frozen for the step, as in L-BFGS-B's active set, without its Cauchy-point machinery
//! (unnecessary for a few box-bounded log-parameters).

#[derive(Debug, Clone, Copy)]
pub struct LbfgsConfig {
    pub max_iter: usize,
    pub memory: usize,
    /// Stop when the projected gradient's largest component is below this.
    pub pgtol: f64,
    /// Stop when the relative decrease of the objective falls below this.
    pub ftol: f64,
    /// Largest change of any variable in one step (log-parameters: a factor e² per step).
    pub max_step: f64,
}

impl Default for LbfgsConfig {
    fn default() -> Self {
        LbfgsConfig {
            max_iter: 200,
            memory: 10,
            pgtol: 1e-5,
            ftol: 1e7 * f64::EPSILON,
            max_step: 2.0,
        }
    }
}

#[derive(Debug, Clone)]
pub struct OptResult {
    pub x: Vec<f64>,
    pub fx: f64,
    pub iterations: usize,
    pub evaluations: usize,
    pub converged: bool,
}

/// Minimises `f` (value and gradient, `None` where it cannot be evaluated) over the box
/// `[lo, hi]`, with variables where `free[i]` is false held fixed.
pub fn minimize<F>(
    mut f: F,
    x0: &[f64],
    lo: &[f64],
    hi: &[f64],
    free: &[bool],
    cfg: &LbfgsConfig,
) -> Option<OptResult>
where
    F: FnMut(&[f64]) -> Option<(f64, Vec<f64>)>,
{
    let n = x0.len();
    let project = |x: &mut [f64]| {
        for i in 0..n {
            x[i] = x[i].clamp(lo[i], hi[i]);
        }
    };
    let mut x = x0.to_vec();
    project(&mut x);
    let (mut fx, mut g) = f(&x)?;
    let mut evaluations = 1;
    let mut s_hist: Vec<Vec<f64>> = Vec::new();
    let mut y_hist: Vec<Vec<f64>> = Vec::new();
    let mut converged = false;
    let mut iterations = 0;

    for it in 0..cfg.max_iter {
        iterations = it;
        // Active set: fixed variables and those pinned at a bound by the gradient.
        let active: Vec<bool> = (0..n)
            .map(|i| !free[i] || (x[i] <= lo[i] && g[i] > 0.0) || (x[i] >= hi[i] && g[i] < 0.0))
            .collect();
        let pg_max = (0..n)
            .filter(|&i| !active[i])
            .map(|i| g[i].abs())
            .fold(0.0, f64::max);
        if pg_max < cfg.pgtol {
            converged = true;
            break;
        }
        let mut d = two_loop(&g, &s_hist, &y_hist, &active);
        let slope: f64 = (0..n).map(|i| g[i] * d[i]).sum();
        if slope >= 0.0 || !slope.is_finite() {
            s_hist.clear();
            y_hist.clear();
            d = (0..n)
                .map(|i| if active[i] { 0.0 } else { -g[i] })
                .collect();
        }
        let dmax = d.iter().fold(0.0f64, |a, v| a.max(v.abs()));
        let mut t = if s_hist.is_empty() {
            (1.0 / dmax).min(1.0)
        } else {
            1.0
        };
        if t * dmax > cfg.max_step {
            t = cfg.max_step / dmax;
        }
        // Backtracking along the projected path until the Armijo condition holds.
        let mut accepted = None;
        for _ in 0..40 {
            let mut xn: Vec<f64> = (0..n).map(|i| x[i] + t * d[i]).collect();
            project(&mut xn);
            evaluations += 1;
            if let Some((fn_, gn)) = f(&xn) {
                let decrease: f64 = (0..n).map(|i| g[i] * (xn[i] - x[i])).sum();
                if fn_.is_finite() && fn_ <= fx + 1e-4 * decrease.min(0.0) {
                    accepted = Some((xn, fn_, gn));
                    break;
                }
            }
            t *= 0.5;
        }
        let Some((xn, fn_, gn)) = accepted else {
            break;
        };
        let s: Vec<f64> = (0..n).map(|i| xn[i] - x[i]).collect();
        let y: Vec<f64> = (0..n).map(|i| gn[i] - g[i]).collect();
        let sy: f64 = s.iter().zip(&y).map(|(a, b)| a * b).sum();
        let ss: f64 = s.iter().map(|a| a * a).sum();
        let yy: f64 = y.iter().map(|a| a * a).sum();
        if sy > 1e-10 * (ss * yy).sqrt() {
            if s_hist.len() == cfg.memory {
                s_hist.remove(0);
                y_hist.remove(0);
            }
            s_hist.push(s);
            y_hist.push(y);
        }
        let rel = (fx - fn_) / fx.abs().max(fn_.abs()).max(1.0);
        x = xn;
        fx = fn_;
        g = gn;
        if rel <= cfg.ftol {
            converged = true;
            iterations = it + 1;
            break;
        }
        iterations = it + 1;
    }
    Some(OptResult {
        x,
        fx,
        iterations,
        evaluations,
        converged,
    })
}

/// L-BFGS two-loop recursion restricted to the free (inactive) variables.
fn two_loop(g: &[f64], s_hist: &[Vec<f64>], y_hist: &[Vec<f64>], active: &[bool]) -> Vec<f64> {
    let n = g.len();
    let dot =
        |a: &[f64], b: &[f64]| -> f64 { (0..n).filter(|&i| !active[i]).map(|i| a[i] * b[i]).sum() };
    let mut q: Vec<f64> = (0..n).map(|i| if active[i] { 0.0 } else { g[i] }).collect();
    let k = s_hist.len();
    let mut alpha = vec![0.0; k];
    let mut rho = vec![0.0; k];
    for j in (0..k).rev() {
        let sy = dot(&s_hist[j], &y_hist[j]);
        rho[j] = if sy > 0.0 { 1.0 / sy } else { 0.0 };
        alpha[j] = rho[j] * dot(&s_hist[j], &q);
        for i in 0..n {
            if !active[i] {
                q[i] -= alpha[j] * y_hist[j][i];
            }
        }
    }
    if k > 0 {
        let sy = dot(&s_hist[k - 1], &y_hist[k - 1]);
        let yy = dot(&y_hist[k - 1], &y_hist[k - 1]);
        if sy > 0.0 && yy > 0.0 {
            let gamma = sy / yy;
            q.iter_mut().for_each(|v| *v *= gamma);
        }
    }
    for j in 0..k {
        let beta = rho[j] * dot(&y_hist[j], &q);
        for i in 0..n {
            if !active[i] {
                q[i] += s_hist[j][i] * (alpha[j] - beta);
            }
        }
    }
    q.iter().map(|v| -v).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rosenbrock(x: &[f64]) -> Option<(f64, Vec<f64>)> {
        let (a, b) = (x[0], x[1]);
        let f = (1.0 - a).powi(2) + 100.0 * (b - a * a).powi(2);
        let g = vec![
            -2.0 * (1.0 - a) - 400.0 * a * (b - a * a),
            200.0 * (b - a * a),
        ];
        Some((f, g))
    }

    #[test]
    fn finds_rosenbrock_minimum() {
        let cfg = LbfgsConfig {
            max_iter: 500,
            ftol: 1e-16,
            pgtol: 1e-8,
            ..Default::default()
        };
        let r = minimize(
            rosenbrock,
            &[-1.2, 1.0],
            &[-5.0, -5.0],
            &[5.0, 5.0],
            &[true, true],
            &cfg,
        )
        .unwrap();
        assert!(
            (r.x[0] - 1.0).abs() < 1e-4 && (r.x[1] - 1.0).abs() < 1e-4,
            "{:?}",
            r
        );
    }

    #[test]
    fn respects_bounds_and_fixed_variables() {
        let quad = |x: &[f64]| {
            Some((
                (x[0] - 3.0).powi(2) + (x[1] + 2.0).powi(2),
                vec![2.0 * (x[0] - 3.0), 2.0 * (x[1] + 2.0)],
            ))
        };
        let r = minimize(
            quad,
            &[0.0, 0.5],
            &[-1.0, -1.0],
            &[1.0, 1.0],
            &[true, false],
            &LbfgsConfig::default(),
        )
        .unwrap();
        assert!((r.x[0] - 1.0).abs() < 1e-12, "bounded at 1: {:?}", r.x);
        assert_eq!(r.x[1], 0.5, "fixed variable must not move");
        assert!(r.converged);
    }

    #[test]
    fn survives_regions_where_f_is_undefined() {
        // f undefined for x > 0.5: the line search must back off rather than fail.
        let f = |x: &[f64]| {
            if x[0] > 0.5 {
                None
            } else {
                Some(((x[0] - 2.0).powi(2), vec![2.0 * (x[0] - 2.0)]))
            }
        };
        let r = minimize(
            f,
            &[0.0],
            &[-10.0],
            &[10.0],
            &[true],
            &LbfgsConfig::default(),
        )
        .unwrap();
        assert!(r.x[0] <= 0.5 && r.x[0] > 0.4, "{:?}", r.x);
    }
}
