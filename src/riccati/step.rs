//! One step of the backward Riccati recursion of a linear–quadratic
//! problem, on preallocated buffers, and its fixed point solved directly.
//!
//! **Problem.** The cost-to-go `V_k(x) = xᵀ P_k x − 2 p_kᵀ x + const` of
//! the stage cost `xᵀQx + 2uᵀSx + uᵀRu` (plus the data terms, linear in
//! `x` and `u`, which only the vector pass sees) under `x⁺ = A x + B u`.
//! [`Stage`] holds `A`, `B`, `Q`, `S`, `R`; the trailing `n − top` rows of
//! `x⁺` may be the control itself (`A` zero there, `B` the identity: the
//! full-horizon smoother's state `[x; w]` holds the previous force), which
//! the step does not multiply out.
//!
//! **Step.** With `P' = P_{k+1}`, `W = P'[A, B]` and `Q_uu = C Cᵀ`
//! (Cholesky):
//!
//! $$ Q_{uu} = R + D_k + BᵀW_B,\quad Q_{ux} = S + BᵀW_A,\quad
//!    Y = C^{-1} Q_{ux},\quad L = C^{-ᵀ} Y,\quad X = C^{-1} Bᵀ, $$
//! $$ P = Q + A_{top}ᵀ W_{A,top} − YᵀY $$
//!
//! (`Q_uxᵀ Q_uu⁻¹ Q_ux = YᵀY`; `D_k` an optional diagonal that changes
//! from step to step: the lifted smoother's reweighted force prior). `X`
//! carries the rest: `Q_uu⁻¹Bᵀ = C^{-ᵀ}X` and `B Q_uu⁻¹ Bᵀ = XᵀX` (the
//! covariance's process term). For the full-horizon smoother on lanl8dof
//! with 8 forces (22 reduced states) about 24 000 multiply–adds in four
//! fused products and two triangular solves, with no allocation.
//!
//! A stage whose costs are outputs and whose controls share their
//! weights by groups (the lifted smoother's) has its own step, solved in
//! the output space: [`super::grouped`].
//!
//! The optimal control is `u_k = −L x_k + l_k`; the vector pass
//! (`l_k`, `p_k`) belongs to each smoother, since their data terms differ.
//!
//! **Fixed point.** `P_∞ = 𝓡(P_∞)` is solved by Newton's method
//! (Kleinman–Hewer) from a recursion iterate close to it: the derivative
//! of the Riccati map at `P` is `E ↦ Φᵀ E Φ` (`Φ = A − B L(P)`), so a
//! Newton step solves the Stein equation `E = Φᵀ E Φ + 𝓡(P) − P`, by
//! Smith's doubling `E ← E + AᵀEA, A ← A²` (2^j terms of the series after
//! j doublings). Convergence is quadratic; `P_∞` is accepted when the last
//! Newton correction is below `1e-12 ‖P‖`. Its own accuracy is rounding
//! amplified by the Stein operator, `~ε/(1 − ρ(Φ)²)`: 1e-13 for the
//! benchmark problem of the full-horizon smoother (which uses it to
//! decide when to hold its gain, [`crate::horizon::smoother`]). It is
//! None when `P_∞` is ill-conditioned (a closed-loop pole within ~1e-8 of
//! the unit circle, along directions the data barely see).

use super::dense::{cholesky_in_place, mul, solve_lower, solve_lower_t, view, view_mut};
use super::symmetrize;
use nalgebra::DMatrix;

/// The constant matrices of one stage (see the module docs).
#[derive(Debug, Clone)]
pub(crate) struct Stage {
    /// States n.
    pub n: usize,
    /// Controls m.
    pub m: usize,
    /// Rows of `x⁺` that `A`, `B` move; the other `n − top` (0 or m) are
    /// the control.
    pub top: usize,
    /// `[A, B]`, first `top` rows (top × (n + m)).
    ab: DMatrix<f64>,
    /// `A`, first `top` rows (top × n).
    a_top: DMatrix<f64>,
    /// `B` (n × m) and `Bᵀ`.
    b: DMatrix<f64>,
    bt: DMatrix<f64>,
    /// `Q` (n × n), `S` (m × n), `R` (m × m).
    q: DMatrix<f64>,
    s: DMatrix<f64>,
    r: DMatrix<f64>,
}

