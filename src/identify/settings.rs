//! Settings of the window identification: one flat struct with a documented
//! default per field and a [`IdentifySettings::validate`] run before any
//! work. Choices are enums, parsed once at the CLI boundary.

use crate::error::{Result, TacitError};
use serde::Serialize;

/// Identification scheme.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum Method {
    /// The published sequential scheme (Hemez & Doebling §6.2): non-overlapping
    /// windows of `window` samples, one force vector constant over each
    /// window, the state carried from window to window. Unstable over long
    /// records for most settings: its closed-loop spectral radius is reported.
    Paper,
    /// Moving-horizon estimation (default): overlapping windows of `horizon`
    /// samples that estimate the window's start state together with one
    /// force vector per sample, commit the first `window` samples and move on.
    #[default]
    Mhe,
}

/// Solver of each window problem.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum Solver {
    /// Regularized least squares through a gain precomputed once (default).
    #[default]
    Ls,
    /// Quadratic program (Clarabel) with the user's [`Constraints`].
    Qp,
}

/// Model reduction onto the sensor DOFs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum Reduce {
    /// Full-order model: forces at every DOF, sensors at a subset.
    None,
    /// SEREP (default, as in the paper: keeps the lowest modes exactly).
    #[default]
    Serep,
    /// Guyan static condensation.
    Guyan,
    /// Improved reduced system.
    Irs,
}

impl Reduce {
    /// The reduction method, `None` for the full-order model.
    pub fn method(self) -> Option<crate::reduce::Method> {
        match self {
            Reduce::None => None,
            Reduce::Serep => Some(crate::reduce::Method::Serep),
            Reduce::Guyan => Some(crate::reduce::Method::Guyan),
            Reduce::Irs => Some(crate::reduce::Method::Irs),
        }
    }
}

/// How the Tikhonov weight α is chosen.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(rename_all = "lowercase", tag = "kind", content = "alpha")]
pub enum Regularization {
    /// Given α (≥ 0), in (output unit)²/N²: the weight of ‖f‖² against the
    /// squared output residual in SI units (the paper's eq. 10).
    Fixed(f64),
    /// Generalized cross-validation over [`IdentifySettings::alpha_grid`].
    Gcv,
    /// Corner of the L-curve (largest curvature of log residual vs log
    /// force norm) over [`IdentifySettings::alpha_grid`].
    LCurve,
}

/// Constraints on the per-sample internal-force vector (QP solver only).
/// DOFs are numbered from 1. Forces follow the internal-force sign
/// convention of the reports (`M a + C v + K u + f = f_ext`).
#[derive(Debug, Clone, PartialEq, Default, Serialize)]
pub struct Constraints {
    /// Lower bounds `(dof, value)`, N.
    pub lower: Vec<(usize, f64)>,
    /// Upper bounds `(dof, value)`, N.
    pub upper: Vec<(usize, f64)>,
    /// Self-equilibrium: the components sum to zero (a purely internal force).
    pub equilibrium: bool,
    /// Pairs `(i, j)` with `f_i = −f_j`.
    pub pairs: Vec<(usize, usize)>,
    /// For every pair `(i, j)`: the contact only pushes apart, i.e. with the
    /// contact closing when `u_i − u_j` grows, `f_i ≥ 0` (and `f_j ≤ 0`).
    pub push_apart: bool,
    /// When given, only these DOFs carry a force; the others are fixed to 0.
    pub active: Option<Vec<usize>>,
}

impl Constraints {
    /// True when no constraint is stated.
    pub fn is_empty(&self) -> bool {
        self.lower.is_empty()
            && self.upper.is_empty()
            && !self.equilibrium
            && self.pairs.is_empty()
            && self.active.is_none()
    }

