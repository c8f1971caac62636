//! The two errors of a model against a record: multiple-shooting
//! prediction error over short segments from start states refined for the
//! model ([`super::starts`]; `relative_error`, the headline) and open-loop
//! simulation error over the whole record (`simulation_error`).

pub use super::comparison::{segment_residual, Comparison, ShotError};
use super::starts::StartFit;
use crate::integrate::SimSettings;
use crate::model::Model;
use crate::update::shooting::Segment;
use nalgebra::DMatrix;
use serde::Serialize;
use std::collections::BTreeMap;

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
    /// Open-loop RMS error per channel (by name) in the channel's units
    /// (SI: m, m/s, m/s²), over the samples scored (null where the
    /// open-loop run failed).
    pub rms_per_channel: BTreeMap<String, Option<f64>>,
    /// What failed, if anything (written `"ok"` or the failures joined by
    /// `; ` in report.json).
    pub status: ErrorStatus,
    /// The start-state refinement of the multiple-shooting error (None
    /// when off or when the segments could not be simulated).
    pub starts: Option<StartFit>,
    /// The open-loop prediction of the record (p × N; None when it
    /// failed), for the report's figures.
    #[serde(skip)]
    pub open_loop_prediction: Option<DMatrix<f64>>,
}

/// The failures behind an [`ErrorSet`]'s missing errors.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ErrorStatus {
    /// Why the multiple shooting failed.
    pub multiple_shooting: Option<ShotError>,
    /// Why the open-loop run failed.
    pub open_loop: Option<ShotError>,
}

impl ErrorStatus {
    /// Nothing failed.
    pub fn is_ok(&self) -> bool {
        self.multiple_shooting.is_none() && self.open_loop.is_none()
    }
}

impl std::fmt::Display for ErrorStatus {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let mut parts = vec![];
        if let Some(e) = &self.multiple_shooting {
            parts.push(format!("multiple shooting: {e}"));
        }
        if let Some(e) = &self.open_loop {
            parts.push(format!("open-loop simulation: {e}"));
        }
        if parts.is_empty() {
            write!(f, "ok")
        } else {
            write!(f, "{}", parts.join("; "))
        }
    }
}

impl Serialize for ErrorStatus {
    fn serialize<S: serde::Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        s.collect_str(self)
    }
}

/// Multiple-shooting predictions (p × N), the segments with the start
/// states used, and the refinement that produced them.
pub type Shot = (DMatrix<f64>, Vec<Segment>, Option<StartFit>);

/// A model's multiple shooting, or why it failed.
pub type ShotResult = std::result::Result<Shot, ShotError>;

/// A refinement of the segments' start states ([`super::starts::refine`],
/// [`super::starts::refine_both`]).
pub(super) type Refine = fn(
    &Comparison,
    &Model,
    SimSettings,
    &[Segment],
    usize,
) -> (Vec<Segment>, DMatrix<f64>, StartFit);

impl Comparison {
    /// Multiple-shooting predictions of `model` (p × N) with the start
    /// states refined for it ([`super::starts::refine`], when
    /// `starts.iterations > 0`), the segments used and the refinement; Err
    /// names a failed simulation.
    pub fn shoot(&self, model: &Model, sim: SimSettings) -> ShotResult {
        self.shoot_by(model, sim, super::starts::refine)
    }

    /// [`Comparison::shoot`] with the start states refined by `refine`
    /// (one of [`super::starts`]'s refinements).
    pub(super) fn shoot_by(&self, model: &Model, sim: SimSettings, refine: Refine) -> ShotResult {
        self.shoot_refined(model, sim, refine, self.starts.iterations)
    }

    /// [`Comparison::shoot_by`] with `iterations` Gauss–Newton iterations
    /// of the refinement in place of `starts.iterations` (0: the segments'
    /// start states as they are).
    pub(super) fn shoot_refined(
        &self,
        model: &Model,
        sim: SimSettings,
        refine: Refine,
        iterations: usize,
    ) -> ShotResult {
        if iterations == 0 {
            let y = self.predict(model, &self.segments, sim)?;
            return Ok((y, self.segments.clone(), None));
        }
        let (segs, y, fit) = refine(self, model, sim, &self.segments, iterations);
        if let Some(k) = (0..y.ncols()).find(|&k| y.column(k).iter().any(|v| v.is_nan())) {
            let segment = segs
                .iter()
                .position(|s| k >= s.start && k < s.start + s.len);
            return Err(ShotError::Segment { segment, sample: k });
        }
        Ok((y, segs, Some(fit)))
    }

