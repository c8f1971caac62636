//! The smoothed covariance of the Riccati sweep ([`super::smoother`]).
//!
//! With `exp(−J/2)` the posterior density (W the inverse noise covariance,
//! λ, μ the prior precisions), the posterior factors forwards into
//! `p(s_0) Π p(w_{k+1} | s_k)`: `Cov(s_0) = (P_0 + P)^{-1}` and
//! `w_{k+1} | s_k ~ N(−L s_k + l_k, R^{-1})`, so
//!
//! $$ Σ_{k+1} = Φ_k Σ_k Φ_kᵀ + G R_k^{-1} Gᵀ,\quad Φ_k = F − G L_k,
//!    \quad G R^{-1} Gᵀ = XᵀX $$
//!
//! — the Rauch–Tung–Striebel smoothed covariance, obtained without a
//! filter. In the coordinates of [`super::basis`] the covariance of the
//! observable part `[z_V; w]` evolves on its own, exactly (the closed loop
//! has exact zeros in its `[V w, U]` block), and it is all that is
//! computed: the forces, the outputs and the states without a component
//! along a hidden direction depend on it alone. States with such a
//! component (for a free-free model under acceleration data: every
//! displacement and velocity) are set by the initial-state prior, not by
//! the data, and their variance grows without bound: their std is NaN.
//!
//! **Steady region.** The steady closed loop has the fixed point
//! `Σ_∞ = Φ Σ_∞ Φᵀ + XᵀX`, solved by Smith's doubling
//! ([`crate::riccati::stein`]). Before the end transient every transition
//! uses the steady gain, so `Σ_k = Σ_∞ + Φ^k Δ_0 Φ^{kᵀ}`, `Δ_0 = Σ_0 − Σ_∞
//! = V Λ Vᵀ`: one product `Y_{k+1} = Φ Y_k` (`Y_0 = V`) per sample gives every
//! variance, `diag Σ_k = diag Σ_∞ + Σ_j λ_j Y_{k,·j}²`, exactly. Once the
//! force variances and the output trace are within `tol` (relative) of
//! `Σ_∞`'s, `Σ_∞` is held over the steady region; over the transient at the
//! end of the record the recursion runs with the exact gains. When `Σ_∞`
//! cannot be solved for, the recursion runs from the first sample and is
//! held once its force variances and output trace changed by less than
//! `tol` over [`WINDOW`] steps.

use super::basis::Sys;
use super::problem::Lq;
use super::smoother::Backward;
use super::smoother::WINDOW;
use crate::riccati::dense::{mul, solve_lower, symmetrize, view, view_mut};
use crate::riccati::stein;
use nalgebra::DMatrix;

/// Smoother covariance summaries (scaled units, model scale).
#[derive(Debug, Clone)]
pub(crate) struct Covariance {
    /// Variance of every force component (m × N).
    pub var_w: DMatrix<f64>,
    /// Variance of every state (nx × N); NaN where undetermined.
    pub var_x: DMatrix<f64>,
    /// `tr H = Σ_k tr(Ĉ Σ_k Ĉᵀ)` (trace of the influence matrix).
    pub tr_h: f64,
    /// Sample from which the covariance was held constant, if any.
    pub held_from: Option<usize>,
    /// States not determined by the data (a component along a hidden
    /// direction).
    pub undetermined: Vec<usize>,
}

/// One covariance step on the observable block:
/// `Σ' = [ΦΣ, Xᵀ] [Φ, Xᵀ]ᵀ`, two products (and for a transient step one
/// more for Φ and a triangular solve for X).
struct Step<'a> {
    sys: &'a Sys,
    bw: &'a Backward,
    /// `[Φ, Xᵀ]` of a transient step, `[Φ_∞, X_∞ᵀ]` (nr × (nr + m)).
    b: DMatrix<f64>,
    b_ss: DMatrix<f64>,
    /// `[ΦΣ, Xᵀ]`.
    a: DMatrix<f64>,
    /// `X = C⁻¹ Gᵀ` (m × nr) and `Gᵀ`.
    xbar: DMatrix<f64>,
    gt: DMatrix<f64>,
}

