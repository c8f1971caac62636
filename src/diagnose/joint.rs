//! Effect parameters and segment start states fitted together.
//!
//! The multiple-shooting cost of a fit depends on the parameters `x` and on
//! the start state `s_i` of every segment:
//!
//! $$ J(x, s) = \sum_i \lVert r_i(x, s_i) \rVert^2, \qquad
//!    r_i = W (y_i - \hat y_i(x, s_i)). $$
//!
//! Fitting `x` with the states fixed and then the states with `x` fixed, in
//! turn, creeps along the valley where the two trade (a contact's gap
//! against where the segment starts); so both are stepped at once, with
//! Levenberg–Marquardt on the whole vector. One simulation of every segment
//! with forward sensitivities ([`sensitivity::simulate_seeded`], `2n`
//! state seeds and one seed per parameter) gives `r_i`, `J_s,i = ∂r_i/∂s_i`
//! and `J_p,i = ∂r_i/∂x`. The normal equations are block-arrow shaped: the
//! states of a segment couple only to themselves and to `x`. With Marquardt
//! damping `λ diag(·)` on every block, each segment's block
//! `A_i = J_sᵀJ_s + λ D_i` is eliminated (Schur complement):
//!
//! $$ \Big(\sum_i J_pᵀJ_p - B_iᵀ A_i^{-1} B_i + λ D_p\Big) δx
//!    = \sum_i J_pᵀ r_i - B_iᵀ A_i^{-1} J_sᵀ r_i, \qquad
//!    δs_i = A_i^{-1}(J_sᵀ r_i - B_i δx), $$
//!
//! with `B_i = J_sᵀ J_p`: the cost of a step is a `2n × 2n` Cholesky per
//! segment and one `n_p × n_p` solve. States are scaled to a common unit
//! ([`crate::linear::SampledModel::state_scale`]) and `D_i` is floored at
//! `1e-10` of its largest entry, so directions the outputs never see (a
//! free-free model's rigid-body position under acceleration data) take no
//! step. The iterations are the least-squares driver's ([`crate::lsq`],
//! the Schur-complement solve plugged in as its step): a step is accepted
//! when the cost falls (λ ÷ 3), else λ × 4 and the step is recomputed; the fit stops when an accepted step with light
//! damping (λ ≤ 0.01 after it) lowers the cost by less than the relative
//! `f_tol` (at least 1e-4), when λ exceeds 1e6 (stalled: the cost
//! is rough at the sub-step scale), or at the iteration limit. A trial
//! point's simulations keep their tapes ([`crate::integrate::Tape`]): when
//! the point is accepted, its residuals and Jacobians come from the
//! derivative steps alone, without simulating the segments again (the
//! same numbers, bit for bit).

use super::comparison::segment_residual;
use crate::integrate::{Integrator, Seeds, Tape};
use crate::record::Quantity;
use crate::update::optimize::FitSettings;
use crate::update::{sensitivity, Problem, Segment};
use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;

/// How a joint fit ended.
#[derive(Debug, Clone)]
pub struct JointFit {
    /// Scaled parameters at the end.
    pub x: Vec<f64>,
    /// Segments with their fitted start states.
    pub segments: Vec<Segment>,
    /// Cost of each segment at the end.
    pub segment_costs: Vec<f64>,
    /// Cost at the start and at the end.
    pub cost: (f64, f64),
    /// Accepted steps.
    pub iterations: usize,
    /// Segment simulations run (with or without sensitivities).
    pub simulations: usize,
    /// Why it stopped.
    pub termination: JointTermination,
}

/// Why a joint fit stopped.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum JointTermination {
    /// The iteration limit.
    IterationLimit,
    /// An accepted step with light damping gained less than the tolerance.
    Converged,
    /// Accepted steps in a row each gained less than a fraction of the
    /// cost ([`Stall`]).
    Stalled(Stall),
    /// The damping grew past 1e6: steps vanish (the cost is rough at this
    /// scale or the derivatives unreliable).
    StepsVanish,
    /// A simulation or its derivatives failed at the current point.
    SimulationFailed,
}

impl std::fmt::Display for JointTermination {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            JointTermination::IterationLimit => write!(f, "iteration limit"),
            JointTermination::Converged => write!(f, "converged (cost)"),
            JointTermination::Stalled(s) => write!(
                f,
                "stalled: {} accepted steps in a row each lowered the cost by less than {:.1} %",
                s.steps,
                100.0 * s.gain
            ),
            JointTermination::StepsVanish => write!(
                f,
                "stalled: steps vanish (the cost is rough at this scale or the derivatives unreliable)"
            ),
            JointTermination::SimulationFailed => write!(
                f,
                "a simulation or its derivatives failed at the current point"
            ),
        }
    }
}

