//! Forward sensitivities of the Newmark / HHT-α scheme: the exact
//! derivatives of the *discrete* solution with respect to the initial state
//! and to model parameters, from one simulation.
//!
//! Each sub-step solves `R(u_{n+1}; u_n, v_n, a_n, g_n, p) = 0` with
//!
//! $$ R = M a_{n+1} + (1+α)\,g(u_{n+1}, v_{n+1}) − α\,g_n − f(t_n + (1+α)h), $$
//!
//! `g = C v + K u + f_int(u, v)`, `a_{n+1} = a_0 u_{n+1} + z`,
//! `v_{n+1} = a_1 u_{n+1} + w` and the affine parts
//! `z = −a_0 u_n − a_2 v_n − a_3 a_n`, `w = v_n + h(1−γ) a_n + hγ z`
//! (the Newmark constants depend on `h` and `α` only). The implicit
//! function theorem at the converged `u_{n+1}` gives, for one seed
//! direction (a state direction or `∂/∂p` of a parameter),
//!
//! $$ J_T\,δu_{n+1} = −M δz − (1+α)(C + F_v) δw + α δg_n − δM a_{n+1}
//!    − (1+α)\,q_{n+1}, $$
//!
//! with the converged tangent `J_T = J_0 + (1+α)(F_u + a_1 F_v)`
//! (`F_u = ∂f_int/∂u`, `F_v = ∂f_int/∂v` at `(u_{n+1}, v_{n+1})`),
//! `q = δC v + δK u + ∂f_int/∂p` at the new state, `δz`, `δw` the affine
//! parts applied to `(δu_n, δv_n, δa_n)`, and then
//! `δa_{n+1} = a_0 δu_{n+1} + δz`, `δv_{n+1} = a_1 δu_{n+1} + δw`. With
//! HHT (`α ≠ 0`) the derivative of `g_{n+1}` is carried along:
//! `δg = (C + F_v) δv + (K + F_u) δu + q`. The start is the derivative of
//! the initial acceleration `a_0 = M⁻¹(f_0 − C v_0 − K u_0 − f_int)`:
//! `M δa_0 = −δM a_0 − C δv_0 − K δu_0 − F_u δu_0 − F_v δv_0 − q_0`.
//!
//! `J_T` is factored once per sub-step (Cholesky, or LU when it is not
//! positive definite), and the factor is reused while the element slopes
//! do not change (a linear model, a closed contact without friction);
//! every seed is one more pair of triangular solves. The primal run is
//! [`Integrator::run`]'s own code, so the simulation is the same bit for
//! bit.
//!
//! The derivative is that of the sub-step solution the run computed. For
//! smooth laws (friction, cubic) the slopes are taken at the accepted
//! iterate, which differs from the exact solution by the Newton tolerance.
//! A penalty contact is piecewise linear: the accepted iterate solves
//! exactly the linear law of the side (open or closed) of the last Newton
//! matrix, and Newton may accept it when it lies across the switch by less
//! than the tolerance allows (`k_c |p| ≤ tol · scale`). Its derivative is
//! then that side's — slope and `∂f/∂gap`, `∂f/∂k_c` of the law that
//! produced it — not the other side's, which the implicit function theorem
//! at the accepted point would give: on an 80-segment bumper fit at the
//! default tolerance 1e-10, about one such sub-step per run made the gap's
//! Jacobian column differ by 3 % from the differences of the computed
//! trajectory, enough to stall Levenberg–Marquardt. (`g_{n+1}` for HHT is
//! the actual law at the accepted point, and so is `δg`.) When Newton
//! accepts the predictor without a step (its residual already below the
//! tolerance), the sub-step is differentiated as the exact solution at that
//! point, not as the explicit predictor. At a contact's switching point
//! itself (`δ = gap` exactly) the open side is used.

#[cfg(target_arch = "x86_64")]
use super::dense::Lanes;
use super::dense::{chol_solve, cholesky_in_place, dim, mat_vec, mat_vec_axpy};
use super::{Integrator, OperatorCache, Outputs, SimStatus, Simulation, Work};
use crate::error::{Result, TacitError};
use crate::model::elements::{self, ElementParam};
use nalgebra::{DMatrix, DMatrixView, Dyn, LU};
use serde::Serialize;
use std::ops::Range;

mod tape;
pub use tape::Tape;

static POWERS: OperatorCache<Vec<f64>> = OperatorCache::new();

/// One element parameter in a [`ParamSeed`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ElementSeed {
    /// Index of the element in the integrator's list
    /// ([`Integrator::elements`]; for a model: contacts, then frictions,
    /// then cubic springs, as [`elements::compile`] orders them).
    pub element: usize,
    /// Which of its parameters.
    pub param: ElementParam,
    /// `∂q/∂p`: the element parameter's change per unit of the seeded
    /// parameter (1 for the parameter itself, its scale for a scaled one).
    pub scale: f64,
}

/// The derivative of the model with respect to one parameter `p`: `∂M/∂p`,
/// `∂C/∂p`, `∂K/∂p` (n × n, `None` = 0) and the element parameters it
/// moves.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ParamSeed {
    /// `∂M/∂p`.
    pub dm: Option<DMatrix<f64>>,
    /// `∂C/∂p`.
    pub dc: Option<DMatrix<f64>>,
    /// `∂K/∂p`.
    pub dk: Option<DMatrix<f64>>,
    /// Element parameters moved by `p`.
    pub elements: Vec<ElementSeed>,
}

/// The directions to differentiate along: initial-state directions and
/// parameters.
#[derive(Debug, Clone, PartialEq)]
pub struct Seeds {
    /// `2n × s`: each column an initial direction `(δu_0; δv_0)`
    /// (`2n × 0` for none).
    pub state: DMatrix<f64>,
    /// Parameters.
    pub params: Vec<ParamSeed>,
}

impl Seeds {
    /// Parameter seeds only, for `n` DOFs.
    pub fn params(n: usize, params: Vec<ParamSeed>) -> Seeds {
        Seeds {
            state: DMatrix::zeros(2 * n, 0),
            params,
        }
    }

    /// Every initial-state direction (the `2n × 2n` identity): the
    /// derivatives with respect to `u_0` (seeds `0..n`) and `v_0`
    /// (`n..2n`).
    pub fn initial_state(n: usize) -> Seeds {
        Seeds {
            state: DMatrix::identity(2 * n, 2 * n),
            params: vec![],
        }
    }

