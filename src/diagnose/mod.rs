//! Close the loop: find the residual, trace it to the missing effect, add
//! it, fit it, and report the error before and after.
//!
//! [`diagnose`] runs these stages, in this order:
//!
//! 1. **Prepare** ([`prepare`]): check the record, choose the channels.
//! 2. **Locate** ([`locate`]): a greedy search for the few directions (a
//!    spring-joined pair, or one DOF to ground) along which an unknown
//!    force explains the measurements.
//! 3. **Identify** ([`lifted`]): the sub-sample ("lifted") smoother on the
//!    linear part of the declared model, an unknown force along the
//!    located directions (at every DOF when none dominates):
//!    reconstructed states and internal force; the segments of the
//!    multiple-shooting error cut where that force is quiet. A validation
//!    record is identified along the same directions.
//! 4. **Score before** ([`errors`]): the declared model's multiple-shooting
//!    error over short segments, each from its reconstructed start state
//!    refined for the model ([`starts`]; `relative_error`), and its
//!    open-loop simulation error (`simulation_error`).
//! 5. **Rounds** (`round`), while the error is above the noise floor and
//!    an effect pays, at most [`ScreenSettings::max_effects`]:
//!    - *against ground* ([`ground`]): on a free-free model with the force
//!      located at one DOF to ground, the laws there (cubic, stop, linear
//!      spring) fitted to the identified force with the rigid-body wander
//!      of the reconstruction; the best fitted first when it pays on the
//!      force, the trace's choice when its fit does not;
//!    - *trace* ([`crate::trace`]): rank the candidate effects by how much
//!      of the segment residual they remove (BIC, minimum gain), those
//!      acting along the located directions first;
//!    - *screen* (`screen`): the trace's choice, or below it a linear
//!      change beside a nonlinear effect found, fitted when the joint
//!      linearization at the current fit ([`joint::predicted_gain`])
//!      predicts enough gain;
//!    - *fit* (`fit`, `polish`): the effect added as a model element
//!      ([`effects`]), all added effects' parameters fitted jointly by the
//!      multiple-shooting error — a race of Levenberg–Marquardt starts
//!      (contact scans, cubic brackets), the best carried on with the
//!      segment start states fitted too ([`joint::fit`]); a large
//!      stiffness change far from the noise is also fitted as the cubic
//!      spring on its pair, a cubic as the clearance, a spring to ground
//!      as the cubic to ground, a damper as the other damper law
//!      (`alternative`);
//!    - *decide* (`decide`): keep the effect when it removes enough of the
//!      squared error, else withdraw it ([`Decision`]).
//! 6. **Score after**: the errors of the final model, the fitted values
//!    with their standard errors (`uncertainty`).
//! 7. **Validate** (`validation`): both models' errors on the validation
//!    record, and the non-parametric prediction.
//!
//! Every threshold is in [`DiagnoseSettings`] ([`settings`]). [`report`]
//! writes the result: report.json (with the settings), report.md, the
//! fitted model and the figures.

pub use crate::identify::{lifted, locate};

mod alternative;
pub mod calibrated;
pub mod comparison;
mod decide;
pub mod effects;
pub mod errors;
mod figures;
mod fit;
pub mod gap_search;
pub mod ground;
pub mod interface;
pub mod joint;
mod laws;
pub mod noise;
mod open_loop;
mod outcome;
mod polish;
pub mod prepare;
pub mod report;
mod round;
mod screen;
pub mod settings;
pub mod starts;
mod state;
mod substeps;
mod uncertainty;
mod validation;

pub use errors::{ChannelError, Comparison, ErrorSet, ErrorStatus, ShotError};
pub use outcome::{
    AlternativeTried, BelowScreen, Decision, Diagnosis, EffectReport, Round, Score,
    ToleratedFailure, Validation, WithdrawReason,
};
pub use prepare::{
    prepare, prepare_located, quiet_segments, reconstruct, Prepared, Reconstruction,
};
pub use settings::{
    DiagnoseSettings, FitGroup, LiftedGroup, LocateSettings, NoiseSettings, ScreenSettings,
    SegmentSettings, StartSettings, StatesSource, SubstepSettings, TraceGroup, ZeroStarts,
};
pub use substeps::auto_substeps;

use crate::error::Result;
use crate::integrate::SimSettings;
use crate::model::Model;
use crate::record::Record;
use nalgebra::DMatrix;
use round::Next;
use state::{add_time, Context, State};
use std::collections::BTreeMap;
use std::time::Instant;

