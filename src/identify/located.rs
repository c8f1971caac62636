//! The located, lifted smoother as an identification method
//! (`tacit identify --method lifted`, the default).
//!
//! The same reconstruction `tacit diagnose` starts from: first *where* the
//! missing force acts is decided from the measurements alone
//! ([`super::locate`]: a greedy search over spring-joined pairs
//! and single DOFs, each candidate scored by how well a force restricted to
//! it fits the data), then the states and the force are reconstructed
//! along the located directions by the sub-sample ("lifted") smoother
//! ([`super::lifted`]: the unknown force piecewise constant on
//! `R` sub-intervals of every sample, a sparsity prior over DOFs and time).
//! When no direction dominates (a force spread over many DOFs, or none)
//! the force is reconstructed at every DOF.
//!
//! Restricting the force to a few directions leaves fewer unknowns than
//! measurements, so the force is determined by the data rather than by the
//! prior; an unknown force at every DOF seen through three accelerometers
//! is not (docs/identification.md, §2). The result is a
//! [`ForceEstimate`] on the full-order model (`--reduce none`). The force
//! per DOF at sample `k` is that of the sub-interval starting at `t_k`:
//! the force at the sample instant, which an acceleration sampled at `t_k`
//! sees directly and which a record's truth (`fint`) holds. An impact
//! shorter than a sample has a mean over the sample interval far below its
//! value at the instant (on the shipped bumper record the interval means
//! correlate 0.63 with the sampled true force, the instant values 0.99).
//! The open-loop replay runs the lifted map with the whole sub-sample
//! force, so each impact keeps its impulse.

use super::lifted::{self, LiftedSettings};
use super::locate::{self, LocateSettings, Located};
use super::output::{ForceEstimate, Timings};
use super::settings::Reduce;
use super::system::{Problem, System};
use crate::error::{Result, TacitError};
use crate::model::Model;
use nalgebra::DMatrix;
use std::time::Instant;

/// Settings of [`identify_located`].
#[derive(Debug, Clone, PartialEq)]
pub struct LocatedSettings {
    /// The lifted smoother (resolution, force prior λ, noise level,
    /// reweighting).
    pub lifted: LiftedSettings,
    /// The location search; `ratio = 0` switches it off (an unknown force
    /// at every DOF).
    pub locate: LocateSettings,
    /// Newmark sub-steps per sample of the linear model (default 10;
    /// 1..=1000).
    pub substeps: usize,
}

impl Default for LocatedSettings {
    fn default() -> Self {
        LocatedSettings {
            lifted: LiftedSettings::default(),
            locate: LocateSettings::default(),
            substeps: 10,
        }
    }
}

impl LocatedSettings {
    /// Check every field; the error names the setting and its range.
    pub fn validate(&self) -> Result<()> {
        self.lifted.validate()?;
        let l = &self.locate;
        if !(0.0..1.0).contains(&l.ratio) {
            return Err(TacitError::Setting(format!(
                "location search: ratio = {} must be in [0, 1) (0 switches the search off)",
                l.ratio
            )));
        }
        if !(l.noise_stop > 0.0 && l.noise_stop.is_finite()) {
            return Err(TacitError::Setting(format!(
                "location search: noise_stop = {} must be finite and > 0",
                l.noise_stop
            )));
        }
        if !(1..=1000).contains(&self.substeps) {
            return Err(TacitError::Setting(format!(
                "substeps = {} must be in 1..=1000",
                self.substeps
            )));
        }
        Ok(())
    }

    /// Whether the location search runs.
    fn searches(&self) -> bool {
        self.locate.ratio > 0.0 && self.locate.max > 0
    }
}

/// The measured input placed at its DOFs (n × N), as a right-hand side.
fn known_force(prob: &Problem) -> DMatrix<f64> {
    let mut g = DMatrix::zeros(prob.ndof(), prob.len());
    for (j, &d) in prob.input_dofs.iter().enumerate() {
        for k in 0..prob.len() {
            g[(d, k)] += prob.e[(j, k)];
        }
    }
    g
}