    /// Number of seeds (state directions, then parameters).
    pub fn len(&self) -> usize {
        self.state.ncols() + self.params.len()
    }

    /// True when there is no seed.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// Derivatives of a [`Simulation`] along each seed (state seeds first, then
/// parameters), in the simulation's layout: DOF × sample, column 0 the
/// derivative of the initial state (for `a`: of the initial acceleration).
/// Truncated where the simulation stops.
#[derive(Debug, Clone)]
pub struct Sensitivities {
    /// `∂u/∂seed`, one matrix per seed.
    pub du: Vec<DMatrix<f64>>,
    /// `∂v/∂seed`.
    pub dv: Vec<DMatrix<f64>>,
    /// `∂a/∂seed`.
    pub da: Vec<DMatrix<f64>>,
    /// Factorizations of the converged tangent (the rest of the sub-steps
    /// reused one).
    pub factorizations: usize,
    /// Sub-steps whose accepted Newton iterate lies (within the Newton
    /// tolerance) across a contact's switch from the matrix that produced
    /// it; their derivative is taken on the matrix's side (see the module
    /// documentation).
    pub newton_side_steps: usize,
    /// Time (s) of the first sub-step whose converged tangent was singular,
    /// if any: the derivatives are NaN from there on (the simulation is
    /// not affected).
    pub singular_tangent: Option<f64>,
}

/// A parameter seed as column-major slices.
struct Prepared {
    dm: Option<Vec<f64>>,
    dc: Option<Vec<f64>>,
    dk: Option<Vec<f64>>,
    elements: Vec<ElementSeed>,
}

/// The factor of the converged tangent in use.
enum Factor {
    /// None yet (or invalidated).
    Stale,
    /// `J_0`'s own Cholesky factor (no element slope).
    J0,
    /// Cholesky factor in `TangentFactor::l`.
    Chol,
    /// LU of an indefinite tangent.
    Lu(Box<LU<f64, Dyn, Dyn>>),
    /// Singular: no solve.
    Singular,
}

struct TangentFactor {
    factor: Factor,
    /// Cholesky factor (column-major) when `factor` is `Chol`.
    l: Vec<f64>,
    /// The tangent before its factorization (for the LU when it is not
    /// positive definite).
    full: Vec<f64>,
    /// Slopes the factor was built from.
    slopes: Vec<f64>,
    /// LU of `J_0` when it has no Cholesky factor.
    j0_lu: Option<Box<LU<f64, Dyn, Dyn>>>,
    count: usize,
}

/// Derivative state and scratch of one run. `du`, `dv`, `da` are
/// seed-minor (DOF `i` of seed `j` at `i s + j`), so that a sub-step
/// advances every seed at once, each DOF's row one vector
/// ([`Integrator::seeds_step`]); the rest is seed-major (seed `j` at
/// `j n .. (j+1) n`).
struct SensWork {
    s: usize,
    du: Vec<f64>,
    dv: Vec<f64>,
    da: Vec<f64>,
    /// `δg` per seed (HHT only).
    dg: Vec<f64>,
    dz: Vec<f64>,
    dw: Vec<f64>,
    rhs: Vec<f64>,
    /// One seed's `(δu, δv, δa)`, gathered (3n).
    one: Vec<f64>,
    /// One row of every seed (s).
    row: Vec<f64>,
    /// `δz`, `δw` and the right-hand sides of every seed (seed-minor).
    all_z: Vec<f64>,
    all_w: Vec<f64>,
    all_rhs: Vec<f64>,
    /// Sub-steps each seed has yet to be advanced over (batched).
    pending: Vec<usize>,
    /// Scratch of the batched advance (3n).
    y3: Vec<f64>,
    /// `q` per parameter seed at the current state.
    q: Vec<f64>,
    /// `δM a + (1+α) q` per parameter seed.
    p: Vec<f64>,
    /// `q` with the actual contact sides (HHT, when they differ).
    q_act: Vec<f64>,
    slopes0: Vec<f64>,
    /// Slopes used by the current sub-step's derivative.
    eff: Vec<f64>,
    /// Each contact's side used (None for other elements).
    closed: Vec<Option<bool>>,
    /// Sub-steps where a contact's side differed from the accepted point.
    side_steps: usize,
    tangent: TangentFactor,
    singular_at: Option<f64>,
}

impl Integrator {
    /// The compiled nonlinear elements (indices of [`ElementSeed::element`]).
    pub fn elements(&self) -> &[elements::Element] {
        &self.elements
    }

    /// Simulate as [`Integrator::run`] (the same numbers bit for bit) and
    /// propagate the derivatives of the discrete solution along `seeds`
    /// (see the module documentation for the equations).
    ///
    /// Errors (bad input): `force` without `n` rows, `u0`/`v0` shorter than
    /// `n`, a state seed matrix without `2n` rows, a seed matrix that is not
    /// `n × n`, an element index out of range or a parameter the element
    /// does not have. A simulation that stops is a status in the
    /// [`Simulation`], and the derivatives stop with it.
    pub fn run_sensitivities(
        &self,
        force: DMatrixView<'_, f64>,
        u0: &[f64],
        v0: &[f64],
        seeds: &Seeds,
    ) -> Result<(Simulation, Sensitivities)> {
        let prep = self.check_seeds(force, u0, v0, seeds)?;
        let st = &seeds.state;
        Ok(match self.n {
            1 => self.run_sens_n::<1>(force, u0, v0, st, &prep),
            2 => self.run_sens_n::<2>(force, u0, v0, st, &prep),
            3 => self.run_sens_n::<3>(force, u0, v0, st, &prep),
            4 => self.run_sens_n::<4>(force, u0, v0, st, &prep),
            5 => self.run_sens_n::<5>(force, u0, v0, st, &prep),
            6 => self.run_sens_n::<6>(force, u0, v0, st, &prep),
            7 => self.run_sens_n::<7>(force, u0, v0, st, &prep),
            8 => self.run_sens_n::<8>(force, u0, v0, st, &prep),
            _ => self.run_sens_n::<0>(force, u0, v0, st, &prep),
        })
    }

