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
use crate::record::Quantity;
use crate::trace::EffectKind;
use crate::update::optimize::FitSettings;
use crate::update::shooting::Segment;
use crate::update::Observation;
use nalgebra::DVector;
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
    let observations = &ctx.cmp().observations;
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
            let mut undetermined = undetermined(&parameters, &std_errors);
            let unobservable: Vec<String> = (e.candidate.kind == EffectKind::Contact
                && gap_unobservable(model, &e.candidate.dofs, observations))
            .then(|| "gap".to_string())
            .into_iter()
            .collect();
            for u in &unobservable {
                if !undetermined.contains(u) {
                    undetermined.push(u.clone());
                }
            }
            EffectReport {
                kind: e.candidate.kind,
                dofs: e.candidate.dofs.iter().map(|d| d + 1).collect(),
                label: e.label.clone(),
                undetermined,
                unobservable,
                parameters,
                std_errors,
                group_estimates,
                traced: r.parameters.iter().cloned().collect(),
                score: score.clone(),
            }
        })
        .collect()
}

/// Whether the gap of a contact against ground at `dofs` (one DOF, from 0)
/// trades exactly with the structure's absolute position: the linear
/// part has a zero-stiffness motion `φ` that moves the DOF (a free
/// structure's rigid-body translation), and nothing the records see
/// depends on where along `φ` the structure sits — no displacement
/// channel and no position-dependent element but the contact moved by
/// it (a law against ground at a DOF `φ` moves, a law between DOFs `φ`
/// moves apart). A clearance against ground is not such a law: its
/// dead zone is centred on the position zero, so it ties the position. Shifting every segment's start along `φ` by `δ` and the gap by
/// `δ φ_d` then leaves every prediction unchanged, whatever the noise
/// says about the gap's standard error.
pub fn gap_unobservable(model: &Model, dofs: &[usize], observations: &[Observation]) -> bool {
    let &[d] = dofs else { return false };
    let Some(phi) = zero_stiffness_motion(model, d) else {
        return false;
    };
    let tol = 1e-6 * phi.amax();
    let moves = |q: usize| phi[q].abs() > tol;
    if observations
        .iter()
        .any(|o| o.quantity == Quantity::Disp && moves(o.dof - 1))
    {
        return false;
    }
    let seen = |ds: &[usize]| match *ds {
        [i] => moves(i - 1),
        [i, j] => (phi[i - 1] - phi[j - 1]).abs() > tol,
        _ => true,
    };
    let mut laws: Vec<&[usize]> = vec![];
    laws.extend(model.contacts.iter().map(|c| c.dofs.as_slice()));
    laws.extend(model.cubics.iter().map(|c| c.dofs.as_slice()));
    laws.extend(model.quadratics.iter().map(|c| c.dofs.as_slice()));
    laws.extend(model.clearances.iter().map(|c| c.dofs.as_slice()));
    laws.extend(model.jenkins.iter().map(|c| c.dofs.as_slice()));
    laws.extend(model.saturating.iter().map(|c| c.dofs.as_slice()));
    // the law itself is the one element allowed to see the motion
    model.contacts.iter().any(|c| c.dofs == [d + 1])
        && laws.iter().filter(|ds| seen(ds)).count() == 1
}

/// The zero-stiffness motion of `model`'s linear part closest to moving
/// DOF `d` alone (from 0): `e_d` projected on the null space of `K`
/// (eigenvalues below 1e-10 of the largest); `None` when `K` has no null
/// space or it does not move `d`.
fn zero_stiffness_motion(model: &Model, d: usize) -> Option<DVector<f64>> {
    let k = model.stiffness_matrix();
    if d >= k.nrows() {
        return None;
    }
    let n = k.nrows();
    let eig = k.symmetric_eigen();
    let top = eig.eigenvalues.amax();
    if !(top > 0.0) {
        return None;
    }
    let mut phi = DVector::zeros(n);
    for (r, &lam) in eig.eigenvalues.iter().enumerate() {
        if lam.abs() <= 1e-10 * top {
            let v = eig.eigenvectors.column(r);
            phi.axpy(v[d], &v, 1.0);
        }
    }
    (phi[d].abs() > 1e-6).then_some(phi)
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::{Contact, Cubic, Spring};

    fn accel(dof: usize) -> Observation {
        Observation {
            quantity: Quantity::Accel,
            dof,
            weight: 1.0,
            data: vec![],
            point: None,
        }
    }

    /// Three masses in a chain, free-free, with a stop of mass 3 against
    /// ground.
    fn chain_with_stop() -> Model {
        let spring = |i: usize| Spring {
            name: Some(format!("k{i}")),
            dofs: vec![i, i + 1],
            stiffness: 5e4,
        };
        Model {
            masses: vec![0.5, 0.4, 0.4],
            springs: vec![spring(1), spring(2)],
            contacts: vec![Contact {
                dofs: vec![3],
                gap: 5e-4,
                stiffness: 5e5,
            }],
            ..Default::default()
        }
    }

    /// A stop against ground on a free chain seen by accelerometers: the
    /// gap trades with the rigid-body position; a ground spring, a
    /// displacement channel or a cubic spring to ground ties it, and a
    /// contact between two masses is not concerned.
    #[test]
    fn a_stop_against_ground_on_a_free_structure_has_an_unobservable_gap() {
        let obs: Vec<Observation> = (1..=3).map(accel).collect();
        let m = chain_with_stop();
        assert!(gap_unobservable(&m, &[2], &obs));
        assert!(!gap_unobservable(&m, &[1, 2], &obs));
        let mut disp = obs.clone();
        disp[0].quantity = Quantity::Disp;
        assert!(!gap_unobservable(&m, &[2], &disp));
        let mut grounded = m.clone();
        grounded.springs.push(Spring {
            name: Some("g".into()),
            dofs: vec![1],
            stiffness: 1e3,
        });
        assert!(!gap_unobservable(&grounded, &[2], &obs));
        let mut cubic = m.clone();
        cubic.cubics.push(Cubic {
            dofs: vec![1],
            k3: 1e11,
        });
        assert!(!gap_unobservable(&cubic, &[2], &obs));
        // a cubic between masses does not see a rigid translation
        let mut between = m;
        between.cubics.push(Cubic {
            dofs: vec![1, 2],
            k3: 1e11,
        });
        assert!(gap_unobservable(&between, &[2], &obs));
    }
}
