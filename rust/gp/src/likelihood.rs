//! The logistic likelihood and the predictive integral `∫ σ(f) N(f | μ, s²) df`.

use std::sync::OnceLock;

/// σ(z) = 1 / (1 + e^{-z}) without overflow for large |z|.
#[inline]
pub fn sigmoid(z: f64) -> f64 {
    if z >= 0.0 {
        1.0 / (1.0 + (-z).exp())
    } else {
        let e = z.exp();
        e / (1.0 + e)
    }
}

/// log σ(z) = -log(1 + e^{-z}), stable for large |z|.
#[inline]
pub fn log_sigmoid(z: f64) -> f64 {
    if z >= 0.0 {
        -(-z).exp().ln_1p()
    } else {
        z - z.exp().ln_1p()
    }
}

/// How the predictive probability integral is evaluated.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Predictive {
    /// σ approximated by a mixture of five cumulative Gaussians, integrated in closed form
    /// (Williams & Barber 1998; the approximation scikit-learn uses). Error ≲ 1e-4 (see tests).
    ErfMixture,
    /// Panel Gauss–Legendre quadrature of the exact integrand; error ≲ 1e-10.
    Quadrature,
}

// Mixture σ(f) ≈ Σ c_i Φ(λ_i √2 f) with the published scales and least-squares weights of
// Williams & Barber (1998), as used by GPML and scikit-learn; reusing the same constants lets
// our probabilities agree with scikit-learn's to rounding when this approximation is selected.
const MIX_LAMBDAS: [f64; 5] = [0.41, 0.4, 0.37, 0.44, 0.39];
const MIX_COEFS: [f64; 5] = [
    -1854.8214151,
    3516.89893646,
    221.29346712,
    128.12323805,
    -2010.49422654,
];

/// Approximate `∫ σ(f) N(f | mean, var) df`.
pub fn predictive_probability(mean: f64, var: f64, method: Predictive) -> f64 {
    let var = var.max(0.0);
    let p = match method {
        Predictive::ErfMixture => erf_mixture(mean, var),
        Predictive::Quadrature => quadrature(mean, var),
    };
    p.clamp(0.0, 1.0)
}

fn erf_mixture(mean: f64, var: f64) -> f64 {
    // ∫ Φ(a f) N(f | μ, v) df = Φ(a μ / sqrt(1 + a² v)) with a = √2 λ, and Φ(x) = (1 + erf(x/√2))/2.
    let mut p = 0.0;
    for (lam, c) in MIX_LAMBDAS.iter().zip(MIX_COEFS.iter()) {
        let z = lam * mean / (1.0 + 2.0 * lam * lam * var).sqrt();
        p += c * 0.5 * (1.0 + libm::erf(z));
    }
    p
}

/// Gauss–Legendre nodes and weights on [-1, 1] by Newton iteration on P_n.
fn gauss_legendre(n: usize) -> (Vec<f64>, Vec<f64>) {
    let mut nodes = vec![0.0; n];
    let mut weights = vec![0.0; n];
    for i in 0..n.div_ceil(2) {
        let mut x = (std::f64::consts::PI * (i as f64 + 0.75) / (n as f64 + 0.5)).cos();
        let mut dp = 1.0;
        for _ in 0..100 {
            let (mut p0, mut p1) = (1.0f64, x);
            for k in 2..=n {
                let p2 = ((2 * k - 1) as f64 * x * p1 - (k - 1) as f64 * p0) / k as f64;
                p0 = p1;
                p1 = p2;
            }
            dp = n as f64 * (x * p1 - p0) / (x * x - 1.0);
            let dx = p1 / dp;
            x -= dx;
            if dx.abs() < 1e-15 {
                break;
            }
        }
        nodes[i] = -x;
        nodes[n - 1 - i] = x;
        let w = 2.0 / ((1.0 - x * x) * dp * dp);
        weights[i] = w;
        weights[n - 1 - i] = w;
    }
    (nodes, weights)
}

fn gl_rule() -> &'static (Vec<f64>, Vec<f64>) {
    static RULE: OnceLock<(Vec<f64>, Vec<f64>)> = OnceLock::new();
    RULE.get_or_init(|| gauss_legendre(16))
}

