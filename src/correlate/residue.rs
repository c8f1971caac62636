//! Modal residues (paper §3.1) and the updating of per-spring stiffnesses
//! that minimises them (paper §4, Figs 2–3).
//!
//! The model is parameterised by one factor per updated spring,
//! `K(p) = K_fixed + Σ_e (1 + p_e) K_e` (`p_e = −0.14`: 14 % softer); the
//! mass matrix is kept.
//!
//! - **Force residue**, eq. 4: `R_f = K(p) φ − λ M φ`, the out-of-balance
//!   force of a test mode (λ = ω², φ its shape).
//! - **Hybrid residue**, eqs. 5–6: the "strain" shape `ψ` solves
//!   `K(p) ψ = λ M φ` (eq. 5) and `R_d = φ − ψ` (eq. 6). For a free-free
//!   model `K` is singular; `ψ` is then taken with the same rigid-body
//!   content as `φ` (`Φ_rbᵀ M ψ = Φ_rbᵀ M φ`) and the rigid-body part of the
//!   load is dropped: `[K  MΦ_rb; Φ_rbᵀM  0] [ψ; μ] = [λMφ; Φ_rbᵀMφ]`.
//! - Eq. 7: `K R_d = R_f` (exactly so when the load has no rigid-body
//!   part), so both residues vanish at the same `p`; with unmeasured DOFs,
//!   the expansion breaks this equivalence (paper §3.1).
//!
//! When DOFs are missing, each test shape is expanded ([`super::expand`])
//! *with the model being updated*, so the expanded shape depends on `p`.
//! The test shapes are scaled once, so that their expansion with the initial
//! model has `φᵀ M φ = 1` (a fixed scale: the scale cannot drift to make the
//! residue small). The force residue of mode `r` is divided by `λ_r` so that
//! every mode weighs alike. The cost
//!
//! $$ J(p) = \sum_r \| R_r(p) \|^2 + α \|p\|^2 $$
//!
//! is minimised by Levenberg–Marquardt (crate `levenberg-marquardt`) over
//! `q_e = ln(1 + p_e)`, which keeps every stiffness positive. The Jacobian
//! is exact when every DOF is measured (`∂R_f/∂p_e = K_e φ / λ`,
//! `∂R_d/∂p_e = [A⁻¹ [K_e ψ; 0]]_ψ`) and by central finite differences
//! otherwise (the expansion moves with `p`).
//!
//! References: force residues — Farhat & Hemez, AIAA J. 31 (1993) (the
//! paper's [10–11]); hybrid residues and their expansion — the paper's [9].

use super::expand::{expand, Expansion};
use super::testmodes::TestModes;
use crate::error::{Result, TacitError};
use crate::modal;
use crate::model::{add_spring, Model};
use levenberg_marquardt::{LeastSquaresProblem, LevenbergMarquardt, TerminationReason};
use nalgebra::{DMatrix, DVector, Dyn, Owned};
use serde::Serialize;

/// Which residue is minimised.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Residue {
    /// Force residue, eq. 4.
    Force,
    /// Hybrid residue, eqs. 5–6.
    Hybrid,
}

impl std::str::FromStr for Residue {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s.to_ascii_lowercase().as_str() {
            "force" => Ok(Residue::Force),
            "hybrid" => Ok(Residue::Hybrid),
            _ => Err(format!("unknown residue '{s}' (expected force or hybrid)")),
        }
    }
}

/// Settings of the stiffness updating.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct UpdateSettings {
    /// Residue minimised.
    pub residue: Residue,
    /// Expansion of the test shapes to the unmeasured DOFs (default SEREP
    /// on the nearest model modes).
    pub expansion: Expansion,
    /// Springs updated, numbered from 1 in the model file's order; empty =
    /// every spring (default).
    pub springs: Vec<usize>,
    /// Tikhonov weight α on ‖p‖² (>= 0; default 0).
    pub regularization: f64,
    /// Levenberg–Marquardt tolerance on the relative reduction of the cost
    /// and of the step (> 0; default 1e-12).
    pub tol: f64,
    /// Largest number of cost evaluations, about (>= 10; default 2000).
    pub max_evaluations: usize,
    /// Step of the central differences in `ln(1 + p)` when DOFs are
    /// expanded (> 0; default 1e-6).
    pub fd_step: f64,
}

