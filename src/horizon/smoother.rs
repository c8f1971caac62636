//! The Riccati sweep: exact minimiser of the full-horizon cost in time
//! linear in the record length.
//!
//! **Backward pass** (dynamic programming). The cost-to-go of samples
//! `k … N−1` given `s_k` is `V_k(s) = sᵀ P_k s − 2 p_kᵀ s + const`, with
//! `P_{N−1} = Q = ĈᵀĈ + λ JᵀJ` (`J s = w`). One step, with `P' = P_{k+1}`:
//!
//! $$ R = μ I + Gᵀ P' G,\quad H = Gᵀ P' F − μ J,\quad L = R^{-1} H, $$
//! $$ P_k = Q + μ JᵀJ + Fᵀ P' F − Hᵀ L,\quad
//!    e = p' − P' c_k,\quad p_k = Ĉᵀ ỹ_k + (F − G L)ᵀ e,\quad
//!    l_k = R^{-1} Gᵀ e. $$
//!
//! The optimal control is `w_{k+1} = −L s_k + l_k`. The sweep runs in the
//! coordinates of [`super::basis`]: the states the data cannot see (a
//! free-free model's rigid-body position, and velocity, under
//! acceleration data) have an exactly zero cost-to-go and are split off,
//! so the recursion runs on the closed, observable part (22 of 24 states
//! for lanl8dof with 8 forces).
//!
//! `P_k` does not depend on the data. It is iterated from the end of the
//! record ([`crate::riccati::Riccati`]) until its measured distance to the fixed
//! point is below `riccati_tol`; those transient gains are stored and the
//! last one is held for the rest of the sweep. There a sample costs one
//! product `Φᵀ p'` (Φ = F − G L, 22 × 22); every term that does not depend
//! on `p'` — data, known force, `l_k` from the stored `p'` — is formed by
//! matrix–matrix products over blocks of [`BLOCK`] samples. On records
//! shorter than the transient nothing is held.
//!
//! **Forward pass.** `s_0 = argmin V_0(s) + ‖x_0 − x̄_0‖²_P` (the prior
//! sets the hidden directions), then `s_{k+1} = F s_k + G(−L s_k + l_k) +
//! c_k` on the whole state: the terms `G l_k + c_k` for all samples in
//! three matrix products, then one `Φ̄ z_k` per sample (`Φ̄` has exact
//! zeros where the forces would see the rigid-body drift).
//!
//! The covariance pass is in [`super::covariance`].

use super::assemble::Sink;
use super::basis::{Reduced, Sys};
use super::problem::{Init, Lq};
use super::settings::HorizonSettings;
use crate::riccati::dense::{
    gemv_acc, mul, solve_lower_t, solve_lower_t_vec, symmetrize, view, view_mut,
};
use crate::riccati::step::rel_change;
use crate::riccati::{fixed_point, Riccati};
use nalgebra::{DMatrix, DVector};

/// Steps over which the change of the recursion must stay below the
/// tolerance when the distance to the fixed point cannot decide (see
/// [`backward`]).
pub(crate) const WINDOW: usize = 64;
/// Samples per block of the steady backward pass.
pub(crate) const BLOCK: usize = 256;
/// The fixed point is solved for when the change of `P` over one step
/// first falls below each of these (at most one attempt each; Newton then
/// converges in two or three steps).
const NEWTON_AT: [f64; 3] = [1e-8, 1e-10, 1e-12];

/// Gains of one transition `k → k+1` (reduced coordinates).
#[derive(Debug, Clone)]
pub(crate) struct Gain {
    /// L (m × ns of the reduced system).
    pub l: DMatrix<f64>,
    /// Cholesky factor `C` of `R` (m × m): `G R⁻¹ Gᵀ = XᵀX`, `X = C⁻¹Gᵀ`.
    pub c: DMatrix<f64>,
}

/// Numerical trouble of the sweep: a matrix that must be positive definite
/// was not, at transition `k` (N−1 for the initial-state system).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct NotPositiveDefinite {
    /// Transition index.
    pub k: usize,
}