    fn check_seeds(
        &self,
        force: DMatrixView<'_, f64>,
        u0: &[f64],
        v0: &[f64],
        seeds: &Seeds,
    ) -> Result<Vec<Prepared>> {
        let n = self.n;
        let err = |m: String| TacitError::Setting(format!("sensitivities: {m}"));
        let bad = |m: String| Err(err(m));
        if self.stateful {
            return bad("a Jenkins element's slip state has no derivative recursion here; take finite differences of the simulation".into());
        }
        if force.nrows() != n || u0.len() < n || v0.len() < n {
            return bad(format!(
                "force has {} rows, u0 {} and v0 {} values; the model has {n} DOFs",
                force.nrows(),
                u0.len(),
                v0.len()
            ));
        }
        if seeds.state.ncols() > 0 && seeds.state.nrows() != 2 * n {
            return bad(format!(
                "the state seeds have {} rows, expected 2n = {}",
                seeds.state.nrows(),
                2 * n
            ));
        }
        let mut out = Vec::with_capacity(seeds.params.len());
        for (j, p) in seeds.params.iter().enumerate() {
            let mat = |m: &Option<DMatrix<f64>>, what: &str| -> Result<Option<Vec<f64>>> {
                match m {
                    Some(m) if m.shape() != (n, n) => Err(err(format!(
                        "parameter seed {j}: {what} is {}x{}, expected {n}x{n}",
                        m.nrows(),
                        m.ncols()
                    ))),
                    Some(m) => Ok(Some(m.as_slice().to_vec())),
                    None => Ok(None),
                }
            };
            let (dm, dc, dk) = (mat(&p.dm, "dM")?, mat(&p.dc, "dC")?, mat(&p.dk, "dK")?);
            for e in &p.elements {
                match self.elements.get(e.element) {
                    None => {
                        return bad(format!(
                            "parameter seed {j}: element {} of {}",
                            e.element,
                            self.elements.len()
                        ))
                    }
                    Some(el) if !e.param.belongs_to(el) => {
                        return bad(format!(
                            "parameter seed {j}: element {} ({el:?}) has no {:?} parameter",
                            e.element, e.param
                        ))
                    }
                    _ => {}
                }
            }
            out.push(Prepared {
                dm,
                dc,
                dk,
                elements: p.elements.clone(),
            });
        }
        Ok(out)
    }

    /// [`Integrator::run_sensitivities`] with the kernels' size `N`; the
    /// sample loop is [`Integrator::run_n`]'s with the derivative step added.
    fn run_sens_n<const N: usize>(
        &self,
        force: DMatrixView<'_, f64>,
        u0: &[f64],
        v0: &[f64],
        state: &DMatrix<f64>,
        prep: &[Prepared],
    ) -> (Simulation, Sensitivities) {
        let n = self.n;
        let ns = force.ncols();
        let mut out = Outputs::new(n, ns);
        let mut ws = Work::new(n, self.elements.len());
        let mut sw = SensWork::new(self, state.ncols() + prep.len(), prep.len());
        let mut dout = SensOutputs::new(n, ns, sw.s);
        let powers = self.linear_powers();
        // a parameter that moves M, C or K has a term in every sub-step
        let map = self.sample_map().filter(|_| powers.is_some()).filter(|_| {
            prep.iter()
                .all(|p| p.dm.is_none() && p.dc.is_none() && p.dk.is_none())
        });
        ws.u.copy_from_slice(&u0[..n]);
        ws.v.copy_from_slice(&v0[..n]);
        let mut status = SimStatus::Completed;
        let (mut steps, mut iters, mut done) = (0, 0, 0usize);
        if ns > 0 {
            if !self.initial_acceleration(force, &mut ws) {
                let sim = Outputs::new(n, 0).finish(
                    SimStatus::NonFinite {
                        time: 0.0,
                        sample: 0,
                    },
                    0,
                    0,
                );
                return (sim, dout.finish(0, &sw));
            }
            out.store(&ws, 0);
            self.initial_sensitivities::<N>(&ws, &mut sw, state, prep);
            dout.store(&sw, 0);
            if self.alpha != 0.0 {
                self.g_of::<N>(&mut ws);
            }
            done = 1;
        }
        'samples: for k in 1..ns {
            for i in 0..n {
                ws.f_prev[i] = force[(i, k - 1)];
                ws.f_next[i] = force[(i, k)];
            }
            // the whole sample by its map ([`SampleMap`]): every seed is
            // then without a parameter term and waits for the powers
            let whole = self.whole_sample(map, &mut ws, k);
            if whole.is_some() {
                let s = self.settings.substeps;
                steps += s;
                iters += s;
                sw.pending.iter_mut().for_each(|p| *p += s);
            }
            if let Some(Err(s)) = whole {
                status = s;
                break 'samples;
            }
            for sub in (0..self.settings.substeps).filter(|_| whole.is_none()) {
                let time = || (k - 1) as f64 / self.fs() + (sub + 1) as f64 * self.h;
                match self.advance::<N>(&mut ws, sub) {
                    Ok(it) => iters += it,
                    Err((iterations, residual)) => {
                        iters += iterations;
                        status = SimStatus::NewtonFailed {
                            time: time(),
                            sample: k - 1,
                            iterations,
                            residual,
                        };
                        break 'samples;
                    }
                }
                steps += 1;
                if !ws.finite() {
                    status = SimStatus::NonFinite {
                        time: time(),
                        sample: k - 1,
                    };
                    break 'samples;
                }
                if !self.sensitivity_step::<N>(&ws, &mut sw, prep, powers)
                    && sw.singular_at.is_none()
                {
                    sw.singular_at = Some(time());
                }
                if self.alpha != 0.0 {
                    self.g_of::<N>(&mut ws);
                }
            }
            elements::internal_force(&self.elements, &ws.u, &ws.v, &mut ws.fnl);
            out.store(&ws, k);
            flush_all(powers, n, &mut sw);
            dout.store(&sw, k);
            done = k + 1;
        }
        out.truncate(done);
        (out.finish(status, steps, iters), dout.finish(done, &sw))
    }

