//! The optimizers of §5.1: Nelder–Mead simplex (order zero), Gauss–Newton,
//! BFGS and Levenberg–Marquardt (order one), all with bounds. The
//! derivatives ([`JacobianMethod`]) come from forward sensitivities of the
//! integrator (one simulation per segment gives the Jacobian) where the
//! problem allows it, else from centered finite differences (the paper's
//! choice, two simulations per parameter and segment).
//!
//! They minimise `J(x) = ‖r(x)‖²` over the box `lo ≤ x ≤ hi` of scaled
//! parameters. A failed model evaluation (a simulation that stops, a
//! non-finite residual) is never turned into a large number: the trial
//! point is rejected (Levenberg–Marquardt raises its damping, the line
//! searches shorten the step, the simplex contracts) and counted in
//! `failed_trials`.
//!
//! Levenberg–Marquardt and Gauss–Newton run on the crate's bounded
//! least-squares driver ([`crate::lsq`]; this module supplies the
//! residual, its Jacobian and the normal-equation solves); BFGS and the
//! simplex are here. Why not the `levenberg-marquardt` crate: it has no
//! bounds and aborts the whole run when one evaluation fails.
//! References: Nocedal & Wright, *Numerical Optimization* (2006): ch. 10
//! (Gauss–Newton, Levenberg–Marquardt), ch. 6 (BFGS), ch. 9 (Nelder–Mead);
//! Lagarias et al. (1998) for the simplex coefficients.

use super::cost::Evaluator;
use super::forward::Failure;
use crate::lsq;
use nalgebra::{DMatrix, DVector};
use serde::Serialize;

/// Optimization method.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
pub enum Optimizer {
    /// Levenberg–Marquardt with Marquardt's diagonal scaling.
    Lm,
    /// Gauss–Newton with a backtracking line search.
    Gn,
    /// BFGS (quasi-Newton) on the gradient `2 Jᵀ r` of J.
    Bfgs,
    /// Nelder–Mead simplex.
    Simplex,
}

/// How the Jacobian of the residual is computed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, serde::Deserialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
pub enum JacobianMethod {
    /// Forward sensitivities of the integrator
    /// ([`super::cost::Evaluator::sensitivity_jacobian`]): one simulation
    /// per segment. Full-order problems only; a reduced problem (whose
    /// basis depends on the parameters) falls back to
    /// [`JacobianMethod::CentralDifference`], and so does a single
    /// evaluation whose sensitivities fail. PCD residuals are
    /// differentiated along the sensitivities by differences of the
    /// residual map (no simulation).
    #[value(name = "sens")]
    Sensitivity,
    /// Centered finite differences of step `fd_step (1 + |x|)` (one-sided
    /// at a bound): two simulations per parameter and segment.
    #[value(name = "fd")]
    CentralDifference,
}

impl JacobianMethod {
    /// The method used for `problem` when `self` is requested, and why it
    /// differs (if it does).
    pub fn resolve(self, problem: &super::Problem) -> (JacobianMethod, Option<String>) {
        match (self, super::sensitivity::unsupported(problem)) {
            (JacobianMethod::Sensitivity, Some(why)) => (
                JacobianMethod::CentralDifference,
                Some(format!("finite differences: {why}")),
            ),
            (m, _) => (m, None),
        }
    }
}

