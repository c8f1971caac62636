//! The constrained full-horizon problem as one sparse, banded QP solved by
//! Clarabel (interior point, sparse LDLᵀ).
//!
//! Variables: the scaled `s̃_k = [x̃_k; w̃_k]` of every sample, stacked by
//! sample, so every matrix is block-banded. With `Ĉ`, `F`, `G`, `c_k` of
//! [`super::problem`] the problem is
//!
//! $$ \min \tfrac12 zᵀ P z + qᵀ z,\quad
//!    P = 2\,\mathrm{blkdiag}(ĈᵀĈ + λ JᵀJ) + 2 μ\,(\text{first differences of } w)
//!    + 2\,\mathrm{blkdiag}_0(P_{x_0}),\quad q_k = −2 Ĉᵀ ỹ_k $$
//!
//! subject to the dynamics `x_{k+1} − [A, B_0B_u] s_k − B_1B_u w_{k+1} = c_k`
//! (equalities), `x_0` fixed when known, and the user's constraints:
//! equilibrium `1ᵀ B_u w_k = 0` and pairs `(B_u w_k)_i + (B_u w_k)_j = 0`
//! (equalities), bounds `lo ≤ w_{k,i} ≤ hi` (inequalities). Without active
//! constraints the answer equals the Riccati sweep's to the solver
//! tolerance. The reported standard deviations are those of the
//! unconstrained problem.

use super::problem::{Init, Lq};
use super::{smoother, HorizonData, HorizonResult, HorizonSettings, HorizonStatus};
use super::{SelectedWeights, Solver, Timings, WeightSelection};
use crate::error::{Result, TacitError};
use crate::linear::SampledModel;
use clarabel::algebra::CscMatrix;
use clarabel::solver::{DefaultSettings, DefaultSolver, IPSolver, SolverStatus, SupportedConeT};
use nalgebra::DMatrix;
use std::time::Instant;

/// Triplet lists.
#[derive(Default)]
struct Triplets {
    i: Vec<usize>,
    j: Vec<usize>,
    v: Vec<f64>,
}

impl Triplets {
    fn push(&mut self, i: usize, j: usize, v: f64) {
        if v != 0.0 {
            self.i.push(i);
            self.j.push(j);
            self.v.push(v);
        }
    }
    fn csc(self, m: usize, n: usize) -> CscMatrix<f64> {
        CscMatrix::new_from_triplets(m, n, self.i, self.j, self.v)
    }
}

fn objective(lq: &Lq) -> (Triplets, Vec<f64>) {
    let (ns, nx, m, len) = (lq.ns, lq.nx, lq.m, lq.len);
    let q = lq.stage_weight();
    let mut t = Triplets::default();
    let mut lin = vec![0.0; ns * len];
    let chty = lq.ch.transpose() * &lq.target;
    for k in 0..len {
        let o = k * ns;
        for c in 0..ns {
            for r in 0..=c {
                let mut v = 2.0 * q[(r, c)];
                if r == c && r >= nx {
                    let ends = if len == 1 {
                        0.0
                    } else if k == 0 || k == len - 1 {
                        1.0
                    } else {
                        2.0
                    };
                    v += 2.0 * lq.mu * ends;
                }
                t.push(o + r, o + c, v);
            }
            lin[o + c] = -2.0 * chty[(c, k)];
        }
        if k + 1 < len {
            for i in 0..m {
                t.push(o + nx + i, o + ns + nx + i, -2.0 * lq.mu);
            }
        }
    }
    if let Init::Prior { p, mean } = &lq.init {
        for c in 0..nx {
            for r in 0..=c {
                t.push(r, c, 2.0 * p[(r, c)]);
            }
        }
        let pm = p * mean;
        for r in 0..nx {
            lin[r] -= 2.0 * pm[r];
        }
    }
    (t, lin)
}

