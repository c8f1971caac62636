//! The output error of a linear model over segments whose start states are
//! free, with the start states eliminated (variable projection).
//!
//! For the sampled model `x_{k+1} = A x_k + B_0 f_k + B_1 f_{k+1}`,
//! `y_k = C_y x_k + D_y f_k`, the prediction over a segment of `L` samples
//! from `k_0` is `ŷ = O x_{k_0} + ŷ_f`, with `O = [C_y; C_y A; …; C_y A^{L−1}]`
//! and `ŷ_f` the forced response. The whole record is simulated once from
//! rest (`x̃`); on each segment `y − ŷ = (y − ỹ) − O (x_{k_0} − x̃_{k_0})`, so
//! the best start state leaves the residual
//!
//! $$ r_s = (I − U Uᵀ) W (y − ỹ)_s, $$
//!
//! `U` an orthonormal basis of the range of `W O` (`W` the channel weights;
//! states the outputs never see drop out). The residual of every
//! parameter set is then one simulation and one projection per segment,
//! and does not depend on states reconstructed with the declared model.
//! Reference: Golub & Pereyra, "Separable nonlinear least squares: the
//! variable projection method and its applications", Inverse Problems 19
//! (2003).

use crate::error::{Result, TacitError};
use crate::linear::SampledModel;
use crate::model::Model;
use crate::record::Quantity;
use nalgebra::{DMatrix, DVector};

/// One record as the calibration sees it.
#[derive(Debug, Clone)]
pub struct Data {
    /// Where it came from (for messages and the report).
    pub source: String,
    /// Sample rate, Hz.
    pub fs: f64,
    /// Known external force (n × N), N.
    pub force: DMatrix<f64>,
    /// Measured channels (p × N).
    pub measured: DMatrix<f64>,
    /// `(quantity, DOF from 0)` of each measured channel.
    pub channels: Vec<(Quantity, usize)>,
    /// The user's channel names.
    pub names: Vec<String>,
    /// Samples at the start that are not scored (warm-up).
    pub warmup: usize,
}

impl Data {
    /// Channel weights `1 / ‖y_c‖` (relative errors), scored samples only.
    pub fn weights(&self) -> Vec<f64> {
        (0..self.measured.nrows())
            .map(|c| {
                let ss: f64 = (self.warmup..self.measured.ncols())
                    .map(|k| self.measured[(c, k)].powi(2))
                    .sum();
                1.0 / ss.sqrt().max(1e-300)
            })
            .collect()
    }

    /// Start samples of the scored segments of `len` samples (the last
    /// partial one joins the one before by being dropped).
    pub fn segment_starts(&self, len: usize) -> Vec<usize> {
        let n = self.measured.ncols();
        (0..)
            .map(|i| self.warmup + i * len)
            .take_while(|s| s + len <= n)
            .collect()
    }
}

/// The weighted residual of one record with the segment start states
/// eliminated: sample-major within a segment (`k p + c`), segments in
/// order. Also the number of start-state directions the outputs see.
pub struct Projected {
    /// Residual vector.
    pub r: DVector<f64>,
    /// Rank of `W O` (start-state directions eliminated per segment).
    pub rank: usize,
    /// Segments scored.
    pub segments: usize,
}

/// Orthonormal basis of the range of `W O` over `len` samples.
fn observability_basis(
    a: &DMatrix<f64>,
    cy: &DMatrix<f64>,
    w: &[f64],
    len: usize,
) -> Result<DMatrix<f64>> {
    let (p, n2) = cy.shape();
    let mut o = DMatrix::zeros(len * p, n2);
    let mut block = cy.clone();
    for (c, wc) in w.iter().enumerate() {
        block.row_mut(c).scale_mut(*wc);
    }
    for k in 0..len {
        o.rows_mut(k * p, p).copy_from(&block);
        block = &block * a;
    }
    // (an SVD of a matrix with a non-finite entry does not end)
    if o.iter().any(|v| !v.is_finite()) {
        return Err(TacitError::Numerical(
            "calibration: the observability matrix is not finite".into(),
        ));
    }
    let svd = o.svd(true, false);
    let u = svd.u.ok_or_else(|| {
        TacitError::Numerical("calibration: SVD of the observability matrix failed".into())
    })?;
    let smax = svd.singular_values.max();
    let keep: Vec<usize> = (0..svd.singular_values.len())
        .filter(|&i| svd.singular_values[i] > 1e-9 * smax)
        .collect();
    Ok(DMatrix::from_fn(len * p, keep.len(), |r, j| {
        u[(r, keep[j])]
    }))
}