/// Result of the backward pass.
#[derive(Debug, Clone)]
pub(crate) struct Backward {
    /// Transitions `k ≥ j0` use `transient[k − j0]`; `k < j0` the steady
    /// gain.
    pub j0: usize,
    /// Gains of the transient near the end of the record.
    pub transient: Vec<Gain>,
    /// Steady-state gain.
    pub steady: Gain,
    /// Steady closed loop `Φ̄ = F̄ − Ḡ [0, L]` (ns × ns, z coordinates).
    pub phi: DMatrix<f64>,
    /// Feed-forward terms `l_k` (m × N, the last column unused).
    pub lff: DMatrix<f64>,
    /// `P_0` (reduced).
    pub p0: DMatrix<f64>,
    /// `p_0` (reduced).
    pub pv0: DVector<f64>,
    /// False when `max_transient` steps passed without convergence.
    pub converged: bool,
    /// Relative change of `P` at the last transient step.
    pub last_change: f64,
    /// Relative distance `‖P_{j0} − P_∞‖_max / ‖P_∞‖_max` of the last exact
    /// iterate to the fixed point whose gain is held (0 when nothing is
    /// held, NaN when the fixed point was not found).
    pub held_distance: f64,
}

/// `e = p' − P' c_k` and the transient step's `l_k`, `p_k`, with the
/// transposed matrices they need (so that every product is a `y += A x`).
struct Vectors {
    c: Vec<f64>,
    e: Vec<f64>,
    ge: Vec<f64>,
    u: Vec<f64>,
    pnew: DVector<f64>,
    /// Ĉᵀ (ns × p), F_xᵀ (ns × nx), Gᵀ (m × ns).
    cht: DMatrix<f64>,
    fxt: DMatrix<f64>,
    gt: DMatrix<f64>,
    lt: DMatrix<f64>,
}

impl Vectors {
    fn new(r: &Reduced) -> Vectors {
        Vectors {
            c: vec![0.0; r.ns],
            e: vec![0.0; r.ns],
            ge: vec![0.0; r.m],
            u: vec![0.0; r.m],
            pnew: DVector::zeros(r.ns),
            cht: r.ch.transpose(),
            fxt: r.f.rows(0, r.nx).transpose(),
            gt: r.g.transpose(),
            lt: DMatrix::zeros(r.ns, r.m),
        }
    }

    /// Backward vector step `k` with exact gains from `P' = pn`: writes
    /// `l_k` into `lff` and returns `p_k` in `self.pnew`.
    #[allow(clippy::too_many_arguments)]
    fn step(
        &mut self,
        lq: &Lq,
        r: &Reduced,
        ric: &Riccati,
        pn: &DMatrix<f64>,
        pv: &DVector<f64>,
        k: usize,
        lff: &mut DMatrix<f64>,
    ) {
        // e = p' − P' c_k
        self.c.iter_mut().for_each(|v| *v = 0.0);
        r.add_c(&lq.gin, k, &mut self.c);
        self.c.iter_mut().for_each(|v| *v = -*v);
        self.e.copy_from_slice(pv.as_slice());
        gemv_acc(pn.as_slice(), &self.c, &mut self.e);
        // l_k = C⁻ᵀ (X e)
        self.u.iter_mut().for_each(|v| *v = 0.0);
        gemv_acc(ric.xg.as_slice(), &self.e, &mut self.u);
        solve_lower_t_vec(&ric.c, &mut self.u);
        lff.column_mut(k).as_mut_slice().copy_from_slice(&self.u);
        // p_k = Ĉᵀ ỹ_k + F_xᵀ e_x − Lᵀ (Gᵀ e)
        let out = self.pnew.as_mut_slice();
        out.iter_mut().for_each(|v| *v = 0.0);
        gemv_acc(self.cht.as_slice(), lq.target.column(k).as_slice(), out);
        gemv_acc(self.fxt.as_slice(), &self.e[..r.nx], out);
        self.ge.iter_mut().for_each(|v| *v = 0.0);
        gemv_acc(self.gt.as_slice(), &self.e, &mut self.ge);
        self.ge.iter_mut().for_each(|v| *v = -*v);
        self.lt.tr_copy_from(&ric.l);
        gemv_acc(self.lt.as_slice(), &self.ge, out);
    }
}