/// An error with the facts when the declared model cannot be scored on
/// the record (a simulation failed, or an error is not finite): a
/// diagnosis would then compare nothing.
fn unscored(declared: &Model, rec: &Record, sim: SimSettings, before: &ErrorSet) -> Result<()> {
    if before.status.is_ok() {
        return Ok(());
    }
    let step = crate::integrate::Integrator::new(declared, rec.fs, sim)
        .map(|i| format!("; {}", i.describe_step()))
        .unwrap_or_default();
    Err(crate::error::TacitError::Numerical(format!(
        "the declared model {} cannot be scored on the record: {}{step}",
        declared.name, before.status
    )))
}

/// An error with the facts when an error set of the result is not finite
/// (`which`: the model and the record it was scored on): a verdict resting
/// on NaN errors would mean nothing, so no report is made.
fn finite_errors(which: &str, set: &ErrorSet) -> Result<()> {
    let parts = [&set.status.multiple_shooting, &set.status.open_loop];
    if !parts
        .iter()
        .any(|p| matches!(p, Some(ShotError::NotFinite)))
    {
        return Ok(());
    }
    Err(crate::error::TacitError::Numerical(format!(
        "the errors of {which} are not finite ({}): the verdict would rest on NaN, so no report is made",
        set.status
    )))
}

/// The fitted model's errors on the record and both models' on the
/// validation record, all finite ([`finite_errors`]).
pub(crate) fn finite_result(
    fitted: &Model,
    after: &ErrorSet,
    val: Option<&Validation>,
) -> Result<()> {
    finite_errors(
        &format!("the fitted model {} on the record", fitted.name),
        after,
    )?;
    if let Some(v) = val {
        finite_errors("the declared model on the validation record", &v.before)?;
        finite_errors(
            &format!("the fitted model {} on the validation record", fitted.name),
            &v.after,
        )?;
    }
    Ok(())
}

/// The validation record prepared by [`diagnose`] on the linear part of
/// `model` at `settings` (the settings it ran at), located along the
/// record's force directions (its [`Prepared::located`]): what
/// [`prepare_located`] gives for the same inputs, so a refinement of the
/// same linear part ([`calibrated`]) takes it instead of preparing it again.
#[derive(Debug, Clone)]
pub struct ValidationPrepared {
    /// The model diagnosed.
    pub model: Model,
    /// The settings the diagnosis ran at.
    pub settings: DiagnoseSettings,
    /// The prepared record.
    pub prepared: Prepared,
}

impl ValidationPrepared {
    /// The prepared record when it was prepared on `model` at `settings`.
    pub fn take_for(self, model: &Model, settings: &DiagnoseSettings) -> Option<Prepared> {
        (self.model == *model && self.settings == *settings).then_some(self.prepared)
    }
}

/// Run the diagnosis of `rec` with the `declared` model (module docs),
/// validated on `validation` when given; `progress` hears each stage.
pub fn diagnose(
    declared: &Model,
    rec: &Record,
    validation: Option<&Record>,
    sensors: Option<&[usize]>,
    settings: &DiagnoseSettings,
    progress: &dyn Fn(&str),
) -> Result<Diagnosis> {
    settings.validate()?;
    let t_all = Instant::now();
    let mut timings = BTreeMap::new();
    progress("identify");
    let prepare::Both {
        prep,
        vprep,
        noise,
        settings,
    } = prepare::both(declared, rec, validation, sensors, settings, &mut timings)?;
    let settings = &settings;
    // (the record's located directions are its `located` with the
    // lifted states alone)
    let validation_prepared = vprep
        .as_ref()
        .filter(|_| settings.states == StatesSource::Lifted)
        .map(|v| ValidationPrepared {
            model: declared.clone(),
            settings: settings.clone(),
            prepared: v.clone(),
        });
    let (cy, dy) = prep.sampled.outputs(&prep.channels)?;
    let ctx = Context {
        declared,
        rec,
        sensors,
        settings,
        prep: &prep,
        cy,
        dy,
        measured: prep.comparison.measured(),
        located: prep.located.as_ref().map(|l| l.matrix(declared.ndof())),
        tolerated: Default::default(),
        measured_noise: noise.as_ref().map(|n| n.level),
    };
    let sim0 = substeps::resolved(declared, rec.fs, settings, &prep.recon.states);
    progress("errors before");
    let t = Instant::now();
    let (before, pred_before) = ctx.cmp().errors(declared, sim0);
    unscored(declared, rec, sim0, &before)?;
    timings.insert("errors_before".into(), t.elapsed().as_secs_f64());
    let sims = errors::error_simulations(&before, ctx.cmp());
    let mut st = State::new(
        declared,
        &before,
        pred_before.as_ref(),
        sim0.substeps,
        sims,
        timings,
    );
    let t_loop = Instant::now();
    for index in 0..settings.screen.max_effects {
        if let Next::Stop = round::run(&ctx, &mut st, index, progress)? {
            break;
        }
    }
    add_time(&mut st.timings, "trace_and_fit", t_loop);
    progress("errors after");
    let t = Instant::now();
    let sim1 = SimSettings {
        substeps: st.substeps,
        ..Default::default()
    };
    // the validation record's scores do not depend on the record's: on
    // the pool beside them
    let val_in = match (vprep.as_ref(), validation) {
        (Some(v), Some(r)) => Some((v, ctx.own_prep(&st.current, r))),
        _ => None,
    };
    if val_in.is_some() {
        progress("validation");
    }
    let current = st.current.clone();
    let mut val_out = None;
    let (after, pred_after, effects) = rayon::in_place_scope(|s| {
        if let Some((v, own)) = val_in.as_ref() {
            let (declared, prep, out) = (ctx.declared, ctx.prep, &mut val_out);
            let q = &ctx.settings.fit.gap_quantiles;
            s.spawn(move |_| {
                let t = Instant::now();
                let mut count = 0;
                let r = validation::score(
                    declared,
                    &current,
                    v,
                    own.as_ref(),
                    prep,
                    ((sim0, sim1), q),
                    &mut count,
                );
                *out = Some((r, count, t.elapsed().as_secs_f64()));
            });
        }
        let r = score_after(&ctx, &mut st, (&before, &pred_before), sim1);
        add_time(&mut st.timings, "errors_after", t);
        r
    });
    let validation = match val_out {
        Some((r, count, secs)) => {
            st.simulations += count;
            st.timings.insert("validation".into(), secs);
            Some(r?)
        }
        None => None,
    };
    finite_result(&st.current, &after, validation.as_ref())?;
    st.timings
        .insert("total".into(), t_all.elapsed().as_secs_f64());
    let tolerated_failures = ctx.tolerated.into_inner();
    Ok(Diagnosis {
        verdict: verdict(&effects),
        before,
        after,
        validation,
        effects,
        ranking: st.ranking,
        rounds: st.rounds,
        substeps: (sim0.substeps, st.substeps),
        simulations: st.simulations,
        trace_simulations: st.trace_simulations,
        identification: format!(
            "full-order model, λ = {:.3e}: {}",
            prep.recon.lambda, prep.recon.status
        ),
        tolerated_failures,
        timings: st.timings,
        calibration: None,
        noise,
        model: st.current,
        added: st.added.iter().map(|a| a.effect.clone()).collect(),
        prepared: prep,
        predictions: (pred_before, pred_after),
        validation_prepared,
    })
}

