//! Sparse symmetric matrices (faer CSC) and the lowest modes of a sparse
//! generalized eigenproblem `K φ = ω² M φ`.
//!
//! The modes come from faer's Krylov–Schur partial eigensolver
//! ([`faer::matrix_free::eigen::partial_eigen`]) applied to the
//! shift-invert operator `x ↦ (K + σM)⁻¹ M x`, whose largest eigenvalues
//! `μ = 1/(ω² + σ)` are the lowest modes; `K + σM` is factored once with
//! faer's sparse Cholesky. The Krylov vectors are then cleaned by a
//! Rayleigh–Ritz step on the dense projected pair `(Vᵀ K V, Vᵀ M V)`, which
//! returns real, mass-normalized shapes and Ritz frequencies.

use crate::error::{Result, TacitError};
use faer::dyn_stack::{MemBuffer, MemStack, StackReq};
use faer::linalg::solvers::Solve;
use faer::matrix_free::eigen::{partial_eigen, partial_eigen_scratch, PartialEigenParams};
use faer::matrix_free::LinOp;
use faer::sparse::{SparseColMat, Triplet};
use faer::{Mat, MatMut, MatRef, Par};
use nalgebra::DMatrix;

/// A sparse real matrix (compressed columns, 0-based).
pub type SpMat = SparseColMat<usize, f64>;

/// Build an `n × m` sparse matrix from `(row, col, value)` entries
/// (duplicates are summed).
pub fn from_entries(n: usize, m: usize, entries: &[(usize, usize, f64)]) -> Result<SpMat> {
    let t: Vec<Triplet<usize, usize, f64>> = entries
        .iter()
        .map(|&(r, c, v)| Triplet::new(r, c, v))
        .collect();
    SpMat::try_new_from_triplets(n, m, &t)
        .map_err(|e| TacitError::Numerical(format!("sparse matrix assembly failed: {e:?}")))
}

/// The entries of `a`, column by column.
pub fn entries(a: &SpMat) -> Vec<(usize, usize, f64)> {
    let mut out = Vec::with_capacity(a.compute_nnz());
    let s = a.symbolic();
    let vals = a.val();
    for c in 0..a.ncols() {
        let range = s.col_range(c);
        for (p, &r) in range.clone().zip(s.row_idx()[range].iter()) {
            out.push((r, c, vals[p]));
        }
    }
    out
}

/// The block `a[rows, cols]` (indices into the full matrix).
pub fn block(a: &SpMat, rows: &[usize], cols: &[usize]) -> Result<SpMat> {
    let mut rmap = vec![usize::MAX; a.nrows()];
    for (i, &r) in rows.iter().enumerate() {
        rmap[r] = i;
    }
    let mut cmap = vec![usize::MAX; a.ncols()];
    for (j, &c) in cols.iter().enumerate() {
        cmap[c] = j;
    }
    let e: Vec<(usize, usize, f64)> = entries(a)
        .into_iter()
        .filter(|&(r, c, _)| rmap[r] != usize::MAX && cmap[c] != usize::MAX)
        .map(|(r, c, v)| (rmap[r], cmap[c], v))
        .collect();
    from_entries(rows.len(), cols.len(), &e)
}

/// `a x` for a sparse `a` and a dense `x`.
pub fn mul(a: &SpMat, x: MatRef<'_, f64>) -> Mat<f64> {
    a.as_ref() * x
}

/// `xᵀ a x`, symmetrized, as a nalgebra matrix.
pub fn project(a: &SpMat, x: MatRef<'_, f64>) -> DMatrix<f64> {
    let ax = mul(a, x);
    let p = x.transpose() * ax.as_ref();
    let r = p.nrows();
    DMatrix::from_fn(r, r, |i, j| 0.5 * (p[(i, j)] + p[(j, i)]))
}

/// A sparse Cholesky factor of a symmetric positive definite matrix.
pub struct Factor(faer::sparse::linalg::solvers::Llt<usize, f64>);

impl std::fmt::Debug for Factor {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Factor")
    }
}

impl Factor {
    /// Factor `a` (symmetric; both triangles stored); `None` when it is not
    /// positive definite.
    pub fn new(a: &SpMat) -> Option<Factor> {
        a.sp_cholesky(faer::Side::Lower).ok().map(Factor)
    }
    /// Solve `a x = b` in place (every column of `b`).
    pub fn solve_in_place(&self, b: MatMut<'_, f64>) {
        self.0.solve_in_place(b);
    }
}

/// The shift-invert operator `x ↦ (K + σM)⁻¹ M x`.
#[derive(Debug)]
struct ShiftInvert<'a> {
    factor: &'a Factor,
    m: &'a SpMat,
}

