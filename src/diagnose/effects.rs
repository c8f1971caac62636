//! Turning a traced candidate into a model element and free parameters.

use crate::model::{Contact, Cubic, Damping, Friction, Model, Spring};
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
    /// Parameter names in the report (`gap`, `stiffness`, `level`, `k3`, `delta`).
    pub names: Vec<String>,
    /// Regression estimates from the trace step (start of the fit).
    pub traced: Vec<f64>,
    /// Nominal stiffness of the changed spring (stiffness effects), N/m.
    pub nominal: f64,
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
            model.springs.push(Spring {
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
        label: r.label.clone(),
        targets,
        names: names.into_iter().map(String::from).collect(),
        traced,
        nominal,
    }
}

/// Free parameters of an added effect for the time-domain fit, at the
/// model's current values, with physical bounds.
pub fn parameters(model: &Model, e: &AddedEffect) -> Result<Vec<Parameter>> {
    e.targets
        .iter()
        .map(|&t| {
            let p = Parameter::relative(model, t)?;
            Ok(match t {
                Target::ContactGap(_) => p.with_relative_bounds(-0.8, 2.0),
                Target::ContactStiffness(_) => p.with_relative_bounds(-0.98, 50.0),
                Target::FrictionLevel(_) => p.with_relative_bounds(-0.99, 10.0),
                Target::CubicK3(_) => p.with_relative_bounds(-0.95, 10.0),
                Target::SpringStiffness(_) => p.with_relative_bounds(-0.9, 10.0),
                _ => p,
            })
        })
        .collect()
}

/// `model` with the effect `e` switched off (its other parameters and the
/// other effects as they are): a stiffness or damping change back to its
/// nominal value, a ground spring, friction level, cubic coefficient or
/// contact stiffness to zero (a contact's gap stays).
pub fn without(model: &Model, e: &AddedEffect) -> Model {
    let mut m = model.clone();
    for t in &e.targets {
        let off = match (e.candidate.kind, t) {
            (_, Target::ContactGap(_)) => continue,
            (EffectKind::Stiffness | EffectKind::Damping, _) => e.nominal,
            _ => 0.0,
        };
        t.set(&mut m, off);
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
        | Target::ContactGap(i) => i,
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