impl UpdateSettings {
    /// Defaults for a residue.
    pub fn new(residue: Residue) -> Self {
        UpdateSettings {
            residue,
            expansion: Expansion::default(),
            springs: vec![],
            regularization: 0.0,
            tol: 1e-12,
            max_evaluations: 2000,
            fd_step: 1e-6,
        }
    }

    /// The same settings with another expansion.
    pub fn with_expansion(mut self, e: Expansion) -> Self {
        self.expansion = e;
        self
    }

    /// Check the settings against a model; the error repeats the rule.
    pub fn validate(&self, model: &Model) -> Result<()> {
        let ns = model.springs.len();
        for (i, &s) in self.springs.iter().enumerate() {
            if s < 1 || s > ns {
                return Err(TacitError::Setting(format!(
                    "updated spring {s} is not in the model (springs 1..={ns})"
                )));
            }
            if self.springs[..i].contains(&s) {
                return Err(TacitError::Setting(format!(
                    "updated spring {s} is listed twice"
                )));
            }
        }
        if !(self.regularization.is_finite() && self.regularization >= 0.0) {
            return Err(TacitError::Setting(format!(
                "regularization = {}: must be >= 0",
                self.regularization
            )));
        }
        if !(self.tol > 0.0 && self.tol < 1.0) {
            return Err(TacitError::Setting(format!(
                "update tol = {}: must be in (0, 1)",
                self.tol
            )));
        }
        if self.max_evaluations < 10 {
            return Err(TacitError::Setting(format!(
                "max_evaluations = {}: must be >= 10",
                self.max_evaluations
            )));
        }
        if !(self.fd_step > 0.0 && self.fd_step < 0.1) {
            return Err(TacitError::Setting(format!(
                "fd_step = {}: must be in (0, 0.1)",
                self.fd_step
            )));
        }
        Ok(())
    }
}

/// How an update ended.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "status", rename_all = "snake_case")]
pub enum UpdateStatus {
    /// The minimiser converged (`reason` says on what).
    Converged {
        /// The minimiser's termination reason.
        reason: String,
    },
    /// The evaluation budget ran out; `p` is the best point found.
    MaxEvaluations,
    /// The minimiser stopped without success (e.g. the expansion became
    /// singular); `p` is the last accepted point.
    Failed {
        /// Why.
        reason: String,
    },
}

impl UpdateStatus {
    /// True for [`UpdateStatus::Converged`].
    pub fn converged(&self) -> bool {
        matches!(self, UpdateStatus::Converged { .. })
    }
}

impl std::fmt::Display for UpdateStatus {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            UpdateStatus::Converged { .. } => write!(f, "converged"),
            UpdateStatus::MaxEvaluations => write!(f, "evaluation limit"),
            UpdateStatus::Failed { reason } => write!(f, "failed: {reason}"),
        }
    }
}

/// Result of a stiffness update.
#[derive(Debug, Clone, Serialize)]
pub struct UpdateResult {
    /// How it ended.
    pub status: UpdateStatus,
    /// Residue minimised.
    pub residue: Residue,
    /// Expansion used.
    pub expansion: Expansion,
    /// Measured DOFs.
    pub dofs: Vec<usize>,
    /// Labels of the updated springs (`k1` …).
    pub labels: Vec<String>,
    /// Fractional stiffness changes `p_e` (−0.14 = 14 % softer).
    pub change: Vec<f64>,
    /// Cost evaluations.
    pub evaluations: usize,
    /// Residue norm `(Σ_r ‖R_r‖²)^½` with the initial model.
    pub residual_initial: f64,
    /// Residue norm with the updated model.
    pub residual_final: f64,
    /// Singular values of the Jacobian `∂R/∂p` at the solution, largest
    /// first: a small ratio means some combination of springs is not
    /// determined by the data.
    pub singular_values: Vec<f64>,
    /// The updated model.
    #[serde(skip)]
    pub model: Model,
}

impl UpdateResult {
    /// Changes in percent.
    pub fn change_pct(&self) -> Vec<f64> {
        self.change.iter().map(|p| 100.0 * p).collect()
    }
    /// Condition number of the Jacobian at the solution (largest over
    /// smallest singular value; infinite when the smallest is 0).
    pub fn condition(&self) -> f64 {
        match (self.singular_values.first(), self.singular_values.last()) {
            (Some(a), Some(b)) if *b > 0.0 => a / b,
            (Some(_), Some(_)) => f64::INFINITY,
            _ => f64::NAN,
        }
    }
}

