//! The screen: which candidate of a trace round is fitted.
//!
//! The trace's screen ([`crate::trace`]) proposes at most one effect. When
//! it proposes none after a first effect was found, two candidates below
//! it are still considered: a change linear in the state along the
//! located force direction (the *companion*: a nonlinear effect's fit
//! absorbs a linear change at the same place, so the screen, run after
//! that fit, cannot see it), then the best remaining candidate that lowers
//! the BIC (the screen's regression on the linear model's states can
//! underrate a second effect). Each is fitted only when the joint
//! linearization at the current fit ([`joint::predicted_gain`]) predicts
//! it removes enough of the fit cost.

use super::effects::{self, AddedEffect};
use super::errors::Comparison;
use super::joint;
use super::outcome::BelowScreen;
use super::state::{add_time, add_to, Context, KeptEffect, State};
use super::DiagnoseSettings;
use crate::error::Result;
use crate::integrate::SimSettings;
use crate::model::Model;
use crate::trace::{self, EffectKind, RankedEffect, TraceResult};
use crate::update::param::Parameter;
use crate::update::shooting::Segment;
use nalgebra::DMatrix;
use std::time::Instant;

/// A candidate chosen for the fit.
pub(super) struct Chosen {
    /// The candidate.
    pub best: RankedEffect,
    /// Start values from the joint linearization's step (below the screen).
    pub predicted: Option<Vec<Vec<f64>>>,
    /// The candidate's own parameters at the linearization's step, when
    /// the step leaves the box the fit's bounds set around the traced
    /// values: the fit starts there and its bounds follow ([`Recentred`]).
    pub start: Option<Vec<f64>>,
}

/// The candidates of a round, in the order they are tried: the one the
/// trace's screen selected, else the companion and the best remaining one
/// that lowers the BIC (module docs). In the first round that one is
/// tried only with the model `far` from the noise, and only when
/// nonlinear: a declared linear part that is off (damping twice the
/// declared, springs a few per cent away) spreads residual over every
/// candidate, and a localized effect's share can fall under the screen's
/// 5 % while the model is far from the record (a bumper seen from three
/// sensors: 4.4 % of the residual at 70 % error). It is fitted and judged
/// as any candidate below the screen ([`super::decide`]: half of the
/// squared error above the noise); a change linear in the state is left
/// to the calibration there.
pub(super) fn pool(
    tr: &TraceResult,
    added: &[KeptEffect],
    located: Option<&DMatrix<f64>>,
    far: bool,
) -> Vec<RankedEffect> {
    if let Some(s) = tr.selected.first() {
        return vec![s.clone()];
    }
    let mut pool: Vec<RankedEffect> = companion(tr, added, located).into_iter().collect();
    let first = added.is_empty();
    if !first || far {
        let next = tr.ranking.iter().find(|e| {
            e.bic_change < 0.0
                && !(first && e.candidate.kind.linear_in_state())
                && !pool.iter().any(|p| p.candidate == e.candidate)
        });
        pool.extend(next.cloned());
    }
    pool
}

/// A change linear in the state along the located directions, once a
/// nonlinear effect was found: fitted once below the screen, jointly with
/// the effects found (a bumper's gap and penalty stiffness trade against a
/// softer spring beside it); the fit decides whether it pays. (A damping
/// change acts along no single direction.)
fn companion(
    tr: &TraceResult,
    added: &[KeptEffect],
    located: Option<&DMatrix<f64>>,
) -> Option<RankedEffect> {
    let dirs = located.filter(|d| d.ncols() > 0)?;
    if added
        .iter()
        .all(|a| a.effect.candidate.kind.linear_in_state())
    {
        return None;
    }
    tr.ranking
        .iter()
        .find(|e| e.candidate.kind.linear_in_state() && trace::acts_along(&e.candidate, dirs))
        .cloned()
}

