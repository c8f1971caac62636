//! Settings of the full-horizon identification: the weights of the cost
//!
//! $$ J = \sum_k \|y_k - \hat y_k\|^2_W + \lambda \sum_k \|w_k\|^2
//!      + \mu \sum_k \|w_{k+1} - w_k\|^2 + \|x_0 - \bar x_0\|^2_{P} $$
//!
//! how they are chosen, the initial state, constraints and the numerical
//! tolerances of the Riccati sweep.

use crate::error::{Result, TacitError};
use serde::{Deserialize, Serialize};

/// The output weight `W = diag(1/σ_c²)`: the noise standard deviation
/// assumed for each measured channel.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum ChannelNoise {
    /// σ_c = `fraction` × RMS of channel c (e.g. 0.01 for 1 % noise).
    RmsFraction {
        /// Fraction of the channel RMS, > 0.
        fraction: f64,
    },
    /// σ_c given per channel, in the channel's unit (> 0 each).
    Std {
        /// One value per measured channel.
        std: Vec<f64>,
    },
}

/// The initial state `x_0 = [u_0; v_0]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum InitialState {
    /// The record starts at rest: `x_0 = 0`, not estimated.
    Rest,
    /// `x_0` is known (2n values, `[u_0; v_0]`), not estimated.
    Known {
        /// `[u_0; v_0]`, m and m/s.
        x0: Vec<f64>,
    },
    /// `x_0` is estimated with the prior `‖x_0 − x̄_0‖²_P`,
    /// `P = diag(1/σ_u², …, 1/σ_v², …)`. A weak prior (large σ) lets the
    /// data decide; it must be finite so that states the data do not see
    /// (a free-free model's rigid-body position under acceleration data)
    /// stay determined.
    Estimate {
        /// Prior mean `x̄_0` (2n values), or empty for zero.
        mean: Vec<f64>,
        /// Prior standard deviation of every initial displacement, m (> 0).
        std_disp: f64,
        /// Prior standard deviation of every initial velocity, m/s (> 0).
        std_vel: f64,
    },
}

/// Noise level used by the discrepancy principle.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum NoiseLevel {
    /// The channel noise given by [`HorizonSettings::noise`] is the true
    /// noise: the target is `‖r‖²_W = τ · N p`.
    Known,
    /// Estimated from the generalized cross-validation fit,
    /// `σ̂² = ‖r‖²_W / (N p − tr H)`: the target is `τ · σ̂² · N p`.
    Estimated,
}

/// How the weights λ and μ are chosen. Automatic choices scale both by one
/// factor `α` (`λ = α λ_0`, `μ = α μ_0`, with λ_0, μ_0 from the settings),
/// searched on a logarithmic grid of `α` and refined.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum WeightSelection {
    /// Use λ and μ as given.
    Fixed,
    /// Minimise the generalized cross-validation function
    /// `GCV(α) = N p ‖r‖²_W / (N p − tr H)²` (Golub, Heath & Wahba 1979).
    Gcv,
    /// Corner of the L-curve `(log ‖r‖_W, log ‖w‖)`: maximum curvature
    /// (Hansen 1992).
    LCurve,
    /// Morozov's discrepancy principle: the largest α whose residual does
    /// not exceed `tau` times the expected noise energy.
    Discrepancy {
        /// Known or estimated noise.
        noise: NoiseLevel,
        /// Safety factor τ ≥ 1 (1.0 by default in the CLI).
        tau: f64,
    },
}

/// Constraints that make the problem a quadratic program (solved with
/// Clarabel over the whole horizon). Components are indexed like the
/// columns of the unknown-force input matrix; DOFs are 0-based.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct ForceConstraints {
    /// `(component, lower, upper)` bounds in N; use ±∞ for one-sided
    /// bounds (a sign constraint is `(i, 0, ∞)` or `(i, −∞, 0)`).
    pub bounds: Vec<(usize, f64, f64)>,
    /// The unknown DOF forces are self-equilibrated at every sample:
    /// `Σ_dof (B_u w_k)_dof = 0` (internal forces of elements that do not
    /// touch the ground).
    pub equilibrium: bool,
    /// Action–reaction pairs of DOFs `(i, j)`: `(B_u w_k)_i + (B_u w_k)_j = 0`.
    pub pairs: Vec<(usize, usize)>,
}

