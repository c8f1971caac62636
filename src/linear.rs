//! The sampled linear model: the Newmark average-acceleration integrator
//! applied to `M ü + C u̇ + K u = f(t)`, with `S` sub-steps per sample and
//! the force linear between samples, written as an exact discrete map over
//! one sample on the state `x = [u; v]`:
//!
//! $$ x_{k+1} = A x_k + B_0 f_k + B_1 f_{k+1} $$
//!
//! (the acceleration is not a state: Newmark enforces equilibrium at every
//! sub-step, so `a_k = M⁻¹ (f_k − C v_k − K u_k)`). Measured outputs are
//! `y_k = C_y x_k + D_y f_k`. This is the same integrator as
//! [`crate::integrate::Integrator`] with no nonlinear element, so the window
//! and full-horizon identifications see exactly the simulator's dynamics.

use crate::error::{Result, TacitError};
use crate::record::Quantity;
use nalgebra::{DMatrix, DVector};

/// One sample of the linear Newmark map.
#[derive(Debug, Clone)]
pub struct SampledModel {
    /// Number of DOFs.
    pub n: usize,
    /// Sample rate, Hz.
    pub fs: f64,
    /// Sub-steps per sample.
    pub substeps: usize,
    /// State transition (2n × 2n).
    pub a: DMatrix<f64>,
    /// Input matrix of the force at the start of the sample (2n × n).
    pub b0: DMatrix<f64>,
    /// Input matrix of the force at the end of the sample (2n × n).
    pub b1: DMatrix<f64>,
    /// Mass matrix.
    pub m: DMatrix<f64>,
    /// Damping matrix.
    pub c: DMatrix<f64>,
    /// Stiffness matrix.
    pub k: DMatrix<f64>,
    /// M⁻¹.
    pub m_inv: DMatrix<f64>,
}

impl SampledModel {
    /// Build from matrices.
    pub fn new(
        m: DMatrix<f64>,
        c: DMatrix<f64>,
        k: DMatrix<f64>,
        fs: f64,
        substeps: usize,
    ) -> Result<SampledModel> {
        let n = m.nrows();
        if substeps < 1 || !(fs > 0.0) {
            return Err(TacitError::Setting(format!(
                "sampled model: substeps = {substeps} must be >= 1 and fs = {fs} > 0"
            )));
        }
        let m_inv = m.clone().try_inverse().ok_or_else(|| {
            TacitError::Numerical("sampled model: the mass matrix is singular".into())
        })?;
        let h = 1.0 / (fs * substeps as f64);
        let (gamma, beta) = (0.5, 0.25);
        let a0 = 1.0 / (beta * h * h);
        let a1 = gamma / (beta * h);
        let j0 = &m * a0 + &c * a1 + &k;
        let lu = j0.lu();
        // propagate the 2n + 2n unit inputs through S sub-steps
        let cols = 4 * n;
        let mut u = DMatrix::zeros(n, cols);
        let mut v = DMatrix::zeros(n, cols);
        let mut f0 = DMatrix::zeros(n, cols);
        let mut f1 = DMatrix::zeros(n, cols);
        for i in 0..n {
            u[(i, i)] = 1.0;
            v[(i, n + i)] = 1.0;
            f0[(i, 2 * n + i)] = 1.0;
            f1[(i, 3 * n + i)] = 1.0;
        }
        let mut acc = &m_inv * (&f0 - &c * &v - &k * &u);
        for j in 0..substeps {
            let th = (j + 1) as f64 / substeps as f64;
            let fnext = &f0 * (1.0 - th) + &f1 * th;
            let rhs = &fnext
                + &m * (&u * a0 + &v * (1.0 / (beta * h)) + &acc * (0.5 / beta - 1.0))
                + &c * (&u * a1
                    + &v * (gamma / beta - 1.0)
                    + &acc * (h * (gamma / (2.0 * beta) - 1.0)));
            let un = lu.solve(&rhs).ok_or_else(|| {
                TacitError::Numerical("sampled model: the Newmark matrix is singular".into())
            })?;
            let an = (&un - &u) * a0 - &v * (1.0 / (beta * h)) - &acc * (0.5 / beta - 1.0);
            let vn = &v + (&acc * (1.0 - gamma) + &an * gamma) * h;
            u = un;
            v = vn;
            acc = an;
        }
        let mut x = DMatrix::zeros(2 * n, cols);
        x.rows_mut(0, n).copy_from(&u);
        x.rows_mut(n, n).copy_from(&v);
        Ok(SampledModel {
            n,
            fs,
            substeps,
            a: x.columns(0, 2 * n).into_owned(),
            b0: x.columns(2 * n, n).into_owned(),
            b1: x.columns(3 * n, n).into_owned(),
            m,
            c,
            k,
            m_inv,
        })
    }