/// Why a joint fit could not start.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum JointError {
    /// The problem is reduced (the joint fit is for full-order problems).
    #[error("the problem is reduced; the joint fit needs a full-order one")]
    Reduced,
    /// The start has the wrong length.
    #[error("{given} start values for {expected} parameters")]
    StartLength {
        /// Parameters of the problem.
        expected: usize,
        /// Values given.
        given: usize,
    },
    /// The linear part of the model could not be sampled (no state scale).
    #[error("the linear part of the model could not be sampled")]
    StateScale,
    /// A segment could not be simulated at the start.
    #[error("a segment could not be simulated at the start")]
    StartFailed,
}

/// One segment linearized: residual, state and parameter Jacobians
/// (states scaled).
struct Lin {
    r: DVector<f64>,
    js: DMatrix<f64>,
    jp: DMatrix<f64>,
}

/// The state scale of `problem`'s model (displacements × ω, velocities
/// as they are; [`crate::linear::SampledModel::state_scale`]).
fn state_scale(problem: &Problem) -> Option<DVector<f64>> {
    let lin = problem.model.linear_part();
    crate::linear::SampledModel::from_model(&lin, problem.fs, problem.sim.substeps)
        .ok()
        .map(|sm| sm.state_scale())
}

/// The observed channels (p × len) of a full-order simulation's
/// `(u, v, a)` (DOF × sample), as [`crate::update::forward::simulate`] extracts them.
fn channels(
    problem: &Problem,
    (u, v, a): (&DMatrix<f64>, &DMatrix<f64>, &DMatrix<f64>),
) -> DMatrix<f64> {
    let mut y = DMatrix::zeros(problem.observations.len(), u.ncols());
    for (c, o) in problem.observations.iter().enumerate() {
        let src = match o.quantity {
            Quantity::Disp => u,
            Quantity::Vel => v,
            _ => a,
        };
        y.row_mut(c).copy_from(&src.row(o.dof - 1));
    }
    y
}

/// The weighted residual of every segment of `problem` at `x` and the
/// tape of its simulation (with the states, for the parameter seeds):
/// [`residuals`] with what [`linearize_taped`] needs to differentiate at
/// the same point without simulating again. The integrator is the one
/// [`crate::update::forward::simulate`] builds for a full-order problem, so the
/// simulations are the same; `None` when one fails.
fn residuals_taped(problem: &Problem, x: &[f64]) -> Option<Vec<(DVector<f64>, Tape)>> {
    let model = problem.model_at(x);
    let integ = Integrator::new(&model, problem.fs, problem.sim).ok()?;
    let runs: Vec<Option<(DVector<f64>, Tape)>> = problem
        .segments
        .par_iter()
        .map(|s| {
            let force = problem.force.columns(s.start, s.len);
            let (sim, tape) = integ.run_taped(force, &s.u0, &s.v0, true);
            if !sim.completed() {
                return None;
            }
            let y = channels(problem, (&sim.u, &sim.v, &sim.a));
            let r = segment_residual(&problem.observations, s, y.as_view())?;
            Some((r, tape))
        })
        .collect();
    runs.into_iter().collect()
}

/// [`linearize`] from the segments' residuals and tapes at `x`
/// ([`residuals_taped`]): the same residuals and Jacobians, bit for bit,
/// from the derivative steps alone
/// ([`Integrator::sensitivities_from_tape`]); `None` when the tapes cannot
/// be replayed for these seeds (a parameter of M, C or K where a tape took
/// samples whole) or a tangent is singular.
fn linearize_taped(
    problem: &Problem,
    x: &[f64],
    scale: &DVector<f64>,
    taped: &[(DVector<f64>, Tape)],
) -> Option<Vec<Lin>> {
    let model = problem.model_at(x);
    let integ = Integrator::new(&model, problem.fs, problem.sim).ok()?;
    let n = model.ndof();
    let seeds = Seeds {
        state: DMatrix::identity(2 * n, 2 * n),
        params: sensitivity::param_seeds(&model, &problem.parameters).ok()?,
    };
    let runs: Vec<Option<Lin>> = problem
        .segments
        .par_iter()
        .zip(taped)
        .map(|(s, (r, tape))| {
            let force = problem.force.columns(s.start, s.len);
            let d = integ
                .sensitivities_from_tape(force, &s.u0, &s.v0, tape, &seeds)
                .ok()?;
            if d.singular_tangent.is_some() {
                return None;
            }
            let dy: Vec<DMatrix<f64>> = (0..seeds.len())
                .map(|j| channels(problem, (&d.du[j], &d.dv[j], &d.da[j])))
                .collect();
            jacobians(problem, s, r.clone(), &dy, scale)
        })
        .collect();
    runs.into_iter().collect()
}

