//! The backward Riccati recursion of [`super::smoother`] on the reduced
//! system ([`super::basis::Reduced`]): one step on preallocated buffers,
//! and its fixed point solved directly.
//!
//! **Step.** With `P' = P_{k+1}`, `F = [F_x; 0]` (the last m rows of F are
//! zero: the previous force does not propagate) and `R = C Cᵀ` (Cholesky):
//!
//! $$ R = μI + GᵀP'G,\quad H = (P'G)_xᵀ F_x − μJ,\quad Y = C^{-1} H,\quad
//!    L = C^{-ᵀ} Y,\quad X = C^{-1} Gᵀ, $$
//! $$ P = Q + μJᵀJ + F_xᵀ P'_{xx} F_x − YᵀY $$
//!
//! (`HᵀR⁻¹H = YᵀY`). `X` carries the rest: `R⁻¹Gᵀ = C^{-ᵀ}X` and
//! `G R⁻¹ Gᵀ = XᵀX` (the covariance's process term). About 24 000
//! multiply–adds for lanl8dof with 8 forces (22 reduced states), against
//! 50 000 for the dense form on all 24, in four fused products and two
//! triangular solves, with no allocation.
//!
//! **Fixed point.** `P_∞ = 𝓡(P_∞)` is solved by Newton's method
//! (Kleinman–Hewer) from a recursion iterate close to it: the derivative
//! of the Riccati map at `P` is `E ↦ Φᵀ E Φ` (`Φ = F − G L(P)`), so a
//! Newton step solves the Stein equation `E = Φᵀ E Φ + 𝓡(P) − P`, by
//! Smith's doubling `E ← E + AᵀEA, A ← A²` (2^j terms of the series after
//! j doublings). Convergence is quadratic; `P_∞` is accepted when the last
//! Newton correction is below `1e-12 ‖P‖`. Its own accuracy is rounding
//! amplified by the Stein operator, `~ε/(1 − ρ(Φ)²)`: 1e-13 for the
//! benchmark problem. Knowing `P_∞`, the sweep measures the distance
//! `‖P_k − P_∞‖_max / ‖P_∞‖_max` of every exact iterate and holds the gain
//! once it is below `riccati_tol` (or below twice `P_∞`'s accuracy,
//! estimated by the last Newton correction, when that is larger; or when
//! the change stayed below `riccati_tol` for 4 × [`WINDOW`] steps, should
//! that estimate be too low) — a
//! measured distance, where a small
//! change between two steps is not one (the recursion converges with
//! oscillations: its change dips by 10² and grows again, and stopping in
//! a dip held the gain 50 times too early in the lanl8dof benchmark).
//! The matrix held is the last exact iterate (within rounding of those it
//! stands for), not `P_∞` (whose own rounding it would add).
//!
//! When `P_∞` cannot be solved for because it is ill-conditioned (a
//! closed-loop pole within ~1e-8 of the unit circle,
//! along directions the data barely see: small λ against the noise, more
//! forces than sensors) — the sweep holds the gain once the change of the
//! recursion stayed below `riccati_tol` for [`WINDOW`] steps (longer than
//! the dips), and reports NaN for the distance.

use super::basis::Reduced;
use super::dense::{
    cholesky_in_place, mul, solve_lower, solve_lower_t, symmetrize, view, view_mut,
};
use nalgebra::DMatrix;

/// Steps over which the change of the recursion must stay below the
/// tolerance when the distance to the fixed point cannot decide.
pub(crate) const WINDOW: usize = 64;

/// The matrices of one Riccati step and the buffers to compute them.
#[derive(Debug, Clone)]
pub(crate) struct Riccati {
    /// `P_k` (ns × ns) after [`Riccati::step`].
    pub p: DMatrix<f64>,
    /// `L` (m × ns).
    pub l: DMatrix<f64>,
    /// `X = C⁻¹ Gᵀ` (m × ns).
    pub xg: DMatrix<f64>,
    /// Cholesky factor `C` of `R` (m × m, lower).
    pub c: DMatrix<f64>,
    /// Top rows of F (nx × ns).
    fx: DMatrix<f64>,
    /// `[F_x, G_x]` (nx × (ns + m)).
    fgx: DMatrix<f64>,
    /// `Gᵀ` (m × ns).
    gt: DMatrix<f64>,
    /// `Q + μ JᵀJ`.
    qmu: DMatrix<f64>,
    /// `[P'F, P'G]` (ns × (ns + m)).
    w: DMatrix<f64>,
    /// `Gᵀ [P'F, P'G]` (m × (ns + m)).
    hr: DMatrix<f64>,
    /// `C⁻¹ [H, Gᵀ] = [Y, X]` (m × 2ns).
    yx: DMatrix<f64>,
}