/// The state of the exact recursion from the end of the record and of its
/// fixed-point test (see [`backward`]).
struct Transient {
    /// `P` of the last exact step.
    p: DMatrix<f64>,
    /// The fixed point and its accuracy, once solved for.
    pinf: Option<(DMatrix<f64>, f64)>,
    /// `‖P − P_∞‖_max / ‖P_∞‖_max` (∞ before `P_∞` is known).
    distance: f64,
    /// Relative change of `P` over the last step.
    last_change: f64,
    /// Newton attempts made (at most one per [`NEWTON_AT`] threshold).
    attempts: usize,
    /// Consecutive steps with a change below the tolerance.
    calm: usize,
}

impl Transient {
    fn new(r: &Reduced) -> Transient {
        Transient {
            p: r.stage_weight(),
            pinf: None,
            distance: f64::INFINITY,
            last_change: f64::INFINITY,
            attempts: 0,
            calm: 0,
        }
    }

    /// After an exact step: may the gain be held from here? The measured
    /// distance when the fixed point is known (down to its own accuracy),
    /// else a change that stayed below `tol` for [`WINDOW`] steps.
    fn settles(&mut self, ric: &mut Riccati, tol: f64) -> bool {
        self.calm = if self.last_change <= tol {
            self.calm + 1
        } else {
            0
        };
        let due = NEWTON_AT
            .get(self.attempts)
            .is_some_and(|t| self.last_change <= *t);
        if self.pinf.is_none() && due {
            self.attempts += 1;
            self.pinf = fixed_point(ric, &self.p);
        }
        match &self.pinf {
            Some((pinf, acc)) => {
                self.distance = rel_change(&self.p, pinf);
                // (a floor under-estimated by `acc` must not run on forever)
                self.distance <= tol.max(2.0 * acc) || self.calm >= 4 * WINDOW
            }
            None => self.attempts == NEWTON_AT.len() && self.calm >= WINDOW,
        }
    }
}

