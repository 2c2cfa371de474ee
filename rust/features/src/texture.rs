use ndarray::{Array1, ArrayD, ArrayView1, ArrayView2, ArrayViewD, Axis, Dimension, Ix2, IxDyn};

use crate::checks::{check_finite, finite_result, resolve_axis, FeatureError};
use crate::hjorth::hjorth_checked;
use crate::Sample;

/// Length of the texture descriptor: A, M, C per axis (3 × 3) and the 3 axis-pair correlations.
pub const TEXTURE_DIM: usize = 12;

/// Pearson correlation of two equally long signals; NaN when either is constant.
pub fn pearson<A: Sample, B: Sample>(a: ArrayView1<'_, A>, b: ArrayView1<'_, B>) -> f64 {
    let n = a.len().min(b.len());
    if n == 0 {
        return f64::NAN;
    }
    let nf = n as f64;
    let ma = a.iter().take(n).map(|v| v.to_f64()).sum::<f64>() / nf;
    let mb = b.iter().take(n).map(|v| v.to_f64()).sum::<f64>() / nf;
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for (x, y) in a.iter().zip(b.iter()) {
        let da = x.to_f64() - ma;
        let db = y.to_f64() - mb;
        sab += da * db;
        saa += da * da;
        sbb += db * db;
    }
    sab / (saa * sbb).sqrt()
}

/// Correlations of the axis pairs (x, y), (y, z), (x, z) — the paper's L(a) — for every
/// 3-axis signal in `acc`. `channel_axis` must have length 3; `time_axis` holds the samples.
/// The output drops both axes and appends one of length 3.
pub fn axis_pair_correlations<T: Sample>(
    name: &str,
    acc: ArrayViewD<'_, T>,
    channel_axis: isize,
    time_axis: isize,
) -> Result<ArrayD<f64>, FeatureError> {
    let ndim = acc.ndim();
    let ch = resolve_axis(name, channel_axis, ndim)?;
    let ti = resolve_axis(name, time_axis, ndim)?;
    if ch == ti {
        return Err(FeatureError::shape(
            name,
            "channel_axis and time_axis must differ",
        ));
    }
    if acc.len_of(Axis(ch)) != 3 {
        return Err(FeatureError::shape(
            name,
            format!(
                "axis {ch} must hold the 3 acceleration axes, it has length {}",
                acc.len_of(Axis(ch))
            ),
        ));
    }
    if acc.len_of(Axis(ti)) < 2 {
        return Err(FeatureError::shape(
            name,
            "a correlation needs at least 2 samples",
        ));
    }
    check_finite(name, &acc)?;
    // Put channels and time last so each outer index yields one (3, T) block.
    let mut order: Vec<usize> = (0..ndim).filter(|&a| a != ch && a != ti).collect();
    let outer_shape: Vec<usize> = order.iter().map(|&a| acc.len_of(Axis(a))).collect();
    order.push(ch);
    order.push(ti);
    let view = acc.permuted_axes(IxDyn(&order));
    let mut out = Vec::with_capacity(outer_shape.iter().product::<usize>() * 3);
    for idx in ndarray::indices(IxDyn(&outer_shape)) {
        let mut block = view.view();
        for &i in idx.slice() {
            block = block.index_axis_move(Axis(0), i);
        }
        let block = block
            .into_dimensionality::<Ix2>()
            .map_err(|e| FeatureError::shape(name, format!("internal shape error: {e}")))?;
        push_pairs(&mut out, block);
    }
    let mut shape = outer_shape;
    shape.push(3);
    ArrayD::from_shape_vec(IxDyn(&shape), out)
        .map_err(|e| FeatureError::shape(name, format!("internal shape error: {e}")))
}

fn push_pairs<T: Sample>(out: &mut Vec<f64>, block: ArrayView2<'_, T>) {
    let (x, y, z) = (block.row(0), block.row(1), block.row(2));
    out.push(pearson(x, y));
    out.push(pearson(y, z));
    out.push(pearson(x, z));
}