impl<'a> Step<'a> {
    fn new(sys: &'a Sys, bw: &'a Backward) -> Step<'a> {
        let (nr, m, q) = (sys.r.ns, sys.r.m, sys.q);
        let mut st = Step {
            sys,
            bw,
            b: DMatrix::zeros(nr, nr + m),
            b_ss: DMatrix::zeros(nr, nr + m),
            a: DMatrix::zeros(nr, nr + m),
            xbar: DMatrix::zeros(m, nr),
            gt: sys.r.g.transpose(),
        };
        st.process(&bw.steady.c);
        st.b_ss
            .columns_mut(0, nr)
            .copy_from(&bw.phi.view((q, q), (nr, nr)));
        st.b_ss.columns_mut(nr, m).tr_copy_from(&st.xbar);
        st
    }

    /// `X = C⁻¹Gᵀ` (`G R⁻¹ Gᵀ = XᵀX`) into `xbar`.
    fn process(&mut self, c: &DMatrix<f64>) {
        self.xbar.copy_from(&self.gt);
        solve_lower(c, view_mut(&mut self.xbar));
    }

    /// `Φ_∞` (nr × nr) and `G R_∞⁻¹ Gᵀ`.
    fn steady(&self) -> (DMatrix<f64>, DMatrix<f64>) {
        let nr = self.b_ss.nrows();
        let x = self.b_ss.columns(nr, self.b_ss.ncols() - nr);
        (self.b_ss.columns(0, nr).into_owned(), x * x.transpose())
    }

    /// `out = Φ_k Σ Φ_kᵀ + XᵀX` for transition `k`.
    fn step(&mut self, k: usize, sig: &DMatrix<f64>, out: &mut DMatrix<f64>) {
        let (bw, r) = (self.bw, &self.sys.r);
        let (nr, m) = (r.ns, r.m);
        if k >= bw.j0 {
            let gain = &bw.transient[k - bw.j0];
            self.process(&gain.c);
            self.b.columns_mut(0, nr).copy_from(&r.f);
            let dst = view_mut(&mut self.b).submatrix_mut(0, 0, nr, nr);
            mul(dst, true, view(&r.g), view(&gain.l), -1.0);
            self.b.columns_mut(nr, m).tr_copy_from(&self.xbar);
        }
        let b = if k < bw.j0 { &self.b_ss } else { &self.b };
        let phi = view(b).submatrix(0, 0, nr, nr);
        let dst = view_mut(&mut self.a).submatrix_mut(0, 0, nr, nr);
        mul(dst, false, phi, view(sig), 1.0);
        self.a.columns_mut(nr, m).copy_from(&b.columns(nr, m));
        mul(
            view_mut(out),
            false,
            view(&self.a),
            view(b).transpose(),
            1.0,
        );
        symmetrize(out);
    }
}

/// One sample's summaries.
#[derive(Debug, Clone)]
struct Summary {
    var_w: Vec<f64>,
    var_x: Vec<f64>,
    tr: f64,
}

impl Summary {
    /// Largest relative distance of the force variances and of the output
    /// trace to `other`'s.
    fn distance(&self, other: &Summary) -> f64 {
        let rel = |a: f64, b: f64| (a - b).abs() / b.abs().max(f64::MIN_POSITIVE);
        self.var_w
            .iter()
            .zip(&other.var_w)
            .map(|(a, b)| rel(*a, *b))
            .fold(rel(self.tr, other.tr), f64::max)
    }
}

/// Reads the summaries off the observable block.
struct Observe {
    /// States along `[z_V; w]` (nxr) and forces (m).
    nxr: usize,
    /// `[Ĉ; W_V]` ((p + nx) × nr), `W_V` the rows of `W_x` on `z_V`
    /// (states, zero on the forces); only Ĉ when every state is
    /// undetermined.
    rows: DMatrix<f64>,
    p: usize,
    /// Undetermined states (NaN).
    undetermined: Vec<bool>,
    /// `rows · Σ`.
    t: DMatrix<f64>,
}

