//! The updating problem: a model, the measured channels and their weights,
//! the free parameters, the segmentation of the record with the start state
//! of each segment, the model order (full or reduced), the metric and the
//! minimum-change weight α.

use super::param::Parameter;
use super::shooting::Segment;
use crate::error::{Result, TacitError};
use crate::integrate::SimSettings;
use crate::model::Model;
use crate::record::{Quantity, Record};
use crate::reduce::Method;
use nalgebra::DMatrix;
use serde::Serialize;

/// One measured channel used in the fit.
#[derive(Debug, Clone, PartialEq)]
pub struct Observation {
    /// Displacement, velocity or acceleration.
    pub quantity: Quantity,
    /// DOF, from 1.
    pub dof: usize,
    /// Weight of the channel's residual (≥ 0). [`Problem::from_record`]
    /// sets `1 / ‖y‖₂` so that every channel counts by its relative error,
    /// whatever its unit.
    pub weight: f64,
    /// Measured samples (one per record sample).
    pub data: Vec<f64>,
    /// The point label of the record's channel, when it names one (a
    /// model from matrices: `n12:uy`).
    pub point: Option<String>,
}

impl Observation {
    /// Channel name as the record names it, e.g. `disp_4`, or
    /// `accel:n12:uy` at a labelled point.
    pub fn name(&self) -> String {
        crate::record::channel_name(self.quantity, self.dof, self.point.as_deref())
    }

    /// Standard deviation of this channel's weighted residual rows under
    /// white noise of `level` times the channel's RMS: `level w rms(y)`.
    pub fn noise_std(&self, level: f64) -> f64 {
        level * self.weight * crate::signal::rms_of(&self.data)
    }
}

/// The correlation metric.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(tag = "kind", rename_all = "lowercase")]
pub enum Metric {
    /// Generalized least squares (paper eqs 9–10): weighted differences of
    /// the measured and simulated samples.
    Gls,
    /// Principal component decomposition (paper eqs 11–12): differences of
    /// the paired right singular vectors and of the singular values of the
    /// channel × time matrices (see [`super::cost::pcd_residual`]).
    Pcd {
        /// Components are kept while their cumulated energy `Σσ²` stays
        /// below this fraction of the total (0 < energy ≤ 1; default
        /// 0.9999) — the rest is noise or negligible.
        energy: f64,
    },
}

impl Metric {
    /// PCD with the default energy fraction 0.9999.
    pub fn pcd() -> Metric {
        Metric::Pcd { energy: 0.9999 }
    }
}

/// An updating problem. Build it with [`Problem::from_record`] (or fill
/// the fields), then call [`super::fit`].
#[derive(Debug, Clone)]
pub struct Problem {
    /// The model at its nominal values.
    pub model: Model,
    /// Sample rate of the record, Hz.
    pub fs: f64,
    /// External force at every model DOF (DOF × sample).
    pub force: DMatrix<f64>,
    /// The measured channels used.
    pub observations: Vec<Observation>,
    /// Free parameters.
    pub parameters: Vec<Parameter>,
    /// Segments simulated, each from its own start state (one segment for
    /// the whole record; several for multiple shooting).
    pub segments: Vec<Segment>,
    /// `None`: full-order model; `Some(method)`: the model reduced to the
    /// measured DOFs (plus the DOFs of nonlinear elements) at every
    /// evaluation, i.e. the reduction follows the parameters.
    pub reduction: Option<Method>,
    /// The metric.
    pub metric: Metric,
    /// Weight α ≥ 0 of the minimum-change term `α ‖x − x0‖²` (x: scaled
    /// parameters, x0 = 0 at the nominal values).
    pub alpha: f64,
    /// Integrator settings of every simulation.
    pub sim: SimSettings,
}

