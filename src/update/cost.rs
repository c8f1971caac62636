//! Residual vectors of the two metrics and the minimum-change term.
//!
//! The optimizers minimise `J(x) = ‖r(x)‖²` with `r = [r_data; √α x]`,
//! the squared form of the paper's eq. (10) `‖R‖ + α‖p − p0‖` (squared so
//! that Gauss–Newton and Levenberg–Marquardt apply; `x` is the scaled
//! change, so `x = 0` at p0).
//!
//! **GLS** (eq. 9): for every segment, channel c and sample k,
//! `r = w_c (y_test,c(k) − y_sim,c(k))`, with `w_c = 1/‖y_test,c‖₂` by
//! default, so that `‖r_data‖² = Σ_c e_c²` sums the squared relative errors
//! of the channels.
//!
//! **PCD** (eqs 11–12): per segment, the channel × time matrices of test
//! and model, each row scaled by one weight per quantity (`1/‖Y_q‖_F` of the
//! test data, so displacement and velocity blocks count alike), are
//! decomposed `Y = U Σ Vᵀ`. Test components are kept in decreasing σ until
//! their cumulated energy `Σσ²` reaches the fraction `energy` of the total
//! (the rest is noise or negligible). Each kept test component i is paired
//! with the model component j of largest `|v_iᵀ v_j|` (the MAC of the right
//! singular vectors), the model vectors' sign is aligned
//! (`s = sign(v_iᵀ v_j)`), and the residual stacks, with
//! `ω_i = σ_i^T / ‖σ^T‖`:
//! - `ω_i (v_i^T − s v_j^M)` (time histories, eq. 12),
//! - `ω_i (u_i^T − s u_j^M)` (spatial shapes),
//! - `(σ_i^T − σ_j^M) / ‖σ^T‖` (singular values).
//!
//! The residual is zero exactly when the kept components coincide, and
//! the metric ignores the discarded components (so noise is filtered).
//!
//! **Jacobian from sensitivities** ([`Evaluator::sensitivity_jacobian`],
//! full-order problems): one simulation per segment gives the channels `y`
//! and `∂y/∂x_j` ([`super::sensitivity`]). GLS: `∂r/∂x_j = −W ∂y/∂x_j`
//! exactly. PCD: the residual is a function of the weighted model matrix
//! `Y`, differentiated along `∂Y/∂x_j` by central differences of that
//! function, `(r(Y + t ∂Y) − r(Y − t ∂Y)) / 2t` with the optimizers'
//! finite-difference step `t`: two SVDs per parameter and segment, no
//! simulation. The minimum-change rows add `√α I`.

use super::forward::{self, Failure, SegmentResponse};
use super::problem::{Metric, Problem};
use crate::integrate::Tape;
use nalgebra::{DMatrix, DVector};

/// The work counted by an [`Evaluator`].
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Counters {
    /// Segment simulations (those with sensitivities included).
    pub simulations: usize,
    /// Jacobians computed.
    pub jacobians: usize,
    /// Segment simulations with forward sensitivities.
    pub sensitivity_simulations: usize,
    /// Sensitivity Jacobians replaced by finite differences.
    pub sensitivity_fallbacks: usize,
    /// Wall time in Jacobians, s.
    pub jacobian_seconds: f64,
}

impl std::ops::AddAssign for Counters {
    fn add_assign(&mut self, o: Counters) {
        self.simulations += o.simulations;
        self.jacobians += o.jacobians;
        self.sensitivity_simulations += o.sensitivity_simulations;
        self.sensitivity_fallbacks += o.sensitivity_fallbacks;
        self.jacobian_seconds += o.jacobian_seconds;
    }
}

