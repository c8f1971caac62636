//! Model reduction onto a set of kept DOFs (the sensors): `u ≈ T u_a`,
//! `M_a = Tᵀ M T`, `K_a = Tᵀ K T`, `f_a = Tᵀ f` (docs/theory.md, Definitions).
//!
//! - SEREP (O'Callahan 1989): `T = Φ Φ_a⁺` with Φ the lowest `m` modes
//!   (m = number of kept DOFs) and Φ_a its rows at the kept DOFs; the
//!   retained modes are reproduced exactly.
//! - Guyan (static condensation): `T = [I; −K_oo⁻¹ K_oa]`.
//! - IRS (improved reduced system): `T = T_G + S M T_G M_G⁻¹ K_G` with
//!   `S = [0 0; 0 K_oo⁻¹]`, the first-order inertia correction.

pub mod cb;
pub mod sparse;

use crate::error::{Result, TacitError};
use nalgebra::{DMatrix, DVector};
use serde::Serialize;

/// Reduction method.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum Method {
    /// System equivalent reduction expansion process.
    Serep,
    /// Static (Guyan) condensation.
    Guyan,
    /// Improved reduced system.
    Irs,
}

/// A reduction basis and the reduced matrices.
#[derive(Debug, Clone)]
pub struct Reduction {
    /// Method used.
    pub method: Method,
    /// Kept DOFs (0-based), in the order of the reduced coordinates.
    pub kept: Vec<usize>,
    /// Basis `T` (n × m): `u = T u_a`.
    pub t: DMatrix<f64>,
    /// Reduced mass `TᵀMT`.
    pub m: DMatrix<f64>,
    /// Reduced stiffness `TᵀKT`.
    pub k: DMatrix<f64>,
    /// Condition number of the matrix inverted to build `T`
    /// (Φ_a for SEREP, K_oo for Guyan/IRS).
    pub condition: f64,
}

impl Reduction {
    /// `Tᵀ X T` for any full-order matrix (e.g. damping).
    pub fn project(&self, x: &DMatrix<f64>) -> DMatrix<f64> {
        self.t.transpose() * x * &self.t
    }
    /// Generalized force `Tᵀ f`.
    pub fn project_force(&self, f: &DVector<f64>) -> DVector<f64> {
        self.t.transpose() * f
    }
    /// Expand reduced coordinates: `T x_a`.
    pub fn expand(&self, xa: &DVector<f64>) -> DVector<f64> {
        &self.t * xa
    }
}

fn check_kept(n: usize, kept: &[usize]) -> Result<()> {
    if kept.is_empty() {
        return Err(TacitError::Setting("reduction: no kept DOF".into()));
    }
    let mut seen = vec![false; n];
    for &d in kept {
        if d >= n {
            return Err(TacitError::Setting(format!(
                "reduction: kept DOF {} is outside the model (1..={n})",
                d + 1
            )));
        }
        if seen[d] {
            return Err(TacitError::Setting(format!(
                "reduction: kept DOF {} is listed twice",
                d + 1
            )));
        }
        seen[d] = true;
    }
    Ok(())
}

fn dof_list(kept: &[usize]) -> String {
    kept.iter()
        .map(|d| (d + 1).to_string())
        .collect::<Vec<_>>()
        .join(",")
}

/// Reduce (M, K) onto `kept` (0-based).
pub fn reduce(
    m: &DMatrix<f64>,
    k: &DMatrix<f64>,
    kept: &[usize],
    method: Method,
) -> Result<Reduction> {
    let n = m.nrows();
    check_kept(n, kept)?;
    let (t, condition) = match method {
        Method::Serep => serep_basis(m, k, kept)?,
        Method::Guyan => guyan_basis(k, kept)?,
        Method::Irs => {
            let (tg, cond) = guyan_basis(k, kept)?;
            let mg = tg.transpose() * m * &tg;
            let kg = tg.transpose() * k * &tg;
            let mg_inv = mg.try_inverse().ok_or_else(|| {
                TacitError::Numerical(format!(
                    "IRS reduction onto DOFs {}: the Guyan mass matrix is singular",
                    dof_list(kept)
                ))
            })?;
            let s = omitted_flexibility(k, kept)?;
            (&tg + s * m * &tg * mg_inv * kg, cond)
        }
    };
    let mr = t.transpose() * m * &t;
    let kr = t.transpose() * k * &t;
    Ok(Reduction {
        method,
        kept: kept.to_vec(),
        m: (&mr + mr.transpose()) * 0.5,
        k: (&kr + kr.transpose()) * 0.5,
        t,
        condition,
    })
}

fn omitted(n: usize, kept: &[usize]) -> Vec<usize> {
    (0..n).filter(|d| !kept.contains(d)).collect()
}

fn cond_of(a: &DMatrix<f64>) -> f64 {
    let sv = a.clone().svd(false, false).singular_values;
    let (mx, mn) = sv
        .iter()
        .fold((0.0f64, f64::INFINITY), |(a, b), &s| (a.max(s), b.min(s)));
    if mn > 0.0 {
        mx / mn
    } else {
        f64::INFINITY
    }
}

