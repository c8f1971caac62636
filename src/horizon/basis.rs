//! The sweep's coordinates: the hidden directions split off exactly.
//!
//! A free-free model measured by accelerometers has states the data cannot
//! see (rigid-body position and velocity, [`Lq::hidden`] = `U`). They form
//! an invariant subspace of the dynamics (`A U = U T`, T a Jordan block)
//! that the outputs do not see (`Ĉ U = 0`), so their cost-to-go is exactly
//! zero and their posterior variance grows without bound. Worked in the
//! original coordinates, rounding couples them back: `L U` and `Vᵀ Φ U`
//! are not exactly zero, and the rigid-body drift of the states and its
//! growing variance (10⁴–10¹⁵ times the rest over long records) leak into
//! the forces and their variances.
//!
//! The sweep therefore works in `z = Wᵀ s`, `W = diag(W_x, I)`,
//! `W_x = [U_x, V_x]` orthogonal: `z = [z_U; z_V; w]`. There the coupling
//! blocks `F̄[V w, U]` and `Ĉ̄[:, U]` are zero in exact arithmetic and are
//! set to exact zeros, so
//!
//! - the **reduced system** on `[z_V; w]` (the trailing `ns − q`
//!   coordinates, [`Reduced`]) is closed: the Riccati recursion runs on it
//!   alone, with no projection and nothing to leak;
//! - the full closed loop `Φ̄ = F̄ − Ḡ [0, L]` keeps exact zeros in its
//!   `[V w, U]` block, so the smoothed covariance of `[z_V; w]` evolves
//!   autonomously in floating point as it does in exact arithmetic, and
//!   the forces do not see the drift of `z_U`.
//!
//! Without hidden directions `W = I` and the reduced system is the whole.

use super::problem::Lq;
use crate::riccati::Stage;
use nalgebra::DMatrix;

/// The closed (observable) part of the problem, `[z_V; w]`: the same form
/// as [`Lq`] with `nx − q` states.
#[derive(Debug, Clone)]
pub(crate) struct Reduced {
    /// States `nx − q`.
    pub nx: usize,
    /// Unknown force components.
    pub m: usize,
    /// `nx − q + m`.
    pub ns: usize,
    /// Scaled μ.
    pub mu: f64,
    /// Scaled λ.
    pub lambda: f64,
    /// F (ns × ns); its last m rows are zero.
    pub f: DMatrix<f64>,
    /// G (ns × m).
    pub g: DMatrix<f64>,
    /// Ĉ (p × ns).
    pub ch: DMatrix<f64>,
    /// `[B_0 S_in; 0]` (ns × n_in).
    pub bc0: DMatrix<f64>,
    /// `[B_1 S_in; 0]` (ns × n_in).
    pub bc1: DMatrix<f64>,
}

impl Reduced {
    /// `ĈᵀĈ + λ JᵀJ`.
    pub fn stage_weight(&self) -> DMatrix<f64> {
        let mut q = self.ch.transpose() * &self.ch;
        for i in 0..self.m {
            q[(self.nx + i, self.nx + i)] += self.lambda;
        }
        q
    }

    /// The Riccati stage ([`crate::riccati::Stage`]): `A = F` (its first
    /// nx rows; the last m are zero), `B = G` (the identity in its last m
    /// rows: the state holds the previous force), `Q = ĈᵀĈ + (λ + μ)JᵀJ`,
    /// `S = −μJ`, `R = μI`.
    pub fn stage(&self) -> Stage {
        let (nx, m, ns) = (self.nx, self.m, self.ns);
        debug_assert!(self.f.rows(nx, m).iter().all(|v| *v == 0.0));
        let mut q = self.stage_weight();
        let mut s = DMatrix::zeros(m, ns);
        for i in 0..m {
            q[(nx + i, nx + i)] += self.mu;
            s[(i, nx + i)] = -self.mu;
        }
        let r = DMatrix::identity(m, m) * self.mu;
        Stage::new(&self.f.rows(0, nx).into_owned(), &self.g, q, s, r)
    }

    /// `c_k` (ns) added into `out`.
    pub fn add_c(&self, gin: &DMatrix<f64>, k: usize, out: &mut [f64]) {
        for j in 0..gin.nrows() {
            let (g0, g1) = (gin[(j, k)], gin[(j, k + 1)]);
            let (c0, c1) = (self.bc0.column(j), self.bc1.column(j));
            for r in 0..self.nx {
                out[r] += c0[r] * g0 + c1[r] * g1;
            }
        }
    }
}