impl Riccati {
    /// Buffers for the system `sys`.
    pub fn new(sys: &Reduced) -> Riccati {
        let (nx, m, ns) = (sys.nx, sys.m, sys.ns);
        debug_assert!(sys.f.rows(nx, m).iter().all(|v| *v == 0.0));
        let mut qmu = sys.stage_weight();
        for i in 0..m {
            qmu[(nx + i, nx + i)] += sys.mu;
        }
        let mut fgx = DMatrix::zeros(nx, ns + m);
        fgx.columns_mut(0, ns).copy_from(&sys.f.rows(0, nx));
        fgx.columns_mut(ns, m).copy_from(&sys.g.rows(0, nx));
        Riccati {
            p: DMatrix::zeros(ns, ns),
            l: DMatrix::zeros(m, ns),
            xg: DMatrix::zeros(m, ns),
            c: DMatrix::zeros(m, m),
            fx: sys.f.rows(0, nx).into_owned(),
            fgx,
            gt: sys.g.transpose(),
            qmu,
            w: DMatrix::zeros(ns, ns + m),
            hr: DMatrix::zeros(m, ns + m),
            yx: DMatrix::zeros(m, 2 * ns),
        }
    }

    /// One step from `pn = P_{k+1}`; false when `R` is not positive
    /// definite. Four products and two triangular solves (the products are
    /// fused: at these sizes a call costs more than its flops).
    pub fn step(&mut self, sys: &Reduced, pn: &DMatrix<f64>) -> bool {
        let (nx, m, ns) = (sys.nx, sys.m, sys.ns);
        let pv = view(pn);
        // W = [P'F, P'G] = P'_{:,x} [F_x, G_x] + [0, P'_{:,w}]
        mul(
            view_mut(&mut self.w),
            false,
            pv.submatrix(0, 0, ns, nx),
            view(&self.fgx),
            1.0,
        );
        for j in 0..m {
            let src = pn.column(nx + j);
            let mut dst = self.w.column_mut(ns + j);
            dst += src;
        }
        // [H + μJ, R − μI] = Gᵀ W
        mul(
            view_mut(&mut self.hr),
            false,
            view(&self.gt),
            view(&self.w),
            1.0,
        );
        // P = Qμ + F_xᵀ (P'F)_x
        self.p.copy_from(&self.qmu);
        let pfx = view(&self.w).submatrix(0, 0, nx, ns);
        mul(
            view_mut(&mut self.p),
            true,
            view(&self.fx).transpose(),
            pfx,
            1.0,
        );
        // R and its Cholesky factor
        self.c.copy_from(&self.hr.columns(ns, m));
        for i in 0..m {
            self.c[(i, i)] += sys.mu;
        }
        if !cholesky_in_place(&mut self.c) {
            return false;
        }
        // [Y, X] = C⁻¹ [H, Gᵀ]
        self.yx
            .columns_mut(0, ns)
            .copy_from(&self.hr.columns(0, ns));
        for i in 0..m {
            self.yx[(i, nx + i)] -= sys.mu;
        }
        self.yx.columns_mut(ns, ns).copy_from(&self.gt);
        solve_lower(&self.c, view_mut(&mut self.yx));
        // P −= YᵀY (HᵀR⁻¹H), L = C⁻ᵀY
        let y = view(&self.yx).submatrix(0, 0, m, ns);
        mul(view_mut(&mut self.p), true, y.transpose(), y, -1.0);
        symmetrize(&mut self.p);
        self.l.copy_from(&self.yx.columns(0, ns));
        solve_lower_t(&self.c, view_mut(&mut self.l));
        self.xg.copy_from(&self.yx.columns(ns, ns));
        true
    }

    /// `Φ = F − G L` of the last step into `phi`.
    pub fn closed_loop(&self, sys: &Reduced, phi: &mut DMatrix<f64>) {
        phi.copy_from(&sys.f);
        mul(view_mut(phi), true, view(&sys.g), view(&self.l), -1.0);
    }
}

/// Relative change `‖a − b‖_max / ‖b‖_max` ([`crate::riccati::rel_change`]).
pub(crate) fn rel_change(a: &DMatrix<f64>, b: &DMatrix<f64>) -> f64 {
    crate::riccati::rel_change(a, b, crate::riccati::RelativeTo::Second)
}

/// Most doublings [`stein`] takes: the series is then summed over 2^40
/// terms, enough for a closed-loop spectral radius up to 1 − 3·10⁻¹¹.
const MAX_DOUBLINGS: usize = 40;
/// Most Newton steps of [`fixed_point`].
const MAX_NEWTON: usize = 6;

