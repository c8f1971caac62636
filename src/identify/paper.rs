//! The published sequential window scheme (Hemez & Doebling §6.2, eqs 8–10
//! applied to a force instead of parameters).
//!
//! The record is cut into non-overlapping windows of `L` measurements
//! (`L = 3` in the paper: 30 optimisations over the first 90 samples). In
//! window `w` (start sample `s = wL`, state `x_s` carried from the previous
//! window) one internal-force vector `g_w ∈ Rⁿ` acts, constant, over the
//! whole window interval `(t_s, t_{s+L}]` (piecewise constant, jumping at
//! window starts, as published: the model is integrated through the window
//! with the force held), and
//!
//! $$ g_w = \arg\min_g \sum_{j=1}^{L} ‖ y_{s+j} − ŷ_{s+j}(x_s, g) ‖^2
//!    + α ‖g‖^2 + β ‖g − g_{w−1}‖^2 . $$
//!
//! In the sampled model (force linear between samples) a held force is
//! `f_{s+j} = g_w` for `j = 0..=L` inside the window; the output at the
//! window's start sample was fitted by the previous window with `g_{w−1}`.
//!
//! The state is then propagated to `x_{s+L}` and carried. The record starts
//! at rest with no force. The recursion `c_{w+1} = F c_w + (data)` on
//! `c = [x_s; g_{w−1}]` is linear; the spectral radius of `F`
//! ([`super::window::OperatorInfo::spectral_radius`]) decides whether
//! errors (model error, noise, round-off) grow from window to window.
//! docs/theory.md, fact R1: with SEREP on DOFs 1, 5, 6 and α ≤ 1 it exceeds 1 and
//! the estimate diverges over a whole record.

use super::run::Plan;
use super::system::System;
use super::window::{Param, RawWindow, WindowOperator};
use nalgebra::{DMatrix, DVector};

/// Parametrization of a paper window of `raw.len` measurements.
pub fn param(raw: &RawWindow, alpha: f64, beta: f64) -> Param {
    let (ns, n, len) = (raw.ns, raw.n, raw.len);
    let nxf = raw.nxf();
    let nc = ns + n;
    let mut s_theta = DMatrix::zeros(nxf, n);
    for j in 0..=len {
        s_theta
            .view_mut((raw.col_f(j), 0), (n, n))
            .fill_with_identity();
    }
    let mut s_c = DMatrix::zeros(nxf, nc);
    s_c.view_mut((0, 0), (ns, ns)).fill_with_identity();
    let npen = if beta > 0.0 { 2 * n } else { n };
    let mut pen_theta = DMatrix::zeros(npen, n);
    let mut pen_c = DMatrix::zeros(npen, nc);
    pen_theta
        .view_mut((0, 0), (n, n))
        .fill_diagonal(alpha.sqrt());
    if beta > 0.0 {
        pen_theta
            .view_mut((n, 0), (n, n))
            .fill_diagonal(beta.sqrt());
        pen_c.view_mut((n, ns), (n, n)).fill_diagonal(beta.sqrt());
    }
    Param {
        ntheta: n,
        nc,
        s_theta,
        s_c,
        pen_theta,
        pen_c,
        fit: (1..=len).collect(),
        commit: 1..len + 1,
        next: Some(len),
        carry_force: len,
        force_blocks: vec![0],
    }
}

fn operator(sys: &System, len: usize, alpha: f64, beta: f64) -> WindowOperator {
    let raw = RawWindow::build(sys, len);
    let prm = param(&raw, alpha, beta);
    WindowOperator::new(&raw, prm)
}

/// Plan the paper scheme over `samples` samples (≥ 2) with windows of
/// `window` measurements, starting at rest with no force.
pub fn plan(sys: &System, samples: usize, window: usize, alpha: f64, beta: f64) -> Plan {
    let last = samples.saturating_sub(1);
    let mut ops = vec![operator(sys, window, alpha, beta)];
    let mut windows = Vec::new();
    let mut s = 0;
    while s < last {
        let len = window.min(last - s);
        if len == window {
            windows.push((s, 0));
        } else {
            ops.push(operator(sys, len, alpha, beta));
            windows.push((s, 1));
        }
        s += len;
    }
    Plan {
        ops,
        windows,
        c0: DVector::zeros(2 * sys.m() + sys.n()),
        commit_start: true,
    }
}

/// Closed-loop spectral radius of the paper recursion for these settings.
pub fn spectral_radius(sys: &System, window: usize, alpha: f64, beta: f64) -> f64 {
    operator(sys, window, alpha, beta)
        .info
        .spectral_radius
        .unwrap_or(f64::NAN)
}