/// Weighted output error `W (y − ỹ)` (p × N) of the linear part simulated
/// from rest ([`SampledModel::simulate`]).
fn output_error(sm: &SampledModel, data: &Data, w: &[f64]) -> Result<DMatrix<f64>> {
    let (cy, dy) = sm.outputs(&data.channels)?;
    let ns = data.force.ncols();
    let xs = sm.simulate(&DVector::zeros(2 * sm.n), &data.force);
    let mut e = DMatrix::zeros(cy.nrows(), ns);
    for k in 0..ns {
        let y = &cy * xs.column(k) + &dy * data.force.column(k);
        for (c, wc) in w.iter().enumerate() {
            e[(c, k)] = wc * (data.measured[(c, k)] - y[c]);
        }
    }
    if e.iter().any(|v| !v.is_finite()) {
        return Err(TacitError::Numerical(format!(
            "calibration: the linear model's response to {} is not finite",
            data.source
        )));
    }
    Ok(e)
}

/// The projected residual of `model`'s linear part on `data`, segments of
/// `len` samples, `substeps` Newmark sub-steps per sample.
pub fn project(
    model: &Model,
    data: &Data,
    w: &[f64],
    len: usize,
    substeps: usize,
) -> Result<Projected> {
    let lin = model.linear_part();
    let sm = SampledModel::from_model(&lin, data.fs, substeps)?;
    let (cy, _) = sm.outputs(&data.channels)?;
    let u = observability_basis(&sm.a, &cy, w, len)?;
    let e = output_error(&sm, data, w)?;
    let p = cy.nrows();
    let starts = data.segment_starts(len);
    let mut r = DVector::zeros(starts.len() * len * p);
    for (s, &k0) in starts.iter().enumerate() {
        let es = DVector::from_fn(len * p, |i, _| e[(i % p, k0 + i / p)]);
        let rs = &es - &u * (u.transpose() * &es);
        r.rows_mut(s * len * p, len * p).copy_from(&rs);
    }
    Ok(Projected {
        r,
        rank: u.ncols(),
        segments: starts.len(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::Model;

    fn sdof() -> Model {
        Model::from_toml_str(
            r#"
name = "sdof"
masses = [2.0]
[[spring]]
dofs = [1]
stiffness = 8000.0
[damping]
kind = "rayleigh"
alpha = 1.0
beta = 0.0
"#,
            "sdof",
        )
        .unwrap()
    }

    /// A record of the model itself from a non-zero start state: the
    /// projected residual is zero to rounding (the start state is free),
    /// and it is not for a model 5 % stiffer.
    #[test]
    fn own_response_from_any_start_leaves_no_residual() {
        let m = sdof();
        let fs = 200.0;
        let sm = SampledModel::from_model(&m, fs, 10).unwrap();
        let ns = 400;
        let force = DMatrix::from_fn(1, ns, |_, k| ((k as f64) * 0.37).sin() * 3.0);
        let x0 = DVector::from_vec(vec![0.01, -0.2]);
        let xs = sm.simulate(&x0, &force);
        let (cy, dy) = sm.outputs(&[(Quantity::Accel, 0)]).unwrap();
        let y = &cy * &xs + &dy * &force;
        let data = Data {
            source: "own".into(),
            fs,
            force,
            measured: y,
            channels: vec![(Quantity::Accel, 0)],
            names: vec!["accel_1".into()],
            warmup: 0,
        };
        let w = data.weights();
        let r = project(&m, &data, &w, 100, 10).unwrap();
        assert_eq!(r.segments, 4);
        assert_eq!(r.rank, 2);
        assert!(r.r.norm() < 1e-10, "{}", r.r.norm());
        let mut stiff = m.clone();
        stiff.springs[0].stiffness *= 1.05;
        let r = project(&stiff, &data, &w, 100, 10).unwrap();
        assert!(r.r.norm() > 1e-2, "{}", r.r.norm());
    }
}
