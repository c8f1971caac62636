//! Forward simulation of a [`Problem`] at given parameters: every segment
//! from its start state, on the full-order model or on the model reduced to
//! the measured DOFs.
//!
//! Reduced model: `u ≈ T u_a` with `T` from [`crate::reduce::reduce`] built
//! for the current parameters, `M_a = TᵀMT`, `C_a = TᵀCT`, `K_a = TᵀKT`,
//! `f_a = Tᵀ f`. The kept set is the measured DOFs plus every DOF a
//! nonlinear element acts on; Guyan, IRS and SEREP bases have identity rows
//! at the kept DOFs, so the reduced coordinates *are* the kept displacements
//! and an element between kept DOFs acts on them unchanged
//! (`Tᵀ f_int(T u_a) = f_int,a(u_a)`). The start state of a segment is its
//! full-order state projected on the basis in the mass metric,
//! `u_a = (TᵀMT)⁻¹ TᵀM u` (for SEREP: the modal coordinates of the retained
//! modes, seen at the kept DOFs), so the omitted part of the state does not
//! leak into the retained modes.

use super::problem::Problem;
use crate::integrate::{Integrator, Simulation, Tape};
use crate::model::elements::{self, Element};
use crate::model::Model;
use crate::record::Quantity;
use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;
use serde::Serialize;

/// Why an evaluation of the model failed (a status, not an error: the
/// optimizer rejects the trial point and goes on).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Failure {
    /// Segment whose simulation failed, if the failure is in a simulation.
    pub segment: Option<usize>,
    /// What happened, with the numbers.
    pub reason: String,
}

impl std::fmt::Display for Failure {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.segment {
            Some(s) => write!(f, "segment {s}: {}", self.reason),
            None => write!(f, "{}", self.reason),
        }
    }
}

/// Simulated channels of one segment: one row per observation of the
/// problem, one column per sample of the segment.
pub type SegmentResponse = DMatrix<f64>;

/// A compiled simulator for one parameter vector.
pub(super) struct Compiled {
    pub(super) integ: Integrator,
    /// Reduction basis transposed (m × n) when reduced.
    tt: Option<DMatrix<f64>>,
    /// Mass-metric projection `(TᵀMT)⁻¹ TᵀM` (m × n) of full-order states
    /// onto the reduced coordinates.
    proj: Option<DMatrix<f64>>,
    /// Position of each model DOF in the simulated coordinates (None: not
    /// simulated).
    pub(super) pos: Vec<Option<usize>>,
}

/// Simulate every segment of `problem` for the scaled parameters `x`.
/// Returns the responses and the number of segment simulations run.
pub fn simulate(
    problem: &Problem,
    x: &[f64],
) -> (std::result::Result<Vec<SegmentResponse>, Failure>, usize) {
    let (res, n) = simulate_with(problem, x, false);
    (res.map(|(y, _)| y), n)
}

/// [`simulate`], each segment's run taped ([`Integrator::run_taped`], with
/// the states: parameter seeds need them) so that the sensitivities at `x`
/// can be replayed from the tapes ([`super::sensitivity::from_tapes`]);
/// no tapes (None) for a reduced problem.
#[allow(clippy::type_complexity)]
pub(super) fn simulate_taped(
    problem: &Problem,
    x: &[f64],
) -> (
    std::result::Result<(Vec<SegmentResponse>, Option<Vec<Tape>>), Failure>,
    usize,
) {
    simulate_with(problem, x, true)
}