/// The first candidate of `pool` that passes the screen (every one when
/// the trace selected it, `screened`), what the screen turned away, and
/// the simulations spent.
pub(super) fn choose(
    ctx: &Context<'_>,
    st: &mut State,
    pool: Vec<RankedEffect>,
    screened: bool,
    trace_reason: &str,
) -> (Option<Chosen>, BelowScreen, usize) {
    let mut below = BelowScreen {
        trace: trace_reason.to_string(),
        screened_out: vec![],
        screen: companion_screen(st.error, ctx.settings),
    };
    let mut sims = 0;
    for best in pool {
        let (model, eff, all) = add_to(st, &best);
        let mut predicted = None;
        let mut start = None;
        // (a spring to ground on a free-free model is judged on states
        // reconstructed with it, [`super::prepare::rescore_prep`]:
        // linearized on the declared model's reconstruction its gain is
        // not seen, and with modal damping its derivative at zero is
        // infinite; the fit decides)
        let own = model.has_ground_spring()
            && !st.current.has_ground_spring()
            && !ctx.declared.has_ground_spring();
        if !screened && !own {
            if let Some((segs, sim)) = st.fitted.as_ref() {
                let t = Instant::now();
                let strides = &ctx.settings.screen.gn_strides;
                let gain = companion_gain(&model, &all, ctx.cmp(), (segs, *sim), strides);
                let p = gain.unwrap_or_else(|e| {
                    let step = format!("predicted gain of {}", best.label);
                    ctx.tolerate(&step, e, "fitted without a predicted gain");
                    Predicted::default()
                });
                let g = p.gain;
                sims += p.simulations;
                predicted = p.at;
                start = p.start;
                add_time(&mut st.timings, "fit", t);
                let screen = with_damping_freed(&eff, below.screen, st, ctx);
                if let Some(g) = g.filter(|&g| g < screen) {
                    below.screened_out.push((best.label.clone(), g));
                    continue;
                }
                // fitted whatever its prediction (the report says so)
                if screen == 0.0 {
                    below.screen = 0.0;
                }
            }
        }
        let chosen = Chosen {
            best,
            predicted,
            start,
        };
        return (Some(chosen), below, sims);
    }
    (None, below, sims)
}

/// The screen of a candidate below the trace's: `screen`, or
/// [`super::settings::ScreenSettings::companion_screen_far`] when it is
/// lower for a dissipative law fitted with the model's damping freed
/// beside it ([`AddedEffect::nuisance`]); none at all for a dissipative
/// law with the damping free beside it (its nuisance parameters, or a
/// damping change found before it) while the multiple-shooting error is
/// above [`super::settings::ScreenSettings::dissipative_far`] × the noise
/// measured on the record. The joint linearization is taken at zero
/// strength, where a friction law's derivative is a viscous-like force
/// that the free damping takes up; what a finite level adds (the masses
/// sticking) it does not see. On a record of a bumper 7→6 with 0.3 N of
/// friction on every mass, after the contact on a damping the refinement
/// had raised to take the friction (modal ratios +136 to +253 % against
/// +100 %, error 3.3 % at 1.5 % measured noise), the friction on every
/// mass was predicted to remove 2.5 % of the fit cost; fitted, it takes
/// the error to 2.5 % and the refinement beside it to 0.99 %. The cost is
/// one fit a round, in a loop of at most
/// [`super::settings::ScreenSettings::max_effects`] rounds, and a
/// candidate below the screen that is withdrawn ends the loop.
fn with_damping_freed(eff: &AddedEffect, screen: f64, st: &State, ctx: &Context<'_>) -> f64 {
    if !eff.candidate.kind.dissipative() {
        return screen;
    }
    let own = !eff.nuisance.is_empty();
    let beside = st
        .added
        .iter()
        .any(|a| a.effect.candidate.kind == EffectKind::Damping);
    let s = &ctx.settings.screen;
    let far = match (st.error, ctx.measured_noise) {
        (Some(e), Some(m)) => e > s.dissipative_far * m,
        _ => false,
    };
    if far && (own || beside) {
        0.0
    } else if own {
        screen.min(s.companion_screen_far)
    } else {
        screen
    }
}

