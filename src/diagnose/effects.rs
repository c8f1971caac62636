//! Turning a traced candidate into a model element and free parameters.

use crate::model::{
    Clearance, Contact, Cubic, CubicDamper, Damping, Friction, Model, Quadratic, QuadraticDamper,
    RelativeFriction, Spring,
};
use crate::trace::{Candidate, EffectKind, RankedEffect};
use crate::update::param::{Parameter, Target};
use crate::Result;
use serde::Serialize;

/// An effect added to the model, with where its parameters live.
#[derive(Debug, Clone, Serialize)]
pub struct AddedEffect {
    /// The traced candidate.
    pub candidate: Candidate,
    /// Label with DOFs from 1.
    pub label: String,
    /// Parameter targets in the model, in report order.
    #[serde(skip)]
    pub targets: Vec<Target>,
    /// Parameter names in the report (`gap`, `stiffness`, `level`, `k3`,
    /// `k2`, `c2`, `c3`, `delta`).
    pub names: Vec<String>,
    /// Regression estimates from the trace step (start of the fit).
    pub traced: Vec<f64>,
    /// Nominal stiffness of the changed spring (stiffness effects), N/m.
    pub nominal: f64,
    /// The model's viscous damping parameters freed beside a dissipative
    /// effect ([`damping_targets`]; empty for the others): fitted with it,
    /// never reported as its parameters, left as fitted when it is
    /// switched off.
    #[serde(skip)]
    pub nuisance: Vec<Target>,
}

/// Add the effect of `r` to `model` at its traced values; returns the
/// bookkeeping of its parameters.
pub fn add(model: &mut Model, r: &RankedEffect) -> AddedEffect {
    let c = &r.candidate;
    let one = |d: usize| d + 1;
    let val = |name: &str| {
        r.parameters
            .iter()
            .find(|p| p.0 == name)
            .map_or(0.0, |p| p.1)
    };
    let (targets, names, traced, nominal): (Vec<Target>, Vec<&str>, Vec<f64>, f64) = match c.kind {
        EffectKind::Contact => {
            model.contacts.push(Contact {
                dofs: c.dofs.iter().map(|&d| one(d)).collect(),
                gap: val("gap").max(0.0),
                stiffness: val("stiffness"),
            });
            let i = model.contacts.len() - 1;
            (
                vec![Target::ContactGap(i), Target::ContactStiffness(i)],
                vec!["gap", "stiffness"],
                vec![val("gap"), val("stiffness")],
                0.0,
            )
        }
        EffectKind::Friction => {
            let mut t = vec![];
            for &d in &c.dofs {
                model.frictions.push(Friction {
                    dof: one(d),
                    level: val("level"),
                    velocity: c.vreg,
                });
                t.push(model.frictions.len() - 1);
            }
            // one level per DOF (fitted separately; reported as their mean)
            (
                t.iter().map(|&i| Target::FrictionLevel(i)).collect(),
                vec!["level"; t.len()],
                vec![val("level"); t.len()],
                0.0,
            )
        }
        EffectKind::Cubic => {
            model.cubics.push(Cubic {
                dofs: c.dofs.iter().map(|&d| one(d)).collect(),
                k3: val("k3"),
            });
            (
                vec![Target::CubicK3(model.cubics.len() - 1)],
                vec!["k3"],
                vec![val("k3")],
                0.0,
            )
        }
        EffectKind::Stiffness => {
            let s = c.spring.unwrap_or(0);
            let k0 = model.springs[s].stiffness;
            model.springs[s].stiffness = k0 * (1.0 + val("delta"));
            (
                vec![Target::SpringStiffness(s)],
                vec!["delta"],
                vec![val("delta")],
                k0,
            )
        }
        EffectKind::GroundSpring => {
            model.push_ground_spring(Spring {
                dofs: vec![one(c.dofs[0])],
                stiffness: val("stiffness"),
                name: Some(format!("ground{}", one(c.dofs[0]))),
            });
            (
                vec![Target::SpringStiffness(model.springs.len() - 1)],
                vec!["stiffness"],
                vec![val("stiffness")],
                0.0,
            )
        }
        EffectKind::Quadratic
        | EffectKind::QuadraticDamping
        | EffectKind::CubicDamping
        | EffectKind::Clearance
        | EffectKind::RelativeFriction => add_element(model, c, &val),
        EffectKind::Damping => {
            let z0 = match &model.damping {
                Damping::Modal { ratio: Some(z), .. } => *z,
                _ => 0.0,
            };
            if let Damping::Modal { ratio: Some(z), .. } = &mut model.damping {
                *z = (z0 * (1.0 + val("delta"))).max(0.0);
            }
            (
                vec![Target::DampingRatio],
                vec!["delta"],
                vec![val("delta")],
                z0,
            )
        }
    };
    AddedEffect {
        candidate: c.clone(),
        label: model.label_at_points(&r.label, &c.dofs),
        targets,
        names: names.into_iter().map(String::from).collect(),
        traced,
        nominal,
        nuisance: vec![],
    }
}