impl ForceConstraints {
    /// True when no constraint is set.
    pub fn is_empty(&self) -> bool {
        self.bounds.is_empty() && !self.equilibrium && self.pairs.is_empty()
    }
}

/// How the reported covariance is scaled.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CovarianceScale {
    /// As the weights say: correct when `W` and `λ` are the true inverse
    /// noise and force variances.
    Model,
    /// Multiplied by the estimated variance of unit weight
    /// `σ̂² = ‖r‖²_W / (N p − tr H)` (weights known up to a common factor).
    Estimated,
}

/// Settings of [`crate::horizon::identify`]. Every field has a documented
/// default; call [`HorizonSettings::validate`] before use (the front door
/// does).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct HorizonSettings {
    /// λ, weight of `Σ‖w_k‖²`, 1/N² (relative to `W`). Must be > 0: it is
    /// the prior that makes every force sample determined. Default 1e-2
    /// (a prior force standard deviation of 10 N when W is the inverse
    /// noise variance).
    pub lambda: f64,
    /// μ, weight of `Σ‖w_{k+1} − w_k‖²`, 1/N², ≥ 0. Default 0.
    pub mu: f64,
    /// Channel noise that defines `W`. Default 1 % of each channel's RMS.
    pub noise: ChannelNoise,
    /// Initial state. Default: estimated, zero mean, σ_u = 10 mm,
    /// σ_v = 1 m/s (weak for a laboratory structure, yet enough to keep
    /// the rigid-body position of a free-free model determined).
    pub initial: InitialState,
    /// Weight selection. Default [`WeightSelection::Fixed`].
    pub selection: WeightSelection,
    /// Search range of the selection factor α, decades below and above 1
    /// (default 4, i.e. α ∈ [1e-4, 1e4]); 1 ≤ value ≤ 12.
    pub selection_decades: f64,
    /// Grid points per decade of the α search (default 2; 1..=10).
    pub selection_points_per_decade: usize,
    /// Constraints (default none: the Riccati smoother is used).
    pub constraints: ForceConstraints,
    /// Compute the smoother covariance, the force standard deviations and
    /// `tr H` (default true).
    pub covariance: bool,
    /// Scaling of the reported covariance (default
    /// [`CovarianceScale::Estimated`]).
    pub covariance_scale: CovarianceScale,
    /// Tolerance on the Riccati recursion's distance to its fixed point
    /// (relative, max norm) below which its gain is held over the rest of
    /// the record (default 1e-13; (0, 1e-4]). The fixed point is solved
    /// for by Newton's method, so the distance is measured, not guessed
    /// from a change between steps; below ~1e-13 it is rounding (the
    /// recursion is then held once its change stayed below this for 64
    /// steps, as it is when the fixed point is too ill-conditioned to
    /// solve for). The covariance recursion is held once its force
    /// variances and output trace are within max(this, 1e-10) of their
    /// steady values.
    pub riccati_tol: f64,
    /// Hold the Riccati gain once the recursion has reached its fixed point
    /// (default true). False computes the exact gain of every transition —
    /// the reference the held answer is checked against, at the cost of
    /// one Riccati step per sample (`max_transient` is then ignored).
    pub hold_steady_gain: bool,
    /// Longest transient (samples) the Riccati recursion may take before it
    /// is declared non-convergent (default 20 000; ≥ 10). The last gain is
    /// then used and the status says so.
    pub max_transient: usize,
}

