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
//! guards the non-smooth contact law. A sub-step that follows one where no
//! element was active starts from the linear step's solution `J_0⁻¹ b`
//! rather than the predictor: while the elements stay inactive that is the
//! answer, and one residual evaluation confirms it.

use crate::error::{Result, TacitError};
use crate::model::elements::{self, Element};
use crate::model::Model;
use nalgebra::{DMatrix, DMatrixView};

mod dense;
mod sensitivity;
mod stability;
#[cfg(target_arch = "x86_64")]
use dense::Lanes;
use dense::{chol_solve, cholesky_in_place, dim, lu_solve, mat_vec_axpy, max_abs};
pub use sensitivity::{ElementSeed, ParamSeed, Seeds, Sensitivities, Tape};
use serde::Serialize;
pub use stability::{Divergence, MAX_SUBSTEPS};

/// Newton tolerance relative to the step's physical forces (external and
/// inertial, the elements'), where it is tighter than the settings'
/// `newton_tol` relative to `max(‖J0 u‖∞, ‖b‖∞)` (see
/// `Integrator::residual`): an acceleration error below 1e-6 of the
/// forces.
const FORCE_TOLERANCE: f64 = 1e-6;

/// Share of `max(‖J0 u‖∞, ‖b‖∞)` below which the Newton residual is
/// accepted whatever the tolerance (see `Integrator::residual`): the
/// residual's rounding is a few `n ε` of it.
const ROUNDING_FLOOR: f64 = 1e-13;

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
    /// M's diagonal when M is diagonal (lumped masses): `M z` in n products.
    m_diag: Option<Vec<f64>>,
    /// `‖M‖∞` (largest absolute row sum): `‖M a‖∞ ≤ ‖M‖∞ ‖a‖∞` bounds the
    /// inertial force of the Newton tolerance's scale in n operations.
    m_norm: f64,
    /// Powers of the sub-step map of a derivative when no element is
    /// active (taken on first use by the sensitivities from the cache of
    /// integrators with the same linear part; see
    /// `sensitivity::linear_powers`).
    linear_powers: std::sync::OnceLock<Option<std::sync::Arc<Vec<f64>>>>,
    /// Indices of the contacts among the elements.
    contacts: Vec<usize>,
    /// C = 0 (undamped): the sensitivities skip its products.
    c_zero: bool,
    /// The affine map of a whole sample without an active element (taken
    /// on first use from the cache of integrators with the same linear part
    /// and contact pairs; see [`SampleMap`]).
    sample_map: std::sync::OnceLock<Option<std::sync::Arc<SampleMap>>>,
    /// Gaps of the contacts, in element order.
    contact_gaps: Vec<f64>,
    /// Batch the sub-steps without an active element (off only to test
    /// the batching against the plain recursion).
    batch_linear: bool,
    /// Some element carries a state (a Jenkins element's slip), committed
    /// at every accepted sub-step.
    stateful: bool,
}

/// The state after a whole sample as an affine function of the state at
/// its start and the force at its two ends, when no element is active in
/// any of its sub-steps (α = 0, every element a contact): each sub-step is
/// then `u_{n+1} = J_0⁻¹ b_n`, linear in the inputs. A sample is taken in
/// one product when every contact's relative displacement, evaluated by
/// the same map after each sub-step, stays at or below its gap; otherwise
/// it is sub-stepped as usual.
#[derive(Debug, Clone)]
struct SampleMap {
    /// `(u, v, a)` after the sample: `3n × 5n`, column-major, from the
    /// inputs `(u, v, a, f_prev, f_next)`.
    full: Vec<f64>,
    /// Per contact (in element order): its relative displacement after
    /// each sub-step of the sample as `S` coefficients per input, `5n`
    /// such columns (the gaps are the integrator's: the map does not
    /// depend on them), so that every sub-step's sum advances at once.
    contacts: Vec<Vec<f64>>,
}

/// Recently built linear operators ([`SampleMap`], the derivative powers
/// of `sensitivity::linear_powers`), shared by integrators whose inactive
/// sub-step is the same (the same M, C, K, sub-step and contact pairs: a
/// fit of contact or friction parameters builds a new integrator at every
/// trial, with the same linear part). A hit returns what the build would
/// compute, bit for bit.
pub(crate) struct OperatorCache<T> {
    entries: std::sync::Mutex<Vec<(Vec<u64>, std::sync::Arc<T>)>>,
}

