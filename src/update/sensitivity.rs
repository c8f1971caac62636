//! Derivatives of the simulated channels with respect to the scaled
//! parameters, from forward sensitivities of the integrator
//! ([`crate::integrate::Integrator::run_sensitivities`]): one simulation per
//! segment gives the responses and all their derivatives.
//!
//! A parameter `p = p0 + s x` ([`Parameter::from_x`]) moves the model by
//! `∂/∂x = s ∂/∂p`:
//!
//! | target | `∂M/∂p` | `∂K/∂p` | `∂C/∂p` | element |
//! |---|---|---|---|---|
//! | spring `k` between i, j | 0 | `(e_i − e_j)(e_i − e_j)ᵀ` | Rayleigh: `β ∂K`; modal: see below | – |
//! | mass of DOF i | `e_i e_iᵀ` | 0 | Rayleigh: `α ∂M`; modal: see below | – |
//! | modal damping ratio ζ | 0 | 0 | `C(ζ = 1)` (C is linear in ζ) | – |
//! | contact gap / stiffness, friction level, cubic k3 | 0 | 0 | 0 | `∂f_int/∂p` |
//!
//! Modal damping `C = MΦ diag(2ζω) ΦᵀM` moves with M and K through the modes;
//! its derivative is taken by central differences of
//! [`crate::model::damping_matrix`] (step `1e-5 |p|`, an `n × n` eigenproblem
//! per side, no simulation; truncation and rounding ~1e-10 relative).
//!
//! Only full-order problems: in a reduced problem the basis follows the
//! parameters, and its derivative is not propagated
//! ([`unsupported`] says why; the optimizers then use finite differences).
//! The start states of the segments are data and do not depend on the
//! parameters.

use super::forward::{self, Failure, SegmentResponse};
use super::param::{Parameter, Target};
use super::problem::Problem;
use crate::integrate::{ElementSeed, ParamSeed, Seeds, Sensitivities, Tape};
use crate::model::elements::{self, ElementList, ElementParam};
use crate::model::{Damping, Model};
use nalgebra::DMatrix;
use rayon::prelude::*;

/// Why the sensitivity Jacobian cannot be used for `problem` (None: it
/// can).
pub fn unsupported(problem: &Problem) -> Option<String> {
    problem.reduction.map(|m| {
        format!(
            "reduced model ({m:?}): the basis depends on the parameters and its derivative is not propagated"
        )
    })
}

/// Simulated channels of one segment and their derivatives with respect to
/// each scaled parameter (observation × sample each).
#[derive(Debug, Clone)]
pub struct SegmentDerivatives {
    /// Channels, as [`forward::simulate`] gives them.
    pub y: SegmentResponse,
    /// `∂y/∂x_j`, one matrix per parameter (after the start-state
    /// directions when [`simulate_seeded`] was asked for them).
    pub dy: Vec<DMatrix<f64>>,
}

/// Simulate every segment of a full-order `problem` at scaled parameters
/// `x` with forward sensitivities. Returns the channels and derivatives and
/// the number of segment simulations run (each a simulation with
/// sensitivities).
pub fn simulate(
    problem: &Problem,
    x: &[f64],
) -> (std::result::Result<Vec<SegmentDerivatives>, Failure>, usize) {
    simulate_seeded(problem, x, false)
}