/// Settings of the optimizers.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct FitSettings {
    /// Method (default Levenberg–Marquardt).
    pub optimizer: Optimizer,
    /// Iteration limit (default 100; simplex: 400).
    pub max_iterations: usize,
    /// Limit on cost evaluations (parameter vectors simulated), default 5000.
    pub max_evaluations: usize,
    /// Converged when a step changes every scaled parameter by less than
    /// `x_tol (1 + |x|)` (default 1e-7).
    pub x_tol: f64,
    /// Converged when an accepted step lowers J by less than `f_tol J`
    /// (default 1e-10).
    pub f_tol: f64,
    /// Converged when the projected gradient of J is below `g_tol`
    /// (default 1e-12; J is dimensionless).
    pub g_tol: f64,
    /// Jacobian method (default [`JacobianMethod::Sensitivity`], with the
    /// fallbacks it documents).
    pub jacobian: JacobianMethod,
    /// Step of the centered differences in scaled parameters (default
    /// 1e-5; also the step of the PCD residual's differences along the
    /// sensitivities).
    pub fd_step: f64,
    /// Initial Levenberg–Marquardt damping relative to `diag(JᵀJ)`
    /// (default 1e-3).
    pub lm_lambda: f64,
    /// Edge of the initial simplex in scaled parameters (default 0.05).
    pub simplex_size: f64,
    /// Relative noise level (fraction of each channel's RMS) assumed by the
    /// identifiability report (default 0.01).
    pub noise_level: f64,
    /// A parameter is "determined" when its standard deviation at
    /// `noise_level` is below this many scaled units (default 0.005, i.e.
    /// 0.5 percentage points for relative parameters).
    pub determined_tol: f64,
}

impl Default for FitSettings {
    fn default() -> Self {
        FitSettings {
            optimizer: Optimizer::Lm,
            max_iterations: 100,
            max_evaluations: 5000,
            x_tol: 1e-7,
            f_tol: 1e-10,
            g_tol: 1e-12,
            jacobian: JacobianMethod::Sensitivity,
            fd_step: 1e-5,
            lm_lambda: 1e-3,
            simplex_size: 0.05,
            noise_level: 0.01,
            determined_tol: 0.005,
        }
    }
}

impl FitSettings {
    /// Defaults with another optimizer (and the simplex's larger
    /// iteration limit).
    pub fn with(optimizer: Optimizer) -> FitSettings {
        let max_iterations = if optimizer == Optimizer::Simplex {
            400
        } else {
            100
        };
        FitSettings {
            optimizer,
            max_iterations,
            ..Default::default()
        }
    }

    /// Check every field; the error repeats the rule.
    pub fn validate(&self) -> crate::Result<()> {
        let bad = |m: &str| Err(crate::TacitError::Setting(format!("fit settings: {m}")));
        if self.max_iterations == 0 || self.max_evaluations == 0 {
            return bad("max_iterations and max_evaluations must be >= 1");
        }
        for (name, v) in [
            ("x_tol", self.x_tol),
            ("f_tol", self.f_tol),
            ("fd_step", self.fd_step),
            ("lm_lambda", self.lm_lambda),
            ("simplex_size", self.simplex_size),
            ("determined_tol", self.determined_tol),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return bad(&format!("{name} = {v} must be finite and > 0"));
            }
        }
        if !(self.g_tol.is_finite() && self.g_tol >= 0.0) {
            return bad(&format!("g_tol = {} must be >= 0", self.g_tol));
        }
        if !(self.noise_level.is_finite() && self.noise_level > 0.0) {
            return bad(&format!("noise_level = {} must be > 0", self.noise_level));
        }
        Ok(())
    }
}

/// How an optimization ended.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "status", rename_all = "snake_case")]
pub enum Termination {
    /// A convergence test passed.
    Converged {
        /// `step`, `cost`, `gradient` or `simplex`.
        criterion: String,
    },
    /// `max_iterations` reached.
    IterationLimit,
    /// `max_evaluations` reached.
    EvaluationLimit,
    /// No acceptable step could be found (e.g. every trial failed or none
    /// lowered the cost).
    Stalled {
        /// Why.
        reason: String,
    },
    /// The model could not be evaluated at the start.
    StartFailed {
        /// The failure.
        failure: Failure,
    },
}

impl Termination {
    /// True for [`Termination::Converged`].
    pub fn converged(&self) -> bool {
        matches!(self, Termination::Converged { .. })
    }

    /// How the search ended, in words (no type names).
    pub fn words(&self) -> String {
        match self {
            Termination::Converged { criterion } => format!("converged ({criterion} test)"),
            Termination::IterationLimit => "stopped at the iteration limit".into(),
            Termination::EvaluationLimit => "stopped at the limit of cost evaluations".into(),
            Termination::Stalled { reason } => format!("stalled: {reason}"),
            Termination::StartFailed { failure } => {
                format!("the model could not be simulated at the start: {failure}")
            }
        }
    }
}

