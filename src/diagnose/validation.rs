//! The model found, scored on a validation record it was not fitted to.

use super::errors::error_simulations;
use super::outcome::Validation;
use super::prepare::Prepared;
use crate::error::Result;
use crate::integrate::SimSettings;
use crate::model::Model;
use crate::trace;

/// Errors on a validation record, and the non-parametric prediction.
pub(super) fn score(
    declared: &Model,
    fitted: &Model,
    prep: &Prepared,
    own: Option<&Prepared>,
    first: &Prepared,
    sims: (SimSettings, SimSettings),
    count: &mut usize,
) -> Result<Validation> {
    let cmp = &prep.comparison;
    let (before, _) = cmp.errors(declared, sims.0);
    // the fitted model from its own reconstruction when it needs one
    let cmp_after = own.map_or(cmp, |p| &p.comparison);
    let (after, _) = cmp_after.errors(fitted, sims.1);
    *count += error_simulations(&before, cmp) + error_simulations(&after, cmp_after);
    // the linear model driven by the first record's identified force
    let n = declared.ndof();
    let ns = cmp.force.ncols();
    let f1 = &first.recon.force;
    let mut force = cmp.force.clone();
    for k in 0..ns.min(f1.ncols()) {
        for i in 0..n {
            force[(i, k)] -= f1[(i, k)];
        }
    }
    let (cy, dy) = prep.sampled.outputs(&prep.channels)?;
    let y = trace::regress::segment_response(
        &prep.sampled,
        &cy,
        &dy,
        Some(&prep.recon.states),
        &force,
        prep.segment,
    );
    Ok(Validation {
        before,
        after,
        nonparametric_relative_error: Some(cmp.total_error(&y)),
    })
}