impl LinOp<f64> for ShiftInvert<'_> {
    fn apply_scratch(&self, _rhs_ncols: usize, _par: Par) -> StackReq {
        StackReq::EMPTY
    }
    fn nrows(&self) -> usize {
        self.m.nrows()
    }
    fn ncols(&self) -> usize {
        self.m.ncols()
    }
    fn apply(&self, mut out: MatMut<'_, f64>, rhs: MatRef<'_, f64>, _par: Par, _s: &mut MemStack) {
        let mx = mul(self.m, rhs);
        out.copy_from(&mx);
        self.factor.solve_in_place(out);
    }
    fn conj_apply(&self, out: MatMut<'_, f64>, rhs: MatRef<'_, f64>, par: Par, s: &mut MemStack) {
        self.apply(out, rhs, par, s);
    }
}

/// Lowest modes of a sparse pair.
#[derive(Debug, Clone)]
pub struct SparseModes {
    /// ω² in ascending order.
    pub omega2: Vec<f64>,
    /// Mass-normalized shapes, one column per mode.
    pub shapes: Mat<f64>,
}

impl SparseModes {
    /// Frequencies, Hz (rigid-body modes 0).
    pub fn freq_hz(&self) -> Vec<f64> {
        self.omega2
            .iter()
            .map(|w2| w2.max(0.0).sqrt() / (2.0 * std::f64::consts::PI))
            .collect()
    }
}

/// The `count` lowest modes of `(k, m)` with shift `sigma` (`K + σM` must
/// be positive definite; `factor` is its Cholesky factor). Returns fewer
/// when the Krylov–Schur iteration converges fewer.
pub fn lowest_modes(k: &SpMat, m: &SpMat, factor: &Factor, count: usize) -> Result<SparseModes> {
    let n = m.nrows();
    let count = count.min(n);
    if count == 0 {
        return Ok(SparseModes {
            omega2: vec![],
            shapes: Mat::zeros(n, 0),
        });
    }
    let op = ShiftInvert { factor, m };
    let params = PartialEigenParams {
        min_dim: (2 * count).max(32).min(n),
        max_dim: (4 * count).max(64).min(n),
        max_restarts: 200,
        ..Default::default()
    };
    let par = Par::Seq;
    let mut mem = MemBuffer::new(partial_eigen_scratch(&op, count, par, params));
    let mut vecs = Mat::<faer::c64>::zeros(n, count);
    let mut vals = vec![faer::c64::new(0.0, 0.0); count];
    // deterministic start vector
    let v0 = Mat::<f64>::from_fn(n, 1, |i, _| 1.0 + ((i * 7919) % 101) as f64 / 101.0);
    let v0 = v0.col(0) / v0.col(0).norm_l2();
    // the residual test is absolute: scale it by the largest μ (power
    // iterations from v0)
    let mut x = v0.as_mat().to_owned();
    let mut mu_max = 0.0;
    for _ in 0..6 {
        let mut y = Mat::<f64>::zeros(n, 1);
        op.apply(
            y.as_mut(),
            x.as_ref(),
            par,
            MemStack::new(&mut MemBuffer::new(StackReq::EMPTY)),
        );
        mu_max = y.col(0).norm_l2();
        x = y / mu_max.max(f64::MIN_POSITIVE);
    }
    let info = partial_eigen(
        vecs.as_mut(),
        &mut vals,
        &op,
        v0.as_ref(),
        1e-10 * mu_max,
        par,
        MemStack::new(&mut mem),
        params,
    );
    let got = info.n_converged_eigen;
    if got == 0 {
        return Err(TacitError::Numerical(format!(
            "sparse eigensolver: no mode converged (asked for {count} of {n})"
        )));
    }
    // real basis: real and imaginary parts (a complex eigenvector of a
    // real operator with a real eigenvalue is a real vector times a phase)
    let phases: Vec<(f64, f64)> = (0..got).map(|j| phase_fix(vecs.as_ref(), j)).collect();
    let basis = Mat::<f64>::from_fn(n, got, |i, j| {
        let z = vecs[(i, j)];
        let (re, im) = phases[j];
        z.re * re + z.im * im
    });
    rayleigh_ritz(k, m, basis.as_ref())
}

/// Cosine and sine that rotate column `j` so that its largest entry is real.
fn phase_fix(v: MatRef<'_, faer::c64>, j: usize) -> (f64, f64) {
    let mut best = faer::c64::new(1.0, 0.0);
    let mut bn = -1.0;
    for i in 0..v.nrows() {
        let z = v[(i, j)];
        let a = z.re * z.re + z.im * z.im;
        if a > bn {
            bn = a;
            best = z;
        }
    }
    let r = bn.sqrt().max(f64::MIN_POSITIVE);
    (best.re / r, best.im / r)
}