/// Raw outcome of one optimization.
#[derive(Debug, Clone)]
pub struct Outcome {
    /// Final scaled parameters.
    pub x: Vec<f64>,
    /// Final cost J (NaN if the start failed).
    pub cost: f64,
    /// Cost after each iteration, the start first.
    pub history: Vec<f64>,
    /// How it ended.
    pub termination: Termination,
    /// Iterations.
    pub iterations: usize,
    /// Trial points whose evaluation failed.
    pub failed_trials: usize,
}

/// Run the chosen optimizer from `x0` in the box `[lo, hi]`.
pub fn minimize(
    ev: &mut Evaluator<'_>,
    x0: &[f64],
    lo: &[f64],
    hi: &[f64],
    s: &FitSettings,
) -> Outcome {
    let x0 = clamp(x0, lo, hi);
    let mut st = State {
        ev,
        lo,
        hi,
        s,
        failed: 0,
    };
    match s.optimizer {
        Optimizer::Lm => st.lm(x0, true),
        Optimizer::Gn => st.lm(x0, false),
        Optimizer::Bfgs => st.bfgs(x0),
        Optimizer::Simplex => st.simplex(x0),
    }
}

/// Jacobian of the residual at `x` by the method of `s` (resolved with
/// [`JacobianMethod::resolve`]; a failed sensitivity evaluation falls back
/// to finite differences and is counted in `ev.sensitivity_fallbacks`).
/// Counts the Jacobian and its time in `ev`.
pub fn jacobian_with(
    ev: &mut Evaluator<'_>,
    x: &[f64],
    r0: &DVector<f64>,
    lo: &[f64],
    hi: &[f64],
    s: &FitSettings,
) -> Result<DMatrix<f64>, Failure> {
    let t0 = std::time::Instant::now();
    ev.jacobians += 1;
    let mut out = None;
    if s.jacobian.resolve(ev.problem()).0 == JacobianMethod::Sensitivity {
        match ev.sensitivity_jacobian(x, s.fd_step) {
            Ok(j) if j.shape() == (r0.len(), x.len()) => out = Some(Ok(j)),
            _ => ev.sensitivity_fallbacks += 1,
        }
    }
    let out = out.unwrap_or_else(|| jacobian(ev, x, r0, lo, hi, s.fd_step));
    ev.jacobian_seconds += t0.elapsed().as_secs_f64();
    out
}

/// Centered finite-difference Jacobian of the residual at `x` (one-sided
/// at a bound or where one side fails).
pub fn jacobian(
    ev: &mut Evaluator<'_>,
    x: &[f64],
    r0: &DVector<f64>,
    lo: &[f64],
    hi: &[f64],
    h: f64,
) -> Result<DMatrix<f64>, Failure> {
    let mut jac = DMatrix::zeros(r0.len(), x.len());
    for j in 0..x.len() {
        let step = h * (1.0 + x[j].abs());
        let (xp, xm) = (x[j] + step, x[j] - step);
        let mut side = |v: f64| -> Option<DVector<f64>> {
            let mut xt = x.to_vec();
            xt[j] = v;
            ev.residual(&xt).ok().filter(|r| r.len() == r0.len())
        };
        let rp = if xp <= hi[j] { side(xp) } else { None };
        let rm = if xm >= lo[j] { side(xm) } else { None };
        let col = match (rp, rm) {
            (Some(p), Some(m)) => (p - m) / (2.0 * step),
            (Some(p), None) => (p - r0) / step,
            (None, Some(m)) => (r0 - m) / step,
            (None, None) => {
                return Err(Failure {
                    segment: None,
                    reason: format!("finite differences failed on both sides of parameter {j}"),
                })
            }
        };
        jac.set_column(j, &col);
    }
    Ok(jac)
}

fn clamp(x: &[f64], lo: &[f64], hi: &[f64]) -> Vec<f64> {
    x.iter()
        .zip(lo.iter().zip(hi))
        .map(|(v, (l, h))| v.clamp(*l, *h))
        .collect()
}

