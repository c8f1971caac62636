//! Small dense kernels of the sweep on preallocated buffers: matrix
//! products through faer (SIMD chosen at run time) on nalgebra storage,
//! a column-blocked `y += A x`, an in-place Cholesky factorisation and
//! triangular solves. Nothing here allocates.

use faer::linalg::matmul::matmul;
use faer::linalg::triangular_solve::{
    solve_lower_triangular_in_place, solve_upper_triangular_in_place,
};
use faer::{Accum, MatMut, MatRef, Par};
use nalgebra::DMatrix;

/// faer view of a whole nalgebra matrix.
#[inline]
pub(crate) fn view(a: &DMatrix<f64>) -> MatRef<'_, f64> {
    MatRef::from_column_major_slice(a.as_slice(), a.nrows(), a.ncols())
}

/// Mutable faer view of a whole nalgebra matrix.
#[inline]
pub(crate) fn view_mut(a: &mut DMatrix<f64>) -> MatMut<'_, f64> {
    let (r, c) = a.shape();
    MatMut::from_column_major_slice_mut(a.as_mut_slice(), r, c)
}

/// `dst = α a b` (`add = false`) or `dst += α a b` (`add = true`).
#[inline]
pub(crate) fn mul(
    dst: MatMut<'_, f64>,
    add: bool,
    a: MatRef<'_, f64>,
    b: MatRef<'_, f64>,
    alpha: f64,
) {
    let acc = if add { Accum::Add } else { Accum::Replace };
    matmul(dst, acc, a, b, alpha, Par::Seq);
}

/// `y += A x` for a column-major `y.len() × x.len()` matrix `a`. Four
/// columns per pass over `y` (a quarter of the loads and stores of the
/// axpy form, and it vectorises without reassociating within a column).
#[inline]
pub(crate) fn gemv_acc(a: &[f64], x: &[f64], y: &mut [f64]) {
    let rows = y.len();
    if rows == 0 {
        return;
    }
    debug_assert_eq!(a.len(), rows * x.len());
    let mut cols = a.chunks_exact(rows);
    let mut xs = x.chunks_exact(4);
    for xq in &mut xs {
        let (Some(c0), Some(c1), Some(c2), Some(c3)) =
            (cols.next(), cols.next(), cols.next(), cols.next())
        else {
            return;
        };
        let (x0, x1, x2, x3) = (xq[0], xq[1], xq[2], xq[3]);
        for ((((yi, a0), a1), a2), a3) in y.iter_mut().zip(c0).zip(c1).zip(c2).zip(c3) {
            *yi += (a0 * x0 + a1 * x1) + (a2 * x2 + a3 * x3);
        }
    }
    for (&xj, col) in xs.remainder().iter().zip(cols) {
        for (yi, ai) in y.iter_mut().zip(col) {
            *yi += ai * xj;
        }
    }
}

/// In-place Cholesky factor `A = C Cᵀ` of a symmetric matrix (lower
/// triangle read, `C` written there, the strict upper triangle zeroed).
/// False when `A` is not numerically positive definite.
pub(crate) fn cholesky_in_place(a: &mut DMatrix<f64>) -> bool {
    let n = a.nrows();
    for j in 0..n {
        let mut d = a[(j, j)];
        for k in 0..j {
            d -= a[(j, k)] * a[(j, k)];
        }
        if !(d > 0.0 && d.is_finite()) {
            return false;
        }
        let d = d.sqrt();
        a[(j, j)] = d;
        for i in j + 1..n {
            let mut s = a[(i, j)];
            for k in 0..j {
                s -= a[(i, k)] * a[(j, k)];
            }
            a[(i, j)] = s / d;
            a[(j, i)] = 0.0;
        }
    }
    true
}

/// `B ← C⁻¹ B` with `C` lower triangular.
#[inline]
pub(crate) fn solve_lower(c: &DMatrix<f64>, b: MatMut<'_, f64>) {
    solve_lower_triangular_in_place(view(c), b, Par::Seq);
}

/// `B ← C⁻ᵀ B` with `C` lower triangular.
#[inline]
pub(crate) fn solve_lower_t(c: &DMatrix<f64>, b: MatMut<'_, f64>) {
    solve_upper_triangular_in_place(view(c).transpose(), b, Par::Seq);
}

/// `x ← C⁻ᵀ x` for a vector (`C` lower triangular).
pub(crate) fn solve_lower_t_vec(c: &DMatrix<f64>, x: &mut [f64]) {
    for i in (0..x.len()).rev() {
        let mut s = x[i];
        for (k, xk) in x.iter().enumerate().skip(i + 1) {
            s -= c[(k, i)] * xk;
        }
        x[i] = s / c[(i, i)];
    }
}

pub(crate) use super::symmetrize;

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(r: usize, c: usize, seed: usize) -> DMatrix<f64> {
        DMatrix::from_fn(r, c, |i, j| {
            (((i * 31 + j * 17 + seed * 7) % 23) as f64 - 11.0) / 7.0
        })
    }

    #[test]
    fn gemv_matches_nalgebra() {
        for (r, c) in [(24, 24), (24, 22), (7, 5), (32, 24), (3, 1)] {
            let a = sample(r, c, 1);
            let x = sample(c, 1, 2);
            let mut y = sample(r, 1, 3);
            let want = &y + &a * &x;
            gemv_acc(a.as_slice(), x.as_slice(), y.as_mut_slice());
            assert!((&y - &want).amax() < 1e-13 * want.amax());
        }
    }

    #[test]
    fn symmetrize_averages_the_triangles() {
        let a = sample(7, 7, 6);
        let mut s = a.clone();
        symmetrize(&mut s);
        let want = (&a + a.transpose()) * 0.5;
        assert!((&s - &want).amax() < 1e-15);
    }

    #[test]
    fn cholesky_and_solves_reconstruct() {
        let b = sample(8, 8, 4);
        let a = &b * b.transpose() + DMatrix::identity(8, 8);
        let mut c = a.clone();
        assert!(cholesky_in_place(&mut c));
        assert!((&c * c.transpose() - &a).amax() < 1e-12 * a.amax());
        let rhs = sample(8, 5, 5);
        let mut x = rhs.clone();
        solve_lower(&c, view_mut(&mut x));
        solve_lower_t(&c, view_mut(&mut x));
        assert!((&a * &x - &rhs).amax() < 1e-11);
        let v = rhs.column(0).into_owned();
        let mut w = c.transpose() * &v;
        solve_lower_t_vec(&c, w.as_mut_slice());
        assert!((&w - &v).amax() < 1e-12);
        let mut bad = -a;
        assert!(!cholesky_in_place(&mut bad));
    }
}
