//! Window operators: the exact sensitivities of a window's outputs to its
//! start state, its force samples and the measured input, built once (the
//! model is linear and time-invariant, so they do not change from window to
//! window), and the regularized least-squares gain of a window problem.
//!
//! A raw window covers samples `s + j`, `j = 0..=N`. With
//! `z = [x_0; f_0 … f_N; e_0 … e_N]`, the state and output at `j` are
//! `x_j = X_j z`, `y_j = Y_j z` ([`RawWindow`]), from the recursion of
//! [`crate::identify::system`]. A scheme ([`Param`]) says which part of
//! `(x_0, f_0 … f_N)` is unknown (`θ`) and which is carried from the
//! previous window (`c`): `(x_0, F) = S_θ θ + S_c c`, which samples are
//! fitted, and which penalty rows `P_θ θ − P_c c` regularize it. The window
//! problem is then
//!
//! $$ \min_θ \; ‖ y_{fit} − H_θ θ − H_c c − H_e e ‖^2 + ‖ P_θ θ − P_c c ‖^2 , $$
//!
//! solved as `θ = Ā⁺ B̄ d` with `Ā = [H_θ; P_θ]`, `d = [y_fit; c; e]`
//! (Ā is column-scaled before its SVD; a rank-deficient Ā gives the
//! minimum-norm solution and is reported). Everything the run needs from θ
//! is a fixed linear map of `d` ([`WindowOperator::gain`]), so a window costs
//! one matrix–vector product.

use super::system::System;
use crate::linear::spectral_radius;
use nalgebra::{DMatrix, DVector};
use serde::Serialize;

/// Sensitivities of one raw window of `len + 1` samples.
#[derive(Debug, Clone)]
pub struct RawWindow {
    /// N: the window holds samples `j = 0..=N`.
    pub len: usize,
    /// State size 2m.
    pub ns: usize,
    /// Force components n.
    pub n: usize,
    /// Measured inputs.
    pub ne: usize,
    /// Output channels p.
    pub p: usize,
    /// `X_j` (2m × nz), j = 0..=N.
    pub x: Vec<DMatrix<f64>>,
    /// `Y_j` (p × nz), j = 0..=N.
    pub y: Vec<DMatrix<f64>>,
}

impl RawWindow {
    /// Build by the exact recursion of the sampled model.
    pub fn build(sys: &System, len: usize) -> RawWindow {
        let (ns, n, ne, p) = (2 * sys.m(), sys.n(), sys.ne(), sys.p());
        let mut w = RawWindow {
            len,
            ns,
            n,
            ne,
            p,
            x: Vec::with_capacity(len + 1),
            y: Vec::with_capacity(len + 1),
        };
        let nz = w.nz();
        let (cf, ce): (Vec<usize>, Vec<usize>) =
            (0..=len).map(|j| (w.col_f(j), w.col_e(j))).unzip();
        let gen = |j: usize| -> DMatrix<f64> {
            let mut u = DMatrix::zeros(sys.m(), nz);
            u.columns_mut(cf[j], n).copy_from(&sys.bf);
            if ne > 0 {
                u.columns_mut(ce[j], ne).copy_from(&sys.be);
            }
            u
        };
        let mut xj = DMatrix::zeros(ns, nz);
        xj.columns_mut(0, ns).fill_with_identity();
        let mut uj = gen(0);
        for j in 0..=len {
            w.y.push(&sys.cy * &xj + &sys.dy * &uj);
            if j == len {
                w.x.push(xj);
                break;
            }
            let un = gen(j + 1);
            let next = &sys.sm.a * &xj + &sys.sm.b0 * &uj + &sys.sm.b1 * &un;
            w.x.push(std::mem::replace(&mut xj, next));
            uj = un;
        }
        w
    }
    /// Number of raw variables `2m + (n + n_e)(N + 1)`.
    pub fn nz(&self) -> usize {
        self.ns + (self.n + self.ne) * (self.len + 1)
    }
    /// Size of `(x_0, F)`: `2m + n (N + 1)`.
    pub fn nxf(&self) -> usize {
        self.ns + self.n * (self.len + 1)
    }
    /// First column of `f_j`.
    pub fn col_f(&self, j: usize) -> usize {
        self.ns + j * self.n
    }
    /// First column of `e_j`.
    pub fn col_e(&self, j: usize) -> usize {
        self.nxf() + j * self.ne
    }
}