/// Evaluates residuals of a problem and counts the work.
#[derive(Debug)]
pub struct Evaluator<'a> {
    problem: &'a Problem,
    /// Measured data per segment (observation × sample), weights applied.
    measured: Vec<DMatrix<f64>>,
    /// Row weights of the data matrices.
    weights: Vec<f64>,
    /// Cost evaluations (one per parameter vector).
    pub evaluations: usize,
    /// Segment simulations (those with sensitivities included).
    pub simulations: usize,
    /// Jacobians computed (any method).
    pub jacobians: usize,
    /// Segment simulations run with forward sensitivities (each also
    /// counted in `simulations`).
    pub sensitivity_simulations: usize,
    /// Sensitivity Jacobians that failed and were replaced by finite
    /// differences.
    pub sensitivity_fallbacks: usize,
    /// Wall time spent in Jacobians, s.
    pub jacobian_seconds: f64,
    /// Keep the tapes of the last evaluation's runs, for the sensitivity
    /// Jacobian at that point ([`Evaluator::sensitivity_jacobian`]; off by
    /// default: it pays when the Jacobian follows the evaluation, as in
    /// Levenberg–Marquardt).
    pub keep_tapes: bool,
    /// The last point evaluated with its responses and tapes.
    taped: Option<(Vec<f64>, Vec<SegmentResponse>, Vec<Tape>)>,
}

