//! State reconstruction with a sub-sample ("lifted") unknown force.
//!
//! The full-horizon smoother ([`crate::horizon`]) models the unknown force
//! as linear between samples. An impact that lasts less than a sample
//! (the LANL testbed's bumper: about 1 ms at 512 Hz) cannot be written that
//! way, and the states it reconstructs on a contact record are wrong. Here
//! the unknown force is piecewise constant on `R` sub-intervals of every
//! sample interval, `u_k = (f_{k,0}, …, f_{k,R−1}) ∈ ℝ^{nR}`:
//!
//! $$ x_{k+1} = A x_k + \sum_{j<R} G_j f_{k,j} + B_{g0} g_k + B_{g1} g_{k+1},
//!    \qquad y_k = C_y x_k + D_y (g_k + f_{k,0}), $$
//!
//! with `g` the known (measured) force, linear between samples as in
//! [`SampledModel`], and the output at a sample seeing the force of the
//! sub-interval that starts there. `A`, `G_j`, `B_{g0}`, `B_{g1}` are built
//! exactly from the same Newmark integrator: one sub-interval is
//! `SampledModel::new(M, C, K, R f_s, s)` (`A_s`, `B_{0s}`, `B_{1s}`), a force
//! constant over it enters as `B_{0s} + B_{1s}`, and
//! `G_j = A_s^{R−1−j} (B_{0s} + B_{1s})`, `A = A_s^R`. With
//! `s = ⌈S/R⌉` sub-steps per sub-interval (`S` the sub-steps of the sample
//! model); when `R` divides `S`, `A`, `B_{g0}`, `B_{g1}` are exactly the
//! sample model's `A`, `B_0`, `B_1` and `Σ_j G_j = B_0 + B_1`.
//!
//! The states and forces minimise
//!
//! $$ J = \sum_k \|y_k - \hat y_k\|^2_W + \frac{\lambda}{R} \sum_{k,j} \|f_{k,j}\|^2
//!      + \|x_0 - \bar x_0\|^2_{P_0}, $$
//!
//! `W = diag(1/σ_c²)`, `σ_c` = `noise_fraction` × RMS of channel `c`;
//! `P_0 = diag(1/σ_u², 1/σ_v²)` a weak prior with zero mean. The `1/R` makes
//! the prior on the mean force over a sample interval independent of `R`
//! (standard deviation `1/√λ` in units of `W`, as the horizon smoother's λ).
//!
//! **Weight of the force prior.** Along a few located directions
//! ([`reconstruct_floored`]) λ is a floor, not a fixed value: a force at a
//! measured point reaches that point's output within the sample (the
//! feed-through `D_y`), so it can follow the channel's noise, and a weak
//! prior lets it also follow the other channels' noise through the
//! dynamics, with forces the data barely see and states that move with
//! them. How cheap this is depends on the model, not on λ alone: on a
//! membrane whose point load has a displacement growing with the mesh
//! refinement (docs/formats.md) the same λ = 1e-2 leaves a weighted
//! residual of 0.31 of the noise at 1 066 DOFs and 0.18 at 32 361 DOFs,
//! where the force comes out at 1.26 N RMS for a true 0.34 N. The rule
//! asks the data instead (a one-sided discrepancy principle, Morozov
//! 1966): λ is raised by factors of √10 until the quadratic
//! reconstruction leaves at least [`LiftedSettings::min_residual`] (0.5)
//! of the assumed noise — a fit closer than that absorbs more than three
//! quarters of the noise variance with the force; when no weight up to
//! `10^4 λ_0` reaches it (a single channel with the force at its own DOF,
//! as the Silverbox, is fitted exactly whatever λ) λ stays. At 32 361 DOFs this
//! takes λ to 10 (residual 0.54, force 0.343 N RMS, correlation with the
//! true force 0.92 against 0.23); the lumped LANL bumper record (residual
//! 0.74 with sensors 1, 5, 6, 0.94 with all eight) keeps λ = 1e-2.
//!
//! **Solver.** A linear-quadratic regulator with an output feed-through,
//! solved exactly by a backward Riccati sweep and a forward pass — time and
//! memory linear in the record length, blocks of size `2n` and `nR` only.
//! With `P', p'` the cost-to-go `V_{k+1}(x) = xᵀP'x − 2p'ᵀx` and the stage
//! rows `H_x = W^{1/2} C_y`, `H_u = W^{1/2} D_y E_0` (`E_0` picks `f_{k,0}`),
//! target `r_k = W^{1/2}(y_k − D_y g_k)`, `e = p' − P' c_k`:
//!
//! $$ Q_{uu} = H_uᵀH_u + \tfrac{λ}{R} I + GᵀP'G,\quad
//!    Q_{ux} = H_uᵀH_x + GᵀP'A,\quad L = Q_{uu}^{-1} Q_{ux}, $$
//! $$ P = H_xᵀH_x + AᵀP'A − Q_{ux}ᵀ L,\quad
//!    p = (H_x − H_u L)ᵀ r_k + (A − G L)ᵀ e,\quad
//!    l_k = Q_{uu}^{-1}(H_uᵀ r_k + Gᵀ e), $$
//!
//! and `u_k = −L x_k + l_k`. The matrix step is the one of
//! [`crate::riccati::grouped`]: with `Z = [H_u; G]`, `S = diag(I, P')` and
//! `M = Z Λ⁻¹ Zᵀ` (`Λ` the diagonal force weights, equal over the `R`
//! sub-intervals of one force direction, so `M` is a weighted sum of one
//! Gram matrix per direction), the push-through identity
//! `Q_uu⁻¹ Zᵀ = Λ⁻¹ Zᵀ (I + S M)⁻¹` puts every product and solve in size
//! `p + 2n` whatever `R` is, and the forward pass needs per sample only
//! `T_k = (I + S M)⁻¹ S Y` ((p + 2n) × 2n) and `ω_k = (I + S M)⁻¹ [r_k; e]`:
//! `u_k = Λ_k⁻¹ Zᵀ (ω_k − T_k x_k)`. When the gains of the whole record
//! would take more than 32 MB (the F-16 modal model with a force at each
//! of its 9 coordinates: 21 × 18 per sample, 223 MB over 73 728 samples),
//! the backward pass keeps `P` every `K = ⌈√N⌉` samples instead and the
//! forward pass recomputes the gains of one block at a time from the `P`
//! at its end (the same steps, so the same gains): one more matrix step
//! per sample, memory `O(√N)` matrices besides the `O(N)` data and
//! estimates. `P` does not depend on the data: once it stops
//! changing the steady gains are used, so a sample costs a few
//! matrix–vector products. States the outputs never see (the unobservable
//! subspace `N` of `(A, C_y)`: a free-free model's rigid-body displacement
//! and velocity under acceleration data) cost nothing from any sample on,
//! so `P N = 0` and `p ⊥ N` exactly; `P` and `p` are projected onto `N^⊥`
//! at every step, else rounding in the rigid-body Jordan block grows
//! without bound and the sweep never settles. Those states are then fixed by
//! the `x_0` prior and the force prior alone. Internally displacements are scaled by a
//! reference frequency ω and forces by `m ω` so the blocks are balanced.

use crate::error::{Result, TacitError};
use crate::linear::SampledModel;
use crate::record::Quantity;
use crate::riccati::{rel_change, symmetrize, Grouped, RelativeTo};
use nalgebra::{DMatrix, DVector};
use std::time::Instant;

