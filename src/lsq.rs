//! One bounded least-squares driver: Levenberg–Marquardt (a damped step,
//! the damping raised on a rejected or unsolvable step and lowered on an
//! accepted one) or Gauss–Newton with a halving line search, on any
//! problem that can evaluate a point, linearize there and solve its own
//! step ([`Problem`]): a dense normal-equation solve, a Schur complement
//! over per-segment blocks, a pseudo-inverse. The bounds are the
//! problem's (its trial points are clamped to them).
//!
//! The policies the callers differ in are data, not copies of the loop:
//! the damping rule ([`Damping`]: start, growth, shrink, floor, ceiling),
//! the cost test of convergence ([`CostTest`]), the damping at or below
//! which a short or flat step is convergence rather than a step held
//! short by the damping ([`Stopping::light`]), a stall rule, and whether
//! an attempt that fails counts as an iteration. Every way the driver
//! stops is a [`Termination`]; the callers turn it into their statuses.
//! References: Nocedal & Wright, *Numerical Optimization* (2006), ch. 10;
//! Marquardt (1963).

/// Why a convergence test passed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Criterion {
    /// The projected gradient is below its tolerance.
    Gradient,
    /// The step is below its tolerance.
    Step,
    /// The cost fell by less than its tolerance.
    Cost,
}

/// How the driver stopped.
#[derive(Debug, Clone, PartialEq)]
pub enum Termination {
    /// The start point could not be evaluated.
    StartFailed,
    /// A convergence test passed.
    Converged(Criterion),
    /// The iteration limit.
    IterationLimit,
    /// The problem's evaluation budget is spent (before a linearization).
    EvaluationLimit,
    /// The budget ran out inside a step.
    BudgetInStep,
    /// Accepted steps in a row each lowered the cost by less than the
    /// stall fraction.
    Stalled {
        /// Steps in a row.
        steps: usize,
        /// Fraction of the cost.
        gain: f64,
    },
    /// The damping passed its ceiling without a lower cost.
    DampingCeiling {
        /// The damping reached.
        lambda: f64,
    },
    /// The trial point is within round-off of the current one while the
    /// damping is heavy.
    VanishingSteps {
        /// The damping.
        lambda: f64,
    },
    /// The line search found no lower cost.
    NoDecrease,
    /// The undamped step could not be solved for.
    SolveFailed(String),
    /// The problem could not be linearized at the current point.
    LinearizationFailed(String),
}

/// The damping rule of Levenberg–Marquardt.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Damping {
    /// Starting damping.
    pub initial: f64,
    /// Factor on a rejected or unsolvable step.
    pub grow: f64,
    /// Divisor on an accepted step…
    pub shrink: f64,
    /// …down to this floor.
    pub floor: f64,
    /// Above this, stop ([`Termination::DampingCeiling`]).
    pub ceiling: f64,
}

/// How a step is found.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Method {
    /// Levenberg–Marquardt with this damping rule.
    Damped(Damping),
    /// Gauss–Newton along its step scaled by 1, ½, ¼, … down to `min_t`.
    LineSearch {
        /// Smallest step fraction tried.
        min_t: f64,
    },
}

/// The cost test applied after an accepted step, from `c` to `c'`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum CostTest {
    /// Flat when `c − c' ≤ tol · c`.
    Drop(f64),
    /// Flat when the gain `1 − c'/c < tol`.
    Gain(f64),
}

/// When to stop.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Stopping {
    /// Most iterations.
    pub max_iterations: usize,
    /// A step changing the point by less than this ([`Problem::small_step`])
    /// is convergence; a trial within a thousandth of it is vanishing.
    /// None: no step test.
    pub x_tol: Option<f64>,
    /// The cost test.
    pub cost: CostTest,
    /// A short or flat step is convergence only at a damping at or below
    /// this (a line search is never damped).
    pub light: f64,
    /// Stop after this many accepted steps in a row each with a gain
    /// below the fraction (steps, fraction).
    pub stall: Option<(usize, f64)>,
    /// An attempt that ends the run without an accepted step counts as an
    /// iteration.
    pub count_failed_attempt: bool,
}

/// A least-squares problem the driver can step.
pub trait Problem {
    /// A point (parameters, and whatever else is stepped).
    type Point: Clone;
    /// What an evaluation gives (the residual, or the costs of its parts).
    type Eval;
    /// The linearization at a point.
    type Lin;
    /// A step (direction) from a linearization.
    type Step;