/// Equality rows (dynamics, fixed x0, equilibrium, pairs) then inequality
/// rows (bounds). Returns (A, b, number of equalities).
fn constraints(
    lq: &Lq,
    bu: &DMatrix<f64>,
    settings: &HorizonSettings,
) -> Result<(Triplets, Vec<f64>, usize, usize)> {
    let (ns, nx, m, len) = (lq.ns, lq.nx, lq.m, lq.len);
    let n = nx / 2;
    let cons = &settings.constraints;
    let mut t = Triplets::default();
    let mut b = Vec::new();
    let mut row = 0;
    let mut c = vec![0.0; ns];
    for k in 0..len - 1 {
        c.iter_mut().for_each(|v| *v = 0.0);
        lq.add_c(k, &mut c);
        for (r, &cr) in c.iter().enumerate().take(nx) {
            t.push(row + r, (k + 1) * ns + r, 1.0);
            for j in 0..ns {
                t.push(row + r, k * ns + j, -lq.f[(r, j)]);
            }
            for j in 0..m {
                t.push(row + r, (k + 1) * ns + nx + j, -lq.g[(r, j)]);
            }
            b.push(cr);
        }
        row += nx;
    }
    if let Init::Fixed(x0) = &lq.init {
        for r in 0..nx {
            t.push(row + r, r, 1.0);
            b.push(x0[r]);
        }
        row += nx;
    }
    let mut lin_rows: Vec<Vec<f64>> = Vec::new();
    if cons.equilibrium {
        lin_rows.push((0..m).map(|j| bu.column(j).sum()).collect());
    }
    for &(i, j) in &cons.pairs {
        if i >= n || j >= n {
            return Err(TacitError::Setting(format!(
                "horizon: pair ({}, {}) names a DOF outside the model (1..={n})",
                i + 1,
                j + 1
            )));
        }
        lin_rows.push((0..m).map(|c| bu[(i, c)] + bu[(j, c)]).collect());
    }
    for coeffs in &lin_rows {
        for k in 0..len {
            for (j, a) in coeffs.iter().enumerate() {
                t.push(row, k * ns + nx + j, *a);
            }
            b.push(0.0);
            row += 1;
        }
    }
    let neq = row;
    let dw = lq.d[nx];
    for &(i, lo, hi) in &cons.bounds {
        if i >= m {
            return Err(TacitError::Setting(format!(
                "horizon: bound on component {i}, but there are {m} unknown force components"
            )));
        }
        for k in 0..len {
            if hi.is_finite() {
                t.push(row, k * ns + nx + i, 1.0);
                b.push(hi / dw);
                row += 1;
            }
            if lo.is_finite() {
                t.push(row, k * ns + nx + i, -1.0);
                b.push(-lo / dw);
                row += 1;
            }
        }
    }
    Ok((t, b, neq, row - neq))
}

/// Solve with constraints (see the module docs).
pub fn solve_constrained(
    model: &SampledModel,
    data: &HorizonData<'_>,
    settings: &HorizonSettings,
    lambda: f64,
    mu: f64,
) -> Result<HorizonResult> {
    let t0 = Instant::now();
    let lq = Lq::new(model, data, settings, lambda, mu)?;
    let (pt, q) = objective(&lq);
    let (at, b, neq, nineq) = constraints(&lq, data.unknown, settings)?;
    let nv = lq.ns * lq.len;
    let p = pt.csc(nv, nv);
    let a = at.csc(neq + nineq, nv);
    let mut cones = vec![SupportedConeT::ZeroConeT(neq)];
    if nineq > 0 {
        cones.push(SupportedConeT::NonnegativeConeT(nineq));
    }
    let opts = DefaultSettings {
        verbose: false,
        tol_gap_abs: 1e-10,
        tol_gap_rel: 1e-10,
        tol_feas: 1e-10,
        ..DefaultSettings::default()
    };
    let t_setup = t0.elapsed().as_secs_f64();
    let t1 = Instant::now();
    let mut solver = DefaultSolver::new(&p, &q, &a, &b, &cones, opts)
        .map_err(|e| TacitError::Numerical(format!("horizon QP: Clarabel setup failed: {e:?}")))?;
    solver.solve();
    let t_qp = t1.elapsed().as_secs_f64();
    let sol = &solver.solution;
    let s = DMatrix::from_column_slice(lq.ns, lq.len, &sol.x);
    let weights = SelectedWeights {
        lambda,
        mu,
        selection: WeightSelection::Fixed,
        criterion: f64::NAN,
        candidates: vec![],
    };
    // the unconstrained covariance, for the reported std
    let cov = if settings.covariance {
        let sys = super::basis::Sys::new(&lq);
        smoother::backward(&lq, &sys, settings).ok().and_then(|bw| {
            let (_, sig0, _) = smoother::initial_state(&lq, &sys, &bw).ok()?;
            let tol = settings.riccati_tol.max(super::COVARIANCE_TOL);
            Some(super::covariance::covariance(&lq, &sys, &bw, sig0, tol))
        })
    } else {
        None
    };
    let has_cov = cov.is_some();
    let mut sink = super::assemble::Sink::new(&lq, data, None, DMatrix::zeros(lq.m, lq.len));
    sink.push_all(&s);
    let mut res = sink.finish(settings, cov, weights);
    res.diagnostics.solver = Solver::Qp;
    res.diagnostics.qp_iterations = sol.iterations;
    if sol.status != SolverStatus::Solved {
        res.status = HorizonStatus::QpNotSolved {
            solver_status: format!("{:?}", sol.status),
        };
        res.notes.push(format!(
            "Clarabel ended with {:?} after {} iterations (primal residual {:.2e}, dual {:.2e})",
            sol.status, sol.iterations, sol.r_prim, sol.r_dual
        ));
    }
    if has_cov {
        res.notes.push(
            "force_std is that of the unconstrained problem (constraints can only reduce it)"
                .into(),
        );
    }
    res.timings = Timings {
        setup: t_setup,
        qp: t_qp,
        total: t0.elapsed().as_secs_f64(),
        ..Default::default()
    };
    Ok(res)
}