/// The viscous damping parameters of `model` that a dissipative effect is
/// fitted beside (friction, relative friction, a nonlinear damper): each
/// mode's ratio of modal damping given per mode, the one ratio of modal
/// damping given as one, the non-zero Rayleigh coefficients; none without
/// damping. Friction's equivalent viscous damping differs from mode to
/// mode (largest on the lowest), so a damping calibrated on a record with
/// friction has absorbed part of it: with the damping held, the friction
/// is underrated (and the effect beside it misfit); freed, the two share
/// the dissipation by their shapes (amplitude-independent friction,
/// velocity-proportional damping).
pub fn damping_targets(model: &Model) -> Vec<Target> {
    match &model.damping {
        Damping::Modal { ratio: Some(z), .. } if *z > 0.0 => vec![Target::DampingRatio],
        Damping::Modal {
            ratio: None,
            ratios,
        } => (0..ratios.len())
            .filter(|&i| ratios[i] > 0.0)
            .map(Target::ModalRatio)
            .collect(),
        Damping::Rayleigh { alpha, beta } => [
            (*alpha, Target::RayleighAlpha),
            (*beta, Target::RayleighBeta),
        ]
        .into_iter()
        .filter(|(v, _)| *v > 0.0)
        .map(|(_, t)| t)
        .collect(),
        _ => vec![],
    }
}

/// Add the element of a quadratic spring, nonlinear damper, clearance or
/// friction between two DOFs at the traced values `val(name)`; its
/// targets, parameter names, traced values and nominal (0).
fn add_element(
    model: &mut Model,
    c: &Candidate,
    val: &dyn Fn(&str) -> f64,
) -> (Vec<Target>, Vec<&'static str>, Vec<f64>, f64) {
    let dofs: Vec<usize> = c.dofs.iter().map(|&d| d + 1).collect();
    let (targets, names) = match c.kind {
        EffectKind::Quadratic => {
            model.quadratics.push(Quadratic {
                dofs,
                k2: val("k2"),
            });
            (
                vec![Target::QuadraticK2(model.quadratics.len() - 1)],
                vec!["k2"],
            )
        }
        EffectKind::QuadraticDamping => {
            model.quadratic_dampers.push(QuadraticDamper {
                dofs,
                c2: val("c2"),
            });
            let i = model.quadratic_dampers.len() - 1;
            (vec![Target::DamperC2(i)], vec!["c2"])
        }
        EffectKind::CubicDamping => {
            model.cubic_dampers.push(CubicDamper {
                dofs,
                c3: val("c3"),
            });
            (
                vec![Target::DamperC3(model.cubic_dampers.len() - 1)],
                vec!["c3"],
            )
        }
        EffectKind::Clearance => {
            model.clearances.push(Clearance {
                dofs,
                gap: val("gap").max(0.0),
                stiffness: val("stiffness"),
            });
            let i = model.clearances.len() - 1;
            (
                vec![Target::ClearanceGap(i), Target::ClearanceStiffness(i)],
                vec!["gap", "stiffness"],
            )
        }
        _ => {
            model.relative_frictions.push(RelativeFriction {
                dofs,
                level: val("level"),
                velocity: c.vreg,
            });
            let i = model.relative_frictions.len() - 1;
            (vec![Target::RelativeFrictionLevel(i)], vec!["level"])
        }
    };
    let traced = names.iter().map(|n| val(n)).collect();
    (targets, names, traced, 0.0)
}