/// The final model's errors (the last kept round shot it at these
/// settings already; with no effect kept it is the declared model, scored
/// before), its segment predictions and the effects' reports.
fn score_after(
    ctx: &Context<'_>,
    st: &mut State,
    (before, pred_before): (&ErrorSet, &Option<DMatrix<f64>>),
    sim1: SimSettings,
) -> (ErrorSet, Option<DMatrix<f64>>, Vec<EffectReport>) {
    let cmp = ctx.cmp();
    let (after, pred_after) = match st.scored.take() {
        Some((own, shot)) => {
            let own_cmp = own.as_ref().map_or(cmp, |p| &p.comparison);
            let r = own_cmp.errors_of(&st.current, sim1, shot);
            st.simulations += 1; // the open-loop run
            r
        }
        None => (before.clone(), pred_before.clone()),
    };
    let effects = uncertainty::report_effects(ctx, st, sim1);
    (after, pred_after, effects)
}

/// "no missing effect found", or the effects found.
pub fn verdict(effects: &[EffectReport]) -> String {
    if effects.is_empty() {
        "no missing effect found".to_string()
    } else {
        let labels: Vec<String> = effects.iter().map(|e| e.label.clone()).collect();
        format!("found {}", labels.join(", "))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn set(ms: Option<ShotError>, ol: Option<ShotError>) -> ErrorSet {
        ErrorSet {
            relative_error: Some(f64::NAN),
            simulation_error: Some(0.1),
            per_channel: vec![],
            rms_per_channel: Default::default(),
            status: ErrorStatus {
                multiple_shooting: ms,
                open_loop: ol,
            },
            starts: None,
            open_loop_prediction: None,
        }
    }

    #[test]
    fn non_finite_errors_after_the_fit_are_an_error_naming_model_and_record() {
        let e = finite_errors(
            "the fitted model m on the record",
            &set(Some(ShotError::NotFinite), None),
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("the errors of the fitted model m on the record are not finite (multiple shooting: the error is not finite")
                && e.contains("no report is made"),
            "{e}"
        );
        let e = finite_errors("x", &set(None, Some(ShotError::NotFinite))).unwrap_err();
        assert!(
            e.to_string()
                .contains("open-loop simulation: the error is not finite"),
            "{e}"
        );
        // a failed simulation is reported in the errors, not refused here
        let failed = set(None, Some(ShotError::Simulation("diverged".into())));
        assert!(finite_errors("x", &failed).is_ok());
        assert!(finite_errors("x", &set(None, None)).is_ok());
    }
}