impl Stage {
    /// The stage `x⁺ = A x + B u`, cost `xᵀQx + 2uᵀSx + uᵀRu`. `a` holds
    /// the first `top` rows of `A` (the others are zero), `b` all of `B`;
    /// when `top < n` the remaining `n − top = m` rows of `x⁺` are `u`
    /// (`B` the identity there, within rounding of its scaling).
    pub fn new(
        a: &DMatrix<f64>,
        b: &DMatrix<f64>,
        q: DMatrix<f64>,
        s: DMatrix<f64>,
        r: DMatrix<f64>,
    ) -> Stage {
        let (top, n, m) = (a.nrows(), a.ncols(), b.ncols());
        assert!(
            b.nrows() == n && (top == n || top + m == n),
            "held rows must be the control"
        );
        let mut ab = DMatrix::zeros(top, n + m);
        ab.columns_mut(0, n).copy_from(a);
        ab.columns_mut(n, m).copy_from(&b.rows(0, top));
        Stage {
            n,
            m,
            top,
            ab,
            a_top: a.clone(),
            bt: b.transpose(),
            b: b.clone(),
            q,
            s,
            r,
        }
    }
}

/// The matrices of one Riccati step and the buffers to compute them.
#[derive(Debug, Clone)]
pub(crate) struct Riccati {
    /// The stage.
    pub stage: Stage,
    /// `P_k` (n × n) after [`Riccati::step`].
    pub p: DMatrix<f64>,
    /// `L` (m × n).
    pub l: DMatrix<f64>,
    /// `X = C⁻¹ Bᵀ` (m × n).
    pub xg: DMatrix<f64>,
    /// Cholesky factor `C` of `Q_uu` (m × m, lower; covariance form).
    pub c: DMatrix<f64>,
    /// `[P'A, P'B]` (n × (n + m)).
    w: DMatrix<f64>,
    /// `Bᵀ [P'A, P'B]` (m × (n + m)).
    hr: DMatrix<f64>,
    /// `C⁻¹ [Q_ux, Bᵀ] = [Y, X]` (m × 2n).
    yx: DMatrix<f64>,
}

impl Riccati {
    /// Buffers for `stage`.
    pub fn new(stage: Stage) -> Riccati {
        let (n, m) = (stage.n, stage.m);
        Riccati {
            stage,
            p: DMatrix::zeros(n, n),
            l: DMatrix::zeros(m, n),
            xg: DMatrix::zeros(m, n),
            c: DMatrix::zeros(m, m),
            w: DMatrix::zeros(n, n + m),
            hr: DMatrix::zeros(m, n + m),
            yx: DMatrix::zeros(m, 2 * n),
        }
    }

    /// One step from `pn = P_{k+1}`, with `diag` (m) added to `Q_uu`'s
    /// diagonal when given; false when `Q_uu` is not positive definite.
    /// Four products and two triangular solves (the products are fused:
    /// at these sizes a call costs more than its flops).
    pub fn step(&mut self, pn: &DMatrix<f64>, diag: Option<&[f64]>) -> bool {
        let st = &self.stage;
        let (n, m, top) = (st.n, st.m, st.top);
        let pv = view(pn);
        // W = [P'A, P'B] = P'_{:,top} [A, B]_top + [0, P'_{:,held}]
        mul(
            view_mut(&mut self.w),
            false,
            pv.submatrix(0, 0, n, top),
            view(&st.ab),
            1.0,
        );
        for j in 0..n - top {
            let src = pn.column(top + j);
            let mut dst = self.w.column_mut(n + j);
            dst += src;
        }
        // [Q_ux − S, Q_uu − R] = Bᵀ W
        mul(
            view_mut(&mut self.hr),
            false,
            view(&st.bt),
            view(&self.w),
            1.0,
        );
        // P = Q + A_topᵀ (P'A)_top
        self.p.copy_from(&st.q);
        let pa = view(&self.w).submatrix(0, 0, top, n);
        mul(
            view_mut(&mut self.p),
            true,
            view(&st.a_top).transpose(),
            pa,
            1.0,
        );
        // Q_uu and its Cholesky factor
        self.c.copy_from(&self.hr.columns(n, m));
        self.c += &st.r;
        if let Some(d) = diag {
            for (i, di) in d.iter().enumerate() {
                self.c[(i, i)] += di;
            }
        }
        if !cholesky_in_place(&mut self.c) {
            return false;
        }
        // [Y, X] = C⁻¹ [Q_ux, Bᵀ]
        self.yx.columns_mut(0, n).copy_from(&self.hr.columns(0, n));
        let mut yq = self.yx.columns_mut(0, n);
        yq += &st.s;
        self.yx.columns_mut(n, n).copy_from(&st.bt);
        solve_lower(&self.c, view_mut(&mut self.yx));
        // P −= YᵀY, L = C⁻ᵀY
        let y = view(&self.yx).submatrix(0, 0, m, n);
        mul(view_mut(&mut self.p), true, y.transpose(), y, -1.0);
        symmetrize(&mut self.p);
        self.l.copy_from(&self.yx.columns(0, n));
        solve_lower_t(&self.c, view_mut(&mut self.l));
        self.xg.copy_from(&self.yx.columns(n, n));
        true
    }

    /// `Φ = A − B L` of the last step into `phi` (n × n).
    pub fn closed_loop(&self, phi: &mut DMatrix<f64>) {
        let st = &self.stage;
        phi.fill(0.0);
        phi.rows_mut(0, st.top).copy_from(&st.a_top);
        mul(view_mut(phi), true, view(&st.b), view(&self.l), -1.0);
    }
}