/// [`simulate`], and with `states` also the derivatives with respect to
/// each segment's start state: `dy` then holds the `2n` state directions
/// first (`u_0`, then `v_0`), then the parameters.
pub fn simulate_seeded(
    problem: &Problem,
    x: &[f64],
    states: bool,
) -> (std::result::Result<Vec<SegmentDerivatives>, Failure>, usize) {
    let fail = |segment, reason: String| Failure { segment, reason };
    if let Some(why) = unsupported(problem) {
        return (Err(fail(None, why)), 0);
    }
    let model = problem.model_at(x);
    let compiled = match forward::compile(problem, &model) {
        Ok(c) => c,
        Err(f) => return (Err(f), 0),
    };
    let n = model.ndof();
    let seeds = match param_seeds(&model, &problem.parameters) {
        Ok(params) if states => Seeds {
            state: DMatrix::identity(2 * n, 2 * n),
            params,
        },
        Ok(p) => Seeds::params(n, p),
        Err(e) => return (Err(fail(None, e)), 0),
    };
    // in parallel, collected in order (as forward::simulate)
    let runs: Vec<std::result::Result<SegmentDerivatives, Failure>> = problem
        .segments
        .par_iter()
        .enumerate()
        .map(|(i, seg)| {
            let force = problem.force.columns(seg.start, seg.len);
            let (sim, sens) = compiled
                .integ
                .run_sensitivities(force, &seg.u0, &seg.v0, &seeds)
                .map_err(|e| fail(Some(i), e.to_string()))?;
            if !sim.completed() {
                return Err(forward::stopped(i, &sim));
            }
            let pos = &compiled.pos;
            let y = forward::extract_channels(problem, (&sim.u, &sim.v, &sim.a), pos);
            segment_derivatives(problem, pos, i, y, &sens)
        })
        .collect();
    let count = runs.len();
    (runs.into_iter().collect(), count)
}

/// The derivatives [`simulate`] gives at `x`, replayed from the tapes of
/// the runs at `x` ([`forward::simulate_taped`]; `responses` their
/// channels) without simulating again: the same numbers
/// ([`crate::integrate::Integrator::sensitivities_from_tape`]). None when
/// the tapes cannot give them (then [`simulate`] must run), else what
/// [`simulate`] would return, a failure included.
pub fn from_tapes(
    problem: &Problem,
    x: &[f64],
    responses: &[SegmentResponse],
    tapes: &[Tape],
) -> Option<std::result::Result<Vec<SegmentDerivatives>, Failure>> {
    if unsupported(problem).is_some() || tapes.len() != problem.segments.len() {
        return None;
    }
    let model = problem.model_at(x);
    let compiled = forward::compile(problem, &model).ok()?;
    let seeds = Seeds::params(model.ndof(), param_seeds(&model, &problem.parameters).ok()?);
    let runs: Vec<Option<std::result::Result<SegmentDerivatives, Failure>>> = problem
        .segments
        .par_iter()
        .zip(tapes)
        .zip(responses)
        .enumerate()
        .map(|(i, ((seg, tape), y))| {
            let force = problem.force.columns(seg.start, seg.len);
            let sens = compiled
                .integ
                .sensitivities_from_tape(force, &seg.u0, &seg.v0, tape, &seeds)
                .ok()?;
            Some(segment_derivatives(
                problem,
                &compiled.pos,
                i,
                y.clone(),
                &sens,
            ))
        })
        .collect();
    runs.into_iter()
        .collect::<Option<Vec<_>>>()
        .map(|r| r.into_iter().collect())
}

/// Segment `i`'s channels `y` with their derivatives along every seed of
/// `sens` (`pos`: each DOF's simulated coordinate); a failure when the
/// converged tangent was singular (the derivatives NaN from there on).
fn segment_derivatives(
    problem: &Problem,
    pos: &[Option<usize>],
    i: usize,
    y: SegmentResponse,
    sens: &Sensitivities,
) -> std::result::Result<SegmentDerivatives, Failure> {
    if let Some(t) = sens.singular_tangent {
        return Err(Failure {
            segment: Some(i),
            reason: format!("the converged tangent is singular at t = {t} s"),
        });
    }
    let dy = (0..sens.du.len())
        .map(|j| forward::extract_channels(problem, (&sens.du[j], &sens.dv[j], &sens.da[j]), pos))
        .collect();
    Ok(SegmentDerivatives { y, dy })
}

