//! Full-horizon force identification as optimal control (Hemez & Doebling
//! §7, ref. [17]): the unknown force history is the input of the linear
//! model, chosen over the whole record to track the measurements,
//!
//! $$ \min_{x_0, w_0 … w_{N−1}} \sum_k \|y_k − \hat y_k\|^2_W
//!   + λ \sum_k \|w_k\|^2 + μ \sum_k \|w_{k+1} − w_k\|^2
//!   + \|x_0 − \bar x_0\|^2_P $$
//!
//! subject to the exact sampled Newmark model with the measured input
//! ([`crate::linear::SampledModel`], force linear between samples in the
//! dynamics *and* in the output equation). It is stable by construction,
//! where the sequential window scheme is not (docs/theory.md, fact R1).
//!
//! - [`smoother`]: the Riccati sweep (equivalently the Rauch–Tung–Striebel
//!   smoother on the state `[x; w]`), time linear in N, steady-state gains
//!   once the recursion has converged, covariance for ±2σ bands;
//! - [`qp`]: with bounds, sign, equilibrium or pair constraints, one sparse
//!   banded QP over the whole horizon in Clarabel;
//! - [`select`]: λ, μ by GCV, L-curve or the discrepancy principle;
//! - [`batch`]: the dense least-squares solution for small problems (tests).
//!
//! The identified force is on the right-hand side, `M a + C v + K u =
//! g + B_u w`: for a missing internal force of the simulator's convention
//! (`… + f_int = f_ext`), `B_u w ≈ −f_int`.
//!
//! The front door is [`identify`]; see `docs/horizon.md`.

mod assemble;
mod basis;
pub mod batch;
pub mod convert;
mod covariance;
pub mod problem;
pub mod qp;
pub mod select;
pub mod settings;
pub mod smoother;

pub use problem::{unknown_at_dofs, HorizonData};
pub use settings::{
    ChannelNoise, CovarianceScale, ForceConstraints, HorizonSettings, InitialState, NoiseLevel,
    WeightSelection,
};

use crate::error::Result;
use crate::linear::SampledModel;
use assemble::Sink;
use nalgebra::DMatrix;
use problem::Lq;
use serde::Serialize;
use std::time::Instant;

/// Floor of the tolerance on the held covariance (relative error of the
/// held force variances and output trace).
pub(crate) const COVARIANCE_TOL: f64 = 1e-10;

/// How the identification ended. Numerical trouble is reported here, never
/// as a panic; the result then says what could still be computed.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "status", rename_all = "snake_case")]
pub enum HorizonStatus {
    /// Solved exactly (up to rounding, or to the QP tolerance).
    Solved,
    /// The Riccati recursion had not converged after `steps` samples (last
    /// relative change `change`); its last gain was used for the earlier
    /// samples, so the answer is approximate there.
    RiccatiNotConverged {
        /// Transient length, samples.
        steps: usize,
        /// Relative change of the Riccati matrix at the last step.
        change: f64,
    },
    /// The initial-state system was singular: `dropped` directions were
    /// left at the minimum-norm solution.
    RankDeficient {
        /// Number of undetermined directions.
        dropped: usize,
    },
    /// A matrix that must be positive definite was not (transition
    /// `sample`); no answer (all outputs NaN).
    NotPositiveDefinite {
        /// Transition index.
        sample: usize,
    },
    /// The QP solver stopped without a full-accuracy solution.
    QpNotSolved {
        /// Clarabel's status.
        solver_status: String,
    },
}

/// The weights used and how they were chosen.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SelectedWeights {
    /// λ used.
    pub lambda: f64,
    /// μ used.
    pub mu: f64,
    /// The rule.
    pub selection: WeightSelection,
    /// Value of the rule's criterion at the chosen weights (GCV value,
    /// L-curve curvature, or residual / target for the discrepancy
    /// principle); NaN for fixed weights.
    pub criterion: f64,
    /// Every evaluation of the search, by increasing λ.
    pub candidates: Vec<Candidate>,
}

/// One evaluation of the weight search.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Candidate {
    /// λ.
    pub lambda: f64,
    /// μ.
    pub mu: f64,
    /// Weighted residual `‖r‖²_W`.
    pub rss: f64,
    /// `Σ‖w_k‖²`, N².
    pub force_norm2: f64,
    /// `tr H` (NaN when not computed).
    pub tr_h: f64,
    /// GCV value (NaN when not computed).
    pub gcv: f64,
}

