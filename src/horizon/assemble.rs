//! From the scaled states to the result: residuals, forces, physical
//! states, standard deviations and summaries.
//!
//! The states arrive by blocks of samples ([`Sink::push`]); the sweep's
//! forward pass pushes each block as it is computed, so the whole
//! `ns × N` state history is never stored. Every output is written once
//! into new memory (no zero fill first): at these sizes first-touch page
//! faults cost as much as the arithmetic. The forces overwrite the
//! feed-forward terms of the backward pass, the standard deviations the
//! variances.

use super::covariance::Covariance;
use super::problem::{Init, Lq};
use super::{
    CovarianceScale, Diagnostics, HorizonData, HorizonResult, HorizonSettings, HorizonStatus,
    SelectedWeights, Solver, Timings,
};
use crate::riccati::dense::{gemv_acc, mul, view, view_mut};
use faer::MatRef;
use nalgebra::{DMatrix, DVector};

/// Samples per block pushed by [`Sink::push_all`].
const BLOCK: usize = 256;

/// Collects the outputs from blocks of scaled states.
pub(crate) struct Sink<'a> {
    lq: &'a Lq,
    data: &'a HorizonData<'a>,
    /// Ĉ in the coordinates pushed (p × ns).
    ch: DMatrix<f64>,
    /// `W_x` when the states pushed are `z` (`s̃_x = W_x z_x`).
    wx: Option<DMatrix<f64>>,
    /// `W^{1/2}(y − ŷ)` then `y − ŷ` (p × N), filled from ỹ.
    residual: DMatrix<f64>,
    predicted: Vec<f64>,
    states: Vec<f64>,
    /// Forces (m × N); on the sweep, the memory of its `l_k`.
    pub force: DMatrix<f64>,
    dof: Vec<f64>,
    rss: f64,
    res2: Vec<f64>,
    meas2: Vec<f64>,
    wn2: f64,
    smooth: f64,
    prev_w: Vec<f64>,
    x0: DVector<f64>,
    tmp: DMatrix<f64>,
}

