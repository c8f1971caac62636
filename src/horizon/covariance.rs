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
//! filter. It runs in the coordinates of [`super::basis`], where the
//! covariance of the observable part `[z_V; w]` evolves on its own, exactly
//! (the closed loop has exact zeros in its `[V w, U]` block): the growing
//! variance of the hidden directions cannot leak into the forces.
//!
//! Over the steady region the observable block converges to the fixed
//! point `Σ_∞ = Φ Σ_∞ Φᵀ + XᵀX` of the steady closed loop, solved by
//! Smith's doubling ([`super::riccati::stein`]). The recursion runs from
//! the first sample until its force variances and output-variance trace
//! are within `tol` (relative) of `Σ_∞`'s; `Σ_∞` is then held over the
//! steady region, and over the transient at the end of the record the
//! recursion runs again with the exact gains (when `Σ_∞` cannot be solved
//! for, the recursion is held once its force variances and output trace
//! changed by less than `tol` over [`WINDOW`] steps). States with a component
//! along a hidden direction (for a free-free model under acceleration
//! data: every displacement and velocity) have a variance that grows
//! without bound; from the hold on it is reported as NaN.

use super::basis::Sys;
use super::dense::{mul, solve_lower, symmetrize, view, view_mut};
use super::problem::Lq;
use super::riccati::{stein, WINDOW};
use super::smoother::Backward;
use nalgebra::{DMatrix, DVector};

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
    /// States flagged as not determined by the data.
    pub undetermined: Vec<usize>,
}

/// Buffers of one covariance step (z coordinates). A step is
/// `Σ' = [ΦΣ, Xᵀ] [Φ, Xᵀ]ᵀ`: two products, and for a transient step one
/// more for Φ and a triangular solve for X.
struct Propagator<'a> {
    sys: &'a Sys,
    bw: &'a Backward,
    /// `[Φ, Xᵀ]` of the transient step (ns × (ns + m)).
    b: DMatrix<f64>,
    /// `[Φ_∞, X_∞ᵀ]` (ns × (ns + m)).
    b_ss: DMatrix<f64>,
    /// `[ΦΣ, Xᵀ]` (ns × (ns + m)).
    a: DMatrix<f64>,
    /// `X = C⁻¹Ḡᵀ` (m × ns).
    xbar: DMatrix<f64>,
    gt: DMatrix<f64>,
    cs: DMatrix<f64>,
    tx: DMatrix<f64>,
}

