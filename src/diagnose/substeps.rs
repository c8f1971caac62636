//! Sub-steps per sample that resolve a model's stiffest element.

use super::DiagnoseSettings;
use crate::integrate::SimSettings;
use crate::model::Model;
use nalgebra::DMatrix;

/// Sub-steps that resolve the stiffest element of `model`:
/// `ω h ≤ omega_h` with ω the contact (or stiffest spring) frequency of the
/// lightest masses it joins, and for a cubic spring its tangent stiffness
/// `3 k_3 δ_max²` at the largest relative displacement of `states` (2n × N,
/// when given); at least `base`, at most `max`.
pub fn auto_substeps(
    model: &Model,
    fs: f64,
    base: usize,
    omega_h: f64,
    max: usize,
    states: Option<&DMatrix<f64>>,
) -> usize {
    let inv_m = |d: usize| 1.0 / model.masses[d - 1];
    let mut w2: f64 = 0.0;
    for c in &model.contacts {
        let s: f64 = c.dofs.iter().map(|&d| inv_m(d)).sum();
        w2 = w2.max(c.stiffness * s);
    }
    for sp in &model.springs {
        let s: f64 = sp.dofs.iter().map(|&d| inv_m(d)).sum();
        w2 = w2.max(sp.stiffness * s);
    }
    if let Some(x) = states {
        for c in &model.cubics {
            let rel = |k: usize| match c.dofs.as_slice() {
                [i, j] => x[(i - 1, k)] - x[(j - 1, k)],
                [i] => x[(i - 1, k)],
                _ => 0.0,
            };
            let dmax = (0..x.ncols()).map(|k| rel(k).abs()).fold(0.0, f64::max);
            let s: f64 = c.dofs.iter().map(|&d| inv_m(d)).sum();
            w2 = w2.max(3.0 * c.k3.abs() * dmax * dmax * s);
        }
    }
    w2 = w2.max(super::effects::stiffest_added(model, states));
    let need = (w2.sqrt() / (omega_h * fs)).ceil() as usize;
    need.clamp(base.max(1), max.max(base))
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
