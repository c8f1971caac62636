//! The data of one identification and its internal, scaled linear-quadratic
//! form.
//!
//! With `g_k` the known (measured) force at the model DOFs, `w_k` the
//! unknown force coefficients and `B_u` their input matrix, the model is
//! the exact Newmark map with the force linear between samples
//! ([`crate::linear::SampledModel`]):
//!
//! $$ x_{k+1} = A x_k + B_0 (g_k + B_u w_k) + B_1 (g_{k+1} + B_u w_{k+1}),\quad
//!    y_k = C_y x_k + D_y (g_k + B_u w_k). $$
//!
//! The force carries the same interpolation in the dynamics and in the
//! output equation (the remedy of docs/theory.md, fact R7). The smoother's state
//! is `s_k = [x_k; w_k]`; the "control" of step `k` is `w_{k+1}`:
//! `s_{k+1} = F s_k + G w_{k+1} + c_k` with `F = [A, B_0 B_u; 0, 0]`,
//! `G = [B_1 B_u; I]`, `c_k = [B_0 g_k + B_1 g_{k+1}; 0]`.
//!
//! Internally the state is scaled, `s = D s̃` with `D = diag(1/ω, 1, m ω)`
//! for (displacement, velocity, force) and ω, m a reference frequency and
//! mass of the model, and every output row is multiplied by `W^{1/2}`, so
//! the Riccati matrices are balanced and `W = I`.

use super::settings::{ChannelNoise, HorizonSettings, InitialState};
use crate::error::{Result, TacitError};
use crate::linear::SampledModel;
use crate::record::Quantity;
use nalgebra::{DMatrix, DVector};

/// The measured data of one identification, borrowed.
#[derive(Debug, Clone, Copy)]
pub struct HorizonData<'a> {
    /// Known (measured) external force at every model DOF, `n × N`:
    /// the `g` of `M a + C v + K u = g + B_u w`.
    pub known_force: &'a DMatrix<f64>,
    /// Measured outputs, `p × N`, one row per channel.
    pub measured: &'a DMatrix<f64>,
    /// `(quantity, dof0)` of every row of `measured` (DOFs 0-based).
    pub channels: &'a [(Quantity, usize)],
    /// Unknown-force input matrix `B_u`, `n × n_f`: the DOF forces are
    /// `B_u w_k`. Columns of the identity select DOFs
    /// ([`unknown_at_dofs`]); a column `e_i − e_j` is an action–reaction
    /// pair.
    pub unknown: &'a DMatrix<f64>,
}

/// `B_u` that puts one unknown force at each of `dofs` (0-based).
pub fn unknown_at_dofs(n: usize, dofs: &[usize]) -> Result<DMatrix<f64>> {
    let mut b = DMatrix::zeros(n, dofs.len());
    for (j, &d) in dofs.iter().enumerate() {
        if d >= n {
            return Err(TacitError::Setting(format!(
                "horizon: unknown-force DOF {} is outside the model (1..={n})",
                d + 1
            )));
        }
        b[(d, j)] = 1.0;
    }
    Ok(b)
}

/// How the initial state enters the scaled problem.
#[derive(Debug, Clone)]
pub(crate) enum Init {
    /// `x̃_0` fixed.
    Fixed(DVector<f64>),
    /// Prior `(x̃_0 − m)ᵀ P (x̃_0 − m)`.
    Prior {
        /// Weight (nx × nx).
        p: DMatrix<f64>,
        /// Mean (nx).
        mean: DVector<f64>,
    },
}