/// SEREP basis `T = Φ Φ_a⁺` with the lowest `kept.len()` modes.
fn serep_basis(m: &DMatrix<f64>, k: &DMatrix<f64>, kept: &[usize]) -> Result<(DMatrix<f64>, f64)> {
    let modes = crate::modal::solve(m, k)?;
    let nm = kept.len();
    let phi = modes.shapes.columns(0, nm).into_owned();
    let phi_a = DMatrix::from_fn(nm, nm, |i, j| phi[(kept[i], j)]);
    let cond = cond_of(&phi_a);
    if !(cond < 1e10) {
        return Err(TacitError::Numerical(format!(
            "SEREP reduction onto DOFs {} is singular: the lowest {nm} mode shapes are not independent at these DOFs (condition {cond:.3e})",
            dof_list(kept)
        )));
    }
    let inv = phi_a.try_inverse().ok_or_else(|| {
        TacitError::Numerical(format!(
            "SEREP reduction onto DOFs {} is singular",
            dof_list(kept)
        ))
    })?;
    Ok((phi * inv, cond))
}

/// Guyan basis.
fn guyan_basis(k: &DMatrix<f64>, kept: &[usize]) -> Result<(DMatrix<f64>, f64)> {
    let n = k.nrows();
    let om = omitted(n, kept);
    let na = kept.len();
    let mut t = DMatrix::zeros(n, na);
    for (j, &d) in kept.iter().enumerate() {
        t[(d, j)] = 1.0;
    }
    if om.is_empty() {
        return Ok((t, 1.0));
    }
    let koo = DMatrix::from_fn(om.len(), om.len(), |i, j| k[(om[i], om[j])]);
    let koa = DMatrix::from_fn(om.len(), na, |i, j| k[(om[i], kept[j])]);
    let cond = cond_of(&koo);
    if !(cond < 1e12) {
        return Err(TacitError::Numerical(format!(
            "Guyan reduction onto DOFs {}: K_oo of the omitted DOFs is singular (condition {cond:.3e})",
            dof_list(kept)
        )));
    }
    let x = koo.lu().solve(&(-koa)).ok_or_else(|| {
        TacitError::Numerical(format!(
            "Guyan reduction onto DOFs {}: K_oo is singular",
            dof_list(kept)
        ))
    })?;
    for (i, &d) in om.iter().enumerate() {
        for j in 0..na {
            t[(d, j)] = x[(i, j)];
        }
    }
    Ok((t, cond))
}

/// `S = [0 0; 0 K_oo⁻¹]` in full coordinates.
fn omitted_flexibility(k: &DMatrix<f64>, kept: &[usize]) -> Result<DMatrix<f64>> {
    let n = k.nrows();
    let om = omitted(n, kept);
    let mut s = DMatrix::zeros(n, n);
    if om.is_empty() {
        return Ok(s);
    }
    let koo = DMatrix::from_fn(om.len(), om.len(), |i, j| k[(om[i], om[j])]);
    let inv = koo
        .try_inverse()
        .ok_or_else(|| TacitError::Numerical("IRS: K_oo is singular".into()))?;
    for (i, &a) in om.iter().enumerate() {
        for (j, &b) in om.iter().enumerate() {
            s[(a, b)] = inv[(i, j)];
        }
    }
    Ok(s)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::Model;

    fn lanl() -> Model {
        let p = concat!(env!("CARGO_MANIFEST_DIR"), "/data/lanl8dof.toml");
        Model::from_file(std::path::Path::new(p)).unwrap()
    }

    #[test]
    fn serep_reproduces_retained_modes() {
        let model = lanl();
        let (m, k) = (model.mass_matrix(), model.stiffness_matrix());
        let full = crate::modal::solve(&m, &k).unwrap();
        let r = reduce(&m, &k, &[0, 4, 5], Method::Serep).unwrap();
        let red = crate::modal::solve(&r.m, &r.k).unwrap();
        for i in 1..3 {
            approx::assert_relative_eq!(red.freq_hz[i], full.freq_hz[i], max_relative = 1e-9);
        }
        // expanded shapes equal the full shapes
        for i in 0..3 {
            let e = &r.t * red.shapes.column(i);
            let f = full.shapes.column(i);
            let s = if e.dot(&f) < 0.0 { -1.0 } else { 1.0 };
            approx::assert_relative_eq!(e * s, f.into_owned(), epsilon = 1e-8);
        }
    }

    #[test]
    fn guyan_and_irs_bracket_the_first_frequency() {
        let model = lanl();
        let (m, k) = (model.mass_matrix(), model.stiffness_matrix());
        let full = crate::modal::solve(&m, &k).unwrap();
        let g = reduce(&m, &k, &[0, 4, 5], Method::Guyan).unwrap();
        let i = reduce(&m, &k, &[0, 4, 5], Method::Irs).unwrap();
        let fg = crate::modal::solve(&g.m, &g.k).unwrap().freq_hz[1];
        let fi = crate::modal::solve(&i.m, &i.k).unwrap().freq_hz[1];
        let f = full.freq_hz[1];
        // Guyan overestimates; IRS is closer
        assert!(fg > f && (fi - f).abs() < (fg - f).abs(), "{f} {fg} {fi}");
    }

    #[test]
    fn bad_kept_sets_are_errors() {
        let model = lanl();
        let (m, k) = (model.mass_matrix(), model.stiffness_matrix());
        assert!(reduce(&m, &k, &[0, 8], Method::Serep)
            .unwrap_err()
            .to_string()
            .contains("DOF 9"));
        assert!(reduce(&m, &k, &[], Method::Guyan).is_err());
        // a DOF with no spring: K_oo is singular, Guyan must say so
        let loose = Model::from_toml_str(
            "masses = [1.0, 1.0, 1.0]\n[[spring]]\ndofs = [1, 2]\nstiffness = 100.0\n",
            "t",
        )
        .unwrap();
        let e = reduce(
            &loose.mass_matrix(),
            &loose.stiffness_matrix(),
            &[0],
            Method::Guyan,
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("singular") && e.contains("DOFs 1"), "{e}");
    }
}