/// [`simulate`] with each run's tape when `taped` (and the problem is not
/// reduced).
#[allow(clippy::type_complexity)]
fn simulate_with(
    problem: &Problem,
    x: &[f64],
    taped: bool,
) -> (
    std::result::Result<(Vec<SegmentResponse>, Option<Vec<Tape>>), Failure>,
    usize,
) {
    let model = problem.model_at(x);
    let compiled = match compile(problem, &model) {
        Ok(c) => c,
        Err(f) => return (Err(f), 0),
    };
    let taped = taped && compiled.tt.is_none();
    // segments are independent: simulated in parallel and collected in
    // order, so the result (and the first failure reported) does not depend
    // on the thread count; every segment is simulated and counted
    let runs: Vec<std::result::Result<(SegmentResponse, Option<Tape>), Failure>> = problem
        .segments
        .par_iter()
        .enumerate()
        .map(|(i, seg)| {
            let force = problem.force.columns(seg.start, seg.len);
            let (sim, tape) = match &compiled.tt {
                None if taped => {
                    let (sim, tape) = compiled.integ.run_taped(force, &seg.u0, &seg.v0, true);
                    (sim, Some(tape))
                }
                None => (compiled.integ.run(force, &seg.u0, &seg.v0), None),
                Some(tt) => {
                    let fa = tt * force;
                    let proj = compiled.proj.as_ref().unwrap_or(tt);
                    let ua = proj * DVector::from_column_slice(&seg.u0);
                    let va = proj * DVector::from_column_slice(&seg.v0);
                    let sim = compiled
                        .integ
                        .run(fa.as_view(), ua.as_slice(), va.as_slice());
                    (sim, None)
                }
            };
            if !sim.completed() {
                return Err(stopped(i, &sim));
            }
            Ok((extract(problem, &sim, &compiled.pos), tape))
        })
        .collect();
    let count = runs.len();
    let runs: std::result::Result<Vec<_>, Failure> = runs.into_iter().collect();
    let split = |r: Vec<(SegmentResponse, Option<Tape>)>| {
        let (y, t): (Vec<_>, Vec<_>) = r.into_iter().unzip();
        (
            y,
            t.into_iter().collect::<Option<Vec<_>>>().filter(|_| taped),
        )
    };
    (runs.map(split), count)
}

/// The failure of segment `i`, whose simulation `sim` stopped early.
pub(super) fn stopped(i: usize, sim: &Simulation) -> Failure {
    Failure {
        segment: Some(i),
        reason: format!(
            "simulation stopped: {}",
            crate::simulate::describe_status(&sim.status)
        ),
    }
}

/// The first segment whose simulation at `x` diverges (its energy above
/// what the force can put in, [`Integrator::divergence`]), in words with
/// the step's facts; None when every segment stays bounded (or a
/// simulation fails, which [`simulate`] reports).
pub fn divergence(problem: &Problem, x: &[f64]) -> Option<String> {
    let model = problem.model_at(x);
    let compiled = compile(problem, &model).ok()?;
    problem.segments.iter().enumerate().find_map(|(i, seg)| {
        let force = problem.force.columns(seg.start, seg.len);
        let (fa, ua, va) = match (&compiled.tt, &compiled.proj) {
            (None, _) => (force.into_owned(), seg.u0.clone(), seg.v0.clone()),
            (Some(tt), proj) => {
                let proj = proj.as_ref().unwrap_or(tt);
                let ua = proj * DVector::from_column_slice(&seg.u0);
                let va = proj * DVector::from_column_slice(&seg.v0);
                (tt * force, ua.as_slice().to_vec(), va.as_slice().to_vec())
            }
        };
        let sim = compiled.integ.run(fa.as_view(), &ua, &va);
        let d = compiled.integ.divergence(fa.as_view(), &sim)?;
        let at = match compiled.tt {
            None => format!("DOF {} at {:.3e} m/s^2", d.dof, d.accel),
            Some(_) => format!("reduced coordinate {} at {:.3e}", d.dof, d.accel),
        };
        Some(format!(
            "segment {i} diverges from its sample {} on: its energy is {:.3e} times what the force can put in ({at}); {}",
            d.sample,
            d.growth.powi(2),
            compiled.integ.describe_step()
        ))
    })
}

