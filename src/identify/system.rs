//! The identification problem (record + model + sensors) and the sampled,
//! possibly reduced, linear system the windows work on.
//!
//! With a reduction `u ≈ T u_a` onto the sensor DOFs (docs/theory.md, Definitions) the
//! reduced model is `T^T M T ü_a + T^T C T u̇_a + T^T K T u_a = T^T (f_ext − f)`,
//! where `f` is the internal force (left-hand-side convention of
//! [`crate::model`]: `M ü + C u̇ + K u + f = f_ext`). Without reduction
//! `T = I`. Sampled with [`SampledModel`] (Newmark, `S` sub-steps, forces
//! linear between samples), with `w_k = B_f f_k + B_e e_k`,
//! `B_f = −T^T`, `B_e = T^T S_e` (`S_e` places each measured input channel
//! at its DOF):
//!
//! $$ x_{k+1} = A x_k + B_0 w_k + B_1 w_{k+1}, \qquad y_k = C_y x_k + D_y w_k . $$

use crate::error::{Result, TacitError};
use crate::linear::SampledModel;
use crate::model::Model;
use crate::record::{Quantity, Record};
use crate::reduce::{reduce, Reduction};
use nalgebra::{DMatrix, DVector};

use super::settings::Reduce;

/// What is identified from what: the linear model's matrices, the measured
/// channels at the sensors and the measured input, as matrices.
#[derive(Debug, Clone)]
pub struct Problem {
    /// Model name (for reports).
    pub model_name: String,
    /// Record file (for reports and errors); `<memory>` when built in memory.
    pub record_name: String,
    /// Full-order mass matrix (n × n).
    pub m: DMatrix<f64>,
    /// Full-order damping matrix.
    pub c: DMatrix<f64>,
    /// Full-order stiffness matrix (linear part of the model).
    pub k: DMatrix<f64>,
    /// Sensor DOFs, 0-based, in the order given.
    pub sensors: Vec<usize>,
    /// Measured channels `(quantity, dof0)`: every output channel of the
    /// record at a sensor DOF, sensor by sensor.
    pub channels: Vec<(Quantity, usize)>,
    /// Channel names (`accel_5`).
    pub channel_names: Vec<String>,
    /// Measured outputs (channels × samples).
    pub y: DMatrix<f64>,
    /// DOFs (0-based) of the measured input channels.
    pub input_dofs: Vec<usize>,
    /// Measured inputs (input channels × samples), N.
    pub e: DMatrix<f64>,
    /// Sample rate, Hz.
    pub fs: f64,
    /// Time of sample 0, s.
    pub t0: f64,
    /// True internal force (n × samples) when the record carries its truth.
    pub truth_fint: Option<DMatrix<f64>>,
}

impl Problem {
    /// Gather the problem. `sensors` are DOFs numbered from 1. Errors name
    /// the record file, the DOF and the channel.
    pub fn new(model: &Model, record: &Record, sensors: &[usize]) -> Result<Problem> {
        let n = model.ndof();
        let rname = crate::record::display_path(record).display().to_string();
        let rname = if rname.is_empty() {
            "<memory>".to_string()
        } else {
            rname
        };
        if sensors.is_empty() {
            return Err(TacitError::Setting("no sensor DOF given".into()));
        }
        for (i, &d) in sensors.iter().enumerate() {
            if d < 1 || d > n {
                return Err(TacitError::Setting(format!(
                    "sensor DOF {d} is outside the model {} (1..={n})",
                    model.name
                )));
            }
            if sensors[..i].contains(&d) {
                return Err(TacitError::Setting(format!(
                    "sensor DOF {d} is listed twice"
                )));
            }
        }
        record.validate(Some(n))?;
        let mut channels = Vec::new();
        let mut names = Vec::new();
        let mut rows: Vec<&[f64]> = Vec::new();
        for &d in sensors {
            let found: Vec<_> = record.outputs.iter().filter(|c| c.dof == d).collect();
            if found.is_empty() {
                return Err(TacitError::record(
                    &record.source,
                    format!(
                        "no output channel at sensor DOF {d} (channels: {})",
                        record
                            .outputs
                            .iter()
                            .map(|c| c.name())
                            .collect::<Vec<_>>()
                            .join(", ")
                    ),
                ));
            }
            for c in found {
                channels.push((c.quantity, d - 1));
                names.push(c.name());
                rows.push(&c.data);
            }
        }
        let ns = record.len();
        let y = DMatrix::from_fn(rows.len(), ns, |i, k| rows[i][k]);
        let e = DMatrix::from_fn(record.inputs.len(), ns, |i, k| record.inputs[i].data[k]);
        let input_dofs = record.inputs.iter().map(|c| c.dof - 1).collect();
        let truth_fint = record.truth.as_ref().and_then(|t| {
            (t.fint.len() == n && t.fint.iter().all(|r| r.len() == ns))
                .then(|| DMatrix::from_fn(n, ns, |i, k| t.fint[i][k]))
        });
        Ok(Problem {
            model_name: model.name.clone(),
            record_name: rname,
            m: model.mass_matrix(),
            c: model.damping_matrix()?,
            k: model.stiffness_matrix(),
            sensors: sensors.iter().map(|d| d - 1).collect(),
            channels,
            channel_names: names,
            y,
            input_dofs,
            e,
            fs: record.fs,
            t0: record.t0,
            truth_fint,
        })
    }

