//! The two errors of a model against a record: multiple-shooting
//! prediction error over short segments from estimated start states
//! (`relative_error`, the headline) and open-loop simulation error over the
//! whole record (`simulation_error`).

use super::starts::StartFit;
use crate::integrate::SimSettings;
use crate::model::Model;
use crate::update::problem::{Metric, Observation, Problem};
use crate::update::shooting::Segment;
use nalgebra::{DMatrix, DMatrixView, DVector};
use serde::Serialize;

/// Errors of one channel.
#[derive(Debug, Clone, Serialize)]
pub struct ChannelError {
    /// Channel name, e.g. `accel_5`.
    pub channel: String,
    /// Multiple-shooting relative error ‖ŷ − y‖ / ‖y‖ over all segments.
    pub relative_error: Option<f64>,
    /// Open-loop relative error over the whole record.
    pub simulation_error: Option<f64>,
}

/// Errors of a model on a record. `None` (JSON null) where a simulation
/// failed; `status` says why.
#[derive(Debug, Clone, Serialize)]
pub struct ErrorSet {
    /// Multiple-shooting relative error over all channels.
    pub relative_error: Option<f64>,
    /// Open-loop relative error over all channels.
    pub simulation_error: Option<f64>,
    /// Per channel.
    pub per_channel: Vec<ChannelError>,
    /// "ok", or what failed.
    pub status: String,
    /// The start-state refinement of the multiple-shooting error (None
    /// when off or when the segments could not be simulated).
    pub starts: Option<super::starts::StartFit>,
}

/// Weighted residual `w_c (y_c − ŷ_c)` of one segment from its predicted
/// channels `y` (observation × sample of the segment), rows sample-major
/// (`k p + c`); `None` when a prediction is not finite.
pub fn segment_residual(
    observations: &[Observation],
    seg: &Segment,
    y: DMatrixView<'_, f64>,
) -> Option<DVector<f64>> {
    let p = observations.len();
    let mut r = DVector::zeros(seg.len * p);
    for k in 0..seg.len {
        for (c, o) in observations.iter().enumerate() {
            let v = y[(c, k)];
            if !v.is_finite() {
                return None;
            }
            r[k * p + c] = o.weight * (o.data[seg.start + k] - v);
        }
    }
    Some(r)
}

/// Multiple-shooting predictions (p × N), the segments with the start
/// states used, and the refinement that produced them.
pub type Shot = (DMatrix<f64>, Vec<Segment>, Option<StartFit>);

/// The data a model is compared with.
#[derive(Debug, Clone)]
pub struct Comparison {
    /// Sample rate, Hz.
    pub fs: f64,
    /// External force (n × N).
    pub force: DMatrix<f64>,
    /// Observed channels.
    pub observations: Vec<Observation>,
    /// Segments with start states (multiple shooting).
    pub segments: Vec<Segment>,
    /// The open-loop segment (whole record from the estimated start).
    pub whole: Segment,
    /// Gauss–Newton iterations of the segment start-state refinement
    /// ([`super::starts`]; 0 = the reconstructed start states as they are).
    pub start_iterations: usize,
}

impl Comparison {
    /// An updating problem with no free parameter on the given segments.
    pub fn problem(&self, model: &Model, segments: Vec<Segment>, sim: SimSettings) -> Problem {
        Problem {
            model: model.clone(),
            fs: self.fs,
            force: self.force.clone(),
            observations: self.observations.clone(),
            parameters: vec![],
            segments,
            reduction: None,
            metric: Metric::Gls,
            alpha: 0.0,
            sim,
        }
    }

    /// Predicted channels (p × N) over the segments; Err names the failure.
    pub fn predict(
        &self,
        model: &Model,
        segments: &[Segment],
        sim: SimSettings,
    ) -> std::result::Result<DMatrix<f64>, String> {
        let p = self.problem(model, segments.to_vec(), sim);
        let rows = crate::update::predict(&p, &[]).map_err(|e| e.to_string())?;
        let ns = self.force.ncols();
        Ok(DMatrix::from_fn(rows.len(), ns, |c, k| rows[c][k]))
    }