impl<'a> Evaluator<'a> {
    /// Prepare the weighted test data of every segment.
    pub fn new(problem: &'a Problem) -> Evaluator<'a> {
        let weights = row_weights(problem);
        let measured = problem
            .segments
            .iter()
            .map(|s| {
                DMatrix::from_fn(problem.observations.len(), s.len, |r, k| {
                    problem.observations[r].data[s.start + k] * weights[r]
                })
            })
            .collect();
        Evaluator {
            problem,
            measured,
            weights,
            evaluations: 0,
            simulations: 0,
            jacobians: 0,
            sensitivity_simulations: 0,
            sensitivity_fallbacks: 0,
            jacobian_seconds: 0.0,
            keep_tapes: false,
            taped: None,
        }
    }

    /// The problem.
    pub fn problem(&self) -> &Problem {
        self.problem
    }

    /// The work counted so far.
    pub fn counters(&self) -> Counters {
        Counters {
            simulations: self.simulations,
            jacobians: self.jacobians,
            sensitivity_simulations: self.sensitivity_simulations,
            sensitivity_fallbacks: self.sensitivity_fallbacks,
            jacobian_seconds: self.jacobian_seconds,
        }
    }

    /// Simulated responses at `x` (unweighted).
    pub fn responses(&mut self, x: &[f64]) -> Result<Vec<SegmentResponse>, Failure> {
        self.evaluations += 1;
        if !self.keep_tapes {
            let (res, n) = forward::simulate(self.problem, x);
            self.simulations += n;
            return res;
        }
        self.taped = None;
        let (res, n) = forward::simulate_taped(self.problem, x);
        self.simulations += n;
        let (resp, tapes) = res?;
        if let Some(t) = tapes {
            self.taped = Some((x.to_vec(), resp.clone(), t));
        }
        Ok(resp)
    }

    /// The derivatives at `x`: replayed from the last evaluation's tapes
    /// when it was at `x`, else simulated; and the simulations run.
    fn derivatives(
        &self,
        x: &[f64],
    ) -> (
        Result<Vec<super::sensitivity::SegmentDerivatives>, Failure>,
        usize,
    ) {
        if let Some((tx, resp, tapes)) = &self.taped {
            if tx.as_slice() == x {
                if let Some(r) = super::sensitivity::from_tapes(self.problem, x, resp, tapes) {
                    return (r, 0);
                }
            }
        }
        super::sensitivity::simulate(self.problem, x)
    }

    /// Residual vector `[r_data; √α x]` at `x`.
    pub fn residual(&mut self, x: &[f64]) -> Result<DVector<f64>, Failure> {
        let resp = self.responses(x)?;
        let mut r = self.data_residual(&resp)?;
        let a = self.problem.alpha;
        if a > 0.0 {
            let n = r.len();
            r = r.resize_vertically(n + x.len(), 0.0);
            for (i, xi) in x.iter().enumerate() {
                r[n + i] = a.sqrt() * xi;
            }
        }
        Ok(r)
    }

    /// Jacobian of the residual `[r_data; √α x]` at `x` from one simulation
    /// with forward sensitivities per segment (see the module docs; `h` is
    /// the step of the PCD residual's differences along `∂Y/∂x_j`, scaled
    /// as the finite differences' `h (1 + |x_j|)`). Counts one evaluation
    /// and one simulation per segment. Fails for reduced problems
    /// ([`super::sensitivity::unsupported`]) and when a simulation fails.
    pub fn sensitivity_jacobian(&mut self, x: &[f64], h: f64) -> Result<DMatrix<f64>, Failure> {
        self.evaluations += 1;
        let (res, count) = self.derivatives(x);
        self.simulations += count;
        self.sensitivity_simulations += count;
        let segs = res?;
        let mut cols: Vec<Vec<f64>> = vec![Vec::new(); x.len()];
        for (s, (sd, meas)) in segs.iter().zip(&self.measured).enumerate() {
            let fail = |reason: String| Failure {
                segment: Some(s),
                reason,
            };
            match self.problem.metric {
                Metric::Gls => {
                    for (col, dy) in cols.iter_mut().zip(&sd.dy) {
                        col.extend(scale_rows(dy, &self.weights).iter().map(|v| -v));
                    }
                }
                Metric::Pcd { energy } => {
                    let ys = scale_rows(&sd.y, &self.weights);
                    for (j, (col, dy)) in cols.iter_mut().zip(&sd.dy).enumerate() {
                        let t = h * (1.0 + x[j].abs());
                        let d = scale_rows(dy, &self.weights) * t;
                        let rp = pcd_residual(meas, &(&ys + &d), energy).map_err(fail)?;
                        let rm = pcd_residual(meas, &(&ys - &d), energy).map_err(fail)?;
                        if rp.len() != rm.len() {
                            return Err(fail("PCD residuals of different lengths".into()));
                        }
                        col.extend(((rp - rm) / (2.0 * t)).iter());
                    }
                }
            }
        }
        let a = self.problem.alpha;
        let rows = cols.first().map_or(0, Vec::len);
        let extra = if a > 0.0 { x.len() } else { 0 };
        let mut jac = DMatrix::zeros(rows + extra, x.len());
        for (j, col) in cols.iter().enumerate() {
            jac.view_mut((0, j), (rows, 1)).copy_from_slice(col);
            if a > 0.0 {
                jac[(rows + j, j)] = a.sqrt();
            }
        }
        if jac.iter().any(|v| !v.is_finite()) {
            return Err(Failure {
                segment: None,
                reason: "the sensitivity Jacobian is not finite".into(),
            });
        }
        Ok(jac)
    }

    /// Number of data rows of the residual (without the minimum-change
    /// rows); PCD residuals are evaluated once to find it.
    pub fn data_rows(&self, r: &DVector<f64>) -> usize {
        if self.problem.alpha > 0.0 {
            r.len() - self.problem.parameters.len()
        } else {
            r.len()
        }
    }

    /// Data part of the residual from simulated responses.
    pub fn data_residual(&self, resp: &[SegmentResponse]) -> Result<DVector<f64>, Failure> {
        let mut parts: Vec<f64> = Vec::new();
        for (s, (y, meas)) in resp.iter().zip(&self.measured).enumerate() {
            let ys = scale_rows(y, &self.weights);
            match self.problem.metric {
                Metric::Gls => parts.extend((meas - ys).iter()),
                Metric::Pcd { energy } => {
                    let r = pcd_residual(meas, &ys, energy).map_err(|reason| Failure {
                        segment: Some(s),
                        reason,
                    })?;
                    parts.extend(r.iter());
                }
            }
        }
        if parts.iter().any(|v| !v.is_finite()) {
            return Err(Failure {
                segment: None,
                reason: "the residual is not finite".into(),
            });
        }
        Ok(DVector::from_vec(parts))
    }
}

/// Row weights: GLS uses each observation's weight; PCD one weight per
/// quantity, `1/‖Y_q‖_F` of the test data over that quantity's channels
/// (under PCD an observation weight only switches a channel on (> 0) or
/// off (0)).
fn row_weights(problem: &Problem) -> Vec<f64> {
    let obs = &problem.observations;
    match problem.metric {
        Metric::Gls => obs.iter().map(|o| o.weight).collect(),
        Metric::Pcd { .. } => obs
            .iter()
            .map(|o| {
                let f: f64 = obs
                    .iter()
                    .filter(|p| p.quantity == o.quantity && p.weight > 0.0)
                    .map(|p| p.data.iter().map(|v| v * v).sum::<f64>())
                    .sum::<f64>()
                    .sqrt();
                if o.weight > 0.0 && f > 0.0 {
                    1.0 / f
                } else {
                    0.0
                }
            })
            .collect(),
    }
}

fn scale_rows(y: &DMatrix<f64>, w: &[f64]) -> DMatrix<f64> {
    let mut out = y.clone();
    for (r, &wr) in w.iter().enumerate() {
        out.row_mut(r).scale_mut(wr);
    }
    out
}

/// PCD residual between a test matrix and a model matrix of equal shape
/// (channels × samples); see the module docs. Returns an error message when
/// the decomposition fails or the test matrix is zero.
pub fn pcd_residual(
    test: &DMatrix<f64>,
    model: &DMatrix<f64>,
    energy: f64,
) -> Result<DVector<f64>, String> {
    let (ut, st, vt) = svd(test)?;
    let (um, sm, vm) = svd(model)?;
    let total: f64 = st.iter().map(|s| s * s).sum();
    if total <= 0.0 {
        return Err("PCD: the test matrix is zero".into());
    }
    let norm = total.sqrt();
    let mut keep = 0;
    let mut acc = 0.0;
    while keep < st.len() {
        acc += st[keep] * st[keep];
        keep += 1;
        if acc >= energy * total {
            break;
        }
    }
    let (c, l) = (test.nrows(), test.ncols());
    let mut out = Vec::with_capacity(keep * (l + c + 1));
    for i in 0..keep {
        let vi = vt.row(i);
        let (mut best, mut dot) = (0, 0.0f64);
        for j in 0..sm.len() {
            let d = vi.dot(&vm.row(j));
            if d.abs() > dot.abs() {
                best = j;
                dot = d;
            }
        }
        let s = if dot < 0.0 { -1.0 } else { 1.0 };
        let w = st[i] / norm;
        out.extend((0..l).map(|k| w * (vt[(i, k)] - s * vm[(best, k)])));
        out.extend((0..c).map(|r| w * (ut[(r, i)] - s * um[(r, best)])));
        out.push((st[i] - sm[best]) / norm);
    }
    Ok(DVector::from_vec(out))
}

/// (U, σ, Vᵀ) of a thin SVD.
type Svd = (DMatrix<f64>, Vec<f64>, DMatrix<f64>);

/// Thin SVD with descending singular values: (U, σ, Vᵀ).
fn svd(a: &DMatrix<f64>) -> Result<Svd, String> {
    let svd = a
        .clone()
        .try_svd(true, true, 1e-14, 500)
        .ok_or_else(|| "PCD: the SVD did not converge".to_string())?;
    let (u, vt) = match (svd.u, svd.v_t) {
        (Some(u), Some(vt)) => (u, vt),
        _ => return Err("PCD: the SVD returned no singular vectors".into()),
    };
    let s = svd.singular_values;
    let mut idx: Vec<usize> = (0..s.len()).collect();
    idx.sort_by(|&a, &b| s[b].total_cmp(&s[a]));
    let u2 = DMatrix::from_fn(u.nrows(), idx.len(), |r, j| u[(r, idx[j])]);
    let vt2 = DMatrix::from_fn(idx.len(), vt.ncols(), |j, k| vt[(idx[j], k)]);
    Ok((u2, idx.iter().map(|&i| s[i]).collect(), vt2))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pcd_is_zero_for_equal_data_and_sign_blind() {
        let y = DMatrix::from_fn(3, 50, |r, k| {
            ((k as f64) * 0.2).sin() * (r as f64 + 1.0)
                + ((k as f64) * 0.7).cos() * (r as f64 - 1.0)
        });
        let r = pcd_residual(&y, &y, 0.9999).unwrap();
        assert!(r.amax() < 1e-10);
        let y2 = &y * 1.1;
        let r2 = pcd_residual(&y, &y2, 0.9999).unwrap();
        assert!(r2.amax() > 1e-3);
    }
}
