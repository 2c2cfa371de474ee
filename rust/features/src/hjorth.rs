use ndarray::{ArrayD, ArrayView1, ArrayViewD, Axis, IxDyn};

use crate::checks::{check_finite, resolve_axis, FeatureError};
use crate::Sample;

/// Hjorth parameters of one signal.
///
/// With `x' = diff(x)` and `x'' = diff(x')` and population variances:
/// activity = var(x), mobility = sqrt(var(x') / var(x)),
/// complexity = mobility(x') / mobility(x) = sqrt(var(x'') / var(x')) / mobility.
/// Undefined ratios (a constant signal) are NaN, as in numpy-based references.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hjorth {
    pub activity: f64,
    pub mobility: f64,
    pub complexity: f64,
}

/// Hjorth parameters of a signal of at least 3 samples (the second difference needs 3).
///
/// Two passes: the means of `x'` and `x''` telescope to closed forms, so one pass gets mean(x)
/// and a second accumulates all three centred sums of squares. Centring first keeps full
/// precision for signals with a large offset (gravity on an accelerometer axis).
pub fn hjorth<T: Sample>(x: ArrayView1<'_, T>) -> Hjorth {
    hjorth_with_variances(x).0
}

/// [`hjorth`], with the three variances it is built from (var(x), var(x'), var(x'')): a
/// non-finite one means the signal's values overflowed float64 (see [`hjorth_checked`]).
fn hjorth_with_variances<T: Sample>(x: ArrayView1<'_, T>) -> (Hjorth, [f64; 3]) {
    match x.as_slice() {
        Some(s) => hjorth_slice(s),
        None => {
            let lane: Vec<f64> = x.iter().map(|v| v.to_f64()).collect();
            hjorth_slice(&lane)
        }
    }
}

/// [`hjorth`] of a lane of `name`, or an error if its variances are not finite: the input
/// holds a NaN or an infinity (reported with its index in `whole`, the array the lane belongs
/// to), or its values are so large that their squares or differences overflow. The NaN of a
/// constant lane's ratios is an answer (undefined), not an error; an overflow's is not.
pub(crate) fn hjorth_checked<T: Sample>(
    name: &str,
    lane: ArrayView1<'_, T>,
    whole: &ArrayViewD<'_, T>,
) -> Result<Hjorth, FeatureError> {
    let (h, variances) = hjorth_with_variances(lane);
    if lane.len() >= 3 {
        if let Some(&v) = variances.iter().find(|v| !v.is_finite()) {
            check_finite(name, whole)?;
            let what = [
                "activity (variance)",
                "variance of the first difference",
                "variance of the second difference",
            ][variances.iter().position(|x| !x.is_finite()).unwrap_or(0)];
            return Err(FeatureError::overflow(name, &format!("Hjorth {what}"), v));
        }
    }
    Ok(h)
}

const NAN3: Hjorth = Hjorth {
    activity: f64::NAN,
    mobility: f64::NAN,
    complexity: f64::NAN,
};