/// The scaled linear-quadratic problem (see the module docs).
#[derive(Debug, Clone)]
pub(crate) struct Lq {
    /// 2n.
    pub nx: usize,
    /// Number of unknown force components.
    pub m: usize,
    /// nx + m.
    pub ns: usize,
    /// Number of channels.
    pub p: usize,
    /// Number of samples.
    pub len: usize,
    /// F (ns × ns).
    pub f: DMatrix<f64>,
    /// G (ns × m).
    pub g: DMatrix<f64>,
    /// `W^{1/2} [C_y, D_y B_u]`, scaled (p × ns).
    pub ch: DMatrix<f64>,
    /// Scaled λ.
    pub lambda: f64,
    /// Scaled μ.
    pub mu: f64,
    /// `W^{1/2} (y_k − D_y g_k)` (p × N).
    pub target: DMatrix<f64>,
    /// Known inputs that are not identically zero (n_in × N).
    pub gin: DMatrix<f64>,
    /// `[B_0 S_in; 0]`, scaled (ns × n_in).
    pub bc0: DMatrix<f64>,
    /// `[B_1 S_in; 0]`, scaled (ns × n_in).
    pub bc1: DMatrix<f64>,
    /// Initial state.
    pub init: Init,
    /// Scaling `s = D s̃` (ns).
    pub d: DVector<f64>,
    /// `W^{1/2}` per channel (p).
    pub wsqrt: DVector<f64>,
    /// Orthonormal basis (scaled coordinates, ns × q) of the states the
    /// data cannot see: rigid-body positions (and velocities) of a model
    /// with `K r = C r = 0` when no displacement (velocity) channel sees
    /// them. The exact cost-to-go vanishes on them; the sweep splits them
    /// off exactly ([`super::basis`]) so that rounding does not couple them
    /// back.
    pub hidden: DMatrix<f64>,
}

impl Lq {
    /// Build and check sizes; `lambda`, `mu` are the physical weights.
    pub fn new(
        model: &SampledModel,
        data: &HorizonData<'_>,
        settings: &HorizonSettings,
        lambda: f64,
        mu: f64,
    ) -> Result<Lq> {
        let (n, len) = check_sizes(model, data)?;
        let (nx, m, p) = (2 * n, data.unknown.ncols(), data.channels.len());
        let ns = nx + m;
        let wsqrt = noise_weights(data.measured, &settings.noise)?;
        let d = scaling(model, m);
        let (cy, dy) = model.outputs(data.channels)?;
        let bu = data.unknown;
        let mut f = DMatrix::zeros(ns, ns);
        f.view_mut((0, 0), (nx, nx)).copy_from(&model.a);
        f.view_mut((0, nx), (nx, m)).copy_from(&(&model.b0 * bu));
        let mut g = DMatrix::zeros(ns, m);
        g.view_mut((0, 0), (nx, m)).copy_from(&(&model.b1 * bu));
        g.view_mut((nx, 0), (m, m)).fill_with_identity();
        let mut ch = DMatrix::zeros(p, ns);
        ch.view_mut((0, 0), (p, nx)).copy_from(&cy);
        ch.view_mut((0, nx), (p, m)).copy_from(&(&dy * bu));
        let dw = d[nx];
        let dinv = d.map(|v| 1.0 / v);
        for i in 0..ns {
            for j in 0..ns {
                f[(i, j)] *= dinv[i] * d[j];
            }
            for j in 0..m {
                g[(i, j)] *= dinv[i] * d[nx + j];
            }
        }
        for r in 0..p {
            for j in 0..ns {
                ch[(r, j)] *= wsqrt[r] * d[j];
            }
        }
        // known inputs: keep the DOFs that carry a force
        let in_dofs: Vec<usize> = (0..n)
            .filter(|&i| data.known_force.row(i).iter().any(|v| *v != 0.0))
            .collect();
        let n_in = in_dofs.len();
        let mut gin = DMatrix::zeros(n_in, len);
        let mut bc0 = DMatrix::zeros(ns, n_in);
        let mut bc1 = DMatrix::zeros(ns, n_in);
        for (j, &i) in in_dofs.iter().enumerate() {
            gin.row_mut(j).copy_from(&data.known_force.row(i));
            for r in 0..nx {
                bc0[(r, j)] = model.b0[(r, i)] * dinv[r];
                bc1[(r, j)] = model.b1[(r, i)] * dinv[r];
            }
        }
        let mut target = data.measured.clone();
        let (dyv, gv) = (
            crate::riccati::dense::view(&dy),
            crate::riccati::dense::view(data.known_force),
        );
        crate::riccati::dense::mul(
            crate::riccati::dense::view_mut(&mut target),
            true,
            dyv,
            gv,
            -1.0,
        );
        for col in target.as_mut_slice().chunks_exact_mut(p) {
            col.iter_mut().zip(wsqrt.iter()).for_each(|(v, w)| *v *= w);
        }
        let init = initial(&settings.initial, nx, &d)?;
        let hidden = hidden_directions(model, data.channels, &d, ns);
        Ok(Lq {
            nx,
            m,
            ns,
            p,
            len,
            f,
            g,
            ch,
            lambda: lambda * dw * dw,
            mu: mu * dw * dw,
            target,
            gin,
            bc0,
            bc1,
            init,
            d,
            wsqrt,
            hidden,
        })
    }

