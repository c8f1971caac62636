//! What the rounds of the loop read ([`Context`]: the record prepared,
//! the declared model, the settings) and change ([`State`]: the current
//! model and its error, the effects kept, the rounds' outcomes, the counts
//! and timings).

use super::effects::{self, AddedEffect};
use super::errors::{shot_simulations, Comparison, ErrorSet, ShotResult};
use super::fit::EffectFit;
use super::outcome::{Round, Score, ToleratedFailure};
use super::prepare::{rescore_prep, Prepared};
use super::DiagnoseSettings;
use crate::integrate::SimSettings;
use crate::model::Model;
use crate::record::Record;
use crate::trace::{EffectKind, RankedEffect};
use crate::update::shooting::Segment;
use nalgebra::DMatrix;
use std::cell::RefCell;
use std::collections::BTreeMap;
use std::time::Instant;

/// Add the seconds since `t` to the timing `name`.
pub(super) fn add_time(timings: &mut BTreeMap<String, f64>, name: &str, t: Instant) {
    *timings.entry(name.into()).or_insert(0.0) += t.elapsed().as_secs_f64();
}

/// What every round reads.
pub(super) struct Context<'a> {
    /// The declared model.
    pub declared: &'a Model,
    /// The record diagnosed.
    pub rec: &'a Record,
    /// Sensor DOFs used (all outputs when None).
    pub sensors: Option<&'a [usize]>,
    /// Settings.
    pub settings: &'a DiagnoseSettings,
    /// The record prepared.
    pub prep: &'a Prepared,
    /// Output maps of the linear model on the channels.
    pub cy: DMatrix<f64>,
    /// Feed-through of the channels.
    pub dy: DMatrix<f64>,
    /// Measured channels (p × N).
    pub measured: DMatrix<f64>,
    /// Located force directions (n × q).
    pub located: Option<DMatrix<f64>>,
    /// Failures gone on past, each with its fallback.
    pub tolerated: RefCell<Vec<ToleratedFailure>>,
    /// The noise level measured on the record (None when not measured).
    pub measured_noise: Option<f64>,
}

/// A model's multiple shooting on the record.
pub(super) struct Scored {
    /// The model's own reconstruction, when it needs one
    /// ([`rescore_prep`]).
    pub own: Option<Prepared>,
    /// The multiple shooting.
    pub shot: ShotResult,
    /// Its error on the record.
    pub error: Option<f64>,
}

/// An effect added, fitted and scored.
pub(super) struct Trial {
    /// The candidate.
    pub best: RankedEffect,
    /// Its bookkeeping.
    pub effect: AddedEffect,
    /// The fit.
    pub fit: EffectFit,
    /// Simulation settings that resolve the fitted model.
    pub sim: SimSettings,
    /// The fitted model's multiple shooting.
    pub scored: Scored,
}

/// An effect kept.
pub(super) struct KeptEffect {
    /// Its bookkeeping.
    pub effect: AddedEffect,
    /// How the trace ranked it.
    pub ranked: RankedEffect,
    /// How much it paid.
    pub score: Score,
}

/// What the rounds change.
pub(super) struct State {
    /// The current model.
    pub current: Model,
    /// Its multiple-shooting error.
    pub error: Option<f64>,
    /// Its sub-steps.
    pub substeps: usize,
    /// Its multiple shooting, once an effect is kept.
    pub scored: Option<(Option<Prepared>, ShotResult)>,
    /// The fit segments with their fitted start states and the fit's
    /// simulation settings.
    pub fitted: Option<(Vec<Segment>, SimSettings)>,
    /// Segment predictions of the current model for the trace (a
    /// nonlinear model).
    pub baseline: Option<DMatrix<f64>>,
    /// Effects kept.
    pub added: Vec<KeptEffect>,
    /// The rounds so far.
    pub rounds: Vec<Round>,
    /// Best candidates of the first trace round.
    pub ranking: Vec<RankedEffect>,
    /// Nonlinear segment simulations.
    pub simulations: usize,
    /// Linear segment simulations of the trace.
    pub trace_simulations: usize,
    /// Stage timings, s.
    pub timings: BTreeMap<String, f64>,
}