    /// Build from a model's linear part.
    pub fn from_model(
        model: &crate::model::Model,
        fs: f64,
        substeps: usize,
    ) -> Result<SampledModel> {
        SampledModel::new(
            model.mass_matrix(),
            model.damping_matrix()?,
            model.stiffness_matrix(),
            fs,
            substeps,
        )
    }

    /// Reference frequency ω (rad/s) and mass (kg) that balance state and
    /// force scales: ω the largest `sqrt(|(M⁻¹K)_ii|)` (or `2π f_s / 10`
    /// when the model has no stiffness), the mass the mean `|M_ii|` (or 1).
    /// Displacements × ω and forces / (m ω) then have velocity units.
    pub fn reference_scales(&self) -> (f64, f64) {
        let n = self.n;
        let mk = &self.m_inv * &self.k;
        let wmax = (0..n).map(|i| mk[(i, i)].abs()).fold(0.0, f64::max).sqrt();
        let omega = if wmax > 0.0 {
            wmax
        } else {
            2.0 * std::f64::consts::PI * self.fs / 10.0
        };
        let mref = (0..n).map(|i| self.m[(i, i)].abs()).sum::<f64>() / n as f64;
        (omega, if mref > 0.0 { mref } else { 1.0 })
    }

    /// Diagonal state scaling to velocity units, `[1/ω …; 1 …]` (2n) with ω
    /// from [`SampledModel::reference_scales`]: scaled states `x_i / d_i`.
    pub fn state_scale(&self) -> DVector<f64> {
        let (omega, _) = self.reference_scales();
        let n = self.n;
        DVector::from_fn(2 * n, |i, _| if i < n { 1.0 / omega } else { 1.0 })
    }

    /// Output rows for measured channels `(quantity, dof0)`:
    /// `y_k = C_y x_k + D_y f_k` (p × 2n and p × n).
    pub fn outputs(&self, channels: &[(Quantity, usize)]) -> Result<(DMatrix<f64>, DMatrix<f64>)> {
        let n = self.n;
        let p = channels.len();
        let mut cy = DMatrix::zeros(p, 2 * n);
        let mut dy = DMatrix::zeros(p, n);
        let mk = &self.m_inv * &self.k;
        let mc = &self.m_inv * &self.c;
        for (r, &(q, d)) in channels.iter().enumerate() {
            if d >= n {
                return Err(TacitError::Setting(format!(
                    "output DOF {} is outside the model (1..={n})",
                    d + 1
                )));
            }
            match q {
                Quantity::Disp => cy[(r, d)] = 1.0,
                Quantity::Vel => cy[(r, n + d)] = 1.0,
                Quantity::Accel => {
                    for j in 0..n {
                        cy[(r, j)] = -mk[(d, j)];
                        cy[(r, n + j)] = -mc[(d, j)];
                        dy[(r, j)] = self.m_inv[(d, j)];
                    }
                }
                Quantity::Force => {
                    return Err(TacitError::Setting(
                        "a force is not a measured output".into(),
                    ))
                }
            }
        }
        Ok((cy, dy))
    }

    /// One sample: `A x + B0 f0 + B1 f1`.
    pub fn step(&self, x: &DVector<f64>, f0: &DVector<f64>, f1: &DVector<f64>) -> DVector<f64> {
        &self.a * x + &self.b0 * f0 + &self.b1 * f1
    }

    /// States at every sample (2n × N) from `x0` under `f` (n × N).
    pub fn simulate(&self, x0: &DVector<f64>, f: &DMatrix<f64>) -> DMatrix<f64> {
        let ns = f.ncols();
        let mut xs = DMatrix::zeros(2 * self.n, ns);
        if ns == 0 {
            return xs;
        }
        xs.set_column(0, x0);
        for k in 1..ns {
            let x =
                &self.a * xs.column(k - 1) + &self.b0 * f.column(k - 1) + &self.b1 * f.column(k);
            xs.set_column(k, &x);
        }
        xs
    }

    /// Input matrices of the force at the `S + 1` sub-step nodes of one
    /// sample, for a force linear between sub-steps (not between samples):
    /// `x_{k+1} = A x_k + Σ_j N_j f(t_k + j h)`. With a force linear over the
    /// sample they sum to `B0, B1` (`Σ_j N_j (1 − j/S) = B0`).
    pub fn node_inputs(&self) -> Result<Vec<DMatrix<f64>>> {
        let s = self.substeps;
        let sub = SampledModel::new(
            self.m.clone(),
            self.c.clone(),
            self.k.clone(),
            self.fs * s as f64,
            1,
        )?;
        // powers A_h^p, p = 0..S
        let mut pows = vec![DMatrix::identity(2 * self.n, 2 * self.n)];
        for p in 1..=s {
            let next = &sub.a * &pows[p - 1];
            pows.push(next);
        }
        Ok((0..=s)
            .map(|j| {
                let mut nj = DMatrix::zeros(2 * self.n, self.n);
                if j < s {
                    nj += &pows[s - 1 - j] * &sub.b0;
                }
                if j >= 1 {
                    nj += &pows[s - j] * &sub.b1;
                }
                nj
            })
            .collect())
    }