impl<'a> Sink<'a> {
    /// A sink for states in the coordinates of `wx` (None: `s̃`), writing
    /// the forces into `force` (m × N, overwritten).
    pub fn new(
        lq: &'a Lq,
        data: &'a HorizonData<'a>,
        wx: Option<&DMatrix<f64>>,
        force: DMatrix<f64>,
    ) -> Sink<'a> {
        let (nx, p, len) = (lq.nx, lq.p, lq.len);
        let mut ch = lq.ch.clone();
        if let Some(w) = wx {
            ch.columns_mut(0, nx).copy_from(&(lq.ch.columns(0, nx) * w));
        }
        debug_assert_eq!(force.shape(), (lq.m, len));
        Sink {
            lq,
            data,
            ch,
            wx: wx.cloned(),
            residual: lq.target.clone(),
            predicted: Vec::with_capacity(p * len),
            states: Vec::with_capacity(nx * len),
            force,
            dof: Vec::with_capacity(data.unknown.nrows() * len),
            rss: 0.0,
            res2: vec![0.0; p],
            meas2: vec![0.0; p],
            wn2: 0.0,
            smooth: 0.0,
            prev_w: vec![0.0; lq.m],
            x0: DVector::zeros(nx),
            tmp: DMatrix::zeros(nx, BLOCK),
        }
    }

    /// All the states at once (ns × N).
    pub fn push_all(&mut self, s: &DMatrix<f64>) {
        let ns = s.nrows();
        for (b, z) in s.as_slice().chunks(ns * BLOCK).enumerate() {
            self.push(z, b * BLOCK);
        }
    }

    /// The states of samples `k0, k0 + 1, …` (column-major, ns per
    /// sample, at most 256 samples), in order.
    pub fn push(&mut self, z: &[f64], k0: usize) {
        let ns = self.lq.ns;
        let nb = z.len() / ns;
        let zv = MatRef::from_column_major_slice(z, ns, nb);
        self.outputs(zv, k0);
        self.forces(z, k0);
        self.states(zv, k0 == 0);
        debug_assert_eq!(self.states.len(), (k0 + nb) * self.lq.nx);
    }

    /// `ỹ − Ĉ s̃`, unweighted, with the norms and the predictions.
    fn outputs(&mut self, z: MatRef<'_, f64>, k0: usize) {
        let (p, nb) = (self.lq.p, z.ncols());
        let dst = view_mut(&mut self.residual).submatrix_mut(0, k0, p, nb);
        mul(dst, true, view(&self.ch), z, -1.0);
        let res = &mut self.residual.as_mut_slice()[k0 * p..(k0 + nb) * p];
        let meas = &self.data.measured.as_slice()[k0 * p..(k0 + nb) * p];
        for (r, y) in res.chunks_exact_mut(p).zip(meas.chunks_exact(p)) {
            for i in 0..p {
                self.rss += r[i] * r[i];
                r[i] /= self.lq.wsqrt[i];
                self.res2[i] += r[i] * r[i];
                self.meas2[i] += y[i] * y[i];
                self.predicted.push(y[i] - r[i]);
            }
        }
    }

    /// Forces in newtons, `B_u w`, and the force norms of the cost.
    fn forces(&mut self, z: &[f64], k0: usize) {
        let (nx, m, ns) = (self.lq.nx, self.lq.m, self.lq.ns);
        let dw = self.lq.d[nx];
        let n = self.data.unknown.nrows();
        let mut g = vec![0.0; n];
        for (j, c) in z.chunks_exact(ns).enumerate() {
            let k = k0 + j;
            let w = &c[nx..];
            if k == 0 {
                self.prev_w.copy_from_slice(w);
            }
            let f = &mut self.force.as_mut_slice()[k * m..(k + 1) * m];
            for ((fi, wi), wp) in f.iter_mut().zip(w).zip(self.prev_w.iter_mut()) {
                self.wn2 += wi * wi;
                self.smooth += (wi - *wp) * (wi - *wp);
                *wp = *wi;
                *fi = wi * dw;
            }
            g.iter_mut().for_each(|v| *v = 0.0);
            gemv_acc(self.data.unknown.as_slice(), f, &mut g);
            self.dof.extend_from_slice(&g);
        }
    }

    /// `[u; v] = D_x W_x z_x` (or `D_x s̃_x`).
    fn states(&mut self, z: MatRef<'_, f64>, first: bool) {
        let (nx, nb) = (self.lq.nx, z.ncols());
        let zx = z.submatrix(0, 0, nx, nb);
        let mut dst = view_mut(&mut self.tmp).submatrix_mut(0, 0, nx, nb);
        match &self.wx {
            Some(w) => mul(dst, false, view(w), zx, 1.0),
            None => dst.copy_from(zx),
        }
        if first {
            self.x0.copy_from(&self.tmp.column(0));
        }
        let dx = &self.lq.d.as_slice()[..nx];
        for t in self.tmp.as_slice().chunks_exact(nx).take(nb) {
            self.states.extend(t.iter().zip(dx).map(|(t, d)| t * d));
        }
    }

    /// The result, with the covariance (consumed: its memory becomes the
    /// standard deviations).
    pub fn finish(
        self,
        settings: &HorizonSettings,
        cov: Option<Covariance>,
        weights: SelectedWeights,
    ) -> HorizonResult {
        let lq = self.lq;
        let (nx, m, p, len) = (lq.nx, lq.m, lq.p, lq.len);
        let (dw, dx) = (lq.d[nx], &lq.d.as_slice()[..nx]);
        let cost = self.rss + lq.lambda * self.wn2 + lq.mu * self.smooth + prior_cost(lq, &self.x0);
        let relative_residual: Vec<f64> = (0..p)
            .map(|r| crate::metrics::ratio(self.res2[r], self.meas2[r]))
            .collect();
        let total = crate::metrics::ratio(self.res2.iter().sum(), self.meas2.iter().sum());
        let tr_h = cov.as_ref().map_or(f64::NAN, |c| c.tr_h);
        let dof = (len * p) as f64 - tr_h;
        let variance_factor = if dof > 0.0 { self.rss / dof } else { f64::NAN };
        let scale = match settings.covariance_scale {
            CovarianceScale::Model => 1.0,
            CovarianceScale::Estimated => variance_factor,
        };
        let held_from = cov.as_ref().and_then(|c| c.held_from);
        let (force_std, state_std, undetermined) = match cov {
            Some(c) => (
                Some(std(c.var_w, &vec![dw; m], scale)),
                Some(std(c.var_x, dx, scale)),
                c.undetermined,
            ),
            None => (None, None, vec![]),
        };
        HorizonResult {
            force: self.force,
            force_std,
            dof_force: DMatrix::from_vec(self.data.unknown.nrows(), len, self.dof),
            states: DMatrix::from_vec(nx, len, self.states),
            state_std,
            predicted: DMatrix::from_vec(p, len, self.predicted),
            residual: self.residual,
            weights,
            status: HorizonStatus::Solved,
            notes: vec![],
            diagnostics: Diagnostics {
                solver: Solver::Riccati,
                cost,
                rss: self.rss,
                relative_residual,
                relative_residual_total: total,
                tr_h,
                variance_factor,
                riccati_transient: 0,
                riccati_converged: true,
                riccati_held_distance: 0.0,
                covariance_held_from: held_from,
                undetermined_states: undetermined,
                qp_iterations: 0,
            },
            timings: Timings::default(),
        }
    }
}

/// Standard deviations from variances (in place), in physical units; NaN
/// (undetermined) stays NaN.
fn std(mut var: DMatrix<f64>, units: &[f64], scale: f64) -> DMatrix<f64> {
    for col in var.as_mut_slice().chunks_exact_mut(units.len()) {
        for (v, u) in col.iter_mut().zip(units) {
            *v = (*v * scale).abs().sqrt() * u;
        }
    }
    var
}

/// The initial-state prior's cost at the scaled `x̃_0`.
fn prior_cost(lq: &Lq, x0: &DVector<f64>) -> f64 {
    match &lq.init {
        Init::Fixed(_) => 0.0,
        Init::Prior { p, mean } => {
            let dx = x0 - mean;
            dx.dot(&(p * &dx))
        }
    }
}