/// The seeds `∂(M, C, K, elements)/∂x_j` of the parameters at `model`
/// (the model at the current values). Errors name the parameter.
pub fn param_seeds(
    model: &Model,
    parameters: &[Parameter],
) -> std::result::Result<Vec<ParamSeed>, String> {
    parameters
        .iter()
        .map(|p| {
            target_seed(model, p.target, p.scale())
                .map_err(|e| format!("parameter {}: {e}", p.name))
        })
        .collect()
}

/// `s ∂(model)/∂p` for one target.
pub fn target_seed(
    model: &Model,
    target: Target,
    s: f64,
) -> std::result::Result<ParamSeed, String> {
    let n = model.ndof();
    let (nc, nf) = (model.contacts.len(), model.frictions.len());
    let at = |list, i| elements::compiled_index(model, list, i);
    let element = |element, param| ParamSeed {
        elements: vec![ElementSeed {
            element,
            param,
            scale: s,
        }],
        ..Default::default()
    };
    Ok(match target {
        Target::SpringStiffness(i) => {
            let mut dk = DMatrix::zeros(n, n);
            let f = model.spring_factor(i);
            crate::model::add_spring(&mut dk, model.springs[i].ends(), s * f);
            ParamSeed {
                dc: damping_derivative(model, target, s, &dk)?,
                dk: Some(dk),
                ..Default::default()
            }
        }
        Target::Mass(i) => {
            let mut dm = DMatrix::zeros(n, n);
            dm[(i, i)] = s;
            ParamSeed {
                dc: damping_derivative(model, target, s, &dm)?,
                dm: Some(dm),
                ..Default::default()
            }
        }
        Target::StiffnessScale | Target::MassScale => {
            let stiffness = target == Target::StiffnessScale;
            let d = model
                .matrix_scale_derivative(stiffness)
                .ok_or("the model is not given by matrices")?
                * s;
            let dc = damping_derivative(model, target, s, &d)?;
            if stiffness {
                ParamSeed {
                    dc,
                    dk: Some(d),
                    ..Default::default()
                }
            } else {
                ParamSeed {
                    dc,
                    dm: Some(d),
                    ..Default::default()
                }
            }
        }
        Target::DampingRatio | Target::ModalRatio(_) => {
            let unit = unit_damping(model, target)?;
            let c1 = crate::model::damping_matrix(
                &unit,
                &model.mass_matrix(),
                &model.stiffness_matrix(),
            )
            .map_err(|e| e.to_string())?;
            ParamSeed {
                dc: Some(c1 * s),
                ..Default::default()
            }
        }
        Target::RayleighAlpha => ParamSeed {
            dc: Some(model.mass_matrix() * s),
            ..Default::default()
        },
        Target::RayleighBeta => ParamSeed {
            dc: Some(model.stiffness_matrix() * s),
            ..Default::default()
        },
        Target::ContactGap(i) => element(i, ElementParam::Gap),
        Target::ContactStiffness(i) => element(i, ElementParam::Stiffness),
        Target::FrictionLevel(i) => element(nc + i, ElementParam::Level),
        Target::CubicK3(i) => element(nc + nf + i, ElementParam::K3),
        Target::QuadraticK2(i) => element(at(ElementList::Quadratic, i), ElementParam::K2),
        Target::DamperC2(i) => element(at(ElementList::QuadraticDamper, i), ElementParam::C2),
        Target::DamperC3(i) => element(at(ElementList::CubicDamper, i), ElementParam::C3),
        Target::RelativeFrictionLevel(i) => {
            element(at(ElementList::RelativeFriction, i), ElementParam::Level)
        }
        // a clearance is two contacts with the same gap and stiffness
        Target::ClearanceGap(i) | Target::ClearanceStiffness(i) => {
            let param = if matches!(target, Target::ClearanceGap(_)) {
                ElementParam::Gap
            } else {
                ElementParam::Stiffness
            };
            let e = at(ElementList::Clearance, i);
            ParamSeed {
                elements: [e, e + 1]
                    .map(|element| ElementSeed {
                        element,
                        param,
                        scale: s,
                    })
                    .to_vec(),
                ..Default::default()
            }
        }
    })
}