/// A segment's [`Lin`] from its residual `r` and the derivatives `dy` of
/// its channels (the `2n` state directions, then the parameters); `None`
/// when a derivative is not finite.
fn jacobians(
    problem: &Problem,
    s: &Segment,
    r: DVector<f64>,
    dy: &[DMatrix<f64>],
    scale: &DVector<f64>,
) -> Option<Lin> {
    let (nx, np) = (scale.len(), problem.parameters.len());
    let p = problem.observations.len();
    let m = s.len * p;
    // ∂r/∂θ = −w ∂ŷ/∂θ
    let column = |j: usize, f: f64| {
        DVector::from_fn(m, |row, _| {
            let (k, c) = (row / p, row % p);
            -problem.observations[c].weight * dy[j][(c, k)] * f
        })
    };
    let js = DMatrix::from_columns(&(0..nx).map(|j| column(j, scale[j])).collect::<Vec<_>>());
    let jp = DMatrix::from_columns(&(0..np).map(|j| column(nx + j, 1.0)).collect::<Vec<_>>());
    let finite = js.iter().chain(jp.iter()).all(|v| v.is_finite());
    finite.then_some(Lin { r, js, jp })
}

/// Residuals and Jacobians of every segment of `problem` at `x`, from one
/// simulation per segment with the start-state and parameter seeds
/// ([`sensitivity::simulate_seeded`]); `None` when a simulation or its
/// derivatives fail.
fn linearize(problem: &Problem, x: &[f64], scale: &DVector<f64>) -> Option<Vec<Lin>> {
    let runs = sensitivity::simulate_seeded(problem, x, true).0.ok()?;
    problem
        .segments
        .iter()
        .zip(runs)
        .map(|(s, d)| {
            let r = segment_residual(&problem.observations, s, d.y.as_view())?;
            jacobians(problem, s, r, &d.dy, scale)
        })
        .collect()
}

/// `JᵀJ` with Marquardt damping `λ D`, `D` its diagonal floored at 1e-10
/// of the largest entry (directions the outputs never see get the floor
/// itself, so they take no step).
fn damped_gram(j: &DMatrix<f64>, lambda: f64) -> DMatrix<f64> {
    let mut a = j.tr_mul(j);
    let dmax = a.diagonal().max().max(f64::MIN_POSITIVE);
    for k in 0..a.nrows() {
        let akk = a[(k, k)];
        let d = akk.max(1e-10 * dmax);
        a[(k, k)] = d + lambda * d;
    }
    a
}

/// Per segment, the eliminated block: `A⁻¹B` and `A⁻¹ J_sᵀ r`.
struct Eliminated {
    x: DMatrix<f64>,
    z: DVector<f64>,
}

/// The damped step `(δx, δs_i)` at `λ` (states scaled), or `None` when a
/// block cannot be factored. With no parameter (`J_p` of no column) it is
/// the states' step alone.
fn step(lins: &[Lin], lambda: f64) -> Option<(DVector<f64>, Vec<DVector<f64>>)> {
    let np = lins.first()?.jp.ncols();
    let mut s = DMatrix::<f64>::zeros(np, np);
    let mut h = DVector::<f64>::zeros(np);
    let mut elim = Vec::with_capacity(lins.len());
    for l in lins {
        let a = damped_gram(&l.js, lambda);
        let b = l.js.tr_mul(&l.jp);
        // the Gauss–Newton direction: r(θ + δ) ≈ r + J δ, so JᵀJ δ = −Jᵀ r
        let gs = -l.js.tr_mul(&l.r);
        let gp = -l.jp.tr_mul(&l.r);
        let ch = a.cholesky()?;
        let x = ch.solve(&b);
        let z = ch.solve(&gs);
        s += l.jp.tr_mul(&l.jp) - b.tr_mul(&x);
        h += gp - b.tr_mul(&z);
        elim.push(Eliminated { x, z });
    }
    let dx = if np == 0 {
        DVector::zeros(0)
    } else {
        let smax = s.diagonal().max().max(f64::MIN_POSITIVE);
        for j in 0..np {
            let d = s[(j, j)].max(1e-12 * smax);
            s[(j, j)] += lambda * d + 1e-14 * smax;
        }
        s.cholesky()?.solve(&h)
    };
    let ds = elim.iter().map(|e| &e.z - &e.x * &dx).collect();
    Some((dx, ds))
}