fn small_step(a: &[f64], b: &[f64], tol: f64) -> bool {
    a.iter()
        .zip(b)
        .all(|(x, y)| (x - y).abs() <= tol * (1.0 + y.abs()))
}

/// Projected gradient: zero the components that push out of the box at an
/// active bound.
fn projected(g: &DVector<f64>, x: &[f64], lo: &[f64], hi: &[f64]) -> DVector<f64> {
    DVector::from_fn(g.len(), |i, _| {
        let at_lo = x[i] <= lo[i] && g[i] > 0.0;
        let at_hi = x[i] >= hi[i] && g[i] < 0.0;
        if at_lo || at_hi {
            0.0
        } else {
            g[i]
        }
    })
}

struct State<'e, 'p, 'b> {
    ev: &'e mut Evaluator<'p>,
    lo: &'b [f64],
    hi: &'b [f64],
    s: &'b FitSettings,
    failed: usize,
}

impl State<'_, '_, '_> {
    fn out_of_budget(&self) -> bool {
        self.ev.evaluations >= self.s.max_evaluations
    }

    fn eval(&mut self, x: &[f64]) -> Option<DVector<f64>> {
        match self.ev.residual(x) {
            Ok(r) => Some(r),
            Err(_) => {
                self.failed += 1;
                None
            }
        }
    }

    fn outcome(
        &self,
        x: Vec<f64>,
        cost: f64,
        history: Vec<f64>,
        t: Termination,
        it: usize,
    ) -> Outcome {
        Outcome {
            x,
            cost,
            history,
            termination: t,
            iterations: it,
            failed_trials: self.failed,
        }
    }

    fn start_failed(&mut self, x: Vec<f64>) -> Outcome {
        let failure = match self.ev.residual(&x) {
            Err(f) => f,
            Ok(_) => Failure {
                segment: None,
                reason: "evaluation at the start failed".into(),
            },
        };
        self.outcome(x, f64::NAN, vec![], Termination::StartFailed { failure }, 0)
    }

    /// Levenberg–Marquardt (`damped`) or Gauss–Newton with backtracking,
    /// by the least-squares driver ([`crate::lsq`]).
    fn lm(&mut self, x: Vec<f64>, damped: bool) -> Outcome {
        let s = self.s;
        let method = if damped {
            lsq::Method::Damped(lsq::Damping {
                initial: s.lm_lambda,
                grow: 10.0,
                shrink: 10.0,
                floor: 1e-12,
                ceiling: 1e12,
            })
        } else {
            lsq::Method::LineSearch {
                min_t: 1.0 / 1024.0,
            }
        };
        let stop = lsq::Stopping {
            max_iterations: s.max_iterations,
            x_tol: Some(s.x_tol),
            cost: lsq::CostTest::Drop(s.f_tol),
            light: 1.0,
            stall: None,
            count_failed_attempt: true,
        };
        let mut q = Fit { st: self, damped };
        let out = lsq::minimize(&mut q, x, method, &stop);
        let term = match out.termination {
            lsq::Termination::StartFailed => return self.start_failed(out.point),
            t => termination(t),
        };
        self.outcome(out.point, out.cost, out.history, term, out.iterations)
    }

    /// Gradient `2 Jᵀ r` of J at x.
    fn cost_grad(&mut self, x: &[f64], r: &DVector<f64>) -> Result<DVector<f64>, String> {
        let jac =
            jacobian_with(self.ev, x, r, self.lo, self.hi, self.s).map_err(|f| f.to_string())?;
        Ok(jac.transpose() * r * 2.0)
    }

    fn bfgs(&mut self, mut x: Vec<f64>) -> Outcome {
        let n = x.len();
        let Some(mut r) = self.eval(&x) else {
            return self.start_failed(x);
        };
        let mut cost = r.norm_squared();
        let mut history = vec![cost];
        let mut g = match self.cost_grad(&x, &r) {
            Ok(g) => g,
            Err(reason) => {
                return self.outcome(x, cost, history, Termination::Stalled { reason }, 0)
            }
        };
        // initial inverse Hessian from the Gauss-Newton diagonal scale
        let mut h = DMatrix::identity(n, n) * (1.0 / g.amax().max(1e-300)) * 0.1;
        let mut it = 0;
        let term = loop {
            let pg = projected(&g, &x, self.lo, self.hi);
            if pg.amax() <= self.s.g_tol {
                break Termination::Converged {
                    criterion: "gradient".into(),
                };
            }
            if it >= self.s.max_iterations {
                break Termination::IterationLimit;
            }
            if self.out_of_budget() {
                break Termination::EvaluationLimit;
            }
            it += 1;
            let mut d = -(&h * &pg);
            if d.dot(&pg) >= 0.0 {
                h = DMatrix::identity(n, n) * (1.0 / pg.amax().max(1e-300)) * 0.1;
                d = -(&h * &pg);
            }
            let Some((xn, rn)) = self.armijo(&x, &d, &pg, cost) else {
                break Termination::Stalled {
                    reason: "BFGS line search found no sufficient decrease".into(),
                };
            };
            let cn = rn.norm_squared();
            let gn = match self.cost_grad(&xn, &rn) {
                Ok(g) => g,
                Err(reason) => break Termination::Stalled { reason },
            };
            let s = DVector::from_fn(n, |i, _| xn[i] - x[i]);
            let y = &gn - &g;
            let sy = s.dot(&y);
            if sy > 1e-12 * s.norm() * y.norm() {
                let rho = 1.0 / sy;
                let i = DMatrix::<f64>::identity(n, n);
                let a = &i - &s * y.transpose() * rho;
                h = &a * &h * a.transpose() + &s * s.transpose() * rho;
            }
            let small = small_step(&xn, &x, self.s.x_tol);
            let flat = cost - cn <= self.s.f_tol * cost;
            x = xn;
            r = rn;
            g = gn;
            cost = cn;
            history.push(cost);
            if small {
                break Termination::Converged {
                    criterion: "step".into(),
                };
            }
            if flat {
                break Termination::Converged {
                    criterion: "cost".into(),
                };
            }
        };
        let _ = r;
        self.outcome(x, cost, history, term, it)
    }

    /// Backtracking (Armijo) along `d`, projected on the box.
    fn armijo(
        &mut self,
        x: &[f64],
        d: &DVector<f64>,
        g: &DVector<f64>,
        cost: f64,
    ) -> Option<(Vec<f64>, DVector<f64>)> {
        let n = x.len();
        let mut t = 1.0;
        for _ in 0..40 {
            let xn = clamp(
                &(0..n).map(|i| x[i] + t * d[i]).collect::<Vec<_>>(),
                self.lo,
                self.hi,
            );
            let dec: f64 = (0..n).map(|i| g[i] * (xn[i] - x[i])).sum();
            if let Some(rn) = self.eval(&xn) {
                if rn.norm_squared() <= cost + 1e-4 * dec {
                    return Some((xn, rn));
                }
            }
            t *= 0.5;
            if small_step(&xn, x, 1e-15) {
                break;
            }
        }
        None
    }

    /// Cost at x, `None` on a failed evaluation.
    fn cost_at(&mut self, x: &[f64]) -> Option<f64> {
        self.eval(x).map(|r| r.norm_squared())
    }

    fn simplex(&mut self, x0: Vec<f64>) -> Outcome {
        let n = x0.len();
        let Some(c0) = self.cost_at(&x0) else {
            return self.start_failed(x0);
        };
        let mut pts = vec![(x0.clone(), c0)];
        for i in 0..n {
            let mut found = None;
            for sign in [1.0, -1.0] {
                let mut xi = x0.clone();
                xi[i] += sign * self.s.simplex_size;
                let xi = clamp(&xi, self.lo, self.hi);
                if let Some(c) = self.cost_at(&xi) {
                    found = Some((xi, c));
                    break;
                }
            }
            match found {
                Some(p) => pts.push(p),
                None => {
                    let t = Termination::Stalled {
                        reason: format!("no valid initial simplex vertex along parameter {i}"),
                    };
                    return self.outcome(x0, c0, vec![c0], t, 0);
                }
            }
        }
        let mut history = vec![c0];
        let mut it = 0;
        let term = loop {
            pts.sort_by(|a, b| a.1.total_cmp(&b.1));
            let (best, worst) = (pts[0].1, pts[n].1);
            let size = pts[1..]
                .iter()
                .map(|p| {
                    p.0.iter()
                        .zip(&pts[0].0)
                        .map(|(a, b)| (a - b).abs())
                        .fold(0.0, f64::max)
                })
                .fold(0.0, f64::max);
            if size <= self.s.x_tol * (1.0 + pts[0].0.iter().fold(0.0f64, |a, v| a.max(v.abs())))
                && worst - best <= self.s.f_tol * best.max(f64::MIN_POSITIVE)
            {
                break Termination::Converged {
                    criterion: "simplex".into(),
                };
            }
            if it >= self.s.max_iterations {
                break Termination::IterationLimit;
            }
            if self.out_of_budget() {
                break Termination::EvaluationLimit;
            }
            it += 1;
            self.simplex_iteration(&mut pts);
            history.push(pts.iter().map(|p| p.1).fold(f64::INFINITY, f64::min));
        };
        pts.sort_by(|a, b| a.1.total_cmp(&b.1));
        let (x, c) = pts.swap_remove(0);
        self.outcome(x, c, history, term, it)
    }

    /// One Nelder–Mead iteration on sorted vertices (reflection 1,
    /// expansion 2, contraction 1/2, shrink 1/2); failed trials count as
    /// rejected points.
    fn simplex_iteration(&mut self, pts: &mut [(Vec<f64>, f64)]) {
        let n = pts.len() - 1;
        let centroid: Vec<f64> = (0..n)
            .map(|i| pts[..n].iter().map(|p| p.0[i]).sum::<f64>() / n as f64)
            .collect();
        let along = |t: f64, w: &[f64]| -> Vec<f64> {
            (0..n)
                .map(|i| centroid[i] + t * (w[i] - centroid[i]))
                .collect()
        };
        let worst = pts[n].0.clone();
        let xr = clamp(&along(-1.0, &worst), self.lo, self.hi);
        let fr = self.cost_at(&xr);
        if let Some(fr) = fr {
            if fr < pts[0].1 {
                let xe = clamp(&along(-2.0, &worst), self.lo, self.hi);
                pts[n] = match self.cost_at(&xe) {
                    Some(fe) if fe < fr => (xe, fe),
                    _ => (xr, fr),
                };
                return;
            }
            if fr < pts[n - 1].1 {
                pts[n] = (xr, fr);
                return;
            }
        }
        // contraction: outside if the reflection beat the worst, else inside
        let outside = fr.is_some_and(|f| f < pts[n].1);
        let xc = clamp(
            &along(if outside { -0.5 } else { 0.5 }, &worst),
            self.lo,
            self.hi,
        );
        let limit = if outside {
            fr.unwrap_or(f64::INFINITY)
        } else {
            pts[n].1
        };
        if let Some(fc) = self.cost_at(&xc) {
            if fc < limit {
                pts[n] = (xc, fc);
                return;
            }
        }
        let best = pts[0].0.clone();
        for p in pts.iter_mut().skip(1) {
            let xs: Vec<f64> = (0..n).map(|i| best[i] + 0.5 * (p.0[i] - best[i])).collect();
            if let Some(c) = self.cost_at(&xs) {
                *p = (xs, c);
            }
        }
    }
}