    /// `c_k` (scaled, ns) added into `out`.
    pub fn add_c(&self, k: usize, out: &mut [f64]) {
        for j in 0..self.gin.nrows() {
            let (g0, g1) = (self.gin[(j, k)], self.gin[(j, k + 1)]);
            let (c0, c1) = (self.bc0.column(j), self.bc1.column(j));
            for r in 0..self.nx {
                out[r] += c0[r] * g0 + c1[r] * g1;
            }
        }
    }

    /// The scaled stage weight `ĈᵀĈ + λ JᵀJ` (ns × ns).
    pub fn stage_weight(&self) -> DMatrix<f64> {
        let mut q = self.ch.transpose() * &self.ch;
        for i in 0..self.m {
            q[(self.nx + i, self.nx + i)] += self.lambda;
        }
        q
    }
}

fn check_sizes(model: &SampledModel, data: &HorizonData<'_>) -> Result<(usize, usize)> {
    let n = model.n;
    let len = data.measured.ncols();
    let bad = |m: String| Err(TacitError::Setting(format!("horizon: {m}")));
    if len < 2 {
        return bad(format!(
            "the record has {len} samples, at least 2 are needed"
        ));
    }
    if data.measured.nrows() != data.channels.len() || data.channels.is_empty() {
        return bad(format!(
            "{} measured rows but {} channels (at least one needed)",
            data.measured.nrows(),
            data.channels.len()
        ));
    }
    if data.known_force.nrows() != n || data.known_force.ncols() != len {
        return bad(format!(
            "known force is {}×{}, expected {n}×{len} (DOFs × samples)",
            data.known_force.nrows(),
            data.known_force.ncols()
        ));
    }
    if data.unknown.nrows() != n || data.unknown.ncols() == 0 {
        return bad(format!(
            "unknown-force input matrix is {}×{}, expected {n}×n_f with n_f >= 1",
            data.unknown.nrows(),
            data.unknown.ncols()
        ));
    }
    if let Some(i) = data.measured.iter().position(|v| !v.is_finite()) {
        return bad(format!(
            "measured value of channel {} at sample {} is not finite",
            i % data.measured.nrows(),
            i / data.measured.nrows()
        ));
    }
    if data.known_force.iter().any(|v| !v.is_finite())
        || data.unknown.iter().any(|v| !v.is_finite())
    {
        return bad("the known force or the input matrix holds a non-finite value".into());
    }
    Ok((n, len))
}

/// `W^{1/2}` per channel from the assumed channel noise.
pub(crate) fn noise_weights(y: &DMatrix<f64>, noise: &ChannelNoise) -> Result<DVector<f64>> {
    let p = y.nrows();
    match noise {
        ChannelNoise::RmsFraction { fraction } => {
            let w = crate::signal::channel_weights(y, *fraction);
            match w.iter().position(Option::is_none) {
                Some(r) => Err(TacitError::Setting(format!(
                    "horizon: channel {r} is identically zero, so a noise level relative to its RMS is undefined; give the noise std"
                ))),
                None => Ok(DVector::from_iterator(p, w.into_iter().flatten())),
            }
        }
        ChannelNoise::Std { std } => {
            if std.len() != p {
                return Err(TacitError::Setting(format!(
                    "horizon: {} noise std values for {p} channels",
                    std.len()
                )));
            }
            Ok(DVector::from_iterator(p, std.iter().map(|s| 1.0 / s)))
        }
    }
}

