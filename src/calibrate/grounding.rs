//! A spring to ground that a free-free declared model lacks.
//!
//! Under acceleration data a free-free model's rigid-body motion is not
//! seen; a spring from one DOF to ground gives that motion a frequency
//! (the whole mass on the spring), which no spring between DOFs and no
//! damping ratio produces. When the diagnosis on a free-free model leaves
//! the record above the noise, [`ground_springs`] calibrates the linear
//! part with a spring to ground opened at each DOF in turn (the damping
//! free beside it, the other springs held) and gives the DOFs whose
//! spring lowers the linear model's output error enough, the lowest error
//! first ([`crate::diagnose::calibrated`] then ranks them with the effects
//! found, refines the first few and keeps the best when it pays).

use super::{calibrate, CalibrationSettings, Data, Freedom};
use crate::error::Result;
use crate::model::{Model, Spring};
use rayon::prelude::*;

/// The spring to ground starts at this fraction of the median stiffness
/// of the model's springs: far softer than the structure (a stiffer one
/// would belong in the declared model), on the logarithmic scale of the
/// calibration a start from which a spring of 0.1–10 × that value is
/// reached in a few steps.
pub const START_FRACTION: f64 = 0.01;

/// The calibrated output error with the spring to ground must be at most
/// this fraction of the error without it (the damping calibrated alike):
/// a spring that explains less is left alone. On a record a localized
/// effect dominates, the linear model's output error is mostly the
/// effect's: a contact 2→3 with a spring of 1500 N/m at 8 (seed 93557 of
/// the imperfect matrix) leaves 58.1 % without the spring, 54.9 % with it
/// at 8.
pub const MAX_RATIO: f64 = 0.98;

/// A spring to ground calibrated at one DOF ([`ground_springs`]).
#[derive(Debug, Clone)]
pub struct GroundSpring {
    /// DOF, from 1.
    pub dof: usize,
    /// Calibrated stiffness, N/m.
    pub stiffness: f64,
    /// The linear part calibrated with it (its damping goes with it: the
    /// rigid-body mode becomes the lowest flexible mode).
    pub model: Model,
    /// Relative output error with it.
    pub error: f64,
    /// Relative output error without it, the damping calibrated alike.
    pub without: f64,
}

/// The spring to ground calibrated at each DOF (that spring and the
/// damping free, every other spring held) whose output error on `data` is
/// at most [`MAX_RATIO`] of the error left by the damping alone, the
/// lowest error first; empty on a model that has a spring to ground
/// already, or one without springs (a DOF whose calibration fails is left
/// out). A soft spring to ground gives the rigid-body mode nearly the same
/// frequency at any DOF, so the output error of the linear part on a
/// record with a localized effect need not put the right DOF first.
pub fn ground_springs(
    linear: &Model,
    data: &[Data],
    settings: &CalibrationSettings,
) -> Result<Vec<GroundSpring>> {
    if linear.has_ground_spring() || linear.springs.is_empty() {
        return Ok(vec![]);
    }
    let held = CalibrationSettings {
        freedom: Freedom {
            springs: true,
            damping: true,
            masses: false,
        },
        frozen_springs: (0..linear.springs.len()).collect(),
        spring_factor: f64::INFINITY,
        ..settings.clone()
    };
    let mut k: Vec<f64> = linear.springs.iter().map(|s| s.stiffness).collect();
    k.sort_by(f64::total_cmp);
    let k0 = START_FRACTION * k[k.len() / 2];
    let (without, tried) = rayon::join(
        || calibrate(linear, data, &held),
        || {
            (1..=linear.physical_ndof())
                .into_par_iter()
                .map(|dof| {
                    let mut m = linear.clone();
                    m.push_ground_spring(Spring {
                        dofs: vec![dof],
                        stiffness: k0,
                        name: Some(format!("ground{dof}")),
                    });
                    calibrate(&m, data, &held).map(|c| (dof, c)).ok()
                })
                .collect::<Vec<_>>()
        },
    );
    // a calibration that fails (a trial spring so stiff or so soft that
    // the model's response is not finite) leaves that DOF out
    let Ok(without) = without else {
        return Ok(vec![]);
    };
    let mut found: Vec<GroundSpring> = tried
        .into_iter()
        .flatten()
        .filter(|(_, c)| c.status.usable() && c.error_after <= MAX_RATIO * without.error_after)
        .map(|(dof, c)| GroundSpring {
            dof,
            stiffness: c.model.springs.last().map_or(0.0, |s| s.stiffness),
            error: c.error_after,
            without: without.error_after,
            model: c.model,
        })
        .filter(|g| g.stiffness.is_finite())
        .collect();
    found.sort_by(|a, b| a.error.total_cmp(&b.error));
    Ok(found)
}
