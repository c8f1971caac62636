//! Internal-force identification by sliding windows (Hemez & Doebling
//! §6.2), made to hold over whole records.
//!
//! From a record (measured input force, measured responses at a few DOFs)
//! and a linear model, reconstruct the internal force `f` the model lacks
//! (`M ü + C u̇ + K u + f = f_ext`, see [`output::CONVENTION`]).
//!
//! - [`Method::Paper`]: the published sequential scheme ([`paper`]), with
//!   the closed-loop spectral radius of its recursion computed before
//!   running and a warning when it is ≥ 1 (docs/theory.md, fact R1);
//! - [`Method::Mhe`]: moving-horizon estimation ([`mhe`]), which
//!   re-estimates each window's start state and stays bounded;
//! - the located, lifted smoother ([`located`], `tacit identify`'s
//!   default): where the force acts is found first, then the force is
//!   reconstructed along those directions with a sub-sample resolution
//!   (the reconstruction `tacit diagnose` starts from): the search
//!   [`locate`] and the sub-sample smoother [`lifted`].
//!
//! Both run on the exact sampled linear model ([`crate::linear`]), reduced
//! onto the sensors or not ([`Reduce`]); every window problem is linear in
//! the unknowns, so its sensitivities and least-squares gain are built once
//! ([`window`]). `--solver qp` solves each window with Clarabel under the
//! user's [`Constraints`] ([`qp`]). α is given or chosen by GCV / L-curve
//! ([`regularize`]); [`identifiability`] tells which force combinations the
//! sensors see.
//!
//! Front door: [`Problem::new`] then [`identify`] (window schemes) or
//! [`identify_located`]. The result is a
//! [`ForceEstimate`], written by [`output::write_all`]. Theory and the
//! comparison with the paper's Figs 8–10: `docs/identification.md`.

pub mod finite;
pub mod identifiability;
pub mod lifted;
pub mod locate;
pub mod located;
pub mod mhe;
pub mod output;
pub mod paper;
pub mod qp;
pub mod regularize;
pub mod run;
pub mod settings;
pub mod system;
pub mod window;

pub use located::{identify_located, LocatedSettings};
pub use output::{ForceEstimate, Status};
pub use settings::{Constraints, IdentifySettings, Method, Reduce, Regularization, Solver};
pub use system::{Problem, System};

use crate::error::{Result, TacitError};
use nalgebra::DMatrix;
use run::{LsSolver, Plan, RunOutput};
use std::time::Instant;

/// Identify the internal force (no progress report).
pub fn identify(prob: &Problem, settings: &IdentifySettings) -> Result<ForceEstimate> {
    identify_with_progress(prob, settings, &mut |_, _| {})
}

