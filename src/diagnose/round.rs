//! One round of the loop: trace the residual to a candidate effect,
//! screen it, fit it, decide whether it stays.
//!
//! [`Context`] holds what every round reads (the record prepared, the
//! declared model, the settings); [`State`] what the rounds change (the
//! current model and its error, the effects kept, the rounds' outcomes,
//! the counts and timings).

use super::alternative;
use super::decide::{self, Decision};
use super::effects::AddedEffect;
use super::errors::{shot_simulations, Comparison, ErrorSet, ShotResult};
use super::fit::{fit_effects, EffectFit};
use super::outcome::{Round, Score, ToleratedFailure};
use super::prepare::{rescore_prep, Prepared};
use super::screen;
use super::substeps::resolved;
use super::DiagnoseSettings;
use crate::error::Result;
use crate::integrate::SimSettings;
use crate::model::Model;
use crate::record::Record;
use crate::trace::{self, RankedEffect, TraceInput, TraceResult};
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
        match rescore_prep(
            self.declared,
            model,
            rec,
            self.sensors,
            self.settings,
            located,
        ) {
            Ok(p) => p,
            Err(e) => {
                let step = "reconstruction with the model's spring to ground";
                self.tolerate(step, e, "the declared model's reconstruction");
                None
            }
        }
    }

    /// A model's multiple shooting (from its own reconstruction when it
    /// needs one) and the simulations run; the error is on the record.
    pub fn shoot(&self, model: &Model, sim: SimSettings) -> (Scored, usize) {
        let own = self.own_prep(model, self.rec);
        let own_cmp = own.as_ref().map_or(self.cmp(), |p| &p.comparison);
        let shot = own_cmp.shoot(model, sim);
        let n = shot_simulations(shot.as_ref().ok().and_then(|p| p.2.as_ref()), own_cmp);
        let error = shot.as_ref().ok().map(|y| self.cmp().total_error(&y.0));
        (Scored { own, shot, error }, n)
    }

    /// Fit the effects `all` on `trial`: a trial with a spring to ground
    /// is fitted from states reconstructed with its own linear part (as it
    /// is scored), not from the declared reconstruction corrected along
    /// the hidden trajectories.
    fn fit_trial(
        &self,
        trial: &Model,
        all: &[AddedEffect],
        correction: Option<&DMatrix<f64>>,
        predicted: Option<&[Vec<f64>]>,
    ) -> Result<EffectFit> {
        let fs = self.rec.fs;
        match &self.own_prep(trial, self.rec) {
            Some(o) => fit_effects(
                trial,
                all,
                &o.comparison,
                &o.recon.states,
                None,
                predicted,
                fs,
                self.settings,
            ),
            None => fit_effects(
                trial,
                all,
                self.cmp(),
                &self.prep.recon.states,
                correction,
                predicted,
                fs,
                self.settings,
            ),
        }
    }

    /// Add `best` to the current model, fit every added effect and score
    /// the fitted model.
    pub fn fit_scored(
        &self,
        st: &mut State,
        best: RankedEffect,
        correction: Option<&DMatrix<f64>>,
        predicted: Option<&[Vec<f64>]>,
    ) -> Result<Trial> {
        let (model, effect, all) = screen::add_to(st, &best);
        let t = Instant::now();
        let fit = self.fit_trial(&model, &all, correction, predicted)?;
        st.simulations += fit.simulations;
        add_time(&mut st.timings, "fit", t);
        self.tolerated
            .borrow_mut()
            .extend(fit.failures.iter().cloned());
        for (name, secs) in fit.stages {
            *st.timings.entry(name.into()).or_insert(0.0) += secs;
        }
        let sim = resolved(
            &fit.model,
            self.rec.fs,
            self.settings,
            &self.prep.recon.states,
        );
        let (scored, n) = self.shoot(&fit.model, sim);
        st.simulations += n;
        Ok(Trial {
            best,
            effect,
            fit,
            sim,
            scored,
        })
    }
}

/// Whether the loop goes on.
pub(super) enum Next {
    /// Another round.
    Continue,
    /// The loop ends.
    Stop,
}