/// Relative difference between the reduced and the full-order responses
/// at `x` over all channels and segments (`None` for a full-order problem
/// or when either simulation fails).
pub fn reduction_error(problem: &Problem, x: &[f64]) -> Option<f64> {
    problem.reduction?;
    let full = Problem {
        reduction: None,
        ..problem.clone()
    };
    let (a, _) = simulate(problem, x);
    let (b, _) = simulate(&full, x);
    let (a, b) = (a.ok()?, b.ok()?);
    let (mut num, mut den) = (0.0, 0.0);
    for (ra, rb) in a.iter().zip(&b) {
        num += (ra - rb).norm_squared();
        den += rb.norm_squared();
    }
    Some(crate::metrics::ratio(num, den))
}

pub(super) fn compile(problem: &Problem, model: &Model) -> std::result::Result<Compiled, Failure> {
    let fail = |reason: String| Failure {
        segment: None,
        reason,
    };
    let n = model.ndof();
    let Some(method) = problem.reduction else {
        let integ = Integrator::new(model, problem.fs, problem.sim)
            .map_err(|e| fail(format!("model could not be compiled: {e}")))?;
        return Ok(Compiled {
            integ,
            tt: None,
            proj: None,
            pos: (0..n).map(Some).collect(),
        });
    };
    let kept = kept_dofs(problem, model);
    let m = model.mass_matrix();
    let k = model.stiffness_matrix();
    let c = model
        .damping_matrix()
        .map_err(|e| fail(format!("damping matrix: {e}")))?;
    let red = crate::reduce::reduce(&m, &k, &kept, method)
        .map_err(|e| fail(format!("reduction failed: {e}")))?;
    let mut pos = vec![None; n];
    for (p, &d) in red.kept.iter().enumerate() {
        pos[d] = Some(p);
    }
    let els = elements::compile(model)
        .into_iter()
        .map(|e| remap(e, &pos))
        .collect::<Option<Vec<_>>>()
        .ok_or_else(|| {
            fail("a nonlinear element acts on a DOF outside the reduced model".into())
        })?;
    let cr = red.project(&c);
    let tm = red.t.transpose() * &m;
    let proj = red
        .m
        .clone()
        .cholesky()
        .map(|ch| ch.solve(&tm))
        .ok_or_else(|| fail("the reduced mass matrix is not positive definite".into()))?;
    let integ = Integrator::from_matrices(
        red.m.clone(),
        cr,
        red.k.clone(),
        els,
        problem.fs,
        problem.sim,
    )
    .map_err(|e| fail(format!("reduced model could not be compiled: {e}")))?;
    Ok(Compiled {
        integ,
        tt: Some(red.t.transpose()),
        proj: Some(proj),
        pos,
    })
}

/// Kept DOFs (0-based, ascending): measured DOFs and element DOFs.
pub fn kept_dofs(problem: &Problem, model: &Model) -> Vec<usize> {
    let mut kept: Vec<usize> = problem.measured_dofs().iter().map(|d| d - 1).collect();
    for e in elements::compile(model) {
        let (i, j) = e.ends();
        kept.push(i);
        kept.extend(j);
    }
    kept.sort_unstable();
    kept.dedup();
    kept
}

fn remap(e: Element, pos: &[Option<usize>]) -> Option<Element> {
    e.renumbered(|d| pos[d])
}

fn extract(problem: &Problem, sim: &Simulation, pos: &[Option<usize>]) -> SegmentResponse {
    extract_channels(problem, (&sim.u, &sim.v, &sim.a), pos)
}

/// The observed rows of (displacement, velocity, acceleration) matrices
/// (DOF × sample, simulated coordinates): one row per observation.
pub(super) fn extract_channels(
    problem: &Problem,
    (u, v, a): (&DMatrix<f64>, &DMatrix<f64>, &DMatrix<f64>),
    pos: &[Option<usize>],
) -> SegmentResponse {
    let mut out = DMatrix::zeros(problem.observations.len(), u.ncols());
    for (r, o) in problem.observations.iter().enumerate() {
        // measured DOFs are always kept (see `kept_dofs`)
        let p = pos[o.dof - 1].unwrap_or(0);
        let src = match o.quantity {
            Quantity::Disp => u,
            Quantity::Vel => v,
            _ => a,
        };
        out.row_mut(r).copy_from(&src.row(p));
    }
    out
}