/// Force residue `K φ − λ M φ` (eq. 4).
pub fn force_residue(
    k: &DMatrix<f64>,
    m: &DMatrix<f64>,
    lam: f64,
    phi: &DVector<f64>,
) -> DVector<f64> {
    k * phi - m * phi * lam
}

/// The hybrid residue `φ − ψ` (eq. 6) and the strain shape ψ of eq. 5;
/// `rigid` holds the rigid-body modes as columns (none for a grounded
/// model).
pub fn hybrid_residue(
    k: &DMatrix<f64>,
    m: &DMatrix<f64>,
    rigid: &DMatrix<f64>,
    lam: f64,
    phi: &DVector<f64>,
) -> Result<(DVector<f64>, DVector<f64>)> {
    let lu = augmented(k, m, rigid).lu();
    let psi = solve_psi(&lu, m, rigid, lam, phi, k.nrows())?;
    Ok((phi - &psi, psi))
}

fn augmented(k: &DMatrix<f64>, m: &DMatrix<f64>, rigid: &DMatrix<f64>) -> DMatrix<f64> {
    let n = k.nrows();
    let nr = rigid.ncols();
    let mut a = DMatrix::zeros(n + nr, n + nr);
    a.view_mut((0, 0), (n, n)).copy_from(k);
    if nr > 0 {
        let mr = m * rigid;
        a.view_mut((0, n), (n, nr)).copy_from(&mr);
        a.view_mut((n, 0), (nr, n)).copy_from(&mr.transpose());
    }
    a
}

fn solve_psi(
    lu: &nalgebra::LU<f64, Dyn, Dyn>,
    m: &DMatrix<f64>,
    rigid: &DMatrix<f64>,
    lam: f64,
    phi: &DVector<f64>,
    n: usize,
) -> Result<DVector<f64>> {
    let nr = rigid.ncols();
    let mut b = DVector::zeros(n + nr);
    let mphi = m * phi;
    b.rows_mut(0, n).copy_from(&(&mphi * lam));
    if nr > 0 {
        b.rows_mut(n, nr).copy_from(&(rigid.transpose() * &mphi));
    }
    let x = lu
        .solve(&b)
        .filter(|x| x.iter().all(|v| v.is_finite()))
        .ok_or_else(|| {
            TacitError::Numerical(
                "hybrid residue: the stiffness matrix (with the rigid-body constraints) is singular"
                    .into(),
            )
        })?;
    Ok(x.rows(0, n).into_owned())
}

/// The parameterised stiffness `K(p)`.
struct Param {
    fixed: DMatrix<f64>,
    parts: Vec<DMatrix<f64>>,
}

impl Param {
    fn new(model: &Model, springs: &[usize]) -> Param {
        let n = model.ndof();
        let mut fixed = DMatrix::zeros(n, n);
        let mut parts = Vec::with_capacity(springs.len());
        for (i, s) in model.springs.iter().enumerate() {
            if springs.contains(&(i + 1)) {
                let mut ke = DMatrix::zeros(n, n);
                add_spring(&mut ke, s.ends(), s.stiffness);
                parts.push(ke);
            } else {
                add_spring(&mut fixed, s.ends(), s.stiffness);
            }
        }
        Param { fixed, parts }
    }
    fn k(&self, p: &[f64]) -> DMatrix<f64> {
        let mut k = self.fixed.clone();
        for (ke, pe) in self.parts.iter().zip(p) {
            k += ke * (1.0 + pe);
        }
        k
    }
}

/// Everything the cost needs: the parameterised stiffness, the scaled test
/// shapes and how to expand them.
struct Problem<'a> {
    par: &'a Param,
    m: &'a DMatrix<f64>,
    rigid: &'a DMatrix<f64>,
    test: &'a TestModes,
    lams: Vec<f64>,
    settings: &'a UpdateSettings,
    /// Every DOF measured: no expansion, exact Jacobian.
    full: bool,
    q: DVector<f64>,
    /// Residual and Jacobian (in q) at `q`.
    cache: Option<(DVector<f64>, DMatrix<f64>)>,
    /// The first evaluation failure.
    failure: Option<String>,
    evaluations: usize,
}

