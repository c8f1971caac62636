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
    let mut r = DVector::zeros(0);
    let m = sys.m();
    let mut sc = Scratch {
        we: &sys.be * &prob.e,
        x: DVector::zeros(ns),
        xn: DVector::zeros(ns),
        w: DVector::zeros(m),
        wn: DVector::zeros(m),
    };
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
        if r.len() != op.r_theta.nrows() {
            r = DVector::zeros(op.r_theta.nrows());
        }
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
        propagate(sys, op, s, &r, &mut c, &mut sc, &mut out);
        out.windows += 1;
        if wi % step == 0 || wi + 1 == nwin {
            progress(wi + 1, nwin);
        }
    }
    out
}

/// Scratch buffers of the propagation (no allocation per sample).
struct Scratch {
    /// `B_e e_k` for every sample (m × N).
    we: DMatrix<f64>,
    x: DVector<f64>,
    xn: DVector<f64>,
    w: DVector<f64>,
    wn: DVector<f64>,
}

/// Propagate a window's solution over its samples, store the committed
/// ones and update the carried vector `c` in place.
fn propagate(
    sys: &System,
    op: &WindowOperator,
    s: usize,
    r: &DVector<f64>,
    c: &mut DVector<f64>,
    sc: &mut Scratch,
    out: &mut RunOutput,
) {
    let (ns, n) = (2 * sys.m(), sys.n());
    let prm = &op.param;
    let force = |j: usize| r.rows(ns + j * n, n);
    sc.x.copy_from(&r.rows(0, ns));
    sc.w.copy_from(&sc.we.column(s));
    sc.w.gemv(1.0, &sys.bf, &force(0), 1.0);
    for j in 0..=op.last_needed {
        if prm.commit.contains(&j) {
            out.x.set_column(s + j, &sc.x);
            out.f.set_column(s + j, &force(j));
            let mut y = out.yhat.column_mut(s + j);
            y.gemv(1.0, &sys.cy, &sc.x, 0.0);
            y.gemv(1.0, &sys.dy, &sc.w, 1.0);
        }
        if prm.next == Some(j) {
            c.rows_mut(0, ns).copy_from(&sc.x);
        }
        if prm.carry_force == j {
            c.rows_mut(ns, n).copy_from(&force(j));
        }
        if j < op.last_needed {
            sc.wn.copy_from(&sc.we.column(s + j + 1));
            sc.wn.gemv(1.0, &sys.bf, &force(j + 1), 1.0);
            sc.xn.gemv(1.0, &sys.sm.a, &sc.x, 0.0);
            sc.xn.gemv(1.0, &sys.sm.b0, &sc.w, 1.0);
            sc.xn.gemv(1.0, &sys.sm.b1, &sc.wn, 1.0);
            std::mem::swap(&mut sc.x, &mut sc.xn);
            std::mem::swap(&mut sc.w, &mut sc.wn);
        }
    }
}