impl Problem {
    /// A problem fitting `parameters` of `model` to the channels of
    /// `record` of the given quantities (all DOFs measured, or only `dofs`
    /// when given), over the whole record from the start state `(u0, v0)`
    /// (full-order DOFs), GLS metric, full order, α = 0, default integrator
    /// settings. Each channel is weighted by `1 / ‖y‖₂`.
    pub fn from_record(
        model: &Model,
        record: &Record,
        quantities: &[Quantity],
        dofs: Option<&[usize]>,
        parameters: Vec<Parameter>,
        u0: Vec<f64>,
        v0: Vec<f64>,
    ) -> Result<Problem> {
        let n = model.ndof();
        record.validate(Some(n))?;
        let mut observations = Vec::new();
        for &q in quantities {
            if q == Quantity::Force {
                return Err(TacitError::Setting(
                    "data: a force channel cannot be fitted; use disp, vel or accel".into(),
                ));
            }
            for ch in record.outputs.iter().filter(|c| c.quantity == q) {
                if dofs.is_some_and(|d| !d.contains(&ch.dof)) {
                    continue;
                }
                observations.push(Observation {
                    quantity: q,
                    dof: ch.dof,
                    weight: inverse_norm(&ch.data),
                    data: ch.data.clone(),
                    point: ch.point.clone(),
                });
            }
            if let Some(d) = dofs {
                for &dof in d {
                    if record.output(q, dof).is_none() {
                        return Err(TacitError::record(
                            record.source.clone(),
                            format!("no {}_{dof} channel in the record", q.prefix()),
                        ));
                    }
                }
            }
        }
        if observations.is_empty() {
            return Err(TacitError::record(
                record.source.clone(),
                format!(
                    "no output channel of the requested kinds ({})",
                    quantities
                        .iter()
                        .map(|q| q.prefix())
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
            ));
        }
        let samples = record.len();
        Ok(Problem {
            model: model.clone(),
            fs: record.fs,
            force: crate::signal::force_matrix(record, n),
            observations,
            parameters,
            segments: vec![Segment {
                start: 0,
                len: samples,
                u0,
                v0,
            }],
            reduction: None,
            metric: Metric::Gls,
            alpha: 0.0,
            sim: SimSettings::default(),
        })
    }

    /// Number of record samples.
    pub fn samples(&self) -> usize {
        self.force.ncols()
    }

    /// Measured DOFs (from 1), in order of first appearance.
    pub fn measured_dofs(&self) -> Vec<usize> {
        let mut d: Vec<usize> = Vec::new();
        for o in &self.observations {
            if !d.contains(&o.dof) {
                d.push(o.dof);
            }
        }
        d
    }

    /// Scaled start vector of the free parameters.
    pub fn x_start(&self) -> Vec<f64> {
        self.parameters.iter().map(|p| p.to_x(p.start)).collect()
    }

    /// Scaled bounds of the free parameters.
    pub fn x_bounds(&self) -> (Vec<f64>, Vec<f64>) {
        let lo = self.parameters.iter().map(|p| p.to_x(p.lower)).collect();
        let hi = self.parameters.iter().map(|p| p.to_x(p.upper)).collect();
        (lo, hi)
    }

    /// The model at scaled parameters `x`.
    pub fn model_at(&self, x: &[f64]) -> Model {
        let mut m = self.model.clone();
        for (p, &xi) in self.parameters.iter().zip(x) {
            p.target.set(&mut m, p.from_x(xi));
        }
        m
    }

    /// Check everything before any work; errors name the parameter, channel,
    /// segment or setting.
    pub fn validate(&self) -> Result<()> {
        let n = self.model.ndof();
        self.model.validate(&self.model.name)?;
        self.sim.validate()?;
        if self.parameters.is_empty() {
            return Err(TacitError::Setting(
                "no free parameter: give at least one (e.g. k1..k4,cubic)".into(),
            ));
        }
        for (i, p) in self.parameters.iter().enumerate() {
            p.validate(&self.model)?;
            if self.parameters[..i].iter().any(|q| q.target == p.target) {
                return Err(TacitError::Setting(format!(
                    "parameter {} appears twice",
                    p.name
                )));
            }
        }
        if !(self.fs.is_finite() && self.fs > 0.0) {
            return Err(TacitError::Setting(format!(
                "sample rate {} must be > 0",
                self.fs
            )));
        }
        if self.force.nrows() != n {
            return Err(TacitError::Setting(format!(
                "force matrix has {} rows, the model {n} DOFs",
                self.force.nrows()
            )));
        }
        if !(self.alpha.is_finite() && self.alpha >= 0.0) {
            return Err(TacitError::Setting(format!(
                "alpha = {}: the minimum-change weight must be >= 0",
                self.alpha
            )));
        }
        if let Metric::Pcd { energy } = self.metric {
            if !(energy > 0.0 && energy <= 1.0) {
                return Err(TacitError::Setting(format!(
                    "PCD energy fraction {energy} must be in (0, 1]"
                )));
            }
        }
        self.validate_observations()?;
        super::shooting::validate_segments(&self.segments, n, self.samples())
    }

    fn validate_observations(&self) -> Result<()> {
        let n = self.model.ndof();
        if self.observations.is_empty() {
            return Err(TacitError::Setting("no measured channel to fit".into()));
        }
        for o in &self.observations {
            if o.dof < 1 || o.dof > n {
                return Err(TacitError::Setting(format!(
                    "channel {}: DOF {} is outside the model (1..={n})",
                    o.name(),
                    o.dof
                )));
            }
            if o.quantity == Quantity::Force {
                return Err(TacitError::Setting(format!(
                    "channel {}: a force channel cannot be fitted",
                    o.name()
                )));
            }
            if o.data.len() != self.samples() {
                return Err(TacitError::Setting(format!(
                    "channel {} has {} samples, the force {}",
                    o.name(),
                    o.data.len(),
                    self.samples()
                )));
            }
            if let Some(k) = o.data.iter().position(|v| !v.is_finite()) {
                return Err(TacitError::Setting(format!(
                    "channel {}: sample {k} is not finite",
                    o.name()
                )));
            }
            if !(o.weight.is_finite() && o.weight >= 0.0) {
                return Err(TacitError::Setting(format!(
                    "channel {}: weight {} must be finite and >= 0",
                    o.name(),
                    o.weight
                )));
            }
        }
        Ok(())
    }
}

/// `1/‖y‖₂`, or 1 for an all-zero channel.
fn inverse_norm(y: &[f64]) -> f64 {
    let n = y.iter().map(|v| v * v).sum::<f64>().sqrt();
    if n > 0.0 {
        1.0 / n
    } else {
        1.0
    }
}
