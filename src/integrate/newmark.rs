//! Newmark / HHT-α integrator with Newton iterations.
//!
//! With `h` the sub-step, HHT parameter `α ∈ [−1/3, 0]` (α = 0 is the
//! average-acceleration rule), `γ = 1/2 − α`, `β = (1 − α)²/4`, the step
//! solves for `u_{n+1}`
//!
//! $$ M a_{n+1} + (1+α)\,g(u_{n+1}, v_{n+1}) − α\,g(u_n, v_n) = f(t_n + (1+α) h) $$
//!
//! with `g = C v + K u + f_int(u, v)` and the Newmark relations
//! `a_{n+1} = a_0 (u_{n+1} − u_n) − a_2 v_n − a_3 a_n`,
//! `v_{n+1} = v_n + h((1−γ) a_n + γ a_{n+1})`, `a_0 = 1/(βh²)`,
//! `a_2 = 1/(βh)`, `a_3 = 1/(2β) − 1`. Both are affine in `u_{n+1}`, so the
//! residual is `r(u) = J_0 u − b_n + (1+α) f_int(u, a_1 u + w_n)` with the
//! constant matrix `J_0 = a_0 M + (1+α)(a_1 C + K)`, `a_1 = γ/(βh)`.
//! Newton's matrix adds the element tangents; a backtracking line search
//! guards the non-smooth contact law.

use crate::error::{Result, TacitError};
use crate::model::elements::{self, Element};
use crate::model::Model;
use nalgebra::{DMatrix, DMatrixView};
use serde::Serialize;

/// Integrator settings.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct SimSettings {
    /// Sub-steps per sample (>= 1; default 10).
    pub substeps: usize,
    /// HHT α in [−1/3, 0]; 0 = Newmark average acceleration (default).
    pub hht_alpha: f64,
    /// Newton tolerance on the residual, relative to the step's force
    /// scale (default 1e-10).
    pub newton_tol: f64,
    /// Newton iteration limit per sub-step (default 50).
    pub max_newton: usize,
}

impl Default for SimSettings {
    fn default() -> Self {
        SimSettings {
            substeps: 10,
            hht_alpha: 0.0,
            newton_tol: 1e-10,
            max_newton: 50,
        }
    }
}

impl SimSettings {
    /// Check the settings; the error repeats the rule.
    pub fn validate(&self) -> Result<()> {
        if self.substeps < 1 {
            return Err(TacitError::Setting("substeps must be >= 1".into()));
        }
        if !(-1.0 / 3.0 - 1e-12..=0.0).contains(&self.hht_alpha) {
            return Err(TacitError::Setting(format!(
                "HHT alpha = {} must be in [-1/3, 0]",
                self.hht_alpha
            )));
        }
        if !(self.newton_tol > 0.0) || self.max_newton < 1 {
            return Err(TacitError::Setting(
                "newton_tol must be > 0 and max_newton >= 1".into(),
            ));
        }
        Ok(())
    }
}

/// How a simulation ended.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "status", rename_all = "snake_case")]
pub enum SimStatus {
    /// Every sample computed.
    Completed,
    /// Newton did not converge; the outputs stop at `sample`.
    NewtonFailed {
        /// Time at which the failing sub-step ends, s.
        time: f64,
        /// Last sample completed.
        sample: usize,
        /// Iterations spent.
        iterations: usize,
        /// Residual norm reached (N).
        residual: f64,
    },
    /// The state became non-finite.
    NonFinite {
        /// Time, s.
        time: f64,
        /// Last sample completed.
        sample: usize,
    },
}

/// A simulation: states at every sample (DOF × sample matrices; column 0 is
/// the initial state) and counters.
#[derive(Debug, Clone)]
pub struct Simulation {
    /// How it ended.
    pub status: SimStatus,
    /// Displacement.
    pub u: DMatrix<f64>,
    /// Velocity.
    pub v: DMatrix<f64>,
    /// Acceleration.
    pub a: DMatrix<f64>,
    /// Internal force of the nonlinear elements.
    pub fint: DMatrix<f64>,
    /// Sub-steps taken.
    pub steps: usize,
    /// Newton iterations (matrix solves) in total.
    pub newton_iterations: usize,
}

impl Simulation {
    /// True when every sample was computed.
    pub fn completed(&self) -> bool {
        self.status == SimStatus::Completed
    }
    /// Number of samples computed.
    pub fn len(&self) -> usize {
        self.u.ncols()
    }
    /// True when no sample was computed.
    pub fn is_empty(&self) -> bool {
        self.u.ncols() == 0
    }
}