/// Entries kept by an [`OperatorCache`].
const CACHE_ENTRIES: usize = 8;

impl<T> OperatorCache<T> {
    pub(crate) const fn new() -> Self {
        OperatorCache {
            entries: std::sync::Mutex::new(Vec::new()),
        }
    }

    /// The entry for `key`, built by `build` when absent (None: nothing is
    /// cached).
    pub(crate) fn get_or_build(
        &self,
        key: Vec<u64>,
        build: impl FnOnce() -> Option<T>,
    ) -> Option<std::sync::Arc<T>> {
        {
            let mut e = self.entries.lock().unwrap_or_else(|p| p.into_inner());
            if let Some(i) = e.iter().position(|(k, _)| *k == key) {
                let hit = e.remove(i);
                let value = hit.1.clone();
                e.push(hit);
                return Some(value);
            }
        }
        let value = std::sync::Arc::new(build()?);
        let mut e = self.entries.lock().unwrap_or_else(|p| p.into_inner());
        if !e.iter().any(|(k, _)| *k == key) {
            if e.len() >= CACHE_ENTRIES {
                e.remove(0);
            }
            e.push((key, value.clone()));
        }
        Some(value)
    }
}

static SAMPLE_MAPS: OperatorCache<SampleMap> = OperatorCache::new();

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
        let j0_chol = if cholesky_in_place::<0>(&mut buf, n) {
            Some(buf)
        } else {
            None
        };
        let is_diag = m
            .iter()
            .enumerate()
            .all(|(i, &x)| i % n == i / n || x == 0.0);
        let m_diag = is_diag.then(|| m.diagonal().as_slice().to_vec());
        let m_norm = (0..n)
            .map(|i| m.row(i).iter().map(|x| x.abs()).sum::<f64>())
            .fold(0.0, f64::max);
        let contacts = (0..elements.len())
            .filter(|&e| matches!(elements[e], Element::Contact { .. }))
            .collect();
        let c_zero = c.iter().all(|&x| x == 0.0);
        let stateful = elements.iter().any(Element::has_state);
        let contact_gaps = elements
            .iter()
            .filter_map(|e| match *e {
                Element::Contact { gap, .. } => Some(gap),
                _ => None,
            })
            .collect();
        Ok(Integrator {
            contact_gaps,
            n,
            m_diag,
            m_norm,
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
            linear_powers: std::sync::OnceLock::new(),
            contacts,
            c_zero,
            sample_map: std::sync::OnceLock::new(),
            batch_linear: true,
            stateful,
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
        self.run_sized(force, u0, v0, None)
    }

    /// [`Integrator::run`] with the kernels' size chosen, recording into
    /// `tape` when given ([`Integrator::run_taped`]).
    pub(super) fn run_sized(
        &self,
        force: DMatrixView<'_, f64>,
        u0: &[f64],
        v0: &[f64],
        tape: Option<&mut Tape>,
    ) -> Simulation {
        // sizes up to 8 get kernels unrolled at compile time (same bits)
        match self.n {
            1 => self.run_n::<1>(force, u0, v0, tape),
            2 => self.run_n::<2>(force, u0, v0, tape),
            3 => self.run_n::<3>(force, u0, v0, tape),
            4 => self.run_n::<4>(force, u0, v0, tape),
            5 => self.run_n::<5>(force, u0, v0, tape),
            6 => self.run_n::<6>(force, u0, v0, tape),
            7 => self.run_n::<7>(force, u0, v0, tape),
            8 => self.run_n::<8>(force, u0, v0, tape),
            _ => self.run_n::<0>(force, u0, v0, tape),
        }
    }

    /// [`Integrator::run`] with the kernels' size `N` (0: run-time size).
    fn run_n<const N: usize>(
        &self,
        force: DMatrixView<'_, f64>,
        u0: &[f64],
        v0: &[f64],
        mut tape: Option<&mut Tape>,
    ) -> Simulation {
        let n = self.n;
        let ns = force.ncols();
        let mut out = Outputs::new(n, ns);
        let mut ws = Work::new(n, self.elements.len());
        let map = self.sample_map();
        ws.u.copy_from_slice(&u0[..n]);
        ws.v.copy_from_slice(&v0[..n]);
        let mut status = SimStatus::Completed;
        let (mut steps, mut iters, mut done) = (0, 0, 0usize);
        if ns > 0 {
            if !self.initial_acceleration(force, &mut ws) {
                return Outputs::new(n, 0).finish(
                    SimStatus::NonFinite {
                        time: 0.0,
                        sample: 0,
                    },
                    0,
                    0,
                );
            }
            out.store(&ws, 0);
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
            let whole = self.whole_sample(map, &mut ws, k);
            if let Some(t) = tape.as_deref_mut() {
                t.sample(whole.is_some());
            }
            if whole.is_some() {
                steps += self.settings.substeps;
                iters += self.settings.substeps;
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
                if let Some(t) = tape.as_deref_mut() {
                    t.substep(&ws);
                }
                if self.alpha != 0.0 {
                    self.g_of::<N>(&mut ws);
                }
            }
            elements::internal_force_at(&self.elements, &ws.u, &ws.v, &ws.slips, &mut ws.fnl);
            out.store(&ws, k);
            done = k + 1;
        }
        if let Some(t) = tape {
            t.finish(done);
        }
        out.truncate(done);
        out.finish(status, steps, iters)
    }

    fn fs(&self) -> f64 {
        1.0 / (self.h * self.settings.substeps as f64)
    }

    /// Initial acceleration from equilibrium, `M a = f − C v − K u − f_int`;
    /// false when M is not positive definite.
    fn initial_acceleration(&self, force: DMatrixView<'_, f64>, ws: &mut Work) -> bool {
        let n = self.n;
        // the force, and the slopes the first sub-step starts from
        ws.fnl.fill(0.0);
        for (e, s) in self.elements.iter().zip(ws.slopes.iter_mut()) {
            *s = e.force_and_slope(&ws.u, &ws.v, &mut ws.fnl);
        }
        for i in 0..n {
            ws.rhs[i] = force[(i, 0)] - ws.fnl[i];
        }
        mat_vec_axpy::<0>(self.c.as_slice(), n, &ws.v, -1.0, &mut ws.rhs);
        mat_vec_axpy::<0>(self.k.as_slice(), n, &ws.u, -1.0, &mut ws.rhs);
        match self.m.clone().cholesky() {
            Some(ch) => {
                let x = ch.solve(&nalgebra::DVector::from_column_slice(&ws.rhs));
                ws.a.copy_from_slice(x.as_slice());
                true
            }
            None => false,
        }
    }

    /// One sub-step (number `sub` within the sample) from `ws.u, v, a`, the
    /// force interpolated between `ws.f_prev` and `ws.f_next`; the state is
    /// advanced in place. Ok(Newton iterations) or Err((iterations, residual)).
    fn advance<const N: usize>(
        &self,
        ws: &mut Work,
        sub: usize,
    ) -> std::result::Result<usize, (usize, f64)> {
        // SAFETY: each copy runs only where the CPU has its features
        // (detected at run time by `dense::lanes`)
        #[cfg(target_arch = "x86_64")]
        match dense::lanes() {
            Lanes::Eight => return unsafe { self.advance_avx512::<N>(ws, sub) },
            Lanes::Four => return unsafe { self.advance_avx2::<N>(ws, sub) },
            Lanes::Two => {}
        }
        self.advance_body::<N>(ws, sub)
    }

    /// [`Integrator::advance`] compiled for AVX2 (the same operations in
    /// the same order, so the same bits; see [`dense::Lanes`]).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn advance_avx2<const N: usize>(
        &self,
        ws: &mut Work,
        sub: usize,
    ) -> std::result::Result<usize, (usize, f64)> {
        self.advance_body::<N>(ws, sub)
    }

    /// [`Integrator::advance`] compiled for AVX-512 (the same bits).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,avx512f")]
    fn advance_avx512<const N: usize>(
        &self,
        ws: &mut Work,
        sub: usize,
    ) -> std::result::Result<usize, (usize, f64)> {
        self.advance_body::<N>(ws, sub)
    }

    #[inline(always)]
    fn advance_body<const N: usize>(
        &self,
        ws: &mut Work,
        sub: usize,
    ) -> std::result::Result<usize, (usize, f64)> {
        let a1 = self.gamma / (self.beta * self.h);
        self.step_setup::<N>(ws, sub);
        let it = self.newton::<N>(ws, a1)?;
        self.accept::<N>(ws);
        Ok(it)
    }

    /// The state from the sub-step's solution `ws.un` and its affine parts:
    /// `a = a_0 u + z`, `v = a_1 u + w`.
    #[inline(always)]
    fn accept<const N: usize>(&self, ws: &mut Work) {
        let n = dim::<N>(self.n);
        let (h, gamma, beta) = (self.h, self.gamma, self.beta);
        let (a0, a1) = (1.0 / (beta * h * h), gamma / (beta * h));
        let (u, v, a) = (&mut ws.u[..n], &mut ws.v[..n], &mut ws.a[..n]);
        for i in 0..n {
            let un = ws.un[i];
            a[i] = a0 * un + ws.z[i];
            v[i] = a1 * un + ws.w[i];
            u[i] = un;
        }
        // the Jenkins elements' slips committed at the accepted point
        if self.stateful {
            for (e, z) in self.elements.iter().zip(ws.slips.iter_mut()) {
                *z = e.committed_slip(&ws.u, *z);
            }
        }
    }

    /// Sample `k` (forces in `ws.f_prev`, `ws.f_next`) taken whole by the
    /// sample map when it applies ([`Integrator::batch_sample`]): Some(Ok)
    /// when taken, Some(Err(status)) when the state became non-finite, None
    /// when it is to be sub-stepped.
    fn whole_sample(
        &self,
        map: Option<&SampleMap>,
        ws: &mut Work,
        k: usize,
    ) -> Option<std::result::Result<(), SimStatus>> {
        if !map.is_some_and(|m| self.batch_sample(m, ws)) {
            return None;
        }
        Some(if ws.finite() {
            Ok(())
        } else {
            Err(SimStatus::NonFinite {
                time: k as f64 / self.fs(),
                sample: k - 1,
            })
        })
    }

    /// The sample map, if this integrator has one ([`SampleMap`]).
    fn sample_map(&self) -> Option<&SampleMap> {
        self.sample_map
            .get_or_init(|| {
                if !self.batches() {
                    return None;
                }
                // every element a contact: their DOF pairs
                let pairs = self
                    .elements
                    .iter()
                    .map(|e| match *e {
                        Element::Contact { i, j, .. } => Some((i, j)),
                        _ => None,
                    })
                    .collect::<Option<Vec<_>>>()?;
                let mut key = self.linear_key();
                for &(i, j) in &pairs {
                    key.extend([i as u64, j.map_or(u64::MAX, |j| j as u64)]);
                }
                SAMPLE_MAPS.get_or_build(key, || self.build_sample_map(&pairs))
            })
            .as_deref()
    }

    /// Sub-steps without an active element are batched (the sample map,
    /// the derivative powers): α = 0, `J_0` factored, batching on.
    pub(super) fn batches(&self) -> bool {
        self.alpha == 0.0 && self.j0_chol.is_some() && self.batch_linear
    }

    /// Everything the sub-step without an active element reads, as bits:
    /// two integrators with the same key step alike while no element acts.
    pub(crate) fn linear_key(&self) -> Vec<u64> {
        let mut key = vec![
            self.n as u64,
            self.settings.substeps as u64,
            self.h.to_bits(),
            self.alpha.to_bits(),
            self.gamma.to_bits(),
            self.beta.to_bits(),
        ];
        for m in [&self.m, &self.c, &self.k] {
            key.extend(m.iter().map(|x| x.to_bits()));
        }
        key
    }

    /// The sample map of an integrator whose elements are the contacts
    /// between the DOF pairs `contacts`.
    fn build_sample_map(&self, contacts: &[(usize, Option<usize>)]) -> Option<SampleMap> {
        let l = self.j0_chol.as_ref()?;
        let (n, s) = (self.n, self.settings.substeps);
        let (m3, m5) = (3 * n, 5 * n);
        let mut full = vec![0.0; m3 * m5];
        let mut deltas = vec![vec![0.0; s * m5]; contacts.len()];
        let mut ws = Work::new(n, self.elements.len());
        for col in 0..m5 {
            for v in [
                &mut ws.u,
                &mut ws.v,
                &mut ws.a,
                &mut ws.f_prev,
                &mut ws.f_next,
            ] {
                v.fill(0.0);
            }
            let unit = match col / n {
                0 => &mut ws.u,
                1 => &mut ws.v,
                2 => &mut ws.a,
                3 => &mut ws.f_prev,
                _ => &mut ws.f_next,
            };
            unit[col % n] = 1.0;
            for sub in 0..s {
                // the sub-step of Integrator::advance with every
                // element inactive: Newton's answer J0⁻¹ b
                self.step_setup::<0>(&mut ws, sub);
                ws.un.copy_from_slice(&ws.b);
                chol_solve::<0>(l, n, &mut ws.un);
                self.accept::<0>(&mut ws);
                for (&(i, j), d) in contacts.iter().zip(deltas.iter_mut()) {
                    d[sub * m5 + col] = ws.u[i] - j.map_or(0.0, |j| ws.u[j]);
                }
            }
            let out = &mut full[col * m3..(col + 1) * m3];
            out[..n].copy_from_slice(&ws.u);
            out[n..2 * n].copy_from_slice(&ws.v);
            out[2 * n..].copy_from_slice(&ws.a);
        }
        // by input: sub-step `sub` of input `col` at `col S + sub`
        let contacts = deltas
            .iter()
            .map(|d| {
                let mut t = vec![0.0; s * m5];
                for (sub, row) in d.chunks_exact(m5).enumerate() {
                    for (col, &c) in row.iter().enumerate() {
                        t[col * s + sub] = c;
                    }
                }
                t
            })
            .collect();
        Some(SampleMap { full, contacts })
    }

    /// Take the whole sample (forces in `ws.f_prev`, `ws.f_next`) by the
    /// sample map when no element is active at its start nor after any of
    /// its sub-steps; false (`ws` untouched) otherwise.
    fn batch_sample(&self, map: &SampleMap, ws: &mut Work) -> bool {
        if ws.slopes.iter().any(|&s| s != 0.0) {
            return false;
        }
        let n = self.n;
        let x = &mut ws.x5;
        for (q, v) in [&ws.u, &ws.v, &ws.a, &ws.f_prev, &ws.f_next]
            .iter()
            .enumerate()
        {
            x[q * n..(q + 1) * n].copy_from_slice(&v[..n]);
        }
        // each sub-step's relative displacement Σ_c r_c x_c, summed in the
        // order of the inputs for all sub-steps at once (only compared)
        let s = self.settings.substeps;
        ws.dist.resize(s, 0.0);
        for (cols, &gap) in map.contacts.iter().zip(&self.contact_gaps) {
            let d = &mut ws.dist[..s];
            d.fill(-0.0);
            for (col, &xc) in cols.chunks_exact(s).zip(x.iter()) {
                for (di, &r) in d.iter_mut().zip(col) {
                    *di += r * xc;
                }
            }
            if !d.iter().all(|&d| d <= gap) {
                return false;
            }
        }
        let y = &mut ws.y3;
        dense::mat_vec(&map.full, &x[..5 * n], &mut y[..3 * n]);
        ws.u.copy_from_slice(&y[..n]);
        ws.v.copy_from_slice(&y[n..2 * n]);
        ws.a.copy_from_slice(&y[2 * n..]);
        ws.dir_slopes.fill(0.0);
        ws.iterated = true;
        true
    }

    /// The sub-step's affine parts `ws.z, w`, right-hand side `ws.b` and
    /// predictor `ws.un`.
    #[inline(always)]
    fn step_setup<const N: usize>(&self, ws: &mut Work, sub: usize) {
        let n = dim::<N>(self.n);
        let (h, alpha, gamma, beta) = (self.h, self.alpha, self.gamma, self.beta);
        let (a0, a2, a3) = (1.0 / (beta * h * h), 1.0 / (beta * h), 0.5 / beta - 1.0);
        let (u, v, a) = (&ws.u[..n], &ws.v[..n], &ws.a[..n]);
        let (z, w, b) = (&mut ws.z[..n], &mut ws.w[..n], &mut ws.b[..n]);
        // force at t_n + (1+α) h, linear between samples k-1 and k
        let frac = ((sub as f64) + 1.0 + alpha) / self.settings.substeps as f64;
        for ((bi, fp), fnx) in b.iter_mut().zip(&ws.f_prev).zip(&ws.f_next) {
            *bi = fp * (1.0 - frac) + fnx * frac;
        }
        ws.force_scale = max_abs::<N>(0.0, b, n).max(self.m_norm * max_abs::<N>(0.0, a, n));
        // affine parts: a = a0 u + z, v = a1 u + w
        for i in 0..n {
            z[i] = -a0 * u[i] - a2 * v[i] - a3 * a[i];
            w[i] = v[i] + h * (1.0 - gamma) * a[i] + h * gamma * z[i];
        }
        // b = f_t − M z − (1+α) C w + α g_n
        match &self.m_diag {
            // the same sums as the product below, without its zero terms
            Some(m) => (0..n).for_each(|i| b[i] += m[i] * -z[i]),
            None => mat_vec_axpy::<N>(self.m.as_slice(), n, z, -1.0, b),
        }
        mat_vec_axpy::<N>(self.c.as_slice(), n, w, -(1.0 + alpha), b);
        if alpha != 0.0 {
            for (bi, gi) in b.iter_mut().zip(&ws.g) {
                *bi += alpha * gi;
            }
        }
        // predictor
        let un = &mut ws.un[..n];
        for i in 0..n {
            un[i] = u[i] + h * v[i] + 0.5 * h * h * a[i];
        }
    }

    /// g = C v + K u + f_int(u, v) at the current state (HHT only).
    fn g_of<const N: usize>(&self, ws: &mut Work) {
        elements::internal_force_at(&self.elements, &ws.u, &ws.v, &ws.slips, &mut ws.g);
        mat_vec_axpy::<N>(self.c.as_slice(), self.n, &ws.v, 1.0, &mut ws.g);
        mat_vec_axpy::<N>(self.k.as_slice(), self.n, &ws.u, 1.0, &mut ws.g);
    }

    /// Residual r(u) = J0 u − b + (1+α) f_int(u, a1 u + w) into ws.r, the
    /// element slopes into ws.slopes; returns (‖r‖∞, scale).
    #[inline(always)]
    fn residual<const N: usize>(&self, ws: &mut Work, a1: f64) -> (f64, f64) {
        let n = dim::<N>(self.n);
        let c1 = 1.0 + self.alpha;
        let (r, b, un) = (&mut ws.r[..n], &ws.b[..n], &ws.un[..n]);
        r.fill(0.0);
        mat_vec_axpy::<N>(self.j0.as_slice(), n, un, 1.0, r);
        let inertial = max_abs::<N>(max_abs::<N>(0.0, r, n), b, n);
        for i in 0..n {
            r[i] -= b[i];
        }
        let mut elements = 0.0;
        if !self.elements.is_empty() {
            let (vn, fnl) = (&mut ws.vn[..n], &mut ws.fnl[..n]);
            for i in 0..n {
                vn[i] = a1 * un[i] + ws.w[i];
            }
            fnl.fill(0.0);
            let slopes = ws.slopes.iter_mut().zip(&ws.slips);
            for (e, (s, &z)) in self.elements.iter().zip(slopes) {
                *s = e.force_and_slope_at(un, vn, z, fnl);
            }
            // c1 > 0: max |c1 f| = c1 max |f| (rounding is monotone)
            elements = c1 * max_abs::<N>(0.0, fnl, n);
            for i in 0..n {
                r[i] += c1 * fnl[i];
            }
        }
        let norm = max_abs::<N>(0.0, r, n);
        let physical = ws.force_scale.max(elements);
        (norm, self.tolerance_scale(inertial.max(elements), physical))
    }

    /// The scale of the Newton tolerance: `max(‖J0 u‖∞, ‖b‖∞, ‖c1 f‖∞)`
    /// (`inertial`, the elements' forces included), or where tighter the
    /// step's physical forces (`physical`: external, inertial, the
    /// elements') at [`FORCE_TOLERANCE`]. `J0 u` and `b` hold
    /// `M u / (β h²)`, which grows with the displacement (a rigid-body
    /// drift) and as 1/h²: a tolerance on them alone left an acceleration
    /// error of `tol ‖u‖ / (β h²)` at fine sub-steps. Their rounding
    /// remains a floor ([`ROUNDING_FLOOR`]).
    #[inline(always)]
    fn tolerance_scale(&self, inertial: f64, physical: f64) -> f64 {
        let tol = self.settings.newton_tol;
        let physical = (FORCE_TOLERANCE / tol) * physical;
        inertial
            .min(physical)
            .max((ROUNDING_FLOOR / tol) * inertial)
    }

    /// Newton iterations on ws.un; Ok(iterations) or Err((iterations, residual)).
    /// `ws.iterated` says whether a Newton step was taken and
    /// `ws.dir_slopes` holds the slopes of the last step's matrix (for the
    /// side check below and the sensitivities).
    ///
    /// A point whose residual is within the tolerance is accepted unless a
    /// contact lies on the other side of its switch than the matrix that
    /// produced the point (a penetration below `tol · scale / k_c`): then
    /// up to [`SIDE_STEPS`] more steps are taken from there, with the
    /// matrix of the side the point is on, so the accepted point solves
    /// the law of its own side and the computed trajectory stays a
    /// continuous function of the start and the parameters (accepting
    /// across the switch makes it jump where a perturbation moves the
    /// penetration out of the tolerance band; differences of the cost then
    /// disagree with the derivatives by percents).
    #[inline(always)]
    fn newton<const N: usize>(
        &self,
        ws: &mut Work,
        a1: f64,
    ) -> std::result::Result<usize, (usize, f64)> {
        let n = dim::<N>(self.n);
        let tol = self.settings.newton_tol;
        if self.elements.is_empty() {
            if let Some(l) = &self.j0_chol {
                ws.un.copy_from_slice(&ws.b);
                chol_solve::<N>(l, n, &mut ws.un);
                return Ok(1);
            }
        }
        let mut it = 0;
        ws.iterated = false;
        // no element was active at the last accepted point: start from the
        // linear step's solution J0⁻¹ b (one Newton step from anywhere with
        // the open matrix), which is the answer while they stay inactive
        if let (Some(l), false) = (&self.j0_chol, ws.slopes.iter().any(|&s| s != 0.0)) {
            ws.un.copy_from_slice(&ws.b);
            chol_solve::<N>(l, n, &mut ws.un);
            it = 1;
            ws.dir_slopes.fill(0.0);
            ws.iterated = true;
        }
        let (mut rn, mut scale) = self.residual::<N>(ws, a1);
        let mut side_steps = 0;
        loop {
            let converged = rn <= tol * scale || rn == 0.0;
            if converged {
                if side_steps >= SIDE_STEPS || !(ws.iterated && self.across_switch(ws)) {
                    break;
                }
                side_steps += 1;
            }
            if it >= self.settings.max_newton || !rn.is_finite() {
                if converged {
                    break;
                }
                return Err((it, rn));
            }
            it += 1;
            ws.dir_slopes.copy_from_slice(&ws.slopes);
            ws.iterated = true;
            if !self.newton_direction::<N>(ws, a1) {
                return Err((it, rn));
            }
            (rn, scale) = self.line_search::<N>(ws, a1, rn);
        }
        Ok(it.max(1))
    }

    /// True when a contact's side at ws.un (its slope in ws.slopes) differs
    /// from the side of the last Newton matrix (ws.dir_slopes).
    #[inline(always)]
    fn across_switch(&self, ws: &Work) -> bool {
        self.contacts
            .iter()
            .any(|&e| (ws.slopes[e] != 0.0) != (ws.dir_slopes[e] != 0.0))
    }

    /// Newton step ws.du = J⁻¹ r with J = J0 plus the slopes of the last
    /// residual evaluation; false when J is singular. J's factor is kept
    /// in ws.jac and reused while the slopes are unchanged (a closed
    /// contact without friction), so equal matrices give equal factors.
    #[inline(always)]
    fn newton_direction<const N: usize>(&self, ws: &mut Work, a1: f64) -> bool {
        let n = dim::<N>(self.n);
        ws.du.copy_from_slice(&ws.r);
        if let (Some(l), false) = (&self.j0_chol, ws.slopes.iter().any(|&s| s != 0.0)) {
            chol_solve::<N>(l, n, &mut ws.du);
            return true;
        }
        if !(ws.jac_factored && ws.slopes == ws.jac_slopes) {
            self.newton_matrix(ws, a1);
            ws.jac_factored = cholesky_in_place::<N>(&mut ws.jac, n);
            if !ws.jac_factored {
                // not SPD (e.g. a softening cubic): rebuild, solve by LU
                self.newton_matrix(ws, a1);
                return lu_solve(&ws.jac, n, &mut ws.du);
            }
            ws.jac_slopes.copy_from_slice(&ws.slopes);
        }
        chol_solve::<N>(&ws.jac, n, &mut ws.du);
        true
    }

    /// ws.jac = J0 + (1+α)(∂f/∂u + a1 ∂f/∂v) from the slopes in ws.slopes.
    #[inline(always)]
    fn newton_matrix(&self, ws: &mut Work, a1: f64) {
        let c1 = 1.0 + self.alpha;
        ws.jac.copy_from_slice(self.j0.as_slice());
        for (e, &sl) in self.elements.iter().zip(&ws.slopes) {
            e.add_slope(sl, c1, c1 * a1, &mut ws.jac, self.n);
        }
    }

    /// Backtracking line search on ‖r‖∞ along −ws.du from ws.un; leaves the
    /// accepted point in ws.un and returns its (‖r‖∞, scale).
    #[inline(always)]
    fn line_search<const N: usize>(&self, ws: &mut Work, a1: f64, rn: f64) -> (f64, f64) {
        let n = dim::<N>(self.n);
        let tol = self.settings.newton_tol;
        ws.u_old.copy_from_slice(&ws.un);
        let mut lambda = 1.0;
        loop {
            for i in 0..n {
                ws.un[i] = ws.u_old[i] - lambda * ws.du[i];
            }
            let (rn_new, sc) = self.residual::<N>(ws, a1);
            if rn_new < rn || lambda < 1.0 / 64.0 || rn_new <= tol * sc {
                return (rn_new, sc);
            }
            lambda *= 0.5;
        }
    }
}