    /// `q = δC v + δK u + ∂f_int/∂p` of every parameter seed at the state
    /// in `ws` (u, v), into `q` (seed-major); `closed`: each contact's
    /// side of the switch (`None`: from its penetration).
    #[inline(always)]
    fn parameter_q<const N: usize>(
        &self,
        ws: &Work,
        prep: &[Prepared],
        closed: &[Option<bool>],
        q: &mut [f64],
    ) {
        let n = dim::<N>(self.n);
        for (j, p) in prep.iter().enumerate() {
            let q = &mut q[j * n..(j + 1) * n];
            q.fill(0.0);
            if let Some(dc) = &p.dc {
                mat_vec_axpy::<N>(dc, n, &ws.v, 1.0, q);
            }
            if let Some(dk) = &p.dk {
                mat_vec_axpy::<N>(dk, n, &ws.u, 1.0, q);
            }
            for e in &p.elements {
                let side = closed[e.element];
                self.elements[e.element]
                    .add_param_derivative_on(e.param, e.scale, &ws.u, &ws.v, side, q);
            }
        }
    }

    /// `p = δM a + (1+α) q` of every parameter seed (from `sw.q`).
    #[inline(always)]
    fn parameter_p<const N: usize>(&self, ws: &Work, sw: &mut SensWork, prep: &[Prepared]) {
        let n = dim::<N>(self.n);
        let c1 = 1.0 + self.alpha;
        for (j, p) in prep.iter().enumerate() {
            let pj = &mut sw.p[j * n..(j + 1) * n];
            for (x, q) in pj.iter_mut().zip(&sw.q[j * n..(j + 1) * n]) {
                *x = c1 * q;
            }
            if let Some(dm) = &p.dm {
                mat_vec_axpy::<N>(dm, n, &ws.a, 1.0, pj);
            }
        }
    }

    /// The element slopes the sub-step's derivative uses, into `sw.eff`, and
    /// each contact's side into `sw.closed`: a contact is on the side of
    /// the last Newton matrix (the accepted iterate solves that side's
    /// linear law, even when it lies within the Newton tolerance across the
    /// switch), the other elements at the accepted point. True when some
    /// contact's side differs from its actual state at the accepted point.
    #[inline(always)]
    fn newton_side(&self, ws: &Work, sw: &mut SensWork) -> bool {
        let mut differs = false;
        for (e, el) in self.elements.iter().enumerate() {
            let actual = ws.slopes[e];
            sw.eff[e] = actual;
            if let elements::Element::Contact { .. } = el {
                let side = if ws.iterated {
                    ws.dir_slopes[e]
                } else {
                    actual
                };
                sw.eff[e] = side;
                sw.closed[e] = Some(side != 0.0);
                differs |= (side != 0.0) != (actual != 0.0);
            }
        }
        differs
    }

    /// Derivatives of the initial state: the seeds' `(δu_0, δv_0)` and
    /// `δa_0` from `M δa_0 = −δM a_0 − (C + F_v) δv_0 − (K + F_u) δu_0 − q_0`.
    fn initial_sensitivities<const N: usize>(
        &self,
        ws: &Work,
        sw: &mut SensWork,
        state: &DMatrix<f64>,
        prep: &[Prepared],
    ) {
        let n = dim::<N>(self.n);
        let ns0 = state.ncols();
        let s = sw.s;
        for j in 0..ns0 {
            for i in 0..n {
                sw.du[i * s + j] = state[(i, j)];
                sw.dv[i * s + j] = state[(n + i, j)];
            }
        }
        let mut f = vec![0.0; n];
        for (e, s) in self.elements.iter().zip(sw.slopes0.iter_mut()) {
            *s = e.force_and_slope(&ws.u, &ws.v, &mut f);
        }
        let open = vec![None; self.elements.len()];
        self.parameter_q::<N>(ws, prep, &open, &mut sw.q);
        let mchol = self.m.clone().cholesky();
        for j in 0..sw.s {
            let r = j * n..(j + 1) * n;
            let mut g = vec![0.0; n];
            gather(sw, j, n);
            let (du, dv) = (&sw.one[..n], &sw.one[n..2 * n]);
            self.g_derivative::<N>(&sw.slopes0, du, dv, &mut g);
            let mut rhs = nalgebra::DVector::from_fn(n, |i, _| -g[i]);
            if j >= ns0 {
                let jp = j - ns0;
                for i in 0..n {
                    rhs[i] -= sw.q[jp * n + i];
                }
                if let Some(dm) = &prep[jp].dm {
                    mat_vec_axpy::<N>(dm, n, &ws.a, -1.0, rhs.as_mut_slice());
                }
                g.iter_mut()
                    .zip(&sw.q[jp * n..(jp + 1) * n])
                    .for_each(|(gi, qi)| *gi += qi);
            }
            let da = match &mchol {
                Some(ch) => ch.solve(&rhs),
                None => nalgebra::DVector::from_element(n, f64::NAN),
            };
            for i in 0..n {
                sw.da[i * s + j] = da[i];
            }
            if self.alpha != 0.0 {
                sw.dg[r].copy_from_slice(&g);
            }
        }
    }

    /// `y = (C + F_v) δv + (K + F_u) δu` (the state part of `δg`).
    fn g_derivative<const N: usize>(&self, slopes: &[f64], du: &[f64], dv: &[f64], y: &mut [f64]) {
        let n = dim::<N>(self.n);
        y[..n].fill(0.0);
        mat_vec_axpy::<N>(self.c.as_slice(), n, dv, 1.0, y);
        mat_vec_axpy::<N>(self.k.as_slice(), n, du, 1.0, y);
        for (e, &sl) in self.elements.iter().zip(slopes) {
            e.add_slope_product(sl, (1.0, du), (1.0, dv), y);
        }
    }

    /// Propagate every seed over the sub-step just taken (`ws` holds the
    /// new state, the step's affine parts `z, w` and the element slopes at
    /// the converged point). False when the converged tangent is singular
    /// (the derivatives become NaN).
    fn sensitivity_step<const N: usize>(
        &self,
        ws: &Work,
        sw: &mut SensWork,
        prep: &[Prepared],
        powers: Option<&[f64]>,
    ) -> bool {
        // SAFETY: each copy runs only where the CPU has its features
        // (detected at run time by `dense::lanes`)
        #[cfg(target_arch = "x86_64")]
        match super::dense::lanes() {
            Lanes::Eight => {
                return unsafe { self.sensitivity_step_avx512::<N>(ws, sw, prep, powers) }
            }
            Lanes::Four => return unsafe { self.sensitivity_step_avx2::<N>(ws, sw, prep, powers) },
            Lanes::Two => {}
        }
        self.sensitivity_step_body::<N>(ws, sw, prep, powers)
    }