/// The optimizer's state as a problem of the least-squares driver: the
/// residual and its Jacobian ([`jacobian_with`]), the damped normal
/// equations (Marquardt's scaling, floored at 1e-9 of the largest
/// diagonal entry) or the Gauss–Newton system solved by SVD.
struct Fit<'s, 'e, 'p, 'b> {
    st: &'s mut State<'e, 'p, 'b>,
    damped: bool,
}

/// Jacobian, gradient `Jᵀ r` and `JᵀJ`.
struct Normal {
    g: DVector<f64>,
    jtj: DMatrix<f64>,
}

impl lsq::Problem for Fit<'_, '_, '_, '_> {
    type Point = Vec<f64>;
    type Eval = DVector<f64>;
    type Lin = Normal;
    type Step = DVector<f64>;

    fn evaluate(&mut self, x: &Vec<f64>) -> Option<DVector<f64>> {
        self.st.eval(x)
    }

    fn cost(&self, r: &DVector<f64>) -> f64 {
        r.norm_squared()
    }

    fn linearize(&mut self, x: &Vec<f64>, r: &DVector<f64>) -> Result<Normal, String> {
        let st = &mut *self.st;
        let jac = jacobian_with(st.ev, x, r, st.lo, st.hi, st.s).map_err(|f| f.to_string())?;
        let g = jac.transpose() * r;
        let jtj = jac.transpose() * &jac;
        Ok(Normal { g, jtj })
    }

