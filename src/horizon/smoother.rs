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
//! The optimal control is `w_{k+1} = −L s_k + l_k`. `P_k` does not depend
//! on the data: once it stops changing (relative change below
//! `riccati_tol` for three steps) the steady-state gains are used for the
//! rest of the sweep, so each sample costs a few matrix–vector products.
//! On records shorter than the transient nothing is approximated. States
//! the data cannot see (a free-free model's rigid-body position, and
//! velocity, under acceleration data) have an exactly zero cost-to-go; `P`
//! and `p` are projected off them at every step, otherwise rounding there
//! grows quadratically through the rigid-body Jordan block and the
//! recursion never looks converged.
//!
//! **Forward pass.** `s_0 = argmin V_0(s) + ‖x_0 − x̄_0‖²_P`, then
//! `s_{k+1} = F s_k + G(−L s_k + l_k) + c_k`.
//!
//! **Covariance.** With `exp(−J/2)` the posterior density (W the inverse
//! noise covariance, λ, μ the prior precisions), the posterior factors
//! forwards into `p(s_0) Π p(w_{k+1} | s_k)`: `Cov(s_0) = (P_0 + P)^{-1}`
//! and `w_{k+1} | s_k ~ N(−L s_k + l_k, R^{-1})`, so
//! `Σ_{k+1} = Φ Σ_k Φᵀ + G R^{-1} Gᵀ`, `Φ = F − G L` — the
//! Rauch–Tung–Striebel smoothed covariance, obtained without a filter. It
//! is run until its force variances stop changing (or, at the latest, for
//! one Riccati transient, after which it has converged up to rounding) and
//! then held over the steady region. The closed loop leaves the hidden directions `U`
//! (rigid-body position/velocity the channels cannot see) invariant and
//! `L U = Ĉ U = 0`, so the force and output covariances do not depend on
//! them, while their own variance grows without bound: states whose
//! variance still changes when the covariance is held are flagged and
//! reported as NaN from there on.

use super::problem::{Init, Lq};
use nalgebra::{DMatrix, DVector};

/// Gains of one transition `k → k+1`.
#[derive(Debug, Clone)]
pub(crate) struct Gain {
    /// L (m × ns).
    pub l: DMatrix<f64>,
    /// R⁻¹ (m × m).
    pub rinv: DMatrix<f64>,
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
    /// Feed-forward terms `l_k` (m × (N−1)).
    pub lff: DMatrix<f64>,
    /// `P_0`.
    pub p0: DMatrix<f64>,
    /// `p_0`.
    pub pv0: DVector<f64>,
    /// False when `max_transient` steps passed without convergence.
    pub converged: bool,
    /// Relative change of `P` at the last transient step.
    pub last_change: f64,
}

/// `y += A x` for a column-major `rows × x.len()` block (axpy form, which
/// vectorises without reassociation).
#[inline]
pub(crate) fn gemv_acc(a: &[f64], rows: usize, x: &[f64], y: &mut [f64]) {
    for (j, &xj) in x.iter().enumerate() {
        let col = &a[j * rows..(j + 1) * rows];
        for (yi, ai) in y.iter_mut().zip(col) {
            *yi += ai * xj;
        }
    }
}

pub(crate) fn symmetrize(p: &mut DMatrix<f64>) {
    let n = p.nrows();
    for i in 0..n {
        for j in 0..i {
            let v = 0.5 * (p[(i, j)] + p[(j, i)]);
            p[(i, j)] = v;
            p[(j, i)] = v;
        }
    }
}

struct Step {
    p: DMatrix<f64>,
    gain: Gain,
    /// R⁻¹ Gᵀ (m × ns).
    kl: DMatrix<f64>,
    /// F − G L.
    phi: DMatrix<f64>,
}

