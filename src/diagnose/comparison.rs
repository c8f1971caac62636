//! The data a model is compared with: the record's observed channels,
//! its input, and the segments of the multiple-shooting error with their
//! reconstructed start states.

use super::settings::StartSettings;
use crate::integrate::SimSettings;
use crate::model::Model;
use crate::update::problem::{Metric, Observation, Problem};
use crate::update::shooting::Segment;
use nalgebra::{DMatrix, DMatrixView, DVector};

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

/// Why the multiple shooting (or the open-loop run) of a model failed.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ShotError {
    /// The simulation of the segments failed (the simulator's message).
    Simulation(String),
    /// A segment's prediction is not finite after its start state was
    /// refined: the segment (index, when found) and the first sample.
    Segment {
        /// Index of the segment.
        segment: Option<usize>,
        /// Sample (of the record) where the prediction is NaN.
        sample: usize,
    },
    /// The predictions were computed but their error is not finite (a
    /// record or a prediction beyond double precision's range).
    NotFinite,
}

impl std::fmt::Display for ShotError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ShotError::Simulation(m) => write!(f, "{m}"),
            ShotError::Segment { segment, sample } => write!(
                f,
                "segment {} (sample {sample}) could not be simulated from its start state",
                segment.map_or("?".into(), |s| s.to_string())
            ),
            ShotError::NotFinite => write!(
                f,
                "the error is not finite (the record or the predictions exceed double precision's range)"
            ),
        }
    }
}

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
    /// Samples at the start of the open-loop run simulated but not scored
    /// ([`super::DiagnoseSettings::unscored`]; less than the record's
    /// length).
    pub unscored: usize,
    /// The segment start-state refinement ([`super::starts`];
    /// `iterations` 0: the reconstructed start states as they are).
    pub starts: StartSettings,
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
    ) -> std::result::Result<DMatrix<f64>, ShotError> {
        let p = self.problem(model, segments.to_vec(), sim);
        let rows =
            crate::update::predict(&p, &[]).map_err(|e| ShotError::Simulation(e.to_string()))?;
        let ns = self.force.ncols();
        Ok(DMatrix::from_fn(rows.len(), ns, |c, k| rows[c][k]))
    }

    /// Open-loop RMS error of channel `c` in the channel's units over the
    /// finite samples of `y` (p × N) from [`Self::unscored`] on.
    pub fn channel_rms(&self, y: &DMatrix<f64>, c: usize) -> f64 {
        let d = &self.observations[c].data;
        let (mut num, mut count) = (0.0, 0usize);
        for (k, m) in d.iter().enumerate().skip(self.unscored) {
            let v = y[(c, k)];
            if v.is_finite() {
                num += (v - m) * (v - m);
                count += 1;
            }
        }
        if count == 0 {
            f64::NAN
        } else {
            (num / count as f64).sqrt()
        }
    }

    /// The open-loop prediction `y` (p × N) with its unscored samples
    /// blanked (NaN), as the errors count it.
    pub fn scored(&self, mut y: DMatrix<f64>) -> DMatrix<f64> {
        let n = self.unscored.min(y.ncols());
        y.columns_mut(0, n).fill(f64::NAN);
        y
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::record::Quantity;

    fn comparison(unscored: usize) -> Comparison {
        let data = vec![1.0, -1.0, 2.0, -2.0, 0.5, 0.0];
        let seg = Segment {
            start: 0,
            len: data.len(),
            u0: vec![0.0],
            v0: vec![0.0],
        };
        Comparison {
            fs: 10.0,
            force: DMatrix::zeros(1, data.len()),
            observations: vec![Observation {
                quantity: Quantity::Disp,
                dof: 1,
                point: None,
                weight: 1.0,
                data,
            }],
            segments: vec![seg.clone()],
            whole: seg,
            unscored,
            starts: StartSettings::default(),
        }
    }

    /// The RMS error in the channel's units over the samples scored: the
    /// unscored ones and non-finite predictions left out.
    #[test]
    fn channel_rms_leaves_out_the_unscored_samples() {
        // prediction errors 3, 0, 0.1, −0.1, NaN, 0.2
        let y = DMatrix::from_row_slice(1, 6, &[4.0, -1.0, 2.1, -2.1, f64::NAN, 0.2]);
        let all = comparison(0).channel_rms(&y, 0);
        let want = ((9.0 + 0.0 + 0.01 + 0.01 + 0.04) / 5.0f64).sqrt();
        assert!((all - want).abs() < 1e-12, "{all} vs {want}");
        let c = comparison(2);
        let skipped = c.channel_rms(&y, 0);
        assert!(
            (skipped - (0.06f64 / 3.0).sqrt()).abs() < 1e-12,
            "{skipped}"
        );
        // the relative error counts the same samples once blanked
        let blanked = c.scored(y);
        assert!(blanked[(0, 0)].is_nan() && blanked[(0, 1)].is_nan());
        assert_eq!(blanked[(0, 2)], 2.1);
        let rel = c.channel_error(&blanked, 0);
        let den = 4.0 + 4.0 + 0.0;
        assert!((rel - (0.06f64 / den).sqrt()).abs() < 1e-12, "{rel}");
    }
}