/// The state scaling `D`: displacement × ω, force / (m ω) (velocity units).
fn scaling(model: &SampledModel, m: usize) -> DVector<f64> {
    let n = model.n;
    let (omega, mref) = model.reference_scales();
    let mut d = DVector::from_element(2 * n + m, 1.0);
    for i in 0..n {
        d[i] = 1.0 / omega;
    }
    for i in 0..m {
        d[2 * n + i] = mref * omega;
    }
    d
}

fn initial(init: &InitialState, nx: usize, d: &DVector<f64>) -> Result<Init> {
    match init {
        InitialState::Rest => Ok(Init::Fixed(DVector::zeros(nx))),
        InitialState::Known { x0 } => {
            if x0.len() != nx {
                return Err(TacitError::Setting(format!(
                    "horizon: the known initial state has {} values, expected {nx} ([u0; v0])",
                    x0.len()
                )));
            }
            Ok(Init::Fixed(DVector::from_fn(nx, |i, _| x0[i] / d[i])))
        }
        InitialState::Estimate {
            mean,
            std_disp,
            std_vel,
        } => {
            if !(mean.is_empty() || mean.len() == nx) {
                return Err(TacitError::Setting(format!(
                    "horizon: the initial-state prior mean has {} values, expected {nx}",
                    mean.len()
                )));
            }
            let n = nx / 2;
            let mut p = DMatrix::zeros(nx, nx);
            let mut mv = DVector::zeros(nx);
            for i in 0..nx {
                let s = if i < n { *std_disp } else { *std_vel };
                p[(i, i)] = d[i] * d[i] / (s * s);
                if !mean.is_empty() {
                    mv[i] = mean[i] / d[i];
                }
            }
            Ok(Init::Prior { p, mean: mv })
        }
    }
}

/// Rigid-body directions the channels do not see (see [`Lq::hidden`]).
fn hidden_directions(
    model: &SampledModel,
    channels: &[(Quantity, usize)],
    d: &DVector<f64>,
    ns: usize,
) -> DMatrix<f64> {
    let n = model.n;
    let eig = model.k.clone().symmetric_eigen();
    let kmax = eig.eigenvalues.amax();
    let cmax = model.c.amax();
    let mut dirs: Vec<DVector<f64>> = Vec::new();
    for (i, &ev) in eig.eigenvalues.iter().enumerate() {
        let r = eig.eigenvectors.column(i).into_owned();
        if ev.abs() > 1e-10 * kmax || (&model.c * &r).amax() > 1e-10 * cmax.max(1e-300) {
            continue;
        }
        let seen = |q: Quantity| {
            channels
                .iter()
                .any(|&(cq, dof)| cq == q && r[dof].abs() > 1e-8 * r.amax())
        };
        let (disp_seen, vel_seen) = (seen(Quantity::Disp), seen(Quantity::Vel));
        if !disp_seen {
            let mut v = DVector::zeros(ns);
            for j in 0..n {
                v[j] = r[j] / d[j];
            }
            dirs.push(v);
            if !vel_seen {
                let mut v = DVector::zeros(ns);
                for j in 0..n {
                    v[n + j] = r[j] / d[n + j];
                }
                dirs.push(v);
            }
        }
    }
    // Gram–Schmidt (twice) in the scaled coordinates
    let mut basis: Vec<DVector<f64>> = Vec::new();
    for mut v in dirs {
        for _ in 0..2 {
            for b in &basis {
                let a = b.dot(&v);
                v -= b * a;
            }
        }
        let nv = v.norm();
        if nv > 1e-8 {
            basis.push(v / nv);
        }
    }
    let mut u = DMatrix::zeros(ns, basis.len());
    for (j, b) in basis.iter().enumerate() {
        u.set_column(j, b);
    }
    u
}