    /// [`Integrator::sensitivity_step`] compiled for AVX2 (the same
    /// operations in the same order, so the same bits; see
    /// [`super::dense::Lanes`]).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn sensitivity_step_avx2<const N: usize>(
        &self,
        ws: &Work,
        sw: &mut SensWork,
        prep: &[Prepared],
        powers: Option<&[f64]>,
    ) -> bool {
        self.sensitivity_step_body::<N>(ws, sw, prep, powers)
    }

    /// [`Integrator::sensitivity_step`] compiled for AVX-512 (the same bits).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,avx512f")]
    fn sensitivity_step_avx512<const N: usize>(
        &self,
        ws: &Work,
        sw: &mut SensWork,
        prep: &[Prepared],
        powers: Option<&[f64]>,
    ) -> bool {
        self.sensitivity_step_body::<N>(ws, sw, prep, powers)
    }

    #[inline(always)]
    fn sensitivity_step_body<const N: usize>(
        &self,
        ws: &Work,
        sw: &mut SensWork,
        prep: &[Prepared],
        powers: Option<&[f64]>,
    ) -> bool {
        let n = dim::<N>(self.n);
        let (h, alpha, gamma, beta) = (self.h, self.alpha, self.gamma, self.beta);
        let a1 = gamma / (beta * h);
        let differs = self.newton_side(ws, sw);
        sw.side_steps += usize::from(differs);
        let ok = self.factor_tangent::<N>(&sw.eff, a1, &mut sw.tangent);
        self.parameter_q::<N>(ws, prep, &sw.closed, &mut sw.q);
        self.parameter_p::<N>(ws, sw, prep);
        // δg follows the actual law at the accepted point (as g itself)
        let hht_differs = alpha != 0.0 && differs;
        if hht_differs {
            let actual = vec![None; self.elements.len()];
            self.parameter_q::<N>(ws, prep, &actual, &mut sw.q_act);
        }
        let ns0 = sw.s - prep.len();
        // no element active (α = 0): a seed without a parameter term this
        // sub-step only counts it, and is advanced by the power of the
        // constant sub-step map when it is next needed
        let batch = powers.is_some() && sw.eff.iter().all(|&e| e == 0.0);
        // an element active: every seed steps, all at once
        if !batch && alpha == 0.0 {
            flush_all(powers, n, sw);
            self.seeds_step::<N>(sw, 0..sw.s, ns0);
            return ok;
        }
        for j in 0..sw.s {
            let r = j * n..(j + 1) * n;
            let pr = (j >= ns0).then(|| (j - ns0) * n..(j - ns0 + 1) * n);
            if batch && pr.clone().is_none_or(|p| sw.p[p].iter().all(|&x| x == 0.0)) {
                sw.pending[j] += 1;
                continue;
            }
            if let (Some(pw), true) = (powers, sw.pending[j] != 0) {
                flush_seed(pw, n, j, sw);
            }
            gather(sw, j, n);
            let pj = pr.map(|p| &sw.p[p]);
            let dg = (alpha != 0.0).then(|| &sw.dg[r.clone()]);
            let (du, rest) = sw.one.split_at_mut(n);
            let (dv, da) = rest.split_at_mut(n);
            let solved = self.seed_step::<N>(
                &sw.eff,
                (du, dv, da),
                dg,
                pj,
                (&mut sw.dz, &mut sw.dw, &mut sw.rhs),
                |b| self.solve_tangent::<N>(&sw.tangent, b),
            );
            if !solved {
                sw.one.fill(f64::NAN);
            }
            scatter(sw, j, n);
            if alpha != 0.0 {
                let dg = &mut sw.dg[r.clone()];
                let (du, dv) = (&sw.one[..n], &sw.one[n..2 * n]);
                self.g_derivative::<N>(&ws.slopes, du, dv, dg);
                if j >= ns0 {
                    let jp = j - ns0;
                    let q = if hht_differs { &sw.q_act } else { &sw.q };
                    for (x, q) in dg.iter_mut().zip(&q[jp * n..(jp + 1) * n]) {
                        *x += q;
                    }
                }
            }
        }
        ok
    }

    /// Advance one seed's derivative `x = (δu, δv, δa)` over the sub-step:
    /// `δz`, `δw`, the right-hand side `−M δz − (1+α)(C + F_v) δw + α δg_n
    /// − p` with the element slopes `eff`, `δg_n` (HHT) and the parameter
    /// term `p` (None for a state seed), the tangent solve `solve`. False
    /// when the solve failed.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn seed_step<const N: usize>(
        &self,
        eff: &[f64],
        (du, dv, da): (&mut [f64], &mut [f64], &mut [f64]),
        dg: Option<&[f64]>,
        p: Option<&[f64]>,
        (dz, dw, rhs): (&mut [f64], &mut [f64], &mut [f64]),
        solve: impl Fn(&mut [f64]) -> bool,
    ) -> bool {
        let n = dim::<N>(self.n);
        let (h, alpha, gamma, beta) = (self.h, self.alpha, self.gamma, self.beta);
        let (a0, a1) = (1.0 / (beta * h * h), gamma / (beta * h));
        let (a2, a3) = (1.0 / (beta * h), 0.5 / beta - 1.0);
        let c1 = 1.0 + alpha;
        let (du, dv, da) = (&mut du[..n], &mut dv[..n], &mut da[..n]);
        let (dz, dw, rhs) = (&mut dz[..n], &mut dw[..n], &mut rhs[..n]);
        for i in 0..n {
            dz[i] = -a0 * du[i] - a2 * dv[i] - a3 * da[i];
            dw[i] = dv[i] + h * (1.0 - gamma) * da[i] + h * gamma * dz[i];
        }
        match &self.m_diag {
            Some(m) => (0..n).for_each(|i| rhs[i] = -m[i] * dz[i]),
            None => {
                rhs.fill(0.0);
                mat_vec_axpy::<N>(self.m.as_slice(), n, dz, -1.0, rhs);
            }
        }
        if !self.c_zero {
            mat_vec_axpy::<N>(self.c.as_slice(), n, dw, -c1, rhs);
        }
        for (e, &sl) in self.elements.iter().zip(eff) {
            e.add_slope_product(sl, (0.0, dw), (-c1, dw), rhs);
        }
        if let Some(dg) = dg {
            for (x, g) in rhs.iter_mut().zip(dg) {
                *x += alpha * g;
            }
        }
        if let Some(p) = p {
            for (x, p) in rhs.iter_mut().zip(p) {
                *x -= p;
            }
        }
        let ok = solve(rhs);
        for i in 0..n {
            du[i] = rhs[i];
            da[i] = a0 * rhs[i] + dz[i];
            dv[i] = a1 * rhs[i] + dw[i];
        }
        ok
    }

    /// [`Integrator::seed_step`] for the seeds `cols` at once (α = 0), in
    /// the seed-minor layout of [`SensWork`]: each operation runs along a
    /// DOF's row of those seeds, and every seed sees the same operations in
    /// the same order as in `seed_step` (the same bits). The tangent solve
    /// is a triangular solve of all of them when the tangent has a Cholesky
    /// factor, else one seed at a time; a seed whose solve fails becomes
    /// NaN.
    #[inline(always)]
    fn seeds_step<const N: usize>(&self, sw: &mut SensWork, cols: Range<usize>, ns0: usize) {
        let n = dim::<N>(self.n);
        let s = sw.s;
        let (h, alpha, gamma, beta) = (self.h, self.alpha, self.gamma, self.beta);
        let (a0, a1) = (1.0 / (beta * h * h), gamma / (beta * h));
        let (a2, a3) = (1.0 / (beta * h), 0.5 / beta - 1.0);
        let c1 = 1.0 + alpha;
        let rows = Rows { s, cols };
        let (du, dv, da) = (&mut sw.du, &mut sw.dv, &mut sw.da);
        let (dz, dw, rhs) = (&mut sw.all_z, &mut sw.all_w, &mut sw.all_rhs);
        let row = &mut sw.row;
        for i in 0..n {
            let r = rows.of(i);
            let (du, dv, da) = (&du[r.clone()], &dv[r.clone()], &da[r.clone()]);
            let (dz, dw) = (&mut dz[r.clone()], &mut dw[r]);
            for x in 0..du.len() {
                dz[x] = -a0 * du[x] - a2 * dv[x] - a3 * da[x];
                dw[x] = dv[x] + h * (1.0 - gamma) * da[x] + h * gamma * dz[x];
            }
        }
        match &self.m_diag {
            Some(m) => {
                for (i, &mi) in m.iter().enumerate().take(n) {
                    let r = rows.of(i);
                    let (r, z) = (&mut rhs[r.clone()], &dz[r]);
                    r.iter_mut().zip(z).for_each(|(r, z)| *r = -mi * z);
                }
            }
            None => {
                (0..n).for_each(|i| rhs[rows.of(i)].fill(0.0));
                rows.mat_axpy::<N>(self.m.as_slice(), n, dz, -1.0, rhs, row);
            }
        }
        if !self.c_zero {
            rows.mat_axpy::<N>(self.c.as_slice(), n, dw, -c1, rhs, row);
        }
        for (e, &sl) in self.elements.iter().zip(&sw.eff) {
            if sl != 0.0 {
                // the terms of Element::add_slope_product with
                // (c_u, x_u) = (0, δw), (c_v, x_v) = (−c1, δw)
                let c = if e.is_velocity_law() { -c1 } else { 0.0 } * sl;
                rows.pair_axpy(e.ends(), c, dw, rhs);
            }
        }
        for j in rows.cols.clone().filter(|&j| j >= ns0) {
            let jp = j - ns0;
            for i in 0..n {
                rhs[i * s + j] -= sw.p[jp * n + i];
            }
        }
        let factor = match &sw.tangent.factor {
            Factor::J0 => self.j0_chol.as_deref(),
            Factor::Chol => Some(&sw.tangent.l[..]),
            _ => None,
        };
        match factor {
            Some(l) => rows.chol_solve::<N>(l, n, rhs),
            None => {
                for j in rows.cols.clone() {
                    let b = &mut sw.rhs[..n];
                    (0..n).for_each(|i| b[i] = rhs[i * s + j]);
                    let solved = self.solve_tangent::<N>(&sw.tangent, b);
                    (0..n).for_each(|i| rhs[i * s + j] = if solved { b[i] } else { f64::NAN });
                }
            }
        }
        for i in 0..n {
            let r = rows.of(i);
            let (du, dv, da) = (&mut du[r.clone()], &mut dv[r.clone()], &mut da[r.clone()]);
            let (dz, dw, rhs) = (&dz[r.clone()], &dw[r.clone()], &rhs[r]);
            for x in 0..du.len() {
                du[x] = rhs[x];
                da[x] = a0 * rhs[x] + dz[x];
                dv[x] = a1 * rhs[x] + dw[x];
            }
        }
    }

    /// The powers `L, L², …, L^S` (S sub-steps per sample; each `3n × 3n`,
    /// column-major, one after the other) of the sub-step map `L` of a
    /// derivative `(δu, δv, δa)` without a parameter term when no element
    /// is active: the map of [`Integrator::seed_step`] with zero slopes and
    /// the tangent `J_0`, which does not change from sub-step to sub-step.
    /// Built on first use, or taken from the cache of integrators with the
    /// same linear part; None with HHT (`δg` is carried too), without a
    /// Cholesky factor of `J_0`, or when batching is off.
    pub(super) fn linear_powers(&self) -> Option<&[f64]> {
        self.linear_powers
            .get_or_init(|| {
                if !self.batches() {
                    return None;
                }
                POWERS.get_or_build(self.linear_key(), || self.build_linear_powers())
            })
            .as_deref()
            .map(|v| v.as_slice())
    }

    fn build_linear_powers(&self) -> Option<Vec<f64>> {
        let l = self.j0_chol.as_ref()?;
        let n = self.n;
        let m3 = 3 * n;
        let zeros = vec![0.0; self.elements.len()];
        let (mut dz, mut dw, mut rhs) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
        let mut one = vec![0.0; m3 * m3];
        for (c, col) in one.chunks_exact_mut(m3).enumerate() {
            col[c] = 1.0;
            let (du, rest) = col.split_at_mut(n);
            let (dv, da) = rest.split_at_mut(n);
            self.seed_step::<0>(
                &zeros,
                (du, dv, da),
                None,
                None,
                (&mut dz, &mut dw, &mut rhs),
                |b| {
                    chol_solve::<0>(l, n, b);
                    true
                },
            );
        }
        let s = self.settings.substeps;
        let mut out = Vec::with_capacity(s * m3 * m3);
        out.extend_from_slice(&one);
        for k in 1..s {
            let prev = out[(k - 1) * m3 * m3..k * m3 * m3].to_vec();
            let mut next = vec![0.0; m3 * m3];
            for (pc, nc) in prev.chunks_exact(m3).zip(next.chunks_exact_mut(m3)) {
                mat_vec_axpy::<0>(&one, m3, pc, 1.0, nc);
            }
            out.extend_from_slice(&next);
        }
        Some(out)
    }

    /// Factor `J_T = J_0 + (1+α)(F_u + a_1 F_v)` for `slopes`, unless the
    /// factor in `t` was built from the same slopes; false when singular.
    #[inline(always)]
    fn factor_tangent<const N: usize>(
        &self,
        slopes: &[f64],
        a1: f64,
        t: &mut TangentFactor,
    ) -> bool {
        let n = dim::<N>(self.n);
        if !slopes.iter().any(|&s| s != 0.0) {
            t.factor = Factor::J0;
            return self.j0_chol.is_some() || t.j0_lu.is_some();
        }
        let same = t.slopes == slopes;
        match t.factor {
            Factor::Chol | Factor::Lu(_) if same => return true,
            Factor::Singular if same => return false,
            _ => {}
        }
        t.slopes.copy_from_slice(slopes);
        t.count += 1;
        let c1 = 1.0 + self.alpha;
        t.l.copy_from_slice(self.j0.as_slice());
        for (e, &sl) in self.elements.iter().zip(slopes) {
            e.add_slope(sl, c1, c1 * a1, &mut t.l, n);
        }
        t.full.copy_from_slice(&t.l);
        if cholesky_in_place::<N>(&mut t.l, n) {
            t.factor = Factor::Chol;
            return true;
        }
        let lu = DMatrix::from_column_slice(n, n, &t.full).lu();
        if lu.is_invertible() {
            t.factor = Factor::Lu(Box::new(lu));
            true
        } else {
            t.factor = Factor::Singular;
            false
        }
    }

    /// Solve `J_T x = b` in place with the current factor; false when
    /// singular.
    #[inline(always)]
    fn solve_tangent<const N: usize>(&self, t: &TangentFactor, b: &mut [f64]) -> bool {
        let n = dim::<N>(self.n);
        let lu_solve = |lu: &LU<f64, Dyn, Dyn>, b: &mut [f64]| {
            let mut x = nalgebra::DVector::from_column_slice(&b[..n]);
            let ok = lu.solve_mut(&mut x);
            b[..n].copy_from_slice(x.as_slice());
            ok
        };
        match &t.factor {
            Factor::J0 => match (&self.j0_chol, &t.j0_lu) {
                (Some(l), _) => {
                    chol_solve::<N>(l, n, b);
                    true
                }
                (None, Some(lu)) => lu_solve(lu, b),
                (None, None) => false,
            },
            Factor::Chol => {
                chol_solve::<N>(&t.l, n, b);
                true
            }
            Factor::Lu(lu) => lu_solve(lu, b),
            Factor::Stale | Factor::Singular => false,
        }
    }
}

