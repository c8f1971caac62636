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

use super::forward::{self, Failure, SegmentResponse};
use super::problem::{Metric, Problem};
use nalgebra::{DMatrix, DVector};

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
    /// Segment simulations.
    pub simulations: usize,
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
        }
    }

    /// The problem.
    pub fn problem(&self) -> &Problem {
        self.problem
    }

    /// Simulated responses at `x` (unweighted).
    pub fn responses(&mut self, x: &[f64]) -> Result<Vec<SegmentResponse>, Failure> {
        self.evaluations += 1;
        let (res, n) = forward::simulate(self.problem, x);
        self.simulations += n;
        res
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
