//! Dense batch least squares of the full-horizon cost, for small problems:
//! the reference the Riccati sweep is checked against.
//!
//! The unknowns `z = [x_0; w_0; …; w_{N−1}]` (without `x_0` when it is
//! known) enter every state affinely, `x_k = X_k z + ξ_k`, propagated with
//! the physical (unscaled) matrices of the sampled model. The cost is one
//! stacked least-squares problem `‖A z − b‖²`, rows
//! `W^{1/2}(C_y X_k + D_y B_u E_k)`, `√λ E_k`, `√μ (E_{k+1} − E_k)` and
//! `P^{1/2}` on `x_0`; columns are equilibrated and it is solved by
//! Householder QR with two steps of iterative refinement. The posterior covariance is `(AᵀA)^{-1} = R^{-1}R^{-T}`.
//! Memory and time grow as N²: a test tool, limited to 4000 unknowns.

use super::problem::{noise_weights, HorizonData};
use super::settings::{HorizonSettings, InitialState};
use crate::error::{Result, TacitError};
use crate::linear::SampledModel;
use nalgebra::{DMatrix, DVector};

/// The dense solution.
#[derive(Debug, Clone)]
pub struct BatchSolution {
    /// Forces (n_f × N).
    pub force: DMatrix<f64>,
    /// States (2n × N).
    pub states: DMatrix<f64>,
    /// Posterior standard deviation of the forces (n_f × N), model scale
    /// (no variance factor).
    pub force_std: DMatrix<f64>,
    /// Cost J at the solution.
    pub cost: f64,
    /// Trace of the influence matrix `∂ŷ/∂y`: `‖A_y R^{-1}‖²_F` over the
    /// output rows.
    pub tr_h: f64,
}

type InitSplit = (Option<DVector<f64>>, Option<(DVector<f64>, DVector<f64>)>);

fn split_init(init: &InitialState, n: usize) -> InitSplit {
    let nx = 2 * n;
    match init {
        InitialState::Rest => (Some(DVector::zeros(nx)), None),
        InitialState::Known { x0 } => (Some(DVector::from_column_slice(x0)), None),
        InitialState::Estimate {
            mean,
            std_disp,
            std_vel,
        } => {
            let mv = if mean.is_empty() {
                DVector::zeros(nx)
            } else {
                DVector::from_column_slice(mean)
            };
            let sd = DVector::from_fn(nx, |i, _| if i < n { *std_disp } else { *std_vel });
            (None, Some((mv, sd)))
        }
    }
}

/// The stacked least-squares system `(A, b)` and the number of initial-state
/// unknowns (0 or 2n) ahead of the forces.
fn build(
    model: &SampledModel,
    data: &HorizonData<'_>,
    settings: &HorizonSettings,
    lambda: f64,
    mu: f64,
) -> Result<(DMatrix<f64>, DVector<f64>, usize)> {
    let (n, len, m) = (model.n, data.measured.ncols(), data.unknown.ncols());
    let nx = 2 * n;
    let p = data.channels.len();
    let (x0_known, prior) = split_init(&settings.initial, n);
    let nxz = if x0_known.is_some() { 0 } else { nx };
    let nz = nxz + m * len;
    if nz > 4000 || len < 2 {
        return Err(TacitError::Setting(format!(
            "batch least squares: {nz} unknowns and {len} samples; at most 4000 unknowns, at least 2 samples"
        )));
    }
    let ws = noise_weights(data.measured, &settings.noise)?;
    let (cy, dy) = model.outputs(data.channels)?;
    let e = &dy * data.unknown;
    let b0u = &model.b0 * data.unknown;
    let b1u = &model.b1 * data.unknown;
    let rows = p * len + m * len + m * (len - 1) + nxz;
    let mut a = DMatrix::zeros(rows, nz);
    let mut b = DVector::zeros(rows);
    let mut xm = DMatrix::zeros(nx, nz);
    let mut xi = x0_known.clone().unwrap_or_else(|| DVector::zeros(nx));
    if x0_known.is_none() {
        xm.view_mut((0, 0), (nx, nx)).fill_with_identity();
    }
    let wcol = |k: usize| nxz + m * k;
    for k in 0..len {
        if k > 0 {
            let mut xn = &model.a * &xm;
            let mut v = xn.view_mut((0, wcol(k - 1)), (nx, m));
            v += &b0u;
            let mut v = xn.view_mut((0, wcol(k)), (nx, m));
            v += &b1u;
            xi = &model.a * &xi
                + &model.b0 * data.known_force.column(k - 1)
                + &model.b1 * data.known_force.column(k);
            xm = xn;
        }
        let mut blk = &cy * &xm;
        let mut v = blk.view_mut((0, wcol(k)), (p, m));
        v += &e;
        let rhs = data.measured.column(k) - &cy * &xi - &dy * data.known_force.column(k);
        for r in 0..p {
            a.row_mut(p * k + r).copy_from(&(blk.row(r) * ws[r]));
            b[p * k + r] = rhs[r] * ws[r];
        }
    }
    let mut row = p * len;
    let (sl, sm) = (lambda.sqrt(), mu.sqrt());
    for k in 0..len {
        for i in 0..m {
            a[(row, wcol(k) + i)] = sl;
            row += 1;
        }
    }
    for k in 0..len - 1 {
        for i in 0..m {
            a[(row, wcol(k) + i)] = -sm;
            a[(row, wcol(k + 1) + i)] = sm;
            row += 1;
        }
    }
    if let Some((mv, sd)) = &prior {
        for i in 0..nx {
            a[(row, i)] = 1.0 / sd[i];
            b[row] = mv[i] / sd[i];
            row += 1;
        }
    }
    Ok((a, b, nxz))
}