impl<'a> Propagator<'a> {
    fn new(lq: &Lq, sys: &'a Sys, bw: &'a Backward) -> Propagator<'a> {
        let (ns, m) = (lq.ns, lq.m);
        let mut p = Propagator {
            sys,
            bw,
            b: DMatrix::zeros(ns, ns + m),
            b_ss: DMatrix::zeros(ns, ns + m),
            a: DMatrix::zeros(ns, ns + m),
            xbar: DMatrix::zeros(m, ns),
            gt: sys.g.transpose(),
            cs: DMatrix::zeros(lq.p, sys.r.ns),
            tx: DMatrix::zeros(lq.nx, lq.nx),
        };
        p.process(&bw.steady.c);
        p.b_ss.columns_mut(0, ns).copy_from(&bw.phi);
        p.b_ss.columns_mut(ns, m).copy_from(&p.xbar.transpose());
        p
    }

    /// `X = C⁻¹Ḡᵀ` (`Ḡ R⁻¹ Ḡᵀ = XᵀX`) into `xbar`.
    fn process(&mut self, c: &DMatrix<f64>) {
        self.xbar.copy_from(&self.gt);
        solve_lower(c, view_mut(&mut self.xbar));
    }

    /// `Ḡ R_∞⁻¹ Ḡᵀ` (ns × ns).
    fn process_ss(&self) -> DMatrix<f64> {
        let ns = self.b_ss.nrows();
        let x = self.b_ss.columns(ns, self.b_ss.ncols() - ns);
        x * x.transpose()
    }

    /// `out = Φ̄_k Σ Φ̄_kᵀ + XᵀX` for transition `k`; with `observable`, only
    /// the block of `[z_V; w]` (it evolves on its own: `Φ̄[V w, U] = 0`).
    fn step(&mut self, k: usize, sig: &DMatrix<f64>, out: &mut DMatrix<f64>, observable: bool) {
        let (bw, sys) = (self.bw, self.sys);
        let ns = sys.f.nrows();
        let m = self.xbar.nrows();
        if k >= bw.j0 {
            let gain = &bw.transient[k - bw.j0];
            self.process(&gain.c);
            self.b.columns_mut(0, ns).copy_from(&sys.f);
            let dst = view_mut(&mut self.b).submatrix_mut(0, sys.q, ns, sys.r.ns);
            mul(dst, true, view(&sys.g), view(&gain.l), -1.0);
            self.b.columns_mut(ns, m).tr_copy_from(&self.xbar);
        }
        let b = if k < bw.j0 { &self.b_ss } else { &self.b };
        let lo = if observable { sys.q } else { 0 };
        let n = ns - lo;
        // A = [ΦΣ, Xᵀ] (rows and columns lo..), out = A [Φ, Xᵀ]ᵀ
        let phi = view(b).submatrix(lo, lo, n, n);
        let dst = view_mut(&mut self.a).submatrix_mut(lo, lo, n, n);
        mul(dst, false, phi, view(sig).submatrix(lo, lo, n, n), 1.0);
        self.a
            .view_mut((lo, ns), (n, m))
            .copy_from(&b.view((lo, ns), (n, m)));
        let (a, bb) = (
            view(&self.a).submatrix(lo, lo, n, n + m),
            view(b).submatrix(lo, lo, n, n + m),
        );
        mul(
            view_mut(out).submatrix_mut(lo, lo, n, n),
            false,
            a,
            bb.transpose(),
            1.0,
        );
        symmetrize(out);
    }

    /// `tr(Ĉ Σ Ĉᵀ)` (Ĉ is zero on the hidden columns).
    fn output_trace(&mut self, sig: &DMatrix<f64>) -> f64 {
        let (q, nr) = (self.sys.q, self.sys.r.ns);
        let ch = &self.sys.r.ch;
        mul(
            view_mut(&mut self.cs),
            false,
            view(ch),
            view(sig).submatrix(q, q, nr, nr),
            1.0,
        );
        self.cs.iter().zip(ch.iter()).map(|(a, b)| a * b).sum()
    }

    /// Variances of the original states, `diag(W_x Σ̄_xx W_xᵀ)`.
    fn state_var(&mut self, sig: &DMatrix<f64>, out: &mut [f64]) {
        let wx = &self.sys.wx;
        let nx = wx.nrows();
        mul(
            view_mut(&mut self.tx),
            false,
            view(wx),
            view(sig).submatrix(0, 0, nx, nx),
            1.0,
        );
        for (i, o) in out.iter_mut().enumerate() {
            *o = (0..nx).map(|j| self.tx[(i, j)] * wx[(i, j)]).sum();
        }
    }
}

/// The steady covariance of the observable block, `Σ_∞ = Φ Σ_∞ Φᵀ + XᵀX`.
fn steady(sys: &Sys, bw: &Backward, gq_ss: &DMatrix<f64>) -> Option<DMatrix<f64>> {
    let (q, nr) = (sys.q, sys.r.ns);
    let phi_t = bw.phi.view((q, q), (nr, nr)).transpose();
    stein(&phi_t, &gq_ss.view((q, q), (nr, nr)).into_owned())
}

/// One sample's summaries.
#[derive(Debug, Clone)]
struct Summary {
    var_w: DVector<f64>,
    var_x: DVector<f64>,
    tr: f64,
}

impl Summary {
    fn new(lq: &Lq) -> Summary {
        Summary {
            var_w: DVector::zeros(lq.m),
            var_x: DVector::zeros(lq.nx),
            tr: 0.0,
        }
    }

    /// Summaries of `sig`; the state variances only when `states`.
    fn take(&mut self, prop: &mut Propagator<'_>, sig: &DMatrix<f64>, states: bool) {
        let nx = self.var_x.len();
        for (i, v) in self.var_w.iter_mut().enumerate() {
            *v = sig[(nx + i, nx + i)];
        }
        if states {
            prop.state_var(sig, self.var_x.as_mut_slice());
        }
        self.tr = prop.output_trace(sig);
    }