/// The texture descriptor `TD = [A, M, C, L]` (paper §3.2.2) of a sliding recording `acc` with
/// shape (cells, 3 axes, time): Hjorth activity, mobility, complexity of each axis and the
/// axis-pair correlations, each averaged over cells. Layout:
/// `[A_x, A_y, A_z, M_x, M_y, M_z, C_x, C_y, C_z, L_xy, L_yz, L_xz]`.
pub fn texture_descriptor<T: Sample>(
    name: &str,
    acc: ArrayViewD<'_, T>,
) -> Result<Array1<f64>, FeatureError> {
    if acc.ndim() != 3 || acc.shape()[1] != 3 {
        return Err(FeatureError::shape(
            name,
            format!("expected shape (cells, 3, time), got {:?}", acc.shape()),
        ));
    }
    let (cells, _, steps) = (acc.shape()[0], 3, acc.shape()[2]);
    if cells == 0 {
        return Err(FeatureError::shape(name, "no cells"));
    }
    if steps < 3 {
        return Err(FeatureError::shape(
            name,
            format!("need at least 3 time steps, got {steps}"),
        ));
    }
    let mut td = Array1::<f64>::zeros(TEXTURE_DIM);
    for cell in acc.outer_iter() {
        for (axis, lane) in cell.lanes(Axis(1)).into_iter().enumerate() {
            let h = hjorth_checked(name, lane, &acc)?;
            td[axis] += h.activity;
            td[3 + axis] += h.mobility;
            td[6 + axis] += h.complexity;
        }
        let mut pairs = Vec::with_capacity(3);
        let cell = cell
            .into_dimensionality::<Ix2>()
            .map_err(|e| FeatureError::shape(name, format!("internal shape error: {e}")))?;
        push_pairs(&mut pairs, cell);
        for (k, r) in pairs.into_iter().enumerate() {
            td[9 + k] += r;
        }
    }
    td /= cells as f64;
    // Any NaN or infinity in the input reaches the activities; scan for its index only then.
    if td.iter().take(3).any(|v| !v.is_finite()) {
        check_finite(name, &acc)?;
    }
    // Each activity is finite; their sum over the cells may still overflow.
    finite_result(name, "mean activity", td.iter().take(3))?;
    Ok(td)
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::{array, Array3};

    #[test]
    fn pearson_of_affine_copies_is_one() {
        let a = array![1.0, 3.0, 2.0, 5.0, 4.0];
        let b = a.mapv(|v| -2.0 * v + 7.0);
        assert!((pearson(a.view(), a.view()) - 1.0).abs() < 1e-15);
        assert!((pearson(a.view(), b.view()) + 1.0).abs() < 1e-15);
    }

    #[test]
    fn pair_order_is_xy_yz_xz() {
        // x = t, y = -t, z = t^2 over symmetric t: r(x,y) = -1, r(y,z) = 0, r(x,z) = 0.
        let t: Vec<f64> = (-5..=5).map(|v| v as f64).collect();
        let acc = Array3::from_shape_fn((1, 3, t.len()), |(_, a, k)| match a {
            0 => t[k],
            1 => -t[k],
            _ => t[k] * t[k],
        });
        let r = axis_pair_correlations("acc", acc.view().into_dyn(), -2, -1).unwrap();
        assert_eq!(r.shape(), &[1, 3]);
        assert!((r[[0, 0]] + 1.0).abs() < 1e-12);
        assert!(r[[0, 1]].abs() < 1e-12);
        assert!(r[[0, 2]].abs() < 1e-12);
    }

    #[test]
    fn descriptor_averages_cells() {
        let acc = Array3::from_shape_fn((2, 3, 64), |(c, a, k)| {
            ((k * (a + 1)) as f64 * 0.3).sin() * (c + 1) as f64
        });
        let td = texture_descriptor("acc", acc.view().into_dyn()).unwrap();
        let c0 =
            texture_descriptor("acc", acc.slice(ndarray::s![0..1, .., ..]).into_dyn()).unwrap();
        let c1 =
            texture_descriptor("acc", acc.slice(ndarray::s![1..2, .., ..]).into_dyn()).unwrap();
        for k in 0..TEXTURE_DIM {
            assert!((td[k] - (c0[k] + c1[k]) / 2.0).abs() < 1e-12);
        }
        // Scaling a cell's signal by 2 multiplies its activity by 4 and leaves the rest alone.
        assert!((c1[0] - 4.0 * c0[0]).abs() < 1e-12);
        assert!((c1[3] - c0[3]).abs() < 1e-12);
    }
}