/// The output matrices (DOF × sample) being filled.
struct Outputs {
    u: DMatrix<f64>,
    v: DMatrix<f64>,
    a: DMatrix<f64>,
    f: DMatrix<f64>,
}

impl Outputs {
    fn new(n: usize, ns: usize) -> Outputs {
        let z = || DMatrix::zeros(n, ns);
        Outputs {
            u: z(),
            v: z(),
            a: z(),
            f: z(),
        }
    }

    fn store(&mut self, ws: &Work, k: usize) {
        self.u.column_mut(k).copy_from_slice(&ws.u);
        self.v.column_mut(k).copy_from_slice(&ws.v);
        self.a.column_mut(k).copy_from_slice(&ws.a);
        self.f.column_mut(k).copy_from_slice(&ws.fnl);
    }

    /// Keep the first `done` samples.
    fn truncate(&mut self, done: usize) {
        if done < self.u.ncols() {
            for m in [&mut self.u, &mut self.v, &mut self.a, &mut self.f] {
                *m = m.columns(0, done).into_owned();
            }
        }
    }

    fn finish(self, status: SimStatus, steps: usize, newton_iterations: usize) -> Simulation {
        Simulation {
            status,
            u: self.u,
            v: self.v,
            a: self.a,
            fint: self.f,
            steps,
            newton_iterations,
        }
    }
}