    /// Multiple-shooting predictions of `model` (p × N) with the start
    /// states refined for it ([`super::starts::refine`], when
    /// `start_iterations > 0`), the segments used and the refinement; Err
    /// names a failed simulation.
    pub fn shoot(&self, model: &Model, sim: SimSettings) -> std::result::Result<Shot, String> {
        if self.start_iterations == 0 {
            let y = self.predict(model, &self.segments, sim)?;
            return Ok((y, self.segments.clone(), None));
        }
        let (segs, y, fit) =
            super::starts::refine(self, model, sim, &self.segments, self.start_iterations);
        if let Some(k) = (0..y.ncols()).find(|&k| y.column(k).iter().any(|v| v.is_nan())) {
            let s = segs
                .iter()
                .position(|s| k >= s.start && k < s.start + s.len)
                .map_or("?".into(), |i| i.to_string());
            return Err(format!(
                "segment {s} (sample {k}) could not be simulated from its start state"
            ));
        }
        Ok((y, segs, Some(fit)))
    }

    /// Both errors of `model`, and its segment predictions (p × N; None
    /// when a segment simulation failed).
    pub fn errors(&self, model: &Model, sim: SimSettings) -> (ErrorSet, Option<DMatrix<f64>>) {
        self.errors_of(model, sim, self.shoot(model, sim))
    }

    /// [`Comparison::errors`] with the multiple shooting of `model` at
    /// `sim` already done (`shot`, from [`Comparison::shoot`]).
    pub fn errors_of(
        &self,
        model: &Model,
        sim: SimSettings,
        shot: std::result::Result<Shot, String>,
    ) -> (ErrorSet, Option<DMatrix<f64>>) {
        let mut status = vec![];
        let mut starts = None;
        let seg = match shot {
            Ok((y, _, fit)) => {
                starts = fit;
                Some(y)
            }
            Err(e) => {
                status.push(format!("multiple shooting: {e}"));
                None
            }
        };
        let whole = match self.predict(model, std::slice::from_ref(&self.whole), sim) {
            Ok(y) => Some(y),
            Err(e) => {
                status.push(format!("open-loop simulation: {e}"));
                None
            }
        };
        let rel = |y: &Option<DMatrix<f64>>, c: usize| y.as_ref().map(|y| self.channel_error(y, c));
        let per_channel = self
            .observations
            .iter()
            .enumerate()
            .map(|(c, o)| ChannelError {
                channel: o.name(),
                relative_error: rel(&seg, c),
                simulation_error: rel(&whole, c),
            })
            .collect();
        let set = ErrorSet {
            relative_error: seg.as_ref().map(|y| self.total_error(y)),
            simulation_error: whole.as_ref().map(|y| self.total_error(y)),
            per_channel,
            status: if status.is_empty() {
                "ok".into()
            } else {
                status.join("; ")
            },
            starts,
        };
        (set, seg)
    }

    fn sums(&self, y: &DMatrix<f64>, c: usize) -> (f64, f64) {
        let d = &self.observations[c].data;
        let (mut num, mut den) = (0.0, 0.0);
        for (k, m) in d.iter().enumerate() {
            let v = y[(c, k)];
            if v.is_finite() {
                num += (v - m) * (v - m);
                den += m * m;
            }
        }
        (num, den)
    }

    /// Relative error of one channel (samples covered by the segments).
    pub fn channel_error(&self, y: &DMatrix<f64>, c: usize) -> f64 {
        let (num, den) = self.sums(y, c);
        crate::metrics::ratio(num, den)
    }

    /// Relative error over all channels.
    pub fn total_error(&self, y: &DMatrix<f64>) -> f64 {
        let (mut num, mut den) = (0.0, 0.0);
        for c in 0..self.observations.len() {
            let (a, b) = self.sums(y, c);
            num += a;
            den += b;
        }
        crate::metrics::ratio(num, den)
    }

    /// Measured channels as a p × N matrix.
    pub fn measured(&self) -> DMatrix<f64> {
        DMatrix::from_fn(self.observations.len(), self.force.ncols(), |c, k| {
            self.observations[c].data[k]
        })
    }
}