/// A compiled integrator for one model (or reduced matrices) at one rate.
#[derive(Debug, Clone)]
pub struct Integrator {
    n: usize,
    m: DMatrix<f64>,
    c: DMatrix<f64>,
    k: DMatrix<f64>,
    elements: Vec<Element>,
    settings: SimSettings,
    /// Sub-step, s.
    h: f64,
    alpha: f64,
    gamma: f64,
    beta: f64,
    /// J0 = a0 M + (1+α)(a1 C + K), column-major.
    j0: DMatrix<f64>,
    /// Cholesky factor of J0 (lower, column-major), None if not SPD.
    j0_chol: Option<Vec<f64>>,
}

impl Integrator {
    /// Build for a model sampled at `fs` Hz.
    pub fn new(model: &Model, fs: f64, settings: SimSettings) -> Result<Integrator> {
        let m = model.mass_matrix();
        let k = model.stiffness_matrix();
        let c = model.damping_matrix()?;
        Integrator::from_matrices(m, c, k, elements::compile(model), fs, settings)
    }

    /// Build from matrices (e.g. a reduced model) and compiled elements.
    pub fn from_matrices(
        m: DMatrix<f64>,
        c: DMatrix<f64>,
        k: DMatrix<f64>,
        elements: Vec<Element>,
        fs: f64,
        settings: SimSettings,
    ) -> Result<Integrator> {
        settings.validate()?;
        if !(fs.is_finite() && fs > 0.0) {
            return Err(TacitError::Setting(format!("sample rate {fs} must be > 0")));
        }
        let n = m.nrows();
        let h = 1.0 / (fs * settings.substeps as f64);
        let alpha = settings.hht_alpha;
        let gamma = 0.5 - alpha;
        let beta = 0.25 * (1.0 - alpha) * (1.0 - alpha);
        let a0 = 1.0 / (beta * h * h);
        let a1 = gamma / (beta * h);
        let j0 = &m * a0 + (&c * a1 + &k) * (1.0 + alpha);
        let mut buf = j0.as_slice().to_vec();
        let j0_chol = if cholesky_in_place(&mut buf, n) {
            Some(buf)
        } else {
            None
        };
        Ok(Integrator {
            n,
            m,
            c,
            k,
            elements,
            settings,
            h,
            alpha,
            gamma,
            beta,
            j0,
            j0_chol,
        })
    }

    /// Number of DOFs.
    pub fn ndof(&self) -> usize {
        self.n
    }

    /// Sub-step, s.
    pub fn substep(&self) -> f64 {
        self.h
    }

    /// Settings.
    pub fn settings(&self) -> &SimSettings {
        &self.settings
    }

