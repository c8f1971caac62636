//! The model found, scored on a validation record it was not fitted to.

use super::errors::{error_simulations, Comparison, ErrorSet, ShotResult};
use super::outcome::{DatumShift, Validation};
use super::prepare::Prepared;
use super::starts;
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
    let (before, _) = errors(cmp, declared, sims.0);
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
    let Some(r) = rezero(fitted, prep, quantiles, sim) else {
        let (after, _) = errors(cmp, fitted, sim);
        let n = error_simulations(&after, cmp);
        return (after, vec![], n);
    };
    // the multiple shooting of the model kept is the scan's own
    let (after, _) = cmp.errors_of(&r.model, sim, r.shot);
    let n = error_simulations(&after, cmp) + r.simulations - cmp.segments.len();
    (after, r.shifts, n)
}

/// The errors of `model` on a validation record ([`Comparison::errors`]),
/// the start states refined along both paths of [`starts::refine_both`]
/// when it takes two (a nonlinear model from fewer sensors than it has
/// DOFs; no segment then scores above the first path alone).
fn errors(
    cmp: &Comparison,
    model: &Model,
    sim: SimSettings,
) -> (ErrorSet, Option<nalgebra::DMatrix<f64>>) {
    cmp.errors_by(model, sim, starts::refine_both)
}

/// The fitted model with the gaps of its contacts against ground that the
/// sensors do not observe re-zeroed on this record: what moved, the
/// multiple shooting of the model kept, and the segment simulations of the
/// scan.
struct Rezeroed {
    model: Model,
    shifts: Vec<DatumShift>,
    shot: ShotResult,
    simulations: usize,
}

/// A contact against ground whose gap trades with the structure's
/// absolute position ([`gap_unobservable`]) has its gap measured from the
/// record's own datum, which another record does not share (each record's
/// reconstructed positions carry their own offset). On this record the
/// gap is taken again, everything else held: the fitted gap and the
/// reconstructed position of the contact's DOF at `quantiles` are scored
/// by the multiple-shooting error and the lowest kept. `None` when no
/// contact is concerned.
fn rezero(
    fitted: &Model,
    prep: &Prepared,
    quantiles: &[f64],
    sim: SimSettings,
) -> Option<Rezeroed> {
    let cmp = &prep.comparison;
    let mut model = fitted.clone();
    let (mut shifts, mut sims, mut kept) = (vec![], 0, None);
    for ci in 0..fitted.contacts.len() {
        let c = &fitted.contacts[ci];
        let &[d] = c.dofs.as_slice() else { continue };
        if !gap_unobservable(fitted, &[d - 1], &cmp.observations) {
            continue;
        }
        let mut tries = vec![c.gap];
        tries.extend(
            quantiles_of(prep.recon.states.row(d - 1).iter().copied(), quantiles)
                .into_iter()
                .filter(|g| *g > 0.0),
        );
        let mut best: Option<(f64, f64, ShotResult)> = None;
        for g in tries {
            model.contacts[ci].gap = g;
            sims += cmp.segments.len();
            let shot = cmp.shoot(&model, sim);
            let e = shot.as_ref().map_or(f64::NAN, |y| cmp.total_error(&y.0));
            if e.is_finite() && best.as_ref().is_none_or(|b| e < b.1) {
                best = Some((g, e, shot));
            }
        }
        let (gap, shot) = match best {
            Some((g, _, shot)) => (g, Some(shot)),
            None => (c.gap, None),
        };
        model.contacts[ci].gap = gap;
        // the scan of the last contact ran with the others at their gaps
        kept = shot;
        if gap != c.gap {
            shifts.push(DatumShift {
                label: format!("contact @{d}"),
                fitted: c.gap,
                here: gap,
            });
        }
    }
    let shot = match kept {
        Some(shot) => shot,
        None if sims == 0 => return None,
        None => {
            sims += cmp.segments.len();
            cmp.shoot(&model, sim)
        }
    };
    Some(Rezeroed {
        model,
        shifts,
        shot,
        simulations: sims,
    })
}

/// The `qs` quantiles of `values` (nearest rank; NaN when none is
/// finite).
fn quantiles_of(values: impl Iterator<Item = f64>, qs: &[f64]) -> Vec<f64> {
    let mut v: Vec<f64> = values.filter(|x| x.is_finite()).collect();
    v.sort_by(f64::total_cmp);
    qs.iter()
        .map(|&q| match v.len() {
            0 => f64::NAN,
            n => v[((n - 1) as f64 * q.clamp(0.0, 1.0)).round() as usize],
        })
        .collect()
}