impl Default for HorizonSettings {
    fn default() -> Self {
        HorizonSettings {
            lambda: 1e-2,
            mu: 0.0,
            noise: ChannelNoise::RmsFraction { fraction: 0.01 },
            initial: InitialState::Estimate {
                mean: vec![],
                std_disp: 1e-2,
                std_vel: 1.0,
            },
            selection: WeightSelection::Fixed,
            selection_decades: 4.0,
            selection_points_per_decade: 2,
            constraints: ForceConstraints::default(),
            covariance: true,
            covariance_scale: CovarianceScale::Estimated,
            riccati_tol: 1e-13,
            hold_steady_gain: true,
            max_transient: 20_000,
        }
    }
}

fn bad(msg: String) -> TacitError {
    TacitError::Setting(format!("horizon: {msg}"))
}

impl HorizonSettings {
    /// Check every rule that does not depend on the data; the error repeats
    /// the rule.
    pub fn validate(&self) -> Result<()> {
        if !(self.lambda > 0.0 && self.lambda.is_finite()) {
            return Err(bad(format!("lambda = {} must be > 0", self.lambda)));
        }
        if !(self.mu >= 0.0 && self.mu.is_finite()) {
            return Err(bad(format!("mu = {} must be >= 0", self.mu)));
        }
        match &self.noise {
            ChannelNoise::RmsFraction { fraction } => {
                if !(*fraction > 0.0 && fraction.is_finite()) {
                    return Err(bad(format!("noise fraction = {fraction} must be > 0")));
                }
            }
            ChannelNoise::Std { std } => {
                if let Some((i, s)) = std.iter().enumerate().find(|(_, s)| !(**s > 0.0)) {
                    return Err(bad(format!("noise std of channel {i} = {s} must be > 0")));
                }
            }
        }
        if let InitialState::Estimate {
            std_disp, std_vel, ..
        } = &self.initial
        {
            if !(*std_disp > 0.0 && std_disp.is_finite() && *std_vel > 0.0 && std_vel.is_finite()) {
                return Err(bad(format!(
                    "initial-state prior std (disp {std_disp}, vel {std_vel}) must be finite and > 0"
                )));
            }
        }
        if let WeightSelection::Discrepancy { tau, .. } = &self.selection {
            if !(*tau >= 1.0 && tau.is_finite()) {
                return Err(bad(format!("discrepancy tau = {tau} must be >= 1")));
            }
        }
        if !(1.0..=12.0).contains(&self.selection_decades) {
            return Err(bad(format!(
                "selection_decades = {} must be in [1, 12]",
                self.selection_decades
            )));
        }
        if !(1..=10).contains(&self.selection_points_per_decade) {
            return Err(bad(format!(
                "selection_points_per_decade = {} must be in 1..=10",
                self.selection_points_per_decade
            )));
        }
        for &(i, lo, hi) in &self.constraints.bounds {
            if lo.is_nan() || hi.is_nan() || lo > hi {
                return Err(bad(format!(
                    "bounds of component {i}: lower {lo} must be <= upper {hi}"
                )));
            }
        }
        if !(self.riccati_tol > 0.0 && self.riccati_tol <= 1e-4) {
            return Err(bad(format!(
                "riccati_tol = {} must be in (0, 1e-4]",
                self.riccati_tol
            )));
        }
        if self.max_transient < 10 {
            return Err(bad(format!(
                "max_transient = {} must be >= 10",
                self.max_transient
            )));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_is_valid_and_rules_are_enforced() {
        assert!(HorizonSettings::default().validate().is_ok());
        let s = HorizonSettings {
            lambda: 0.0,
            ..Default::default()
        };
        let e = s.validate().unwrap_err().to_string();
        assert!(e.contains("lambda = 0"), "{e}");
        let s = HorizonSettings {
            mu: -1.0,
            ..Default::default()
        };
        assert!(s.validate().is_err());
        let s = HorizonSettings {
            selection: WeightSelection::Discrepancy {
                noise: NoiseLevel::Known,
                tau: 0.5,
            },
            ..Default::default()
        };
        assert!(s.validate().is_err());
        let mut s = HorizonSettings::default();
        s.constraints.bounds.push((0, 1.0, -1.0));
        assert!(s.validate().is_err());
    }
}
