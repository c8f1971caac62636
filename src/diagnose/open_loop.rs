//! The final refinement by simulation error: every parameter of the
//! diagnosed model — the linear ones the calibration opens and the
//! effects' — fitted together with the start state by the open-loop
//! output error over the whole record (one segment from its first
//! sample). It is the last step of PNLSS (Paduart et al., Automatica 46,
//! 2010) and of Floren, Noël & Swevers (2025); the multiple-shooting
//! refinement before it only sees segments of a few periods, where a
//! small error of a resonance frequency or of the damping costs little,
//! while over a long record it accumulates into the open-loop error.
//!
//! Kept when it lowers the record's open-loop error (`simulation_error`);
//! the record's open-loop error is then simulated from the fitted start
//! state (the validation record's from its reconstructed one).

use super::calibrated::{lower, refinement_parameters, std_errors_at, Estimated};
use super::report::pct;
use super::{joint, Comparison, DiagnoseSettings, Diagnosis};
use crate::calibrate::{params, CalibrationSettings};
use crate::error::Result;
use crate::integrate::SimSettings;

/// Refine `d`'s model by the open-loop error (module docs), at most
/// `iterations` accepted steps; the note and, when kept, the parameters
/// with their standard errors (the model, its errors on the record and on
/// the validation record (`vcmp`) replaced in `d`).
pub(super) fn refine(
    d: &mut Diagnosis,
    cal: &CalibrationSettings,
    settings: &DiagnoseSettings,
    iterations: usize,
    vcmp: Option<&Comparison>,
) -> Result<(String, Option<Vec<Estimated>>)> {
    let model = params::per_mode(&d.model)?;
    let sim = SimSettings {
        substeps: d.substeps.1,
        ..Default::default()
    };
    let cmp = &d.prepared.comparison;
    let mut problem = cmp.problem(&model, vec![cmp.whole.clone()], sim);
    problem.parameters = refinement_parameters(&model, &d.added, cal)?;
    let fit = crate::update::FitSettings {
        max_iterations: iterations,
        ..settings.fit_settings()
    };
    let stall = joint::Stall {
        steps: settings.starts.stall_steps,
        gain: settings.starts.stall_gain,
    };
    let x0 = vec![0.0; problem.parameters.len()];
    let jf = match joint::fit(&problem, &x0, &fit, stall) {
        Ok(jf) => jf,
        Err(e) => return Ok((format!("open-loop refinement failed: {e}"), None)),
    };
    let refined = problem.model_at(&jf.x);
    // the open-loop error from the fitted start state (a parameter of
    // this fit), not the one reconstructed with the linear model
    let mut fitted_start = cmp.clone();
    fitted_start.whole = jf.segments[0].clone();
    let (after, pred) = fitted_start.errors(&refined, sim);
    let note = format!(
        "open-loop refinement of {} parameters and the start state over the {} samples ({}, {} steps): simulation error {} → {}",
        problem.parameters.len(),
        cmp.whole.len,
        jf.termination,
        jf.iterations,
        pct(d.after.simulation_error),
        pct(after.simulation_error)
    );
    if !lower(after.simulation_error, d.after.simulation_error) {
        return Ok((format!("{note}; not kept"), None));
    }
    let level = after.simulation_error.unwrap_or(settings.noise.level);
    let (params, std) = std_errors_at(&problem, &refined, jf.segments, &d.added, cal, level)?;
    d.model = refined;
    d.after = after;
    d.prepared.comparison = fitted_start;
    d.predictions.1 = pred;
    if let (Some(c), Some(v)) = (vcmp, d.validation.as_mut()) {
        v.after = c.errors(&d.model, sim).0;
    }
    let est = params.into_iter().zip(std).collect();
    Ok((format!("{note}; kept"), Some(est)))
}
