//! The few dense operations the Laplace algorithms need, on top of faer (sequential: the
//! parallelism is over one-vs-all classifiers, one per thread).

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt;
use faer::linalg::triangular_solve;
use faer::{Mat, MatMut, MatRef, Par};

/// In-place lower Cholesky factor of a symmetric positive-definite matrix (only the lower
/// triangle is read). Returns the failing pivot on error. The strictly upper triangle is
/// zeroed so the result is the factor itself.
pub fn cholesky_lower(a: &mut Mat<f64>) -> Result<(), usize> {
    let n = a.nrows();
    let mut buf = MemBuffer::new(llt::factor::cholesky_in_place_scratch::<f64>(
        n,
        Par::Seq,
        Default::default(),
    ));
    let stack = MemStack::new(&mut buf);
    llt::factor::cholesky_in_place(
        a.as_mut(),
        Default::default(),
        Par::Seq,
        stack,
        Default::default(),
    )
    .map_err(|e| match e {
        llt::factor::LltError::NonPositivePivot { index } => index,
    })?;
    for j in 1..n {
        for i in 0..j {
            a[(i, j)] = 0.0;
        }
    }
    Ok(())
}

/// Solves `L x = b` in place for a lower-triangular `L`.
pub fn solve_lower(l: MatRef<'_, f64>, rhs: &mut [f64]) {
    let n = rhs.len();
    let rhs = MatMut::from_column_major_slice_mut(rhs, n, 1);
    triangular_solve::solve_lower_triangular_in_place(l, rhs, Par::Seq);
}

/// Solves `Lᵀ x = b` in place for a lower-triangular `L`.
pub fn solve_lower_transpose(l: MatRef<'_, f64>, rhs: &mut [f64]) {
    let n = rhs.len();
    let rhs = MatMut::from_column_major_slice_mut(rhs, n, 1);
    triangular_solve::solve_upper_triangular_in_place(l.transpose(), rhs, Par::Seq);
}

/// Solves `L X = B` in place for a matrix right-hand side.
pub fn solve_lower_mat(l: MatRef<'_, f64>, rhs: MatMut<'_, f64>) {
    triangular_solve::solve_lower_triangular_in_place(l, rhs, Par::Seq);
}

/// `(L Lᵀ)⁻¹` from the lower Cholesky factor, as a full symmetric matrix.
pub fn inverse_from_cholesky(l: MatRef<'_, f64>) -> Mat<f64> {
    let mut scratch = InverseScratch::default();
    inverse_from_cholesky_in(l, &mut scratch);
    scratch.out
}

/// The output and working memory of [`inverse_from_cholesky_in`], kept by a caller that
/// inverts many n × n factors so that each inversion reuses them (two n × n buffers).
pub struct InverseScratch {
    pub out: Mat<f64>,
    mem: Option<(usize, MemBuffer)>,
}

impl Default for InverseScratch {
    fn default() -> Self {
        InverseScratch {
            out: Mat::zeros(0, 0),
            mem: None,
        }
    }
}

/// `(L Lᵀ)⁻¹` into `scratch.out` (resized to n × n if needed), as a full symmetric matrix.
pub fn inverse_from_cholesky_in(l: MatRef<'_, f64>, scratch: &mut InverseScratch) {
    let n = l.nrows();
    if scratch.out.nrows() != n || scratch.out.ncols() != n {
        scratch.out = Mat::<f64>::zeros(n, n);
    }
    if scratch.mem.as_ref().is_some_and(|(m, _)| *m != n) {
        scratch.mem = None;
    }
    let (_, buf) = scratch.mem.get_or_insert_with(|| {
        (
            n,
            MemBuffer::new(llt::inverse::inverse_scratch::<f64>(n, Par::Seq)),
        )
    });
    let stack = MemStack::new(buf);
    let out = &mut scratch.out;
    llt::inverse::inverse(out.as_mut(), l, Par::Seq, stack);
    mirror_lower(out);
}

/// Copies the strictly lower triangle of a square matrix onto the upper one, in tiles that
/// stay in cache (an element-by-element copy along rows strides through memory).
pub fn mirror_lower(a: &mut Mat<f64>) {
    const TILE: usize = 32;
    let n = a.nrows();
    assert_eq!(n, a.ncols(), "mirror_lower needs a square matrix");
    let stride = a.col_stride();
    let base = a.as_ptr_mut();
    for jb in (0..n).step_by(TILE) {
        let j_end = (jb + TILE).min(n);
        for ib in (jb..n).step_by(TILE) {
            let i_end = (ib + TILE).min(n);
            for j in jb..j_end {
                for i in ib.max(j + 1)..i_end {
                    // SAFETY: i, j < n index the n × n matrix (column stride `stride`, row
                    // stride 1 as for every Mat); the two elements differ (i > j).
                    unsafe {
                        *base.offset(j as isize + i as isize * stride) =
                            *base.offset(i as isize + j as isize * stride);
                    }
                }
            }
        }
    }
}