/// Solve the full-horizon problem densely with weights λ, μ (the
/// settings give W and the initial state).
pub fn solve_dense(
    model: &SampledModel,
    data: &HorizonData<'_>,
    settings: &HorizonSettings,
    lambda: f64,
    mu: f64,
) -> Result<BatchSolution> {
    let (n, len, m) = (model.n, data.measured.ncols(), data.unknown.ncols());
    let nx = 2 * n;
    let (x0_known, _) = split_init(&settings.initial, n);
    let (mut a, b, nxz) = build(model, data, settings, lambda, mu)?;
    let nz = a.ncols();
    let wcol = |k: usize| nxz + m * k;
    // equilibrate columns, QR
    let cs = DVector::from_fn(nz, |j, _| {
        let c = a.column(j).norm();
        if c > 0.0 {
            1.0 / c
        } else {
            1.0
        }
    });
    for j in 0..nz {
        a.column_mut(j).scale_mut(cs[j]);
    }
    let a_scaled = a.clone();
    let qr = a.qr();
    let r = qr.r();
    let qtb = qr.q().transpose() * &b;
    let singular = || TacitError::Numerical("batch least squares: R is singular".into());
    let mut zs = r.solve_upper_triangular(&qtb).ok_or_else(singular)?;
    // two steps of iterative refinement (corrected semi-normal equations)
    let rt = r.transpose();
    for _ in 0..2 {
        let grad = a_scaled.transpose() * (&b - &a_scaled * &zs);
        let y = rt.solve_lower_triangular(&grad).ok_or_else(singular)?;
        zs += r.solve_upper_triangular(&y).ok_or_else(singular)?;
    }
    let cost = (&a_scaled * &zs - &b).norm_squared();
    let z = zs.component_mul(&cs);
    let rinv = r
        .solve_upper_triangular(&DMatrix::identity(nz, nz))
        .ok_or_else(singular)?;
    let force = DMatrix::from_fn(m, len, |i, k| z[wcol(k) + i]);
    let fd = data.unknown * &force + data.known_force;
    let mut states = DMatrix::zeros(nx, len);
    let mut x = match &x0_known {
        Some(x0) => x0.clone(),
        None => z.rows(0, nx).into_owned(),
    };
    for k in 0..len {
        if k > 0 {
            x = model.step(
                &x,
                &fd.column(k - 1).into_owned(),
                &fd.column(k).into_owned(),
            );
        }
        states.set_column(k, &x);
    }
    let force_std = DMatrix::from_fn(m, len, |i, k| {
        let j = wcol(k) + i;
        rinv.row(j).norm() * cs[j]
    });
    let p = data.channels.len();
    let tr_h = (a_scaled.rows(0, p * len) * &rinv).norm_squared();
    Ok(BatchSolution {
        force,
        states,
        force_std,
        cost,
        tr_h,
    })
}

/// Relative gradient `‖Aᵀ(A z − b)‖ / ‖Aᵀ b‖` of the cost at a candidate
/// answer (`x0` ignored when the initial state is not estimated): an
/// optimality check independent of how the answer was computed.
pub fn relative_gradient(
    model: &SampledModel,
    data: &HorizonData<'_>,
    settings: &HorizonSettings,
    lambda: f64,
    mu: f64,
    x0: &DVector<f64>,
    force: &DMatrix<f64>,
) -> Result<f64> {
    let (a, b, nxz) = build(model, data, settings, lambda, mu)?;
    let m = data.unknown.ncols();
    let mut z = DVector::zeros(a.ncols());
    for i in 0..nxz {
        z[i] = x0[i];
    }
    for k in 0..force.ncols() {
        for i in 0..m {
            z[nxz + m * k + i] = force[(i, k)];
        }
    }
    // column scaling keeps the norms meaningful across units
    let mut a = a;
    let mut zs = z;
    for j in 0..a.ncols() {
        let c = a.column(j).norm();
        if c > 0.0 {
            a.column_mut(j).scale_mut(1.0 / c);
            zs[j] *= c;
        }
    }
    let g = a.transpose() * (&a * &zs - &b);
    Ok(g.norm() / (a.transpose() * &b).norm())
}