/// The clearance on the pair of a fitted cubic spring `best`, at its
/// traced values, when the trace ranked it and it lowers the information
/// criterion (the trace puts the cubic first when both pay,
/// `crate::trace`'s `smooth_first`; the loop fits this one when the
/// cubic's fit leaves the error far from the noise).
pub fn clearance_alternative(
    best: &RankedEffect,
    ranking: &[RankedEffect],
) -> Option<RankedEffect> {
    if best.candidate.dofs.len() != 2 {
        return None;
    }
    let pair = crate::trace::regress::sorted_pair(&best.candidate);
    ranking
        .iter()
        .find(|e| {
            e.candidate.kind == EffectKind::Clearance
                && crate::trace::regress::sorted_pair(&e.candidate) == pair
                && e.bic_change < 0.0
        })
        .cloned()
}

/// Free parameters of an added effect for the time-domain fit, at the
/// model's current values, with physical bounds: its damping nuisance
/// parameters first ([`AddedEffect::nuisance`], a damping ratio or
/// Rayleigh coefficient between 5 % and 10× its value), then its own (the
/// last effect's own parameters are the problem's last).
pub fn parameters(model: &Model, e: &AddedEffect) -> Result<Vec<Parameter>> {
    let nuisance = e
        .nuisance
        .iter()
        .map(|&t| Ok(Parameter::relative(model, t)?.with_relative_bounds(-0.95, 10.0)));
    let own = e.targets.iter().map(|&t| {
        let p = Parameter::relative(model, t)?;
        Ok(match t {
            Target::ContactGap(_) => p.with_relative_bounds(-0.8, 2.0),
            Target::ContactStiffness(_) => p.with_relative_bounds(-0.98, 50.0),
            Target::FrictionLevel(_) => p.with_relative_bounds(-0.99, 10.0),
            Target::CubicK3(_) => p.with_relative_bounds(-0.95, 10.0),
            Target::QuadraticK2(_) => p.with_relative_bounds(-0.95, 10.0),
            Target::DamperC2(_) | Target::DamperC3(_) => p.with_relative_bounds(-0.95, 10.0),
            Target::ClearanceGap(_) => p.with_relative_bounds(-0.8, 2.0),
            Target::ClearanceStiffness(_) => p.with_relative_bounds(-0.98, 50.0),
            Target::RelativeFrictionLevel(_) => p.with_relative_bounds(-0.99, 10.0),
            Target::SpringStiffness(_) => p.with_relative_bounds(-0.9, 10.0),
            _ => p,
        })
    });
    nuisance.chain(own).collect()
}