fn p_of(q: &DVector<f64>) -> Vec<f64> {
    q.iter().map(|v| v.exp_m1()).collect()
}

impl Problem<'_> {
    /// Expanded shapes at `p` (the full test shapes when nothing is missing).
    fn shapes(&self, k: &DMatrix<f64>) -> Result<Vec<DVector<f64>>> {
        let n = self.m.nrows();
        let full = if self.full {
            let mut out = DMatrix::zeros(n, self.test.modes.len());
            for (r, t) in self.test.modes.iter().enumerate() {
                for (i, &d) in self.test.dofs.iter().enumerate() {
                    out[(d - 1, r)] = t.shape[i];
                }
            }
            out
        } else {
            let modes = modal::solve(self.m, k)?;
            expand(self.test, self.m, k, &modes, &self.settings.expansion)?
        };
        Ok(full.column_iter().map(|c| c.into_owned()).collect())
    }

    /// Stacked residues at `p` (without the regularisation rows).
    fn residues(&self, p: &[f64]) -> Result<DVector<f64>> {
        let n = self.m.nrows();
        let k = self.par.k(p);
        let phis = self.shapes(&k)?;
        let mut out = DVector::zeros(n * phis.len());
        let lu = match self.settings.residue {
            Residue::Hybrid => Some(augmented(&k, self.m, self.rigid).lu()),
            Residue::Force => None,
        };
        for (r, (phi, lam)) in phis.iter().zip(&self.lams).enumerate() {
            let v = match &lu {
                None => force_residue(&k, self.m, *lam, phi) / *lam,
                Some(lu) => phi - solve_psi(lu, self.m, self.rigid, *lam, phi, n)?,
            };
            out.rows_mut(r * n, n).copy_from(&v);
        }
        Ok(out)
    }

    /// Exact Jacobian ∂R/∂p when every DOF is measured.
    fn exact_jacobian(&self, p: &[f64]) -> Result<DMatrix<f64>> {
        let n = self.m.nrows();
        let k = self.par.k(p);
        let phis = self.shapes(&k)?;
        let np = p.len();
        let mut jac = DMatrix::zeros(n * phis.len(), np);
        let nr = self.rigid.ncols();
        let lu = augmented(&k, self.m, self.rigid).lu();
        for (r, (phi, lam)) in phis.iter().zip(&self.lams).enumerate() {
            let psi = match self.settings.residue {
                Residue::Hybrid => Some(solve_psi(&lu, self.m, self.rigid, *lam, phi, n)?),
                Residue::Force => None,
            };
            for (e, ke) in self.par.parts.iter().enumerate() {
                let col = match &psi {
                    None => ke * phi / *lam,
                    Some(psi) => {
                        let mut b = DVector::zeros(n + nr);
                        b.rows_mut(0, n).copy_from(&(ke * psi));
                        lu.solve(&b)
                            .ok_or_else(|| {
                                TacitError::Numerical("singular hybrid-residue system".into())
                            })?
                            .rows(0, n)
                            .into_owned()
                    }
                };
                jac.view_mut((r * n, e), (n, 1)).copy_from(&col);
            }
        }
        Ok(jac)
    }

    /// Jacobian ∂R/∂p by central differences in q.
    fn fd_jacobian(&mut self, q: &DVector<f64>) -> Result<DMatrix<f64>> {
        let h = self.settings.fd_step;
        let mut cols = Vec::with_capacity(q.len());
        for e in 0..q.len() {
            let mut qp = q.clone();
            let mut qm = q.clone();
            qp[e] += h;
            qm[e] -= h;
            let rp = self.residues(&p_of(&qp))?;
            let rm = self.residues(&p_of(&qm))?;
            self.evaluations += 2;
            // ∂R/∂q_e, converted to ∂R/∂p_e = ∂R/∂q_e / (1 + p_e)
            cols.push((rp - rm) / (2.0 * h * q[e].exp()));
        }
        Ok(DMatrix::from_columns(&cols))
    }

    /// Residual and Jacobian in q (regularisation rows appended).
    fn evaluate(&mut self, q: &DVector<f64>) -> Result<(DVector<f64>, DMatrix<f64>)> {
        let p = p_of(q);
        let r = self.residues(&p)?;
        self.evaluations += 1;
        let jp = if self.full {
            self.exact_jacobian(&p)?
        } else {
            self.fd_jacobian(q)?
        };
        let np = p.len();
        let alpha = self.settings.regularization;
        let extra = if alpha > 0.0 { np } else { 0 };
        let mut res = DVector::zeros(r.len() + extra);
        res.rows_mut(0, r.len()).copy_from(&r);
        let mut jac = DMatrix::zeros(r.len() + extra, np);
        for e in 0..np {
            let dp_dq = q[e].exp();
            jac.view_mut((0, e), (r.len(), 1))
                .copy_from(&(jp.column(e) * dp_dq));
            if alpha > 0.0 {
                res[r.len() + e] = alpha.sqrt() * p[e];
                jac[(r.len() + e, e)] = alpha.sqrt() * dp_dq;
            }
        }
        if res.iter().chain(jac.iter()).any(|v| !v.is_finite()) {
            return Err(TacitError::Numerical(format!(
                "non-finite residue at p = {p:?}"
            )));
        }
        Ok((res, jac))
    }
}