/// The companion screen at multiple-shooting error `err`
/// ([`super::settings::ScreenSettings::companion_screen`]: lower far from
/// the noise floor).
fn companion_screen(err: Option<f64>, settings: &DiagnoseSettings) -> f64 {
    let s = &settings.screen;
    if err.is_some_and(|e| e > s.far_from_noise * settings.noise_floor()) {
        s.companion_screen_far
    } else {
        s.companion_screen
    }
}

/// What the joint linearization predicts for a candidate below the
/// screen.
#[derive(Default)]
struct Predicted {
    /// The fraction of the fit cost it is predicted to remove (None when a
    /// simulation failed).
    gain: Option<f64>,
    /// Simulations spent.
    simulations: usize,
    /// Every parameter's value at the strides of the step, clamped to the
    /// fit's bounds (starts for the fit).
    at: Option<Vec<Vec<f64>>>,
    /// The candidate's own parameters at one step, unclamped, when the
    /// step leaves their bounds ([`recentred`]).
    start: Option<Vec<f64>>,
}

/// The fraction of the fit cost a candidate below the screen (the last
/// effect of `all` on `trial`, taken at no change: a spring at its declared
/// stiffness, a nonlinear element at zero strength with its traced gap) is
/// predicted to remove at the current fit
/// ([`joint::predicted_gain`] on the fit segments `segs`, with the fit's
/// sub-steps), and the simulations spent; with the parameter values at
/// `strides` multiples of the linearization's step (starts for the fit);
/// None when a simulation fails; Err when the effects' parameters cannot
/// be set up.
fn companion_gain(
    trial: &Model,
    all: &[AddedEffect],
    cmp: &Comparison,
    (segs, sim): (&[Segment], SimSettings),
    strides: &[f64],
) -> Result<Predicted> {
    let mut params = vec![];
    for e in all {
        params.extend(effects::parameters(trial, e)?);
    }
    let Some(last) = all.last() else {
        return Ok(Predicted::default());
    };
    // the candidate's own parameters (the last ones); its damping
    // nuisance parameters before them are free with and without it
    let extra = last.targets.len();
    let mut problem = cmp.problem(trial, segs.to_vec(), sim);
    problem.parameters = params;
    // linearized where the candidate is no change at all (the traced
    // value is only the screen's estimate)
    let mut x = problem.x_start();
    let zero = match last.candidate.kind {
        EffectKind::GroundSpring => 0.0,
        _ => last.nominal,
    };
    for (xi, p) in x.iter_mut().zip(&problem.parameters).rev().take(extra) {
        // a contact is switched off by its stiffness; its gap stays where
        // the trace put it
        if !matches!(
            p.target,
            crate::update::Target::ContactGap(_) | crate::update::Target::ClearanceGap(_)
        ) {
            *xi = p.to_x(zero);
        }
    }
    match joint::predicted_gain(&problem, &x, extra) {
        Some((g, dx, n)) => {
            let (lo, hi) = problem.x_bounds();
            let own = last.targets.len();
            let start = recentred(&problem.parameters, (&x, &dx), (&lo, &hi), own);
            // the Gauss–Newton step's parameter values: a start for the
            // fit (the trace's value of a companion comes from a
            // regression on states the effects found already absorb it in)
            let at = strides
                .iter()
                .map(|f| {
                    problem
                        .parameters
                        .iter()
                        .enumerate()
                        .map(|(i, p)| p.from_x((x[i] + f * dx[i]).clamp(lo[i], hi[i])))
                        .collect()
                })
                .collect();
            Ok(Predicted {
                gain: Some(g),
                simulations: n,
                at: Some(at),
                start,
            })
        }
        None => Ok(Predicted::default()),
    }
}