    /// The evaluation at `p`; None when it fails.
    fn evaluate(&mut self, p: &Self::Point) -> Option<Self::Eval>;
    /// The cost (squared norm) of an evaluation.
    fn cost(&self, e: &Self::Eval) -> f64;
    /// Linearize at `p` (evaluated as `e`); Err says why it failed.
    fn linearize(&mut self, p: &Self::Point, e: &Self::Eval) -> Result<Self::Lin, String>;
    /// The step at damping `lambda` (0 for Gauss–Newton): the pluggable
    /// linear solve. Err: not solvable at this damping.
    fn step(&mut self, lin: &Self::Lin, lambda: f64) -> Result<Self::Step, String>;
    /// The trial point `p + t · step`, within the bounds.
    fn trial(&self, p: &Self::Point, step: &Self::Step, t: f64) -> Self::Point;
    /// True when a gradient test passes at this linearization.
    fn gradient_converged(&self, _p: &Self::Point, _lin: &Self::Lin) -> bool {
        false
    }
    /// True when `a` is within `tol` of `b` (relative).
    fn small_step(&self, _a: &Self::Point, _b: &Self::Point, _tol: f64) -> bool {
        false
    }
    /// True when the evaluation budget is spent.
    fn budget_spent(&self) -> bool {
        false
    }
}

/// What the driver did.
#[derive(Debug, Clone)]
pub struct Outcome<P, E> {
    /// The last accepted point.
    pub point: P,
    /// Its evaluation (None only when the start failed).
    pub eval: Option<E>,
    /// Its cost (NaN when the start failed).
    pub cost: f64,
    /// The cost at the start and after each accepted step.
    pub history: Vec<f64>,
    /// How it stopped.
    pub termination: Termination,
    /// Iterations.
    pub iterations: usize,
}

/// One step's result.
enum Taken<P, E> {
    Accepted(P, E),
    Vanishing,
    Stop(Termination),
}

/// Minimize the problem's cost from `x0` (module docs).
pub fn minimize<Q: Problem>(
    q: &mut Q,
    x0: Q::Point,
    method: Method,
    stop: &Stopping,
) -> Outcome<Q::Point, Q::Eval> {
    let Some(e0) = q.evaluate(&x0) else {
        return Outcome {
            point: x0,
            eval: None,
            cost: f64::NAN,
            history: vec![],
            termination: Termination::StartFailed,
            iterations: 0,
        };
    };
    minimize_from(q, x0, e0, method, stop)
}

/// [`minimize`] from `x0` already evaluated as `e0`.
pub fn minimize_from<Q: Problem>(
    q: &mut Q,
    x0: Q::Point,
    e0: Q::Eval,
    method: Method,
    stop: &Stopping,
) -> Outcome<Q::Point, Q::Eval> {
    let mut cost = q.cost(&e0);
    let (mut x, mut e) = (x0, e0);
    let mut history = vec![cost];
    let mut lambda = match method {
        Method::Damped(d) => d.initial,
        Method::LineSearch { .. } => 0.0,
    };
    let (mut it, mut slow) = (0, 0);
    let termination = loop {
        if it >= stop.max_iterations {
            break Termination::IterationLimit;
        }
        if q.budget_spent() {
            break Termination::EvaluationLimit;
        }
        let lin = match q.linearize(&x, &e) {
            Ok(l) => l,
            Err(reason) => break Termination::LinearizationFailed(reason),
        };
        if q.gradient_converged(&x, &lin) {
            break Termination::Converged(Criterion::Gradient);
        }
        let taken = match method {
            Method::Damped(d) => damped_step(q, &x, &lin, cost, &d, &mut lambda, stop.x_tol),
            Method::LineSearch { min_t } => line_search(q, &x, &lin, cost, min_t, stop.x_tol),
        };
        let light = lambda <= stop.light;
        let (xn, en) = match taken {
            Taken::Accepted(xn, en) => (xn, en),
            Taken::Vanishing if light => {
                it += usize::from(stop.count_failed_attempt);
                break Termination::Converged(Criterion::Step);
            }
            Taken::Vanishing => {
                it += usize::from(stop.count_failed_attempt);
                break Termination::VanishingSteps { lambda };
            }
            Taken::Stop(t) => {
                it += usize::from(stop.count_failed_attempt);
                break t;
            }
        };
        it += 1;
        let cn = q.cost(&en);
        let small = stop.x_tol.is_some_and(|tol| q.small_step(&xn, &x, tol));
        let (flat, gain) = match stop.cost {
            CostTest::Drop(tol) => (cost - cn <= tol * cost, 1.0 - cn / cost),
            CostTest::Gain(tol) => {
                let gain = 1.0 - cn / cost;
                (gain < tol, gain)
            }
        };
        (x, e, cost) = (xn, en, cn);
        history.push(cost);
        if small && light {
            break Termination::Converged(Criterion::Step);
        }
        if flat && light {
            break Termination::Converged(Criterion::Cost);
        }
        if let Some((steps, fraction)) = stop.stall {
            slow = if gain < fraction { slow + 1 } else { 0 };
            if slow >= steps {
                break Termination::Stalled {
                    steps,
                    gain: fraction,
                };
            }
        }
    };
    Outcome {
        point: x,
        eval: Some(e),
        cost,
        history,
        termination,
        iterations: it,
    }
}

