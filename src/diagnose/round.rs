//! One round of the loop: trace the residual to a candidate effect,
//! screen it, fit it (and another law in its place when it leaves the
//! error far from the noise: [`super::alternative`]), decide whether it
//! stays.

use super::alternative::alternative_law;
use super::decide;
use super::effects::AddedEffect;
use super::fit::{fit_effects, EffectFit};
use super::outcome::{AlternativeTried, Decision, Round, Score};
use super::screen;
use super::state::{add_time, add_to, Context, KeptEffect, State, Trial};
use super::substeps::resolved;
use crate::error::Result;
use crate::model::Model;
use crate::trace::{self, EffectKind, RankedEffect, TraceInput, TraceResult};
use crate::update::Segment;
use nalgebra::DMatrix;
use std::time::Instant;

/// Fit the effects `all` on `trial`: a trial with a spring to ground
/// is fitted from states reconstructed with its own linear part (as it
/// is scored), not from the declared reconstruction corrected along
/// the hidden trajectories; otherwise the start states fitted for the
/// current model (`fitted`) are offered to the fit.
fn fit_trial(
    ctx: &Context<'_>,
    trial: &Model,
    all: &[AddedEffect],
    (correction, fitted): (Option<&DMatrix<f64>>, Option<&[Segment]>),
    predicted: Option<&[Vec<f64>]>,
) -> Result<EffectFit> {
    let own = ctx.own_prep(trial, ctx.rec);
    let (cmp, states, correction, fitted) = match &own {
        Some(o) => (&o.comparison, &o.recon.states, None, None),
        None => (ctx.cmp(), &ctx.prep.recon.states, correction, fitted),
    };
    let fs = ctx.rec.fs;
    fit_effects(
        trial,
        all,
        cmp,
        states,
        (correction, fitted),
        predicted,
        fs,
        ctx.settings,
    )
}