/// Settings of [`reconstruct`]. Call [`LiftedSettings::validate`] before use
/// (the front door does).
#[derive(Debug, Clone, PartialEq)]
pub struct LiftedSettings {
    /// `R`, sub-intervals per sample on which the unknown force is
    /// constant (default 8; 1..=64). `R = 1` is a force held over the
    /// sample (seen by the output at its start).
    pub resolution: usize,
    /// λ, weight of the force prior, 1/N² relative to `W` (default 1e-2: a
    /// prior standard deviation of 10 N for the mean force over a sample
    /// interval when `W` is the inverse noise variance; > 0). Values from
    /// 1e-4 to 1e-1 gave the same states to within a few per cent on the
    /// LANL contact records (see `tests/lifted_states.rs`).
    pub lambda: f64,
    /// Assumed noise standard deviation of every channel as a fraction of
    /// its RMS; defines `W` (default 0.01; > 0).
    pub noise_fraction: f64,
    /// Prior standard deviations of the initial displacements (m) and
    /// velocities (m/s), zero mean (default (1.0, 10.0): weak; both must be
    /// finite and positive, so that states the data do not see — a
    /// free-free model's rigid-body motion under acceleration data — stay
    /// determined).
    pub x0_std: (f64, f64),
    /// Passes of iteratively reweighted least squares that turn the
    /// quadratic force prior into a sparsity prior over DOFs and samples
    /// (weights in `group_l1_weights`; default 4; 0..=50; 0 = the plain
    /// quadratic prior). Needed when the missing force has a mean: only
    /// accelerations are measured and a static force pair `K δu` with the
    /// static deformation `δu` leaves every acceleration unchanged, so the
    /// quadratic prior removes the contact force's mean and shifts the
    /// relative displacement (60 % error on u5 − u6 noise-free). A sparse
    /// prior prefers a force that is zero between impacts (1–2 %). Each pass
    /// is one more sweep with time-varying weights (no steady state).
    pub reweight_passes: usize,
    /// ε of the reweighting, relative to the force RMS (default 1e-3;
    /// (0, 1]): weights are bounded by `1/ε`.
    pub reweight_floor: f64,
    /// Least weighted residual RMS (1 = the assumed noise) of a
    /// reconstruction along located directions ([`reconstruct_floored`]):
    /// below it the force prior's weight λ is raised (default 0.5; in
    /// [0, 1), 0 keeps λ as given). A residual below half the noise means
    /// the force absorbs more than three quarters of the noise variance.
    pub min_residual: f64,
}

impl Default for LiftedSettings {
    fn default() -> Self {
        LiftedSettings {
            resolution: 8,
            lambda: 1e-2,
            noise_fraction: 0.01,
            x0_std: (1.0, 10.0),
            reweight_passes: 4,
            reweight_floor: 1e-3,
            min_residual: 0.5,
        }
    }
}

fn bad(msg: String) -> TacitError {
    TacitError::Setting(format!("lifted reconstruction: {msg}"))
}

impl LiftedSettings {
    /// Check every rule; the error repeats the rule.
    pub fn validate(&self) -> Result<()> {
        if !(1..=64).contains(&self.resolution) {
            return Err(bad(format!(
                "resolution = {} must be in 1..=64",
                self.resolution
            )));
        }
        if !(self.lambda > 0.0 && self.lambda.is_finite()) {
            return Err(bad(format!(
                "lambda = {} must be finite and > 0",
                self.lambda
            )));
        }
        if !(self.noise_fraction > 0.0 && self.noise_fraction.is_finite()) {
            return Err(bad(format!(
                "noise_fraction = {} must be finite and > 0",
                self.noise_fraction
            )));
        }
        if self.reweight_passes > 50 {
            return Err(bad(format!(
                "reweight_passes = {} must be in 0..=50",
                self.reweight_passes
            )));
        }
        if !(self.reweight_floor > 0.0 && self.reweight_floor <= 1.0) {
            return Err(bad(format!(
                "reweight_floor = {} must be in (0, 1]",
                self.reweight_floor
            )));
        }
        if !(0.0..1.0).contains(&self.min_residual) {
            return Err(bad(format!(
                "min_residual = {} must be in [0, 1)",
                self.min_residual
            )));
        }
        let (su, sv) = self.x0_std;
        if !(su > 0.0 && su.is_finite() && sv > 0.0 && sv.is_finite()) {
            return Err(bad(format!("x0_std = ({su}, {sv}) must be finite and > 0")));
        }
        Ok(())
    }
}

/// The result of [`reconstruct`].
#[derive(Debug, Clone)]
pub struct LiftedResult {
    /// States `[u; v]` at the samples (2n × N), m and m/s.
    pub states: DMatrix<f64>,
    /// Mean unknown force over each sample interval `[t_k, t_{k+1})`
    /// (n × N), right-hand-side convention (the force added to the model),
    /// N. The last column copies the previous one.
    pub force: DMatrix<f64>,
    /// The sub-interval forces (n × N R): column `k R + j` is `f_{k,j}`
    /// on `[t_k + j h/R, t_k + (j+1) h/R)`. In the last interval only
    /// `f_{N−1,0}` is seen by the data; the others are 0.
    pub fine_force: DMatrix<f64>,
    /// RMS of the output residual weighted by the assumed noise (1 = the
    /// residual is as large as the noise `noise_fraction` describes).
    pub weighted_rms: f64,
    /// The output residual weighted by the assumed noise (p × N, one row
    /// per channel; 1 = the assumed standard deviation of that channel).
    pub residual: DMatrix<f64>,
    /// The weight of the force prior used (λ of the settings, or the one
    /// [`reconstruct_floored`] chose).
    pub lambda: f64,
    /// What was done: Riccati convergence, sub-steps, weighted residual.
    pub status: String,
    /// Wall time, s.
    pub elapsed_s: f64,
}

/// The lifted sample map of a [`SampledModel`] (unscaled).
#[derive(Debug, Clone)]
pub struct LiftedModel {
    /// `R`.
    pub resolution: usize,
    /// Newmark sub-steps per sub-interval, `⌈S/R⌉`.
    pub substeps_per_sub: usize,
    /// `A = A_s^R` (2n × 2n).
    pub a: DMatrix<f64>,
    /// `[G_0, …, G_{R−1}]` (2n × nR).
    pub g: DMatrix<f64>,
    /// Input of the known force at the start of the sample (2n × n).
    pub bg0: DMatrix<f64>,
    /// Input of the known force at the end of the sample (2n × n).
    pub bg1: DMatrix<f64>,
}

/// Build the lifted map of `sm` with `resolution` sub-intervals (see the
/// module docs).
pub fn lift(sm: &SampledModel, resolution: usize) -> Result<LiftedModel> {
    let (n, r) = (sm.n, resolution);
    if r < 1 {
        return Err(bad("resolution must be >= 1".into()));
    }
    let per = sm.substeps.div_ceil(r).max(1);
    let sub = SampledModel::new(
        sm.m.clone(),
        sm.c.clone(),
        sm.k.clone(),
        sm.fs * r as f64,
        per,
    )?;
    let bc = &sub.b0 + &sub.b1;
    // pows[p] = A_s^p, p = 0..=R
    let mut pows = vec![DMatrix::identity(2 * n, 2 * n)];
    for p in 1..=r {
        let next = &sub.a * &pows[p - 1];
        pows.push(next);
    }
    let mut g = DMatrix::zeros(2 * n, n * r);
    let mut bg0 = DMatrix::zeros(2 * n, n);
    let mut bg1 = DMatrix::zeros(2 * n, n);
    for j in 0..r {
        let pw = &pows[r - 1 - j];
        g.columns_mut(j * n, n).copy_from(&(pw * &bc));
        let (t0, t1) = (j as f64 / r as f64, (j + 1) as f64 / r as f64);
        let pb0 = pw * &sub.b0;
        let pb1 = pw * &sub.b1;
        bg0 += &pb0 * (1.0 - t0) + &pb1 * (1.0 - t1);
        bg1 += &pb0 * t0 + &pb1 * t1;
    }
    Ok(LiftedModel {
        resolution: r,
        substeps_per_sub: per,
        a: pows.swap_remove(r),
        g,
        bg0,
        bg1,
    })
}