    /// Check every DOF is in `1..=n` and the bounds are consistent.
    pub fn validate(&self, n: usize) -> Result<()> {
        let dof_ok = |d: usize, what: &str| -> Result<()> {
            if d < 1 || d > n {
                return Err(TacitError::Setting(format!(
                    "constraint {what}: DOF {d} is outside the model (1..={n})"
                )));
            }
            Ok(())
        };
        for &(d, v) in &self.lower {
            dof_ok(d, "lower bound")?;
            if v.is_nan() {
                return Err(TacitError::Setting(format!(
                    "lower bound at DOF {d} is NaN"
                )));
            }
        }
        for &(d, v) in &self.upper {
            dof_ok(d, "upper bound")?;
            if v.is_nan() {
                return Err(TacitError::Setting(format!(
                    "upper bound at DOF {d} is NaN"
                )));
            }
            for &(dl, lo) in &self.lower {
                if dl == d && lo > v {
                    return Err(TacitError::Setting(format!(
                        "DOF {d}: lower bound {lo} N exceeds upper bound {v} N"
                    )));
                }
            }
        }
        for &(i, j) in &self.pairs {
            dof_ok(i, "pair")?;
            dof_ok(j, "pair")?;
            if i == j {
                return Err(TacitError::Setting(format!(
                    "pair ({i}, {j}): the two DOFs must differ"
                )));
            }
        }
        if self.push_apart && self.pairs.is_empty() {
            return Err(TacitError::Setting(
                "push-apart needs at least one pair (i, j)".into(),
            ));
        }
        if let Some(a) = &self.active {
            if a.is_empty() {
                return Err(TacitError::Setting("the active DOF list is empty".into()));
            }
            for &d in a {
                dof_ok(d, "active")?;
            }
        }
        Ok(())
    }
}

/// Settings of [`crate::identify::identify`].
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct IdentifySettings {
    /// Scheme. Default [`Method::Mhe`].
    pub method: Method,
    /// Window solver. Default [`Solver::Ls`].
    pub solver: Solver,
    /// Reduction onto the sensor DOFs. Default [`Reduce::Serep`].
    pub reduce: Reduce,
    /// Window length in samples (≥ 1, default 3): the paper's window of 3
    /// measurements; for MHE the number of samples committed per window.
    pub window: usize,
    /// MHE horizon in samples after the window's start sample (≥ `window`,
    /// default 24). Ignored by the paper scheme.
    pub horizon: usize,
    /// Integration sub-steps per sample of the linear model (≥ 1, default 10).
    pub substeps: usize,
    /// Tikhonov weight of the force. Default `Fixed(1e-3)` (keeps the
    /// reconstruction of the lanl8dof bumper record near 1 % while bounding
    /// the force; see docs/identification.md).
    pub regularization: Regularization,
    /// Grid `(lowest, highest, count)` of α searched by GCV and the L-curve
    /// (log-spaced; lowest > 0, count ≥ 3; default (1e-10, 1e2, 25)).
    pub alpha_grid: (f64, f64, usize),
    /// Weight β of the first differences of the force between consecutive
    /// force vectors (paper: windows; MHE: samples), same units as α
    /// (≥ 0, default 0).
    pub smoothness: f64,
    /// MHE: weight μ of the prior on the window's start state (the previous
    /// window's estimate), relative to the output sensitivity of each state
    /// component (≥ 0, default 1e-2). Larger values keep the reconstructed
    /// state continuous (an exact model wants 1–10); smaller ones let each
    /// window correct the state more (a reduced or wrong model).
    pub prior_weight: f64,
    /// MHE: weight ε pulling the start state towards zero, relative like μ
    /// (> 0, default 1e-4). It makes the directions no sensor sees (the
    /// rigid-body motion of a free-free model under acceleration data)
    /// decay by μ/(μ+ε) per window instead of drifting.
    pub leak: f64,
    /// Constraints on the force (QP solver only).
    pub constraints: Constraints,
    /// Relative singular-value threshold used for the numerical rank of the
    /// window operators (> 0, default 1e-6).
    pub rank_rtol: f64,
}

