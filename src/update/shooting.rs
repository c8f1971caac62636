//! Segments of a record for multiple shooting.
//!
//! A segment covers record samples `start .. start + len` and is simulated
//! from its own start state `(u0, v0)` at sample `start` (full-order DOFs).
//! One segment over the whole record is the classical open-loop fit; many
//! short segments keep a chaotic or impacting response close to the test
//! (docs/theory.md, fact R4): the simulation error of each segment then measures
//! the model, not the accumulated divergence of two trajectories.

use crate::error::{Result, TacitError};
use crate::record::Record;
use serde::Serialize;

/// One simulated stretch of the record.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Segment {
    /// First sample (the start state is the state at this sample).
    pub start: usize,
    /// Number of samples, the first included (≥ 2).
    pub len: usize,
    /// Displacement at `start`, one value per model DOF, m.
    pub u0: Vec<f64>,
    /// Velocity at `start`, one value per model DOF, m/s.
    pub v0: Vec<f64>,
}

/// Cut `samples` into consecutive segments of `len` samples (the last one
/// may be longer, to absorb a remainder of at most `len / 2`, or shorter
/// otherwise), each started from `state(start)`.
pub fn uniform<F>(samples: usize, len: usize, mut state: F) -> Result<Vec<Segment>>
where
    F: FnMut(usize) -> Result<(Vec<f64>, Vec<f64>)>,
{
    if len < 2 {
        return Err(TacitError::Setting(format!(
            "segment length {len} must be >= 2 samples"
        )));
    }
    if samples < 2 {
        return Err(TacitError::Setting(format!(
            "a record of {samples} samples cannot be segmented"
        )));
    }
    let mut out = Vec::new();
    let mut start = 0;
    while start + 1 < samples {
        let mut l = len.min(samples - start);
        if samples - (start + l) <= len / 2 {
            l = samples - start;
        }
        if l < 2 {
            break;
        }
        let (u0, v0) = state(start)?;
        out.push(Segment {
            start,
            len: l,
            u0,
            v0,
        });
        start += l;
    }
    Ok(out)
}

/// Segments of `len` samples started from the true states stored with a
/// simulated record (an error if the record has no truth). For tests and
/// validation: with measured data the start states come from an estimator
/// (e.g. a smoother) or are fitted.
pub fn from_truth(record: &Record, len: usize) -> Result<Vec<Segment>> {
    let truth = record.truth.as_ref().ok_or_else(|| {
        TacitError::record(
            record.source.clone(),
            "multiple shooting from the true states needs a simulated record with its truth",
        )
    })?;
    uniform(record.len(), len, |k| {
        let u = truth.u.iter().map(|row| row[k]).collect();
        let v = truth.v.iter().map(|row| row[k]).collect();
        Ok((u, v))
    })
}

/// Check segments against the model size and record length; errors name
/// the segment.
pub fn validate_segments(segments: &[Segment], ndof: usize, samples: usize) -> Result<()> {
    if segments.is_empty() {
        return Err(TacitError::Setting("no segment to simulate".into()));
    }
    for (i, s) in segments.iter().enumerate() {
        if s.len < 2 {
            return Err(TacitError::Setting(format!(
                "segment {i}: length {} must be >= 2 samples",
                s.len
            )));
        }
        if s.start + s.len > samples {
            return Err(TacitError::Setting(format!(
                "segment {i}: samples {}..{} run past the record's {samples}",
                s.start,
                s.start + s.len
            )));
        }
        if s.u0.len() != ndof || s.v0.len() != ndof {
            return Err(TacitError::Setting(format!(
                "segment {i}: start state has {} displacements and {} velocities, the model {ndof} DOFs",
                s.u0.len(),
                s.v0.len()
            )));
        }
        if s.u0.iter().chain(&s.v0).any(|v| !v.is_finite()) {
            return Err(TacitError::Setting(format!(
                "segment {i}: start state is not finite"
            )));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn uniform_covers_the_record() {
        let segs = uniform(105, 10, |_| Ok((vec![0.0], vec![0.0]))).unwrap();
        assert_eq!(segs.len(), 10);
        assert_eq!(segs.last().unwrap().start + segs.last().unwrap().len, 105);
        assert!(uniform(105, 1, |_| Ok((vec![], vec![]))).is_err());
        let e = validate_segments(&segs, 2, 105).unwrap_err().to_string();
        assert!(e.contains("segment 0"), "{e}");
    }
}