/// The scaled problem (`x = D_x x̃`, `f = d_f f̃`, output rows × `W^{1/2}`).
struct Scaled {
    nx: usize,
    nu: usize,
    len: usize,
    a: DMatrix<f64>,
    g: DMatrix<f64>,
    hx: DMatrix<f64>,
    hu: DMatrix<f64>,
    /// The Riccati stage in output form with the controls grouped by force
    /// direction (the R sub-intervals of one direction share a weight).
    grouped: Grouped,
    /// `Zᵀ = [H_u; G]ᵀ` (nu × (p + nx)).
    zt: DMatrix<f64>,
    /// Force directions q (the groups of the controls).
    groups: usize,
    /// Samples per block of the backward pass's checkpoints: the forward
    /// pass recomputes the gains of one block at a time from the Riccati
    /// matrix stored at its end; `len` (one block) stores every gain.
    block: usize,
    /// `r_k` (p × N).
    target: DMatrix<f64>,
    /// `c_k` (nx × (N−1)).
    c: DMatrix<f64>,
    /// Force prior weight of every control component (nu).
    lambda: DVector<f64>,
    /// Optional multipliers of `lambda` per DOF and sample (n × N), the
    /// same for the R sub-intervals; disables the steady state.
    lam_k: Option<DMatrix<f64>>,
    /// Prior weight (diagonal, nx).
    p0: DVector<f64>,
    /// Orthonormal basis of the unobservable subspace of `(A, H_x)` (nx × d).
    null: DMatrix<f64>,
    dx: DVector<f64>,
    df: f64,
}

/// `W^{1/2}` per channel: `1/(fraction × RMS)`.
fn rms_weights(y: &DMatrix<f64>, fraction: f64) -> Result<DVector<f64>> {
    let w = crate::signal::channel_weights(y, fraction);
    match w.iter().position(Option::is_none) {
        Some(r) => Err(bad(format!(
            "channel {r} is identically zero, so a noise level relative to its RMS is undefined"
        ))),
        None => Ok(DVector::from_iterator(y.nrows(), w.into_iter().flatten())),
    }
}

fn check_sizes(
    sm: &SampledModel,
    known_force: &DMatrix<f64>,
    measured: &DMatrix<f64>,
    channels: &[(Quantity, usize)],
) -> Result<usize> {
    let (n, len) = (sm.n, measured.ncols());
    if len < 2 {
        return Err(bad(format!(
            "the record has {len} samples, at least 2 are needed"
        )));
    }
    if measured.nrows() != channels.len() || channels.is_empty() {
        return Err(bad(format!(
            "{} measured rows but {} channels (at least one needed)",
            measured.nrows(),
            channels.len()
        )));
    }
    if known_force.nrows() != n || known_force.ncols() != len {
        return Err(bad(format!(
            "known force is {}×{}, expected {n}×{len} (DOFs × samples)",
            known_force.nrows(),
            known_force.ncols()
        )));
    }
    if let Some(i) = measured.iter().position(|v| !v.is_finite()) {
        return Err(bad(format!(
            "measured value of channel {} at sample {} is not finite",
            i % measured.nrows(),
            i / measured.nrows()
        )));
    }
    if let Some(i) = known_force.iter().position(|v| !v.is_finite()) {
        return Err(bad(format!(
            "known force at DOF {} sample {} is not finite",
            i % n + 1,
            i / n
        )));
    }
    Ok(len)
}

impl Scaled {
    fn new(
        sm: &SampledModel,
        lm: &LiftedModel,
        known_force: &DMatrix<f64>,
        measured: &DMatrix<f64>,
        channels: &[(Quantity, usize)],
        directions: &DMatrix<f64>,
        s: &LiftedSettings,
    ) -> Result<Scaled> {
        let len = check_sizes(sm, known_force, measured, channels)?;
        let (n, r) = (sm.n, lm.resolution);
        if directions.nrows() != n {
            return Err(bad(format!(
                "force directions have {} rows, the model has {n} DOFs",
                directions.nrows()
            )));
        }
        let nq = directions.ncols();
        let (nx, nu, p) = (2 * n, nq * r, channels.len());
        let (cy, dy) = sm.outputs(channels)?;
        let wsqrt = rms_weights(measured, s.noise_fraction)?;
        // reference frequency and mass (as the horizon smoother)
        let (omega, mref) = sm.reference_scales();
        let dx = sm.state_scale();
        let df = mref * omega;
        let a = DMatrix::from_fn(nx, nx, |i, j| lm.a[(i, j)] * dx[j] / dx[i]);
        let mut g = DMatrix::zeros(nx, nu);
        for j in 0..r {
            let gj = lm.g.columns(j * n, n) * directions;
            for i in 0..nx {
                for c in 0..nq {
                    g[(i, j * nq + c)] = gj[(i, c)] * df / dx[i];
                }
            }
        }
        let hx = DMatrix::from_fn(p, nx, |i, j| cy[(i, j)] * wsqrt[i] * dx[j]);
        let dye = &dy * directions;
        let mut hu = DMatrix::zeros(p, nu);
        for i in 0..p {
            for j in 0..nq {
                hu[(i, j)] = dye[(i, j)] * wsqrt[i] * df;
            }
        }
        let mut target = measured - &dy * known_force;
        for i in 0..p {
            target.row_mut(i).scale_mut(wsqrt[i]);
        }
        let mut c =
            &lm.bg0 * known_force.columns(0, len - 1) + &lm.bg1 * known_force.columns(1, len - 1);
        for i in 0..nx {
            c.row_mut(i).scale_mut(1.0 / dx[i]);
        }
        let null = crate::linear::unobservable(&a, &hx);
        let lambda = DVector::from_element(nu, s.lambda / r as f64 * df * df);
        let group: Vec<usize> = (0..nu).map(|i| i % nq.max(1)).collect();
        let grouped = Grouped::new(&a, &g, &hx, &hu, &group, nq, lambda.as_slice());
        let mut zt = DMatrix::zeros(nu, p + nx);
        zt.columns_mut(0, p).copy_from(&hu.transpose());
        zt.columns_mut(p, nx).copy_from(&g.transpose());
        let block = gain_block(len, grouped.gain_rows(), nx);
        let (su, sv) = s.x0_std;
        let p0 = DVector::from_fn(nx, |i, _| {
            let sd = if i < n { su } else { sv };
            dx[i] * dx[i] / (sd * sd)
        });
        Ok(Scaled {
            nx,
            nu,
            len,
            a,
            g,
            hx,
            hu,
            grouped,
            zt,
            groups: nq,
            block,
            target,
            c,
            lambda,
            lam_k: None,
            p0,
            null,
            dx,
            df,
        })
    }
}

/// `P ← (I − N Nᵀ) P (I − N Nᵀ)`.
fn project_matrix(null: &DMatrix<f64>, p: &mut DMatrix<f64>) {
    if null.ncols() == 0 {
        return;
    }
    let pn = &*p * null;
    let npn = null.transpose() * &pn;
    *p -= &pn * null.transpose() + null * pn.transpose() - null * npn * null.transpose();
    symmetrize(p);
}

/// `p ← (I − N Nᵀ) p`.
fn project_vector(null: &DMatrix<f64>, p: &mut DVector<f64>) {
    if null.ncols() > 0 {
        let c = null.transpose() * &*p;
        p.gemv(-1.0, null, &c, 1.0);
    }
}

/// Bytes of gains the backward pass may store for the forward pass
/// (`T_k`, (p + nx) × nx per sample, or `L_k`, nu × nx); beyond, it keeps the Riccati matrix
/// every [`Scaled::block`] samples and the forward pass recomputes the
/// gains of one block at a time.
const GAIN_BUDGET: usize = 32 << 20;

/// Samples per checkpoint block: the whole record when its gains fit in
/// [`GAIN_BUDGET`], else `⌈√N⌉` (at least 64), so that the checkpoints
/// (`N/K` matrices nx × nx) and one block's gains (`K` matrices
/// q × nx) both grow as `√N`.
fn gain_block(len: usize, q: usize, nx: usize) -> usize {
    if len * q * nx * 8 <= GAIN_BUDGET {
        len
    } else {
        ((len as f64).sqrt().ceil() as usize).max(64)
    }
}