impl Default for IdentifySettings {
    fn default() -> Self {
        IdentifySettings {
            method: Method::Mhe,
            solver: Solver::Ls,
            reduce: Reduce::Serep,
            window: 3,
            horizon: 24,
            substeps: 10,
            regularization: Regularization::Fixed(1e-3),
            alpha_grid: (1e-10, 1e2, 25),
            smoothness: 0.0,
            prior_weight: 1e-2,
            leak: 1e-4,
            constraints: Constraints::default(),
            rank_rtol: 1e-6,
        }
    }
}

impl IdentifySettings {
    /// Settings of the published scheme: paper method, SEREP, windows of 3,
    /// 10 sub-steps, the given α.
    pub fn paper(alpha: f64) -> Self {
        IdentifySettings {
            method: Method::Paper,
            regularization: Regularization::Fixed(alpha),
            ..Default::default()
        }
    }

    /// Check the settings; the error repeats the rule.
    pub fn validate(&self) -> Result<()> {
        let bad = |m: String| Err(TacitError::Setting(m));
        if self.window < 1 {
            return bad(format!("window = {} samples: must be >= 1", self.window));
        }
        if self.method == Method::Mhe && self.horizon < self.window {
            return bad(format!(
                "horizon = {} samples: must be >= window = {}",
                self.horizon, self.window
            ));
        }
        if self.substeps < 1 {
            return bad(format!("substeps = {}: must be >= 1", self.substeps));
        }
        if let Regularization::Fixed(a) = self.regularization {
            if !(a.is_finite() && a >= 0.0) {
                return bad(format!("alpha = {a}: must be finite and >= 0"));
            }
        }
        let (lo, hi, count) = self.alpha_grid;
        if !(lo.is_finite() && hi.is_finite() && lo > 0.0 && hi > lo && count >= 3) {
            return bad(format!(
                "alpha grid ({lo}, {hi}, {count}): need 0 < lowest < highest and count >= 3"
            ));
        }
        let nonneg = |v: f64, name: &str| -> Result<()> {
            if !(v.is_finite() && v >= 0.0) {
                return Err(TacitError::Setting(format!(
                    "{name} = {v}: must be finite and >= 0"
                )));
            }
            Ok(())
        };
        nonneg(self.smoothness, "smoothness")?;
        nonneg(self.prior_weight, "prior weight")?;
        if !(self.leak.is_finite() && self.leak > 0.0) {
            return bad(format!("leak = {}: must be finite and > 0", self.leak));
        }
        if !(self.rank_rtol.is_finite() && self.rank_rtol > 0.0 && self.rank_rtol < 1.0) {
            return bad(format!("rank rtol = {}: must be in (0, 1)", self.rank_rtol));
        }
        if self.solver == Solver::Ls && !self.constraints.is_empty() {
            return bad("constraints need the QP solver (--solver qp)".into());
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_validate_and_bad_values_are_named() {
        IdentifySettings::default().validate().unwrap();
        IdentifySettings::paper(1.0).validate().unwrap();
        let s = IdentifySettings {
            window: 0,
            ..Default::default()
        };
        let e = s.validate().unwrap_err().to_string();
        assert!(e.contains("window = 0"), "{e}");
        let s = IdentifySettings {
            horizon: 2,
            ..Default::default()
        };
        assert!(s
            .validate()
            .unwrap_err()
            .to_string()
            .contains("horizon = 2"));
        let s = IdentifySettings {
            constraints: Constraints {
                equilibrium: true,
                ..Default::default()
            },
            ..Default::default()
        };
        assert!(s.validate().unwrap_err().to_string().contains("QP"));
        let c = Constraints {
            pairs: vec![(5, 9)],
            ..Default::default()
        };
        assert!(c.validate(8).unwrap_err().to_string().contains("DOF 9"));
    }
}