/// The damping whose matrix is `∂C/∂p` for a modal damping target: every
/// ratio 1 (a single ratio), the ratios over their mean (ratios moved in
/// proportion), or a 1 at mode `r` alone.
fn unit_damping(model: &Model, target: Target) -> std::result::Result<Damping, String> {
    let ratios = match (&model.damping, target) {
        (Damping::Modal { ratio: Some(_), .. }, Target::DampingRatio) => {
            return Ok(Damping::Modal {
                ratio: Some(1.0),
                ratios: vec![],
            })
        }
        (
            Damping::Modal {
                ratio: None,
                ratios,
            },
            Target::DampingRatio,
        ) if !ratios.is_empty() => {
            let mean = super::param::mean_ratio(ratios);
            ratios.iter().map(|z| z / mean.max(1e-300)).collect()
        }
        (
            Damping::Modal {
                ratio: None,
                ratios,
            },
            Target::ModalRatio(r),
        ) if r < ratios.len() => (0..ratios.len())
            .map(|j| if j == r { 1.0 } else { 0.0 })
            .collect(),
        _ => return Err("the model's damping is not modal".into()),
    };
    Ok(Damping::Modal {
        ratio: None,
        ratios,
    })
}

/// `s ∂C/∂p` for a spring or mass target whose matrix derivative (times
/// `s`) is `dmat`: Rayleigh `C = a M + b K` exactly, modal damping by
/// central differences of the damping matrix.
fn damping_derivative(
    model: &Model,
    target: Target,
    s: f64,
    dmat: &DMatrix<f64>,
) -> std::result::Result<Option<DMatrix<f64>>, String> {
    match model.damping {
        Damping::None => Ok(None),
        Damping::Rayleigh { alpha, beta } => {
            let c = if matches!(target, Target::Mass(_) | Target::MassScale) {
                alpha
            } else {
                beta
            };
            Ok((c != 0.0).then(|| dmat * c))
        }
        Damping::Modal { .. } => {
            let p = target.get(model).map_err(|e| e.to_string())?;
            let h = 1e-5 * p.abs();
            let at = |v: f64| {
                let mut m = model.clone();
                target.set(&mut m, v);
                m.damping_matrix().map_err(|e| e.to_string())
            };
            let (cp, cm) = (at(p + h)?, at(p - h)?);
            Ok(Some((cp - cm) * (s / (2.0 * h))))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The modal damping derivative against the eigenvalue sensitivity of
    /// an SDOF: C = 2 ζ √(k m), ∂C/∂k = ζ √(m/k), ∂C/∂m = ζ √(k/m).
    #[test]
    fn modal_damping_derivative_of_an_oscillator() {
        let model = Model::from_toml_str(
            "masses = [2.0]\n[[spring]]\ndofs = [1]\nstiffness = 800.0\n[damping]\nkind = \"modal\"\nratio = 0.05\n",
            "sdof",
        )
        .unwrap();
        let dk = target_seed(&model, Target::SpringStiffness(0), 3.0).unwrap();
        approx::assert_relative_eq!(
            dk.dc.unwrap()[(0, 0)],
            3.0 * 0.05 * (2.0f64 / 800.0).sqrt(),
            max_relative = 1e-9
        );
        assert_eq!(dk.dk.unwrap()[(0, 0)], 3.0);
        let dm = target_seed(&model, Target::Mass(0), 0.5).unwrap();
        approx::assert_relative_eq!(
            dm.dc.unwrap()[(0, 0)],
            0.5 * 0.05 * (800.0f64 / 2.0).sqrt(),
            max_relative = 1e-9
        );
        let dz = target_seed(&model, Target::DampingRatio, 0.05).unwrap();
        approx::assert_relative_eq!(
            dz.dc.unwrap()[(0, 0)],
            0.05 * 2.0 * (800.0f64 * 2.0).sqrt(),
            max_relative = 1e-12
        );
    }
}