/// [`fit`] stops after `steps` accepted steps in a row each lowering the
/// cost by less than the fraction `gain` of it
/// ([`super::settings::StartSettings::stall_steps`]).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Stall {
    /// Steps in a row.
    pub steps: usize,
    /// Fraction of the cost.
    pub gain: f64,
}

/// The joint fit as a problem of the least-squares driver: the point is
/// the parameters and the segments (with their start states), the step
/// the Schur-complement solve of [`step`].
struct Joint<'a> {
    cur: Problem,
    scale: &'a DVector<f64>,
    lo: Vec<f64>,
    hi: Vec<f64>,
    sims: usize,
    /// The last point evaluated with its segments' residuals and tapes.
    last: Option<Taped>,
}

/// A joint-fit point with its segments' residuals and simulation tapes.
type Taped = ((Vec<f64>, Vec<Segment>), Vec<(DVector<f64>, Tape)>);

impl crate::lsq::Problem for Joint<'_> {
    type Point = (Vec<f64>, Vec<Segment>);
    type Eval = Vec<f64>;
    type Lin = Vec<Lin>;
    type Step = (DVector<f64>, Vec<DVector<f64>>);

    fn evaluate(&mut self, (x, segs): &Self::Point) -> Option<Vec<f64>> {
        self.sims += segs.len();
        let old = std::mem::replace(&mut self.cur.segments, segs.clone());
        // the tapes of the last point evaluated: its linearization, when
        // the driver accepts it, needs no simulation ([`linearize_taped`])
        self.last = None;
        let taped = residuals_taped(&self.cur, x);
        let costs = taped
            .as_ref()
            .map(|t| t.iter().map(|(r, _)| r.norm_squared()).collect());
        self.last = taped.map(|t| ((x.clone(), segs.clone()), t));
        self.cur.segments = old;
        costs
    }

    fn cost(&self, costs: &Vec<f64>) -> f64 {
        costs.iter().sum()
    }

    fn linearize(&mut self, (x, segs): &Self::Point, _: &Vec<f64>) -> Result<Vec<Lin>, String> {
        self.sims += segs.len();
        self.cur.segments.clone_from(segs);
        let last = self.last.take().filter(|(p, _)| p.0 == *x && p.1 == *segs);
        let taped = last.and_then(|(_, t)| linearize_taped(&self.cur, x, self.scale, &t));
        taped
            .or_else(|| linearize(&self.cur, x, self.scale))
            .ok_or_else(|| "simulation failed".into())
    }

    fn step(&mut self, lins: &Vec<Lin>, lambda: f64) -> Result<Self::Step, String> {
        step(lins, lambda).ok_or_else(|| "a block is not positive definite".into())
    }

    fn trial(&self, (x, segs): &Self::Point, (dx, ds): &Self::Step, _t: f64) -> Self::Point {
        let (n, scale) = (self.cur.model.ndof(), self.scale);
        let xt = (0..x.len())
            .map(|j| (x[j] + dx[j]).clamp(self.lo[j], self.hi[j]))
            .collect();
        let st = segs
            .iter()
            .zip(ds)
            .map(|(s, d)| Segment {
                start: s.start,
                len: s.len,
                u0: (0..n).map(|q| s.u0[q] + d[q] * scale[q]).collect(),
                v0: (0..n).map(|q| s.v0[q] + d[n + q] * scale[n + q]).collect(),
            })
            .collect();
        (xt, st)
    }
}