/// The backward pass.
///
/// **When the gain is held.** Once the change of `P` over a step first
/// falls below each of [`NEWTON_AT`], the fixed point `P_∞` is solved for
/// ([`crate::riccati::fixed_point`]). Knowing it, the sweep measures the
/// distance `‖P_k − P_∞‖_max / ‖P_∞‖_max` of every exact iterate and holds
/// the gain once it is below `riccati_tol` (or below twice `P_∞`'s
/// accuracy, estimated by the last Newton correction, when that is
/// larger; or when the change stayed below `riccati_tol` for 4 ×
/// [`WINDOW`] steps, should that estimate be too low) — a measured
/// distance, where a small change between two steps is not one (the
/// recursion converges with oscillations: its change dips by 10² and grows
/// again, and stopping in a dip held the gain 50 times too early in the
/// lanl8dof benchmark). The matrix held is the last exact iterate (within
/// rounding of those it stands for), not `P_∞` (whose own rounding it
/// would add). When `P_∞` cannot be solved for (a closed-loop pole within
/// ~1e-8 of the unit circle, along directions the data barely see: small
/// λ against the noise, more forces than sensors) the gain is held once
/// the change stayed below `riccati_tol` for [`WINDOW`] steps (longer than
/// the dips), and the distance is reported as NaN.
pub(crate) fn backward(
    lq: &Lq,
    sys: &Sys,
    settings: &HorizonSettings,
) -> Result<Backward, NotPositiveDefinite> {
    let (tol, hold) = (settings.riccati_tol, settings.hold_steady_gain);
    let (r, m, len) = (&sys.r, lq.m, lq.len);
    let mut ric = Riccati::new(r.stage());
    let mut pv = DVector::zeros(r.ns);
    pv.gemv_tr(1.0, &r.ch, &lq.target.column(len - 1), 0.0);
    let mut lff = DMatrix::zeros(m, len);
    let mut transient: Vec<Gain> = Vec::new();
    let mut tr = Transient::new(r);
    let mut vec = Vectors::new(r);
    let (mut j, mut settled) = (len - 1, false);
    while j > 0 {
        let k = j - 1;
        if !ric.step(&tr.p, None) {
            return Err(NotPositiveDefinite { k });
        }
        vec.step(lq, r, &ric, &tr.p, &pv, k, &mut lff);
        std::mem::swap(&mut pv, &mut vec.pnew);
        tr.last_change = rel_change(&ric.p, &tr.p);
        std::mem::swap(&mut tr.p, &mut ric.p);
        transient.push(Gain {
            l: ric.l.clone(),
            c: ric.c.clone(),
        });
        j -= 1;
        if hold {
            settled = tr.settles(&mut ric, tol);
            if settled || transient.len() >= settings.max_transient {
                break;
            }
        }
    }
    // hold the last exact iterate: it is within `tol` of the fixed point,
    // and within rounding of the iterates it stands for, where the fixed
    // point solved for carries its own rounding, amplified by the Stein
    // operator (1e-13 for the benchmark problem)
    let held = (j > 0).then(|| tr.p.clone());
    let steady = match &held {
        Some(pss) => {
            // the steady gain: one step at the held matrix
            if !ric.step(pss, None) {
                return Err(NotPositiveDefinite { k: j - 1 });
            }
            Gain {
                l: ric.l.clone(),
                c: ric.c.clone(),
            }
        }
        None => transient
            .last()
            .cloned()
            .ok_or(NotPositiveDefinite { k: 0 })?,
    };
    let mut phi = sys.f.clone();
    let dst = view_mut(&mut phi).submatrix_mut(0, sys.q, lq.ns, r.ns);
    mul(dst, true, view(&sys.g), view(&steady.l), -1.0);
    let held_distance = match (&held, &tr.pinf) {
        (None, _) => 0.0,
        (Some(_), Some(_)) => tr.distance,
        (Some(_), None) => f64::NAN,
    };
    let p0 = match held {
        Some(pss) => {
            steady_backward(lq, r, &ric, &pss, j, &mut pv, &mut lff);
            pss
        }
        None => tr.p,
    };
    transient.reverse();
    let j0 = len - 1 - transient.len();
    Ok(Backward {
        j0,
        transient,
        steady,
        phi,
        lff,
        p0,
        pv0: pv,
        converged: j == 0 || settled,
        last_change: tr.last_change,
        held_distance,
    })
}

