//! Bridge to the window method's problem and result types
//! ([`crate::identify`]): run the full-horizon identification on an
//! [`identify::Problem`](crate::identify::Problem) /
//! [`identify::System`](crate::identify::System) (reduced or full order)
//! and return a [`ForceEstimate`], so the same writers (HDF5, CSV, JSON,
//! figures) serve both methods.
//!
//! The unknowns are the internal forces `f` at the chosen DOFs in the
//! convention of [`crate::identify::output::CONVENTION`] (left-hand side,
//! as the truth `fint`): the horizon input matrix is the system's
//! `B_f = −Tᵀ` restricted to those DOFs, so the identified coefficients
//! *are* `f`.

use super::{identify, HorizonData, HorizonResult, HorizonSettings, HorizonStatus};
use crate::error::{Result, TacitError};
use crate::identify::output::ForceEstimate;
use crate::identify::{Problem, System};
use nalgebra::DMatrix;

/// `(known generalized input, channels on the model coordinates, B_u)`.
pub type ProblemData = (
    DMatrix<f64>,
    Vec<(crate::record::Quantity, usize)>,
    DMatrix<f64>,
);

/// The horizon data of a problem: known generalized input `B_e e`,
/// channels on the (reduced) coordinates, input matrix of the unknown
/// internal forces at `dofs` (0-based; all DOFs when empty).
pub fn problem_data(prob: &Problem, sys: &System, dofs: &[usize]) -> Result<ProblemData> {
    let n = sys.n();
    let dofs: Vec<usize> = if dofs.is_empty() {
        (0..n).collect()
    } else {
        dofs.to_vec()
    };
    if let Some(d) = dofs.iter().find(|&&d| d >= n) {
        return Err(TacitError::Setting(format!(
            "horizon: unknown-force DOF {} is outside the model (1..={n})",
            d + 1
        )));
    }
    let known = &sys.be * &prob.e;
    let channels = prob
        .channels
        .iter()
        .map(|&(q, d)| match &sys.reduction {
            None => Ok((q, d)),
            Some(r) => r
                .kept
                .iter()
                .position(|&k| k == d)
                .map(|i| (q, i))
                .ok_or_else(|| {
                    TacitError::Setting(format!(
                        "horizon: channel at DOF {} is not a kept DOF of the reduction",
                        d + 1
                    ))
                }),
        })
        .collect::<Result<Vec<_>>>()?;
    let mut bu = DMatrix::zeros(sys.m(), dofs.len());
    for (j, &d) in dofs.iter().enumerate() {
        bu.set_column(j, &sys.bf.column(d));
    }
    Ok((known, channels, bu))
}

/// Run [`identify`] on a problem and convert the answer.
pub fn identify_problem(
    prob: &Problem,
    sys: &System,
    dofs: &[usize],
    settings: &HorizonSettings,
) -> Result<(HorizonResult, ForceEstimate)> {
    let (known, channels, bu) = problem_data(prob, sys, dofs)?;
    let data = HorizonData {
        known_force: &known,
        measured: &prob.y,
        channels: &channels,
        unknown: &bu,
    };
    let res = identify(&sys.sm, &data, settings)?;
    let est = to_force_estimate(&res, prob, sys, dofs, settings);
    Ok((res, est))
}

/// Convert a result obtained on [`problem_data`] to a [`ForceEstimate`]
/// (method `horizon`).
pub fn to_force_estimate(
    res: &HorizonResult,
    prob: &Problem,
    sys: &System,
    dofs: &[usize],
    settings: &HorizonSettings,
) -> ForceEstimate {
    let n = sys.n();
    let len = res.force.ncols();
    let dofs: Vec<usize> = if dofs.is_empty() {
        (0..n).collect()
    } else {
        dofs.to_vec()
    };
    let mut f = DMatrix::zeros(n, len);
    let mut fs = DMatrix::zeros(n, len);
    for (j, &d) in dofs.iter().enumerate() {
        f.set_row(d, &res.force.row(j));
        if let Some(s) = &res.force_std {
            fs.set_row(d, &s.row(j));
        }
    }
    let mut est = ForceEstimate::assemble(
        "horizon",
        prob,
        sys,
        &res.states,
        &f,
        Some(res.predicted.clone()),
    );
    est.force_std = res.force_std.as_ref().map(|_| fs);
    est.settings = serde_json::json!({
        "horizon": settings,
        "selected_weights": res.weights,
        "diagnostics": res.diagnostics,
        "unknown_dofs": dofs.iter().map(|d| d + 1).collect::<Vec<_>>(),
    });
    est.diagnostics.solver_iterations = u64::from(res.diagnostics.qp_iterations);
    est.diagnostics.residual_sigma = Some(res.diagnostics.variance_factor.sqrt());
    est.timings.setup = res.timings.setup;
    est.timings.selection = res.timings.selection;
    est.timings.solve =
        res.timings.backward + res.timings.forward + res.timings.covariance + res.timings.qp;
    est.timings.total = res.timings.total;
    est.warnings.extend(res.notes.iter().cloned());
    if res.status != HorizonStatus::Solved {
        est.warnings
            .push(format!("horizon status: {:?}", res.status));
    }
    crate::identify::finite::settle(&mut est);
    est
}
