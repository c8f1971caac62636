//! The non-finite guard of an identification: the first value of a
//! [`ForceEstimate`] that is NaN or infinite, by the stage that produced
//! it, so that no run reports "NaN %" with status ok.

use super::output::{ForceEstimate, Status};
use crate::error::TacitError;
use nalgebra::DMatrix;
use serde::Serialize;

/// A part of an identification's result, in the order it is computed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Stage {
    /// The identified internal force.
    Force,
    /// The reconstructed displacements.
    Displacement,
    /// The reconstructed velocities.
    Velocity,
    /// The reconstructed accelerations.
    Acceleration,
    /// The method's reconstruction of a measured channel.
    Prediction,
    /// The linear model's response without the identified force.
    NoForce,
    /// The open-loop replay with the identified force.
    Replay,
}

impl Stage {
    /// The stage in words.
    pub fn words(self) -> &'static str {
        match self {
            Stage::Force => "identified force",
            Stage::Displacement => "reconstructed displacement",
            Stage::Velocity => "reconstructed velocity",
            Stage::Acceleration => "reconstructed acceleration",
            Stage::Prediction => "reconstruction of the channel",
            Stage::NoForce => "response without the identified force",
            Stage::Replay => "open-loop replay",
        }
    }
}

/// The first non-finite value among the first `end` samples: the stage,
/// the component (`f_5`, `u_3`, `accel_5`) and the sample.
pub fn first_non_finite(est: &ForceEstimate, end: usize) -> Option<(Stage, String, usize)> {
    let matrices = [
        (Stage::Force, "f", &est.force),
        (Stage::Displacement, "u", &est.states.u),
        (Stage::Velocity, "v", &est.states.v),
        (Stage::Acceleration, "a", &est.states.a),
    ];
    for (stage, prefix, m) in matrices {
        if let Some((i, k)) = first_in_matrix(m, end) {
            return Some((stage, format!("{prefix}_{}", i + 1), k));
        }
    }
    for stage in [Stage::Prediction, Stage::NoForce, Stage::Replay] {
        for c in &est.channels {
            let row = match stage {
                Stage::Prediction => &c.predicted,
                Stage::NoForce => &c.no_force,
                _ => &c.replay,
            };
            if let Some(k) = row.iter().take(end).position(|v| !v.is_finite()) {
                return Some((stage, c.name.clone(), k));
            }
        }
    }
    None
}

/// (row, column) of the first non-finite entry by column, among the first
/// `end` columns.
fn first_in_matrix(m: &DMatrix<f64>, end: usize) -> Option<(usize, usize)> {
    (0..end.min(m.ncols())).find_map(|k| {
        (0..m.nrows())
            .find(|&i| !m[(i, k)].is_finite())
            .map(|i| (i, k))
    })
}

/// Settle the status of a finished estimate: a non-finite value (before
/// the failed window of a stopped run) makes it [`Status::NonFinite`]; a
/// diverged run stays diverged (its values may overflow); otherwise `Ok`
/// with warnings becomes `Warning`.
pub fn settle(est: &mut ForceEstimate) {
    let end = match &est.status {
        Status::Diverged { .. } | Status::NonFinite { .. } => return,
        Status::Failed { sample, .. } => *sample,
        Status::Ok | Status::Warning => est.time.len(),
    };
    if let Some((stage, component, sample)) = first_non_finite(est, end) {
        est.status = Status::NonFinite {
            stage,
            component,
            sample,
        };
    } else if est.status == Status::Ok && !est.warnings.is_empty() {
        est.status = Status::Warning;
    }
}

/// The error for an estimate whose status is [`Status::NonFinite`]: its
/// numbers mean nothing, so nothing is written.
pub fn error(est: &ForceEstimate) -> Option<TacitError> {
    let Status::NonFinite {
        stage,
        component,
        sample,
    } = &est.status
    else {
        return None;
    };
    let t = est.time.get(*sample).copied().unwrap_or(f64::NAN);
    Some(TacitError::Numerical(format!(
        "the identification ({}) of {} gave a non-finite {} at {component}, sample {sample} (t = {t:.6} s): its errors and force would be NaN, so nothing was written; the record or the model is out of double precision's range, or the method is unstable on this record",
        est.method,
        est.record,
        stage.words()
    )))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::identify::{identify, IdentifySettings, Problem};
    use crate::model::Model;
    use std::path::Path;

    /// The full-order MHE on 512 samples of the shipped bumper record.
    fn estimate() -> ForceEstimate {
        let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("data");
        let model = Model::from_file(&data.join("lanl8dof.toml")).unwrap();
        let rec = crate::record::read(&data.join("lanl8dof-bumper.h5"))
            .unwrap()
            .slice(0, 512)
            .unwrap();
        let prob = Problem::new(&model.linear_part(), &rec, &[1, 5, 6]).unwrap();
        identify(&prob, &IdentifySettings::default()).unwrap()
    }

    #[test]
    fn a_nan_is_named_by_stage_component_and_sample() {
        let mut est = estimate();
        assert!(
            matches!(est.status, Status::Ok | Status::Warning),
            "{:?}",
            est.status
        );
        assert_eq!(first_non_finite(&est, est.time.len()), None);
        assert!(error(&est).is_none());
        est.states.v[(4, 301)] = f64::NAN;
        est.channels[1].replay[20] = f64::INFINITY;
        settle(&mut est);
        assert_eq!(
            est.status,
            Status::NonFinite {
                stage: Stage::Velocity,
                component: "v_5".into(),
                sample: 301
            }
        );
        let e = error(&est).unwrap().to_string();
        assert!(
            e.contains("non-finite reconstructed velocity at v_5, sample 301 (t = 0.587891 s)")
                && e.contains("nothing was written"),
            "{e}"
        );
        // a stopped run: the NaN after its failed window is expected
        est.status = Status::Failed {
            window: 3,
            sample: 10,
            message: "test".into(),
        };
        settle(&mut est);
        assert!(
            matches!(est.status, Status::Failed { .. }),
            "{:?}",
            est.status
        );
        est.status = Status::Failed {
            window: 9,
            sample: 400,
            message: "test".into(),
        };
        settle(&mut est);
        assert!(
            matches!(
                &est.status,
                Status::NonFinite {
                    stage: Stage::Velocity,
                    sample: 301,
                    ..
                }
            ),
            "{:?}",
            est.status
        );
    }
}