/// Levenberg–Marquardt: solve at the damping, raise it until a trial
/// lowers the cost, then lower it.
fn damped_step<Q: Problem>(
    q: &mut Q,
    x: &Q::Point,
    lin: &Q::Lin,
    cost: f64,
    d: &Damping,
    lambda: &mut f64,
    x_tol: Option<f64>,
) -> Taken<Q::Point, Q::Eval> {
    loop {
        if *lambda > d.ceiling {
            return Taken::Stop(Termination::DampingCeiling { lambda: *lambda });
        }
        if q.budget_spent() {
            return Taken::Stop(Termination::BudgetInStep);
        }
        let Ok(step) = q.step(lin, *lambda) else {
            *lambda *= d.grow;
            continue;
        };
        let xn = q.trial(x, &step, 1.0);
        if x_tol.is_some_and(|tol| q.small_step(&xn, x, tol * 1e-3)) {
            return Taken::Vanishing;
        }
        match q.evaluate(&xn) {
            Some(en) if q.cost(&en) < cost => {
                *lambda = (*lambda / d.shrink).max(d.floor);
                return Taken::Accepted(xn, en);
            }
            _ => *lambda *= d.grow,
        }
    }
}

/// Gauss–Newton: the undamped step, halved until a trial lowers the cost.
fn line_search<Q: Problem>(
    q: &mut Q,
    x: &Q::Point,
    lin: &Q::Lin,
    cost: f64,
    min_t: f64,
    x_tol: Option<f64>,
) -> Taken<Q::Point, Q::Eval> {
    let step = match q.step(lin, 0.0) {
        Ok(s) => s,
        Err(reason) => return Taken::Stop(Termination::SolveFailed(reason)),
    };
    let mut found = None;
    let mut vanished = false;
    halving(1.0, min_t, |t| {
        let xn = q.trial(x, &step, t);
        if x_tol.is_some_and(|tol| q.small_step(&xn, x, tol * 1e-3)) {
            vanished = true;
            return Halve::Stop;
        }
        match q.evaluate(&xn) {
            Some(en) if q.cost(&en) < cost => {
                found = Some((xn, en));
                Halve::Stop
            }
            _ => Halve::Again,
        }
    });
    match found {
        Some((xn, en)) => Taken::Accepted(xn, en),
        None if vanished => Taken::Vanishing,
        None => Taken::Stop(Termination::NoDecrease),
    }
}

/// What a halving line search does after a trial.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Halve {
    /// Try half the step.
    Again,
    /// Stop (accepted, or nothing left to try).
    Stop,
}