/// `y = A x` for a column-major square or rectangular `A`.
///
/// Column by column (`y += A[:, j] x_j`, the columns in order): on contiguous columns the loop
/// runs on the widest vector instructions the CPU offers, chosen at run time. Each `y_i` gets
/// the same additions in the same order whatever the instruction set (no fused multiply-add:
/// Rust never contracts `a * b + c`), so the result is bit-for-bit the same everywhere.
pub fn matvec(a: MatRef<'_, f64>, x: &[f64], y: &mut [f64]) {
    y.iter_mut().for_each(|v| *v = 0.0);
    if a.nrows() > 0 && a.row_stride() == 1 {
        matvec_contiguous(a, x, y);
        return;
    }
    for (j, &xj) in x.iter().enumerate() {
        if xj == 0.0 {
            continue;
        }
        let col = a.col(j);
        for (i, yi) in y.iter_mut().enumerate() {
            *yi += col[i] * xj;
        }
    }
}

/// The column loop of [`matvec`] for a matrix with contiguous columns.
#[inline(always)]
fn matvec_columns(a: MatRef<'_, f64>, x: &[f64], y: &mut [f64]) {
    let n = a.nrows();
    for (j, &xj) in x.iter().enumerate() {
        if xj == 0.0 {
            continue;
        }
        // SAFETY: row stride 1 (checked by the caller): column j is n contiguous values.
        let col = unsafe { std::slice::from_raw_parts(a.col(j).as_ptr(), n) };
        for (yi, &c) in y.iter_mut().zip(col) {
            *yi += c * xj;
        }
    }
}

crate::simd::widest_vectors! {
    fn matvec_contiguous(a: MatRef<'_, f64>, x: &[f64], y: &mut [f64]) = matvec_columns;
}

/// `y = Aᵀ x`.
pub fn matvec_t(a: MatRef<'_, f64>, x: &[f64], y: &mut [f64]) {
    for (j, yj) in y.iter_mut().enumerate() {
        let col = a.col(j);
        let mut s = 0.0;
        for (i, &xi) in x.iter().enumerate() {
            s += col[i] * xi;
        }
        *yj = s;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spd(n: usize) -> Mat<f64> {
        let a = Mat::<f64>::from_fn(n, n, |i, j| ((i * 7 + j * 13) % 11) as f64 / 11.0 - 0.4);
        let mut s = Mat::<f64>::zeros(n, n);
        for i in 0..n {
            for j in 0..n {
                let mut v = 0.0;
                for k in 0..n {
                    v += a[(i, k)] * a[(j, k)];
                }
                s[(i, j)] = v + if i == j { 1.0 } else { 0.0 };
            }
        }
        s
    }

    #[test]
    fn cholesky_reconstructs() {
        let a = spd(9);
        let mut l = a.clone();
        cholesky_lower(&mut l).unwrap();
        let r = &l * l.transpose();
        for i in 0..9 {
            for j in 0..9 {
                assert!((r[(i, j)] - a[(i, j)]).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn solves_and_inverse_agree() {
        let a = spd(12);
        let mut l = a.clone();
        cholesky_lower(&mut l).unwrap();
        let inv = inverse_from_cholesky(l.as_ref());
        let b: Vec<f64> = (0..12).map(|i| (i as f64).sin()).collect();
        let mut x = b.clone();
        solve_lower(l.as_ref(), &mut x);
        solve_lower_transpose(l.as_ref(), &mut x);
        let mut y = vec![0.0; 12];
        matvec(inv.as_ref(), &b, &mut y);
        for i in 0..12 {
            assert!((x[i] - y[i]).abs() < 1e-10);
        }
        let mut back = vec![0.0; 12];
        matvec(a.as_ref(), &x, &mut back);
        for i in 0..12 {
            assert!((back[i] - b[i]).abs() < 1e-10);
        }
    }

    #[test]
    fn mirror_lower_copies_every_element_below_the_diagonal() {
        for n in [1, 5, 31, 32, 33, 70] {
            let mut a = Mat::<f64>::from_fn(
                n,
                n,
                |i, j| if i >= j { (i * 100 + j) as f64 } else { -1.0 },
            );
            mirror_lower(&mut a);
            for i in 0..n {
                for j in 0..n {
                    assert_eq!(a[(i, j)], (i.max(j) * 100 + i.min(j)) as f64);
                }
            }
        }
    }

    #[test]
    fn indefinite_matrix_fails() {
        let mut a = Mat::<f64>::from_fn(2, 2, |i, j| if i == j { 1.0 } else { 3.0 });
        assert!(cholesky_lower(&mut a).is_err());
    }
}
