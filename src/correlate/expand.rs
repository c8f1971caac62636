//! Mode-shape expansion from the measured DOFs `a` to every model DOF
//! (the omitted DOFs `o`), needed by the residues of eqs. 4–6 when only some
//! DOFs are measured (paper §4: DOFs 1, 4, 7).
//!
//! - **SEREP** (O'Callahan, Avitabile & Riemer, IMAC 1989): with `Φ` the
//!   model shapes of a set of modes and `Φ_a` their rows at `a`,
//!   `φ = Φ Φ_a⁺ φ_a`. The default basis for a test mode is, among the
//!   flexible model modes, the `n_a` modes nearest to its frequency (one per
//!   measured DOF), so `Φ_a` is square and the measured values are
//!   reproduced.
//! - **Dynamic** (Kidder 1973; Berman & Nagy 1983): the omitted rows of the
//!   model's eigen-equation at the test eigenvalue `λ = ω²`,
//!   `φ_o = −(K_oo − λ M_oo)⁻¹ (K_oa − λ M_oa) φ_a`.
//!
//! Both keep the measured values. When every DOF is measured, both return
//! the test shape unchanged.

use super::testmodes::TestModes;
use crate::error::{Result, TacitError};
use crate::modal::Modes;
use nalgebra::{DMatrix, DVector};
use serde::Serialize;

/// How test shapes are expanded to the full model.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Expansion {
    /// SEREP on the model modes nearest in frequency (one per measured DOF).
    #[default]
    Serep,
    /// SEREP on given flexible model modes (from 1).
    SerepModes(Vec<usize>),
    /// Dynamic expansion at the test eigenvalue.
    Dynamic,
}

impl std::str::FromStr for Expansion {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s.to_ascii_lowercase().as_str() {
            "serep" => Ok(Expansion::Serep),
            "dynamic" => Ok(Expansion::Dynamic),
            _ => Err(format!(
                "unknown expansion '{s}' (expected serep or dynamic)"
            )),
        }
    }
}

/// Expand every test mode: (model DOFs × test modes). `modes` must be the
/// eigen-solution of `(m, k)` (used by SEREP).
pub fn expand(
    test: &TestModes,
    m: &DMatrix<f64>,
    k: &DMatrix<f64>,
    modes: &Modes,
    how: &Expansion,
) -> Result<DMatrix<f64>> {
    let n = m.nrows();
    test.validate(n, &test.name)?;
    let flex = flexible_indices(modes);
    let mut out = DMatrix::zeros(n, test.modes.len());
    for (r, tm) in test.modes.iter().enumerate() {
        let lam = (2.0 * std::f64::consts::PI * tm.frequency_hz).powi(2);
        let phi = match how {
            Expansion::Dynamic => dynamic(&tm.shape, &test.dofs, m, k, lam),
            Expansion::Serep => {
                let basis = nearest_modes(modes, tm.frequency_hz, test.dofs.len());
                serep(&tm.shape, &test.dofs, modes, &basis)
            }
            Expansion::SerepModes(list) => {
                let mut basis = Vec::with_capacity(list.len());
                for &j in list {
                    basis.push(*flex.get(j.wrapping_sub(1)).ok_or_else(|| {
                        TacitError::Setting(format!(
                            "SEREP basis: flexible mode {j} does not exist (1..={})",
                            flex.len()
                        ))
                    })?);
                }
                serep(&tm.shape, &test.dofs, modes, &basis)
            }
        }
        .map_err(|e| with_mode(e, r, tm.frequency_hz))?;
        out.set_column(r, &phi);
    }
    Ok(out)
}

fn with_mode(e: TacitError, r: usize, f: f64) -> TacitError {
    match e {
        TacitError::Numerical(m) => {
            TacitError::Numerical(format!("expansion of test mode {} ({f:.2} Hz): {m}", r + 1))
        }
        other => other,
    }
}

fn flexible_indices(modes: &Modes) -> Vec<usize> {
    (0..modes.rigid.len())
        .filter(|&r| !modes.rigid[r])
        .collect()
}

