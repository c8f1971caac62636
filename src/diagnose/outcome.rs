//! What the diagnosis returns: the errors before and after, the effects
//! found and how each round of the loop ended.

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
    /// The effect's kind ([`EffectKind`]; serialized in snake case).
    pub kind: EffectKind,
    /// DOFs from 1 (contact `[i, j]`: on when `u_i − u_j` exceeds the gap).
    pub dofs: Vec<usize>,
    /// Label.
    pub label: String,
    /// Fitted parameters, SI (`gap` m, `stiffness` N/m, `level` N, `k3`
    /// N/m³, `delta` relative change).
    pub parameters: BTreeMap<String, f64>,
    /// Standard errors of the parameters from measurement noise alone
    /// (null when not determined).
    pub std_errors: BTreeMap<String, Option<f64>>,
    /// Each parameter fitted on each quarter of the fit's segments alone
    /// (one linearized step from the fit, start states re-estimated; empty
    /// when not computed): their scatter includes model error and
    /// coloured residual, which the standard errors do not.
    pub group_estimates: BTreeMap<String, Vec<f64>>,
    /// Parameters from the trace regression (the fit's start).
    pub traced: BTreeMap<String, f64>,
    /// Parameters the records do not determine: their noise-only standard
    /// error exceeds their value ([`undetermined`]), or no record from
    /// these sensors could determine them (`unobservable`).
    pub undetermined: Vec<String>,
    /// Parameters that trade exactly with something the sensors do not
    /// see, whatever the noise: the gap of a contact against ground on a
    /// structure free to translate, measured by accelerations only (the
    /// absolute position; [`super::uncertainty::gap_unobservable`]). Also
    /// in `undetermined`.
    pub unobservable: Vec<String>,
    /// Scores.
    pub score: Score,
}

impl EffectReport {
    /// The mean and the standard error (sample standard deviation over the
    /// square root of their number) of `name`'s values on the quarters of
    /// the record ([`EffectReport::group_estimates`]); None with fewer
    /// than two.
    pub fn quarters(&self, name: &str) -> Option<(f64, f64)> {
        let g = self.group_estimates.get(name)?;
        let n = g.len();
        if n < 2 {
            return None;
        }
        let mean = g.iter().sum::<f64>() / n as f64;
        let var = g.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1) as f64;
        Some((mean, (var / n as f64).sqrt())).filter(|(m, s)| m.is_finite() && s.is_finite())
    }

    /// The uncertainty of `name` seen across the record: the quarters'
    /// standard error ([`EffectReport::quarters`]) combined (root sum of
    /// squares) with the distance of their mean from the reported value,
    /// which is large when the fit stopped short of its minimum.
    pub fn spread_error(&self, name: &str) -> Option<f64> {
        let (mean, se) = self.quarters(name)?;
        let v = *self.parameters.get(name)?;
        Some(se.hypot(mean - v))
    }
}

/// The parameters of `values` whose standard error (`std_errors`)
/// exceeds their magnitude: noise alone could move them by more than
/// their whole value, so the records do not tell what they are (a stop's
/// gap against ground on a structure free to move as a rigid body, which
/// each segment's free start position absorbs, is the known case).
pub fn undetermined(
    values: &BTreeMap<String, f64>,
    std_errors: &BTreeMap<String, Option<f64>>,
) -> Vec<String> {
    values
        .iter()
        .filter(|(k, v)| {
            std_errors
                .get(*k)
                .copied()
                .flatten()
                .is_some_and(|se| se > v.abs())
        })
        .map(|(k, _)| k.clone())
        .collect()
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
    /// The law tried in place of the one fitted
    /// ([`super::alternative`]), if one was.
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
    /// Gaps of contacts against ground that the sensors do not observe,
    /// taken again from this record's own datum (the fitted model is
    /// scored with them; empty when none moved).
    pub datum: Vec<DatumShift>,
}

/// A contact's gap against ground measured from another record's datum:
/// the structure's absolute position is not observed, so each record
/// places the gap relative to its own reconstructed positions.
#[derive(Debug, Clone, Serialize)]
pub struct DatumShift {
    /// The contact.
    pub label: String,
    /// Gap fitted on the record diagnosed, m.
    pub fitted: f64,
    /// Gap on this record's datum, m.
    pub here: f64,
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
    /// The calibration of the linear part and its corrections (None when
    /// the declared model was trusted).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub calibration: Option<super::calibrated::CalibrationReport>,
    /// The noise measured on the record (None when the level was
    /// assumed: [`super::NoiseSettings::measure`] off).
    pub noise: Option<super::noise::NoiseEstimate>,
    /// The fitted model.
    #[serde(skip)]
    pub model: Model,
    /// The effects' parameter bookkeeping, in the order of `effects`.
    #[serde(skip)]
    pub added: Vec<super::effects::AddedEffect>,
    /// Data of the first record (for figures).
    #[serde(skip)]
    pub prepared: Prepared,
    /// Segment predictions before and after (p × N).
    #[serde(skip)]
    pub predictions: (Option<DMatrix<f64>>, Option<DMatrix<f64>>),
    /// The validation record as the diagnosis prepared it, when given.
    #[serde(skip)]
    pub validation_prepared: Option<super::ValidationPrepared>,
}

