//! Time-domain parametric model updating (paper §5, §6.1).
//!
//! Adjust parameters `p` of a [`Model`] (spring stiffnesses, masses,
//! damping, contact gap and stiffness, friction level, cubic coefficient)
//! so that simulated responses match a record:
//!
//! 1. simulate the model at `p` (eq. 8) over each segment of the record,
//!    from the segment's start state ([`shooting`]), on the full-order or
//!    the reduced model ([`forward`]);
//! 2. form the residual at the chosen DOFs and samples: GLS (eq. 9) or PCD
//!    (eqs 11–12) ([`cost`]);
//! 3. minimise `‖r‖² + α‖x − x0‖²` (eq. 10, squared) with Levenberg–Marquardt,
//!    Gauss–Newton, BFGS or the simplex ([`optimize`]), with bounds and
//!    derivatives from forward sensitivities of the integrator
//!    ([`sensitivity`]; full-order problems) or centered finite
//!    differences ([`JacobianMethod`]);
//! 4. report the parameters, the errors before and after, and whether the
//!    data determine them ([`identifiability`]).
//!
//! The front door is [`fit`] (one start) or [`fit_multistart`]. A failed
//! simulation inside the search is a rejected trial, never a large cost;
//! the result says how the search ended. Everything is single-threaded and
//! deterministic: the same problem gives the same result bit for bit.
//!
//! ```no_run
//! use tacit::update::{self, Parameter, Problem, Target, FitSettings};
//! # fn main() -> tacit::Result<()> {
//! # let (model, record): (tacit::model::Model, tacit::record::Record) = todo!();
//! let params = vec![
//!     Parameter::relative(&model, Target::SpringStiffness(2))?,
//!     Parameter::relative(&model, Target::CubicK3(0))?,
//! ];
//! let u0 = vec![0.0; model.ndof()];
//! let problem = Problem::from_record(&model, &record, &[tacit::record::Quantity::Disp],
//!     None, params, u0.clone(), u0)?;
//! let result = update::fit(&problem, &FitSettings::default())?;
//! println!("{:?}", result.percent_changes());
//! # Ok(()) }
//! ```

pub mod cost;
pub mod figures;
pub mod forward;
pub mod identifiability;
pub mod optimize;
pub mod param;
pub mod problem;
pub mod sensitivity;
pub mod shooting;

pub use forward::Failure;
pub use identifiability::Identifiability;
pub use optimize::{FitSettings, JacobianMethod, Optimizer, Termination};
pub use param::{parse_free, Parameter, Scaling, Target};
pub use problem::{Metric, Observation, Problem};
pub use shooting::Segment;

use crate::error::Result;
use crate::model::Model;
use cost::{Counters, Evaluator};
use serde::Serialize;

/// A fitted parameter.
#[derive(Debug, Clone, Serialize)]
pub struct FittedParameter {
    /// Name.
    pub name: String,
    /// What it is.
    pub target: Target,
    /// Nominal value p0.
    pub nominal: f64,
    /// Start of the search.
    pub start: f64,
    /// Final value.
    pub value: f64,
    /// Change from nominal, % (NaN for a zero nominal value).
    pub percent_change: f64,
    /// Lower bound.
    pub lower: f64,
    /// Upper bound.
    pub upper: f64,
    /// True when the value is within 1e-6 (scaled) of a bound.
    pub at_bound: bool,
}

/// Relative error of one channel.
#[derive(Debug, Clone, Serialize)]
pub struct ChannelError {
    /// Channel name, e.g. `disp_4`.
    pub channel: String,
    /// `‖ŷ − y‖₂ / ‖y‖₂` over the simulated samples.
    pub relative_error: f64,
}

/// Relative errors of every channel and over all of them.
#[derive(Debug, Clone, Serialize)]
pub struct ErrorReport {
    /// Per channel.
    pub channels: Vec<ChannelError>,
    /// Over all channels: `√(Σ‖ŷ − y‖² / Σ‖y‖²)` with each channel scaled by
    /// its weight.
    pub overall: f64,
}