/// Wall-clock time of each stage, s.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct Timings {
    /// Building the scaled problem.
    pub setup: f64,
    /// Backward Riccati pass.
    pub backward: f64,
    /// Forward pass (states, forces).
    pub forward: f64,
    /// Covariance pass.
    pub covariance: f64,
    /// Weight selection (all candidate solves).
    pub selection: f64,
    /// QP solve (constrained problems).
    pub qp: f64,
    /// Total.
    pub total: f64,
}

/// Which solver produced the answer.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Solver {
    /// The Riccati sweep (no constraints).
    Riccati,
    /// Clarabel QP (constraints).
    Qp,
}

/// Diagnostics of one identification.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Diagnostics {
    /// Solver used.
    pub solver: Solver,
    /// Cost J at the answer.
    pub cost: f64,
    /// Weighted residual `‖r‖²_W`.
    pub rss: f64,
    /// Relative residual `‖y − ŷ‖ / ‖y‖` per channel.
    pub relative_residual: Vec<f64>,
    /// Relative residual over all channels.
    pub relative_residual_total: f64,
    /// Trace of the influence matrix (effective number of fitted
    /// parameters); NaN without covariance.
    pub tr_h: f64,
    /// Estimated variance of unit weight `‖r‖²_W / (N p − tr H)`.
    pub variance_factor: f64,
    /// Samples computed with exact (non-steady) gains at the end.
    pub riccati_transient: usize,
    /// Whether the Riccati recursion converged (or covered the record).
    pub riccati_converged: bool,
    /// Relative distance (max norm) of the held Riccati matrix (the last
    /// exact one) to the fixed point solved for by Newton's method: at
    /// most `riccati_tol`, or at the fixed point's own accuracy when the
    /// gain was held on the change rule; 0 when nothing is held (the record
    /// is shorter than the transient, or the constrained QP answered), NaN
    /// when the fixed point could not be solved for (see
    /// `horizon::riccati`'s docs).
    pub riccati_held_distance: f64,
    /// Sample from which the covariance was held at its steady value.
    pub covariance_held_from: Option<usize>,
    /// States (0-based index in `[u; v]`) the data do not determine (a
    /// component along a rigid-body direction no channel sees); their std
    /// is NaN.
    pub undetermined_states: Vec<usize>,
    /// QP iterations (0 for the Riccati sweep).
    pub qp_iterations: u32,
}

/// The answer of [`identify`].
#[derive(Debug, Clone)]
pub struct HorizonResult {
    /// Identified force coefficients `w` (n_f × N), N.
    pub force: DMatrix<f64>,
    /// Their posterior standard deviation (n_f × N); for constrained
    /// problems that of the unconstrained problem.
    pub force_std: Option<DMatrix<f64>>,
    /// The DOF forces `B_u w` (n × N), N (right-hand-side convention).
    pub dof_force: DMatrix<f64>,
    /// States `[u; v]` (2n × N).
    pub states: DMatrix<f64>,
    /// Their standard deviation (NaN for undetermined states).
    pub state_std: Option<DMatrix<f64>>,
    /// Predicted outputs `ŷ` (p × N).
    pub predicted: DMatrix<f64>,
    /// Residuals `y − ŷ` (p × N).
    pub residual: DMatrix<f64>,
    /// Weights used and how they were chosen.
    pub weights: SelectedWeights,
    /// How it ended.
    pub status: HorizonStatus,
    /// Human-readable notes on anything the status does not say.
    pub notes: Vec<String>,
    /// Diagnostics.
    pub diagnostics: Diagnostics,
    /// Timings.
    pub timings: Timings,
}

/// Identify the unknown forces over the whole record (see the module docs):
/// choose the weights, then solve by the Riccati sweep, or by the QP when
/// constraints are set.
///
/// Errors are for bad input (sizes, settings); numerical trouble is a
/// [`HorizonStatus`] in the result.
pub fn identify(
    model: &SampledModel,
    data: &HorizonData<'_>,
    settings: &HorizonSettings,
) -> Result<HorizonResult> {
    settings.validate()?;
    let t0 = Instant::now();
    let (lambda, mu, weights, t_sel) = select::choose(model, data, settings)?;
    let mut res = if settings.constraints.is_empty() {
        solve(model, data, settings, lambda, mu, settings.covariance)?
    } else {
        qp::solve_constrained(model, data, settings, lambda, mu)?
    };
    res.weights = weights;
    res.timings.selection = t_sel;
    res.timings.total = t0.elapsed().as_secs_f64();
    Ok(res)
}