/// Identify the internal force; `progress(done, total)` is called as
/// windows complete. Bad input is an `Err`; numerical trouble (spectral
/// radius ≥ 1, rank deficiency, divergence, QP failure) is reported in
/// [`ForceEstimate::status`] and [`ForceEstimate::warnings`].
pub fn identify_with_progress(
    prob: &Problem,
    settings: &IdentifySettings,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<ForceEstimate> {
    let t0 = Instant::now();
    settings.validate()?;
    settings.constraints.validate(prob.ndof())?;
    if prob.len() < settings.window + 1 {
        return Err(TacitError::Record {
            path: prob.record_name.clone().into(),
            message: format!(
                "the record has {} samples, shorter than one window: {} samples + the start sample are needed",
                prob.len(),
                settings.window
            ),
        });
    }
    let sys = System::new(prob, settings.reduce, settings.substeps)?;
    let t_sel = Instant::now();
    let report = match settings.regularization {
        Regularization::Fixed(a) => regularize::RegularizationReport::fixed(a, settings.smoothness),
        _ => regularize::select(prob, &sys, settings),
    };
    let selection = t_sel.elapsed().as_secs_f64();
    let t_build = Instant::now();
    let alpha = report.alpha;
    let plan = build_plan(&sys, prob.len(), settings, alpha);
    let mut warnings = Vec::new();
    let regular = &plan.ops[0];
    let radius = regular.info.spectral_radius;
    if let Some(r) = radius {
        if r.is_nan() || r >= 1.0 {
            let nw = plan.windows.len() as f64;
            warnings.push(format!(
                "closed-loop spectral radius {r:.4} >= 1: errors can grow by ×{r:.4} per window, up to ×{:.3e} over the {} windows of this record",
                r.powf(nw),
                plan.windows.len()
            ));
        }
    }
    for op in &plan.ops {
        if op.info.rank < op.info.unknowns {
            warnings.push(format!(
                "window operator ({} samples) has rank {} < {} unknowns: minimum-norm solution",
                op.info.samples, op.info.rank, op.info.unknowns
            ));
        }
    }
    let method_h = force_columns(&sys, settings.method, &regular.h_theta);
    let ident =
        identifiability::analyse(&sys, settings.window, Some(&method_h), settings.rank_rtol);
    let setup = t_build.elapsed().as_secs_f64();
    let t_run = Instant::now();
    let mut qp_almost = 0;
    let out = match settings.solver {
        Solver::Ls => run::run(&sys, prob, &plan, &mut LsSolver, progress),
        Solver::Qp => {
            let mut s = qp::QpSolver::new(settings.constraints.clone(), sys.n(), plan.ops.len());
            let o = run::run(&sys, prob, &plan, &mut s, progress);
            qp_almost = s.almost_solved;
            o
        }
    };
    let solve = t_run.elapsed().as_secs_f64();
    if qp_almost > 0 {
        warnings.push(format!(
            "{qp_almost} window QPs were solved to reduced accuracy only"
        ));
    }
    let method = match settings.method {
        Method::Paper => "paper",
        Method::Mhe => "mhe",
    };
    let mut est =
        ForceEstimate::assemble(method, prob, &sys, &out.x, &out.f, Some(out.yhat.clone()));
    if settings.solver == Solver::Ls && out.failure.is_none() {
        let (std, sigma) = force_std(prob, &plan, &out);
        est.force_std = Some(std);
        est.diagnostics.residual_sigma = Some(sigma);
    }
    est.settings = serde_json::to_value(settings).unwrap_or(serde_json::Value::Null);
    if let serde_json::Value::Object(m) = &mut est.settings {
        m.insert("alpha_used".into(), serde_json::json!(alpha));
    }
    est.diagnostics.spectral_radius = radius;
    est.diagnostics.operators = plan.ops.iter().map(|o| o.info.clone()).collect();
    est.diagnostics.identifiability = Some(ident);
    est.diagnostics.regularization = Some(report);
    est.diagnostics.windows = out.windows;
    est.diagnostics.solver_iterations = out.iterations;
    warnings.append(&mut est.warnings);
    est.warnings = warnings;
    if let Some(fl) = &out.failure {
        est.status = Status::Failed {
            window: fl.window,
            sample: fl.sample,
            message: fl.message.clone(),
        };
        est.warnings.push(format!(
            "stopped at window {} (sample {}): {}; later samples are NaN",
            fl.window, fl.sample, fl.message
        ));
    }
    finite::settle(&mut est);
    est.timings = output::Timings {
        setup,
        selection,
        solve,
        total: t0.elapsed().as_secs_f64(),
    };
    Ok(est)
}

/// The plan of the chosen method for `samples` samples and weight `alpha`.
pub fn build_plan(sys: &System, samples: usize, s: &IdentifySettings, alpha: f64) -> Plan {
    match s.method {
        Method::Paper => paper::plan(sys, samples, s.window, alpha, s.smoothness),
        Method::Mhe => mhe::plan(
            sys,
            samples,
            s.window,
            s.horizon,
            mhe::Weights {
                alpha,
                beta: s.smoothness,
                mu: s.prior_weight,
                eps: s.leak,
            },
        ),
    }
}

/// Closed-loop spectral radius of the chosen method's window recursion for
/// these settings and weight (`None` when the record is a single window).
pub fn spectral_radius(sys: &System, s: &IdentifySettings, alpha: f64) -> Option<f64> {
    match s.method {
        Method::Paper => Some(paper::spectral_radius(sys, s.window, alpha, s.smoothness)),
        Method::Mhe => {
            let w = mhe::Weights {
                alpha,
                beta: s.smoothness,
                mu: s.prior_weight,
                eps: s.leak,
            };
            mhe::regular_operator(sys, s.window, s.horizon, w)
                .info
                .spectral_radius
        }
    }
}

/// `H_θ` restricted to the force unknowns.
fn force_columns(sys: &System, method: Method, h: &DMatrix<f64>) -> DMatrix<f64> {
    match method {
        Method::Paper => h.clone(),
        Method::Mhe => {
            let ns = 2 * sys.m();
            h.columns(ns, h.ncols() - ns).into_owned()
        }
    }
}

/// Per-sample standard deviation of the force from the residual level:
/// `σ̂² = ‖r‖² / (n_obs − p_eff)`, `std = σ̂ ‖G_f,y row‖`, with `G_f,y` the
/// gain from a window's measurements to a committed force (the coupling
/// through the carried state is neglected).
fn force_std(prob: &Problem, plan: &Plan, out: &RunOutput) -> (DMatrix<f64>, f64) {
    let n = out.f.nrows();
    let rss: f64 = (&out.yhat - &prob.y).iter().map(|v| v * v).sum();
    let peff: f64 = plan
        .windows
        .iter()
        .map(|&(_, oi)| plan.ops[oi].info.influence_trace)
        .sum();
    let nobs = prob.y.len() as f64;
    let sigma = (rss / (nobs - peff).max(1.0)).sqrt();
    let mut std = DMatrix::zeros(n, prob.len());
    let ns = out.x.nrows();
    // per operator and committed j: row norms of the gain's data block
    let per_op: Vec<Vec<Vec<f64>>> = plan
        .ops
        .iter()
        .map(|op| {
            (0..=op.last_needed)
                .map(|j| {
                    (0..n)
                        .map(|i| op.gain.row(ns + j * n + i).columns(0, op.nfit).norm() * sigma)
                        .collect()
                })
                .collect()
        })
        .collect();
    for &(s, oi) in &plan.windows {
        let op = &plan.ops[oi];
        for j in op.param.commit.clone() {
            for i in 0..n {
                std[(i, s + j)] = per_op[oi][j][i];
            }
        }
    }
    (std, sigma)
}