/// `model` with the effect `e` switched off (its other parameters and the
/// other effects as they are): a stiffness or damping change back to its
/// nominal value, a ground spring, friction level, spring or damper
/// coefficient or contact (clearance) stiffness to zero (a gap stays).
pub fn without(model: &Model, e: &AddedEffect) -> Model {
    let mut m = model.clone();
    // a spring to ground switched off gives the structure its rigid-body
    // mode back: the flexible modes keep their per-mode ratios
    let before = (e.candidate.kind == EffectKind::GroundSpring)
        .then(|| crate::model::flexible_frequencies(model).ok())
        .flatten();
    for t in &e.targets {
        let off = match (e.candidate.kind, t) {
            (_, Target::ContactGap(_) | Target::ClearanceGap(_)) => continue,
            (EffectKind::Stiffness | EffectKind::Damping, _) => e.nominal,
            _ => 0.0,
        };
        t.set(&mut m, off);
    }
    // a model whose modes cannot be computed is left as it is (the same
    // eigenproblem fails, and is reported, where it is simulated)
    if let Some(b) = before {
        crate::model::keep_modal_ratios(&mut m, &b).ok();
    }
    m
}

/// `model` without the effect `e`, which must be the last one added (its
/// elements are the last of their lists, so the others' targets stay
/// valid): its elements removed, a stiffness or damping change set back
/// to its nominal value.
pub fn remove(model: &Model, e: &AddedEffect) -> Model {
    let mut m = without(model, e);
    let mut targets = e.targets.clone();
    // from the highest index down
    targets.sort_by_key(|t| std::cmp::Reverse(index(t)));
    for t in targets {
        match (e.candidate.kind, t) {
            (EffectKind::Stiffness | EffectKind::Damping, _) => {}
            (EffectKind::GroundSpring, Target::SpringStiffness(i)) if i < m.springs.len() => {
                m.springs.remove(i);
            }
            (_, Target::ContactStiffness(i)) if i < m.contacts.len() => {
                m.contacts.remove(i);
            }
            (_, Target::FrictionLevel(i)) if i < m.frictions.len() => {
                m.frictions.remove(i);
            }
            (_, Target::CubicK3(i)) if i < m.cubics.len() => {
                m.cubics.remove(i);
            }
            (_, Target::QuadraticK2(i)) if i < m.quadratics.len() => {
                m.quadratics.remove(i);
            }
            (_, Target::DamperC2(i)) if i < m.quadratic_dampers.len() => {
                m.quadratic_dampers.remove(i);
            }
            (_, Target::DamperC3(i)) if i < m.cubic_dampers.len() => {
                m.cubic_dampers.remove(i);
            }
            (_, Target::ClearanceStiffness(i)) if i < m.clearances.len() => {
                m.clearances.remove(i);
            }
            (_, Target::RelativeFrictionLevel(i)) if i < m.relative_frictions.len() => {
                m.relative_frictions.remove(i);
            }
            _ => {}
        }
    }
    m
}

fn index(t: &Target) -> usize {
    match *t {
        Target::SpringStiffness(i)
        | Target::ContactStiffness(i)
        | Target::FrictionLevel(i)
        | Target::CubicK3(i)
        | Target::Mass(i)
        | Target::ContactGap(i)
        | Target::QuadraticK2(i)
        | Target::DamperC2(i)
        | Target::DamperC3(i)
        | Target::ClearanceGap(i)
        | Target::ClearanceStiffness(i)
        | Target::RelativeFrictionLevel(i) => i,
        _ => 0,
    }
}

/// Report values `(name, value)` of an effect's parameters from a fitted
/// model (SI; a stiffness or damping change as a relative change of the
/// nominal; friction at several DOFs as the mean level).
pub fn values(model: &Model, e: &AddedEffect) -> Vec<(String, f64)> {
    let raw: Vec<f64> = e
        .targets
        .iter()
        .map(|t| {
            let v = t.get(model).unwrap_or(f64::NAN);
            match e.candidate.kind {
                EffectKind::Stiffness | EffectKind::Damping if e.nominal != 0.0 => {
                    v / e.nominal - 1.0
                }
                _ => v,
            }
        })
        .collect();
    if e.candidate.kind == EffectKind::Friction {
        let mean = raw.iter().sum::<f64>() / raw.len().max(1) as f64;
        return vec![("level".to_string(), mean)];
    }
    e.names.iter().cloned().zip(raw).collect()
}