/// One solve with fixed weights by the Riccati sweep (no selection, no
/// constraints). `covariance` turns the covariance pass on.
pub fn solve(
    model: &SampledModel,
    data: &HorizonData<'_>,
    settings: &HorizonSettings,
    lambda: f64,
    mu: f64,
    covariance: bool,
) -> Result<HorizonResult> {
    let t0 = Instant::now();
    let lq = Lq::new(model, data, settings, lambda, mu)?;
    let mut tm = Timings {
        setup: t0.elapsed().as_secs_f64(),
        ..Default::default()
    };
    let fixed = SelectedWeights {
        lambda,
        mu,
        selection: WeightSelection::Fixed,
        criterion: f64::NAN,
        candidates: vec![],
    };
    let t1 = Instant::now();
    let sys = basis::Sys::new(&lq);
    let mut bw = match smoother::backward(&lq, &sys, settings) {
        Ok(b) => b,
        Err(e) => return Ok(failed(&lq, data, fixed, e.k)),
    };
    tm.backward = t1.elapsed().as_secs_f64();
    let t2 = Instant::now();
    let (z0, sig0, dropped) = match smoother::initial_state(&lq, &sys, &bw) {
        Ok(v) => v,
        Err(e) => return Ok(failed(&lq, data, fixed, e.k)),
    };
    let lff = std::mem::replace(&mut bw.lff, DMatrix::zeros(0, 0));
    let mut sink = Sink::new(&lq, data, Some(&sys.wx), lff);
    smoother::forward(&lq, &sys, &bw, &z0, &mut sink);
    tm.forward = t2.elapsed().as_secs_f64();
    let t3 = Instant::now();
    let cov_tol = settings.riccati_tol.max(COVARIANCE_TOL);
    let cov = covariance.then(|| self::covariance::covariance(&lq, &sys, &bw, sig0, cov_tol));
    tm.covariance = t3.elapsed().as_secs_f64();
    let mut res = sink.finish(settings, cov, fixed);
    res.diagnostics.riccati_transient = bw.transient.len();
    res.diagnostics.riccati_converged = bw.converged;
    res.diagnostics.riccati_held_distance = bw.held_distance;
    if !bw.converged {
        res.status = HorizonStatus::RiccatiNotConverged {
            steps: bw.transient.len(),
            change: bw.last_change,
        };
        res.notes.push(format!(
            "the Riccati recursion did not converge within {} samples (relative change {:.2e}); raise max_transient or riccati_tol",
            bw.transient.len(),
            bw.last_change
        ));
    } else if dropped > 0 {
        res.status = HorizonStatus::RankDeficient { dropped };
        res.notes.push(format!(
            "{dropped} direction(s) of the initial state are determined neither by the data nor by the prior; minimum-norm values used"
        ));
    }
    if sys.dropped_coupling > 1e-10 {
        res.notes.push(format!(
            "the unseen rigid-body directions are invariant under the sampled model only to {:.1e} (relative); that coupling was dropped",
            sys.dropped_coupling
        ));
    }
    if lq.hidden.ncols() > 0 {
        res.notes.push(format!(
            "{} rigid-body direction(s) of the state are not seen by the channels: they are set by the initial-state prior",
            lq.hidden.ncols()
        ));
    }
    let undetermined = &res.diagnostics.undetermined_states;
    if !undetermined.is_empty() {
        let note = format!(
            "{} state(s) are not determined by the data (set by the initial-state prior, their variance grows without bound): their std is NaN: {:?}",
            undetermined.len(),
            undetermined
        );
        res.notes.push(note);
    }
    tm.total = t0.elapsed().as_secs_f64();
    res.timings = tm;
    Ok(res)
}

fn failed(lq: &Lq, data: &HorizonData<'_>, weights: SelectedWeights, k: usize) -> HorizonResult {
    let nan = |r, c| DMatrix::from_element(r, c, f64::NAN);
    let (nx, m, p, len) = (lq.nx, lq.m, lq.p, lq.len);
    HorizonResult {
        force: nan(m, len),
        force_std: None,
        dof_force: nan(data.unknown.nrows(), len),
        states: nan(nx, len),
        state_std: None,
        predicted: nan(p, len),
        residual: nan(p, len),
        weights,
        status: HorizonStatus::NotPositiveDefinite { sample: k },
        notes: vec![format!(
            "the Riccati recursion met a matrix that is not positive definite at transition {k}"
        )],
        diagnostics: Diagnostics {
            solver: Solver::Riccati,
            cost: f64::NAN,
            rss: f64::NAN,
            relative_residual: vec![f64::NAN; p],
            relative_residual_total: f64::NAN,
            tr_h: f64::NAN,
            variance_factor: f64::NAN,
            riccati_transient: 0,
            riccati_converged: false,
            riccati_held_distance: f64::NAN,
            covariance_held_from: None,
            undetermined_states: vec![],
            qp_iterations: 0,
        },
        timings: Timings::default(),
    }
}
