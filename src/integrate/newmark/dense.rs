//! Small dense kernels of the Newton step (n ≤ a few dozen; large problems
//! go through faer elsewhere): column-major matrix–vector products, an
//! in-place Cholesky with reciprocal diagonal and its solve, an LU fallback.
//!
//! Every kernel takes a const `N`: a non-zero `N` is the size known at
//! compile time (loops unrolled, bounds checks gone, vectors kept in
//! registers); `N = 0` uses the run-time `n`. Both perform the same
//! operations in the same order, so the results are the same bits.

use nalgebra::DMatrix;

/// The kernel size: `N` when non-zero, else the run-time `n`.
#[inline(always)]
pub(super) fn dim<const N: usize>(n: usize) -> usize {
    if N == 0 {
        n
    } else {
        debug_assert_eq!(n, N);
        N
    }
}

/// The vector width the Newton iterations and the derivative steps run
/// at: a copy of each compiled for AVX-512 (eight lanes) or AVX2 (four)
/// when the CPU runs it (x86-64, detected at run time), else the baseline
/// (two). Rust never fuses a product and a sum on its own and keeps the
/// order of every sum, so every copy performs the same operations as the
/// baseline: the same bits (test
/// `every_vector_width_gives_the_same_bits`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Lanes {
    Two,
    Four,
    Eight,
}

#[cfg(test)]
thread_local! {
    /// A width forced on this thread (tests of the copies).
    pub(crate) static FORCED: std::cell::Cell<Option<Lanes>> = const { std::cell::Cell::new(None) };
}

/// The widest copy the CPU runs ([`Lanes`]).
#[inline(always)]
pub(crate) fn lanes() -> Lanes {
    #[cfg(test)]
    if let Some(l) = FORCED.with(|f| f.get()) {
        return l;
    }
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx512f") {
            return Lanes::Eight;
        }
        if std::arch::is_x86_feature_detected!("avx2") {
            return Lanes::Four;
        }
    }
    Lanes::Two
}

/// y += s A x (A column-major n×n).
#[inline(always)]
pub(super) fn mat_vec_axpy<const N: usize>(a: &[f64], n: usize, x: &[f64], s: f64, y: &mut [f64]) {
    let n = dim::<N>(n);
    let (a, x, y) = (&a[..n * n], &x[..n], &mut y[..n]);
    for (col, &xj) in a.chunks_exact(n).zip(x) {
        let sx = s * xj;
        for (yi, &aij) in y.iter_mut().zip(col) {
            *yi += aij * sx;
        }
    }
}

/// `y = A x` (A column-major, `4Q` rows, `x.len()` columns): the sums of
/// [`mat_vec_axpy`] with `s = 1` from `y = 0`, column after column, each
/// row in the same order (the same bits), with the `4Q` sums held in `Q`
/// arrays of four for the whole product instead of stored after each
/// column.
#[inline(always)]
#[allow(clippy::needless_range_loop)]
pub(super) fn mat_vec_quads<const Q: usize>(a: &[f64], x: &[f64], y: &mut [f64]) {
    let m = 4 * Q;
    let mut acc = [[0.0; 4]; Q];
    for (col, &xj) in a.chunks_exact(m).zip(x) {
        let sx = 1.0 * xj;
        for q in 0..Q {
            for l in 0..4 {
                acc[q][l] += col[4 * q + l] * sx;
            }
        }
    }
    for (yq, aq) in y[..m].chunks_exact_mut(4).zip(&acc) {
        yq.copy_from_slice(aq);
    }
}

/// `y = A x` (A column-major with `y.len()` rows and `x.len()` columns,
/// `y` overwritten): [`mat_vec_quads`] for 12 or 24 rows (the derivative
/// and whole-sample maps of 4 and 8 DOFs), else [`mat_vec_axpy`]'s sums
/// from zero; the same bits either way.
#[inline(always)]
pub(super) fn mat_vec(a: &[f64], x: &[f64], y: &mut [f64]) {
    match y.len() {
        12 => mat_vec_quads::<3>(a, x, y),
        24 => mat_vec_quads::<6>(a, x, y),
        m => {
            y.fill(0.0);
            for (col, &xj) in a.chunks_exact(m).zip(x) {
                let sx = 1.0 * xj;
                for (yi, &aij) in y.iter_mut().zip(col) {
                    *yi += aij * sx;
                }
            }
        }
    }
}

/// `max(m, maxᵢ |xᵢ|)`, NaNs ignored (as `f64::max` does). `m ≥ 0` and the
/// `|xᵢ|` are never −0, so the order of the comparisons cannot change the
/// result: four independent lanes instead of one serial chain.
#[inline(always)]
pub(super) fn max_abs<const N: usize>(m: f64, x: &[f64], n: usize) -> f64 {
    let n = dim::<N>(n);
    let mut acc = [m; 4];
    let chunks = x[..n].chunks_exact(4);
    let rest = chunks.remainder();
    for c in chunks {
        for (a, &v) in acc.iter_mut().zip(c) {
            *a = max_num(*a, v.abs());
        }
    }
    for (a, &v) in acc.iter_mut().zip(rest) {
        *a = max_num(*a, v.abs());
    }
    max_num(max_num(acc[0], acc[1]), max_num(acc[2], acc[3]))
}

/// `a.max(b)` for a non-NaN `a`: one comparison (a NaN `b` keeps `a`).
#[inline(always)]
fn max_num(a: f64, b: f64) -> f64 {
    if b > a {
        b
    } else {
        a
    }
}