impl LeastSquaresProblem<f64, Dyn, Dyn> for Problem<'_> {
    type ResidualStorage = Owned<f64, Dyn>;
    type JacobianStorage = Owned<f64, Dyn, Dyn>;
    type ParameterStorage = Owned<f64, Dyn>;

    fn set_params(&mut self, x: &DVector<f64>) {
        self.q.copy_from(x);
        let q = x.clone();
        match self.evaluate(&q) {
            Ok(c) => self.cache = Some(c),
            Err(e) => {
                self.cache = None;
                if self.failure.is_none() {
                    self.failure = Some(e.to_string());
                }
            }
        }
    }
    fn params(&self) -> DVector<f64> {
        self.q.clone()
    }
    fn residuals(&self) -> Option<DVector<f64>> {
        self.cache.as_ref().map(|c| c.0.clone())
    }
    fn jacobian(&self) -> Option<DMatrix<f64>> {
        self.cache.as_ref().map(|c| c.1.clone())
    }
}

/// Scale each test shape so that its expansion with the initial model has
/// `φᵀ M φ = 1`; errors name the mode.
fn scaled_test(
    test: &TestModes,
    m: &DMatrix<f64>,
    k: &DMatrix<f64>,
    how: &Expansion,
) -> Result<TestModes> {
    let modes = modal::solve(m, k)?;
    let full = expand(test, m, k, &modes, how)?;
    let mut out = test.clone();
    for (r, c) in full.column_iter().enumerate() {
        let g = (c.transpose() * m * c)[(0, 0)];
        if !(g > 0.0 && g.is_finite()) {
            return Err(TacitError::Numerical(format!(
                "test mode {} ({:.2} Hz): the expanded shape has no mass (φᵀMφ = {g})",
                r + 1,
                test.modes[r].frequency_hz
            )));
        }
        let s = 1.0 / g.sqrt();
        out.modes[r].shape.iter_mut().for_each(|v| *v *= s);
    }
    out.mass_normalized = true;
    Ok(out)
}

/// The residue norm at `p` and the singular values (largest first) of its
/// Jacobian in the relative changes; NaN and none when the residues fail.
fn residual_and_singular_values(prob: &Problem<'_>, p: &[f64]) -> (f64, Vec<f64>) {
    let np = p.len();
    match prob.residues(p) {
        Ok(r) => {
            let jp = prob.cache.as_ref().map(|c| {
                let mut j = c.1.rows(0, r.len()).into_owned();
                for e in 0..np {
                    let f = 1.0 / prob.q[e].exp();
                    j.column_mut(e).scale_mut(f);
                }
                j
            });
            let mut sv: Vec<f64> = jp
                .map(|j| {
                    j.svd(false, false)
                        .singular_values
                        .iter()
                        .copied()
                        .collect()
                })
                .unwrap_or_default();
            sv.sort_by(|a, b| b.total_cmp(a));
            (r.norm(), sv)
        }
        Err(_) => (f64::NAN, vec![]),
    }
}