fn riccati_step(lq: &Lq, qmu: &DMatrix<f64>, pn: &DMatrix<f64>) -> Option<Step> {
    let (nx, m) = (lq.nx, lq.m);
    let pg = pn * &lq.g;
    let pf = pn * &lq.f;
    let mut r = lq.g.transpose() * &pg;
    for i in 0..m {
        r[(i, i)] += lq.mu;
    }
    symmetrize(&mut r);
    let mut hus = pg.transpose() * &lq.f;
    for i in 0..m {
        hus[(i, nx + i)] -= lq.mu;
    }
    let chol = r.cholesky()?;
    let l = chol.solve(&hus);
    let kl = chol.solve(&lq.g.transpose());
    let rinv = chol.inverse();
    let mut p = qmu + lq.f.transpose() * pf - hus.transpose() * &l;
    symmetrize(&mut p);
    let phi = &lq.f - &lq.g * &l;
    Some(Step {
        p,
        gain: Gain { l, rinv },
        kl,
        phi,
    })
}

fn rel_change(a: &DMatrix<f64>, b: &DMatrix<f64>) -> f64 {
    let scale = a.amax().max(b.amax());
    if scale == 0.0 {
        return 0.0;
    }
    (a - b).amax() / scale
}

/// `Ĉᵀ ỹ_k` added into `out`.
fn add_data(lq: &Lq, cht: &DMatrix<f64>, k: usize, out: &mut [f64]) {
    gemv_acc(cht.as_slice(), lq.ns, lq.target.column(k).as_slice(), out);
}

/// The backward pass.
pub(crate) fn backward(
    lq: &Lq,
    tol: f64,
    max_transient: usize,
) -> Result<Backward, NotPositiveDefinite> {
    let (ns, m, len) = (lq.ns, lq.m, lq.len);
    let q = lq.stage_weight();
    let mut qmu = q.clone();
    for i in 0..m {
        qmu[(lq.nx + i, lq.nx + i)] += lq.mu;
    }
    let cht = lq.ch.transpose();
    let mut p = q;
    let mut pv = DVector::zeros(ns);
    add_data(lq, &cht, len - 1, pv.as_mut_slice());
    let mut lff = DMatrix::zeros(m, len - 1);
    let mut transient: Vec<Gain> = Vec::new();
    let (mut calm, mut last_change, mut j) = (0usize, f64::INFINITY, len - 1);
    let mut c = DVector::zeros(ns);
    while j > 0 {
        let k = j - 1;
        let st = riccati_step(lq, &qmu, &p).ok_or(NotPositiveDefinite { k })?;
        c.fill(0.0);
        lq.add_c(k, c.as_mut_slice());
        let e = &pv - &p * &c;
        lff.set_column(k, &(&st.kl * &e));
        let mut pnew = st.phi.transpose() * &e;
        add_data(lq, &cht, k, pnew.as_mut_slice());
        lq.project_vector(pnew.as_mut_slice());
        let mut pk = st.p;
        lq.project_matrix(&mut pk);
        last_change = rel_change(&pk, &p);
        p = pk;
        pv = pnew;
        transient.push(st.gain);
        j -= 1;
        calm = if last_change <= tol { calm + 1 } else { 0 };
        if calm >= 3 || transient.len() >= max_transient {
            break;
        }
    }
    let converged = j == 0 || calm >= 3;
    let steady = if j > 0 {
        let st = riccati_step(lq, &qmu, &p).ok_or(NotPositiveDefinite { k: j - 1 })?;
        steady_backward(lq, &st, &p, &cht, j, &mut pv, &mut lff);
        st.gain
    } else {
        transient
            .last()
            .cloned()
            .ok_or(NotPositiveDefinite { k: 0 })?
    };
    transient.reverse();
    let j0 = len - 1 - transient.len();
    Ok(Backward {
        j0,
        transient,
        steady,
        lff,
        p0: p,
        pv0: pv,
        converged,
        last_change,
    })
}