impl State {
    /// The state before any round: the declared model scored.
    pub fn new(
        declared: &Model,
        before: &ErrorSet,
        pred_before: Option<&DMatrix<f64>>,
        substeps: usize,
        simulations: usize,
        timings: BTreeMap<String, f64>,
    ) -> State {
        State {
            current: declared.clone(),
            error: before.relative_error,
            substeps,
            scored: None,
            fitted: None,
            baseline: pred_before.filter(|_| declared.is_nonlinear()).cloned(),
            added: vec![],
            rounds: vec![],
            ranking: vec![],
            simulations,
            trace_simulations: 0,
            timings,
        }
    }
}

impl<'a> Context<'a> {
    /// The comparison data of the record.
    pub fn cmp(&self) -> &'a Comparison {
        &self.prep.comparison
    }

    /// Record a failure the diagnosis goes on past.
    pub fn tolerate(&self, step: &str, error: impl std::fmt::Display, fallback: &str) {
        self.tolerated.borrow_mut().push(ToleratedFailure {
            step: step.into(),
            error: error.to_string(),
            fallback: fallback.into(),
        });
    }

    /// `model`'s own reconstruction of `rec` when it needs one
    /// ([`rescore_prep`]; when it fails, the declared model's is used and
    /// the failure is recorded).
    pub fn own_prep(&self, model: &Model, rec: &Record) -> Option<Prepared> {
        let located = self.prep.located.as_ref();
        // the record's own reconstruction is at hand
        let base = std::ptr::eq(rec, self.rec).then_some(self.prep);
        match rescore_prep(
            self.declared,
            model,
            rec,
            self.sensors,
            self.settings,
            located,
            base,
        ) {
            Ok(p) => p,
            Err(e) => {
                let step = "reconstruction with the model's spring or law to ground";
                self.tolerate(step, e, "the declared model's reconstruction");
                None
            }
        }
    }

    /// A model's multiple shooting (from its own reconstruction when it
    /// needs one) and the simulations run; the error is on the record.
    pub fn shoot(&self, model: &Model, sim: SimSettings) -> (Scored, usize) {
        self.shoot_with(model, sim, None)
    }

    /// A model's multiple-shooting error on the record with the start
    /// states refined by `iterations` Gauss–Newton iterations
    /// ([`Context::shoot`] with them), and the simulations run; None when
    /// a segment's prediction or the error is not finite.
    pub fn shoot_error(
        &self,
        model: &Model,
        sim: SimSettings,
        iterations: usize,
    ) -> (Option<f64>, usize) {
        let (scored, n) = self.shoot_with(model, sim, Some(iterations));
        (scored.error.filter(|e| e.is_finite()), n)
    }

    /// [`Context::shoot`] with `iterations` Gauss–Newton iterations of the
    /// start states (None: the comparison's own).
    fn shoot_with(
        &self,
        model: &Model,
        sim: SimSettings,
        iterations: Option<usize>,
    ) -> (Scored, usize) {
        let own = self.own_prep(model, self.rec);
        let own_cmp = own.as_ref().map_or(self.cmp(), |p| &p.comparison);
        let iterations = iterations.unwrap_or(own_cmp.starts.iterations);
        let shot = own_cmp.shoot_refined(model, sim, super::starts::refine, iterations);
        let n = shot_simulations(shot.as_ref().ok().and_then(|p| p.2.as_ref()), own_cmp);
        let error = shot.as_ref().ok().map(|y| self.cmp().total_error(&y.0));
        (Scored { own, shot, error }, n)
    }
}

/// The current model with `best` added at its traced values, its
/// bookkeeping, and every added effect with it last. A dissipative
/// candidate carries the model's damping parameters as its nuisance
/// parameters ([`effects::damping_targets`]) unless an effect found
/// already frees the damping (its own nuisance or a damping change).
pub(super) fn add_to(st: &State, best: &RankedEffect) -> (Model, AddedEffect, Vec<AddedEffect>) {
    let mut trial = st.current.clone();
    let mut eff = effects::add(&mut trial, best);
    let freed = st
        .added
        .iter()
        .any(|a| !a.effect.nuisance.is_empty() || a.effect.candidate.kind == EffectKind::Damping);
    if best.candidate.kind.dissipative() && !freed {
        eff.nuisance = effects::damping_targets(&trial);
    }
    let mut all: Vec<AddedEffect> = st.added.iter().map(|a| a.effect.clone()).collect();
    all.push(eff.clone());
    (trial, eff, all)
}
