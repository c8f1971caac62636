//! The window loop shared by the schemes: gather each window's data, solve
//! (least-squares gain or QP), propagate the committed samples with the
//! exact sampled model and carry `c = [x; f_prev]` to the next window.

use super::system::{Problem, System};
use super::window::WindowOperator;
use nalgebra::{DMatrix, DVector};

/// A scheme's plan over a record.
#[derive(Debug, Clone)]
pub struct Plan {
    /// The distinct window operators (regular first, then the last one).
    pub ops: Vec<WindowOperator>,
    /// `(start sample, operator index)` of every window, in order.
    pub windows: Vec<(usize, usize)>,
    /// Carried vector before the first window.
    pub c0: DVector<f64>,
    /// Sample 0 is committed from `c0` before the first window (paper).
    pub commit_start: bool,
}

/// Solves one window: fills `r = [x_0; f_0 … f_J]` from `d = [y_fit; c; e]`.
pub trait WindowSolver {
    /// Solve; returns the solver iterations, or a message on failure.
    fn solve(
        &mut self,
        op_index: usize,
        op: &WindowOperator,
        d: &DVector<f64>,
        r: &mut DVector<f64>,
    ) -> std::result::Result<u32, String>;
}

/// Least squares through the precomputed gain.
#[derive(Debug, Default)]
pub struct LsSolver;

impl WindowSolver for LsSolver {
    fn solve(
        &mut self,
        _op_index: usize,
        op: &WindowOperator,
        d: &DVector<f64>,
        r: &mut DVector<f64>,
    ) -> std::result::Result<u32, String> {
        r.gemv(1.0, &op.gain, d, 0.0);
        Ok(0)
    }
}

/// Where and why the window loop stopped early.
#[derive(Debug, Clone, serde::Serialize)]
pub struct RunFailure {
    /// Window index (from 0).
    pub window: usize,
    /// Its start sample.
    pub sample: usize,
    /// What happened.
    pub message: String,
}

/// What the window loop produced (reduced coordinates).
#[derive(Debug, Clone)]
pub struct RunOutput {
    /// States (2m × N); NaN after a failure.
    pub x: DMatrix<f64>,
    /// Internal force (n × N); NaN after a failure.
    pub f: DMatrix<f64>,
    /// Predicted outputs (p × N).
    pub yhat: DMatrix<f64>,
    /// Windows solved.
    pub windows: usize,
    /// Total solver iterations (QP).
    pub iterations: u64,
    /// Early stop.
    pub failure: Option<RunFailure>,
}

/// Run a plan.
pub fn run(
    sys: &System,
    prob: &Problem,
    plan: &Plan,
    solver: &mut dyn WindowSolver,
    progress: &mut dyn FnMut(usize, usize),
) -> RunOutput {
    let (ns, n, p, ne) = (2 * sys.m(), sys.n(), sys.p(), sys.ne());
    let total = prob.len();
    let mut out = RunOutput {
        x: DMatrix::from_element(ns, total, f64::NAN),
        f: DMatrix::from_element(n, total, f64::NAN),
        yhat: DMatrix::from_element(p, total, f64::NAN),
        windows: 0,
        iterations: 0,
        failure: None,
    };
    let mut c = plan.c0.clone();
    if plan.commit_start {
        let x0 = c.rows(0, ns).into_owned();
        let f0: Vec<f64> = c.rows(ns, n).iter().copied().collect();
        let e0: Vec<f64> = prob.e.column(0).iter().copied().collect();
        let w = sys.gen_force(&f0, &e0);
        out.yhat.set_column(0, &(&sys.cy * &x0 + &sys.dy * &w));
        out.x.set_column(0, &x0);
        out.f.set_column(0, &DVector::from_vec(f0));
    }
    let nwin = plan.windows.len();
    let step = (nwin / 100).max(1);
    let mut d = DVector::zeros(0);
    for (wi, &(s, oi)) in plan.windows.iter().enumerate() {
        let op = &plan.ops[oi];
        if d.len() != op.nd {
            d = DVector::zeros(op.nd);
        }
        for (i, &j) in op.param.fit.iter().enumerate() {
            d.rows_mut(i * p, p).copy_from(&prob.y.column(s + j));
        }
        d.rows_mut(op.nfit, op.param.nc).copy_from(&c);
        if ne > 0 {
            for j in 0..=op.len {
                d.rows_mut(op.nfit + op.param.nc + j * ne, ne)
                    .copy_from(&prob.e.column(s + j));
            }
        }
        let mut r = DVector::zeros(op.r_theta.nrows());
        let fail = |message: String| RunFailure {
            window: wi,
            sample: s,
            message,
        };
        match solver.solve(oi, op, &d, &mut r) {
            Ok(it) => out.iterations += it as u64,
            Err(m) => {
                out.failure = Some(fail(m));
                break;
            }
        }
        if let Some(bad) = r.iter().position(|v| !v.is_finite()) {
            out.failure = Some(fail(format!(
                "non-finite estimate (component {bad} of the window solution)"
            )));
            break;
        }
        c = propagate(sys, prob, op, s, &r, &c, &mut out);
        out.windows += 1;
        if wi % step == 0 || wi + 1 == nwin {
            progress(wi + 1, nwin);
        }
    }
    out
}

/// Propagate a window's solution over its samples, store the committed
/// ones and return the next carried vector.
fn propagate(
    sys: &System,
    prob: &Problem,
    op: &WindowOperator,
    s: usize,
    r: &DVector<f64>,
    c: &DVector<f64>,
    out: &mut RunOutput,
) -> DVector<f64> {
    let (ns, n) = (2 * sys.m(), sys.n());
    let prm = &op.param;
    let mut x = r.rows(0, ns).into_owned();
    let force = |j: usize| -> &[f64] { &r.as_slice()[ns + j * n..ns + (j + 1) * n] };
    let e_at = |k: usize| -> Vec<f64> { prob.e.column(k).iter().copied().collect() };
    let mut next = c.clone();
    let mut w = sys.gen_force(force(0), &e_at(s));
    let mut xn = DVector::zeros(ns);
    for j in 0..=op.last_needed {
        let fj = force(j);
        if prm.commit.contains(&j) {
            out.x.set_column(s + j, &x);
            out.f.column_mut(s + j).copy_from_slice(fj);
            let y = &sys.cy * &x + &sys.dy * &w;
            out.yhat.set_column(s + j, &y);
        }
        if prm.next == Some(j) {
            next.rows_mut(0, ns).copy_from(&x);
        }
        if prm.carry_force == j {
            next.rows_mut(ns, n).copy_from_slice(fj);
        }
        if j < op.last_needed {
            let wn = sys.gen_force(force(j + 1), &e_at(s + j + 1));
            xn.gemv(1.0, &sys.sm.a, &x, 0.0);
            xn.gemv(1.0, &sys.sm.b0, &w, 1.0);
            xn.gemv(1.0, &sys.sm.b1, &wn, 1.0);
            std::mem::swap(&mut x, &mut xn);
            w = wn;
        }
    }
    next
}