/// Fit `problem`'s parameters (from `x0`) and its segments' start states
/// together (module docs). Full-order GLS problems only.
pub fn fit(
    problem: &Problem,
    x0: &[f64],
    settings: &FitSettings,
    stall: Stall,
) -> Result<JointFit, JointError> {
    use crate::lsq;
    if problem.reduction.is_some() {
        return Err(JointError::Reduced);
    }
    if problem.parameters.len() != x0.len() {
        return Err(JointError::StartLength {
            expected: problem.parameters.len(),
            given: x0.len(),
        });
    }
    let scale = state_scale(problem).ok_or(JointError::StateScale)?;
    let (lo, hi) = problem.x_bounds();
    let mut q = Joint {
        cur: problem.clone(),
        scale: &scale,
        lo,
        hi,
        sims: 0,
        last: None,
    };
    let damping = lsq::Damping {
        initial: settings.lm_lambda.max(1e-6),
        grow: 4.0,
        shrink: 3.0,
        floor: 1e-9,
        ceiling: 1e6,
    };
    let stop = lsq::Stopping {
        max_iterations: settings.max_iterations,
        x_tol: None,
        cost: lsq::CostTest::Gain(settings.f_tol.max(1e-4)),
        light: 1e-2,
        stall: Some((stall.steps, stall.gain)),
        count_failed_attempt: false,
    };
    let start = (x0.to_vec(), problem.segments.clone());
    let out = lsq::minimize(&mut q, start, lsq::Method::Damped(damping), &stop);
    let termination = match out.termination {
        lsq::Termination::StartFailed => return Err(JointError::StartFailed),
        lsq::Termination::Converged(_) => JointTermination::Converged,
        lsq::Termination::Stalled { .. } => JointTermination::Stalled(stall),
        lsq::Termination::DampingCeiling { .. } => JointTermination::StepsVanish,
        lsq::Termination::LinearizationFailed(_) => JointTermination::SimulationFailed,
        // no budget, step test or line search here: the limit is the rest
        _ => JointTermination::IterationLimit,
    };
    let (x, segments) = out.point;
    Ok(JointFit {
        segment_costs: out.eval.unwrap_or_default(),
        x,
        segments,
        cost: (out.history[0], out.cost),
        iterations: out.iterations,
        simulations: q.sims,
        termination,
    })
}

/// How much of the cost the last `extra` parameters of `problem` are
/// predicted to remove, at `x` with the segments' start states free: the
/// Gauss–Newton predicted cost `Σ‖r_i + J_s δs_i + J_p δx‖²` (lightly
/// damped) with all parameters, against the same with the last `extra`
/// held, as a fraction of the cost now. Also returns the predicted step
/// of the parameters and the simulations run (one with sensitivities per
/// segment).
pub fn predicted_gain(
    problem: &Problem,
    x: &[f64],
    extra: usize,
) -> Option<(f64, Vec<f64>, usize)> {
    let np = problem.parameters.len();
    if problem.reduction.is_some() || np != x.len() || extra == 0 || extra > np {
        return None;
    }
    let lins = linearize(problem, x, &state_scale(problem)?)?;
    let sims = lins.len();
    let cost: f64 = lins.iter().map(|l| l.r.norm_squared()).sum();
    let predicted = |lins: &[Lin]| -> Option<(f64, DVector<f64>)> {
        let (dx, ds) = step(lins, 1e-3)?;
        let c = lins
            .iter()
            .zip(&ds)
            .map(|(l, d)| (&l.r + &l.js * d + &l.jp * &dx).norm_squared())
            .sum();
        Some((c, dx))
    };
    let (with, dx) = predicted(&lins)?;
    let held: Vec<Lin> = lins
        .into_iter()
        .map(|l| Lin {
            jp: l.jp.columns(0, np - extra).into_owned(),
            ..l
        })
        .collect();
    let without = predicted(&held)?.0;
    let gain = if cost > 0.0 {
        ((without - with) / cost).max(0.0)
    } else {
        0.0
    };
    Some((gain, dx.iter().copied().collect(), sims))
}

/// Standard errors of the parameters (in their units) at `x`, with the
/// segments' start states as nuisance parameters: white noise of `level`
/// times each channel's RMS gives a residual row the deviation
/// [`Observation::noise_std`](crate::update::Observation::noise_std); the
/// rows are whitened and the parameters' covariance is the inverse of the
/// Schur complement `Σ J_pᵀJ_p − B_iᵀ A_i⁺ B_i` (the marginal of the joint
/// covariance). `None` when a simulation fails or the complement is
/// singular. One simulation with sensitivities per segment.
pub fn std_errors(problem: &Problem, x: &[f64], level: f64) -> Option<Vec<f64>> {
    uncertainty(problem, x, level, 1).map(|u| u.std_errors)
}

/// How sure the parameters at a fit are: the noise-only standard errors
/// of [`std_errors`] and the parameters estimated from each group of
/// consecutive segments alone.
#[derive(Debug, Clone, PartialEq)]
pub struct Uncertainty {
    /// Standard error of each parameter (its unit) from measurement noise
    /// alone.
    pub std_errors: Vec<f64>,
    /// Per group of consecutive segments, the value of each parameter (its
    /// unit) after one Gauss–Newton step from `x` on that group's segments
    /// alone, their start states re-estimated; a group whose Schur
    /// complement is singular is left out.
    pub groups: Vec<Vec<f64>>,
}