    /// Number of DOFs of the full-order model.
    pub fn ndof(&self) -> usize {
        self.m.nrows()
    }
    /// Number of samples.
    pub fn len(&self) -> usize {
        self.y.ncols()
    }
    /// True when the record holds no sample.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Time of every sample, s.
    pub fn times(&self) -> Vec<f64> {
        (0..self.len())
            .map(|k| self.t0 + k as f64 / self.fs)
            .collect()
    }
}

/// The sampled (reduced) linear system with its input and output maps.
#[derive(Debug, Clone)]
pub struct System {
    /// Sampled model in the (reduced) coordinates.
    pub sm: SampledModel,
    /// The reduction, when one was made.
    pub reduction: Option<Reduction>,
    /// Basis `T` (n × m); the identity without reduction.
    pub t: DMatrix<f64>,
    /// Internal force → generalized force: `−T^T` (m × n).
    pub bf: DMatrix<f64>,
    /// Measured input → generalized force: `T^T S_e` (m × n_e).
    pub be: DMatrix<f64>,
    /// Output matrix on the state (p × 2m).
    pub cy: DMatrix<f64>,
    /// Output matrix on the generalized force (p × m).
    pub dy: DMatrix<f64>,
}

impl System {
    /// Reduce (or not), sample and build the input/output maps.
    pub fn new(p: &Problem, reduce_with: Reduce, substeps: usize) -> Result<System> {
        let n = p.ndof();
        let reduction = match reduce_with.method() {
            None => None,
            Some(method) => Some(
                reduce(&p.m, &p.k, &p.sensors, method)
                    .map_err(|e| TacitError::Numerical(format!("model {}: {e}", p.model_name)))?,
            ),
        };
        let (t, sm) = match &reduction {
            None => (
                DMatrix::identity(n, n),
                SampledModel::new(p.m.clone(), p.c.clone(), p.k.clone(), p.fs, substeps)?,
            ),
            Some(r) => (
                r.t.clone(),
                SampledModel::new(r.m.clone(), r.project(&p.c), r.k.clone(), p.fs, substeps)?,
            ),
        };
        let mr = t.ncols();
        let bf = -t.transpose();
        let mut se = DMatrix::zeros(n, p.input_dofs.len());
        for (j, &d) in p.input_dofs.iter().enumerate() {
            se[(d, j)] = 1.0;
        }
        let be = t.transpose() * se;
        let np = p.channels.len();
        let mut cy = DMatrix::zeros(np, 2 * mr);
        let mut dy = DMatrix::zeros(np, mr);
        for (r, &(q, d)) in p.channels.iter().enumerate() {
            let all: Vec<(Quantity, usize)> = (0..mr).map(|i| (q, i)).collect();
            let (c_all, d_all) = sm.outputs(&all)?;
            let trow = t.row(d);
            cy.row_mut(r).copy_from(&(trow * c_all));
            dy.row_mut(r).copy_from(&(trow * d_all));
        }
        Ok(System {
            sm,
            reduction,
            t,
            bf,
            be,
            cy,
            dy,
        })
    }

    /// Number of reduced coordinates m.
    pub fn m(&self) -> usize {
        self.sm.n
    }
    /// Number of force components n (full-order DOFs).
    pub fn n(&self) -> usize {
        self.t.nrows()
    }
    /// Number of measured channels p.
    pub fn p(&self) -> usize {
        self.cy.nrows()
    }
    /// Number of measured inputs.
    pub fn ne(&self) -> usize {
        self.be.ncols()
    }

    /// Generalized force `w = B_f f + B_e e` for one sample.
    pub fn gen_force(&self, f: &[f64], e: &[f64]) -> DVector<f64> {
        let mut w = DVector::zeros(self.m());
        w.gemv(1.0, &self.bf, &DVector::from_column_slice(f), 0.0);
        if !e.is_empty() {
            w.gemv(1.0, &self.be, &DVector::from_column_slice(e), 1.0);
        }
        w
    }

    /// Simulate the (reduced) model from `x0` under internal force `f`
    /// (n × N) and the measured input `e`; returns the states (2m × N) and
    /// the outputs (p × N).
    pub fn simulate(
        &self,
        x0: &DVector<f64>,
        f: &DMatrix<f64>,
        e: &DMatrix<f64>,
    ) -> (DMatrix<f64>, DMatrix<f64>) {
        let w = &self.bf * f + &self.be * e;
        let xs = self.sm.simulate(x0, &w);
        let ys = &self.cy * &xs + &self.dy * &w;
        (xs, ys)
    }
}