/// The backward pass.
struct Backward {
    /// Samples `k ≥ j0` use their own gain `T_k`, `k < j0` the steady one.
    j0: usize,
    /// `T_k` of the samples `k ≥ j0` (index `k − j0`) when every gain is
    /// stored; empty when checkpointed.
    stored: Vec<DMatrix<f64>>,
    /// The Riccati matrix `P_e` at the end `e` of every block of
    /// [`Scaled::block`] samples (index: the block), when checkpointed.
    checkpoints: Vec<Option<DMatrix<f64>>>,
    /// Steady `T`.
    steady: Option<DMatrix<f64>>,
    /// `ω_k = F_k⁻¹ [r_k; e_k]` ((p + nx) × N), or `l_k` (nu × N) in the
    /// control space.
    omega: DMatrix<f64>,
    p0: DMatrix<f64>,
    pv0: DVector<f64>,
}

const RICCATI_TOL: f64 = 1e-13;

fn not_definite(k: usize) -> TacitError {
    TacitError::Numerical(format!(
        "lifted reconstruction: the Riccati step is singular (I + S M not invertible) at sample {k}"
    ))
}

impl Scaled {
    /// The force prior of sample `k` (the diagonal of `Λ_k`).
    fn prior_at(&self, k: usize, out: &mut [f64]) {
        for (i, o) in out.iter_mut().enumerate() {
            *o = self.lambda[i] * self.lam_k.as_ref().map_or(1.0, |m| m[(i % m.nrows(), k)]);
        }
    }

    /// The multiplier of the force prior of every direction at sample `k`
    /// (the group weights of the Riccati step).
    fn group_weights(&self, k: usize, out: &mut [f64]) {
        for (c, o) in out.iter_mut().enumerate() {
            *o = self.lam_k.as_ref().map_or(1.0, |m| m[(c, k)]);
        }
    }

    /// Whether the backward pass keeps checkpoints rather than gains.
    fn checkpointed(&self) -> bool {
        self.block < self.len
    }
}

/// The data part of the backward step at sample `k` from `pn = P_{k+1}`
/// (the step `st` taken at it): `e = p' − P' c_k`, `v = [r_k; e]`,
/// `ω_k = F⁻¹ v`, `p_k = closedᵀ v` (projected off the unobservable
/// subspace).
fn data_step(
    sp: &Scaled,
    st: &Grouped,
    k: usize,
    pn: &DMatrix<f64>,
    pv: &mut DVector<f64>,
    omega: &mut DMatrix<f64>,
) {
    let p_out = st.p;
    let mut v = DVector::zeros(p_out + sp.nx);
    v.rows_mut(0, p_out).copy_from(&sp.target.column(k));
    if k + 1 < sp.len {
        let mut e = pv.clone();
        e.gemv(-1.0, pn, &sp.c.column(k), 1.0);
        v.rows_mut(p_out, sp.nx).copy_from(&e);
    }
    omega.set_column(k, &st.feed(&v));
    pv.gemv_tr(1.0, &st.closed, &v, 0.0);
    project_vector(&sp.null, pv);
}

fn backward(sp: &Scaled) -> Result<Backward> {
    let (nx, len, block) = (sp.nx, sp.len, sp.block);
    let mut st = sp.grouped.clone();
    let mut p = DMatrix::zeros(nx, nx);
    let mut pv = DVector::zeros(nx);
    let mut omega = DMatrix::zeros(st.gain_rows(), len);
    let mut stored: Vec<DMatrix<f64>> = Vec::new();
    let mut checkpoints = vec![None; len.div_ceil(block)];
    let mut w = vec![0.0; sp.groups];
    let mut calm = 0usize;
    let mut k = len;
    // transient: full Riccati steps until P stops changing
    while k > 0 {
        k -= 1;
        if sp.checkpointed() && (k + 1 == len || (k + 1) % block == 0) {
            checkpoints[k / block] = Some(p.clone());
        }
        sp.group_weights(k, &mut w);
        if !st.step(&p, &w) {
            return Err(not_definite(k));
        }
        project_matrix(&sp.null, &mut st.pm);
        data_step(sp, &st, k, &p, &mut pv, &mut omega);
        calm = if rel_change(&st.pm, &p, RelativeTo::Larger) <= RICCATI_TOL {
            calm + 1
        } else {
            0
        };
        std::mem::swap(&mut p, &mut st.pm);
        if !sp.checkpointed() {
            stored.push(st.t.clone());
        }
        if calm >= 3 && sp.lam_k.is_none() {
            break;
        }
    }
    let j0 = k;
    let mut steady = None;
    if j0 > 0 {
        // steady state: P_k = P for every k < j0
        sp.group_weights(0, &mut w);
        if !st.step(&p, &w) {
            return Err(not_definite(j0 - 1));
        }
        for k in (0..j0).rev() {
            data_step(sp, &st, k, &p, &mut pv, &mut omega);
        }
        steady = Some(st.t.clone());
    }
    stored.reverse();
    Ok(Backward {
        j0,
        stored,
        checkpoints,
        steady,
        omega,
        p0: p,
        pv0: pv,
    })
}

/// The gains `T_k` of the block holding sample `k` (samples `lo..e`,
/// `lo` not below `j0`), recomputed from the checkpoint at its end by the
/// same steps as the backward pass, so they equal the gains it had.
fn block_gains(sp: &Scaled, bw: &Backward, k: usize) -> Result<(usize, Vec<DMatrix<f64>>)> {
    let b = k / sp.block;
    let (lo, e) = ((b * sp.block).max(bw.j0), ((b + 1) * sp.block).min(sp.len));
    let mut p = bw.checkpoints[b]
        .clone()
        .expect("a checkpoint at the end of every transient block");
    let mut st = sp.grouped.clone();
    let mut w = vec![0.0; sp.groups];
    let mut gains = vec![DMatrix::zeros(0, 0); e - lo];
    for kk in (lo..e).rev() {
        sp.group_weights(kk, &mut w);
        if !st.step(&p, &w) {
            return Err(not_definite(kk));
        }
        gains[kk - lo] = st.t.clone();
        project_matrix(&sp.null, &mut st.pm);
        std::mem::swap(&mut p, &mut st.pm);
    }
    Ok((lo, gains))
}

/// Rounding of the initial-state system `P_0 + P_prior` relative to its
/// largest eigenvalue: eigenvalues within it are not determined.
const INITIAL_ROUNDING: f64 = 1e-12;

/// `x_0 = (P_0 + P_prior)⁻¹ p_0` and the number of directions dropped.
/// Cholesky; when it fails (the prior's weight is below the rounding of
/// `P_0` along directions the data barely see), the minimum-norm solution
/// over the eigenvalues above [`INITIAL_ROUNDING`] × the largest: those
/// directions take the prior mean (0). An eigenvalue below −that bound is
/// not rounding, and an error.
fn initial_state(mut h: DMatrix<f64>, rhs: &DVector<f64>) -> Result<(DVector<f64>, usize)> {
    symmetrize(&mut h);
    if let Some(ch) = h.clone().cholesky() {
        return Ok((ch.solve(rhs), 0));
    }
    let eig = h.symmetric_eigen();
    let (vmin, vmax) = (eig.eigenvalues.min(), eig.eigenvalues.max());
    let cut = INITIAL_ROUNDING * vmax;
    if !(vmax > 0.0 && vmax.is_finite() && vmin >= -cut) {
        return Err(TacitError::Numerical(format!(
            "lifted reconstruction: the initial-state system P_0 + P_prior is not positive definite: its eigenvalues run from {vmin:.3e} to {vmax:.3e}, below −{cut:.1e} (more than the rounding of P_0)"
        )));
    }
    let q = &eig.eigenvectors;
    let mut c = q.tr_mul(rhs);
    let mut dropped = 0;
    for (ci, v) in c.iter_mut().zip(eig.eigenvalues.iter()) {
        if *v > cut {
            *ci /= v;
        } else {
            *ci = 0.0;
            dropped += 1;
        }
    }
    Ok((q * c, dropped))
}