/// The last `own` parameters (the candidate's) at one linearization step
/// `dx` from `x`, when that step takes one of them beyond its bounds and
/// each lands on a value the fit can start from (finite, on the
/// physical side of its floor and not zero: the fit's bounds are
/// relative to it). The bounds are set around the traced values, and the
/// trace's regression on the linear model's states can underrate an
/// effect whose share the linear part took (a friction's share of the
/// dissipation in a damping calibrated beside it: traced at 8 mN, the
/// step asks for 0.09 N and the bound at 11 × the traced value holds it
/// at 0.091 N); starting there moves the box with it. None when the step
/// stays inside.
fn recentred(
    params: &[Parameter],
    (x, dx): (&[f64], &[f64]),
    (lo, hi): (&[f64], &[f64]),
    own: usize,
) -> Option<Vec<f64>> {
    let np = params.len();
    let first = np.checked_sub(own)?;
    let mut out = Vec::with_capacity(own);
    let mut leaves = false;
    for i in first..np {
        let p = &params[i];
        let xi = x[i] + dx[i];
        leaves |= xi > hi[i] || xi < lo[i];
        let v = p.from_x(xi);
        let floor = p.target.physical_floor();
        if !v.is_finite() || v == 0.0 || floor.is_some_and(|f| v <= f) {
            return None;
        }
        out.push(v);
    }
    leaves.then_some(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::Friction;
    use crate::trace::{Candidate, EffectKind};
    use crate::update::param::Target;

    /// The first round's ranking of the bumper seen from sensors 1, 5, 6
    /// on a declared model with half the damping (seed 71129): nothing
    /// passes the 5 % screen. Far from the noise the best nonlinear
    /// candidate that lowers the BIC is tried (the contact, not the damping
    /// change ranked above it, nor the friction with a BIC that rises);
    /// near the noise, or after an effect was found, it is not.
    #[test]
    fn far_from_the_noise_the_first_round_tries_the_best_nonlinear_candidate() {
        let ranked = |kind, dofs: Vec<usize>, explained: f64, bic: f64| {
            let mut r = RankedEffect::for_test(Candidate::new(kind, dofs), &[("p", 1.0)]);
            (r.residual_explained, r.bic_change) = (explained, bic);
            r
        };
        let tr = TraceResult {
            ranking: vec![
                ranked(EffectKind::Friction, vec![0, 1, 2], 0.05, 12.0),
                ranked(EffectKind::Damping, vec![], 0.037, -460.1),
                ranked(EffectKind::Contact, vec![4, 5], 0.044, -537.4),
                ranked(EffectKind::RelativeFriction, vec![2, 3], 0.034, -414.4),
            ],
            selected: vec![],
            rss_history: vec![],
            stop_reason: "best remaining candidate removes 4.4 %".into(),
            simulations: 0,
            hidden: vec![],
        };
        let far = pool(&tr, &[], None, true);
        assert_eq!(far.len(), 1);
        assert_eq!(far[0].candidate.kind, EffectKind::Contact);
        assert!(pool(&tr, &[], None, false).is_empty());
    }

    /// A friction level traced at 8 mN with the fit's bounds (−99 %,
    /// +1000 %) around it: a step to 0.09 N leaves them and is the start;
    /// a step inside them, or to a negative level, is not.
    #[test]
    fn a_step_beyond_the_bounds_is_the_start_and_one_inside_is_not() {
        let p = concat!(env!("CARGO_MANIFEST_DIR"), "/data/lanl8dof.toml");
        let mut model = Model::from_file(std::path::Path::new(p)).unwrap();
        model.frictions = vec![Friction {
            dof: 1,
            level: 0.008,
            velocity: 1e-3,
        }];
        let par = Parameter::relative(&model, Target::FrictionLevel(0))
            .unwrap()
            .with_relative_bounds(-0.99, 10.0);
        let params = [par.clone()];
        let (lo, hi) = (vec![par.to_x(par.lower)], vec![par.to_x(par.upper)]);
        // linearized at no friction
        let x = vec![par.to_x(0.0)];
        let step = |v: f64| vec![par.to_x(v) - x[0]];
        let got = recentred(&params, (&x, &step(0.09)), (&lo, &hi), 1).unwrap();
        assert!((got[0] - 0.09).abs() < 1e-12, "{got:?}");
        assert!(recentred(&params, (&x, &step(0.05)), (&lo, &hi), 1).is_none());
        assert!(recentred(&params, (&x, &step(-0.2)), (&lo, &hi), 1).is_none());
    }
}
