//! Moving-horizon estimation (MHE): the stable default.
//!
//! Window `w` starts at sample `s = wL` and looks `N` samples ahead
//! (`N ≥ L`, the horizon). Its unknowns are the start state `x_s` **and**
//! one internal-force vector per sample `f_s … f_{s+N}` (force linear
//! between samples, as in the simulator); it minimises
//!
//! $$ \sum_{j=0}^{N} ‖y_{s+j} − ŷ_{s+j}‖^2 + α \sum_j ‖f_{s+j}‖^2
//!    + β \Big(‖f_s − f_{s−1}‖^2 + \sum_j ‖f_{s+j+1} − f_{s+j}‖^2\Big)
//!    + μ ‖D (x_s − \bar x_s)‖^2 + ε ‖D x_s‖^2 , $$
//!
//! where `x̄_s` is the previous window's prediction of `x_s` (the arrival
//! cost), `f_{s−1}` the last committed force and `D` scales each state
//! component by the norm of its output sensitivity over the horizon. The
//! first `L` samples (force and state) are committed, and the window moves
//! by `L`. The last window reaches the end of the record and commits all
//! its samples.
//!
//! Why it stays bounded: the start state is re-estimated from the data of
//! every window instead of being carried open-loop, so an error in `x̄_s`
//! reaches the next window only through the weight `μ` (small); directions
//! of the state no sensor sees (rigid-body motion under acceleration data)
//! shrink by `μ/(μ+ε)` per window instead of drifting. The closed-loop map
//! of the recursion is computed exactly like the paper scheme's and its
//! spectral radius is reported.

use super::run::Plan;
use super::system::System;
use super::window::{Param, RawWindow, WindowOperator};
use nalgebra::{DMatrix, DVector};

/// Weights of the MHE window problem.
#[derive(Debug, Clone, Copy)]
pub struct Weights {
    /// Tikhonov α.
    pub alpha: f64,
    /// First differences β.
    pub beta: f64,
    /// Arrival-cost weight μ.
    pub mu: f64,
    /// Leak ε.
    pub eps: f64,
}

/// Output sensitivity of each start-state component over the window.
fn state_scale(raw: &RawWindow) -> Vec<f64> {
    let mut d = vec![0.0; raw.ns];
    for yj in &raw.y {
        for (i, di) in d.iter_mut().enumerate() {
            *di += yj.column(i).norm_squared();
        }
    }
    let dmax = d.iter().cloned().fold(0.0, f64::max).sqrt();
    d.iter()
        .map(|v| v.sqrt().max(1e-6 * dmax).max(f64::MIN_POSITIVE))
        .collect()
}

/// Parametrization of an MHE window of `raw.len + 1` samples committing
/// `commit` samples (`None`: the last window, committing all).
pub fn param(raw: &RawWindow, w: Weights, commit: Option<usize>) -> Param {
    let (ns, n, len) = (raw.ns, raw.n, raw.len);
    let nxf = raw.nxf();
    let nc = ns + n;
    let nf = n * (len + 1);
    let d = state_scale(raw);
    let with_beta = w.beta > 0.0;
    let npen = nf + if with_beta { nf } else { 0 } + 2 * ns;
    let mut pt = DMatrix::zeros(npen, nxf);
    let mut pc = DMatrix::zeros(npen, nc);
    pt.view_mut((0, ns), (nf, nf)).fill_diagonal(w.alpha.sqrt());
    let mut row = nf;
    if with_beta {
        let sb = w.beta.sqrt();
        for j in 0..=len {
            for i in 0..n {
                pt[(row + i, raw.col_f(j) + i)] = sb;
                if j == 0 {
                    pc[(row + i, ns + i)] = sb;
                } else {
                    pt[(row + i, raw.col_f(j - 1) + i)] = -sb;
                }
            }
            row += n;
        }
    }
    let (sm, se) = (w.mu.sqrt(), w.eps.sqrt());
    for (i, &di) in d.iter().enumerate() {
        pt[(row + i, i)] = sm * di;
        pc[(row + i, i)] = sm * di;
        pt[(row + ns + i, i)] = se * di;
    }
    let (commit_range, next, carry) = match commit {
        Some(l) => (0..l, Some(l), l - 1),
        None => (0..len + 1, None, len),
    };
    Param {
        ntheta: nxf,
        nc,
        s_theta: DMatrix::identity(nxf, nxf),
        s_c: DMatrix::zeros(nxf, nc),
        pen_theta: pt,
        pen_c: pc,
        fit: (0..=len).collect(),
        commit: commit_range,
        next,
        carry_force: carry,
        force_blocks: (0..=len).map(|j| raw.col_f(j)).collect(),
    }
}

/// Plan MHE over `samples` samples (≥ 1): windows advance by `window` and
/// look `horizon` samples ahead; the last window reaches the end.
pub fn plan(sys: &System, samples: usize, window: usize, horizon: usize, w: Weights) -> Plan {
    let last = samples.saturating_sub(1);
    let mut ops: Vec<WindowOperator> = Vec::new();
    let mut windows = Vec::new();
    let mut s = 0;
    loop {
        if s + horizon >= last {
            let raw = RawWindow::build(sys, last - s);
            let prm = param(&raw, w, None);
            ops.push(WindowOperator::new(&raw, prm));
            windows.push((s, ops.len() - 1));
            break;
        }
        if ops.is_empty() {
            ops.push(regular_operator(sys, window, horizon, w));
        }
        windows.push((s, 0));
        s += window;
    }
    Plan {
        ops,
        windows,
        c0: DVector::zeros(2 * sys.m() + sys.n()),
        commit_start: false,
    }
}

/// The regular (non-final) MHE window operator for these settings.
pub fn regular_operator(sys: &System, window: usize, horizon: usize, w: Weights) -> WindowOperator {
    let raw = RawWindow::build(sys, horizon);
    let prm = param(&raw, w, Some(window));
    WindowOperator::new(&raw, prm)
}