/// What a scheme makes of a raw window.
#[derive(Debug, Clone)]
pub struct Param {
    /// Number of unknowns θ.
    pub ntheta: usize,
    /// Size of the carried vector `c = [x; f_prev]` (2m + n).
    pub nc: usize,
    /// `(x_0, F) = S_θ θ + S_c c` (nxf × nθ).
    pub s_theta: DMatrix<f64>,
    /// (nxf × nc).
    pub s_c: DMatrix<f64>,
    /// Penalty rows on θ.
    pub pen_theta: DMatrix<f64>,
    /// Penalty rows on c (the residual is `P_θ θ − P_c c`).
    pub pen_c: DMatrix<f64>,
    /// Fitted samples `j`.
    pub fit: Vec<usize>,
    /// Committed samples `j` (their force and state are kept).
    pub commit: std::ops::Range<usize>,
    /// Sample `j` whose state is carried to the next window (`None`: last).
    pub next: Option<usize>,
    /// Sample `j` whose force is carried as `f_prev`.
    pub carry_force: usize,
    /// Offsets in θ of the per-sample force vectors (for constraints).
    pub force_blocks: Vec<usize>,
}

/// Facts about one window operator, reported in the summary.
#[derive(Debug, Clone, Serialize)]
pub struct OperatorInfo {
    /// Raw window samples N + 1.
    pub samples: usize,
    /// Unknowns per window.
    pub unknowns: usize,
    /// Rows of Ā (fitted outputs + penalty rows).
    pub rows: usize,
    /// Numerical rank of the column-scaled Ā (relative threshold 1e-12).
    pub rank: usize,
    /// Condition number of the column-scaled Ā.
    pub condition: f64,
    /// Spectral radius of the closed-loop map `c → c'` between windows
    /// (`None` for the last window, which carries nothing).
    pub spectral_radius: Option<f64>,
    /// Trace of the influence of the committed measurements on their own
    /// predictions (effective parameters per window).
    pub influence_trace: f64,
}

/// A window problem ready to run: its gain and what QP and diagnostics need.
#[derive(Debug, Clone)]
pub struct WindowOperator {
    /// The scheme's layout.
    pub param: Param,
    /// Raw window length N.
    pub len: usize,
    /// `J`: the needed raw vector is `r = [x_0; f_0 … f_J]`.
    pub last_needed: usize,
    /// Size of `d = [y_fit; c; e]`.
    pub nd: usize,
    /// Fitted output values per window (first block of `d`).
    pub nfit: usize,
    /// Measured-input values per window (last block of `d`).
    pub nee: usize,
    /// LS gain `r = G d` (nr × nd).
    pub gain: DMatrix<f64>,
    /// `r = R_θ θ + R_c c`.
    pub r_theta: DMatrix<f64>,
    /// (nr × nc).
    pub r_c: DMatrix<f64>,
    /// Column-scaled `Ā` (for the QP: `P = Āᵀ Ā`).
    pub abar_scaled: DMatrix<f64>,
    /// `B̄` (rows of Ā × nd): `b̄ = B̄ d`.
    pub bbar: DMatrix<f64>,
    /// Column scaling: `θ = D θ̃`.
    pub dcol: DVector<f64>,
    /// Fitted-output sensitivity to θ (unweighted).
    pub h_theta: DMatrix<f64>,
    /// Closed-loop map between windows (nc × nc), when a state is carried.
    pub closed_loop: Option<DMatrix<f64>>,
    /// Facts for the report.
    pub info: OperatorInfo,
}

/// Relative threshold of the pseudo-inverse.
const PINV_RTOL: f64 = 1e-12;