/// Steady-state part of the backward pass for transitions `j−1 … 0`:
/// `p_k = Φᵀ p' + β_k`, `l_k = K p' + γ_k` with `K = R⁻¹Gᵀ` and
/// `β_k = Ĉᵀỹ_k − ΦᵀP c_k`, `γ_k = −K P c_k` (`c_k = B_c0 g_k + B_c1
/// g_{k+1}`) formed by blocks. `ric` holds the steady step.
fn steady_backward(
    lq: &Lq,
    r: &Reduced,
    ric: &Riccati,
    pss: &DMatrix<f64>,
    j: usize,
    pv: &mut DVector<f64>,
    lff: &mut DMatrix<f64>,
) {
    let (ns, m, p) = (r.ns, r.m, lq.p);
    let n_in = lq.gin.nrows();
    let mut k_gain = ric.xg.clone();
    solve_lower_t(&ric.c, view_mut(&mut k_gain));
    let mut phi = DMatrix::zeros(ns, ns);
    ric.closed_loop(&mut phi);
    let phit = phi.transpose();
    // −[Φᵀ; K] P B_c0 and −[Φᵀ; K] P B_c1
    let mut stack = DMatrix::zeros(ns + m, ns);
    stack.rows_mut(0, ns).copy_from(&phit);
    stack.rows_mut(ns, m).copy_from(&k_gain);
    let mut z = [DMatrix::zeros(ns + m, n_in), DMatrix::zeros(ns + m, n_in)];
    let mut pb = DMatrix::zeros(ns, n_in);
    for (zi, bc) in z.iter_mut().zip([&r.bc0, &r.bc1]) {
        mul(view_mut(&mut pb), false, view(pss), view(bc), 1.0);
        mul(view_mut(zi), false, view(&stack), view(&pb), -1.0);
    }
    let cht = r.ch.transpose();
    // columns 0..nb: β_k then p_k of the block; column nb: p' carried in
    let mut beta = DMatrix::zeros(ns, BLOCK + 1);
    let gin = view(&lq.gin);
    let mut k1 = j;
    while k1 > 0 {
        let k0 = k1.saturating_sub(BLOCK);
        let nb = k1 - k0;
        beta.column_mut(nb).copy_from(pv);
        let bv = view_mut(&mut beta).submatrix_mut(0, 0, ns, nb);
        mul(
            bv,
            false,
            view(&cht),
            view(&lq.target).submatrix(0, k0, p, nb),
            1.0,
        );
        for (zi, off) in z.iter().zip([0, 1]) {
            let bv = view_mut(&mut beta).submatrix_mut(0, 0, ns, nb);
            let zb = view(zi).submatrix(0, 0, ns, n_in);
            mul(bv, true, zb, gin.submatrix(0, k0 + off, n_in, nb), 1.0);
        }
        for i in (0..nb).rev() {
            let (done, next) = beta.as_mut_slice().split_at_mut((i + 1) * ns);
            gemv_acc(phit.as_slice(), &next[..ns], &mut done[i * ns..]);
        }
        let lv = view_mut(lff).submatrix_mut(0, k0, m, nb);
        mul(
            lv,
            false,
            view(&k_gain),
            view(&beta).submatrix(0, 1, ns, nb),
            1.0,
        );
        for (zi, off) in z.iter().zip([0, 1]) {
            let lv = view_mut(lff).submatrix_mut(0, k0, m, nb);
            let zb = view(zi).submatrix(ns, 0, m, n_in);
            mul(lv, true, zb, gin.submatrix(0, k0 + off, n_in, nb), 1.0);
        }
        pv.copy_from(&beta.column(0));
        k1 = k0;
    }
}

/// Initial state and its covariance in z coordinates: `(z_0, Σ̄_0,
/// dropped directions)`. The reduced `P_0`, `p_0` are embedded in the full
/// state (zero on the hidden directions) and the initial-state prior added.
pub(crate) fn initial_state(
    lq: &Lq,
    sys: &Sys,
    bw: &Backward,
) -> Result<(DVector<f64>, DMatrix<f64>, usize), NotPositiveDefinite> {
    let (nx, m, ns, q) = (lq.nx, lq.m, lq.ns, sys.q);
    let (nr, nxr) = (sys.r.ns, sys.r.nx);
    let trouble = NotPositiveDefinite { k: lq.len - 1 };
    let wxt = sys.wx.transpose();
    match &lq.init {
        Init::Fixed(x0) => {
            let zx0 = &wxt * x0;
            let pww = bw.p0.view((nxr, nxr), (m, m)).into_owned();
            let chol = pww.cholesky().ok_or(trouble)?;
            let rhs = bw.pv0.rows(nxr, m) - bw.p0.view((nxr, 0), (m, nxr)) * zx0.rows(q, nxr);
            let w0 = chol.solve(&rhs);
            let mut z0 = DVector::zeros(ns);
            z0.rows_mut(0, nx).copy_from(&zx0);
            z0.rows_mut(nx, m).copy_from(&w0);
            let mut sig = DMatrix::zeros(ns, ns);
            sig.view_mut((nx, nx), (m, m)).copy_from(&chol.inverse());
            Ok((z0, sig, 0))
        }
        Init::Prior { p, mean } => {
            let mut h = DMatrix::zeros(ns, ns);
            h.view_mut((q, q), (nr, nr)).copy_from(&bw.p0);
            let pz = &wxt * p * &sys.wx;
            let mut h_xx = h.view_mut((0, 0), (nx, nx));
            h_xx += &pz;
            let mut rhs = DVector::zeros(ns);
            rhs.rows_mut(q, nr).copy_from(&bw.pv0);
            let mut r_x = rhs.rows_mut(0, nx);
            r_x += &pz * (&wxt * mean);
            symmetrize(&mut h);
            match h.clone().cholesky() {
                Some(ch) => Ok((ch.solve(&rhs), ch.inverse(), 0)),
                None => pseudo_solve(h, &rhs).ok_or(trouble),
            }
        }
    }
}

