//! The window problem as a quadratic program (Clarabel), with the user's
//! [`Constraints`] on every per-sample force vector of the window:
//!
//! $$ \min_{\tilde θ} \tfrac12 \tilde θ^T (Ā_s^T Ā_s) \tilde θ − (Ā_s^T B̄ d)^T \tilde θ
//!    \quad \text{s.t.}\quad A \tilde θ + s = b,\; s ∈ \{0\}^{m_e} × R_+^{m_i} $$
//!
//! with `θ = D θ̃` (the column scaling of the window operator). `P` and `A`
//! are fixed per window operator, so one solver is set up per operator and
//! only `q` changes from window to window (`update_q`; presolve off). With
//! no constraint the QP and the least-squares gain give the same answer.

use super::run::WindowSolver;
use super::settings::Constraints;
use super::window::WindowOperator;
use clarabel::algebra::CscMatrix;
use clarabel::solver::{
    DefaultSettings, DefaultSolver, IPSolver, NonnegativeConeT, SolverStatus, SupportedConeT,
    ZeroConeT,
};
use nalgebra::{DMatrix, DVector};

/// Clarabel-backed window solver.
pub struct QpSolver {
    constraints: Constraints,
    n: usize,
    slots: Vec<Option<Slot>>,
    /// Windows solved to reduced accuracy (`AlmostSolved`).
    pub almost_solved: usize,
}

struct Slot {
    solver: DefaultSolver<f64>,
    /// `Ā_sᵀ B̄` (nθ × nd).
    qmat: DMatrix<f64>,
}

impl std::fmt::Debug for QpSolver {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("QpSolver")
            .field("constraints", &self.constraints)
            .field("almost_solved", &self.almost_solved)
            .finish()
    }
}

/// Constraint rows as `(column, coefficient)` lists.
type Rows = Vec<Vec<(usize, f64)>>;

impl QpSolver {
    /// A solver for `ops` operators, forces of `n` components.
    pub fn new(constraints: Constraints, n: usize, ops: usize) -> QpSolver {
        QpSolver {
            constraints,
            n,
            slots: (0..ops).map(|_| None).collect(),
            almost_solved: 0,
        }
    }

    fn setup(&self, op: &WindowOperator) -> Result<Slot, String> {
        let nt = op.param.ntheta;
        let p = op.abar_scaled.transpose() * &op.abar_scaled;
        let (mut pi, mut pj, mut pv) = (vec![], vec![], vec![]);
        for j in 0..nt {
            for i in 0..=j {
                pi.push(i);
                pj.push(j);
                pv.push(p[(i, j)]);
            }
        }
        let pm = CscMatrix::new_from_triplets(nt, nt, pi, pj, pv);
        let (rows_eq, rows_in, mut b, b_in) = self.constraint_rows(op);
        let (m_eq, m_in) = (rows_eq.len(), rows_in.len());
        let (mut ai, mut aj, mut av) = (vec![], vec![], vec![]);
        for (r, row) in rows_eq.iter().chain(&rows_in).enumerate() {
            for &(col, v) in row {
                ai.push(r);
                aj.push(col);
                av.push(v * op.dcol[col]);
            }
        }
        let am = CscMatrix::new_from_triplets(m_eq + m_in, nt, ai, aj, av);
        b.extend(b_in);
        let mut cones: Vec<SupportedConeT<f64>> = Vec::new();
        if m_eq > 0 {
            cones.push(ZeroConeT(m_eq));
        }
        if m_in > 0 {
            cones.push(NonnegativeConeT(m_in));
        }
        let settings = DefaultSettings {
            verbose: false,
            presolve_enable: false,
            input_sparse_dropzeros: false,
            tol_gap_abs: 1e-12,
            tol_gap_rel: 1e-12,
            tol_feas: 1e-11,
            tol_ktratio: 1e-10,
            max_iter: 200,
            ..DefaultSettings::default()
        };
        let q = vec![0.0; nt];
        let solver = DefaultSolver::new(&pm, &q, &am, &b, &cones, settings)
            .map_err(|e| format!("QP setup: {e}"))?;
        Ok(Slot {
            solver,
            qmat: op.abar_scaled.transpose() * &op.bbar,
        })
    }

    /// Constraint rows on θ (unscaled), equalities then inequalities
    /// (`row · θ ≤ b`), with their right-hand sides.
    fn constraint_rows(&self, op: &WindowOperator) -> (Rows, Rows, Vec<f64>, Vec<f64>) {
        let c = &self.constraints;
        let n = self.n;
        let (mut eq, mut ineq, mut beq, mut bin) = (vec![], vec![], vec![], vec![]);
        for &o in &op.param.force_blocks {
            if let Some(active) = &c.active {
                for i in 0..n {
                    if !active.contains(&(i + 1)) {
                        eq.push(vec![(o + i, 1.0)]);
                        beq.push(0.0);
                    }
                }
            }
            if c.equilibrium {
                eq.push((0..n).map(|i| (o + i, 1.0)).collect());
                beq.push(0.0);
            }
            for &(i, j) in &c.pairs {
                eq.push(vec![(o + i - 1, 1.0), (o + j - 1, 1.0)]);
                beq.push(0.0);
                if c.push_apart {
                    ineq.push(vec![(o + i - 1, -1.0)]);
                    bin.push(0.0);
                }
            }
            for &(d, v) in &c.upper {
                if v.is_finite() {
                    ineq.push(vec![(o + d - 1, 1.0)]);
                    bin.push(v);
                }
            }
            for &(d, v) in &c.lower {
                if v.is_finite() {
                    ineq.push(vec![(o + d - 1, -1.0)]);
                    bin.push(-v);
                }
            }
        }
        (eq, ineq, beq, bin)
    }
}

impl WindowSolver for QpSolver {
    fn solve(
        &mut self,
        op_index: usize,
        op: &WindowOperator,
        d: &DVector<f64>,
        r: &mut DVector<f64>,
    ) -> Result<u32, String> {
        if self.slots[op_index].is_none() {
            let slot = self.setup(op)?;
            self.slots[op_index] = Some(slot);
        }
        let slot = self.slots[op_index].as_mut().expect("slot set above");
        let q: Vec<f64> = (-(&slot.qmat * d)).iter().copied().collect();
        slot.solver
            .update_q(&q)
            .map_err(|e| format!("QP update: {e:?}"))?;
        slot.solver.solve();
        let sol = &slot.solver.solution;
        match sol.status {
            SolverStatus::Solved => {}
            SolverStatus::AlmostSolved => self.almost_solved += 1,
            other => return Err(format!("QP not solved: {other:?}")),
        }
        let theta = DVector::from_fn(op.param.ntheta, |i, _| sol.x[i] * op.dcol[i]);
        let c = d.rows(op.nfit, op.param.nc);
        r.gemv(1.0, &op.r_theta, &theta, 0.0);
        r.gemv(1.0, &op.r_c, &c, 1.0);
        Ok(sol.iterations)
    }
}