/// Lanes of 4 independent accumulators let the CPU overlap the additions (a single running
/// sum is bound by the floating-point add latency).
fn hjorth_slice<T: Sample>(s: &[T]) -> (Hjorth, [f64; 3]) {
    let n = s.len();
    if n < 3 {
        return (NAN3, [f64::NAN; 3]);
    }
    let mut sums = [0.0f64; 4];
    let mut chunks = s.chunks_exact(4);
    for c in &mut chunks {
        for u in 0..4 {
            sums[u] += c[u].to_f64();
        }
    }
    let tail: f64 = chunks.remainder().iter().map(|v| v.to_f64()).sum();
    let nf = n as f64;
    let mean_x = (sums[0] + sums[1] + sums[2] + sums[3] + tail) / nf;
    let at = |i: usize| s[i].to_f64();
    let mean_d1 = (at(n - 1) - at(0)) / (nf - 1.0);
    // diff(x')[k] = x[k+2] - 2 x[k+1] + x[k]; its sum telescopes to (x[n-1]-x[n-2]) - (x[1]-x[0]).
    let mean_d2 = ((at(n - 1) - at(n - 2)) - (at(1) - at(0))) / (nf - 2.0);

    let (c00, c01) = (at(0) - mean_x, at(1) - mean_x);
    let c11 = (at(1) - at(0)) - mean_d1;
    let mut ss0 = [0.0f64; 4];
    let mut ss1 = [0.0f64; 4];
    let mut ss2 = [0.0f64; 4];
    // Every window of three samples contributes one term to each of the three sums.
    let mut windows = s.windows(6).step_by(4);
    let full = (n - 2) / 4;
    for _ in 0..full {
        let Some(w) = windows.next() else { break };
        for u in 0..4 {
            let (x0, x1, x2) = (w[u].to_f64(), w[u + 1].to_f64(), w[u + 2].to_f64());
            let d1 = x2 - x1;
            let c0 = x2 - mean_x;
            let c1 = d1 - mean_d1;
            let c2 = (d1 - (x1 - x0)) - mean_d2;
            ss0[u] += c0 * c0;
            ss1[u] += c1 * c1;
            ss2[u] += c2 * c2;
        }
    }
    let (mut r0, mut r1, mut r2) = (c00 * c00 + c01 * c01, c11 * c11, 0.0);
    for i in (2 + 4 * full)..n {
        let (x0, x1, x2) = (at(i - 2), at(i - 1), at(i));
        let d1 = x2 - x1;
        let c0 = x2 - mean_x;
        let c1 = d1 - mean_d1;
        let c2 = (d1 - (x1 - x0)) - mean_d2;
        r0 += c0 * c0;
        r1 += c1 * c1;
        r2 += c2 * c2;
    }
    let var0 = (ss0.iter().sum::<f64>() + r0) / nf;
    let var1 = (ss1.iter().sum::<f64>() + r1) / (nf - 1.0);
    let var2 = (ss2.iter().sum::<f64>() + r2) / (nf - 2.0);
    let mobility = (var1 / var0).sqrt();
    let complexity = (var2 / var1).sqrt() / mobility;
    (
        Hjorth {
            activity: var0,
            mobility,
            complexity,
        },
        [var0, var1, var2],
    )
}

/// Hjorth parameters of every lane of `x` along `axis`; output arrays have `x`'s shape without
/// that axis.
pub struct HjorthArrays {
    pub activity: ArrayD<f64>,
    pub mobility: ArrayD<f64>,
    pub complexity: ArrayD<f64>,
}