/// In-place Cholesky of an SPD matrix (column-major, lower triangle used
/// and overwritten with L, whose diagonal is stored as its reciprocal so
/// the solves multiply instead of divide). Returns false if not SPD.
#[inline(always)]
pub(super) fn cholesky_in_place<const N: usize>(a: &mut [f64], n: usize) -> bool {
    let n = dim::<N>(n);
    let a = &mut a[..n * n];
    for j in 0..n {
        let (done, rest) = a.split_at_mut(j * n);
        let col_j = &mut rest[..n];
        // col_j[i] -= Σ_k L[i,k] L[j,k]  for i ≥ j
        for col_k in done.chunks_exact(n) {
            let ljk = col_k[j];
            for i in j..n {
                col_j[i] -= col_k[i] * ljk;
            }
        }
        let d = col_j[j];
        if !(d > 0.0) || !d.is_finite() {
            return false;
        }
        let inv = 1.0 / d.sqrt();
        col_j[j] = inv;
        for x in col_j.iter_mut().skip(j + 1) {
            *x *= inv;
        }
    }
    true
}

/// Solve L Lᵀ x = b in place (L from [`cholesky_in_place`]).
#[inline(always)]
pub(super) fn chol_solve<const N: usize>(l: &[f64], n: usize, b: &mut [f64]) {
    let n = dim::<N>(n);
    let (l, b) = (&l[..n * n], &mut b[..n]);
    // forward: L y = b, column-oriented
    for j in 0..n {
        let col = &l[j * n..(j + 1) * n];
        let y = b[j] * col[j];
        b[j] = y;
        for i in (j + 1)..n {
            b[i] -= col[i] * y;
        }
    }
    // backward: Lᵀ x = y
    for i in (0..n).rev() {
        let col = &l[i * n..(i + 1) * n];
        let mut s = b[i];
        for k in (i + 1)..n {
            s -= col[k] * b[k];
        }
        b[i] = s * col[i];
    }
}

/// General solve (indefinite tangent, e.g. a softening cubic), with
/// nalgebra's LU. Returns false when singular.
pub(super) fn lu_solve(a: &[f64], n: usize, b: &mut [f64]) -> bool {
    let m = DMatrix::from_column_slice(n, n, a);
    match m.lu().solve(&nalgebra::DVector::from_column_slice(b)) {
        Some(x) => {
            b.copy_from_slice(x.as_slice());
            true
        }
        None => false,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A seeded SPD matrix `B Bᵀ + n I` and a right-hand side.
    fn spd(n: usize, seed: u64) -> (Vec<f64>, Vec<f64>) {
        let mut s = seed;
        let mut rnd = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        let b: Vec<f64> = (0..n * n).map(|_| rnd()).collect();
        let mut a = vec![0.0; n * n];
        for c in 0..n {
            for r in 0..n {
                a[c * n + r] = (0..n).map(|k| b[k * n + r] * b[k * n + c]).sum::<f64>();
            }
            a[c * n + c] += n as f64;
        }
        (a, (0..n).map(|_| rnd()).collect())
    }

    fn solve<const N: usize>(a: &[f64], n: usize, rhs: &[f64]) -> Vec<f64> {
        let mut l = a.to_vec();
        assert!(cholesky_in_place::<N>(&mut l, n));
        let mut x = rhs.to_vec();
        chol_solve::<N>(&l, n, &mut x);
        x
    }

    #[test]
    fn cholesky_solves_and_sizes_agree_bit_for_bit() {
        for seed in 1..6 {
            let (a, rhs) = spd(8, seed);
            let x = solve::<0>(&a, 8, &rhs);
            assert_eq!(x, solve::<8>(&a, 8, &rhs));
            // A x = rhs
            let mut r = rhs.clone();
            mat_vec_axpy::<0>(&a, 8, &x, -1.0, &mut r);
            let mut r8 = rhs.clone();
            mat_vec_axpy::<8>(&a, 8, &x, -1.0, &mut r8);
            assert_eq!(r, r8);
            assert!(r.iter().all(|e| e.abs() < 1e-13), "{r:?}");
            let mut lu = rhs.clone();
            assert!(lu_solve(&a, 8, &mut lu));
            for (p, q) in x.iter().zip(&lu) {
                approx::assert_relative_eq!(p, q, max_relative = 1e-12);
            }
        }
    }

    #[test]
    fn quads_product_equals_the_axpy_bit_for_bit() {
        for seed in 1..4 {
            let (a, _) = spd(24, seed);
            let x: Vec<f64> = a[..24].iter().map(|v| v * 3.7 - 1.0).collect();
            let mut y = vec![0.0; 24];
            mat_vec_axpy::<0>(&a, 24, &x, 1.0, &mut y);
            let mut q = vec![f64::NAN; 24];
            mat_vec_quads::<6>(&a, &x, &mut q);
            assert_eq!(y, q);
            // a tall map (rows 4Q, more columns)
            let mut yt = vec![0.0; 12];
            for (col, &xj) in a[..12 * 20].chunks_exact(12).zip(&x[..20]) {
                for (yi, &c) in yt.iter_mut().zip(col) {
                    *yi += c * xj;
                }
            }
            let mut qt = vec![f64::NAN; 12];
            mat_vec_quads::<3>(&a[..12 * 20], &x[..20], &mut qt);
            assert_eq!(yt, qt);
        }
    }

    #[test]
    fn cholesky_rejects_indefinite() {
        let (mut a, _) = spd(3, 9);
        a[4] = -50.0;
        assert!(!cholesky_in_place::<3>(&mut a.clone(), 3));
        assert!(!cholesky_in_place::<0>(&mut a, 3));
    }
}