/// [`std_errors`] and, with `groups` ≥ 2, the parameters estimated on
/// each of `groups` runs of consecutive segments (about equal in number):
/// at a converged fit the steps of the groups add up to zero, and how far
/// they scatter shows how much the value depends on the part of the
/// record fitted (model error, coloured residual), which the noise-only
/// standard errors do not see. One simulation with sensitivities per
/// segment.
pub fn uncertainty(problem: &Problem, x: &[f64], level: f64, groups: usize) -> Option<Uncertainty> {
    let sigma: Vec<f64> = problem
        .observations
        .iter()
        .map(|o| o.noise_std(level))
        .collect();
    if sigma.iter().any(|&s| !(s > 0.0)) {
        return None;
    }
    let p = sigma.len();
    let mut lins = linearize(problem, x, &state_scale(problem)?)?;
    for l in &mut lins {
        for r in 0..l.r.len() {
            let w = 1.0 / sigma[r % p];
            l.r[r] *= w;
            l.js.row_mut(r).scale_mut(w);
            l.jp.row_mut(r).scale_mut(w);
        }
    }
    let parts: Vec<(DMatrix<f64>, DVector<f64>)> = lins.iter().map(eliminated).collect();
    let np = x.len();
    let sum = |ps: &[(DMatrix<f64>, DVector<f64>)]| {
        ps.iter().fold(
            (DMatrix::<f64>::zeros(np, np), DVector::<f64>::zeros(np)),
            |(s, h), (si, hi)| (s + si, h + hi),
        )
    };
    let cov = sum(&parts).0.cholesky()?.inverse();
    let value = |j: usize, dx: f64| problem.parameters[j].from_x(x[j] + dx);
    let estimates = if groups >= 2 && parts.len() >= groups {
        let per = parts.len().div_ceil(groups);
        parts
            .chunks(per)
            .filter_map(|g| {
                let (s, h) = sum(g);
                let dx = s.cholesky()?.solve(&h);
                Some((0..np).map(|j| value(j, dx[j])).collect())
            })
            .collect()
    } else {
        vec![]
    };
    Some(Uncertainty {
        std_errors: (0..np)
            .map(|j| cov[(j, j)].max(0.0).sqrt() * problem.parameters[j].scale())
            .collect(),
        groups: estimates,
    })
}