/// Everything a fit did.
#[derive(Debug, Clone, Serialize)]
pub struct FitResult {
    /// Fitted parameters.
    pub parameters: Vec<FittedParameter>,
    /// Final scaled parameters.
    pub x: Vec<f64>,
    /// Optimizer used.
    pub optimizer: Optimizer,
    /// Jacobian method used (the requested one, or finite differences
    /// where sensitivities do not apply; see `jacobian_note`).
    pub jacobian: JacobianMethod,
    /// Why the Jacobian method differs from the requested one (None: it
    /// does not).
    pub jacobian_note: Option<String>,
    /// Metric used.
    pub metric: Metric,
    /// Reduction used (None: full order).
    pub reduction: Option<crate::reduce::Method>,
    /// How the search ended.
    pub termination: Termination,
    /// Iterations.
    pub iterations: usize,
    /// Cost evaluations (parameter vectors) by the optimizer.
    pub evaluations: usize,
    /// Segment simulations, all included (optimizer, final Jacobian, error
    /// reports); a simulation with sensitivities counts as one.
    pub simulations: usize,
    /// Jacobians computed (optimizer and identifiability report).
    pub jacobians: usize,
    /// Of `simulations`, those run with forward sensitivities (each costs
    /// about 1.8–2.3× a plain simulation for two parameters; see
    /// docs/updating.md).
    pub sensitivity_simulations: usize,
    /// Sensitivity Jacobians that failed and were replaced by finite
    /// differences.
    pub sensitivity_fallbacks: usize,
    /// Wall time spent in Jacobians (any method), s.
    pub jacobian_s: f64,
    /// Rejected trial points whose evaluation failed.
    pub failed_trials: usize,
    /// Cost J at the start and after each iteration.
    pub cost_history: Vec<f64>,
    /// Relative errors at the start.
    pub errors_before: Option<ErrorReport>,
    /// Relative errors at the solution.
    pub errors_after: Option<ErrorReport>,
    /// Identifiability at the solution (None when its Jacobian failed).
    pub identifiability: Option<Identifiability>,
    /// Relative difference between the reduced and the full-order responses
    /// at the solution (None for full order).
    pub reduction_error: Option<f64>,
    /// Wall time, s.
    pub elapsed_s: f64,
    /// The model at the fitted values.
    #[serde(skip)]
    pub model: Model,
}

impl FitResult {
    /// Percent changes of the parameters, in order.
    pub fn percent_changes(&self) -> Vec<f64> {
        self.parameters.iter().map(|p| p.percent_change).collect()
    }
    /// Final values, in order.
    pub fn values(&self) -> Vec<f64> {
        self.parameters.iter().map(|p| p.value).collect()
    }
    /// Final cost.
    pub fn cost(&self) -> f64 {
        self.cost_history.last().copied().unwrap_or(f64::NAN)
    }
}

/// Fit the problem from its parameters' start values.
pub fn fit(problem: &Problem, settings: &FitSettings) -> Result<FitResult> {
    problem.validate()?;
    settings.validate()?;
    let t0 = std::time::Instant::now();
    let mut ev = Evaluator::new(problem);
    let x0 = problem.x_start();
    let (lo, hi) = problem.x_bounds();
    let out = optimize::minimize(&mut ev, &x0, &lo, &hi, settings);
    let evaluations = ev.evaluations;
    let mut work = ev.counters();
    let (errors_before, n1) = error_report(problem, &x0);
    let (errors_after, n2) = error_report(problem, &out.x);
    let (identifiability, w3) = if matches!(out.termination, Termination::StartFailed { .. }) {
        (None, Default::default())
    } else {
        identify(problem, &out.x, settings)
    };
    work += w3;
    work.simulations += n1 + n2;
    let (jacobian, jacobian_note) = settings.jacobian.resolve(problem);
    let reduction_error = forward::reduction_error(problem, &out.x);
    if reduction_error.is_some() {
        work.simulations += 2 * problem.segments.len();
    }
    let parameters = problem
        .parameters
        .iter()
        .zip(&out.x)
        .map(|(p, &x)| {
            let value = p.from_x(x);
            FittedParameter {
                name: p.name.clone(),
                target: p.target,
                nominal: p.nominal,
                start: p.start,
                value,
                percent_change: p.percent(value),
                lower: p.lower,
                upper: p.upper,
                at_bound: x <= p.to_x(p.lower) + 1e-6 || x >= p.to_x(p.upper) - 1e-6,
            }
        })
        .collect();
    Ok(FitResult {
        parameters,
        model: problem.model_at(&out.x),
        x: out.x,
        optimizer: settings.optimizer,
        jacobian,
        jacobian_note,
        metric: problem.metric,
        reduction: problem.reduction,
        termination: out.termination,
        iterations: out.iterations,
        evaluations,
        simulations: work.simulations,
        jacobians: work.jacobians,
        sensitivity_simulations: work.sensitivity_simulations,
        sensitivity_fallbacks: work.sensitivity_fallbacks,
        jacobian_s: work.jacobian_seconds,
        failed_trials: out.failed_trials,
        cost_history: out.history,
        errors_before,
        errors_after,
        identifiability,
        reduction_error,
        elapsed_s: t0.elapsed().as_secs_f64(),
    })
}

