//! The model found, scored on a validation record it was not fitted to.

use super::errors::{error_simulations, ErrorSet};
use super::outcome::{DatumShift, Validation};
use super::prepare::Prepared;
use super::uncertainty::gap_unobservable;
use crate::error::Result;
use crate::integrate::SimSettings;
use crate::model::Model;
use crate::trace;

/// Errors on a validation record, and the non-parametric prediction; the
/// gaps of contacts against ground the sensors do not observe taken from
/// this record's own datum ([`rezero`]; `quantiles`: the reconstructed
/// positions tried).
pub(super) fn score(
    declared: &Model,
    fitted: &Model,
    prep: &Prepared,
    own: Option<&Prepared>,
    first: &Prepared,
    (sims, quantiles): ((SimSettings, SimSettings), &[f64]),
    count: &mut usize,
) -> Result<Validation> {
    let cmp = &prep.comparison;
    let (before, _) = cmp.errors(declared, sims.0);
    // the fitted model from its own reconstruction when it needs one
    let (after, datum, n) = after_errors(fitted, own.unwrap_or(prep), quantiles, sims.1);
    *count += error_simulations(&before, cmp) + n;
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
        datum,
    })
}

/// The fitted model's errors on a validation record (`prep`: prepared
/// with the model's own linear part when it needs one) with the gaps of
/// its contacts against ground that the sensors do not observe taken from
/// this record's datum ([`rezero`]); what moved, and the simulations run.
pub(super) fn after_errors(
    fitted: &Model,
    prep: &Prepared,
    quantiles: &[f64],
    sim: SimSettings,
) -> (ErrorSet, Vec<DatumShift>, usize) {
    let cmp = &prep.comparison;
    let (datum, shots) = rezero(fitted, prep, quantiles, sim);
    let model = datum.as_ref().map_or(fitted, |d| &d.model);
    let (after, _) = cmp.errors(model, sim);
    let n = error_simulations(&after, cmp) + shots;
    (after, datum.map(|d| d.shifts).unwrap_or_default(), n)
}

/// The fitted model with the gaps of its contacts against ground that the
/// sensors do not observe re-zeroed on this record, and what moved.
struct Rezeroed {
    model: Model,
    shifts: Vec<DatumShift>,
}

/// A contact against ground whose gap trades with the structure's
/// absolute position ([`gap_unobservable`]) has its gap measured from the
/// record's own datum, which another record does not share (each record's
/// reconstructed positions carry their own offset). On this record the
/// gap is taken again, everything else held: the fitted gap and the
/// reconstructed position of the contact's DOF at `quantiles` are scored
/// by the multiple-shooting error and the lowest kept. `None` when no
/// contact is concerned or the fitted gap scores best; with the segment
/// simulations run.
fn rezero(
    fitted: &Model,
    prep: &Prepared,
    quantiles: &[f64],
    sim: SimSettings,
) -> (Option<Rezeroed>, usize) {
    let cmp = &prep.comparison;
    let mut model = fitted.clone();
    let (mut shifts, mut sims) = (vec![], 0);
    for ci in 0..fitted.contacts.len() {
        let c = &fitted.contacts[ci];
        let &[d] = c.dofs.as_slice() else { continue };
        if !gap_unobservable(fitted, &[d - 1], &cmp.observations) {
            continue;
        }
        let row = prep.recon.states.row(d - 1);
        let mut tries = vec![c.gap];
        tries.extend(
            quantiles
                .iter()
                .map(|&q| quantile(row.iter().copied(), q))
                .filter(|g| *g > 0.0),
        );
        let score = |m: &Model| cmp.shoot(m, sim).ok().map(|y| cmp.total_error(&y.0));
        let mut best: Option<(f64, f64)> = None;
        for g in tries {
            model.contacts[ci].gap = g;
            sims += cmp.segments.len();
            if let Some(e) = score(&model).filter(|e| e.is_finite()) {
                if best.is_none_or(|b| e < b.1) {
                    best = Some((g, e));
                }
            }
        }
        let gap = best.map_or(c.gap, |b| b.0);
        model.contacts[ci].gap = gap;
        if gap != c.gap {
            shifts.push(DatumShift {
                label: format!("contact @{d}"),
                fitted: c.gap,
                here: gap,
            });
        }
    }
    let found = (!shifts.is_empty()).then_some(Rezeroed { model, shifts });
    (found, sims)
}

/// The `q` quantile of `values` (nearest rank).
fn quantile(values: impl Iterator<Item = f64>, q: f64) -> f64 {
    let mut v: Vec<f64> = values.filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    let k = ((v.len() - 1) as f64 * q.clamp(0.0, 1.0)).round() as usize;
    v[k]
}
