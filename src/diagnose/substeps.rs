//! Sub-steps per sample that resolve a model's stiffest element.

use super::DiagnoseSettings;
use crate::integrate::SimSettings;
use crate::model::Model;
use nalgebra::DMatrix;

/// Sub-steps that resolve the stiffest element of `model`:
/// `ω h ≤ omega_h` with ω the frequency of the stiffest contact, spring or
/// clearance (its penalty stiffness) on the lightest masses it joins
/// (`k Σ 1/m` over its DOFs), and on the largest relative displacement
/// `δ_max` of `states` (2n × N, when given) of a cubic spring's tangent
/// stiffness `3 k_3 δ_max²` and a quadratic spring's `2 |k_2| δ_max`; at
/// least `base`, at most `max`.
pub fn auto_substeps(
    model: &Model,
    fs: f64,
    base: usize,
    omega_h: f64,
    max: usize,
    states: Option<&DMatrix<f64>>,
) -> usize {
    let inv_m = |dofs: &[usize]| -> f64 { dofs.iter().map(|&d| 1.0 / model.masses[d - 1]).sum() };
    let mut w2: f64 = 0.0;
    for c in &model.contacts {
        w2 = w2.max(c.stiffness * inv_m(&c.dofs));
    }
    for sp in &model.springs {
        w2 = w2.max(sp.stiffness * inv_m(&sp.dofs));
    }
    for c in &model.clearances {
        w2 = w2.max(c.stiffness * inv_m(&c.dofs));
    }
    if let Some(x) = states {
        for c in &model.cubics {
            let dmax = max_stroke(x, &c.dofs);
            w2 = w2.max(3.0 * c.k3.abs() * dmax * dmax * inv_m(&c.dofs));
        }
        for q in &model.quadratics {
            w2 = w2.max(2.0 * q.k2.abs() * max_stroke(x, &q.dofs) * inv_m(&q.dofs));
        }
    }
    let need = (w2.sqrt() / (omega_h * fs)).ceil() as usize;
    need.clamp(base.max(1), max.max(base))
}

/// The largest `|u_i − u_j|` (a pair) or `|u_i|` (to ground) of an
/// element on DOFs `dofs` (from 1) over the states `x` (2n × N).
fn max_stroke(x: &DMatrix<f64>, dofs: &[usize]) -> f64 {
    let rel = |k: usize| match dofs {
        [i, j] => x[(i - 1, k)] - x[(j - 1, k)],
        [i] => x[(i - 1, k)],
        _ => 0.0,
    };
    (0..x.ncols()).map(|k| rel(k).abs()).fold(0.0, f64::max)
}

/// Integrator settings with [`auto_substeps`] for `model`, at least
/// `substeps.min` (cubic springs
/// judged on the reconstructed `states`).
pub(super) fn resolved(
    model: &Model,
    fs: f64,
    settings: &DiagnoseSettings,
    states: &DMatrix<f64>,
) -> SimSettings {
    // at least `substeps.min`, for every model alike (the declared one
    // and each fitted one; [`super::settings::SubstepSettings::min`])
    let s = &settings.substeps;
    let base = s.base.max(s.min);
    SimSettings {
        substeps: auto_substeps(model, fs, base, s.omega_h, s.max, Some(states)),
        ..Default::default()
    }
}