    /// Simulate under `force` (DOF × sample, external force at the samples)
    /// from `u0`, `v0`. The first column of the output is the initial state;
    /// the output has as many samples as `force` has columns.
    pub fn run(&self, force: DMatrixView<'_, f64>, u0: &[f64], v0: &[f64]) -> Simulation {
        let n = self.n;
        let ns = force.ncols();
        let s = self.settings.substeps;
        let (h, alpha, gamma, beta) = (self.h, self.alpha, self.gamma, self.beta);
        let a0 = 1.0 / (beta * h * h);
        let a1 = gamma / (beta * h);
        let a2 = 1.0 / (beta * h);
        let a3 = 0.5 / beta - 1.0;
        let hht = alpha != 0.0;
        let mut out_u = DMatrix::zeros(n, ns);
        let mut out_v = DMatrix::zeros(n, ns);
        let mut out_a = DMatrix::zeros(n, ns);
        let mut out_f = DMatrix::zeros(n, ns);
        let mut ws = Work::new(n);
        ws.slopes = vec![0.0; self.elements.len()];
        ws.u.copy_from_slice(&u0[..n]);
        ws.v.copy_from_slice(&v0[..n]);
        // initial acceleration from equilibrium
        let mut status = SimStatus::Completed;
        let mut steps = 0;
        let mut iters = 0;
        let mut done = 0usize;
        if ns > 0 {
            elements::internal_force(&self.elements, &ws.u, &ws.v, &mut ws.fnl);
            for i in 0..n {
                ws.rhs[i] = force[(i, 0)] - ws.fnl[i];
            }
            mat_vec_sub(&self.c, &ws.v, &mut ws.rhs);
            mat_vec_sub(&self.k, &ws.u, &mut ws.rhs);
            match self.m.clone().cholesky() {
                Some(ch) => {
                    let x = ch.solve(&nalgebra::DVector::from_column_slice(&ws.rhs));
                    ws.a.copy_from_slice(x.as_slice());
                }
                None => {
                    return Simulation {
                        status: SimStatus::NonFinite {
                            time: 0.0,
                            sample: 0,
                        },
                        u: DMatrix::zeros(n, 0),
                        v: DMatrix::zeros(n, 0),
                        a: DMatrix::zeros(n, 0),
                        fint: DMatrix::zeros(n, 0),
                        steps: 0,
                        newton_iterations: 0,
                    };
                }
            }
            self.store(&ws, 0, &mut out_u, &mut out_v, &mut out_a, &mut out_f);
            if hht {
                self.g_of(&mut ws);
            }
            done = 1;
        }
        let mut f_prev: Vec<f64> = vec![0.0; n];
        let mut f_next: Vec<f64> = vec![0.0; n];
        'samples: for k in 1..ns {
            for i in 0..n {
                f_prev[i] = force[(i, k - 1)];
                f_next[i] = force[(i, k)];
            }
            for sub in 0..s {
                // force at t_n + (1+α) h, linear between samples k-1 and k
                let frac = ((sub as f64) + 1.0 + alpha) / s as f64;
                for ((ft, fp), fnx) in ws.ft.iter_mut().zip(&f_prev).zip(&f_next) {
                    *ft = fp * (1.0 - frac) + fnx * frac;
                }
                // affine parts: a = a0 u + z, v = a1 u + w
                for i in 0..n {
                    ws.z[i] = -a0 * ws.u[i] - a2 * ws.v[i] - a3 * ws.a[i];
                    ws.w[i] = ws.v[i] + h * (1.0 - gamma) * ws.a[i] + h * gamma * ws.z[i];
                }
                // b = f_t − M z − (1+α) C w + α g_n
                ws.b.copy_from_slice(&ws.ft);
                mat_vec_sub(&self.m, &ws.z, &mut ws.b);
                mat_vec_axpy(&self.c, &ws.w, -(1.0 + alpha), &mut ws.b);
                if hht {
                    for i in 0..n {
                        ws.b[i] += alpha * ws.g[i];
                    }
                }
                // predictor
                for i in 0..n {
                    ws.un[i] = ws.u[i] + h * ws.v[i] + 0.5 * h * h * ws.a[i];
                }
                match self.newton(&mut ws, a1) {
                    Ok(it) => iters += it,
                    Err((it, res)) => {
                        iters += it;
                        status = SimStatus::NewtonFailed {
                            time: (k - 1) as f64 / self.fs() + (sub + 1) as f64 * h,
                            sample: k - 1,
                            iterations: it,
                            residual: res,
                        };
                        break 'samples;
                    }
                }
                steps += 1;
                for i in 0..n {
                    let un = ws.un[i];
                    ws.a[i] = a0 * un + ws.z[i];
                    ws.v[i] = a1 * un + ws.w[i];
                    ws.u[i] = un;
                }
                if ws.u.iter().chain(&ws.v).any(|x| !x.is_finite()) {
                    status = SimStatus::NonFinite {
                        time: (k - 1) as f64 / self.fs() + (sub + 1) as f64 * h,
                        sample: k - 1,
                    };
                    break 'samples;
                }
                if hht {
                    self.g_of(&mut ws);
                }
            }
            elements::internal_force(&self.elements, &ws.u, &ws.v, &mut ws.fnl);
            self.store(&ws, k, &mut out_u, &mut out_v, &mut out_a, &mut out_f);
            done = k + 1;
        }
        if done < ns {
            out_u = out_u.columns(0, done).into_owned();
            out_v = out_v.columns(0, done).into_owned();
            out_a = out_a.columns(0, done).into_owned();
            out_f = out_f.columns(0, done).into_owned();
        }
        Simulation {
            status,
            u: out_u,
            v: out_v,
            a: out_a,
            fint: out_f,
            steps,
            newton_iterations: iters,
        }
    }

    fn fs(&self) -> f64 {
        1.0 / (self.h * self.settings.substeps as f64)
    }

    fn store(
        &self,
        ws: &Work,
        k: usize,
        u: &mut DMatrix<f64>,
        v: &mut DMatrix<f64>,
        a: &mut DMatrix<f64>,
        f: &mut DMatrix<f64>,
    ) {
        u.column_mut(k).copy_from_slice(&ws.u);
        v.column_mut(k).copy_from_slice(&ws.v);
        a.column_mut(k).copy_from_slice(&ws.a);
        f.column_mut(k).copy_from_slice(&ws.fnl);
    }

    /// g = C v + K u + f_int(u, v) at the current state (HHT only).
    fn g_of(&self, ws: &mut Work) {
        elements::internal_force(&self.elements, &ws.u, &ws.v, &mut ws.g);
        mat_vec_axpy(&self.c, &ws.v, 1.0, &mut ws.g);
        mat_vec_axpy(&self.k, &ws.u, 1.0, &mut ws.g);
    }

    /// Residual r(u) = J0 u − b + (1+α) f_int(u, a1 u + w) into ws.r;
    /// returns (‖r‖∞, scale).
    fn residual(&self, ws: &mut Work, a1: f64) -> (f64, f64) {
        let n = self.n;
        let c1 = 1.0 + self.alpha;
        for i in 0..n {
            ws.r[i] = 0.0;
        }
        mat_vec_axpy(&self.j0, &ws.un, 1.0, &mut ws.r);
        let mut scale = 0.0f64;
        for i in 0..n {
            scale = scale.max(ws.r[i].abs()).max(ws.b[i].abs());
            ws.r[i] -= ws.b[i];
        }
        if !self.elements.is_empty() {
            for i in 0..n {
                ws.vn[i] = a1 * ws.un[i] + ws.w[i];
            }
            ws.fnl.iter_mut().for_each(|x| *x = 0.0);
            for (e, s) in self.elements.iter().zip(ws.slopes.iter_mut()) {
                *s = e.force_and_slope(&ws.un, &ws.vn, &mut ws.fnl);
            }
            for i in 0..n {
                scale = scale.max(c1 * ws.fnl[i].abs());
                ws.r[i] += c1 * ws.fnl[i];
            }
        }
        let norm = ws.r.iter().fold(0.0f64, |a, &b| a.max(b.abs()));
        (norm, scale)
    }

    /// Newton iterations on ws.un; Ok(iterations) or Err((iterations, residual)).
    fn newton(&self, ws: &mut Work, a1: f64) -> std::result::Result<usize, (usize, f64)> {
        let n = self.n;
        let c1 = 1.0 + self.alpha;
        let tol = self.settings.newton_tol;
        if self.elements.is_empty() {
            if let Some(l) = &self.j0_chol {
                ws.un.copy_from_slice(&ws.b);
                chol_solve(l, n, &mut ws.un);
                return Ok(1);
            }
        }
        let (mut rn, mut scale) = self.residual(ws, a1);
        let mut it = 0;
        while !(rn <= tol * scale || rn == 0.0) {
            if it >= self.settings.max_newton || !rn.is_finite() {
                return Err((it, rn));
            }
            it += 1;
            // Newton matrix: J0 plus the slopes of the last residual evaluation
            let mut any_tangent = false;
            ws.jac.copy_from_slice(self.j0.as_slice());
            for (e, &sl) in self.elements.iter().zip(&ws.slopes) {
                any_tangent |= e.add_slope(sl, c1, c1 * a1, &mut ws.jac, n);
            }
            ws.du.copy_from_slice(&ws.r);
            let solved = match (&self.j0_chol, any_tangent) {
                (Some(l), false) => {
                    chol_solve(l, n, &mut ws.du);
                    true
                }
                _ => {
                    if cholesky_in_place(&mut ws.jac, n) {
                        chol_solve(&ws.jac, n, &mut ws.du);
                        true
                    } else {
                        // not SPD (e.g. a softening cubic): rebuild, solve by LU
                        ws.jac.copy_from_slice(self.j0.as_slice());
                        for (e, &sl) in self.elements.iter().zip(&ws.slopes) {
                            e.add_slope(sl, c1, c1 * a1, &mut ws.jac, n);
                        }
                        lu_solve(&ws.jac, n, &mut ws.du)
                    }
                }
            };
            if !solved {
                return Err((it, rn));
            }
            // backtracking line search on ‖r‖∞
            ws.u_old.copy_from_slice(&ws.un);
            let mut lambda = 1.0;
            loop {
                for i in 0..n {
                    ws.un[i] = ws.u_old[i] - lambda * ws.du[i];
                }
                let (rn_new, sc) = self.residual(ws, a1);
                if rn_new < rn || lambda < 1.0 / 64.0 || rn_new <= tol * sc {
                    rn = rn_new;
                    scale = sc;
                    break;
                }
                lambda *= 0.5;
            }
        }
        Ok(it.max(1))
    }
}