/// Solution of the Stein equation `E = Aᵀ E A + Q` by Smith's doubling;
/// None when it does not converge in [`MAX_DOUBLINGS`] doublings.
pub(crate) fn stein(a: &DMatrix<f64>, q: &DMatrix<f64>) -> Option<DMatrix<f64>> {
    let n = a.nrows();
    let mut e = q.clone();
    let mut ak = a.clone();
    let (mut t, mut d, mut a2) = (
        DMatrix::zeros(n, n),
        DMatrix::zeros(n, n),
        DMatrix::zeros(n, n),
    );
    for _ in 0..MAX_DOUBLINGS {
        // E ← E + Aₖᵀ E Aₖ (adds the next 2^j terms), Aₖ₊₁ = Aₖ²
        mul(view_mut(&mut t), false, view(&e), view(&ak), 1.0);
        mul(
            view_mut(&mut d),
            false,
            view(&ak).transpose(),
            view(&t),
            1.0,
        );
        e += &d;
        symmetrize(&mut e);
        let (dmax, emax) = (d.amax(), e.amax());
        if !(dmax.is_finite() && emax.is_finite()) {
            return None;
        }
        if dmax <= 1e-17 * emax {
            return Some(e);
        }
        mul(view_mut(&mut a2), false, view(&ak), view(&ak), 1.0);
        std::mem::swap(&mut ak, &mut a2);
    }
    None
}

/// The fixed point `P_∞` by Newton's method from `start` (see the module
/// docs), with its accuracy (the last Newton correction, relative). None
/// when a step fails, a correction is not smaller than the one before, or
/// [`MAX_NEWTON`] steps do not reach `1e-12 ‖P‖`: the fixed point is then
/// ill-conditioned (a closed-loop pole next to the unit circle).
pub(crate) fn fixed_point(
    sys: &Reduced,
    ric: &mut Riccati,
    start: &DMatrix<f64>,
) -> Option<(DMatrix<f64>, f64)> {
    let mut p = start.clone();
    let mut phi = DMatrix::zeros(sys.ns, sys.ns);
    let mut last = f64::INFINITY;
    for _ in 0..MAX_NEWTON {
        if !ric.step(sys, &p) {
            return None;
        }
        ric.closed_loop(sys, &mut phi);
        let res = &ric.p - &p;
        let e = stein(&phi, &res)?;
        let size = e.amax() / p.amax();
        if !(size < last && size < 1e-3) {
            return None;
        }
        p += &e;
        symmetrize(&mut p);
        if size <= 1e-12 {
            return Some((p, size));
        }
        last = size;
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 2-state, 1-force system: `x_{k+1} = A x_k + b0 w_k + b1 w_{k+1}`,
    /// one output `y = c x + d w`.
    fn small(mu: f64) -> Reduced {
        let f = DMatrix::from_row_slice(3, 3, &[0.95, 0.1, 0.02, -0.3, 0.9, 0.05, 0.0, 0.0, 0.0]);
        let g = DMatrix::from_row_slice(3, 1, &[0.01, 0.04, 1.0]);
        Reduced {
            nx: 2,
            m: 1,
            ns: 3,
            mu,
            lambda: 0.1,
            f,
            g,
            ch: DMatrix::from_row_slice(1, 3, &[1.0, 0.2, 0.5]),
            bc0: DMatrix::zeros(3, 0),
            bc1: DMatrix::zeros(3, 0),
        }
    }

    #[test]
    fn newton_finds_the_limit_of_the_recursion() {
        for mu in [0.0, 0.3] {
            let sys = small(mu);
            let mut ric = Riccati::new(&sys);
            let mut p = sys.stage_weight();
            let mut at = None;
            for k in 0..3000 {
                assert!(ric.step(&sys, &p));
                std::mem::swap(&mut p, &mut ric.p);
                if k == 60 {
                    at = Some(p.clone());
                }
            }
            let start = at.unwrap();
            let (pinf, acc) = fixed_point(&sys, &mut ric, &start).unwrap();
            let d = rel_change(&pinf, &p);
            assert!(
                d < 1e-13 && acc <= 1e-12,
                "μ = {mu}: distance {d:e}, accuracy {acc:e}"
            );
            // and it is a fixed point of the step
            assert!(ric.step(&sys, &pinf));
            assert!(rel_change(&ric.p, &pinf) < 1e-14);
        }
    }

    #[test]
    fn stein_solves_its_equation() {
        let a = DMatrix::from_fn(5, 5, |i, j| 0.15 * (((i * 3 + j * 7) % 5) as f64 - 2.0));
        let b = DMatrix::from_fn(5, 5, |i, j| ((i + 2 * j) % 3) as f64);
        let q = &b * b.transpose();
        let e = stein(&a, &q).unwrap();
        let r = a.transpose() * &e * &a + &q - &e;
        assert!(r.amax() < 1e-13 * e.amax(), "{}", r.amax());
        let unstable = DMatrix::identity(3, 3) * 1.1;
        assert!(stein(&unstable, &DMatrix::identity(3, 3)).is_none());
    }
}