/// The forward pass: scaled states (nx × N), controls (nu × N) and the
/// initial-state directions left to the prior ([`initial_state`]). The
/// control is `u_k = Λ_k⁻¹ Zᵀ (ω_k − T_k x_k)`, or `l_k − L_k x_k` when
/// the step is taken in the control space ([`crate::riccati::grouped`]).
fn forward(sp: &Scaled, bw: &Backward) -> Result<(DMatrix<f64>, DMatrix<f64>, usize)> {
    let (nx, nu, len) = (sp.nx, sp.nu, sp.len);
    let mut h = bw.p0.clone();
    for i in 0..nx {
        h[(i, i)] += sp.p0[i];
    }
    let (x0, dropped) = initial_state(h, &bw.pv0)?;
    let mut xs = DMatrix::zeros(nx, len);
    let mut us = DMatrix::zeros(nu, len);
    let mut x = x0;
    let mut u = DVector::zeros(nu);
    let mut xn = DVector::zeros(nx);
    let mut lam = vec![0.0; nu];
    let mut dev = DVector::zeros(bw.omega.nrows());
    let (mut lo, mut gains) = (0usize, Vec::new());
    for k in 0..len {
        xs.set_column(k, &x);
        let t = if k < bw.j0 {
            bw.steady.as_ref().expect("steady gain exists below j0")
        } else if !sp.checkpointed() {
            &bw.stored[k - bw.j0]
        } else {
            if k < lo || k >= lo + gains.len() {
                (lo, gains) = block_gains(sp, bw, k)?;
            }
            &gains[k - lo]
        };
        if sp.grouped.direct {
            u.copy_from(&bw.omega.column(k));
            u.gemv(-1.0, t, &x, 1.0);
        } else {
            dev.copy_from(&bw.omega.column(k));
            dev.gemv(-1.0, t, &x, 1.0);
            u.gemv(1.0, &sp.zt, &dev, 0.0);
            sp.prior_at(k, &mut lam);
            for (ui, li) in u.iter_mut().zip(&lam) {
                *ui /= li;
            }
        }
        us.set_column(k, &u);
        if k + 1 < len {
            xn.gemv(1.0, &sp.a, &x, 0.0);
            xn.gemv(1.0, &sp.g, &u, 1.0);
            xn += sp.c.column(k);
            std::mem::swap(&mut x, &mut xn);
        }
    }
    Ok((xs, us, dropped))
}

/// Reconstruct the states and the sub-sample unknown force (see the module
/// docs) from measured outputs, with an unknown force at every DOF.
///
/// `sm` is the linear model's sample map, `known_force` the measured force
/// at every DOF (n × N, right-hand side), `measured` the outputs (p × N),
/// one row per `channels` entry `(quantity, dof0)`. With
/// `reweight_passes > 0` the quadratic solve is repeated with the force
/// weights of [`LiftedSettings::reweight_passes`].
pub fn reconstruct(
    sm: &SampledModel,
    known_force: &DMatrix<f64>,
    measured: &DMatrix<f64>,
    channels: &[(Quantity, usize)],
    s: &LiftedSettings,
) -> Result<LiftedResult> {
    let every = DMatrix::identity(sm.n, sm.n);
    reconstruct_along(sm, &every, known_force, measured, channels, s)
}

/// [`reconstruct`] with the unknown force restricted to the span of the
/// columns of `directions` (n × q): `f = E w`, `w ∈ ℝ^q` on each
/// sub-interval. A force between two DOFs is the column `e_i − e_j` (equal
/// and opposite), one at a DOF `e_i`; `q = 0` is the model with no unknown
/// force (a plain smoother). Fewer unknowns than sensors make the states
/// observable from a few accelerometers where a force at every DOF leaves
/// them to the prior; the weighted residual
/// ([`LiftedResult::weighted_rms`]) then tells whether the force can act
/// there.
pub fn reconstruct_along(
    sm: &SampledModel,
    directions: &DMatrix<f64>,
    known_force: &DMatrix<f64>,
    measured: &DMatrix<f64>,
    channels: &[(Quantity, usize)],
    s: &LiftedSettings,
) -> Result<LiftedResult> {
    let t = Instant::now();
    s.validate()?;
    let lm = lift(sm, s.resolution)?;
    let mut sp = Scaled::new(sm, &lm, known_force, measured, channels, directions, s)?;
    let (n, r, len) = (sm.n, s.resolution, sp.len);
    let nq = directions.ncols();
    let mut bw = backward(&sp)?;
    let (mut xs, mut us, mut dropped) = forward(&sp, &bw)?;
    let steady_note = riccati_note(&bw, len);
    let passes = if nq > 0 { s.reweight_passes } else { 0 };
    for _ in 0..passes {
        sp.lam_k = Some(group_l1_weights(&us, nq, r, s.reweight_floor));
        bw = backward(&sp)?;
        (xs, us, dropped) = forward(&sp, &bw)?;
    }
    // weighted residual
    let res = &sp.target - &sp.hx * &xs - &sp.hu * &us;
    let wrms = (res.norm_squared() / (res.nrows() * len) as f64).sqrt();
    let mut states = xs;
    for i in 0..sp.nx {
        states.row_mut(i).scale_mut(sp.dx[i]);
    }
    let mut fine_force = DMatrix::zeros(n, len * r);
    let mut force = DMatrix::zeros(n, len);
    for k in 0..len {
        for j in 0..r {
            for c in 0..nq {
                let w = us[(j * nq + c, k)] * sp.df;
                if w == 0.0 {
                    continue;
                }
                for i in 0..n {
                    let f = directions[(i, c)] * w;
                    fine_force[(i, k * r + j)] += f;
                    force[(i, k)] += f / r as f64;
                }
            }
        }
    }
    let last = force.column(len - 2).into_owned();
    force.set_column(len - 1, &last);
    let hidden = sp.null.ncols();
    Ok(LiftedResult {
        states,
        force,
        fine_force,
        weighted_rms: wrms,
        residual: res,
        lambda: s.lambda,
        status: format!(
            "solved: {steady_note}; {passes} group-L1 reweighting passes; {nq} force directions; R = {r} sub-intervals of {} Newmark sub-steps; {hidden} unobservable state directions (set by the priors); {dropped} initial-state directions below the rounding of the Riccati matrix (set to the prior mean); weighted residual RMS {wrms:.3} (1 = the assumed noise)",
            lm.substeps_per_sub
        ),
        elapsed_s: t.elapsed().as_secs_f64(),
    })
}

/// Steps of the weight search of [`reconstruct_floored`]: λ is tried at
/// `λ_0 10^{k/2}`, `k = 0..=FLOOR_STEPS` (up to `10^4 λ_0`).
pub const FLOOR_STEPS: usize = 8;

/// The weight of the force prior for a reconstruction along located
/// `directions` (module docs, *Weight of the force prior*): the smallest
/// `λ_0 10^{k/2}` (`λ_0` = [`LiftedSettings::lambda`],
/// `k = 0..=`[`FLOOR_STEPS`]) whose quadratic reconstruction (no
/// reweighting) leaves a weighted residual RMS of at least
/// [`LiftedSettings::min_residual`]. When none does (the residual does
/// not respond to the weight: a force at the only measured DOF fits it
/// whatever λ), the principle has no answer and λ stays `λ_0`. Returns
/// the weight and the residuals tried.
pub fn floor_lambda(
    sm: &SampledModel,
    directions: &DMatrix<f64>,
    known_force: &DMatrix<f64>,
    measured: &DMatrix<f64>,
    channels: &[(Quantity, usize)],
    s: &LiftedSettings,
) -> Result<(f64, Vec<(f64, f64)>)> {
    s.validate()?;
    let mut tried = vec![];
    if s.min_residual <= 0.0 || directions.ncols() == 0 {
        return Ok((s.lambda, tried));
    }
    for k in 0..=FLOOR_STEPS {
        let lambda = s.lambda * 10f64.powf(k as f64 / 2.0);
        let quick = LiftedSettings {
            lambda,
            reweight_passes: 0,
            ..s.clone()
        };
        let w = reconstruct_along(sm, directions, known_force, measured, channels, &quick)?
            .weighted_rms;
        tried.push((lambda, w));
        if w >= s.min_residual {
            break;
        }
    }
    let lambda = match tried.last() {
        Some(&(l, w)) if w >= s.min_residual => l,
        _ => s.lambda,
    };
    Ok((lambda, tried))
}

