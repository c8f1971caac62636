//! Real modes of the undamped linear model: the generalized symmetric
//! eigenproblem `K φ = ω² M φ` (paper eq. 3), solved with faer by
//! factoring `M = L Lᵀ` and solving the standard problem for
//! `L⁻¹ K L⁻ᵀ`; shapes are mass-normalized (`Φᵀ M Φ = I`).

use crate::error::{Result, TacitError};
use nalgebra::DMatrix;
use serde::Serialize;

/// Modes in ascending frequency.
#[derive(Debug, Clone, Serialize)]
pub struct Modes {
    /// Circular frequencies ω (rad/s); rigid-body modes are 0.
    pub omega: Vec<f64>,
    /// Frequencies (Hz).
    pub freq_hz: Vec<f64>,
    /// Mass-normalized shapes, one column per mode (n × n).
    #[serde(skip)]
    pub shapes: DMatrix<f64>,
    /// True for rigid-body modes (ω² below 1e-9 of the largest and a shape
    /// that strains no element; [`crate::conditioning`]).
    pub rigid: Vec<bool>,
}

/// Symmetric eigen-decomposition (ascending) of a symmetric matrix with faer.
pub fn sym_eigen(a: &DMatrix<f64>) -> Result<(Vec<f64>, DMatrix<f64>)> {
    let n = a.nrows();
    let fa = faer::MatRef::from_column_major_slice(a.as_slice(), n, n);
    let eig = fa
        .self_adjoint_eigen(faer::Side::Lower)
        .map_err(|e| TacitError::Numerical(format!("symmetric eigenproblem failed: {e:?}")))?;
    let s = eig.S();
    let u = eig.U();
    let vals: Vec<f64> = (0..n).map(|i| s[i]).collect();
    let vecs = DMatrix::from_fn(n, n, |i, j| u[(i, j)]);
    Ok((vals, vecs))
}

/// Solve `K φ = ω² M φ` for symmetric K and symmetric positive definite M
/// of a model: rigid modes and modes lost in round-off as
/// [`crate::conditioning::rigid_modes`] decides.
pub fn solve(m: &DMatrix<f64>, k: &DMatrix<f64>) -> Result<Modes> {
    solve_with(m, k, false)
}

/// [`solve`] for matrices projected on a basis (a Rayleigh–Ritz step),
/// whose rows are round-off along a basis vector that moves rigidly: a
/// mode is rigid when its ω² is below 1e-9 of the largest, without the
/// model's row test.
pub fn solve_projected(m: &DMatrix<f64>, k: &DMatrix<f64>) -> Result<Modes> {
    solve_with(m, k, true)
}

fn solve_with(m: &DMatrix<f64>, k: &DMatrix<f64>, projected: bool) -> Result<Modes> {
    let n = m.nrows();
    if m.ncols() != n || k.nrows() != n || k.ncols() != n {
        return Err(TacitError::Numerical(format!(
            "eigenproblem: M is {}x{}, K is {}x{}",
            m.nrows(),
            m.ncols(),
            k.nrows(),
            k.ncols()
        )));
    }
    let chol = m.clone().cholesky().ok_or_else(|| {
        TacitError::Numerical("eigenproblem: the mass matrix is not positive definite".into())
    })?;
    let l = chol.l();
    // A = L⁻¹ K L⁻ᵀ
    let x = l
        .solve_lower_triangular(k)
        .ok_or_else(|| TacitError::Numerical("eigenproblem: singular mass factor".into()))?;
    let a = l
        .solve_lower_triangular(&x.transpose())
        .ok_or_else(|| TacitError::Numerical("eigenproblem: singular mass factor".into()))?;
    let a = (&a + a.transpose()) * 0.5;
    crate::conditioning::finite(m, k, a.as_slice())?;
    let (vals, y) = sym_eigen(&a)?;
    let shapes = l
        .transpose()
        .solve_upper_triangular(&y)
        .ok_or_else(|| TacitError::Numerical("eigenproblem: singular mass factor".into()))?;
    let rigid = if projected {
        crate::conditioning::finite(m, k, shapes.as_slice())?;
        crate::conditioning::negligible(&vals)
    } else {
        crate::conditioning::rigid_modes(m, k, &vals, &shapes)?
    };
    let omega: Vec<f64> = vals
        .iter()
        .zip(&rigid)
        .map(|(&l, &r)| if r { 0.0 } else { l.max(0.0).sqrt() })
        .collect();
    let freq_hz = omega
        .iter()
        .map(|w| w / (2.0 * std::f64::consts::PI))
        .collect();
    // sign convention: largest-magnitude entry positive
    let mut shapes = shapes;
    for c in 0..n {
        let col = shapes.column(c);
        let imax = col.iamax();
        if col[imax] < 0.0 {
            shapes.column_mut(c).scale_mut(-1.0);
        }
    }
    Ok(Modes {
        omega,
        freq_hz,
        shapes,
        rigid,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::Model;

    #[test]
    fn lanl8dof_frequencies() {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/data/lanl8dof.toml");
        let model = Model::from_file(std::path::Path::new(path)).unwrap();
        let modes = solve(&model.mass_matrix(), &model.stiffness_matrix()).unwrap();
        assert!(modes.rigid[0] && !modes.rigid[1]);
        let want = [21.97, 43.38, 63.50, 81.47, 96.45];
        for (i, w) in want.iter().enumerate() {
            let f = modes.freq_hz[i + 1];
            assert!((f - w).abs() / w < 1e-3, "mode {}: {f} vs {w}", i + 2);
        }
        // mass-orthonormal
        let g = modes.shapes.transpose() * model.mass_matrix() * &modes.shapes;
        approx::assert_relative_eq!(g, DMatrix::identity(8, 8), epsilon = 1e-10);
    }
}