    /// Append this sample's values (samples are recorded in order).
    fn record(&self, rec: &mut Record) {
        rec.var_w.extend_from_slice(self.var_w.as_slice());
        let start = rec.var_x.len();
        rec.var_x.extend_from_slice(self.var_x.as_slice());
        for &i in &rec.undetermined {
            rec.var_x[start + i] = f64::NAN;
        }
        rec.tr_h += self.tr;
    }

    /// Largest relative distance of the force variances and of the output
    /// trace to `other`'s.
    fn distance(&self, other: &Summary) -> f64 {
        let rel = |a: f64, b: f64| (a - b).abs() / b.abs().max(f64::MIN_POSITIVE);
        self.var_w
            .iter()
            .zip(other.var_w.iter())
            .map(|(a, b)| rel(*a, *b))
            .fold(rel(self.tr, other.tr), f64::max)
    }
}

/// The values recorded so far.
struct Record {
    var_w: Vec<f64>,
    var_x: Vec<f64>,
    tr_h: f64,
    undetermined: Vec<usize>,
    held_from: Option<usize>,
}

/// States with a component along a hidden direction.
fn undetermined(sys: &Sys) -> Vec<usize> {
    (0..sys.wx.nrows())
        .filter(|&i| (0..sys.q).any(|j| sys.wx[(i, j)].abs() > 1e-12))
        .collect()
}

/// The covariance pass from `Σ̄_0 = sig0` (z coordinates); `tol` bounds the
/// relative error of the held force variances and output trace.
pub(crate) fn covariance(
    lq: &Lq,
    sys: &Sys,
    bw: &Backward,
    sig0: DMatrix<f64>,
    tol: f64,
) -> Covariance {
    let (nx, m, len, q, nr) = (lq.nx, lq.m, lq.len, sys.q, sys.r.ns);
    let mut cov = Record {
        var_w: Vec::with_capacity(m * len),
        var_x: Vec::with_capacity(nx * len),
        tr_h: 0.0,
        held_from: None,
        undetermined: vec![],
    };
    let mut prop = Propagator::new(lq, sys, bw);
    // the held value (only worth it when there is a steady region)
    let held = if bw.j0 > 2 {
        steady(sys, bw, &prop.process_ss()).map(|s_inf| {
            let mut sig = DMatrix::zeros(lq.ns, lq.ns);
            sig.view_mut((q, q), (nr, nr)).copy_from(&s_inf);
            let mut h = Summary::new(lq);
            h.take(&mut prop, &sig, false);
            (h, s_inf)
        })
    } else {
        None
    };
    let mut sig = sig0;
    let mut new = DMatrix::zeros(lq.ns, lq.ns);
    let (mut prev, mut now) = (Summary::new(lq), Summary::new(lq));
    prev.take(&mut prop, &sig, true);
    prev.record(&mut cov);
    let (mut k, mut calm) = (0usize, 0usize);
    while k + 1 < len {
        // after the hold, the undetermined states are NaN: when they all
        // are, only the observable block is propagated
        let all_nan = cov.undetermined.len() == nx;
        prop.step(k, &sig, &mut new, all_nan);
        std::mem::swap(&mut sig, &mut new);
        k += 1;
        now.take(&mut prop, &sig, !all_nan);
        let open = k + 1 < bw.j0 && cov.held_from.is_none();
        let hold = match &held {
            Some((h, s_inf)) if open && now.distance(h) <= tol => {
                sig.view_mut((q, q), (nr, nr)).copy_from(s_inf);
                true
            }
            None if open && bw.j0 > 2 => {
                // no fixed point: hold once the change stayed small
                calm = if now.distance(&prev) <= tol {
                    calm + 1
                } else {
                    0
                };
                calm >= WINDOW
            }
            _ => false,
        };
        if hold {
            // hold the steady covariance across the steady region
            now.take(&mut prop, &sig, true);
            cov.undetermined = undetermined(sys);
            cov.held_from = Some(k);
            now.record(&mut cov);
            while k + 1 < bw.j0 {
                k += 1;
                now.record(&mut cov);
            }
        } else {
            now.record(&mut cov);
        }
        std::mem::swap(&mut prev, &mut now);
    }
    Covariance {
        var_w: DMatrix::from_vec(m, len, cov.var_w),
        var_x: DMatrix::from_vec(nx, len, cov.var_x),
        tr_h: cov.tr_h,
        held_from: cov.held_from,
        undetermined: cov.undetermined,
    }
}