/// Steady-state part of the backward pass for transitions `j−1 … 0`:
/// `[p_k; l_k] = [Φᵀ; K] p' − Z₀ g_k − Z₁ g_{k+1} + [Ĉᵀ ỹ_k; 0]`.
fn steady_backward(
    lq: &Lq,
    st: &Step,
    pss: &DMatrix<f64>,
    cht: &DMatrix<f64>,
    j: usize,
    pv: &mut DVector<f64>,
    lff: &mut DMatrix<f64>,
) {
    let (ns, m) = (lq.ns, lq.m);
    let mut mb = DMatrix::zeros(ns + m, ns);
    mb.view_mut((0, 0), (ns, ns)).copy_from(&st.phi.transpose());
    mb.view_mut((ns, 0), (m, ns)).copy_from(&st.kl);
    let z0 = -(&mb * (pss * &lq.bc0));
    let z1 = -(&mb * (pss * &lq.bc1));
    let n_in = lq.gin.nrows();
    let mut tmp = vec![0.0; ns + m];
    for k in (0..j).rev() {
        tmp.iter_mut().for_each(|v| *v = 0.0);
        gemv_acc(mb.as_slice(), ns + m, pv.as_slice(), &mut tmp);
        if n_in > 0 {
            gemv_acc(z0.as_slice(), ns + m, lq.gin.column(k).as_slice(), &mut tmp);
            gemv_acc(
                z1.as_slice(),
                ns + m,
                lq.gin.column(k + 1).as_slice(),
                &mut tmp,
            );
        }
        add_data(lq, cht, k, &mut tmp[..ns]);
        lq.project_vector(&mut tmp[..ns]);
        pv.as_mut_slice().copy_from_slice(&tmp[..ns]);
        lff.column_mut(k).as_mut_slice().copy_from_slice(&tmp[ns..]);
    }
}