impl WindowOperator {
    /// Build from a raw window and a scheme's parametrization.
    pub fn new(raw: &RawWindow, param: Param) -> WindowOperator {
        let (ns, n, p, ne) = (raw.ns, raw.n, raw.p, raw.ne);
        let nxf = raw.nxf();
        let nfit = param.fit.len() * p;
        let nee = ne * (raw.len + 1);
        // fitted-output sensitivities to (x0, F) and e
        let mut hxf = DMatrix::zeros(nfit, nxf);
        let mut he = DMatrix::zeros(nfit, nee);
        for (i, &j) in param.fit.iter().enumerate() {
            hxf.rows_mut(i * p, p).copy_from(&raw.y[j].columns(0, nxf));
            he.rows_mut(i * p, p).copy_from(&raw.y[j].columns(nxf, nee));
        }
        let h_theta = &hxf * &param.s_theta;
        let h_c = &hxf * &param.s_c;
        let npen = param.pen_theta.nrows();
        let nt = param.ntheta;
        let nc = param.nc;
        let mut abar = DMatrix::zeros(nfit + npen, nt);
        abar.rows_mut(0, nfit).copy_from(&h_theta);
        abar.rows_mut(nfit, npen).copy_from(&param.pen_theta);
        let nd = nfit + nc + nee;
        let mut bbar = DMatrix::zeros(nfit + npen, nd);
        bbar.view_mut((0, 0), (nfit, nfit)).fill_with_identity();
        bbar.view_mut((0, nfit), (nfit, nc)).copy_from(&(-&h_c));
        bbar.view_mut((0, nfit + nc), (nfit, nee))
            .copy_from(&(-&he));
        bbar.view_mut((nfit, nfit), (npen, nc))
            .copy_from(&param.pen_c);
        // column scaling, SVD, pseudo-inverse
        let dcol = DVector::from_fn(nt, |i, _| {
            let c = abar.column(i).norm();
            if c > 0.0 {
                1.0 / c
            } else {
                1.0
            }
        });
        let mut abar_scaled = abar;
        for i in 0..nt {
            abar_scaled.column_mut(i).scale_mut(dcol[i]);
        }
        let svd = abar_scaled.clone().svd(true, true);
        let sv = &svd.singular_values;
        let smax = sv.max();
        let tol = PINV_RTOL * smax.max(f64::MIN_POSITIVE);
        let rank = sv.iter().filter(|&&s| s > tol).count();
        let smin = sv.min();
        let condition = if smin > 0.0 {
            smax / smin
        } else {
            f64::INFINITY
        };
        let u = svd.u.as_ref().expect("svd u requested");
        let vt = svd.v_t.as_ref().expect("svd v_t requested");
        let mut vs = vt.transpose();
        for (i, &s) in sv.iter().enumerate() {
            let inv = if s > tol { 1.0 / s } else { 0.0 };
            vs.column_mut(i).scale_mut(inv);
        }
        // θ = D V Σ⁺ Uᵀ B̄ d
        let mut kth = vs * (u.transpose() * &bbar);
        for i in 0..nt {
            kth.row_mut(i).scale_mut(dcol[i]);
        }
        let commit_last = param.commit.end.saturating_sub(1);
        let last_needed = param.next.map_or(commit_last, |nx| nx.max(commit_last));
        let nr = ns + n * (last_needed + 1);
        let r_theta = param.s_theta.rows(0, nr).into_owned();
        let r_c = param.s_c.rows(0, nr).into_owned();
        let mut gain = &r_theta * &kth;
        {
            let mut gc = gain.columns_mut(nfit, nc);
            gc += &r_c;
        }
        // closed loop c → c'
        let closed_loop = param.next.map(|nx| {
            let mut q = DMatrix::zeros(nc, nr);
            q.view_mut((0, 0), (ns, nr))
                .copy_from(&raw.x[nx].columns(0, nr));
            let cf = ns + param.carry_force * n;
            q.view_mut((ns, cf), (n, n)).fill_with_identity();
            q * gain.columns(nfit, nc)
        });
        let spectral = closed_loop.as_ref().map(spectral_radius);
        // influence of the committed measurements on their own predictions
        let infl = &h_theta * kth.columns(0, nfit);
        let mut trace = 0.0;
        for (i, &j) in param.fit.iter().enumerate() {
            if param.commit.contains(&j) {
                for r in 0..p {
                    trace += infl[(i * p + r, i * p + r)];
                }
            }
        }
        let info = OperatorInfo {
            samples: raw.len + 1,
            unknowns: nt,
            rows: nfit + npen,
            rank,
            condition,
            spectral_radius: spectral,
            influence_trace: trace,
        };
        WindowOperator {
            len: raw.len,
            last_needed,
            nd,
            nfit,
            nee,
            gain,
            r_theta,
            r_c,
            abar_scaled,
            bbar,
            dcol,
            h_theta,
            closed_loop,
            info,
            param,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::identify::{Problem, Reduce};
    use crate::record::{Channel, Quantity, Record};

    /// The window sensitivities reproduce a step-by-step simulation of the
    /// sampled model, and the paper gain reproduces a direct solve.
    #[test]
    fn sensitivities_match_simulation_and_gain_matches_direct_solve() {
        let p = concat!(env!("CARGO_MANIFEST_DIR"), "/data/lanl8dof.toml");
        let model = crate::model::Model::from_file(std::path::Path::new(p)).unwrap();
        let ns = 12;
        let ch = |d| Channel::new(Quantity::Accel, d, vec![0.0; ns]);
        let rec = Record {
            t0: 0.0,
            fs: 512.0,
            inputs: vec![Channel::new(Quantity::Force, 1, vec![0.0; ns])],
            outputs: vec![ch(1), ch(5), ch(6)],
            truth: None,
            source: Default::default(),
        };
        let prob = Problem::new(&model, &rec, &[1, 5, 6]).unwrap();
        for red in [Reduce::None, Reduce::Serep] {
            let sys = System::new(&prob, red, 10).unwrap();
            let len = 5;
            let raw = RawWindow::build(&sys, len);
            let nz = raw.nz();
            let z = DVector::from_fn(nz, |i, _| ((i * 7919) % 13) as f64 / 13.0 - 0.5);
            let x0 = z.rows(0, raw.ns).into_owned();
            let f = DMatrix::from_fn(raw.n, len + 1, |i, j| z[raw.col_f(j) + i]);
            let e = DMatrix::from_fn(raw.ne, len + 1, |i, j| z[raw.col_e(j) + i]);
            let (xs, ys) = sys.simulate(&x0, &f, &e);
            for j in 0..=len {
                let xj = &raw.x[j] * &z;
                let yj = &raw.y[j] * &z;
                assert!((xj - xs.column(j)).amax() < 1e-9 * (1.0 + xs.amax()));
                assert!((yj - ys.column(j)).amax() < 1e-9 * (1.0 + ys.amax()));
            }
            // paper window: gain equals the normal-equation solution
            let alpha = 0.3;
            let op = WindowOperator::new(&raw, crate::identify::paper::param(&raw, alpha, 0.0));
            let d = DVector::from_fn(op.nd, |i, _| ((i * 31) % 17) as f64 / 17.0 - 0.4);
            let r = &op.gain * &d;
            let nfit = op.nfit;
            let (yfit, c, ee) = (
                d.rows(0, nfit),
                d.rows(nfit, op.param.nc),
                d.rows(nfit + op.param.nc, op.nee),
            );
            let h = &op.h_theta;
            // rebuild H_c c + H_e e from the raw window
            let mut rhs = yfit.into_owned();
            for (i, &j) in op.param.fit.iter().enumerate() {
                let xf = raw.y[j].columns(0, raw.nxf()) * (&op.param.s_c * c);
                let ef = raw.y[j].columns(raw.nxf(), op.nee) * ee;
                let mut blk = rhs.rows_mut(i * raw.p, raw.p);
                blk -= xf + ef;
            }
            let nn = h.transpose() * h + DMatrix::identity(raw.n, raw.n) * alpha;
            let g = nn.lu().solve(&(h.transpose() * rhs)).unwrap();
            let got = r.rows(raw.col_f(1), raw.n);
            assert!((got - &g).amax() < 1e-8 * (1.0 + g.amax()), "{red:?}");
        }
    }
}
