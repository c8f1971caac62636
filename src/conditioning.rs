//! Whether the modes of `K φ = ω² M φ` can be told apart from rigid-body
//! motion in double precision, and which ones are rigid.
//!
//! A symmetric eigensolver returns every eigenvalue of `A = L⁻¹ K L⁻ᵀ`
//! with an absolute error of about `n ε λ_max` (ε = 2.2e-16; Golub & Van
//! Loan, *Matrix Computations*, 4th ed., §8.1.2). An eigenvalue closer to
//! zero than [`DIGITS_LOST`] times that has fewer than three correct
//! digits: it is either a rigid-body mode or a flexible mode lost in
//! round-off, and the eigenvalue alone cannot say which. A mode is called
//! rigid only when its eigenvalue is negligible against `λ_max`
//! ([`RIGID_SHARE`]) *and* its shape moves every DOF as a rigid body:
//! each row `i` of `K φ` is zero against the forces its own terms
//! `|K_ij φ_j|` carry ([`ROW_RESIDUAL`]), a test relative to each
//! element's own stiffness, not to the stiffest one. A mode that is
//! neither rigid nor resolved makes the model ill-conditioned, and the
//! eigenproblem an error stating the stiffness spread.

use crate::error::{Result, TacitError};
use nalgebra::DMatrix;

/// A mode is rigid only when `|ω²| ≤ RIGID_SHARE · ω²_max`.
pub const RIGID_SHARE: f64 = 1e-9;

/// …and every significant row of `K φ` is at most this fraction of the
/// sum of its terms' magnitudes (a flexible mode leaves a fraction near 1;
/// a rigid mode computed from a well-separated spectrum, round-off).
pub const ROW_RESIDUAL: f64 = 1e-3;

/// Rows whose terms carry less than this fraction of `K_ii · max|φ|` are
/// not examined (the mode hardly moves there).
const ROW_SIGNIFICANT: f64 = 1e-8;

/// An eigenvalue resolved to three digits sits above `DIGITS_LOST · n ε
/// λ_max`.
pub const DIGITS_LOST: f64 = 1e3;

/// Which modes are rigid (`vals`: eigenvalues ω², ascending; `shapes`:
/// one column per mode), or an error when the problem is not finite or
/// some modes are neither rigid nor resolved in double precision.
pub fn rigid_modes(
    m: &DMatrix<f64>,
    k: &DMatrix<f64>,
    vals: &[f64],
    shapes: &DMatrix<f64>,
) -> Result<Vec<bool>> {
    finite(m, k, vals)?;
    finite(m, k, shapes.as_slice())?;
    let n = vals.len();
    let lmax = vals.iter().fold(0.0f64, |a, &b| a.max(b.abs()));
    let floor = DIGITS_LOST * n as f64 * f64::EPSILON * lmax;
    let rigid: Vec<bool> = negligible(vals)
        .into_iter()
        .enumerate()
        .map(|(r, small)| small && moves_rigidly(k, shapes, r))
        .collect();
    let lost: Vec<usize> = (0..n)
        .filter(|&r| !rigid[r] && vals[r].abs() <= floor)
        .collect();
    if !lost.is_empty() {
        return Err(ill_conditioned(m, k, &lost, floor, lmax));
    }
    Ok(rigid)
}

/// Modes whose `|ω²|` is at most [`RIGID_SHARE`] of the largest.
pub fn negligible(vals: &[f64]) -> Vec<bool> {
    let lmax = vals.iter().fold(0.0f64, |a, &b| a.max(b.abs()));
    vals.iter().map(|l| l.abs() <= RIGID_SHARE * lmax).collect()
}

/// An error stating the stiffness spread when `values` (the scaled
/// stiffness, the eigenvalues or the shapes) are not all finite.
pub fn finite(m: &DMatrix<f64>, k: &DMatrix<f64>, values: &[f64]) -> Result<()> {
    if values.iter().all(|v| v.is_finite()) {
        return Ok(());
    }
    let ratio = |i: usize| (k[(i, i)] / m[(i, i)]).abs();
    let i = (0..k.nrows())
        .find(|&i| !ratio(i).is_finite())
        .or_else(|| (0..k.nrows()).max_by(|&a, &b| ratio(a).total_cmp(&ratio(b))))
        .unwrap_or(0);
    Err(TacitError::Numerical(format!(
        "eigenproblem: the modes are not finite: K_ii/M_ii at DOF {} is {:.3e} / {:.3e} = {:.3e} s^-2; give masses and stiffnesses in units that keep K_ii/M_ii within double precision (below about 1e300)",
        i + 1,
        k[(i, i)],
        m[(i, i)],
        ratio(i)
    )))
}

/// True when every significant row of `K φ_r` cancels to round-off.
fn moves_rigidly(k: &DMatrix<f64>, shapes: &DMatrix<f64>, r: usize) -> bool {
    let phi = shapes.column(r);
    let amp = phi.amax();
    (0..k.nrows()).all(|i| {
        let (mut sum, mut mag) = (0.0, 0.0);
        for j in 0..k.ncols() {
            sum += k[(i, j)] * phi[j];
            mag += (k[(i, j)] * phi[j]).abs();
        }
        mag < ROW_SIGNIFICANT * k[(i, i)].abs() * amp || sum.abs() <= ROW_RESIDUAL * mag
    })
}