    fn gradient_converged(&self, x: &Vec<f64>, lin: &Normal) -> bool {
        projected(&lin.g, x, self.st.lo, self.st.hi).amax() * 2.0 <= self.st.s.g_tol
    }

    fn step(&mut self, lin: &Normal, lambda: f64) -> Result<DVector<f64>, String> {
        let (jtj, g) = (&lin.jtj, &lin.g);
        if !self.damped {
            return jtj
                .clone()
                .svd(true, true)
                .solve(&(-g), 1e-12 * jtj.amax())
                .map_err(|e| format!("Gauss-Newton system: {e}"));
        }
        let dmax = jtj.diagonal().amax().max(f64::MIN_POSITIVE);
        let mut a = jtj.clone();
        for i in 0..jtj.nrows() {
            a[(i, i)] += lambda * jtj[(i, i)].max(1e-9 * dmax);
        }
        a.cholesky()
            .map(|c| c.solve(&(-g)))
            .ok_or_else(|| "not positive definite".into())
    }

    fn trial(&self, x: &Vec<f64>, d: &DVector<f64>, t: f64) -> Vec<f64> {
        let n = x.len();
        clamp(
            &(0..n).map(|i| x[i] + t * d[i]).collect::<Vec<_>>(),
            self.st.lo,
            self.st.hi,
        )
    }