fn quadrature(mean: f64, var: f64) -> f64 {
    let sd = var.sqrt();
    if sd < 1e-12 {
        return sigmoid(mean);
    }
    // σ is within 1e-17 of a step outside |f| < 40, and N(f|μ,s²) is negligible outside μ ± 12 s,
    // so integrate exactly over the overlap and add the Gaussian mass beyond +40 in closed form.
    const CUT: f64 = 40.0;
    let lo = (mean - 12.0 * sd).max(-CUT);
    let hi = (mean + 12.0 * sd).min(CUT);
    let mut total = 0.5 * libm::erfc((CUT - mean) / (sd * std::f64::consts::SQRT_2));
    if hi <= lo {
        return total;
    }
    // Panels no wider than the scale on which either factor varies.
    let width = sd.min(2.0);
    let panels = ((hi - lo) / width).ceil().max(1.0) as usize;
    let h = (hi - lo) / panels as f64;
    let (nodes, weights) = gl_rule();
    let norm = 1.0 / (sd * (2.0 * std::f64::consts::PI).sqrt());
    for p in 0..panels {
        let mid = lo + (p as f64 + 0.5) * h;
        for (x, w) in nodes.iter().zip(weights.iter()) {
            let f = mid + 0.5 * h * x;
            let u = (f - mean) / sd;
            total += 0.5 * h * w * sigmoid(f) * norm * (-0.5 * u * u).exp();
        }
    }
    total
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Reference by brute-force trapezoid on a very fine grid.
    fn brute(mean: f64, var: f64) -> f64 {
        let sd = var.sqrt();
        let (lo, hi) = (mean - 14.0 * sd, mean + 14.0 * sd);
        let n = 400_000;
        let h = (hi - lo) / n as f64;
        let mut s = 0.0;
        for k in 0..=n {
            let f = lo + k as f64 * h;
            let u = (f - mean) / sd;
            let w = if k == 0 || k == n { 0.5 } else { 1.0 };
            s += w * sigmoid(f) * (-0.5 * u * u).exp();
        }
        s * h / (sd * (2.0 * std::f64::consts::PI).sqrt())
    }

    #[test]
    fn sigmoid_is_stable() {
        assert_eq!(sigmoid(800.0), 1.0);
        assert_eq!(sigmoid(-800.0), 0.0);
        assert!((log_sigmoid(-800.0) + 800.0).abs() < 1e-12);
        assert!(log_sigmoid(800.0).abs() < 1e-300);
        assert!((sigmoid(0.3) + sigmoid(-0.3) - 1.0).abs() < 1e-15);
    }

    #[test]
    fn quadrature_matches_brute_force() {
        for &(m, v) in &[
            (0.0, 1.0),
            (1.5, 0.2),
            (-3.0, 25.0),
            (10.0, 400.0),
            (0.7, 1e-6),
            (-45.0, 4.0),
        ] {
            let q = predictive_probability(m, v, Predictive::Quadrature);
            let b = brute(m, v);
            assert!((q - b).abs() < 1e-9, "m={m} v={v}: {q} vs {b}");
        }
    }

    #[test]
    fn erf_mixture_is_a_close_approximation() {
        for &(m, v) in &[
            (0.0, 1.0),
            (1.5, 0.2),
            (-3.0, 25.0),
            (2.0, 4.0),
            (0.3, 0.01),
        ] {
            let e = predictive_probability(m, v, Predictive::ErfMixture);
            let b = brute(m, v);
            assert!((e - b).abs() < 2e-4, "m={m} v={v}: {e} vs {b}");
        }
    }

    #[test]
    fn symmetric_in_the_mean() {
        // The mixture's weights sum to 1 - 1e-8, which bounds its asymmetry.
        for (method, tol) in [
            (Predictive::ErfMixture, 2e-8),
            (Predictive::Quadrature, 1e-12),
        ] {
            let a = predictive_probability(0.8, 3.0, method);
            let b = predictive_probability(-0.8, 3.0, method);
            assert!((a + b - 1.0).abs() < tol, "{method:?}: {a} + {b}");
        }
    }
}