/// Update spring stiffnesses of `model` so that the test modes satisfy the
/// model's eigen-equation, by minimising the force (eq. 4) or hybrid
/// (eq. 6) residues. Give the test modes to be matched (e.g. the first five
/// paired ones); their frequencies and shapes are used, not their damping.
pub fn update_stiffness(
    model: &Model,
    test: &TestModes,
    s: &UpdateSettings,
) -> Result<UpdateResult> {
    s.validate(model)?;
    let n = model.ndof();
    test.validate(n, &test.name)?;
    let springs: Vec<usize> = if s.springs.is_empty() {
        (1..=model.springs.len()).collect()
    } else {
        s.springs.clone()
    };
    if springs.is_empty() {
        return Err(TacitError::Setting(format!(
            "model {} has no spring to update",
            model.name
        )));
    }
    let labels: Vec<String> = springs
        .iter()
        .map(|&i| model.springs[i - 1].label(i - 1))
        .collect();
    let par = Param::new(model, &springs);
    let m = model.mass_matrix();
    let np = springs.len();
    let k0 = par.k(&vec![0.0; np]);
    let nominal = modal::solve(&m, &k0)?;
    let rigid_cols: Vec<usize> = (0..n).filter(|&r| nominal.rigid[r]).collect();
    let rigid = DMatrix::from_fn(n, rigid_cols.len(), |i, j| {
        nominal.shapes[(i, rigid_cols[j])]
    });
    let scaled = scaled_test(test, &m, &k0, &s.expansion)?;
    let lams = scaled
        .modes
        .iter()
        .map(|t| (2.0 * std::f64::consts::PI * t.frequency_hz).powi(2))
        .collect();
    let mut prob = Problem {
        par: &par,
        m: &m,
        rigid: &rigid,
        test: &scaled,
        lams,
        settings: s,
        full: test.dofs.len() == n,
        q: DVector::zeros(np),
        cache: None,
        failure: None,
        evaluations: 0,
    };
    let residual_initial = prob.residues(&vec![0.0; np])?.norm();
    prob.set_params(&DVector::zeros(np));
    if let Some(f) = prob.failure.take() {
        return Err(TacitError::Numerical(format!(
            "modal updating cannot start: {f}"
        )));
    }
    let patience = (s.max_evaluations / (np + 1)).max(1);
    let (prob, report) = LevenbergMarquardt::new()
        .with_tol(s.tol)
        .with_patience(patience)
        .minimize(prob);
    let status = match &report.termination {
        t if t.was_successful() => UpdateStatus::Converged {
            reason: format!("{t:?}"),
        },
        TerminationReason::LostPatience => UpdateStatus::MaxEvaluations,
        t => UpdateStatus::Failed {
            reason: prob
                .failure
                .clone()
                .unwrap_or_else(|| format!("Levenberg–Marquardt: {t:?}")),
        },
    };
    let p = p_of(&prob.q);
    let (residual_final, singular_values) = residual_and_singular_values(&prob, &p);
    let mut updated = model.clone();
    for (&i, pe) in springs.iter().zip(&p) {
        updated.springs[i - 1].stiffness *= 1.0 + pe;
    }
    updated.description = format!(
        "{} (stiffnesses updated by {:?} residues)",
        model.description, s.residue
    );
    Ok(UpdateResult {
        status,
        residue: s.residue,
        expansion: s.expansion.clone(),
        dofs: test.dofs.clone(),
        labels,
        change: p,
        evaluations: prob.evaluations,
        residual_initial,
        residual_final,
        singular_values,
        model: updated,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Eq. 7 on a grounded 3-DOF chain: K R_d = R_f for any trial shape.
    #[test]
    fn eq7_links_the_residues() {
        let k = DMatrix::from_row_slice(
            3,
            3,
            &[
                300.0, -100.0, 0.0, -100.0, 200.0, -100.0, 0.0, -100.0, 100.0,
            ],
        );
        let m = DMatrix::from_diagonal(&DVector::from_vec(vec![1.0, 2.0, 1.5]));
        let phi = DVector::from_vec(vec![0.3, 0.7, 1.0]);
        let rf = force_residue(&k, &m, 45.0, &phi);
        let (rd, _) = hybrid_residue(&k, &m, &DMatrix::zeros(3, 0), 45.0, &phi).unwrap();
        approx::assert_relative_eq!(&k * rd, rf, epsilon = 1e-10);
    }
}