/// Minimum-norm solution and pseudo-inverse of a symmetric semi-definite
/// matrix, with the count of discarded directions.
fn pseudo_solve(
    h: DMatrix<f64>,
    rhs: &DVector<f64>,
) -> Option<(DVector<f64>, DMatrix<f64>, usize)> {
    let eig = h.symmetric_eigen();
    let vmax = eig.eigenvalues.amax();
    if !(vmax > 0.0 && vmax.is_finite()) {
        return None;
    }
    let cut = vmax * 1e-13;
    let mut dropped = 0;
    let inv = eig.eigenvalues.map(|v| {
        if v > cut {
            1.0 / v
        } else {
            dropped += 1;
            0.0
        }
    });
    let q = &eig.eigenvectors;
    let pinv = q * DMatrix::from_diagonal(&inv) * q.transpose();
    Some((&pinv * rhs, pinv, dropped))
}

/// The forward pass from `z0`: the states `z_k` (coordinates of
/// [`super::basis`]: `s̃_x = W_x z_x`, forces unchanged), pushed to `sink`
/// by blocks of [`BLOCK`] samples. `sink.force` holds the feed-forward
/// terms `l_k` (column k), which it overwrites with the forces as the
/// blocks go by.
pub(crate) fn forward(lq: &Lq, sys: &Sys, bw: &Backward, z0: &DVector<f64>, sink: &mut Sink<'_>) {
    let (nx, ns, m, len, q) = (lq.nx, lq.ns, lq.m, lq.len, sys.q);
    let n_in = lq.gin.nrows();
    let mut zb = DMatrix::zeros(ns, BLOCK + 1);
    zb.set_column(0, z0);
    let fx = sys.f.rows(0, nx).into_owned();
    let mut u = vec![0.0; m];
    let gin = view(&lq.gin);
    let mut k0 = 0;
    while k0 < len {
        let nb = BLOCK.min(len - k0);
        let steps = nb.min(len - 1 - k0);
        // z_{k+1} ← Ḡ l_k + B̄_c0 g_k + B̄_c1 g_{k+1} for the block
        let dst = view_mut(&mut zb).submatrix_mut(0, 1, ns, steps);
        let lv = view(&sink.force).submatrix(0, k0, m, steps);
        mul(dst, false, view(&sys.g), lv, 1.0);
        for (bc, off) in [(&sys.bc0, 0), (&sys.bc1, 1)] {
            let dst = view_mut(&mut zb).submatrix_mut(0, 1, ns, steps);
            mul(
                dst,
                true,
                view(bc),
                gin.submatrix(0, k0 + off, n_in, steps),
                1.0,
            );
        }
        for i in 0..steps {
            let k = k0 + i;
            let (done, next) = zb.as_mut_slice().split_at_mut((i + 1) * ns);
            let (zk, zn) = (&done[i * ns..], &mut next[..ns]);
            if k < bw.j0 {
                gemv_acc(bw.phi.as_slice(), zk, zn);
            } else {
                // z_{k+1} += F̄_x z_k (top rows) − Ḡ (L_k z_k,r)
                let gain = &bw.transient[k - bw.j0];
                gemv_acc(fx.as_slice(), zk, &mut zn[..nx]);
                u.iter_mut().for_each(|v| *v = 0.0);
                gemv_acc(gain.l.as_slice(), &zk[q..], &mut u);
                u.iter_mut().for_each(|v| *v = -*v);
                gemv_acc(sys.g.as_slice(), &u, zn);
            }
        }
        sink.push(&zb.as_slice()[..ns * nb], k0);
        if steps == nb {
            let carry = zb.column(nb).into_owned();
            zb.set_column(0, &carry);
        }
        k0 += nb;
    }
}