/// Initial state and its covariance: `(s_0, Σ_0, dropped directions)`.
pub(crate) fn initial_state(
    lq: &Lq,
    bw: &Backward,
) -> Result<(DVector<f64>, DMatrix<f64>, usize), NotPositiveDefinite> {
    let (nx, m, ns) = (lq.nx, lq.m, lq.ns);
    let trouble = NotPositiveDefinite { k: lq.len - 1 };
    match &lq.init {
        Init::Fixed(x0) => {
            let pww = bw.p0.view((nx, nx), (m, m)).into_owned();
            let chol = pww.cholesky().ok_or(trouble)?;
            let rhs = bw.pv0.rows(nx, m) - bw.p0.view((nx, 0), (m, nx)) * x0;
            let w0 = chol.solve(&rhs);
            let mut s0 = DVector::zeros(ns);
            s0.rows_mut(0, nx).copy_from(x0);
            s0.rows_mut(nx, m).copy_from(&w0);
            let mut sig = DMatrix::zeros(ns, ns);
            sig.view_mut((nx, nx), (m, m)).copy_from(&chol.inverse());
            Ok((s0, sig, 0))
        }
        Init::Prior { p, mean } => {
            let mut h = bw.p0.clone();
            let mut h_xx = h.view_mut((0, 0), (nx, nx));
            h_xx += p;
            let mut rhs = bw.pv0.clone();
            let mut r_x = rhs.rows_mut(0, nx);
            r_x += p * mean;
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

/// The forward pass: scaled states `s̃_k` (ns × N).
pub(crate) fn forward(lq: &Lq, bw: &Backward, s0: &DVector<f64>) -> DMatrix<f64> {
    let (ns, m, len) = (lq.ns, lq.m, lq.len);
    let mut s = DMatrix::zeros(ns, len);
    s.set_column(0, s0);
    let phi = &lq.f - &lq.g * &bw.steady.l;
    let n_in = lq.gin.nrows();
    let mut next = vec![0.0; ns];
    let mut u = vec![0.0; m];
    for k in 0..len - 1 {
        next.iter_mut().for_each(|v| *v = 0.0);
        let sk = s.column(k);
        let lk = bw.lff.column(k);
        if k < bw.j0 {
            gemv_acc(phi.as_slice(), ns, sk.as_slice(), &mut next);
            gemv_acc(lq.g.as_slice(), ns, lk.as_slice(), &mut next);
        } else {
            let gain = &bw.transient[k - bw.j0];
            u.copy_from_slice(lk.as_slice());
            let lsk = &gain.l * sk;
            u.iter_mut().zip(lsk.iter()).for_each(|(a, b)| *a -= b);
            gemv_acc(lq.f.as_slice(), ns, sk.as_slice(), &mut next);
            gemv_acc(lq.g.as_slice(), ns, &u, &mut next);
        }
        if n_in > 0 {
            lq.add_c(k, &mut next);
        }
        s.column_mut(k + 1).as_mut_slice().copy_from_slice(&next);
    }
    s
}

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

/// Force variances, output variances and their trace.
fn watch(lq: &Lq, chp: &DMatrix<f64>, sig: &DMatrix<f64>) -> (DVector<f64>, f64) {
    let (nx, m, p) = (lq.nx, lq.m, lq.p);
    let cs = chp * sig;
    let mut v = DVector::zeros(m + p);
    let mut tr = 0.0;
    for r in 0..p {
        let d = cs.row(r).dot(&chp.row(r));
        v[m + r] = d;
        tr += d;
    }
    for i in 0..m {
        v[i] = sig[(nx + i, nx + i)];
    }
    (v, tr)
}

fn record(lq: &Lq, sig: &DMatrix<f64>, k: usize, cov: &mut Covariance, tr: f64) {
    let nx = lq.nx;
    let cw = cov.var_w.column_mut(k);
    for (i, v) in cw.into_iter().enumerate() {
        *v = sig[(nx + i, nx + i)];
    }
    let mut cx = cov.var_x.column_mut(k);
    for (i, v) in cx.iter_mut().enumerate() {
        *v = sig[(i, i)];
    }
    for &i in &cov.undetermined {
        cx[i] = f64::NAN;
    }
    cov.tr_h += tr;
}

/// The covariance pass.
pub(crate) fn covariance(lq: &Lq, bw: &Backward, sig0: DMatrix<f64>, tol: f64) -> Covariance {
    let (nx, m, len) = (lq.nx, lq.m, lq.len);
    let mut cov = Covariance {
        var_w: DMatrix::zeros(m, len),
        var_x: DMatrix::zeros(nx, len),
        tr_h: 0.0,
        held_from: None,
        undetermined: vec![],
    };
    let phi_ss = &lq.f - &lq.g * &bw.steady.l;
    let gq_ss = &lq.g * &bw.steady.rinv * lq.g.transpose();
    // Ĉ U = 0 exactly: project so that the growing variance of the hidden
    // states does not leak into the output variances through rounding
    let chp = &lq.ch - &lq.ch * &lq.hidden * lq.hidden.transpose();
    let mut sig = sig0;
    let (mut w_old, tr0) = watch(lq, &chp, &sig);
    record(lq, &sig, 0, &mut cov, tr0);
    let (mut calm, mut k) = (0usize, 0usize);
    while k + 1 < len {
        let new = if k < bw.j0 {
            &phi_ss * &sig * phi_ss.transpose() + &gq_ss
        } else {
            let gn = &bw.transient[k - bw.j0];
            let phi = &lq.f - &lq.g * &gn.l;
            &phi * &sig * phi.transpose() + &lq.g * &gn.rinv * lq.g.transpose()
        };
        let (w_new, tr) = watch(lq, &chp, &new);
        // hold on the force variances: the output variances carry rounding
        // from the growing hidden-state variance (ε Σ_hh, small at the hold)
        let change = w_new
            .iter()
            .zip(w_old.iter())
            .take(m)
            .map(|(a, b)| (a - b).abs() / a.abs().max(b.abs()).max(f64::MIN_POSITIVE))
            .fold(0.0, f64::max);
        calm = if change <= tol { calm + 1 } else { 0 };
        // the covariance converges at the rate of the Riccati recursion
        // (both are governed by Φ): past one Riccati transient it has
        // converged up to the rounding the hidden states leak into it
        let settled = calm >= 3 || (k >= bw.transient.len().max(100) && change <= 1e-4);
        let hold = settled && k + 2 < bw.j0;
        if hold {
            for i in 0..nx {
                let (a, b) = (new[(i, i)], sig[(i, i)]);
                if (a - b).abs() > 1e-9 * a.abs().max(b.abs()) && !cov.undetermined.contains(&i) {
                    cov.undetermined.push(i);
                }
            }
        }
        sig = new;
        w_old = w_new;
        k += 1;
        record(lq, &sig, k, &mut cov, tr);
        if hold {
            // hold the converged covariance across the steady region
            cov.held_from.get_or_insert(k);
            while k + 1 < bw.j0 {
                k += 1;
                record(lq, &sig, k, &mut cov, tr);
            }
            calm = 0;
        }
    }
    cov
}