/// Advance seed `j` over its pending sub-steps (`powers` from
/// [`Integrator::linear_powers`]).
fn flush_seed(powers: &[f64], n: usize, j: usize, sw: &mut SensWork) {
    // SAFETY: each copy runs only where the CPU has its features
    // (detected at run time by `dense::lanes`)
    #[cfg(target_arch = "x86_64")]
    match super::dense::lanes() {
        Lanes::Eight => return unsafe { flush_seed_avx512(powers, n, j, sw) },
        Lanes::Four => return unsafe { flush_seed_avx2(powers, n, j, sw) },
        Lanes::Two => {}
    }
    flush_seed_body(powers, n, j, sw)
}

/// [`flush_seed`] compiled for AVX2 (the same bits; see
/// [`super::dense::Lanes`]).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn flush_seed_avx2(powers: &[f64], n: usize, j: usize, sw: &mut SensWork) {
    flush_seed_body(powers, n, j, sw)
}

/// [`flush_seed`] compiled for AVX-512 (the same bits).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,avx512f")]
fn flush_seed_avx512(powers: &[f64], n: usize, j: usize, sw: &mut SensWork) {
    flush_seed_body(powers, n, j, sw)
}

#[inline(always)]
fn flush_seed_body(powers: &[f64], n: usize, j: usize, sw: &mut SensWork) {
    let c = sw.pending[j];
    if c == 0 {
        return;
    }
    sw.pending[j] = 0;
    let m3 = 3 * n;
    let pw = &powers[(c - 1) * m3 * m3..c * m3 * m3];
    gather(sw, j, n);
    let y = &mut sw.y3;
    mat_vec(pw, &sw.one[..m3], &mut y[..m3]);
    sw.one.copy_from_slice(y);
    scatter(sw, j, n);
}