/// Round `index` of the loop (module docs).
pub(super) fn run(
    ctx: &Context<'_>,
    st: &mut State,
    index: usize,
    progress: &dyn Fn(&str),
) -> Result<Next> {
    let floor = ctx.settings.noise_floor();
    if let Some(error) = st.error.filter(|&e| e <= floor) {
        let decision = Decision::AtNoise { error, floor };
        st.rounds.push(Round::unfitted(decision, 0));
        return Ok(Next::Stop);
    }
    progress(&format!("trace, round {}", index + 1));
    let tr = trace_round(ctx, st, index);
    let screened = !tr.selected.is_empty();
    let pool = screen::pool(&tr, &st.added, ctx.located.as_ref());
    if pool.is_empty() {
        let reason = tr.stop_reason.clone();
        st.rounds
            .push(Round::unfitted(Decision::NothingPays { reason }, 0));
        return Ok(Next::Stop);
    }
    let (chosen, below, screen_sims) = screen::choose(ctx, st, pool, screened, &tr.stop_reason);
    st.simulations += screen_sims;
    let Some(chosen) = chosen else {
        let decision = Decision::ScreenedOut(below);
        st.rounds.push(Round::unfitted(decision, screen_sims));
        return Ok(Next::Stop);
    };
    progress(&format!("fit {}", chosen.best.label));
    let correction = hidden_correction(&chosen.best, &tr, &ctx.prep.recon.states);
    let trial = ctx.fit_scored(
        st,
        chosen.best,
        correction.as_ref(),
        chosen.predicted.as_deref(),
    )?;
    let fit_sims = trial.fit.simulations;
    let (trial, alternative) = if screened {
        alternative::try_cubic(ctx, st, trial, &tr.ranking, progress)?
    } else {
        (trial, None)
    };
    let judged = decide::judge(ctx, st, &trial, (!screened).then_some(below));
    st.rounds.push(Round {
        proposed: Some(trial.best.label.clone()),
        decision: judged.decision.clone(),
        fit: Some(trial.fit.note.clone()),
        alternative,
        simulations: fit_sims,
    });
    Ok(apply(st, trial, judged))
}

/// The trace of the current residual; the first round's ranking kept.
fn trace_round(ctx: &Context<'_>, st: &mut State, index: usize) -> TraceResult {
    let prep = ctx.prep;
    let exclude: Vec<_> = st
        .added
        .iter()
        .map(|a| a.effect.candidate.clone())
        .collect();
    let input = TraceInput {
        model: ctx.declared,
        sampled: &prep.sampled,
        cy: &ctx.cy,
        dy: &ctx.dy,
        measured: &ctx.measured,
        force_ext: &ctx.cmp().force,
        states: &prep.recon.states,
        identified_force: Some(&prep.recon.force),
        segment: prep.segment,
        baseline: st.baseline.as_ref(),
        exclude: &exclude,
        located: ctx.located.as_ref(),
    };
    let ts = ctx.settings.trace_settings();
    let t = Instant::now();
    let tr = trace::trace(&input, &ts);
    add_time(&mut st.timings, "trace", t);
    st.trace_simulations += tr.simulations;
    if index == 0 {
        st.ranking = tr.ranking.iter().take(10).cloned().collect();
    }
    tr
}

/// The effect's fit of the states along the hidden trajectories (2n × N).
fn hidden_correction(
    best: &RankedEffect,
    tr: &TraceResult,
    states: &DMatrix<f64>,
) -> Option<DMatrix<f64>> {
    (!best.hidden.is_empty()).then(|| {
        let mut d = DMatrix::zeros(states.nrows(), states.ncols());
        for (c, e) in best.hidden.iter().zip(&tr.hidden) {
            d += e * *c;
        }
        d
    })
}

/// Go on with the decision: a kept effect becomes part of the current
/// model; a withdrawn one ends the loop, with the effects refitted beside
/// it taken when they pay on their own.
fn apply(st: &mut State, trial: Trial, judged: decide::Judged) -> Next {
    let Trial {
        best,
        effect,
        fit,
        sim,
        scored,
    } = trial;
    if let Decision::Kept { before, after, .. } = judged.decision {
        let score = Score {
            residual_explained: best.residual_explained,
            bic_change: best.bic_change,
            force_explained: best.force_explained,
            error_before: before,
            error_after: after,
        };
        st.added.push(KeptEffect {
            effect,
            ranked: best,
            score,
        });
        st.fitted = fit.fitted;
        st.current = fit.model;
        st.error = scored.error;
        st.substeps = sim.substeps;
        st.baseline = scored.shot.as_ref().ok().map(|p| p.0.clone());
        st.scored = Some((scored.own, scored.shot));
        return Next::Continue;
    }
    if let Some((off, off_scored)) = judged.refit {
        st.fitted = fit.fitted;
        st.current = off;
        st.substeps = sim.substeps;
        st.scored = Some((off_scored.own, off_scored.shot));
    }
    Next::Stop
}