struct Work {
    u: Vec<f64>,
    v: Vec<f64>,
    a: Vec<f64>,
    un: Vec<f64>,
    vn: Vec<f64>,
    u_old: Vec<f64>,
    du: Vec<f64>,
    z: Vec<f64>,
    w: Vec<f64>,
    b: Vec<f64>,
    r: Vec<f64>,
    g: Vec<f64>,
    ft: Vec<f64>,
    fnl: Vec<f64>,
    rhs: Vec<f64>,
    jac: Vec<f64>,
    slopes: Vec<f64>,
}

impl Work {
    fn new(n: usize) -> Work {
        let z = || vec![0.0; n];
        Work {
            u: z(),
            v: z(),
            a: z(),
            un: z(),
            vn: z(),
            u_old: z(),
            du: z(),
            z: z(),
            w: z(),
            b: z(),
            r: z(),
            g: z(),
            ft: z(),
            fnl: z(),
            rhs: z(),
            jac: vec![0.0; n * n],
            slopes: vec![],
        }
    }
}

/// y −= A x (A column-major n×n).
#[inline]
fn mat_vec_sub(a: &DMatrix<f64>, x: &[f64], y: &mut [f64]) {
    mat_vec_axpy(a, x, -1.0, y);
}

/// y += s A x.
#[inline]
fn mat_vec_axpy(a: &DMatrix<f64>, x: &[f64], s: f64, y: &mut [f64]) {
    let n = a.nrows();
    let data = a.as_slice();
    for (j, &xj) in x.iter().enumerate() {
        if xj == 0.0 {
            continue;
        }
        let sx = s * xj;
        let col = &data[j * n..(j + 1) * n];
        for (yi, &aij) in y.iter_mut().zip(col) {
            *yi += aij * sx;
        }
    }
}