pub fn hjorth_along<T: Sample>(
    name: &str,
    x: ArrayViewD<'_, T>,
    axis: isize,
) -> Result<HjorthArrays, FeatureError> {
    let axis = resolve_axis(name, axis, x.ndim())?;
    let len = x.len_of(Axis(axis));
    if len < 3 {
        return Err(FeatureError::shape(
            name,
            format!("Hjorth parameters need at least 3 samples along axis {axis}, got {len}"),
        ));
    }
    let mut out_shape: Vec<usize> = x.shape().to_vec();
    out_shape.remove(axis);
    let n_out: usize = out_shape.iter().product();
    let mut activity = Vec::with_capacity(n_out);
    let mut mobility = Vec::with_capacity(n_out);
    let mut complexity = Vec::with_capacity(n_out);
    for lane in x.lanes(Axis(axis)) {
        // A NaN or infinity anywhere in a lane makes its variance non-finite; only then is the
        // whole input scanned to report where (finite data are read once less).
        let h = hjorth_checked(name, lane, &x)?;
        activity.push(h.activity);
        mobility.push(h.mobility);
        complexity.push(h.complexity);
    }
    let shape = IxDyn(&out_shape);
    let build = |v: Vec<f64>| {
        ArrayD::from_shape_vec(shape.clone(), v)
            .map_err(|e| FeatureError::shape(name, format!("internal shape error: {e}")))
    };
    Ok(HjorthArrays {
        activity: build(activity)?,
        mobility: build(mobility)?,
        complexity: build(complexity)?,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::{Array1, Array3};
    use proptest::prelude::*;

    fn naive(x: &[f64]) -> Hjorth {
        let var = |v: &[f64]| {
            let m = v.iter().sum::<f64>() / v.len() as f64;
            v.iter().map(|a| (a - m) * (a - m)).sum::<f64>() / v.len() as f64
        };
        let d1: Vec<f64> = x.windows(2).map(|w| w[1] - w[0]).collect();
        let d2: Vec<f64> = d1.windows(2).map(|w| w[1] - w[0]).collect();
        let mob = (var(&d1) / var(x)).sqrt();
        Hjorth {
            activity: var(x),
            mobility: mob,
            complexity: (var(&d2) / var(&d1)).sqrt() / mob,
        }
    }

    fn close(a: f64, b: f64, rel: f64) -> bool {
        (a - b).abs() <= rel * a.abs().max(b.abs()).max(1e-300)
    }

    #[test]
    fn sine_has_closed_form_mobility() {
        // For a sampled sinusoid of angular step w, var(diff)/var = 2 (1 - cos w), exactly
        // over whole periods.
        let w = std::f64::consts::PI / 25.0;
        let x: Vec<f64> = (0..5000).map(|k| (w * k as f64).sin()).collect();
        let h = hjorth(Array1::from(x).view());
        let expected = (2.0 * (1.0 - w.cos())).sqrt();
        assert!(
            close(h.mobility, expected, 1e-3),
            "{} vs {}",
            h.mobility,
            expected
        );
        assert!(
            close(h.complexity, 1.0, 1e-3),
            "complexity of a pure tone is 1: {}",
            h.complexity
        );
        assert!(close(h.activity, 0.5, 1e-3));
    }

    #[test]
    fn strided_lane_equals_contiguous() {
        let a = Array3::from_shape_fn((2, 3, 50), |(i, j, k)| {
            ((i * 7 + j * 3 + k) as f64).sin() * 3.0 + k as f64 * 0.01
        });
        let t = a.view().permuted_axes([2, 1, 0]).into_dyn();
        let r1 = hjorth_along("a", a.view().into_dyn(), -1).unwrap();
        let r2 = hjorth_along("t", t, 0).unwrap();
        assert_eq!(r1.mobility, r2.mobility.t());
    }

    #[test]
    fn nan_is_reported_with_its_index() {
        let mut a = Array3::<f64>::zeros((2, 3, 10));
        a[[1, 2, 7]] = f64::NAN;
        match hjorth_along("acc", a.view().into_dyn(), -1) {
            Err(FeatureError::NonFinite { name, index, value }) => {
                assert_eq!(name, "acc");
                assert_eq!(index, vec![1, 2, 7]);
                assert!(value.is_nan());
            }
            other => panic!("expected a NonFinite error, got {:?}", other.err()),
        }
    }

    #[test]
    fn overflow_is_an_error_and_a_constant_lane_is_not() {
        let big: Vec<f64> = [1e308, -1e308].repeat(10);
        let a = Array1::from(big);
        match hjorth_along("x", a.view().into_dyn(), 0) {
            Err(FeatureError::NonFiniteResult { name, .. }) => assert_eq!(name, "x"),
            other => panic!("expected a NonFiniteResult error, got {:?}", other.err()),
        }
        // Squares fine, differences overflow: var(x) is finite, var(x') is not.
        let a = Array1::from([1e154, -1e154].repeat(10));
        assert!(matches!(
            hjorth_along("x", a.view().into_dyn(), 0),
            Err(FeatureError::NonFiniteResult { .. })
        ));
        let flat = Array1::from(vec![2.0; 10]);
        let h = hjorth_along("x", flat.view().into_dyn(), 0).unwrap();
        assert_eq!(h.activity[[]], 0.0);
        assert!(h.mobility[[]].is_nan());
    }

    #[test]
    fn too_short_is_a_shape_error() {
        let a = Array1::<f64>::zeros(2);
        assert!(matches!(
            hjorth_along("x", a.view().into_dyn(), 0),
            Err(FeatureError::Shape { .. })
        ));
        assert!(matches!(
            hjorth_along("x", a.view().into_dyn(), 3),
            Err(FeatureError::Shape { .. })
        ));
    }

    proptest! {
        #[test]
        fn matches_naive_definition(x in proptest::collection::vec(-1e3f64..1e3, 3..200)) {
            let h = hjorth(Array1::from(x.clone()).view());
            let r = naive(&x);
            prop_assume!(r.activity > 1e-9 && r.mobility.is_finite() && r.complexity.is_finite());
            prop_assert!(close(h.activity, r.activity, 1e-9));
            prop_assert!(close(h.mobility, r.mobility, 1e-7));
            prop_assert!(close(h.complexity, r.complexity, 1e-6));
        }

        #[test]
        fn mobility_and_complexity_ignore_offsets(
            x in proptest::collection::vec(-1.0f64..1.0, 10..200),
            offset in -1e4f64..1e4,
        ) {
            let h0 = hjorth(Array1::from(x.clone()).view());
            let shifted: Vec<f64> = x.iter().map(|v| v + offset).collect();
            let h1 = hjorth(Array1::from(shifted).view());
            prop_assume!(h0.activity > 1e-6);
            prop_assert!(close(h0.mobility, h1.mobility, 1e-6));
            prop_assert!(close(h0.complexity, h1.complexity, 1e-6));
        }
    }
}