/// [`reconstruct_along`] at the weight [`floor_lambda`] chooses (the
/// reconstruction of located directions; its status says which weights
/// were tried).
pub fn reconstruct_floored(
    sm: &SampledModel,
    directions: &DMatrix<f64>,
    known_force: &DMatrix<f64>,
    measured: &DMatrix<f64>,
    channels: &[(Quantity, usize)],
    s: &LiftedSettings,
) -> Result<LiftedResult> {
    let t = Instant::now();
    let (lambda, tried) = floor_lambda(sm, directions, known_force, measured, channels, s)?;
    let chosen = LiftedSettings {
        lambda,
        ..s.clone()
    };
    let mut r = reconstruct_along(sm, directions, known_force, measured, channels, &chosen)?;
    if tried.len() > 1 {
        let steps: Vec<String> = tried
            .iter()
            .map(|(l, w)| format!("{l:.2e}: {w:.3}"))
            .collect();
        let what = if lambda > s.lambda {
            format!(
                "force-prior weight raised from {:.2e} to {lambda:.2e} so that the quadratic reconstruction leaves",
                s.lambda
            )
        } else {
            format!(
                "force-prior weight kept at {:.2e}: no weight tried makes the quadratic reconstruction leave",
                s.lambda
            )
        };
        r.status = format!(
            "{}; {what} at least {} of the assumed noise (weighted residual by λ: {})",
            r.status,
            s.min_residual,
            steps.join(", ")
        );
    }
    r.elapsed_s = t.elapsed().as_secs_f64();
    Ok(r)
}

/// The reconstruction after a location: along the located `directions`
/// at the floored weight ([`reconstruct_floored`]), or with an unknown
/// force at every DOF at the settings' weight when none were located.
pub fn reconstruct_located(
    sm: &SampledModel,
    directions: Option<&DMatrix<f64>>,
    known_force: &DMatrix<f64>,
    measured: &DMatrix<f64>,
    channels: &[(Quantity, usize)],
    s: &LiftedSettings,
) -> Result<LiftedResult> {
    match directions {
        Some(e) => reconstruct_floored(sm, e, known_force, measured, channels, s),
        None => reconstruct(sm, known_force, measured, channels, s),
    }
}

fn riccati_note(bw: &Backward, len: usize) -> String {
    if bw.j0 > 0 {
        format!("Riccati converged after {} of {len} samples", len - bw.j0)
    } else {
        format!("Riccati transient over the whole record ({len} samples)")
    }
}