/// In-place dense Cholesky of a small SPD matrix (column-major, lower
/// triangle used and overwritten with L, whose diagonal is stored as its
/// reciprocal so the solves multiply instead of divide). Returns false if
/// not SPD. This is the Newton step's n×n solve (n ≤ a few dozen); large
/// problems go through faer elsewhere.
fn cholesky_in_place(a: &mut [f64], n: usize) -> bool {
    for j in 0..n {
        let (done, rest) = a.split_at_mut(j * n);
        let col_j = &mut rest[..n];
        // col_j[i] -= Σ_k L[i,k] L[j,k]  for i ≥ j
        for k in 0..j {
            let col_k = &done[k * n..(k + 1) * n];
            let ljk = col_k[j];
            if ljk != 0.0 {
                for i in j..n {
                    col_j[i] -= col_k[i] * ljk;
                }
            }
        }
        let d = col_j[j];
        if !(d > 0.0) || !d.is_finite() {
            return false;
        }
        let inv = 1.0 / d.sqrt();
        col_j[j] = inv;
        for x in col_j.iter_mut().skip(j + 1) {
            *x *= inv;
        }
    }
    true
}

/// Solve L Lᵀ x = b in place (L from [`cholesky_in_place`]).
fn chol_solve(l: &[f64], n: usize, b: &mut [f64]) {
    // forward: L y = b, column-oriented
    for j in 0..n {
        let col = &l[j * n..(j + 1) * n];
        let y = b[j] * col[j];
        b[j] = y;
        if y != 0.0 {
            for i in (j + 1)..n {
                b[i] -= col[i] * y;
            }
        }
    }
    // backward: Lᵀ x = y
    for i in (0..n).rev() {
        let col = &l[i * n..(i + 1) * n];
        let mut s = b[i];
        for k in (i + 1)..n {
            s -= col[k] * b[k];
        }
        b[i] = s * col[i];
    }
}

/// General solve (indefinite tangent, e.g. a softening cubic), with
/// nalgebra's LU. Returns false when singular.
fn lu_solve(a: &[f64], n: usize, b: &mut [f64]) -> bool {
    let m = DMatrix::from_column_slice(n, n, a);
    match m.lu().solve(&nalgebra::DVector::from_column_slice(b)) {
        Some(x) => {
            b.copy_from_slice(x.as_slice());
            true
        }
        None => false,
    }
}

#[cfg(test)]
mod tests;