    /// Spectral radius of A (the free dynamics over one sample).
    pub fn spectral_radius(&self) -> f64 {
        spectral_radius(&self.a)
    }
}

/// Cubic Hermite upsampling of sampled states `[u; v]` (2n × N) to `s`
/// sub-steps per sample: returns 2n × ((N − 1) s + 1) with node `k s + j`
/// at `t_k + j/(s fs)`. Displacements use the values and slopes at both
/// ends; velocities are the derivative of the same cubic.
pub fn hermite_upsample(states: &DMatrix<f64>, fs: f64, s: usize) -> DMatrix<f64> {
    let n2 = states.nrows();
    let n = n2 / 2;
    let ns = states.ncols();
    if ns == 0 {
        return DMatrix::zeros(n2, 0);
    }
    let dt = 1.0 / fs;
    let mut out = DMatrix::zeros(n2, (ns - 1) * s + 1);
    out.set_column(0, &states.column(0));
    for k in 0..ns - 1 {
        for j in 1..=s {
            let t = j as f64 / s as f64;
            let (t2, t3) = (t * t, t * t * t);
            let (h00, h10, h01, h11) = (
                2.0 * t3 - 3.0 * t2 + 1.0,
                t3 - 2.0 * t2 + t,
                -2.0 * t3 + 3.0 * t2,
                t3 - t2,
            );
            let (d00, d10, d01, d11) = (
                6.0 * t2 - 6.0 * t,
                3.0 * t2 - 4.0 * t + 1.0,
                -6.0 * t2 + 6.0 * t,
                3.0 * t2 - 2.0 * t,
            );
            let col = k * s + j;
            for i in 0..n {
                let (u0, v0) = (states[(i, k)], states[(n + i, k)]);
                let (u1, v1) = (states[(i, k + 1)], states[(n + i, k + 1)]);
                out[(i, col)] = h00 * u0 + h10 * dt * v0 + h01 * u1 + h11 * dt * v1;
                out[(n + i, col)] = (d00 * u0 + d10 * dt * v0 + d01 * u1 + d11 * dt * v1) / dt;
            }
        }
    }
    out
}

/// Spectral radius of a square matrix (nalgebra's real Schur form).
pub fn spectral_radius(a: &DMatrix<f64>) -> f64 {
    a.complex_eigenvalues()
        .iter()
        .map(|z| z.norm())
        .fold(0.0, f64::max)
}

/// Orthonormal basis of the unobservable subspace of `(a, h)`: right
/// singular vectors of `[h; h a; …; h a^{nx−1}]` with singular values below
/// `1e-9` of the largest, kept to its part that `a` maps into itself
/// ([`invariant_part`]). The rank test alone takes a slow, observable mode
/// of a finely sampled model for an unobservable one (a 1-Hz mode at
/// 400 Hz: `a^k` for `k < nx` barely separates its displacement from its
/// velocity); an unobservable subspace is invariant, that direction is not.
pub fn unobservable(a: &DMatrix<f64>, h: &DMatrix<f64>) -> DMatrix<f64> {
    let (nx, p) = (a.nrows(), h.nrows());
    let mut obs = DMatrix::zeros(p * nx, nx);
    let mut blk = h.clone();
    for i in 0..nx {
        obs.rows_mut(i * p, p).copy_from(&blk);
        blk = &blk * a;
    }
    let svd = obs.svd(false, true);
    let vt = svd.v_t.expect("v_t was requested");
    let smax = svd.singular_values.max();
    let idx: Vec<usize> = (0..nx)
        .filter(|&i| !(svd.singular_values[i] > 1e-9 * smax))
        .collect();
    invariant_part(a, DMatrix::from_fn(nx, idx.len(), |r, c| vt[(idx[c], r)]))
}

