//! A search of the gap and stiffness of each contact and clearance on
//! grids, every trial model scored with segment start states refined
//! afresh for it.
//!
//! Seen from fewer sensors than the model has DOFs, a clearance's cost in
//! its gap and stiffness is a funnel only when each trial model is scored
//! on start states refined for it over every segment of the record
//! ([`super::starts::refine`]: continuity, sweep and rescue along
//! consecutive segments). The joint fit of parameters and start states
//! ([`super::joint`]) moves the states only locally, and they absorb a
//! parameter change: on the record of the row "clearance 2–3, modal 2.5 %,
//! sensors 2, 3, 7" of `examples/imperfect_matrix.rs` (seed 15833), the
//! true linear part with the clearance's gap × 1.067 and stiffness × 1.037
//! scores 28.5 % and the joint fit of gap, stiffness and start states
//! from there stalls with the gap unmoved (× 1.0668), while the truth
//! scores 2.5 %. The cost is rough at the 1 % scale along the valley where
//! gap and stiffness trade (the gap × 1.03 at the true stiffness 17.5 %,
//! × 1.01 6.2 %; at the stiffness × 1.037 the gap × 1.01 6.8 %), so a
//! search along one parameter at a time stops in it (10.1 % from the same
//! start); a grid of both does not. The search scores the gap over ±10 %
//! by 2 % at the stiffness × 0.97, 1 and 1.03, then 3 × 3 grids around
//! the best with steps of 1 % and 0.5 % in both, and stops once the error
//! is at a given target (from the same start: gap × 0.998, stiffness ×
//! 1.0009, 3.17 % after 49 models).

use super::errors::Comparison;
use crate::integrate::SimSettings;
use crate::model::Model;
use crate::update::Target;

/// Relative steps of the first stage on a gap.
const GAP_STEPS: [f64; 11] = [
    -0.10, -0.08, -0.06, -0.04, -0.02, 0.0, 0.02, 0.04, 0.06, 0.08, 0.10,
];

/// Relative steps of the first stage on a stiffness.
const STIFFNESS_STEPS: [f64; 3] = [-0.03, 0.0, 0.03];

/// The steps (stiffness, gap) of the local stages around the best point,
/// each a 3 × 3 grid.
const LOCAL_STEPS: [(f64, f64); 2] = [(0.01, 0.01), (0.005, 0.005)];

/// What the search found.
pub struct Searched {
    /// The model at the best point.
    pub model: Model,
    /// Its multiple-shooting error on the record, and the start's.
    pub error: (f64, f64),
    /// Models scored.
    pub trials: usize,
}

/// Whether the search applies to `model` on `cmp`: a contact or clearance
/// seen from fewer distinct DOFs than the model has.
pub fn applies(cmp: &Comparison, model: &Model) -> bool {
    (!model.contacts.is_empty() || !model.clearances.is_empty())
        && super::starts::weakly_observed(cmp, model)
}

/// The record's multiple-shooting error of `model`, start states refined
/// for it over every segment (infinite when a simulation fails).
fn score(cmp: &Comparison, model: &Model, sim: SimSettings) -> f64 {
    cmp.shoot(model, sim)
        .map(|(y, _, _)| cmp.total_error(&y))
        .ok()
        .filter(|e| e.is_finite())
        .unwrap_or(f64::INFINITY)
}

/// The search (module docs) from `model`, stopped once the error is at
/// most `target_error`; None when `model` fails to simulate.
pub fn search(
    cmp: &Comparison,
    model: &Model,
    sim: SimSettings,
    target_error: f64,
) -> Option<Searched> {
    let start = score(cmp, model, sim);
    if !start.is_finite() {
        return None;
    }
    let mut best = (model.clone(), start);
    let mut trials = 1;
    let pairs = (0..model.contacts.len())
        .map(|i| (Target::ContactGap(i), Target::ContactStiffness(i)))
        .chain(
            (0..model.clearances.len())
                .map(|i| (Target::ClearanceGap(i), Target::ClearanceStiffness(i))),
        );
    for (gap, stiffness) in pairs {
        let mut grids = vec![(STIFFNESS_STEPS.to_vec(), GAP_STEPS.to_vec())];
        for (hk, hg) in LOCAL_STEPS {
            grids.push((vec![-hk, 0.0, hk], vec![-hg, 0.0, hg]));
        }
        for (ks, gs) in grids {
            if best.1 <= target_error {
                break;
            }
            let (Ok(g0), Ok(k0)) = (gap.get(&best.0), stiffness.get(&best.0)) else {
                continue;
            };
            let mut grid = None;
            for &fk in &ks {
                for &fg in &gs {
                    if fk == 0.0 && fg == 0.0 {
                        continue;
                    }
                    let mut m = best.0.clone();
                    gap.set(&mut m, g0 * (1.0 + fg));
                    stiffness.set(&mut m, k0 * (1.0 + fk));
                    let e = score(cmp, &m, sim);
                    trials += 1;
                    if e < grid.as_ref().map_or(best.1, |l: &(Model, f64)| l.1) {
                        grid = Some((m, e));
                    }
                }
            }
            if let Some(l) = grid {
                best = l;
            }
        }
    }
    Some(Searched {
        error: (best.1, start),
        model: best.0,
        trials,
    })
}