impl Observe {
    fn new(lq: &Lq, sys: &Sys, undetermined: &[usize]) -> Observe {
        let (nx, p, q, nr, nxr) = (lq.nx, lq.p, sys.q, sys.r.ns, sys.r.nx);
        let states = if undetermined.len() == nx { 0 } else { nx };
        let mut rows = DMatrix::zeros(p + states, nr);
        rows.rows_mut(0, p).copy_from(&sys.r.ch);
        if states > 0 {
            rows.view_mut((p, 0), (nx, nxr))
                .copy_from(&sys.wx.columns(q, nxr));
        }
        Observe {
            nxr,
            t: DMatrix::zeros(rows.nrows(), nr),
            rows,
            p,
            undetermined: (0..nx).map(|i| undetermined.contains(&i)).collect(),
        }
    }

    fn nan_states(&self) -> Vec<f64> {
        vec![f64::NAN; self.undetermined.len()]
    }

    /// The summaries of `Σ` (nr × nr).
    fn of(&mut self, sig: &DMatrix<f64>) -> Summary {
        let m = sig.nrows() - self.nxr;
        mul(
            view_mut(&mut self.t),
            false,
            view(&self.rows),
            view(sig),
            1.0,
        );
        let dot = |r: usize| -> f64 { self.t.row(r).dot(&self.rows.row(r)) };
        let tr = (0..self.p).map(dot).sum();
        let mut var_x = self.nan_states();
        if self.rows.nrows() > self.p {
            for (i, v) in var_x.iter_mut().enumerate() {
                if !self.undetermined[i] {
                    *v = dot(self.p + i);
                }
            }
        }
        Summary {
            var_w: (0..m).map(|i| sig[(self.nxr + i, self.nxr + i)]).collect(),
            var_x,
            tr,
        }
    }
}

/// The values recorded so far, in the order of the samples.
struct Record {
    var_w: Vec<f64>,
    var_x: Vec<f64>,
    tr_h: f64,
    held_from: Option<usize>,
}

impl Record {
    fn push(&mut self, s: &Summary) {
        self.var_w.extend_from_slice(&s.var_w);
        self.var_x.extend_from_slice(&s.var_x);
        self.tr_h += s.tr;
    }
}

/// States with a component along a hidden direction.
fn undetermined(sys: &Sys) -> Vec<usize> {
    (0..sys.wx.nrows())
        .filter(|&i| (0..sys.q).any(|j| sys.wx[(i, j)].abs() > 1e-12))
        .collect()
}