/// Locate the force and reconstruct it with the lifted smoother (module
/// docs). `model` is the declared model the problem was built from (its
/// springs and interfaces give the candidate pairs). Bad settings or a
/// model that does not match the problem are an `Err`.
pub fn identify_located(
    model: &Model,
    prob: &Problem,
    s: &LocatedSettings,
) -> Result<ForceEstimate> {
    let t0 = Instant::now();
    s.validate()?;
    if model.ndof() != prob.ndof() {
        return Err(TacitError::Setting(format!(
            "model {} has {} DOFs, the identification problem {}",
            model.name,
            model.ndof(),
            prob.ndof()
        )));
    }
    let sys = System::new(prob, Reduce::None, s.substeps)?;
    let known = known_force(prob);
    let setup = t0.elapsed().as_secs_f64();
    let t_loc = Instant::now();
    let located = if s.searches() {
        Some(locate::locate(
            model,
            &sys.sm,
            &known,
            &prob.y,
            &prob.channels,
            &s.lifted,
            &s.locate,
        )?)
    } else {
        None
    };
    let selection = t_loc.elapsed().as_secs_f64();
    let t_run = Instant::now();
    let n = prob.ndof();
    let (y, ch) = (&prob.y, &prob.channels);
    let dirs = located
        .as_ref()
        .filter(|l| !l.directions.is_empty())
        .map(|l| l.matrix(n));
    let r = lifted::reconstruct_located(&sys.sm, dirs.as_ref(), &known, y, ch, &s.lifted)?;
    let solve = t_run.elapsed().as_secs_f64();
    let res = s.lifted.resolution;
    let f = DMatrix::from_fn(n, prob.len(), |i, k| -r.fine_force[(i, k * res)]);
    let mut est = ForceEstimate::assemble("lifted", prob, &sys, &r.states, &f, None);
    let lm = lifted::lift(&sys.sm, res)?;
    let replay = lifted_replay(&lm, &sys, &r.states, &r.fine_force, &known, prob);
    for (i, c) in est.channels.iter_mut().enumerate() {
        c.replay = replay.row(i).iter().copied().collect();
        c.error_replay = crate::metrics::relative_error(&c.replay, &c.measured);
    }
    est.settings = settings_json(s, located.as_ref(), &r.status, r.lambda);
    est.diagnostics.windows = 1;
    let mut ident = super::identifiability::analyse(&sys, 3, None, 1e-6);
    ident.note = format!("{}. {}", visible_note(located.as_ref(), n), ident.note);
    est.diagnostics.identifiability = Some(ident);
    super::finite::settle(&mut est);
    est.timings = Timings {
        setup,
        selection,
        solve,
        total: t0.elapsed().as_secs_f64(),
    };
    Ok(est)
}

/// Open-loop replay of the linear model from the estimated start state
/// under the measured input and the identified sub-sample force (the
/// lifted map, so impacts between samples keep their impulse): p × N.
fn lifted_replay(
    lm: &lifted::LiftedModel,
    sys: &System,
    states: &DMatrix<f64>,
    fine: &DMatrix<f64>,
    known: &DMatrix<f64>,
    prob: &Problem,
) -> DMatrix<f64> {
    let (n, r, len) = (sys.n(), lm.resolution, prob.len());
    let mut x = states.column(0).into_owned();
    if x.iter().any(|v| !v.is_finite()) {
        x.fill(0.0);
    }
    let mut y = DMatrix::zeros(sys.p(), len);
    let mut u = nalgebra::DVector::zeros(n * r);
    for k in 0..len {
        // output equation: the force of the sub-interval starting at k
        let w = &sys.be * prob.e.column(k) + fine.column(k * r);
        y.set_column(k, &(&sys.cy * &x + &sys.dy * w));
        if k + 1 == len {
            break;
        }
        for j in 0..r {
            u.rows_mut(j * n, n).copy_from(&fine.column(k * r + j));
        }
        x = &lm.a * &x + &lm.g * &u + &lm.bg0 * known.column(k) + &lm.bg1 * known.column(k + 1);
    }
    y
}

/// Which force combinations the estimate holds, in words.
fn visible_note(located: Option<&Located>, n: usize) -> String {
    match located {
        Some(l) if !l.directions.is_empty() => format!(
            "{}; the force is identified along these directions only, zero elsewhere",
            l.summary()
        ),
        Some(l) => format!(
            "{}: with fewer sensors than DOFs the {n} components are set partly by the force prior, not by the data alone",
            l.summary()
        ),
        None => format!(
            "location search off: unknown force at every DOF; with fewer sensors than DOFs the {n} components are set partly by the force prior"
        ),
    }
}

/// The settings, the force prior's weight used and the location as JSON
/// for `summary.json`.
fn settings_json(
    s: &LocatedSettings,
    located: Option<&Located>,
    status: &str,
    lambda_used: f64,
) -> serde_json::Value {
    let l = &s.lifted;
    serde_json::json!({
        "resolution": l.resolution,
        "lambda": l.lambda,
        "lambda_used": lambda_used,
        "min_residual": l.min_residual,
        "noise_fraction": l.noise_fraction,
        "x0_std": [l.x0_std.0, l.x0_std.1],
        "reweight_passes": l.reweight_passes,
        "reweight_floor": l.reweight_floor,
        "locate": s.locate,
        "substeps": s.substeps,
        "located": located,
        "smoother": status,
    })
}