/// Ritz pairs of `(k, m)` on the span of `basis`, mass-normalized.
pub fn rayleigh_ritz(k: &SpMat, m: &SpMat, basis: MatRef<'_, f64>) -> Result<SparseModes> {
    let kr = project(k, basis);
    let mr = project(m, basis);
    let modes = crate::modal::solve_projected(&mr, &kr).map_err(|e| {
        TacitError::Numerical(format!(
            "sparse eigensolver: the Rayleigh–Ritz step failed ({e})"
        ))
    })?;
    let r = modes.shapes.ncols();
    let q = Mat::<f64>::from_fn(basis.ncols(), r, |i, j| modes.shapes[(i, j)]);
    let shapes = basis * q.as_ref();
    let omega2 = modes.omega.iter().map(|w| w * w).collect();
    Ok(SparseModes { omega2, shapes })
}

/// Modes of `(k, m)` up to `f_max` Hz (at most `max_modes`): the count
/// asked for doubles until a converged mode lies above `f_max`. `sigma` is
/// the shift of the factored `K + σM`.
pub fn modes_up_to(
    k: &SpMat,
    m: &SpMat,
    factor: &Factor,
    f_max: f64,
    max_modes: usize,
) -> Result<(SparseModes, bool)> {
    let n = m.nrows();
    let mut count = 12.min(n);
    loop {
        let modes = lowest_modes(k, m, factor, count)?;
        let f = modes.freq_hz();
        let above = f.iter().any(|&x| x > f_max);
        if above || count >= n || count >= max_modes {
            let keep = f.iter().filter(|&&x| x <= f_max).count().min(max_modes);
            let complete = above || count >= n;
            return Ok((truncate(modes, keep), complete));
        }
        count = (2 * count).min(n).min(max_modes.max(1));
    }
}

fn truncate(m: SparseModes, keep: usize) -> SparseModes {
    SparseModes {
        omega2: m.omega2[..keep].to_vec(),
        shapes: m.shapes.subcols(0, keep).to_owned(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Fixed-free chain of `n` unit masses and unit springs.
    fn chain(n: usize) -> (SpMat, SpMat) {
        let mut k = vec![];
        for i in 0..n {
            k.push((i, i, if i + 1 < n { 2.0 } else { 1.0 }));
            if i + 1 < n {
                k.push((i, i + 1, -1.0));
                k.push((i + 1, i, -1.0));
            }
        }
        let m: Vec<_> = (0..n).map(|i| (i, i, 1.0)).collect();
        (
            from_entries(n, n, &k).unwrap(),
            from_entries(n, n, &m).unwrap(),
        )
    }

    #[test]
    fn lowest_modes_of_a_chain_match_the_closed_form() {
        let n = 300;
        let (k, m) = chain(n);
        let f = Factor::new(&k).unwrap();
        let modes = lowest_modes(&k, &m, &f, 10).unwrap();
        assert_eq!(modes.omega2.len(), 10);
        for (r, w2) in modes.omega2.iter().enumerate() {
            // fixed-free chain: ω_r = 2 sin((2r+1)π / (2(2n+1)))
            let exact = (2.0
                * ((2 * r + 1) as f64 * std::f64::consts::PI / (2.0 * (2 * n + 1) as f64)).sin())
            .powi(2);
            approx::assert_relative_eq!(*w2, exact, max_relative = 1e-9);
        }
        // mass-normalized
        let g = project(&m, modes.shapes.as_ref());
        approx::assert_relative_eq!(g, DMatrix::identity(10, 10), epsilon = 1e-9);
    }

    #[test]
    fn modes_up_to_stops_above_the_cutoff() {
        let (k, m) = chain(500);
        let f = Factor::new(&k).unwrap();
        let (modes, complete) = modes_up_to(&k, &m, &f, 0.05, 400).unwrap();
        let fr = modes.freq_hz();
        assert!(complete && !fr.is_empty() && fr.iter().all(|&x| x <= 0.05));
        // the count is every mode below 0.05 Hz of the closed form
        let want = (0..500)
            .filter(|&r| {
                let w = 2.0 * ((2 * r + 1) as f64 * std::f64::consts::PI / (2.0 * 1001.0)).sin();
                w / (2.0 * std::f64::consts::PI) <= 0.05
            })
            .count();
        assert_eq!(fr.len(), want);
    }

    #[test]
    fn an_indefinite_matrix_has_no_factor() {
        let a = from_entries(2, 2, &[(0, 0, 1.0), (1, 1, -1.0)]).unwrap();
        assert!(Factor::new(&a).is_none());
    }
}