/// Seed `j`'s `(δu, δv, δa)` into `sw.one`.
#[inline(always)]
fn gather(sw: &mut SensWork, j: usize, n: usize) {
    let s = sw.s;
    for i in 0..n {
        sw.one[i] = sw.du[i * s + j];
        sw.one[n + i] = sw.dv[i * s + j];
        sw.one[2 * n + i] = sw.da[i * s + j];
    }
}

/// `sw.one` back into seed `j`'s `(δu, δv, δa)`.
#[inline(always)]
fn scatter(sw: &mut SensWork, j: usize, n: usize) {
    let s = sw.s;
    for i in 0..n {
        sw.du[i * s + j] = sw.one[i];
        sw.dv[i * s + j] = sw.one[n + i];
        sw.da[i * s + j] = sw.one[2 * n + i];
    }
}

/// The seeds `cols` of arrays in the seed-minor layout of [`SensWork`]
/// (`s` seeds per DOF row): [`Rows::of`] is DOF `i`'s part.
struct Rows {
    s: usize,
    cols: Range<usize>,
}

impl Rows {
    /// The indices of DOF `i` of the seeds.
    #[inline(always)]
    fn of(&self, i: usize) -> Range<usize> {
        i * self.s + self.cols.start..i * self.s + self.cols.end
    }