/// The spread of the DOFs' own frequencies `K_ii / M_ii`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Spread {
    /// Largest `K_ii / M_ii` (s⁻²) and its DOF (from 1).
    pub stiffest: (f64, usize),
    /// Smallest positive `K_ii / M_ii` and its DOF (from 1).
    pub softest: (f64, usize),
}

impl Spread {
    /// Stiffness ratio: stiffest over softest.
    pub fn ratio(&self) -> f64 {
        self.stiffest.0 / self.softest.0
    }

    /// The facts in words.
    pub fn describe(&self) -> String {
        format!(
            "K_ii/M_ii spans {:.3e} s^-2 (DOF {}) to {:.3e} s^-2 (DOF {}), a stiffness ratio of {:.3e}",
            self.softest.0,
            self.softest.1,
            self.stiffest.0,
            self.stiffest.1,
            self.ratio()
        )
    }
}

/// The DOFs' own frequencies' spread (diagonal terms).
pub fn spread(m: &DMatrix<f64>, k: &DMatrix<f64>) -> Spread {
    let mut s = Spread {
        stiffest: (0.0, 1),
        softest: (f64::INFINITY, 1),
    };
    for i in 0..k.nrows() {
        let w2 = k[(i, i)] / m[(i, i)];
        if w2 > s.stiffest.0 || w2.is_nan() {
            s.stiffest = (w2, i + 1);
        }
        if w2 > 0.0 && w2 < s.softest.0 {
            s.softest = (w2, i + 1);
        }
    }
    s
}

fn hz(w2: f64) -> f64 {
    w2.max(0.0).sqrt() / (2.0 * std::f64::consts::PI)
}

fn ill_conditioned(
    m: &DMatrix<f64>,
    k: &DMatrix<f64>,
    lost: &[usize],
    floor: f64,
    lmax: f64,
) -> TacitError {
    let modes: Vec<String> = lost.iter().map(|r| (r + 1).to_string()).collect();
    let s = spread(m, k);
    let limit = 1.0 / (DIGITS_LOST * m.nrows() as f64 * f64::EPSILON);
    TacitError::Numerical(format!(
        "the model is too ill-conditioned for its modes: {}; the condition number ω²_max / (softest K_ii/M_ii) is about {:.3e}, above the {:.1e} that leaves three digits: with the highest mode at {:.3e} Hz, double precision resolves no mode below {:.3e} Hz, and mode(s) {} lie there without moving as rigid bodies; lower the stiffest element's stiffness or join the DOFs it links",
        s.describe(),
        lmax / s.softest.0,
        limit,
        hz(lmax),
        hz(floor),
        modes.join(", "),
    ))
}

#[cfg(test)]
mod tests {
    use crate::model::Model;

    fn chain(k5: f64, mass: f64, k: f64) -> Model {
        let mut s = format!("name = \"c\"\nmasses = [{mass:e}, {mass:e}, {mass:e}, {mass:e}]\n");
        for (i, kk) in [k, k5, k].iter().enumerate() {
            s += &format!(
                "[[spring]]\ndofs = [{}, {}]\nstiffness = {kk:e}\n",
                i + 1,
                i + 2
            );
        }
        Model::from_toml_str(&s, "t").unwrap()
    }

    #[test]
    fn stiff_spring_is_an_error_with_the_stiffness_ratio() {
        let ok = chain(1e4, 1.0, 1e4);
        let modes = crate::modal::solve(&ok.mass_matrix(), &ok.stiffness_matrix()).unwrap();
        assert_eq!(modes.rigid, vec![true, false, false, false]);
        let stiff = chain(1e20, 1.0, 1e4);
        let e = crate::modal::solve(&stiff.mass_matrix(), &stiff.stiffness_matrix())
            .unwrap_err()
            .to_string();
        // K_ii/M_ii: 1e4 at DOF 1, 1e20 + 1e4 at DOFs 2 and 3
        assert!(e.contains("stiffness ratio of 1.000e16"), "{e}");
        assert!(e.contains("DOF 1") && e.contains("DOF 2"), "{e}");
        assert!(e.contains("without moving as rigid bodies"), "{e}");
    }

    #[test]
    fn spread_up_to_1e9_still_resolves_every_mode() {
        let m = chain(1e13, 1.0, 1e4);
        let modes = crate::modal::solve(&m.mass_matrix(), &m.stiffness_matrix()).unwrap();
        assert_eq!(modes.rigid, vec![true, false, false, false]);
        // the two soft springs on a stiff middle pair: ω² = 1e4 and 2e4 (to 1e-6)
        let w2 = modes.omega[1].powi(2);
        assert!((w2 - 1e4).abs() < 1e-2 * 1e4 * 1e-4, "{w2}");
    }

    #[test]
    fn overflowing_ratio_is_an_error_not_nan_shapes() {
        let m = chain(1e300, 1e-300, 1e300);
        let e = crate::modal::solve(&m.mass_matrix(), &m.stiffness_matrix())
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("not finite") && e.contains("DOF 1 is 1.000e300 / 1.000e-300 = inf"),
            "{e}"
        );
    }
}