/// An error with the facts when the fit's result cannot stand for the
/// record: the model could not be simulated at its start values, the
/// fitted model cannot be simulated over the record's segments, or the
/// cost, a parameter or an error is not finite, or the fitted model's
/// simulation diverges (its energy above what the force can put in).
/// `what` names the fit in the message (`the updating of REC`).
pub fn usable(problem: &Problem, r: &FitResult, what: &str) -> Result<()> {
    let names = || -> String {
        r.parameters
            .iter()
            .map(|p| format!("{} = {:e}", p.name, p.value))
            .collect::<Vec<_>>()
            .join(", ")
    };
    if let Termination::StartFailed { failure } = &r.termination {
        return Err(crate::TacitError::Numerical(format!(
            "{what}: the model at the start values ({}) cannot be simulated on the record ({failure}); nothing was fitted",
            names()
        )));
    }
    let Some(after) = &r.errors_after else {
        return Err(crate::TacitError::Numerical(format!(
            "{what}: the fitted model ({}) cannot be simulated over the record's segments ({}); its errors and responses would be meaningless, so no result is given",
            names(),
            r.termination.words()
        )));
    };
    if let Some(d) = forward::divergence(problem, &r.x) {
        return Err(crate::TacitError::Numerical(format!(
            "{what}: the fitted model ({}) cannot be simulated on the record: {d}",
            names()
        )));
    }
    let before = r.errors_before.as_ref().map_or(f64::NAN, |e| e.overall);
    let bad_param = r.parameters.iter().find(|p| !p.value.is_finite());
    if !r.cost().is_finite() || bad_param.is_some() || !after.overall.is_finite() {
        return Err(crate::TacitError::Numerical(format!(
            "{what}: the fit gave non-finite results (cost {:e}; {}; relative error {:e} -> {:e}; {}): the record or the model is out of double precision's range",
            r.cost(),
            names(),
            before,
            after.overall,
            r.termination.words()
        )));
    }
    Ok(())
}

/// Fit from several starts (scaled changes, one vector per start, e.g.
/// `[-0.3, 0.3]` for −30 % / +30 % on relative parameters) and return every
/// result with the index of the lowest final cost among the runs that did
/// not fail at their start (None if all did).
pub fn fit_multistart(
    problem: &Problem,
    settings: &FitSettings,
    starts: &[Vec<f64>],
) -> Result<(Option<usize>, Vec<FitResult>)> {
    let mut results = Vec::with_capacity(starts.len());
    for (k, s) in starts.iter().enumerate() {
        results.push(fit(&at_start(problem, k, s)?, settings)?);
    }
    let best = results
        .iter()
        .enumerate()
        .filter(|(_, r)| r.cost().is_finite())
        .min_by(|a, b| a.1.cost().total_cmp(&b.1.cost()))
        .map(|(i, _)| i);
    Ok((best, results))
}

/// Where a fit from one start ends, without the reports [`fit`] adds
/// (errors before and after, identifiability): [`race`] keeps only this.
#[derive(Debug, Clone)]
pub struct Raced {
    /// Final scaled parameters.
    pub x: Vec<f64>,
    /// Cost after each iteration, the start first.
    pub cost_history: Vec<f64>,
    /// How it ended.
    pub termination: Termination,
    /// Iterations.
    pub iterations: usize,
    /// Segment simulations run.
    pub simulations: usize,
}

impl Raced {
    /// Final cost (NaN when the start failed).
    pub fn cost(&self) -> f64 {
        self.cost_history.last().copied().unwrap_or(f64::NAN)
    }
}