    fn small_step(&self, a: &Vec<f64>, b: &Vec<f64>, tol: f64) -> bool {
        small_step(a, b, tol)
    }

    fn budget_spent(&self) -> bool {
        self.st.out_of_budget()
    }
}

/// The driver's termination as the optimizer's.
fn termination(t: lsq::Termination) -> Termination {
    use lsq::Termination as L;
    let stalled = |reason: String| Termination::Stalled { reason };
    match t {
        L::Converged(c) => Termination::Converged {
            criterion: match c {
                lsq::Criterion::Gradient => "gradient",
                lsq::Criterion::Step => "step",
                lsq::Criterion::Cost => "cost",
            }
            .into(),
        },
        L::IterationLimit => Termination::IterationLimit,
        L::EvaluationLimit => Termination::EvaluationLimit,
        L::DampingCeiling { lambda } => stalled(format!(
            "Levenberg-Marquardt damping reached {lambda:.1e} without a better point"
        )),
        L::BudgetInStep => stalled("evaluation limit reached inside a step".into()),
        L::VanishingSteps { lambda } => stalled(format!(
            "Levenberg-Marquardt steps vanish at damping {lambda:.1e}: the cost is rough or the derivatives unreliable here"
        )),
        L::NoDecrease => stalled("Gauss-Newton line search found no lower cost".into()),
        L::SolveFailed(reason) | L::LinearizationFailed(reason) => stalled(reason),
        L::Stalled { steps, gain } => stalled(format!(
            "{steps} accepted steps in a row each lowered the cost by less than {:.1} %",
            100.0 * gain
        )),
        L::StartFailed => stalled("evaluation at the start failed".into()),
    }
}