/// The `count` flexible modes (column indices into `modes.shapes`) nearest
/// to `freq_hz`, in ascending order.
pub fn nearest_modes(modes: &Modes, freq_hz: f64, count: usize) -> Vec<usize> {
    let mut flex = flexible_indices(modes);
    flex.sort_by(|&a, &b| {
        (modes.freq_hz[a] - freq_hz)
            .abs()
            .total_cmp(&(modes.freq_hz[b] - freq_hz).abs())
    });
    flex.truncate(count);
    flex.sort_unstable();
    flex
}

/// SEREP expansion `Φ Φ_a⁺ φ_a` on the model modes `basis` (column indices
/// into `modes.shapes`).
pub fn serep(
    phi_a: &[f64],
    dofs: &[usize],
    modes: &Modes,
    basis: &[usize],
) -> Result<DVector<f64>> {
    let n = modes.shapes.nrows();
    check(phi_a, dofs, n)?;
    if basis.is_empty() {
        return Err(TacitError::Setting(
            "SEREP needs at least one model mode".into(),
        ));
    }
    let phi = DMatrix::from_fn(n, basis.len(), |i, j| modes.shapes[(i, basis[j])]);
    let phi_aa = DMatrix::from_fn(dofs.len(), basis.len(), |i, j| phi[(dofs[i] - 1, j)]);
    let q = phi_aa
        .svd(true, true)
        .solve(&DVector::from_column_slice(phi_a), 1e-10)
        .map_err(|e| TacitError::Numerical(format!("SEREP pseudo-inverse: {e}")))?;
    Ok(phi * q)
}

/// Dynamic expansion at eigenvalue `lam` (rad²/s²).
pub fn dynamic(
    phi_a: &[f64],
    dofs: &[usize],
    m: &DMatrix<f64>,
    k: &DMatrix<f64>,
    lam: f64,
) -> Result<DVector<f64>> {
    let n = m.nrows();
    check(phi_a, dofs, n)?;
    let omitted: Vec<usize> = (0..n).filter(|i| !dofs.contains(&(i + 1))).collect();
    let mut out = DVector::zeros(n);
    for (i, &d) in dofs.iter().enumerate() {
        out[d - 1] = phi_a[i];
    }
    if omitted.is_empty() {
        return Ok(out);
    }
    let z = k - m * lam;
    let zoo = DMatrix::from_fn(omitted.len(), omitted.len(), |i, j| {
        z[(omitted[i], omitted[j])]
    });
    let rhs = DVector::from_fn(omitted.len(), |i, _| {
        -dofs
            .iter()
            .enumerate()
            .map(|(j, &d)| z[(omitted[i], d - 1)] * phi_a[j])
            .sum::<f64>()
    });
    let x = zoo.lu().solve(&rhs).ok_or_else(|| {
        TacitError::Numerical(format!(
            "K_oo − λ M_oo is singular at λ = {lam:.6e}: the test frequency is an eigenvalue of the omitted DOFs {:?}",
            omitted.iter().map(|i| i + 1).collect::<Vec<_>>()
        ))
    })?;
    if x.iter().any(|v| !v.is_finite()) {
        return Err(TacitError::Numerical(format!(
            "K_oo − λ M_oo is numerically singular at λ = {lam:.6e}"
        )));
    }
    for (i, &o) in omitted.iter().enumerate() {
        out[o] = x[i];
    }
    Ok(out)
}

fn check(phi_a: &[f64], dofs: &[usize], n: usize) -> Result<()> {
    if phi_a.len() != dofs.len() {
        return Err(TacitError::Setting(format!(
            "expansion: the shape has {} values for {} measured DOFs {:?}",
            phi_a.len(),
            dofs.len(),
            dofs
        )));
    }
    for &d in dofs {
        if d < 1 || d > n {
            return Err(TacitError::Setting(format!(
                "expansion: DOF {d} is not in the model (1..={n})"
            )));
        }
    }
    Ok(())
}
