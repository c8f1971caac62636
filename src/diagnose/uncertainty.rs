//! The effects found, as reported: fitted values, their standard errors
//! from measurement noise, and their values fitted on each quarter of the
//! fit's segments ([`joint::uncertainty`]).

use super::effects;
use super::errors::Comparison;
use super::fit::spread;
use super::outcome::{undetermined, EffectReport};
use super::state::{Context, KeptEffect, State};
use super::{joint, DiagnoseSettings};
use crate::integrate::SimSettings;
use crate::model::Model;
use crate::trace::EffectKind;
use crate::update::optimize::FitSettings;
use crate::update::shooting::Segment;
use std::collections::BTreeMap;

/// The fit's segments are cut into this many runs of consecutive segments
/// (quarters of the record) for the spread of the parameters across the
/// record ([`EffectReport::group_estimates`]).
pub const SPREAD_GROUPS: usize = 4;

/// Per (effect, parameter) index: the standard error, and the values
/// fitted on each group of segments.
type Spreads = BTreeMap<(usize, usize), (f64, Vec<f64>)>;

/// Effect reports with fitted values and standard errors: from the joint
/// Jacobian of the fit's multiple-shooting residual in the parameters and
/// start states when the fit's segments are given (the states as nuisance
/// parameters), else from the parameter Jacobian with the reconstructed
/// start states.
pub(super) fn report_effects(
    ctx: &Context<'_>,
    st: &mut State,
    sim: SimSettings,
) -> Vec<EffectReport> {
    let (model, added) = (&st.current, &st.added);
    let fitted = st.fitted.as_ref();
    let ses = standard_errors(ctx, (model, added), sim, fitted, &mut st.simulations);
    added
        .iter()
        .enumerate()
        .map(|(ei, k)| {
            let (e, r, score) = (&k.effect, &k.ranked, &k.score);
            let vals = effects::values(model, e);
            let mut std_errors = BTreeMap::new();
            let mut group_estimates = BTreeMap::new();
            // a stiffness change is reported relative to the nominal spring
            let relative = |v: f64| match e.candidate.kind {
                EffectKind::Stiffness if e.nominal != 0.0 => v / e.nominal,
                _ => v,
            };
            for (pi, (name, _)) in vals.iter().enumerate() {
                let got = ses.get(&(ei, pi));
                let se = got.map(|g| g.0).filter(|x| x.is_finite());
                std_errors.insert(name.clone(), se.map(relative));
                let groups: Vec<f64> = got.map_or(vec![], |g| g.1.clone());
                if !groups.is_empty() {
                    let change = |v: f64| match e.candidate.kind {
                        EffectKind::Stiffness if e.nominal != 0.0 => v / e.nominal - 1.0,
                        _ => v,
                    };
                    group_estimates.insert(name.clone(), groups.into_iter().map(change).collect());
                }
            }
            let parameters = vals.into_iter().collect();
            EffectReport {
                kind: e.candidate.kind,
                dofs: e.candidate.dofs.iter().map(|d| d + 1).collect(),
                label: e.label.clone(),
                undetermined: undetermined(&parameters, &std_errors),
                parameters,
                std_errors,
                group_estimates,
                traced: r.parameters.iter().cloned().collect(),
                score: score.clone(),
            }
        })
        .collect()
}

/// The standard error of each parameter, and its values fitted on each
/// quarter of the fit's segments (none without the fit's segments), by
/// (effect, parameter) index.
fn standard_errors(
    ctx: &Context<'_>,
    (model, added): (&Model, &[KeptEffect]),
    sim: SimSettings,
    fitted: Option<&(Vec<Segment>, SimSettings)>,
    sims: &mut usize,
) -> Spreads {
    let (cmp, settings): (&Comparison, &DiagnoseSettings) = (ctx.cmp(), ctx.settings);
    let mut ses: Spreads = BTreeMap::new();
    if added.is_empty() {
        return ses;
    }
    let mut params = vec![];
    let mut owner = vec![];
    for (ei, k) in added.iter().enumerate() {
        match effects::parameters(model, &k.effect) {
            Ok(ps) => {
                // its damping nuisance parameters first, never reported
                let nuis = k.effect.nuisance.len();
                for (pi, p) in ps.into_iter().enumerate() {
                    params.push(p);
                    owner.push((ei, pi.checked_sub(nuis).unwrap_or(usize::MAX - pi)));
                }
            }
            Err(e) => ctx.tolerate(
                &format!("standard errors of {}", k.effect.label),
                e,
                "none reported",
            ),
        }
    }
    // with the fit's segments and start states: the start states are
    // nuisance parameters of the same fit ([`joint::std_errors`])
    let joint = fitted.and_then(|(segs, fsim)| {
        let mut problem = cmp.problem(model, segs.clone(), *fsim);
        problem.parameters = params.clone();
        *sims += segs.len();
        let x = vec![0.0; problem.parameters.len()];
        joint::uncertainty(&problem, &x, settings.noise.level, SPREAD_GROUPS)
    });
    if let Some(u) = joint {
        for (k, v) in u.std_errors.into_iter().enumerate() {
            if let Some(&o) = owner.get(k) {
                let groups = u.groups.iter().filter_map(|g| g.get(k).copied()).collect();
                ses.insert(o, (v, groups));
            }
        }
        return ses;
    }
    let segs = spread(&cmp.segments, settings.segments.fit_segments);
    let mut problem = cmp.problem(model, segs, sim);
    problem.parameters = params;
    let fs_ = FitSettings {
        max_iterations: 1,
        ..settings.fit_settings()
    };
    if fitted.is_some() {
        ctx.tolerate(
            "standard errors with the start states as nuisance parameters",
            "a simulation failed or the Schur complement is singular",
            "from the parameter Jacobian at the reconstructed start states",
        );
    }
    match crate::update::fit(&problem, &fs_) {
        Err(e) => ctx.tolerate(
            "standard errors from the parameter Jacobian",
            e,
            "none reported",
        ),
        Ok(r) => {
            *sims += r.simulations;
            if let Some(id) = &r.identifiability {
                for (k, pid) in id.parameters.iter().enumerate() {
                    if let Some(&o) = owner.get(k) {
                        ses.insert(o, (pid.std_value, vec![]));
                    }
                }
            }
        }
    }
    ses
}