/// Add `best` to the current model (its own parameters at `start` when
/// given, else at the traced values), fit every added effect and score
/// the fitted model.
pub(super) fn fit_scored(
    ctx: &Context<'_>,
    st: &mut State,
    best: RankedEffect,
    correction: Option<&DMatrix<f64>>,
    (predicted, start): (Option<&[Vec<f64>]>, Option<&[f64]>),
) -> Result<Trial> {
    let (mut model, effect, all) = add_to(st, &best);
    for (t, &v) in effect.targets.iter().zip(start.unwrap_or_default()) {
        t.set(&mut model, v);
    }
    let t = Instant::now();
    let fitted = st.fitted.as_ref().map(|(s, _)| s.as_slice());
    let fit = fit_trial(ctx, &model, &all, (correction, fitted), predicted)?;
    st.simulations += fit.simulations;
    add_time(&mut st.timings, "fit", t);
    ctx.tolerated
        .borrow_mut()
        .extend(fit.failures.iter().cloned());
    for (name, secs) in fit.stages {
        *st.timings.entry(name.into()).or_insert(0.0) += secs;
    }
    let sim = resolved(&fit.model, ctx.rec.fs, ctx.settings, &ctx.prep.recon.states);
    let (scored, n) = ctx.shoot(&fit.model, sim);
    st.simulations += n;
    Ok(Trial {
        best,
        effect,
        fit,
        sim,
        scored,
    })
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
    let floor = stop_floor(ctx);
    if let Some(error) = st.error.filter(|&e| e <= floor) {
        let decision = Decision::AtNoise { error, floor };
        st.rounds.push(Round::unfitted(decision, 0));
        return Ok(Next::Stop);
    }
    progress(&format!("trace, round {}", index + 1));
    let tr = trace_round(ctx, st, index);
    // a law against ground at a located ground DOF of a free-free model,
    // screened on the identified force with the rigid-body wander
    // (`super::ground`), fitted ahead of the trace's choice; the trace's
    // choice follows when it does not pay
    if let Some(g) = super::ground::propose(ctx, st) {
        if let Next::Continue = ground_round(ctx, st, g, progress)? {
            return Ok(Next::Continue);
        }
    }
    let screened = !tr.selected.is_empty();
    let far = st
        .error
        .is_some_and(|e| e > ctx.settings.screen.far_from_noise * floor);
    let pool = screen::pool(&tr, &st.added, ctx.located.as_ref(), far);
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
    let trial = fit_scored(
        ctx,
        st,
        chosen.best,
        correction.as_ref(),
        (chosen.predicted.as_deref(), chosen.start.as_deref()),
    )?;
    let fit_sims = trial.fit.simulations;
    let (trial, alternative) = if screened {
        try_alternative(ctx, st, trial, &tr.ranking, progress)?
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

/// The multiple-shooting error at or below which the loop seeks no
/// further effect: the noise floor, or [`super::NoiseSettings::stop_multiple`]
/// × the level measured on the record when that is lower (a small effect
/// above the measured noise is not taken for noise).
fn stop_floor(ctx: &Context<'_>) -> f64 {
    let floor = ctx.settings.noise_floor();
    let stop = ctx.settings.noise.stop_multiple;
    ctx.measured_noise.map_or(floor, |m| floor.min(stop * m))
}

/// Fit the law against ground `g` ([`super::ground::propose`]) and keep
/// it when it pays (`Continue`); a withdrawn one is recorded as a round
/// and leaves the model as it was (`Stop`: the trace's choice is tried).
fn ground_round(
    ctx: &Context<'_>,
    st: &mut State,
    g: RankedEffect,
    progress: &dyn Fn(&str),
) -> Result<Next> {
    progress(&format!("fit {} (against ground)", g.label));
    let trial = fit_scored(ctx, st, g, None, (None, None))?;
    let judged = decide::judge(ctx, st, &trial, None);
    let kept = matches!(judged.decision, Decision::Kept { .. });
    st.rounds.push(Round {
        proposed: Some(trial.best.label.clone()),
        decision: judged.decision.clone(),
        fit: Some(trial.fit.note.clone()),
        alternative: None,
        simulations: trial.fit.simulations,
    });
    if kept {
        return Ok(apply(st, trial, judged));
    }
    Ok(Next::Stop)
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

/// Try another law in place of the one fitted ([`super::alternative`]:
/// the cubic spring in place of a large stiffness change, …) when the fit
/// leaves the error far from the noise; returns the trial that scores
/// better and what was tried, if anything.
pub(super) fn try_alternative(
    ctx: &Context<'_>,
    st: &mut State,
    trial: Trial,
    ranking: &[RankedEffect],
    progress: &dyn Fn(&str),
) -> Result<(Trial, Option<AlternativeTried>)> {
    let s = &ctx.settings.screen;
    let (best, eff, fitted) = (&trial.best, &trial.effect, &trial.fit.model);
    // the other damper law costs one fit of one coefficient: tried whenever
    // the loop would go on
    let damper = matches!(
        best.candidate.kind,
        EffectKind::QuadraticDamping | EffectKind::CubicDamping
    );
    let floor = if damper {
        stop_floor(ctx)
    } else {
        s.alternative_floor * ctx.settings.noise_floor()
    };
    let far = trial.scored.error.is_some_and(|e| e > floor);
    // a spring to ground: its own reconstruction (the declared free-free
    // one wanders)
    let own = (far && best.candidate.kind == EffectKind::GroundSpring)
        .then(|| ctx.own_prep(fitted, ctx.rec))
        .flatten();
    let states = own
        .as_ref()
        .map_or(&ctx.prep.recon.states, |o| &o.recon.states);
    let alt = match alternative_law(best, eff, fitted, ranking, states, s.alternative_change) {
        Some(alt) if far => alt,
        _ => return Ok((trial, None)),
    };
    progress(&format!("fit {} (alternative)", alt.label));
    let start = alt.parameters.clone();
    let second = fit_scored(ctx, st, alt, None, (None, None))?;
    let (e1, e2) = (trial.scored.error, second.scored.error);
    let taken = e2.is_some_and(|e2| e1.is_none_or(|e| e2 < e));
    let tried = AlternativeTried {
        label: second.best.label.clone(),
        start,
        error: e2,
        taken,
        instead_of: (trial.best.label.clone(), e1),
    };
    Ok((if taken { second } else { trial }, Some(tried)))
}