/// The minimization of [`fit_multistart`] from each start (scaled
/// changes, one vector per start), in order, without the reports of
/// [`fit`]: the same end points, costs and iterations, in fewer
/// simulations (a start race needs only where each start ends).
pub fn race(problem: &Problem, settings: &FitSettings, starts: &[Vec<f64>]) -> Result<Vec<Raced>> {
    settings.validate()?;
    let mut out = Vec::with_capacity(starts.len());
    for (k, s) in starts.iter().enumerate() {
        let p = at_start(problem, k, s)?;
        p.validate()?;
        let mut ev = Evaluator::new(&p);
        ev.keep_tapes = settings.jacobian.resolve(&p).0 == JacobianMethod::Sensitivity;
        let (lo, hi) = p.x_bounds();
        let o = optimize::minimize(&mut ev, &p.x_start(), &lo, &hi, settings);
        out.push(Raced {
            x: o.x,
            cost_history: o.history,
            termination: o.termination,
            iterations: o.iterations,
            simulations: ev.counters().simulations,
        });
    }
    Ok(out)
}

/// `problem` with its parameters started at the scaled changes `s` (start
/// `k`, named in the error when `s` has the wrong length).
fn at_start(problem: &Problem, k: usize, s: &[f64]) -> Result<Problem> {
    if s.len() != problem.parameters.len() {
        return Err(crate::TacitError::Setting(format!(
            "start {k} has {} values, the problem {} parameters",
            s.len(),
            problem.parameters.len()
        )));
    }
    let mut p = problem.clone();
    for (prm, &x) in p.parameters.iter_mut().zip(s) {
        prm.start = prm.from_x(x).clamp(prm.lower, prm.upper);
    }
    Ok(p)
}

/// Simulated channels at `x` over the whole record (NaN outside the
/// segments), one vector per observation; `Err` when a simulation fails.
pub fn predict(problem: &Problem, x: &[f64]) -> std::result::Result<Vec<Vec<f64>>, Failure> {
    let (resp, _) = forward::simulate(problem, x);
    let resp = resp?;
    let n = problem.samples();
    let mut out = vec![vec![f64::NAN; n]; problem.observations.len()];
    for (seg, y) in problem.segments.iter().zip(&resp) {
        for (r, row) in out.iter_mut().enumerate() {
            for k in 0..y.ncols() {
                row[seg.start + k] = y[(r, k)];
            }
        }
    }
    Ok(out)
}

/// Per-channel relative errors at `x` and the simulations spent.
fn error_report(problem: &Problem, x: &[f64]) -> (Option<ErrorReport>, usize) {
    let (resp, n) = forward::simulate(problem, x);
    let Ok(resp) = resp else {
        return (None, n);
    };
    let mut channels = Vec::new();
    let (mut tn, mut td) = (0.0, 0.0);
    for (r, o) in problem.observations.iter().enumerate() {
        let (mut num, mut den) = (0.0, 0.0);
        for (seg, y) in problem.segments.iter().zip(&resp) {
            for k in 0..y.ncols() {
                let m = o.data[seg.start + k];
                num += (y[(r, k)] - m).powi(2);
                den += m * m;
            }
        }
        tn += num * o.weight * o.weight;
        td += den * o.weight * o.weight;
        channels.push(ChannelError {
            channel: o.name(),
            relative_error: crate::metrics::ratio(num, den),
        });
    }
    let overall = crate::metrics::ratio(tn, td);
    (Some(ErrorReport { channels, overall }), n)
}

/// Identifiability on the GLS residual at `x` (Jacobian by the method of
/// `s`); returns the report and the work spent.
fn identify(problem: &Problem, x: &[f64], s: &FitSettings) -> (Option<Identifiability>, Counters) {
    let gls = Problem {
        metric: Metric::Gls,
        alpha: 0.0,
        ..problem.clone()
    };
    let mut ev = Evaluator::new(&gls);
    let Ok(r0) = ev.residual(x) else {
        return (None, ev.counters());
    };
    let (lo, hi) = gls.x_bounds();
    let jac = optimize::jacobian_with(&mut ev, x, &r0, &lo, &hi, s);
    let sims = ev.counters();
    let Ok(jac) = jac else {
        return (None, sims);
    };
    // residual rows are ordered sample-major within a segment (column-major
    // observation × sample matrices)
    let rms: Vec<f64> = gls
        .observations
        .iter()
        .map(|o| o.noise_std(s.noise_level))
        .collect();
    let mut sig = Vec::with_capacity(r0.len());
    for seg in &gls.segments {
        for _ in 0..seg.len {
            sig.extend(&rms);
        }
    }
    let rep = identifiability::report(&jac, &sig, &gls.parameters, s.noise_level, s.determined_tol);
    (Some(rep), sims)
}