/// One whitened segment with its start states eliminated: its share of
/// the Schur complement `J_pᵀJ_p − Bᵀ A⁺ B` and of the Gauss–Newton
/// right-hand side `−(J_pᵀ r − Bᵀ A⁺ J_sᵀ r)`, `A = J_sᵀJ_s` inverted on
/// the directions the data see (eigenvalues above 1e-12 of the largest;
/// the others carry no information and are left out).
fn eliminated(l: &Lin) -> (DMatrix<f64>, DVector<f64>) {
    let eig = l.js.tr_mul(&l.js).symmetric_eigen();
    let emax = eig.eigenvalues.max().max(f64::MIN_POSITIVE);
    let b = l.js.tr_mul(&l.jp);
    let qb = eig.eigenvectors.tr_mul(&b);
    let qg = eig.eigenvectors.tr_mul(&l.js.tr_mul(&l.r));
    let (mut xb, mut xg) = (qb.clone(), qg);
    for (k, &e) in eig.eigenvalues.iter().enumerate() {
        let inv = if e > 1e-12 * emax { 1.0 / e } else { 0.0 };
        xb.row_mut(k).scale_mut(inv);
        xg.row_mut(k).scale_mut(inv);
    }
    let s = l.jp.tr_mul(&l.jp) - qb.tr_mul(&xb);
    let h = -(l.jp.tr_mul(&l.r) - qb.tr_mul(&xg));
    (s, h)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::integrate::{Integrator, SimSettings};
    use crate::model::Model;
    use crate::record::Quantity;
    use crate::update::{Metric, Observation, Parameter, Target};

    const STALL: Stall = Stall {
        steps: 3,
        gain: 1e-3,
    };

    /// Two masses, a spring to ground, a spring between them and a cubic
    /// spring from mass 2 to ground; accelerations at both.
    fn truth() -> Model {
        Model::from_toml_str(
            "masses = [1.0, 0.8]\n[[spring]]\ndofs = [1]\nstiffness = 2000.0\n[[spring]]\ndofs = [1, 2]\nstiffness = 1500.0\n[damping]\nkind = \"modal\"\nratio = 0.02\n[[cubic]]\ndofs = [2]\nk3 = 4.0e8\n",
            "two",
        )
        .unwrap()
    }

    /// A record of `model` under a multi-sine on mass 1, cut into ten
    /// 40-sample segments with their true start states, as a problem on
    /// `start` with no parameter.
    fn problem(model: &Model, start: &Model) -> Problem {
        let (fs, ns) = (200.0, 400);
        let force = DMatrix::from_fn(2, ns, |i, k| {
            let t = k as f64 / fs;
            if i == 0 {
                30.0 * ((2.0 * 3.0 * t).sin() + 0.7 * (2.0 * 7.3 * t + 1.0).sin())
            } else {
                0.0
            }
        });
        let sim = SimSettings::default();
        let run = Integrator::new(model, fs, sim).unwrap().run(
            force.columns(0, ns),
            &[0.0; 2],
            &[0.0; 2],
        );
        assert!(run.completed());
        let observations = (0..2)
            .map(|d| {
                let data: Vec<f64> = run.a.row(d).iter().copied().collect();
                let norm = data.iter().map(|v| v * v).sum::<f64>().sqrt();
                Observation {
                    quantity: Quantity::Accel,
                    dof: d + 1,
                    weight: 1.0 / norm,
                    data,
                    point: None,
                }
            })
            .collect();
        let segments = (0..10)
            .map(|i| Segment {
                start: 40 * i,
                len: 40,
                u0: (0..2).map(|d| run.u[(d, 40 * i)]).collect(),
                v0: (0..2).map(|d| run.v[(d, 40 * i)]).collect(),
            })
            .collect();
        Problem {
            model: start.clone(),
            fs,
            force,
            observations,
            parameters: vec![],
            segments,
            reduction: None,
            metric: Metric::Gls,
            alpha: 0.0,
            sim,
        }
    }

    /// k3 started 40 % low and every start state off by 10 % of its size:
    /// the joint fit recovers both (noise-free record).
    #[test]
    fn recovers_a_parameter_and_the_start_states_together() {
        let t = truth();
        let mut start = t.clone();
        start.cubics[0].k3 *= 0.6;
        let mut p = problem(&t, &start);
        let exact = p.segments.clone();
        for (i, s) in p.segments.iter_mut().enumerate() {
            let f = if i % 2 == 0 { 1.1 } else { 0.9 };
            s.u0.iter_mut().for_each(|u| *u *= f);
            s.v0.iter_mut().for_each(|v| *v *= 2.0 - f);
        }
        p.parameters = vec![Parameter::relative(&start, Target::CubicK3(0)).unwrap()];
        let settings = FitSettings {
            max_iterations: 40,
            ..Default::default()
        };
        let fit = fit(&p, &[0.0], &settings, STALL).unwrap();
        let k3 = p.model_at(&fit.x).cubics[0].k3;
        approx::assert_relative_eq!(k3, 4.0e8, max_relative = 1e-4);
        assert!(fit.cost.1 < 1e-8 * fit.cost.0, "{:?}", fit.cost);
        for (a, b) in fit.segments.iter().zip(&exact) {
            for d in 0..2 {
                approx::assert_relative_eq!(a.u0[d], b.u0[d], epsilon = 1e-7);
                approx::assert_relative_eq!(a.v0[d], b.v0[d], epsilon = 1e-5);
            }
        }
        assert_eq!(fit.segment_costs.len(), 10);
    }

    /// At a converged fit of k3 and the start states (as in the loop),
    /// the predicted gain of a spring stiffness is large when that spring
    /// is wrong and negligible when it is right.
    #[test]
    fn predicted_gain_tells_a_wrong_spring_from_a_right_one() {
        let t = truth();
        let gain = |model: &Model| {
            let mut p = problem(&t, model);
            p.parameters = vec![Parameter::relative(model, Target::CubicK3(0)).unwrap()];
            let settings = FitSettings {
                max_iterations: 40,
                ..Default::default()
            };
            let f = fit(&p, &[0.0], &settings, STALL).unwrap();
            p.segments = f.segments;
            p.parameters
                .push(Parameter::relative(model, Target::SpringStiffness(1)).unwrap());
            predicted_gain(&p, &[f.x[0], 0.0], 1).unwrap()
        };
        let mut soft = t.clone();
        soft.springs[1].stiffness *= 0.85;
        let (g, dx, sims) = gain(&soft);
        assert!(g > 0.5, "a 15 % softer spring: gain {g}");
        assert!((dx[1] - 0.15 / 0.85).abs() < 0.03, "step {dx:?}");
        assert_eq!(sims, 10);
        let mut cubic = t.clone();
        cubic.cubics[0].k3 *= 0.8;
        let (g, _, _) = gain(&cubic);
        assert!(g < 0.05, "a right spring: gain {g}");
    }

    /// The predicted standard error of k3 against the scatter of k3 fitted
    /// on twelve records with 1 % noise (start states fitted too).
    #[test]
    fn standard_errors_match_the_scatter_over_noisy_records() {
        let t = truth();
        let clean = problem(&t, &t);
        let mut seed = 12345u64;
        let mut gauss = move || {
            let mut u = || {
                seed = seed
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                ((seed >> 11) as f64 + 0.5) / (1u64 << 53) as f64
            };
            let (a, b) = (u(), u());
            (-2.0 * a.ln()).sqrt() * (2.0 * std::f64::consts::PI * b).cos()
        };
        let settings = FitSettings {
            max_iterations: 40,
            ..Default::default()
        };
        let mut fitted = vec![];
        let mut predicted = 0.0;
        for _ in 0..12 {
            let mut p = clean.clone();
            for o in &mut p.observations {
                let n = o.data.len() as f64;
                let rms = (o.data.iter().map(|v| v * v).sum::<f64>() / n).sqrt();
                o.data.iter_mut().for_each(|v| *v += 0.01 * rms * gauss());
            }
            p.parameters = vec![Parameter::relative(&t, Target::CubicK3(0)).unwrap()];
            let f = fit(&p, &[0.0], &settings, STALL).unwrap();
            fitted.push(p.model_at(&f.x).cubics[0].k3);
            p.segments = f.segments;
            predicted = std_errors(&p, &f.x, 0.01).unwrap()[0];
        }
        let mean = fitted.iter().sum::<f64>() / 12.0;
        let sd = (fitted.iter().map(|k| (k - mean).powi(2)).sum::<f64>() / 11.0).sqrt();
        let ratio = sd / predicted;
        assert!(
            (0.5..2.0).contains(&ratio),
            "scatter {sd:.3e}, predicted {predicted:.3e}"
        );
        assert!((mean / 4.0e8 - 1.0).abs() < 3.0 * predicted / 4.0e8);
    }

    /// k3 fitted with the start states on five groups of two segments:
    /// with the right linear part the groups agree (noise-free record);
    /// with the ground spring 5 % stiff (model error the noise-only
    /// standard error cannot see) they scatter by far more than the 1 %
    /// noise standard error, around the fit of all segments.
    #[test]
    fn segment_groups_scatter_under_model_error_only() {
        let t = truth();
        let spread = |model: &Model| {
            let mut p = problem(&t, model);
            p.parameters = vec![Parameter::relative(model, Target::CubicK3(0)).unwrap()];
            let settings = FitSettings {
                max_iterations: 40,
                ..Default::default()
            };
            let f = fit(&p, &[0.0], &settings, STALL).unwrap();
            let k3 = p.model_at(&f.x).cubics[0].k3;
            p.segments = f.segments;
            let u = uncertainty(&p, &f.x, 0.01, 5).unwrap();
            assert_eq!(u.groups.len(), 5);
            let g: Vec<f64> = u.groups.iter().map(|v| v[0]).collect();
            let mean = g.iter().sum::<f64>() / 5.0;
            let sd = (g.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / 4.0).sqrt();
            (k3, mean, sd, u.std_errors[0])
        };
        let (k3, mean, sd, se) = spread(&t);
        assert!(
            sd < 1e-4 * k3,
            "right model: groups {sd:.3e} around {k3:.4e}"
        );
        assert!((mean - k3).abs() < 1e-4 * k3, "{mean:.4e} vs {k3:.4e}");
        assert!(se > 0.0);
        let mut stiff = t.clone();
        stiff.springs[0].stiffness *= 1.05;
        let (k3, mean, sd, se) = spread(&stiff);
        assert!(
            sd > 10.0 * se,
            "wrong spring: groups {sd:.3e}, noise {se:.3e}"
        );
        assert!((mean - k3).abs() < sd, "{mean:.4e} vs {k3:.4e} ± {sd:.3e}");
    }
}