/// The largest subspace of the span of `v` (orthonormal columns) that `a`
/// maps into that span, to `1e-9 ‖a‖_max` per unit vector: `v` itself
/// when it is invariant, else shrunk (`v ← v W`, `W` the right singular
/// vectors of `(I − v vᵀ) a v` with singular values below the bound) until
/// it is.
pub fn invariant_part(a: &DMatrix<f64>, mut v: DMatrix<f64>) -> DMatrix<f64> {
    let tol = 1e-9 * a.amax();
    while v.ncols() > 0 {
        let av = a * &v;
        let out = &av - &v * v.tr_mul(&av);
        let svd = out.svd(false, true);
        let vt = svd.v_t.expect("v_t was requested");
        let keep: Vec<usize> = (0..v.ncols())
            .filter(|&i| !(svd.singular_values[i] > tol))
            .collect();
        if keep.len() == v.ncols() {
            break;
        }
        let w = DMatrix::from_fn(v.ncols(), keep.len(), |r, c| vt[(keep[c], r)]);
        v = &v * w;
    }
    v
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_an_invariant_subspace_is_kept() {
        let (c, s) = (1e-3f64.cos(), 1e-3f64.sin());
        // a slow rotation in (x0, x1), a decoupled x2
        let a = DMatrix::from_row_slice(3, 3, &[c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 0.5]);
        // x1 alone is not invariant: dropped
        let v = DMatrix::from_column_slice(3, 1, &[0.0, 1.0, 0.0]);
        assert_eq!(invariant_part(&a, v).ncols(), 0);
        // x2 is: kept as given
        let v = DMatrix::from_column_slice(3, 1, &[0.0, 0.0, 1.0]);
        assert_eq!(invariant_part(&a, v.clone()), v);
        // x1 and x2: shrunk to x2
        let v = DMatrix::from_column_slice(3, 2, &[0.0, 1.0, 0.0, 0.0, 0.0, 1.0]);
        let w = invariant_part(&a, v);
        assert_eq!(w.ncols(), 1);
        assert!((w[(2, 0)].abs() - 1.0).abs() < 1e-12, "{w}");
        // a free mass under an accelerometer: position and velocity unseen
        let h = 1.0 / 100.0;
        let a = DMatrix::from_row_slice(2, 2, &[1.0, h, 0.0, 1.0]);
        let acc = DMatrix::from_row_slice(1, 2, &[0.0, 0.0]);
        assert_eq!(unobservable(&a, &acc).ncols(), 2);
    }
    use crate::integrate::{Integrator, SimSettings};
    use crate::model::Model;

    #[test]
    fn matches_the_integrator_exactly() {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/data/lanl8dof.toml");
        let model = Model::from_file(std::path::Path::new(path)).unwrap();
        let fs = 512.0;
        let sm = SampledModel::from_model(&model, fs, 10).unwrap();
        let integ = Integrator::new(&model, fs, SimSettings::default()).unwrap();
        let mut f = DMatrix::zeros(8, 300);
        let x = crate::signal::random_band(300, fs, (5.0, 200.0), 20.0, 3).unwrap();
        for k in 0..300 {
            f[(0, k)] = x[k];
            f[(5, k)] = -0.5 * x[(k + 7) % 300];
        }
        let mut u0 = vec![0.0; 8];
        u0[3] = 1e-4;
        let v0 = vec![0.01; 8];
        let sim = integ.run(f.as_view(), &u0, &v0);
        let mut x0 = DVector::zeros(16);
        x0.rows_mut(0, 8).copy_from_slice(&u0);
        x0.rows_mut(8, 8).copy_from_slice(&v0);
        let xs = sm.simulate(&x0, &f);
        let scale = sim.u.amax();
        assert!((xs.rows(0, 8) - &sim.u).amax() < 1e-9 * scale);
        let (cy, dy) = sm
            .outputs(&[(Quantity::Accel, 4), (Quantity::Vel, 2)])
            .unwrap();
        let y = &cy * &xs + &dy * &f;
        let ascale = sim.a.amax();
        for k in 0..300 {
            assert!((y[(0, k)] - sim.a[(4, k)]).abs() < 1e-8 * ascale);
            assert!((y[(1, k)] - sim.v[(2, k)]).abs() < 1e-8 * sim.v.amax());
        }
        // node inputs sum to B0 and B1 for a force linear over the sample
        let nodes = sm.node_inputs().unwrap();
        let s = nodes.len() - 1;
        let mut b0 = DMatrix::zeros(16, 8);
        let mut b1 = DMatrix::zeros(16, 8);
        for (j, nj) in nodes.iter().enumerate() {
            b0 += nj * (1.0 - j as f64 / s as f64);
            b1 += nj * (j as f64 / s as f64);
        }
        assert!((b0 - &sm.b0).amax() < 1e-9 * sm.b0.amax());
        assert!((b1 - &sm.b1).amax() < 1e-9 * sm.b1.amax());
        // free dynamics are stable (radius ≤ 1; the rigid-body mode gives 1)
        let r = sm.spectral_radius();
        // the rigid-body mode is a defective double eigenvalue 1: ~sqrt(eps) error
        assert!(r <= 1.0 + 1e-6 && r > 0.99, "radius {r}");
    }
}