/// The start of the record, where every transition has the steady gain:
/// `Σ_k = Σ_∞ + Y_k Λ Y_kᵀ`, `Y_{k+1} = Φ Y_k`. Records samples `0 … k` and
/// returns `(Σ_k, k)`: held (`Σ_∞`, k = j0 − 1) once within `tol`, else
/// explicit at k = j0 − 1.
fn start_region(
    obs: &mut Observe,
    rec: &mut Record,
    phi: &DMatrix<f64>,
    s0: &DMatrix<f64>,
    s_inf: &DMatrix<f64>,
    j0: usize,
    tol: f64,
) -> (DMatrix<f64>, usize) {
    let (nr, nxr) = (s0.nrows(), obs.nxr);
    let inf = obs.of(s_inf);
    let eig = (s0 - s_inf).symmetric_eigen();
    let lam = eig.eigenvalues;
    let mut y = eig.eigenvectors;
    // [Φ; Ĉ; W_V] Y: the next Y and what the summaries need of this one
    let mut rows = DMatrix::zeros(nr + obs.rows.nrows(), nr);
    rows.rows_mut(0, nr).copy_from(phi);
    rows.rows_mut(nr, obs.rows.nrows()).copy_from(&obs.rows);
    let mut my = DMatrix::zeros(rows.nrows(), nr);
    let weighted = |mat: &DMatrix<f64>, r: usize| -> f64 {
        (0..nr).map(|j| lam[j] * mat[(r, j)] * mat[(r, j)]).sum()
    };
    let mut k = 0;
    loop {
        mul(view_mut(&mut my), false, view(&rows), view(&y), 1.0);
        let mut now = Summary {
            var_w: inf.var_w.clone(),
            var_x: inf.var_x.clone(),
            tr: inf.tr + (0..obs.p).map(|r| weighted(&my, nr + r)).sum::<f64>(),
        };
        for (i, v) in now.var_w.iter_mut().enumerate() {
            *v += weighted(&y, nxr + i);
        }
        for (i, v) in now.var_x.iter_mut().enumerate() {
            if !obs.undetermined[i] && obs.rows.nrows() > obs.p {
                *v += weighted(&my, nr + obs.p + i);
            }
        }
        if k + 1 < j0 && now.distance(&inf) <= tol {
            // hold the steady covariance across the steady region
            rec.held_from = Some(k);
            for _ in k..j0 {
                rec.push(&inf);
            }
            return (s_inf.clone(), j0 - 1);
        }
        rec.push(&now);
        if k + 1 >= j0 {
            let sig = s_inf + &y * DMatrix::from_diagonal(&lam) * y.transpose();
            return (sig, k);
        }
        y.copy_from(&my.rows(0, nr));
        k += 1;
    }
}

/// The covariance pass from `Σ̄_0 = sig0` (z coordinates, ns × ns); `tol`
/// bounds the relative error of the held force variances and output trace.
pub(crate) fn covariance(
    lq: &Lq,
    sys: &Sys,
    bw: &Backward,
    sig0: DMatrix<f64>,
    tol: f64,
) -> Covariance {
    let (nx, m, len, q, nr) = (lq.nx, lq.m, lq.len, sys.q, sys.r.ns);
    let undetermined = undetermined(sys);
    let mut obs = Observe::new(lq, sys, &undetermined);
    let mut step = Step::new(sys, bw);
    let mut rec = Record {
        var_w: Vec::with_capacity(m * len),
        var_x: Vec::with_capacity(nx * len),
        tr_h: 0.0,
        held_from: None,
    };
    let s0 = sig0.view((q, q), (nr, nr)).into_owned();
    let (phi, gq) = step.steady();
    let s_inf = if bw.j0 > 2 {
        stein(&phi.transpose(), &gq)
    } else {
        None
    };
    let (mut sig, mut k) = match &s_inf {
        Some(s_inf) => start_region(&mut obs, &mut rec, &phi, &s0, s_inf, bw.j0, tol),
        None => {
            rec.push(&obs.of(&s0));
            (s0, 0)
        }
    };
    // the rest exactly; without Σ_∞, held once the change stayed small
    let mut new = DMatrix::zeros(nr, nr);
    let (mut prev, mut calm) = (obs.of(&sig), 0usize);
    while k + 1 < len {
        step.step(k, &sig, &mut new);
        std::mem::swap(&mut sig, &mut new);
        k += 1;
        let now = obs.of(&sig);
        if s_inf.is_none() && rec.held_from.is_none() && k + 1 < bw.j0 && bw.j0 > 2 {
            calm = if now.distance(&prev) <= tol {
                calm + 1
            } else {
                0
            };
            if calm >= WINDOW {
                rec.held_from = Some(k);
                for _ in k..bw.j0 {
                    rec.push(&now);
                }
                k = bw.j0 - 1;
                prev = now;
                continue;
            }
        }
        rec.push(&now);
        prev = now;
    }
    Covariance {
        var_w: DMatrix::from_vec(m, len, rec.var_w),
        var_x: DMatrix::from_vec(nx, len, rec.var_x),
        tr_h: rec.tr_h,
        held_from: rec.held_from,
        undetermined,
    }
}
