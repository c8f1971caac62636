//! Craig–Bampton reduction of a sparse model (Craig & Bampton, "Coupling of
//! substructures for dynamic analyses", AIAA J. 6(7), 1968).
//!
//! The kept (boundary) DOFs `b` stay physical; the others `o` are
//! represented by the constraint modes `Ψ = −K_oo⁻¹ K_ob` (the static
//! response to a unit displacement of each kept DOF) and the lowest
//! fixed-interface modes `Φ` of `(K_oo, M_oo)` up to a cut-off frequency:
//!
//! $$ u = \begin{bmatrix} u_b \\ u_o \end{bmatrix}
//!      = \begin{bmatrix} I & 0 \\ Ψ & Φ \end{bmatrix}
//!        \begin{bmatrix} u_b \\ q \end{bmatrix} = T x,\quad
//!    M_r = Tᵀ M T,\ K_r = Tᵀ K T,\ C_r = Tᵀ C T. $$
//!
//! The reduced coordinates are the kept DOFs in the order given, then the
//! modal coordinates in ascending frequency. `K_oo` is factored once with
//! faer's sparse Cholesky (it serves the constraint modes and the
//! shift-invert eigensolver of [`super::sparse`]).

use super::sparse::{self, Factor, SpMat};
use crate::error::{Result, TacitError};
use faer::Mat;
use nalgebra::DMatrix;

/// Settings of a Craig–Bampton reduction.
#[derive(Debug, Clone, PartialEq)]
pub struct CbSettings {
    /// Fixed-interface modes are kept up to this frequency, Hz.
    pub cutoff_hz: f64,
    /// At most this many fixed-interface modes.
    pub max_modes: usize,
}

impl CbSettings {
    /// Check the values.
    pub fn validate(&self) -> Result<()> {
        if !(self.cutoff_hz.is_finite() && self.cutoff_hz > 0.0) {
            return Err(TacitError::Setting(format!(
                "reduction cut-off {} Hz: must be > 0",
                self.cutoff_hz
            )));
        }
        if self.max_modes == 0 {
            return Err(TacitError::Setting(
                "reduction: max_modes must be at least 1".into(),
            ));
        }
        Ok(())
    }
}

/// A Craig–Bampton reduced model.
#[derive(Debug, Clone)]
pub struct CbModel {
    /// Reduced mass (kept DOFs, then modal coordinates).
    pub m: DMatrix<f64>,
    /// Reduced stiffness.
    pub k: DMatrix<f64>,
    /// Reduced damping, when a damping matrix was given.
    pub c: Option<DMatrix<f64>>,
    /// Number of kept (physical) DOFs.
    pub kept: usize,
    /// Frequencies of the fixed-interface modes kept, Hz.
    pub modes_hz: Vec<f64>,
    /// False when `max_modes` stopped the modes below the cut-off.
    pub complete: bool,
}

/// Reduce `(m, k, c)` onto `kept` (indices into the matrices).
pub fn craig_bampton(
    m: &SpMat,
    k: &SpMat,
    c: Option<&SpMat>,
    kept: &[usize],
    settings: &CbSettings,
) -> Result<CbModel> {
    settings.validate()?;
    let n = m.nrows();
    let mut is_kept = vec![false; n];
    for &d in kept {
        is_kept[d] = true;
    }
    let om: Vec<usize> = (0..n).filter(|&d| !is_kept[d]).collect();
    let nb = kept.len();
    let (psi, phi, omega2, complete) = if om.is_empty() {
        (Mat::zeros(0, nb), Mat::zeros(0, 0), vec![], true)
    } else {
        interior_basis(m, k, kept, &om, settings)?
    };
    let nm = phi.ncols();
    // T in the matrices' numbering
    let mut t = Mat::<f64>::zeros(n, nb + nm);
    for (j, &d) in kept.iter().enumerate() {
        t[(d, j)] = 1.0;
    }
    for (i, &d) in om.iter().enumerate() {
        for j in 0..nb {
            t[(d, j)] = psi[(i, j)];
        }
        for j in 0..nm {
            t[(d, nb + j)] = phi[(i, j)];
        }
    }
    let mut kr = sparse::project(k, t.as_ref());
    // exact structure: no coupling between constraint and fixed-interface
    // modes in K, and K_qq = diag(ω²)
    for j in 0..nm {
        for i in 0..nb + nm {
            if i != nb + j {
                kr[(i, nb + j)] = 0.0;
                kr[(nb + j, i)] = 0.0;
            }
        }
        kr[(nb + j, nb + j)] = omega2[j];
    }
    Ok(CbModel {
        m: sparse::project(m, t.as_ref()),
        k: kr,
        c: c.map(|c| sparse::project(c, t.as_ref())),
        kept: nb,
        modes_hz: omega2
            .iter()
            .map(|w2| w2.max(0.0).sqrt() / (2.0 * std::f64::consts::PI))
            .collect(),
        complete,
    })
}