/// The halving schedule: `attempt(t)` for `t = t0, t0/2, …` while `t ≥
/// min_t`, until it says [`Halve::Stop`]. Shared by [`minimize`]'s line
/// search and the batched one of the start-state refinement (all segments
/// at one `t`).
pub fn halving(t0: f64, min_t: f64, mut attempt: impl FnMut(f64) -> Halve) {
    let mut t = t0;
    while t >= min_t {
        if attempt(t) == Halve::Stop {
            return;
        }
        t *= 0.5;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{DMatrix, DVector};

    /// Rosenbrock as residuals `(10 (x₂ − x₁²), 1 − x₁)` in a box.
    struct Rosen {
        lo: [f64; 2],
        hi: [f64; 2],
        evaluations: usize,
    }

    impl Problem for Rosen {
        type Point = [f64; 2];
        type Eval = DVector<f64>;
        type Lin = (DMatrix<f64>, DVector<f64>);
        type Step = DVector<f64>;
        fn evaluate(&mut self, p: &[f64; 2]) -> Option<DVector<f64>> {
            self.evaluations += 1;
            Some(DVector::from_vec(vec![
                10.0 * (p[1] - p[0] * p[0]),
                1.0 - p[0],
            ]))
        }
        fn cost(&self, e: &DVector<f64>) -> f64 {
            e.norm_squared()
        }
        fn linearize(&mut self, p: &[f64; 2], e: &DVector<f64>) -> Result<Self::Lin, String> {
            let j = DMatrix::from_row_slice(2, 2, &[-20.0 * p[0], 10.0, -1.0, 0.0]);
            Ok((j, e.clone()))
        }
        fn step(&mut self, (j, r): &Self::Lin, lambda: f64) -> Result<DVector<f64>, String> {
            let mut a = j.tr_mul(j);
            for i in 0..2 {
                a[(i, i)] *= 1.0 + lambda;
            }
            a.cholesky()
                .map(|c| c.solve(&(-j.tr_mul(r))))
                .ok_or("singular".into())
        }
        fn trial(&self, p: &[f64; 2], d: &DVector<f64>, t: f64) -> [f64; 2] {
            [0, 1].map(|i| (p[i] + t * d[i]).clamp(self.lo[i], self.hi[i]))
        }
        fn small_step(&self, a: &[f64; 2], b: &[f64; 2], tol: f64) -> bool {
            (0..2).all(|i| (a[i] - b[i]).abs() <= tol * (1.0 + b[i].abs()))
        }
    }

    fn stopping() -> Stopping {
        Stopping {
            max_iterations: 200,
            x_tol: Some(1e-10),
            cost: CostTest::Drop(1e-14),
            light: 1.0,
            stall: None,
            count_failed_attempt: true,
        }
    }

    #[test]
    fn both_methods_find_the_minimum_and_respect_the_box() {
        let damping = Damping {
            initial: 1e-3,
            grow: 10.0,
            shrink: 10.0,
            floor: 1e-12,
            ceiling: 1e12,
        };
        for method in [
            Method::Damped(damping),
            Method::LineSearch {
                min_t: 1.0 / 1024.0,
            },
        ] {
            let mut q = Rosen {
                lo: [-2.0, -2.0],
                hi: [2.0, 2.0],
                evaluations: 0,
            };
            let out = minimize(&mut q, [-1.2, 1.0], method, &stopping());
            assert!(
                matches!(out.termination, Termination::Converged(_)),
                "{out:?}"
            );
            assert!((out.point[0] - 1.0).abs() < 1e-6 && (out.point[1] - 1.0).abs() < 1e-6);
            assert!(out.history.windows(2).all(|w| w[1] < w[0]));
            // a box that excludes the minimum: it ends on the bound x₁ = 0.5
            let mut q = Rosen {
                lo: [-2.0, -2.0],
                hi: [0.5, 2.0],
                evaluations: 0,
            };
            let out = minimize(&mut q, [-1.2, 1.0], method, &stopping());
            assert!((out.point[0] - 0.5).abs() < 1e-9, "{out:?}");
        }
    }

    #[test]
    fn the_iteration_limit_and_a_stall_are_reported() {
        let damping = Damping {
            initial: 1e3,
            grow: 4.0,
            shrink: 3.0,
            floor: 1e-9,
            ceiling: 1e6,
        };
        let mut q = Rosen {
            lo: [-2.0; 2],
            hi: [2.0; 2],
            evaluations: 0,
        };
        let mut stop = stopping();
        stop.max_iterations = 2;
        let out = minimize(&mut q, [-1.2, 1.0], Method::Damped(damping), &stop);
        assert_eq!(out.termination, Termination::IterationLimit);
        assert_eq!((out.iterations, out.history.len()), (2, 3));
        stop.max_iterations = 200;
        stop.stall = Some((1, 0.99));
        let out = minimize(&mut q, [-1.2, 1.0], Method::Damped(damping), &stop);
        assert_eq!(
            out.termination,
            Termination::Stalled {
                steps: 1,
                gain: 0.99
            }
        );
    }

    #[test]
    fn halving_tries_the_schedule_in_order() {
        let mut ts = vec![];
        halving(1.0, 1.0 / 8.0, |t| {
            ts.push(t);
            Halve::Again
        });
        assert_eq!(ts, vec![1.0, 0.5, 0.25, 0.125]);
    }
}
