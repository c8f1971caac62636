//! What the diagnosis returns: the errors before and after, the effects
//! found and how each round of the loop ended.

use super::alternative::AlternativeTried;
use super::decide::Decision;
use super::errors::ErrorSet;
use super::prepare::Prepared;
use crate::model::Model;
use crate::trace::{EffectKind, RankedEffect};
use nalgebra::DMatrix;
use serde::Serialize;
use std::collections::BTreeMap;

/// One effect in the report.
#[derive(Debug, Clone, Serialize)]
pub struct EffectReport {
    /// `contact`, `friction`, `cubic`, `stiffness`, `ground_spring`, `damping`.
    pub kind: EffectKind,
    /// DOFs from 1 (contact `[i, j]`: on when `u_i − u_j` exceeds the gap).
    pub dofs: Vec<usize>,
    /// Label.
    pub label: String,
    /// Fitted parameters, SI (`gap` m, `stiffness` N/m, `level` N, `k3`
    /// N/m³, `delta` relative change).
    pub parameters: BTreeMap<String, f64>,
    /// Standard errors of the parameters (null when not determined).
    pub std_errors: BTreeMap<String, Option<f64>>,
    /// Parameters from the trace regression (the fit's start).
    pub traced: BTreeMap<String, f64>,
    /// Scores.
    pub score: Score,
}

/// How much an effect pays.
#[derive(Debug, Clone, Serialize)]
pub struct Score {
    /// Fraction of the remaining segment residual its regression removed.
    pub residual_explained: f64,
    /// BIC change of the regression (negative pays).
    pub bic_change: f64,
    /// Fraction of the identified force it explains.
    pub force_explained: Option<f64>,
    /// Multiple-shooting error before it was added.
    pub error_before: Option<f64>,
    /// Multiple-shooting error after it was added and fitted.
    pub error_after: Option<f64>,
}

/// One round of the loop (written to report.json with `kept` and `note`,
/// the decision in words, by [`super::report`]).
#[derive(Debug, Clone)]
pub struct Round {
    /// Effect proposed (None when none was fitted).
    pub proposed: Option<String>,
    /// How the round ended.
    pub decision: Decision,
    /// How the fit of the effect proposed ended (if fitted).
    pub fit: Option<String>,
    /// The cubic spring tried in place of a large stiffness change
    /// ([`super::alternative`]), if it was.
    pub alternative: Option<AlternativeTried>,
    /// Simulations spent by the fit (by the screen when nothing was fitted).
    pub simulations: usize,
}

impl Round {
    /// A round that fitted nothing.
    pub fn unfitted(decision: Decision, simulations: usize) -> Round {
        Round {
            proposed: None,
            decision,
            fit: None,
            alternative: None,
            simulations,
        }
    }

    /// Whether the effect proposed was kept.
    pub fn kept(&self) -> bool {
        matches!(self.decision, Decision::Kept { .. })
    }
}

/// Errors on the validation record.
#[derive(Debug, Clone, Serialize)]
pub struct Validation {
    /// Declared model.
    pub before: ErrorSet,
    /// Fitted model.
    pub after: ErrorSet,
    /// Linear model driven by the force identified on the first record
    /// (non-parametric prediction), multiple-shooting error.
    pub nonparametric_relative_error: Option<f64>,
}

/// A failure the diagnosis went on past (it used a fallback), reported so
/// that nothing is lost silently.
#[derive(Debug, Clone, Serialize)]
pub struct ToleratedFailure {
    /// The step that failed.
    pub step: String,
    /// What failed.
    pub error: String,
    /// What was used instead.
    pub fallback: String,
}

/// The result of [`super::diagnose`].
#[derive(Debug, Clone, Serialize)]
pub struct Diagnosis {
    /// "no missing effect found" or what was found.
    pub verdict: String,
    /// Declared model's errors.
    pub before: ErrorSet,
    /// Fitted model's errors.
    pub after: ErrorSet,
    /// On the validation record, when given.
    pub validation: Option<Validation>,
    /// Effects added, in order.
    pub effects: Vec<EffectReport>,
    /// Best candidates of the first trace round.
    pub ranking: Vec<RankedEffect>,
    /// The rounds of the loop.
    pub rounds: Vec<Round>,
    /// Sub-steps used before and after.
    pub substeps: (usize, usize),
    /// Nonlinear simulations run (fits and errors).
    pub simulations: usize,
    /// Linear segment simulations of the trace.
    pub trace_simulations: usize,
    /// Identification notes.
    pub identification: String,
    /// Failures the diagnosis went on past, each with its fallback.
    pub tolerated_failures: Vec<ToleratedFailure>,
    /// Timings, s.
    pub timings: BTreeMap<String, f64>,
    /// The fitted model.
    #[serde(skip)]
    pub model: Model,
    /// Data of the first record (for figures).
    #[serde(skip)]
    pub prepared: Prepared,
    /// Segment predictions before and after (p × N).
    #[serde(skip)]
    pub predictions: (Option<DMatrix<f64>>, Option<DMatrix<f64>>),
}
