use ndarray::{Array1, ArrayD, ArrayView1, ArrayViewD, Axis};

use crate::checks::{check_finite, finite_result, resolve_axis, FeatureError};
use crate::Sample;

/// Mean over every element: the stiffness feature F̄ is the mean normal force over all force
/// sensors of all cells and all time steps of the hold (paper §3.2.1).
pub fn mean_all<T: Sample>(name: &str, x: ArrayViewD<'_, T>) -> Result<f64, FeatureError> {
    if x.is_empty() {
        return Err(FeatureError::shape(name, "cannot average an empty array"));
    }
    check_finite(name, &x)?;
    // Pairwise-free but compensated (Kahan–Babuška/Neumaier) summation keeps the mean exact to
    // the last bits even over millions of samples.
    let mut sum = 0.0f64;
    let mut comp = 0.0f64;
    for v in x.iter() {
        let v = v.to_f64();
        let t = sum + v;
        if sum.abs() >= v.abs() {
            comp += (sum - t) + v;
        } else {
            comp += (v - t) + sum;
        }
        sum = t;
    }
    let mean = (sum + comp) / x.len() as f64;
    finite_result(name, "mean", [mean].iter())?;
    Ok(mean)
}

/// Gradient with unit spacing, as `numpy.gradient(x)` with `edge_order=1`: central differences
/// inside, one-sided differences at both ends. Needs at least 2 samples.
pub fn gradient<T: Sample>(x: ArrayView1<'_, T>) -> Array1<f64> {
    let n = x.len();
    let mut out = Array1::<f64>::zeros(n);
    if n < 2 {
        return out;
    }
    let v = |i: usize| x[i].to_f64();
    out[0] = v(1) - v(0);
    out[n - 1] = v(n - 1) - v(n - 2);
    for i in 1..n - 1 {
        out[i] = (v(i + 1) - v(i - 1)) / 2.0;
    }
    out
}

/// [`gradient`] of every lane along `axis`.
pub fn gradient_along<T: Sample>(
    name: &str,
    x: ArrayViewD<'_, T>,
    axis: isize,
) -> Result<ArrayD<f64>, FeatureError> {
    let axis = resolve_axis(name, axis, x.ndim())?;
    if x.len_of(Axis(axis)) < 2 {
        return Err(FeatureError::shape(
            name,
            format!("a gradient needs at least 2 samples along axis {axis}"),
        ));
    }
    check_finite(name, &x)?;
    let mut out = ArrayD::<f64>::zeros(x.raw_dim());
    for (src, mut dst) in x
        .lanes(Axis(axis))
        .into_iter()
        .zip(out.lanes_mut(Axis(axis)))
    {
        dst.assign(&gradient(src));
    }
    finite_result(name, "gradient", out.iter())?;
    Ok(out)
}

/// The thermal observation `[T̄, ∇T̄]` (paper §3.2.3): `T̄` is the mean over every temperature
/// sensor at each time step and `∇T̄` its gradient per step. `temp` holds time along `axis`;
/// all other axes (cells, sensors per cell) are averaged. Returns `2 · n_steps` values.
pub fn thermal_curve<T: Sample>(
    name: &str,
    temp: ArrayViewD<'_, T>,
    axis: isize,
) -> Result<Array1<f64>, FeatureError> {
    let axis = resolve_axis(name, axis, temp.ndim())?;
    let steps = temp.len_of(Axis(axis));
    if steps < 2 {
        return Err(FeatureError::shape(
            name,
            format!("a temperature curve needs at least 2 time steps, got {steps}"),
        ));
    }
    if temp.is_empty() {
        return Err(FeatureError::shape(name, "no temperature sensors"));
    }
    check_finite(name, &temp)?;
    let sensors = (temp.len() / steps) as f64;
    let mut mean = Array1::<f64>::zeros(steps);
    for (t, slice) in temp.axis_iter(Axis(axis)).enumerate() {
        mean[t] = slice.iter().map(|v| v.to_f64()).sum::<f64>() / sensors;
    }
    let grad = gradient(mean.view());
    let mut out = Array1::<f64>::zeros(2 * steps);
    out.slice_mut(ndarray::s![..steps]).assign(&mean);
    out.slice_mut(ndarray::s![steps..]).assign(&grad);
    finite_result(name, "temperature curve", out.iter())?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::{array, Array3};

    #[test]
    fn gradient_matches_numpy_semantics() {
        let x = array![1.0, 2.0, 4.0, 7.0, 11.0];
        // numpy.gradient([1, 2, 4, 7, 11]) == [1. , 1.5, 2.5, 3.5, 4. ]
        assert_eq!(gradient(x.view()), array![1.0, 1.5, 2.5, 3.5, 4.0]);
    }

    #[test]
    fn mean_is_exact_for_large_offsets() {
        let x = Array3::from_shape_fn((7, 3, 1000), |(i, j, k)| {
            1e8 + ((i + j + k) % 3) as f64 - 1.0
        });
        let m = mean_all("force", x.view().into_dyn()).unwrap();
        let exact = x.iter().map(|v| v - 1e8).sum::<f64>() / x.len() as f64 + 1e8;
        assert!((m - exact).abs() < 1e-7);
    }

    #[test]
    fn thermal_curve_of_linear_ramp() {
        // Two cells, one sensor each, both ramping at 0.5 °C/step: mean ramp, gradient 0.5.
        let temp = Array3::from_shape_fn((2, 1, 6), |(c, _, t)| 30.0 + c as f64 - 0.5 * t as f64);
        let curve = thermal_curve("temp", temp.view().into_dyn(), -1).unwrap();
        assert_eq!(curve.len(), 12);
        for t in 0..6 {
            assert!((curve[t] - (30.5 - 0.5 * t as f64)).abs() < 1e-12);
            assert!((curve[6 + t] + 0.5).abs() < 1e-12);
        }
    }

    #[test]
    fn overflowing_results_are_errors_not_infinities() {
        let big = ArrayD::from_shape_vec(ndarray::IxDyn(&[4]), vec![1e308, -1e308, 1e308, -1e308])
            .unwrap();
        assert_eq!(mean_all("f", big.view()).unwrap(), 0.0);
        let huge = ArrayD::from_shape_vec(ndarray::IxDyn(&[2]), vec![1.7e308, 1.7e308]).unwrap();
        assert!(matches!(
            mean_all("f", huge.view()),
            Err(FeatureError::NonFiniteResult { .. })
        ));
        assert!(matches!(
            gradient_along("t", big.view(), 0),
            Err(FeatureError::NonFiniteResult { .. })
        ));
        let temp =
            ArrayD::from_shape_vec(ndarray::IxDyn(&[1, 2]), vec![1.7e308, -1.7e308]).unwrap();
        assert!(matches!(
            thermal_curve("t", temp.view(), -1),
            Err(FeatureError::NonFiniteResult { .. })
        ));
    }

    #[test]
    fn empty_and_short_inputs_are_errors() {
        let e = ArrayD::<f64>::zeros(ndarray::IxDyn(&[0, 3]));
        assert!(mean_all("f", e.view()).is_err());
        let short = ArrayD::<f64>::zeros(ndarray::IxDyn(&[3, 1]));
        assert!(thermal_curve("t", short.view(), -1).is_err());
        assert!(gradient_along("t", short.view(), 1).is_err());
    }
}