/// Newton steps taken at most, after the residual is within the
/// tolerance, to bring the accepted point to its own side of a contact's
/// switch ([`Integrator::newton`]).
const SIDE_STEPS: usize = 2;

/// Scratch vectors of one run.
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
    f_prev: Vec<f64>,
    f_next: Vec<f64>,
    fnl: Vec<f64>,
    rhs: Vec<f64>,
    /// The sub-step's physical force scale: `max(‖f_t‖∞, ‖M‖∞ ‖a_n‖∞)`.
    force_scale: f64,
    /// Factor of the last Newton matrix (valid when `jac_factored`) and
    /// the slopes it was built from.
    jac: Vec<f64>,
    jac_factored: bool,
    jac_slopes: Vec<f64>,
    slopes: Vec<f64>,
    /// Slopes of the last Newton step's matrix and whether a step was
    /// taken in the current sub-step (the side check, the sensitivities).
    dir_slopes: Vec<f64>,
    /// Committed internal state of each element (a Jenkins element's
    /// slip, m; 0 for the elements without state).
    slips: Vec<f64>,
    iterated: bool,
    /// Scratch of a batched sample: its inputs (5n) and the new state (3n).
    x5: Vec<f64>,
    y3: Vec<f64>,
    /// Scratch of a batched sample: a contact's relative displacement
    /// after each of its sub-steps.
    dist: Vec<f64>,
}

impl Work {
    /// True while the state is finite.
    fn finite(&self) -> bool {
        self.u.iter().chain(&self.v).all(|x| x.is_finite())
    }

    fn new(n: usize, n_elements: usize) -> Work {
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
            f_prev: z(),
            f_next: z(),
            fnl: z(),
            rhs: z(),
            force_scale: 0.0,
            jac: vec![0.0; n * n],
            jac_factored: false,
            jac_slopes: vec![0.0; n_elements],
            slopes: vec![0.0; n_elements],
            dir_slopes: vec![0.0; n_elements],
            slips: vec![0.0; n_elements],
            iterated: false,
            x5: vec![0.0; 5 * n],
            y3: vec![0.0; 3 * n],
            dist: Vec::new(),
        }
    }
}

#[cfg(test)]
mod element_tests;
#[cfg(test)]
mod tests;