/// Relative change `‖a − b‖_max / ‖b‖_max` ([`super::rel_change`]).
pub(crate) fn rel_change(a: &DMatrix<f64>, b: &DMatrix<f64>) -> f64 {
    super::rel_change(a, b, super::RelativeTo::Second)
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
pub(crate) fn fixed_point(ric: &mut Riccati, start: &DMatrix<f64>) -> Option<(DMatrix<f64>, f64)> {
    let mut p = start.clone();
    let n = ric.stage.n;
    let mut phi = DMatrix::zeros(n, n);
    let mut last = f64::INFINITY;
    for _ in 0..MAX_NEWTON {
        if !ric.step(&p, None) {
            return None;
        }
        ric.closed_loop(&mut phi);
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
    use nalgebra::DVector;

    /// A 2-state, 1-force system with the force held in the state,
    /// `x_{k+1} = A x_k + b0 w_k + b1 w_{k+1}`, one output `y = c x + d w`,
    /// force prior λ = 0.1 and increment prior μ.
    fn small(mu: f64) -> Stage {
        let a = DMatrix::from_row_slice(2, 3, &[0.95, 0.1, 0.02, -0.3, 0.9, 0.05]);
        let b = DMatrix::from_row_slice(3, 1, &[0.01, 0.04, 1.0]);
        let ch = DMatrix::from_row_slice(1, 3, &[1.0, 0.2, 0.5]);
        let mut q = ch.transpose() * &ch;
        q[(2, 2)] += 0.1 + mu;
        let s = DMatrix::from_row_slice(1, 3, &[0.0, 0.0, -mu]);
        Stage::new(&a, &b, q, s, DMatrix::from_element(1, 1, mu))
    }

    #[test]
    fn newton_finds_the_limit_of_the_recursion() {
        for mu in [0.0, 0.3] {
            let mut ric = Riccati::new(small(mu));
            let mut p = ric.stage.q.clone();
            let mut at = None;
            for k in 0..3000 {
                assert!(ric.step(&p, None));
                std::mem::swap(&mut p, &mut ric.p);
                if k == 60 {
                    at = Some(p.clone());
                }
            }
            let start = at.unwrap();
            let (pinf, acc) = fixed_point(&mut ric, &start).unwrap();
            let d = rel_change(&pinf, &p);
            assert!(
                d < 1e-13 && acc <= 1e-12,
                "μ = {mu}: distance {d:e}, accuracy {acc:e}"
            );
            // and it is a fixed point of the step
            assert!(ric.step(&pinf, None));
            assert!(rel_change(&ric.p, &pinf) < 1e-14);
        }
    }

    /// The step against the textbook formulas on a stage with a full
    /// cross term, a full `R` and a per-step diagonal.
    #[test]
    fn step_matches_the_textbook_formulas() {
        let a = DMatrix::from_fn(3, 3, |i, j| 0.2 * (((i * 5 + j * 3) % 7) as f64 - 3.0));
        let b = DMatrix::from_fn(3, 2, |i, j| 0.1 * ((i + 2 * j) % 3) as f64 + 0.05);
        let h = DMatrix::from_fn(2, 5, |i, j| ((i * 3 + j) % 4) as f64 - 1.5);
        let (hx, hu) = (h.columns(0, 3).into_owned(), h.columns(3, 2).into_owned());
        let q = hx.transpose() * &hx;
        let s = hu.transpose() * &hx;
        let r = hu.transpose() * &hu;
        let mut ric = Riccati::new(Stage::new(&a, &b, q.clone(), s.clone(), r.clone()));
        let pn = DMatrix::from_fn(3, 3, |i, j| if i == j { 2.0 + i as f64 } else { 0.3 });
        let d = [0.7, 0.2];
        assert!(ric.step(&pn, Some(&d)));
        let quu =
            &r + DMatrix::from_diagonal(&DVector::from_column_slice(&d)) + b.transpose() * &pn * &b;
        let qux = &s + b.transpose() * &pn * &a;
        let l = quu.clone().cholesky().unwrap().solve(&qux);
        let p = &q + a.transpose() * &pn * &a - qux.transpose() * &l;
        assert!((&ric.l - &l).amax() < 1e-13 * l.amax());
        assert!((&ric.p - &p).amax() < 1e-13 * p.amax());
        let k = quu.cholesky().unwrap().solve(&b.transpose());
        let mut kg = ric.xg.clone();
        solve_lower_t(&ric.c, view_mut(&mut kg));
        assert!((kg - &k).amax() < 1e-13 * k.amax());
        let mut phi = DMatrix::zeros(3, 3);
        ric.closed_loop(&mut phi);
        assert!((phi - (&a - &b * &l)).amax() < 1e-13);
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