    /// `Y += σ A X` (`A` column-major `n × n`; `row`: scratch of `s`): for
    /// every seed the operations of [`mat_vec_axpy`] in its order. Zero
    /// entries of `A` are skipped (a structural zero adds nothing).
    #[inline(always)]
    fn mat_axpy<const N: usize>(
        &self,
        a: &[f64],
        n: usize,
        x: &[f64],
        sigma: f64,
        y: &mut [f64],
        row: &mut [f64],
    ) {
        let n = dim::<N>(n);
        let row = &mut row[..self.cols.len()];
        for k in 0..n {
            let xk = &x[self.of(k)];
            row.iter_mut().zip(xk).for_each(|(r, &x)| *r = sigma * x);
            for i in 0..n {
                let aik = a[k * n + i];
                if aik == 0.0 {
                    continue;
                }
                let yi = &mut y[self.of(i)];
                for (y, &x) in yi.iter_mut().zip(row.iter()) {
                    *y += aik * x;
                }
            }
        }
    }

    /// A pair element's slope product: `y_i += c (x_i − x_j)`, `y_j −= c
    /// (x_i − x_j)` (`x_i` alone to ground), as
    /// [`elements::Element::add_slope_product`] computes it.
    #[inline(always)]
    fn pair_axpy(&self, (i, j): (usize, Option<usize>), c: f64, x: &[f64], y: &mut [f64]) {
        let (ri, xi) = (self.of(i), &x[self.of(i)]);
        match j {
            Some(j) => {
                let xj = &x[self.of(j)];
                for (c0, ((&a, &b), k)) in xi.iter().zip(xj).zip(ri).enumerate() {
                    let t = c * (a - b);
                    y[k] += t;
                    y[j * self.s + self.cols.start + c0] -= t;
                }
            }
            None => {
                for (yi, &a) in y[ri].iter_mut().zip(xi) {
                    *yi += c * a;
                }
            }
        }
    }

    /// [`chol_solve`] of every seed of `b`, each by the same operations in
    /// the same order (the row index also places the rows of `b`).
    #[inline(always)]
    #[allow(clippy::needless_range_loop)]
    fn chol_solve<const N: usize>(&self, l: &[f64], n: usize, b: &mut [f64]) {
        let n = dim::<N>(n);
        let l = &l[..n * n];
        let w = self.cols.len();
        for j in 0..n {
            let col = &l[j * n..(j + 1) * n];
            let (head, tail) = b.split_at_mut((j + 1) * self.s);
            let bj = &mut head[self.of(j)];
            bj.iter_mut().for_each(|y| *y *= col[j]);
            for i in (j + 1)..n {
                let o = (i - j - 1) * self.s + self.cols.start;
                for (x, &y) in tail[o..o + w].iter_mut().zip(bj.iter()) {
                    *x -= col[i] * y;
                }
            }
        }
        for i in (0..n).rev() {
            let col = &l[i * n..(i + 1) * n];
            let (head, tail) = b.split_at_mut((i + 1) * self.s);
            let bi = &mut head[self.of(i)];
            for k in (i + 1)..n {
                let o = (k - i - 1) * self.s + self.cols.start;
                for (x, &y) in bi.iter_mut().zip(&tail[o..o + w]) {
                    *x -= col[k] * y;
                }
            }
            bi.iter_mut().for_each(|x| *x *= col[i]);
        }
    }
}

/// Every seed advanced over its pending sub-steps.
#[inline(always)]
fn flush_all(powers: Option<&[f64]>, n: usize, sw: &mut SensWork) {
    if let Some(pw) = powers {
        for j in 0..sw.s {
            if sw.pending[j] != 0 {
                flush_seed(pw, n, j, sw);
            }
        }
    }
}

impl SensWork {
    fn new(integ: &Integrator, s: usize, np: usize) -> SensWork {
        let n = integ.n;
        let z = |k: usize| vec![0.0; k];
        let j0_lu = if integ.j0_chol.is_none() {
            let lu = integ.j0.clone().lu();
            lu.is_invertible().then(|| Box::new(lu))
        } else {
            None
        };
        SensWork {
            s,
            du: z(n * s),
            dv: z(n * s),
            da: z(n * s),
            dg: z(n * s),
            dz: z(n),
            dw: z(n),
            rhs: z(n),
            one: z(3 * n),
            row: z(s),
            all_z: z(n * s),
            all_w: z(n * s),
            all_rhs: z(n * s),
            pending: vec![0; s],
            y3: z(3 * n),
            q: z(n * np),
            p: z(n * np),
            q_act: z(n * np),
            eff: z(integ.elements.len()),
            closed: vec![None; integ.elements.len()],
            side_steps: 0,
            slopes0: z(integ.elements.len()),
            tangent: TangentFactor {
                factor: Factor::Stale,
                l: z(n * n),
                full: z(n * n),
                slopes: z(integ.elements.len()),
                j0_lu,
                count: 0,
            },
            singular_at: None,
        }
    }
}

/// The derivative matrices being filled.
struct SensOutputs {
    n: usize,
    du: Vec<DMatrix<f64>>,
    dv: Vec<DMatrix<f64>>,
    da: Vec<DMatrix<f64>>,
}

impl SensOutputs {
    fn new(n: usize, ns: usize, s: usize) -> SensOutputs {
        let z = || (0..s).map(|_| DMatrix::zeros(n, ns)).collect::<Vec<_>>();
        SensOutputs {
            n,
            du: z(),
            dv: z(),
            da: z(),
        }
    }

    fn store(&mut self, sw: &SensWork, k: usize) {
        let (n, s) = (self.n, sw.s);
        for j in 0..s {
            for (out, src) in [
                (&mut self.du[j], &sw.du),
                (&mut self.dv[j], &sw.dv),
                (&mut self.da[j], &sw.da),
            ] {
                let col = &mut out.as_mut_slice()[k * n..(k + 1) * n];
                for (i, x) in col.iter_mut().enumerate() {
                    *x = src[i * s + j];
                }
            }
        }
    }

    fn finish(self, done: usize, sw: &SensWork) -> Sensitivities {
        let cut = |v: Vec<DMatrix<f64>>| -> Vec<DMatrix<f64>> {
            v.into_iter()
                .map(|m| {
                    if m.ncols() > done {
                        m.columns(0, done).into_owned()
                    } else {
                        m
                    }
                })
                .collect()
        };
        Sensitivities {
            du: cut(self.du),
            dv: cut(self.dv),
            da: cut(self.da),
            factorizations: sw.tangent.count,
            newton_side_steps: sw.side_steps,
            singular_tangent: sw.singular_at,
        }
    }
}

#[cfg(test)]
mod tests;