type Interior = (Mat<f64>, Mat<f64>, Vec<f64>, bool);

/// Constraint modes Ψ and fixed-interface modes Φ of the omitted DOFs.
fn interior_basis(
    m: &SpMat,
    k: &SpMat,
    kept: &[usize],
    om: &[usize],
    settings: &CbSettings,
) -> Result<Interior> {
    let koo = sparse::block(k, om, om)?;
    let moo = sparse::block(m, om, om)?;
    let kob = sparse::block(k, om, kept)?;
    let factor = Factor::new(&koo).ok_or_else(|| {
        TacitError::Numerical(format!(
            "Craig–Bampton: the stiffness of the {} DOFs not kept is not positive definite (they are not held by the {} kept and the fixed DOFs: a free part of the structure, or a mechanism); keep a point on that part or fix it",
            om.len(),
            kept.len()
        ))
    })?;
    let mut psi = kob.to_dense();
    psi *= faer::Scale(-1.0);
    factor.solve_in_place(psi.as_mut());
    let (modes, complete) =
        sparse::modes_up_to(&koo, &moo, &factor, settings.cutoff_hz, settings.max_modes)?;
    Ok((psi, modes.shapes, modes.omega2, complete))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::reduce::sparse::from_entries;

    /// Free-free chain of `n` unit masses, springs of stiffness 1000.
    fn chain(n: usize) -> (SpMat, SpMat) {
        let mut k = vec![];
        for i in 0..n - 1 {
            for (a, b, v) in [
                (i, i, 1.0),
                (i + 1, i + 1, 1.0),
                (i, i + 1, -1.0),
                (i + 1, i, -1.0),
            ] {
                k.push((a, b, 1000.0 * v));
            }
        }
        let m: Vec<_> = (0..n).map(|i| (i, i, 1.0)).collect();
        (
            from_entries(n, n, &m).unwrap(),
            from_entries(n, n, &k).unwrap(),
        )
    }

    #[test]
    fn reduced_frequencies_converge_to_the_full_ones() {
        let n = 200;
        let (m, k) = chain(n);
        let full = crate::modal::solve(&m.to_dense_nalgebra(), &k.to_dense_nalgebra()).unwrap();
        let s = CbSettings {
            cutoff_hz: 3.0,
            max_modes: 100,
        };
        let r = craig_bampton(&m, &k, None, &[0, 60, 199], &s).unwrap();
        assert_eq!(r.kept, 3);
        assert!(!r.modes_hz.is_empty() && r.modes_hz.iter().all(|&f| f <= 3.0));
        let red = crate::modal::solve(&r.m, &r.k).unwrap();
        // below a third of the cut-off, within 0.1 %; upper bounds always
        for i in 1..red.freq_hz.len() {
            let (fr, ff) = (red.freq_hz[i], full.freq_hz[i]);
            assert!(fr >= ff * (1.0 - 1e-9), "mode {i}: {fr} < {ff}");
            if ff < 1.0 {
                approx::assert_relative_eq!(fr, ff, max_relative = 1e-3);
            }
        }
    }

    #[test]
    fn a_free_interior_is_an_error() {
        let (m, k) = chain(10);
        // two disconnected chains' worth of interior: keep nothing that holds 5..9
        let e = craig_bampton(
            &m,
            &k,
            None,
            &[],
            &CbSettings {
                cutoff_hz: 10.0,
                max_modes: 5,
            },
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("not positive definite") && e.contains("10 DOFs"),
            "{e}"
        );
    }

    trait Dense {
        fn to_dense_nalgebra(&self) -> DMatrix<f64>;
    }
    impl Dense for SpMat {
        fn to_dense_nalgebra(&self) -> DMatrix<f64> {
            let d = self.to_dense();
            DMatrix::from_fn(d.nrows(), d.ncols(), |i, j| d[(i, j)])
        }
    }
}