/// The problem in the coordinates `z = Wᵀ s` (see the module docs).
#[derive(Debug, Clone)]
pub(crate) struct Sys {
    /// Number of hidden directions q.
    pub q: usize,
    /// `W_x = [U_x, V_x]` (nx × nx, orthogonal): `s_x = W_x z_x`.
    pub wx: DMatrix<f64>,
    /// F̄ (ns × ns).
    pub f: DMatrix<f64>,
    /// Ḡ (ns × m).
    pub g: DMatrix<f64>,
    /// `B̄_c0` (ns × n_in).
    pub bc0: DMatrix<f64>,
    /// `B̄_c1` (ns × n_in).
    pub bc1: DMatrix<f64>,
    /// The closed part, coordinates `q..ns`.
    pub r: Reduced,
    /// Largest coupling set to zero, relative to ‖F‖ (diagnostic; rounding
    /// level when the hidden directions are exact).
    pub dropped_coupling: f64,
}

impl Sys {
    /// Rotate the problem `lq`.
    pub fn new(lq: &Lq) -> Sys {
        let (nx, m, ns, q) = (lq.nx, lq.m, lq.ns, lq.hidden.ncols());
        let wx = rotation(&lq.hidden.rows(0, nx).into_owned());
        let wxt = wx.transpose();
        let mut f = DMatrix::zeros(ns, ns);
        f.view_mut((0, 0), (nx, nx))
            .copy_from(&(&wxt * lq.f.view((0, 0), (nx, nx)) * &wx));
        f.view_mut((0, nx), (nx, m))
            .copy_from(&(&wxt * lq.f.view((0, nx), (nx, m))));
        let mut g = lq.g.clone();
        g.view_mut((0, 0), (nx, m))
            .copy_from(&(&wxt * lq.g.view((0, 0), (nx, m))));
        let mut ch = lq.ch.clone();
        ch.view_mut((0, 0), (lq.p, nx))
            .copy_from(&(lq.ch.view((0, 0), (lq.p, nx)) * &wx));
        let rot_in = |b: &DMatrix<f64>| {
            let mut out = b.clone();
            out.view_mut((0, 0), (nx, b.ncols()))
                .copy_from(&(&wxt * b.view((0, 0), (nx, b.ncols()))));
            out
        };
        let (bc0, bc1) = (rot_in(&lq.bc0), rot_in(&lq.bc1));
        // exact zeros where exact arithmetic has them
        let fmax = f.amax().max(f64::MIN_POSITIVE);
        let mut dropped = 0.0f64;
        for j in 0..q {
            for i in q..ns {
                dropped = dropped.max(f[(i, j)].abs() / fmax);
                f[(i, j)] = 0.0;
            }
            ch.column_mut(j).fill(0.0);
        }
        let nr = ns - q;
        let r = Reduced {
            nx: nx - q,
            m,
            ns: nr,
            mu: lq.mu,
            lambda: lq.lambda,
            f: f.view((q, q), (nr, nr)).into_owned(),
            g: g.rows(q, nr).into_owned(),
            ch: ch.columns(q, nr).into_owned(),
            bc0: bc0.rows(q, nr).into_owned(),
            bc1: bc1.rows(q, nr).into_owned(),
        };
        Sys {
            q,
            wx,
            f,
            g,
            bc0,
            bc1,
            r,
            dropped_coupling: dropped,
        }
    }
}

/// `[U, V]` with `V` an orthonormal basis of the complement of the
/// orthonormal columns `U` (n × q).
fn rotation(u: &DMatrix<f64>) -> DMatrix<f64> {
    let (n, q) = u.shape();
    if q == 0 {
        return DMatrix::identity(n, n);
    }
    let proj = DMatrix::identity(n, n) - u * u.transpose();
    let eig = proj.symmetric_eigen();
    let mut w = DMatrix::zeros(n, n);
    w.columns_mut(0, q).copy_from(u);
    let mut j = q;
    for (i, ev) in eig.eigenvalues.iter().enumerate() {
        if *ev > 0.5 && j < n {
            w.set_column(j, &eig.eigenvectors.column(i));
            j += 1;
        }
    }
    w
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rotation_is_orthogonal_and_keeps_u_first() {
        let mut u = DMatrix::zeros(6, 2);
        for i in 0..3 {
            u[(i, 0)] = 1.0 / 3f64.sqrt();
            u[(3 + i, 1)] = 1.0 / 3f64.sqrt();
        }
        let w = rotation(&u);
        let err = (w.transpose() * &w - DMatrix::identity(6, 6)).amax();
        assert!(err < 1e-14, "{err}");
        assert!((w.columns(0, 2) - &u).amax() == 0.0);
    }
}