/// Weights of one iteratively reweighted pass, sparse over DOFs and over
/// time: with `|f_{k,i}|² = Σ_j f_{k,j,i}² / R`, `s` its RMS over all DOFs
/// and samples, `s_i` its RMS over the samples of DOF `i` and `ε = floor`,
/// the multiplier of λ for DOF `i` at sample `k` is
/// `(max_i s_i / max(s_i, ε max_i s_i)) · s / (|f_{k,i}| + ε s)` (n × N):
/// the second factor is the IRLS weight of `Σ_{k,i} |f_{k,i}|` (zero force
/// between impacts), the first one of a group penalty `Σ_i s_i` (few
/// DOFs). Time sparsity alone left the force spread over DOFs 4–7 and
/// 33–39 % error on u5 − u6; with both factors 1–2 %.
fn group_l1_weights(us: &DMatrix<f64>, n: usize, r: usize, floor: f64) -> DMatrix<f64> {
    let len = us.ncols();
    let mag = DMatrix::from_fn(n, len, |i, k| {
        ((0..r).map(|j| us[(j * n + i, k)].powi(2)).sum::<f64>() / r as f64).sqrt()
    });
    let scale = (mag.norm_squared() / (n * len) as f64).sqrt();
    if !(scale > 0.0) {
        return DMatrix::from_element(n, len, 1.0);
    }
    // DOF level: RMS of each DOF's force relative to the largest
    let dof_rms: Vec<f64> = (0..n)
        .map(|i| (mag.row(i).norm_squared() / len as f64).sqrt())
        .collect();
    let top = dof_rms.iter().cloned().fold(0.0, f64::max);
    DMatrix::from_fn(n, len, |i, k| {
        let dof = top / dof_rms[i].max(floor * top);
        dof * scale / (mag[(i, k)] + floor * scale)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn chain(n: usize) -> SampledModel {
        let m = DMatrix::from_fn(n, n, |i, j| if i == j { 0.5 + 0.1 * i as f64 } else { 0.0 });
        let mut k = DMatrix::zeros(n, n);
        for i in 0..n {
            k[(i, i)] += 400.0;
            if i + 1 < n {
                k[(i, i)] += 300.0;
                k[(i + 1, i + 1)] += 300.0;
                k[(i, i + 1)] -= 300.0;
                k[(i + 1, i)] -= 300.0;
            }
        }
        let c = &k * 1e-3 + &m * 0.5;
        SampledModel::new(m, c, k, 20.0, 12).unwrap()
    }

    #[test]
    fn lift_composes_the_sample_model() {
        let sm = chain(3);
        let bsum = &sm.b0 + &sm.b1;
        for r in [1, 2, 3, 4, 6, 12] {
            let lm = lift(&sm, r).unwrap();
            assert_eq!(lm.substeps_per_sub * r, 12);
            let tol = 1e-12 * sm.a.amax();
            assert!((&lm.a - &sm.a).amax() < tol, "A, R = {r}");
            assert!(
                (&lm.bg0 - &sm.b0).amax() < 1e-12 * sm.b0.amax(),
                "B0, R = {r}"
            );
            assert!(
                (&lm.bg1 - &sm.b1).amax() < 1e-12 * sm.b1.amax(),
                "B1, R = {r}"
            );
            let mut gsum = DMatrix::zeros(6, 3);
            for j in 0..r {
                gsum += lm.g.columns(j * 3, 3);
            }
            assert!((gsum - &bsum).amax() < 1e-12 * bsum.amax(), "ΣG, R = {r}");
        }
        // R not dividing S: more sub-steps, still close
        let lm = lift(&sm, 5).unwrap();
        assert_eq!(lm.substeps_per_sub, 3);
        assert!((&lm.a - &sm.a).amax() < 1e-2 * sm.a.amax());
    }

    /// The sweep against a dense least-squares solve of the same cost.
    #[test]
    fn sweep_matches_dense_least_squares() {
        let (n, len, r) = (2usize, 7usize, 3usize);
        let sm = chain(n);
        let lm = lift(&sm, r).unwrap();
        let channels = [(Quantity::Accel, 0), (Quantity::Disp, 1)];
        let known = DMatrix::from_fn(
            n,
            len,
            |i, k| if i == 0 { (k as f64 * 0.9).sin() } else { 0.0 },
        );
        let measured = DMatrix::from_fn(2, len, |c, k| {
            ((c + 1) as f64 * 1.3 + k as f64 * 0.7).cos() * [3.0, 0.01][c]
        });
        let s = LiftedSettings {
            resolution: r,
            lambda: 0.3,
            noise_fraction: 0.05,
            x0_std: (0.2, 2.0),
            reweight_passes: 0,
            ..Default::default()
        };
        let res = reconstruct(&sm, &known, &measured, &channels, &s).unwrap();
        assert!(res.status.starts_with("solved"), "{}", res.status);
        let varying = DMatrix::from_fn(n, len, |i, k| 0.3 + ((i * 7 + k * 3) % 5) as f64);
        for ((weights, block), direct) in [None, Some(varying)]
            .into_iter()
            .flat_map(|w| [(w.clone(), len), (w, 3)])
            .flat_map(|c| [(c.clone(), false), (c, true)])
        {
            // the sweep, with optional time-varying weights, every gain
            // stored or checkpointed every 3 samples, the step in the
            // output space or in the control space
            let mut sp = Scaled::new(
                &sm,
                &lm,
                &known,
                &measured,
                &channels,
                &DMatrix::identity(n, n),
                &s,
            )
            .unwrap();
            sp.lam_k = weights.clone();
            sp.block = block;
            sp.grouped.direct = direct;
            let bw = backward(&sp).unwrap();
            let (mut xs, mut us, _) = forward(&sp, &bw).unwrap();
            for i in 0..2 * n {
                xs.row_mut(i).scale_mut(sp.dx[i]);
            }
            us *= sp.df;
            let mult = |i: usize, k: usize| weights.as_ref().map_or(1.0, |w| w[(i % n, k)]);
            check_dense(&sm, &lm, &known, &measured, &channels, &s, &xs, &us, &mult);
        }
    }

    /// Gains recomputed block by block from checkpoints give the estimate
    /// of gains stored per sample, with the reweighting passes (no steady
    /// state) and without (a steady state inside a block), for blocks that
    /// do and do not divide the record.
    #[test]
    fn checkpointed_gains_give_the_stored_estimate() {
        let n = 3;
        let sm = chain(n);
        let len = 1201;
        let known = DMatrix::from_fn(n, len, |i, k| {
            if i == 2 {
                (k as f64 * 0.3).sin() + 0.2 * (k as f64 * 1.1).cos()
            } else {
                0.0
            }
        });
        let xs = sm.simulate(&DVector::zeros(2 * n), &known);
        let channels = vec![
            (Quantity::Accel, 0),
            (Quantity::Accel, 1),
            (Quantity::Disp, 2),
        ];
        let (cy, dy) = sm.outputs(&channels).unwrap();
        let mut measured = &cy * &xs + &dy * &known;
        for (i, v) in measured.iter_mut().enumerate() {
            *v *= 1.0 + 0.05 * ((i * 7919) % 13) as f64 / 13.0;
        }
        for passes in [0, 2] {
            let s = LiftedSettings {
                resolution: 4,
                reweight_passes: passes,
                ..Default::default()
            };
            let lm = lift(&sm, s.resolution).unwrap();
            let run = |block: usize| {
                let mut sp = Scaled::new(
                    &sm,
                    &lm,
                    &known,
                    &measured,
                    &channels,
                    &DMatrix::identity(n, n),
                    &s,
                )
                .unwrap();
                sp.block = block;
                let mut bw = backward(&sp).unwrap();
                let (mut xs, mut us, _) = forward(&sp, &bw).unwrap();
                for _ in 0..passes {
                    sp.lam_k = Some(group_l1_weights(&us, n, s.resolution, s.reweight_floor));
                    bw = backward(&sp).unwrap();
                    (xs, us, _) = forward(&sp, &bw).unwrap();
                }
                (xs, us, bw.j0, bw.stored.len(), bw.checkpoints.len())
            };
            let (xs0, us0, j0, stored, _) = run(len);
            assert_eq!(stored, len - j0, "every transient gain stored");
            if passes == 0 {
                assert!(j0 > 100, "a steady state on this record: j0 = {j0}");
            }
            for block in [7, 50, 64] {
                let (xs1, us1, j1, stored1, cps) = run(block);
                assert_eq!((j1, stored1, cps), (j0, 0, len.div_ceil(block)));
                let dx = (&xs1 - &xs0).amax() / xs0.amax();
                let du = (&us1 - &us0).amax() / us0.amax();
                assert!(
                    dx <= 1e-10 && du <= 1e-10,
                    "passes {passes}, block {block}: states {dx:e}, forces {du:e}"
                );
            }
        }
    }

    #[allow(clippy::too_many_arguments)]
    fn check_dense(
        sm: &SampledModel,
        lm: &LiftedModel,
        known: &DMatrix<f64>,
        measured: &DMatrix<f64>,
        channels: &[(Quantity, usize)],
        s: &LiftedSettings,
        states: &DMatrix<f64>,
        us: &DMatrix<f64>,
        mult: &dyn Fn(usize, usize) -> f64,
    ) {
        let (n, r, len) = (sm.n, s.resolution, measured.ncols());
        let (cy, dy) = sm.outputs(channels).unwrap();
        // dense: z = [x0; u_0; …; u_{N−1}]
        let (nx, nu) = (2 * n, n * r);
        let nz = nx + nu * len;
        let w = rms_weights(measured, s.noise_fraction).unwrap();
        // x_k = X_k z + x_k^c
        let mut xm = DMatrix::zeros(nx, nz);
        xm.columns_mut(0, nx).fill_with_identity();
        let mut xc = DVector::zeros(nx);
        let mut rows: Vec<(DVector<f64>, f64)> = vec![];
        for k in 0..len {
            for c in 0..2 {
                let mut row = (cy.row(c) * &xm).transpose() * w[c];
                for j in 0..n {
                    row[nx + k * nu + j] += dy[(c, j)] * w[c];
                }
                let rhs = w[c]
                    * (measured[(c, k)] - (cy.row(c) * &xc)[0] - (dy.row(c) * known.column(k))[0]);
                rows.push((row, rhs));
            }
            if k + 1 < len {
                let mut xm2 = &lm.a * &xm;
                let mut gz = DMatrix::zeros(nx, nz);
                gz.columns_mut(nx + k * nu, nu).copy_from(&lm.g);
                xm2 += gz;
                xc = &lm.a * &xc + &lm.bg0 * known.column(k) + &lm.bg1 * known.column(k + 1);
                xm = xm2;
            }
        }
        for i in 0..nu * len {
            let mut row = DVector::zeros(nz);
            row[nx + i] = (s.lambda / r as f64 * mult(i % nu, i / nu)).sqrt();
            rows.push((row, 0.0));
        }
        for i in 0..nx {
            let mut row = DVector::zeros(nz);
            row[i] = 1.0 / if i < n { s.x0_std.0 } else { s.x0_std.1 };
            rows.push((row, 0.0));
        }
        let amat = DMatrix::from_fn(rows.len(), nz, |i, j| rows[i].0[j]);
        let b = DVector::from_fn(rows.len(), |i, _| rows[i].1);
        let z = amat.svd(true, true).solve(&b, 1e-14).unwrap();
        // compare the forces and the states
        for k in 0..len {
            for j in 0..r {
                for i in 0..n {
                    let d = z[nx + k * nu + j * n + i];
                    let f = us[(j * n + i, k)];
                    assert!(
                        (d - f).abs() < 1e-7 * (1.0 + d.abs()),
                        "f[{i},{k},{j}] {d} vs {f}"
                    );
                }
            }
        }
        let mut x = z.rows(0, nx).into_owned();
        for k in 0..len {
            for i in 0..nx {
                assert!(
                    (x[i] - states[(i, k)]).abs() < 1e-7 * (1e-3 + x[i].abs()),
                    "x[{i},{k}]"
                );
            }
            if k + 1 < len {
                let u = z.rows(nx + k * nu, nu);
                x = &lm.a * &x
                    + &lm.g * u
                    + &lm.bg0 * known.column(k)
                    + &lm.bg1 * known.column(k + 1);
            }
        }
    }

    #[test]
    fn the_initial_state_leaves_directions_below_rounding_to_the_prior() {
        // eigenvalues 1e6, 2 and −1e-8 (rounding of the 1e6 one)
        let q = DMatrix::from_row_slice(3, 3, &[0.6, 0.8, 0.0, -0.8, 0.6, 0.0, 0.0, 0.0, 1.0]);
        let d = DMatrix::from_diagonal(&DVector::from_vec(vec![1e6, 2.0, -1e-8]));
        let h = &q * d * q.transpose();
        let rhs = DVector::from_vec(vec![1.0, 2.0, 3.0]);
        let (x, dropped) = initial_state(h.clone(), &rhs).unwrap();
        assert_eq!(dropped, 1);
        // the solution on the two determined directions, 0 on the third
        let c = q.tr_mul(&rhs);
        let want = q.column(0) * (c[0] / 1e6) + q.column(1) * (c[1] / 2.0);
        // (h carries rounding of 1e6 ε ≈ 1e-10)
        assert!((&x - &want).amax() < 1e-8, "{x} vs {want}");
        // a negative eigenvalue beyond rounding is an error with its facts
        let d = DMatrix::from_diagonal(&DVector::from_vec(vec![1e6, 2.0, -1.0]));
        let e = initial_state(&q * d * q.transpose(), &rhs)
            .unwrap_err()
            .to_string();
        assert!(e.contains("-1.000e0") && e.contains("1.000e6"), "{e}");
    }

    #[test]
    fn settings_are_checked() {
        assert!(LiftedSettings::default().validate().is_ok());
        let e = LiftedSettings {
            resolution: 0,
            ..Default::default()
        }
        .validate()
        .unwrap_err()
        .to_string();
        assert!(e.contains("resolution = 0"), "{e}");
        assert!(LiftedSettings {
            lambda: 0.0,
            ..Default::default()
        }
        .validate()
        .is_err());
        assert!(LiftedSettings {
            reweight_floor: 0.0,
            ..Default::default()
        }
        .validate()
        .is_err());
        assert!(LiftedSettings {
            x0_std: (1.0, f64::INFINITY),
            ..Default::default()
        }
        .validate()
        .is_err());
    }

    #[test]
    fn a_pair_force_is_recovered_along_its_direction_and_misfits_elsewhere() {
        let n = 3;
        let sm = chain(n);
        let len = 400;
        // an equal and opposite smooth force on DOFs 0 and 1
        let w: Vec<f64> = (0..len)
            .map(|k| {
                let t = k as f64 / sm.fs;
                3.0 * (5.0 * t).sin() + 1.5 * (2.0 * t).cos()
            })
            .collect();
        let known = DMatrix::from_fn(
            n,
            len,
            |i, k| if i == 2 { (k as f64 * 0.3).sin() } else { 0.0 },
        );
        let mut total = known.clone();
        for k in 0..len {
            total[(0, k)] += w[k];
            total[(1, k)] -= w[k];
        }
        let xs = sm.simulate(&DVector::zeros(2 * n), &total);
        // displacements: a slow pair force is nearly static, and a static
        // pair force leaves accelerations unchanged
        let channels = vec![(Quantity::Disp, 0), (Quantity::Disp, 2)];
        let (cy, dy) = sm.outputs(&channels).unwrap();
        let measured = &cy * &xs + &dy * &total;
        let s = LiftedSettings {
            resolution: 4,
            lambda: 1e-3,
            reweight_passes: 0,
            ..Default::default()
        };
        let along = |e: Vec<f64>| {
            let e = DMatrix::from_column_slice(n, 1, &e);
            reconstruct_along(&sm, &e, &known, &measured, &channels, &s).unwrap()
        };
        let right = along(vec![1.0, -1.0, 0.0]);
        let wrong = along(vec![0.0, 1.0, -1.0]);
        // the force is exactly equal and opposite, zero at DOF 2
        for k in 0..len {
            assert_eq!(right.force[(0, k)], -right.force[(1, k)]);
            assert_eq!(right.force[(2, k)], 0.0);
        }
        // and matches the truth away from the ends (mean over a sample of a
        // force linear between samples)
        let (mut num, mut den) = (0.0, 0.0);
        for k in 20..len - 20 {
            let truth = 0.5 * (w[k] + w[k + 1]);
            num += (right.force[(0, k)] - truth).powi(2);
            den += truth * truth;
        }
        let rel = (num / den).sqrt();
        assert!(rel < 0.05, "force error {rel}");
        assert!(
            wrong.weighted_rms > 20.0 * right.weighted_rms,
            "right {} wrong {}",
            right.weighted_rms,
            wrong.weighted_rms
        );
        // no direction: a plain smoother, which cannot fit either
        let none = reconstruct_along(&sm, &DMatrix::zeros(n, 0), &known, &measured, &channels, &s)
            .unwrap();
        assert!(none.force.iter().all(|&f| f == 0.0));
        assert!(none.weighted_rms > 20.0 * right.weighted_rms);
    }

    /// A record of the chain with a pulsed force at the measured DOF 0,
    /// a known force at DOF 2, accelerations at every DOF with 1 % white
    /// noise (seeded): the channels, the known force and the outputs.
    fn pulsed(
        sm: &SampledModel,
        len: usize,
    ) -> (Vec<(Quantity, usize)>, DMatrix<f64>, DMatrix<f64>) {
        use rand::SeedableRng;
        use rand_distr::{Distribution, StandardNormal};
        let n = sm.n;
        let known = DMatrix::from_fn(n, len, |i, k| {
            let t = k as f64 / sm.fs;
            if i == 2 {
                10.0 * ((37.0 * t).sin() + 0.7 * (83.0 * t).cos())
            } else {
                0.0
            }
        });
        let mut all = known.clone();
        for k in 0..len {
            all[(0, k)] = if (k / 5) % 6 == 0 { 3.0 } else { 0.0 };
        }
        let xs = sm.simulate(&DVector::zeros(2 * n), &all);
        let channels: Vec<_> = (0..n).map(|i| (Quantity::Accel, i)).collect();
        let (cy, dy) = sm.outputs(&channels).unwrap();
        let mut y = &cy * &xs + &dy * &all;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        for mut row in y.row_iter_mut() {
            let rms = (row.norm_squared() / len as f64).sqrt();
            for v in row.iter_mut() {
                let e: f64 = StandardNormal.sample(&mut rng);
                *v += 0.01 * rms * e;
            }
        }
        (channels, known, y)
    }

    /// The floor on the residual: a force along DOF 0 (measured) at the
    /// default weight follows the noise (residual 0.24 of it); the
    /// weight is raised by √10 steps to the first that leaves at least
    /// half, the residual growing with it. From 1e-6 no weight of the grid
    /// reaches it (0.24 at 1e-2): the weight stays, as it does with the
    /// floor at 0 or with no direction.
    #[test]
    fn weight_is_raised_until_the_residual_reaches_the_floor() {
        let sm = chain(3);
        let (channels, known, y) = pulsed(&sm, 1200);
        let e0 = DMatrix::from_fn(3, 1, |i, _| if i == 0 { 1.0 } else { 0.0 });
        let s = LiftedSettings::default();
        let (lambda, tried) = floor_lambda(&sm, &e0, &known, &y, &channels, &s).unwrap();
        assert!(tried.len() >= 2 && tried[0].1 < 0.5, "{tried:?}");
        for (k, w) in tried.windows(2).enumerate() {
            assert!(w[1].1 > w[0].1, "residual not growing with λ: {tried:?}");
            assert!((w[1].0 / w[0].0 - 10f64.sqrt()).abs() < 1e-9, "step {k}");
        }
        let last = *tried.last().unwrap();
        assert_eq!(lambda, last.0);
        assert!(last.1 >= 0.5 && tried[tried.len() - 2].1 < 0.5, "{tried:?}");
        let r = reconstruct_floored(&sm, &e0, &known, &y, &channels, &s).unwrap();
        assert_eq!(r.lambda, lambda);
        assert!(r.status.contains("raised"), "{}", r.status);
        // no weight reaches the floor from 1e-6 (up to 1e-2): λ as given
        let weak = LiftedSettings {
            lambda: 1e-6,
            ..s.clone()
        };
        let (kept, tried) = floor_lambda(&sm, &e0, &known, &y, &channels, &weak).unwrap();
        assert_eq!(tried.len(), FLOOR_STEPS + 1);
        assert!(tried.iter().all(|t| t.1 < 0.5), "{tried:?}");
        assert_eq!(kept, 1e-6);
        let r = reconstruct_floored(&sm, &e0, &known, &y, &channels, &weak).unwrap();
        assert_eq!(r.lambda, 1e-6);
        assert!(r.status.contains("kept at 1.00e-6"), "{}", r.status);
        // the floor off, or no direction: λ as given, nothing tried
        let off = LiftedSettings {
            min_residual: 0.0,
            ..s.clone()
        };
        let kept = floor_lambda(&sm, &e0, &known, &y, &channels, &off).unwrap();
        assert_eq!(kept, (1e-2, vec![]));
        let none = DMatrix::zeros(3, 0);
        let kept = floor_lambda(&sm, &none, &known, &y, &channels, &s).unwrap();
        assert_eq!(kept, (1e-2, vec![]));
        let bad = LiftedSettings {
            min_residual: 1.0,
            ..s
        };
        assert!(floor_lambda(&sm, &e0, &known, &y, &channels, &bad).is_err());
    }
}