impl Diagnosis {
    /// The noise level the diagnosis ran at ([`super::NoiseEstimate::used`]),
    /// or the assumed [`super::NoiseSettings::level`] of `settings` when
    /// the noise was not measured.
    pub fn noise_level(&self, settings: &super::DiagnoseSettings) -> f64 {
        self.noise.as_ref().map_or(settings.noise.level, |n| n.used)
    }

    /// The noise floor of the multiple-shooting error the diagnosis ran
    /// at ([`super::NoiseSettings::floor_multiple`] × [`Self::noise_level`]).
    pub fn noise_floor(&self, settings: &super::DiagnoseSettings) -> f64 {
        settings.noise.floor_multiple * self.noise_level(settings)
    }

    /// What the fitted model leaves of the record (its segment
    /// predictions' residual, [`super::noise::remaining`]) over `bands`
    /// frequency bands; None without predictions.
    pub fn remaining(&self, bands: usize) -> Option<super::noise::Remaining> {
        let cmp = &self.prepared.comparison;
        let predicted = self.predictions.1.as_ref()?;
        let names: Vec<String> = cmp.observations.iter().map(|o| o.name()).collect();
        super::noise::remaining(&cmp.measured(), predicted, &names, cmp.fs, bands)
    }
}

/// A candidate below the trace's screen that was considered anyway.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BelowScreen {
    /// Why the trace's screen proposed nothing (the trace's words).
    pub trace: String,
    /// Candidates the joint linearization predicted below the screen:
    /// label and predicted fraction of the fit cost removed.
    pub screened_out: Vec<(String, f64)>,
    /// The screen: the fraction of the fit cost a candidate had to be
    /// predicted to remove.
    pub screen: f64,
}

/// Why a fitted effect was withdrawn.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum WithdrawReason {
    /// Switched off in the fitted model the error is hardly higher: it
    /// does not itself remove the share `need` of the squared error.
    NotItself {
        /// Error with it switched off.
        without: Option<f64>,
        /// Error with it.
        with: Option<f64>,
        /// Share of the squared error it had to remove.
        need: f64,
    },
    /// Fitted, it does not remove the share `need` of the squared error.
    TooLittle {
        /// Share of the squared error it had to remove.
        need: f64,
        /// Error before it.
        before: Option<f64>,
        /// Error with it, fitted.
        after: Option<f64>,
    },
}

/// How a round of the loop ended.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(rename_all = "snake_case", tag = "outcome")]
pub enum Decision {
    /// The model explains the record up to noise: no effect sought.
    AtNoise {
        /// Multiple-shooting error.
        error: f64,
        /// The noise floor it is at or below.
        floor: f64,
    },
    /// No candidate pays (the trace's words).
    NothingPays {
        /// Why the trace stopped.
        reason: String,
    },
    /// Every candidate below the screen was predicted to gain too little.
    ScreenedOut(BelowScreen),
    /// The effect is kept.
    Kept {
        /// Error before it.
        before: Option<f64>,
        /// Error with it, fitted.
        after: Option<f64>,
        /// When it came in below the screen.
        below: Option<BelowScreen>,
        /// The Gauss–Newton iterations of the start states the errors were
        /// scored on when the loop's own scoring withdrew it and the
        /// converged one did not ([`super::StartSettings::confirm_iterations`];
        /// None: kept on the loop's own scoring).
        confirmed: Option<usize>,
    },
    /// The effect is withdrawn.
    Withdrawn {
        /// Why.
        reason: WithdrawReason,
        /// When it came in below the screen.
        below: Option<BelowScreen>,
        /// The effects found, as refitted beside it, kept instead: error
        /// before and after.
        refit_kept: Option<(Option<f64>, Option<f64>)>,
        /// The Gauss–Newton iterations of the start states the withdrawal
        /// was confirmed on (None: on the loop's own scoring alone).
        confirmed: Option<usize>,
    },
}

/// Another law tried in place of the one fitted ([`super::alternative`]):
/// the cubic spring in place of a stiffness change or a spring to ground,
/// the clearance in place of a cubic spring, the other damper law.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct AlternativeTried {
    /// The alternative's label.
    pub label: String,
    /// Its start: parameter names and values, SI (a cubic's k3 is the
    /// change's equivalent).
    pub start: Vec<(String, f64)>,
    /// Its multiple-shooting error, fitted (None when it failed).
    pub error: Option<f64>,
    /// Whether it replaced the stiffness change.
    pub taken: bool,
    /// The stiffness change: label and error.
    pub instead_of: (String, Option<f64>),
}