    /// Both errors of `model`, and its segment predictions (p × N; None
    /// when a segment simulation failed).
    pub fn errors(&self, model: &Model, sim: SimSettings) -> (ErrorSet, Option<DMatrix<f64>>) {
        self.errors_by(model, sim, super::starts::refine)
    }

    /// [`Comparison::errors`] with the start states refined by `refine`.
    pub(super) fn errors_by(
        &self,
        model: &Model,
        sim: SimSettings,
        refine: Refine,
    ) -> (ErrorSet, Option<DMatrix<f64>>) {
        // the open-loop run is one long simulation: beside the segments'
        let (shot, whole) = rayon::join(
            || self.shoot_by(model, sim, refine),
            || self.open_loop(model, sim),
        );
        self.errors_with(shot, whole)
    }

    /// The open-loop prediction of `model` over the whole record (p × N).
    fn open_loop(
        &self,
        model: &Model,
        sim: SimSettings,
    ) -> std::result::Result<DMatrix<f64>, ShotError> {
        self.predict(model, std::slice::from_ref(&self.whole), sim)
    }

    /// [`Comparison::errors`] with the multiple shooting of `model` at
    /// `sim` already done (`shot`, from [`Comparison::shoot`]).
    pub fn errors_of(
        &self,
        model: &Model,
        sim: SimSettings,
        shot: ShotResult,
    ) -> (ErrorSet, Option<DMatrix<f64>>) {
        self.errors_with(shot, self.open_loop(model, sim))
    }

    /// [`Comparison::errors_of`] with the open-loop prediction done
    /// ([`Comparison::open_loop`]).
    fn errors_with(
        &self,
        shot: ShotResult,
        open_loop: std::result::Result<DMatrix<f64>, ShotError>,
    ) -> (ErrorSet, Option<DMatrix<f64>>) {
        let mut status = ErrorStatus::default();
        let mut starts = None;
        let seg = match shot {
            Ok((y, _, fit)) => {
                starts = fit;
                Some(y)
            }
            Err(e) => {
                status.multiple_shooting = Some(e);
                None
            }
        };
        let whole = match open_loop {
            Ok(y) => Some(self.scored(y)),
            Err(e) => {
                status.open_loop = Some(e);
                None
            }
        };
        let rel = |y: &Option<DMatrix<f64>>, c: usize| y.as_ref().map(|y| self.channel_error(y, c));
        let per_channel: Vec<ChannelError> = self
            .observations
            .iter()
            .enumerate()
            .map(|(c, o)| ChannelError {
                channel: o.name(),
                relative_error: rel(&seg, c),
                simulation_error: rel(&whole, c),
            })
            .collect();
        let rms_per_channel = self
            .observations
            .iter()
            .enumerate()
            .map(|(c, o)| {
                let rms = whole.as_ref().map(|y| self.channel_rms(y, c));
                (o.name(), rms.filter(|v| v.is_finite()))
            })
            .collect();
        let relative_error = seg.as_ref().map(|y| self.total_error(y));
        let simulation_error = whole.as_ref().map(|y| self.total_error(y));
        let finite = |e: Option<f64>| e.is_none_or(f64::is_finite);
        if !finite(relative_error) || !per_channel.iter().all(|c| finite(c.relative_error)) {
            status.multiple_shooting = Some(ShotError::NotFinite);
        }
        if !finite(simulation_error) || !per_channel.iter().all(|c| finite(c.simulation_error)) {
            status.open_loop = Some(ShotError::NotFinite);
        }
        let set = ErrorSet {
            relative_error,
            simulation_error,
            per_channel,
            rms_per_channel,
            status,
            starts,
            open_loop_prediction: whole,
        };
        (set, seg)
    }
}

/// Segment simulations spent by [`Comparison::shoot`]: the start-state
/// refinement's, or one per segment.
pub(super) fn shot_simulations(starts: Option<&StartFit>, cmp: &Comparison) -> usize {
    starts.map_or(cmp.segments.len(), |f| f.simulations)
}

/// Segment simulations spent by [`Comparison::errors`]: the multiple
/// shooting and the open-loop run.
pub(super) fn error_simulations(set: &ErrorSet, cmp: &Comparison) -> usize {
    shot_simulations(set.starts.as_ref(), cmp) + 1
}
