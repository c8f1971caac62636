//! Calibration of a declared model's linear part on records.
//!
//! A declared model is never exact: the damping of a real structure is not
//! the 1 % written in a model file, and springs are off by a few per cent.
//! Left as they are, those errors leave a residual spread over every mode
//! that no localized effect explains. The calibration corrects the spring
//! stiffnesses, the damping (each modal ratio, or both Rayleigh
//! coefficients) and, on request, the masses, by the output error of the
//! linear model over segments whose start states are free (eliminated by
//! variable projection, [`varpro`]), minimised by Levenberg–Marquardt
//! (crate `levenberg-marquardt`) on logarithmic parameters
//! `p = p_0 e^{q}` ([`params`]).
//!
//! Records at a level where the structure behaves linearly calibrate the
//! linear part alone; on a record with a nonlinear effect the calibration
//! is biased towards the effect's equivalent linearization, and the
//! diagnosis refits the linear part jointly with the effects it finds.
//!
//! Standard errors come from the Gauss–Newton covariance
//! `σ² (JᵀJ)⁻¹` at the optimum with `σ²` the residual variance; they
//! cover measurement noise only, on the assumption of a white residual. A
//! correction is called *significant* when it exceeds `significance`
//! standard errors and `min_change` of its declared value, and
//! *identifiable* when its relative standard error stays below
//! `max_relative_std` (a parameter the sensors cannot see, or can see only
//! in combination with others, has a large one).

pub mod grounding;
pub mod params;
pub mod varpro;

use crate::error::{Result, TacitError};
use crate::model::Model;
use crate::record::{Quantity, Record};
use levenberg_marquardt::{LeastSquaresProblem, LevenbergMarquardt, TerminationReason};
use nalgebra::{DMatrix, DVector, Dyn, Owned};
pub use params::{Freedom, LinearParam};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::cell::RefCell;
use std::time::Instant;
pub use varpro::Data;

/// Settings of [`calibrate`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CalibrationSettings {
    /// What may be corrected.
    pub freedom: Freedom,
    /// Segment length, s (default 1.0; > 0): long enough for the damping
    /// of the lowest modes to show, short enough that an unmodelled effect
    /// does not accumulate.
    pub segment_seconds: f64,
    /// Newmark sub-steps per sample (default 40; 1..=1000), as the
    /// diagnosis scores linear models.
    pub substeps: usize,
    /// Levenberg–Marquardt tolerance on the relative change of the cost
    /// and of the parameters (default 1e-8; > 0).
    pub tolerance: f64,
    /// Most residual evaluations per parameter (default 40; >= 2).
    pub patience: usize,
    /// Relative finite-difference step of the Jacobian (default 1e-6;
    /// (0, 0.1)).
    pub step: f64,
    /// Standard errors a correction must exceed to be significant
    /// (default 3; > 0).
    pub significance: f64,
    /// Relative change a correction must exceed to be significant
    /// (default 0.005: half a per cent; >= 0).
    pub min_change: f64,
    /// Relative standard error above which a parameter is reported as not
    /// identifiable with the sensors used (default 0.25; > 0).
    pub max_relative_std: f64,
    /// Springs held at their declared stiffness (0-based indices; default
    /// none): those acting along a direction where a force is
    /// reconstructed, which would absorb their change.
    #[serde(default)]
    pub frozen_springs: Vec<usize>,
    /// Plausible range of a spring's correction, as a factor either way
    /// of the declared stiffness (default 1.5; > 1, infinite: no limit).
    /// A spring the calibration moves beyond it has absorbed a localized
    /// effect's equivalent linearization (a cubic or a contact beside it)
    /// and is held at its declared value; the diagnosis must explain the
    /// difference (a stiffness change is one of its candidates) and the
    /// joint refinement frees it again.
    pub spring_factor: f64,
    /// Plausible range of a modal damping ratio, as a factor either way of
    /// the median of the other modes' calibrated ratios (default 4; > 1,
    /// infinite: no limit). A ratio beyond it (a mode's damping run to
    /// zero, or one mode damped many times more than the others) has
    /// absorbed a localized effect acting on that mode; it is held at that
    /// median.
    pub damping_factor: f64,
    /// Most parameters held out of their plausible range (default 2);
    /// one more running out makes the calibration
    /// [`CalibrationStatus::Absorbs`].
    pub max_held: usize,
}

impl Default for CalibrationSettings {
    fn default() -> Self {
        CalibrationSettings {
            freedom: Freedom::default(),
            segment_seconds: 1.0,
            substeps: 40,
            tolerance: 1e-8,
            patience: 40,
            step: 1e-6,
            significance: 3.0,
            min_change: 0.005,
            max_relative_std: 0.25,
            frozen_springs: vec![],
            spring_factor: 1.5,
            damping_factor: 4.0,
            max_held: 2,
        }
    }
}

impl CalibrationSettings {
    /// Check every field; the error names the field and its rule.
    pub fn validate(&self) -> Result<()> {
        let bad = |f: &str, rule: &str| {
            Err(TacitError::Setting(format!(
                "calibration.{f} must be {rule}"
            )))
        };
        if !(self.segment_seconds > 0.0 && self.segment_seconds.is_finite()) {
            return bad("segment_seconds", "finite and > 0 s");
        }
        if !(1..=1000).contains(&self.substeps) {
            return bad("substeps", "in 1..=1000");
        }
        if !(self.tolerance > 0.0) {
            return bad("tolerance", "> 0");
        }
        if self.patience < 2 {
            return bad("patience", ">= 2");
        }
        if !(self.step > 0.0 && self.step < 0.1) {
            return bad("step", "in (0, 0.1)");
        }
        if !(self.significance > 0.0) {
            return bad("significance", "> 0");
        }
        if !(self.min_change >= 0.0) {
            return bad("min_change", ">= 0");
        }
        if !(self.max_relative_std > 0.0) {
            return bad("max_relative_std", "> 0");
        }
        if !(self.spring_factor > 1.0) {
            return bad("spring_factor", "> 1 (inf: no limit)");
        }
        if !(self.damping_factor > 1.0) {
            return bad("damping_factor", "> 1 (inf: no limit)");
        }

        Ok(())
    }
}

/// How the minimisation ended.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum CalibrationStatus {
    /// Converged (the cost and the parameters stopped changing).
    Converged,
    /// The evaluation budget ran out; the best parameters found are used.
    EvaluationLimit,
    /// Nothing to calibrate (no free parameter).
    NothingFree,
    /// Parameters ran out of their plausible range one after another
    /// (more than [`CalibrationSettings::max_held`] held): the calibration
    /// absorbs a localized effect it cannot separate from the linear part
    /// and the declared values are kept; the diagnosis corrects the linear
    /// part jointly with the effects it finds.
    Absorbs {
        /// The parameters held, in the order they ran out.
        parameters: Vec<String>,
    },
    /// The minimisation failed; the declared values are kept.
    Failed {
        /// What failed.
        reason: String,
    },
}

impl CalibrationStatus {
    /// Whether the calibrated model can be used: converged, or the best
    /// parameters found when the evaluation budget ran out.
    pub fn usable(&self) -> bool {
        matches!(self, Self::Converged | Self::EvaluationLimit)
    }
}

/// One corrected number of the linear part.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Correction {
    /// Name (`k5`, `zeta2`, `m3`, `alpha`, `beta`).
    pub name: String,
    /// Which number.
    pub parameter: LinearParam,
    /// Unit ("" for a ratio).
    pub unit: String,
    /// Declared value.
    pub declared: f64,
    /// Calibrated value.
    pub calibrated: f64,
    /// Relative change, calibrated / declared − 1.
    pub change: f64,
    /// Standard error of the calibrated value (noise only), same unit.
    pub std_error: f64,
    /// Larger than `significance` standard errors and `min_change`.
    pub significant: bool,
    /// Relative standard error below `max_relative_std`.
    pub identifiable: bool,
    /// The calibration ran it out of its plausible range
    /// ([`CalibrationSettings::spring_factor`],
    /// [`CalibrationSettings::damping_factor`]) and held it (at the
    /// declared stiffness, or the other modes' median ratio) while the
    /// others were calibrated: a localized effect the linear part cannot
    /// hold acts there. Not estimated (infinite standard error).
    #[serde(default)]
    pub held: bool,
    /// The value it ran to before it was held (None when not held).
    #[serde(default)]
    pub ran_to: Option<f64>,
}

/// Residual of one channel after calibration.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ChannelResidual {
    /// The user's channel name.
    pub channel: String,
    /// Record it belongs to.
    pub record: String,
    /// RMS of the residual, channel units.
    pub rms: f64,
    /// RMS of the residual relative to the channel's RMS.
    pub relative: f64,
}

/// Result of [`calibrate`].
#[derive(Debug, Clone, Serialize)]
pub struct Calibration {
    /// The calibrated model (modal damping written per mode).
    #[serde(skip)]
    pub model: Model,
    /// One entry per free parameter.
    pub corrections: Vec<Correction>,
    /// Relative output error (segments, free starts) of the declared model.
    pub error_before: f64,
    /// The same for the calibrated model.
    pub error_after: f64,
    /// Residual per channel of the calibrated model.
    pub residuals: Vec<ChannelResidual>,
    /// How the minimisation ended.
    pub status: CalibrationStatus,
    /// Residual evaluations.
    pub evaluations: usize,
    /// Segments scored (all records).
    pub segments: usize,
    /// Records used.
    pub records: Vec<String>,
    /// Wall time, s (not serialized: a report's timings hold it).
    #[serde(skip)]
    pub seconds: f64,
    /// When parameters were held: the model the first minimisation gave,
    /// every parameter free (an alternative start for the diagnosis,
    /// which compares the two by the record's error).
    #[serde(skip)]
    pub unheld: Option<Model>,
}

impl Calibration {
    /// The significant corrections.
    pub fn significant(&self) -> impl Iterator<Item = &Correction> {
        self.corrections.iter().filter(|c| c.significant)
    }
}

/// The calibration data of a record: the channels at `sensors` (DOFs from
/// 1; all outputs when None), the force on an `ndof` model, `warmup`
/// samples not scored.
pub fn data_of(
    rec: &Record,
    ndof: usize,
    sensors: Option<&[usize]>,
    warmup: usize,
) -> Result<Data> {
    let outs: Vec<_> = rec
        .outputs
        .iter()
        .filter(|c| sensors.is_none_or(|s| s.contains(&c.dof)))
        .filter(|c| c.quantity != Quantity::Force)
        .collect();
    if outs.is_empty() {
        return Err(TacitError::record(
            rec.source.clone(),
            "calibration: no output channel at the sensors",
        ));
    }
    Ok(Data {
        source: crate::record::display_path(rec).display().to_string(),
        fs: rec.fs,
        force: crate::signal::force_matrix(rec, ndof),
        measured: DMatrix::from_fn(outs.len(), rec.len(), |c, k| outs[c].data[k]),
        channels: outs.iter().map(|c| (c.quantity, c.dof - 1)).collect(),
        names: outs.iter().map(|c| c.name()).collect(),
        warmup,
    })
}

/// The residual of the calibration as a function of `q` (log parameters).
struct Eval<'a> {
    base: Model,
    params: Vec<LinearParam>,
    p0: Vec<f64>,
    data: &'a [Data],
    weights: Vec<Vec<f64>>,
    lens: Vec<usize>,
    settings: &'a CalibrationSettings,
    evaluations: std::sync::atomic::AtomicUsize,
}

/// The least-squares problem the minimiser sees.
struct Problem<'a> {
    eval: Eval<'a>,
    q: DVector<f64>,
    r: Option<DVector<f64>>,
    jac: RefCell<Option<DMatrix<f64>>>,
    failure: Option<String>,
}

impl Eval<'_> {
    fn residual(&self, q: &[f64]) -> Result<DVector<f64>> {
        self.evaluations
            .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let m = params::apply(&self.base, &self.params, &self.p0, q);
        let mut parts = Vec::with_capacity(self.data.len());
        for (i, d) in self.data.iter().enumerate() {
            let (w, len) = (&self.weights[i], self.lens[i]);
            parts.push(varpro::project(&m, d, w, len, self.settings.substeps)?.r);
        }
        let total = parts.iter().map(|p| p.len()).sum();
        let mut r = DVector::zeros(total);
        let mut at = 0;
        for p in parts {
            r.rows_mut(at, p.len()).copy_from(&p);
            at += p.len();
        }
        Ok(r)
    }

    /// Forward-difference Jacobian at `q` (columns in parallel).
    fn jacobian_at(&self, q: &DVector<f64>, r0: &DVector<f64>) -> Result<DMatrix<f64>> {
        let h = self.settings.step;
        let cols: Vec<Result<DVector<f64>>> = (0..q.len())
            .into_par_iter()
            .map(|j| {
                let mut qj = q.clone();
                qj[j] += h;
                Ok((self.residual(qj.as_slice())? - r0) / h)
            })
            .collect();
        let mut jac = DMatrix::zeros(r0.len(), q.len());
        for (j, c) in cols.into_iter().enumerate() {
            jac.set_column(j, &c?);
        }
        Ok(jac)
    }
}

impl LeastSquaresProblem<f64, Dyn, Dyn> for Problem<'_> {
    type ResidualStorage = Owned<f64, Dyn>;
    type JacobianStorage = Owned<f64, Dyn, Dyn>;
    type ParameterStorage = Owned<f64, Dyn>;

    fn set_params(&mut self, x: &DVector<f64>) {
        self.q.copy_from(x);
        *self.jac.borrow_mut() = None;
        match self.eval.residual(x.as_slice()) {
            Ok(r) => self.r = Some(r),
            Err(e) => {
                self.r = None;
                self.failure.get_or_insert(e.to_string());
            }
        }
    }
    fn params(&self) -> DVector<f64> {
        self.q.clone()
    }
    fn residuals(&self) -> Option<DVector<f64>> {
        self.r.clone()
    }
    fn jacobian(&self) -> Option<DMatrix<f64>> {
        if self.jac.borrow().is_none() {
            let r0 = self.r.as_ref()?;
            *self.jac.borrow_mut() = self.eval.jacobian_at(&self.q, r0).ok();
        }
        self.jac.borrow().clone()
    }
}

/// Calibrate `declared`'s linear part on `data` (one or more records of
/// the same structure). A parameter the minimisation runs out of its
/// plausible range ([`implausible`]) is held and the others are
/// calibrated again, one at a time, the worst first.
pub fn calibrate(
    declared: &Model,
    data: &[Data],
    settings: &CalibrationSettings,
) -> Result<Calibration> {
    settings.validate()?;
    let t = Instant::now();
    let base = params::per_mode(&declared.linear_part())?;
    let free: Vec<LinearParam> = params::select(&base, &settings.freedom)
        .into_iter()
        .filter(|p| !matches!(p, LinearParam::Spring(i) if settings.frozen_springs.contains(i)))
        .collect();
    let p0 = free
        .iter()
        .map(|p| p.get(&base))
        .collect::<Result<Vec<_>>>()?;
    let lens = data
        .iter()
        .map(|d| segment_len(d, settings))
        .collect::<Result<Vec<_>>>()?;
    let weights: Vec<Vec<f64>> = data.iter().map(|d| d.weights()).collect();
    let mut q = DVector::zeros(free.len());
    let mut held: Vec<Held> = vec![];
    let mut evaluations = 0;
    let mut r0 = None;
    let mut absorbed = false;
    let mut first_q = None;
    let run = loop {
        let open: Vec<usize> = (0..free.len())
            .filter(|i| !held.iter().any(|h| h.index == *i))
            .collect();
        let pick = |v: &[f64], ix: &[usize]| ix.iter().map(|&i| v[i]).collect::<Vec<_>>();
        let held_ix: Vec<usize> = held.iter().map(|h| h.index).collect();
        let held_params: Vec<LinearParam> = held_ix.iter().map(|&i| free[i]).collect();
        let eval = Eval {
            base: params::apply(
                &base,
                &held_params,
                &pick(&p0, &held_ix),
                &pick(q.as_slice(), &held_ix),
            ),
            params: open.iter().map(|&i| free[i]).collect(),
            p0: pick(&p0, &open),
            data,
            weights: weights.clone(),
            lens: lens.clone(),
            settings,
            evaluations: 0.into(),
        };
        let run = solve(eval, DVector::from_vec(pick(q.as_slice(), &open)), settings)?;
        evaluations += run.evaluations;
        r0.get_or_insert_with(|| run.r0.clone());
        for (k, &i) in open.iter().enumerate() {
            q[i] = run.q[k];
        }
        first_q.get_or_insert_with(|| q.clone());
        // a model calibrated by scales has no local number to hold
        let out = match base.calibrated_by_scales() {
            true => None,
            false => implausible(&free, &q, &held, settings),
        };
        match out {
            // a spring out of range: the springs beside a localized effect
            // take its linearization in turn when one is held, so every
            // spring is held at its declared stiffness and the damping
            // calibrated again from the declared values
            // the effect's linearization moves on to the next parameter
            // when one is held: the calibration cannot separate it, and
            // the declared values are kept
            Some(h) if held.len() >= settings.max_held || open.len() < 2 => {
                held.push(h);
                absorbed = true;
                break (run, open);
            }
            // a spring out of range: the others start again from their
            // declared values (their values were fitted beside it); a
            // ratio: the others go on from where they are
            Some(h) => {
                if matches!(free[h.index], LinearParam::Spring(_)) {
                    q.fill(0.0);
                    held.iter().for_each(|g| q[g.index] = g.q);
                }
                q[h.index] = h.q;
                held.push(h);
            }
            None => break (run, open),
        }
    };
    let ((mut run, open), r0) = (run, r0.expect("one run at least"));
    if absorbed {
        q.fill(0.0);
        run.r = r0.clone();
        run.std_q = None;
        run.status = CalibrationStatus::Absorbs {
            parameters: held.iter().map(|h| free[h.index].label(&base)).collect(),
        };
    }
    let model = restore_damping(declared, &params::apply(&base, &free, &p0, q.as_slice()));
    let mut std_q = run
        .std_q
        .as_ref()
        .map(|_| DVector::from_element(free.len(), f64::INFINITY));
    if let (Some(all), Some(s)) = (std_q.as_mut(), run.std_q.as_ref()) {
        for (k, &i) in open.iter().enumerate() {
            all[i] = s[k];
        }
    }
    let mut corrections = corrections(&base, &free, &p0, &q, std_q.as_ref(), settings);
    for h in &held {
        corrections[h.index].held = true;
        corrections[h.index].ran_to = Some(p0[h.index] * h.ran_to.exp());
    }
    let residuals = channel_residuals(&model, data, settings, &lens)?;
    Ok(Calibration {
        error_before: relative(&r0, data, &lens, &weights),
        error_after: relative(&run.r, data, &lens, &weights),
        model: with_elements(declared, model),
        corrections,
        residuals,
        status: run.status,
        evaluations,
        segments: data
            .iter()
            .zip(&lens)
            .map(|(d, &l)| d.segment_starts(l).len())
            .sum(),
        records: data.iter().map(|d| d.source.clone()).collect(),
        seconds: t.elapsed().as_secs_f64(),
        unheld: (!held.is_empty()).then(|| {
            let q1 = first_q.expect("one run at least");
            with_elements(
                declared,
                restore_damping(declared, &params::apply(&base, &free, &p0, q1.as_slice())),
            )
        }),
    })
}

/// A parameter held out of the calibration.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Held {
    /// Index among the free parameters.
    pub index: usize,
    /// The log value it is held at.
    pub q: f64,
    /// The log value the calibration ran it to.
    pub ran_to: f64,
}

/// The parameter farthest out of its plausible range at `q` (log values
/// of `free`), with the value to hold it at; None when every one not yet
/// `held` is plausible. A spring is plausible within
/// [`CalibrationSettings::spring_factor`] of its declared stiffness (held
/// there); a modal ratio within [`CalibrationSettings::damping_factor`] of
/// the median of the other modes' ratios not held (held at that median).
/// Global numbers (scales, Rayleigh coefficients, one ratio for every
/// mode) are never held: they cannot absorb a localized effect alone.
pub fn implausible(
    free: &[LinearParam],
    q: &DVector<f64>,
    held: &[Held],
    settings: &CalibrationSettings,
) -> Option<Held> {
    let is_held = |i: usize| held.iter().any(|h| h.index == i);
    let mut worst: Option<(f64, Held)> = None;
    for (i, p) in free.iter().enumerate() {
        if is_held(i) {
            continue;
        }
        let (centre, limit) = match p {
            LinearParam::Spring(_) => (0.0, settings.spring_factor.ln()),
            LinearParam::ModalRatio(_) => {
                let others: Vec<f64> = free
                    .iter()
                    .enumerate()
                    .filter(|(j, o)| {
                        *j != i && !is_held(*j) && matches!(o, LinearParam::ModalRatio(_))
                    })
                    .map(|(j, _)| q[j])
                    .collect();
                match median(others) {
                    Some(m) => (m, settings.damping_factor.ln()),
                    None => continue,
                }
            }
            _ => continue,
        };
        let excess = (q[i] - centre).abs() - limit;
        if excess > 0.0 && worst.is_none_or(|(w, _)| excess > w) {
            worst = Some((
                excess,
                Held {
                    index: i,
                    q: centre,
                    ran_to: q[i],
                },
            ));
        }
    }
    worst.map(|(_, h)| h)
}

/// Median of `v` (None when empty).
fn median(mut v: Vec<f64>) -> Option<f64> {
    if v.is_empty() {
        return None;
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    Some(if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    })
}

/// One minimisation of the calibration from `q0`.
struct Run {
    /// Residual at `q0`.
    r0: DVector<f64>,
    /// Parameters at the end.
    q: DVector<f64>,
    /// Residual there.
    r: DVector<f64>,
    /// Their standard errors (None without a Jacobian).
    std_q: Option<DVector<f64>>,
    status: CalibrationStatus,
    evaluations: usize,
}

fn solve(eval: Eval<'_>, q0: DVector<f64>, settings: &CalibrationSettings) -> Result<Run> {
    let mut prob = Problem {
        eval,
        q: q0.clone(),
        r: None,
        jac: RefCell::new(None),
        failure: None,
    };
    prob.set_params(&q0);
    let r0 = prob
        .r
        .clone()
        .ok_or_else(|| TacitError::Numerical(prob.failure.clone().unwrap_or_default()))?;
    let (prob, status) = minimize(prob, settings);
    let r = prob.r.clone().unwrap_or_else(|| r0.clone());
    let std_q = prob.jacobian().map(|j| std_errors(&j, &r, prob_dof(&prob)));
    Ok(Run {
        r0,
        q: prob.q.clone(),
        r,
        std_q,
        status,
        evaluations: prob
            .eval
            .evaluations
            .load(std::sync::atomic::Ordering::Relaxed),
    })
}

/// Segment length in samples of one record; an error when the scored part
/// holds less than one segment.
fn segment_len(d: &Data, settings: &CalibrationSettings) -> Result<usize> {
    let len = ((settings.segment_seconds * d.fs).round() as usize).max(4);
    let scored = d.measured.ncols().saturating_sub(d.warmup);
    if scored < len {
        return Err(TacitError::record(
            d.source.clone(),
            format!(
                "calibration: {scored} scored samples, fewer than one segment of {len} (calibration.segment_seconds = {} s)",
                settings.segment_seconds
            ),
        ));
    }
    Ok(len)
}

fn minimize<'a>(
    prob: Problem<'a>,
    settings: &CalibrationSettings,
) -> (Problem<'a>, CalibrationStatus) {
    if prob.eval.params.is_empty() {
        return (prob, CalibrationStatus::NothingFree);
    }
    let (prob, report) = LevenbergMarquardt::new()
        .with_tol(settings.tolerance)
        .with_patience(settings.patience)
        .minimize(prob);
    let status = match &report.termination {
        t if t.was_successful() => CalibrationStatus::Converged,
        TerminationReason::LostPatience => CalibrationStatus::EvaluationLimit,
        t => CalibrationStatus::Failed {
            reason: prob
                .failure
                .clone()
                .unwrap_or_else(|| format!("Levenberg–Marquardt stopped: {t:?}")),
        },
    };
    (prob, status)
}

/// Degrees of freedom of the residual: rows less the eliminated start
/// states and the parameters.
fn prob_dof(p: &Problem<'_>) -> f64 {
    let rows = p.r.as_ref().map_or(0, |r| r.len());
    let starts: usize = p
        .eval
        .data
        .iter()
        .zip(&p.eval.lens)
        .map(|(d, &l)| d.segment_starts(l).len() * 2 * d.force.nrows())
        .sum();
    (rows as f64 - starts as f64 - p.eval.params.len() as f64).max(1.0)
}

/// Standard errors of `q` from `σ² (JᵀJ)⁻¹` (pseudo-inverse: a direction
/// the data do not fix gets an infinite error).
fn std_errors(j: &DMatrix<f64>, r: &DVector<f64>, dof: f64) -> DVector<f64> {
    if j.ncols() == 0 {
        return DVector::zeros(0);
    }
    let s2 = r.norm_squared() / dof;
    let svd = j.clone().svd(false, true);
    let vt = svd.v_t.expect("V requested");
    let smax = svd.singular_values.max();
    DVector::from_fn(j.ncols(), |i, _| {
        let mut var = 0.0;
        for (k, &s) in svd.singular_values.iter().enumerate() {
            if s <= 1e-12 * smax {
                if vt[(k, i)].abs() > 1e-8 {
                    return f64::INFINITY;
                }
                continue;
            }
            var += (vt[(k, i)] / s).powi(2);
        }
        (s2 * var).sqrt()
    })
}

fn corrections(
    base: &Model,
    free: &[LinearParam],
    p0: &[f64],
    q: &DVector<f64>,
    std_q: Option<&DVector<f64>>,
    s: &CalibrationSettings,
) -> Vec<Correction> {
    free.iter()
        .enumerate()
        .map(|(i, p)| {
            let value = p0[i] * q[i].exp();
            let sq = std_q.map_or(f64::INFINITY, |v| v[i]);
            let change = q[i].exp() - 1.0;
            Correction {
                name: p.label(base),
                parameter: *p,
                unit: p.unit().into(),
                declared: p0[i],
                calibrated: value,
                change,
                std_error: value * sq,
                significant: q[i].abs() > s.significance * sq && change.abs() > s.min_change,
                identifiable: sq < s.max_relative_std,
                held: false,
                ran_to: None,
            }
        })
        .collect()
}

/// Relative error `‖r‖ / ‖W y‖` over the scored segments of every record
/// (segment lengths `lens`, channel weights `weights`).
fn relative(r: &DVector<f64>, data: &[Data], lens: &[usize], weights: &[Vec<f64>]) -> f64 {
    let mut ss = 0.0;
    for ((d, &len), w) in data.iter().zip(lens).zip(weights) {
        for s in d.segment_starts(len) {
            for k in s..s + len {
                for (c, wc) in w.iter().enumerate() {
                    ss += (wc * d.measured[(c, k)]).powi(2);
                }
            }
        }
    }
    r.norm() / ss.sqrt().max(1e-300)
}

/// Residual RMS per channel of the calibrated model (channel units).
fn channel_residuals(
    model: &Model,
    data: &[Data],
    s: &CalibrationSettings,
    lens: &[usize],
) -> Result<Vec<ChannelResidual>> {
    let mut out = vec![];
    for (d, &len) in data.iter().zip(lens) {
        let ones = vec![1.0; d.channels.len()];
        let pr = varpro::project(model, d, &ones, len, s.substeps)?;
        let p = d.channels.len();
        let rows = pr.r.len() / p;
        for c in 0..p {
            let ss: f64 = (0..rows).map(|k| pr.r[k * p + c].powi(2)).sum();
            let ys: f64 = d
                .segment_starts(len)
                .iter()
                .flat_map(|&s0| s0..s0 + len)
                .map(|k| d.measured[(c, k)].powi(2))
                .sum();
            let rms = (ss / rows.max(1) as f64).sqrt();
            out.push(ChannelResidual {
                channel: d.names[c].clone(),
                record: d.source.clone(),
                rms,
                relative: (ss / ys.max(1e-300)).sqrt(),
            });
        }
    }
    Ok(out)
}

/// The calibrated linear part with the declared damping kept as one modal
/// ratio when no ratio moved.
fn restore_damping(declared: &Model, calibrated: &Model) -> Model {
    let mut m = calibrated.clone();
    if let (
        crate::model::Damping::Modal {
            ratio: Some(z),
            ratios: _,
        },
        crate::model::Damping::Modal { ratios, .. },
    ) = (&declared.damping, &calibrated.damping)
    {
        if ratios.iter().all(|r| r == z) {
            m.damping = declared.damping.clone();
        }
    }
    m
}

/// `declared` with its linear part replaced by `linear`'s (the nonlinear
/// elements kept).
fn with_elements(declared: &Model, linear: Model) -> Model {
    let mut m = declared.clone();
    m.masses = linear.masses;
    m.springs = linear.springs;
    m.damping = linear.damping;
    m.matrices = linear.matrices;
    m
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::linear::SampledModel;

    /// The parameter farthest out of its range is named, with the value it
    /// is held at: a spring at its declared value, a modal ratio at the
    /// median of the others not held; global numbers never.
    #[test]
    fn the_worst_implausible_parameter_is_held_at_its_centre() {
        let free = [
            LinearParam::Spring(0),
            LinearParam::Spring(1),
            LinearParam::ModalRatio(0),
            LinearParam::ModalRatio(1),
            LinearParam::ModalRatio(2),
            LinearParam::ModalRatio(3),
            LinearParam::RayleighAlpha,
        ];
        let s = CalibrationSettings::default();
        // spring 2 at +65 % (beyond a factor 1.5 by 0.095 in log), ratio 4
        // at e^-1 against a median e^1.1 of the others (beyond a factor 4
        // by 0.71), alpha far off but global
        let q = DVector::from_vec(vec![0.1, 0.5, 1.0, 1.1, 1.2, -1.0, 9.0]);
        let h = implausible(&free, &q, &[], &s).unwrap();
        assert_eq!(h.index, 5);
        assert!((h.q - 1.1).abs() < 1e-12 && (h.ran_to + 1.0).abs() < 1e-12);
        // with the ratio held, the spring is next, held at its declared value
        let h2 = implausible(&free, &q, &[h], &s).unwrap();
        assert_eq!((h2.index, h2.q), (1, 0.0));
        // with both held nothing else is out of range
        assert!(implausible(&free, &q, &[h, h2], &s).is_none());
        // a wider spring range lets the spring pass
        let wide = CalibrationSettings {
            spring_factor: 2.0,
            ..s
        };
        assert!(implausible(&free, &q, &[h], &wide).is_none());
    }

    fn chain(k12: f64) -> Model {
        Model::from_toml_str(
            &format!(
                r#"
name = "chain"
masses = [1.0, 1.0, 1.0]
[[spring]]
dofs = [1]
stiffness = 1000.0
[[spring]]
dofs = [1, 2]
stiffness = {k12}
[[spring]]
dofs = [2, 3]
stiffness = 1500.0
[damping]
kind = "rayleigh"
alpha = 0.5
beta = 2e-4
"#
            ),
            "chain",
        )
        .unwrap()
    }

    /// Accelerations of `truth` at every DOF under a force at DOF 1.
    fn record_of(truth: &Model, fs: f64, n: usize) -> Data {
        let sm = SampledModel::from_model(truth, fs, 10).unwrap();
        let force = DMatrix::from_fn(3, n, |i, k| {
            let t = k as f64;
            if i == 0 {
                (t * 0.37).sin() * 3.0 + (t * 0.091).cos() * 2.0 + (t * 1.3).sin()
            } else {
                0.0
            }
        });
        let xs = sm.simulate(&DVector::zeros(6), &force);
        let channels: Vec<_> = (0..3).map(|d| (Quantity::Accel, d)).collect();
        let (cy, dy) = sm.outputs(&channels).unwrap();
        Data {
            source: "chain".into(),
            fs,
            measured: &cy * &xs + &dy * &force,
            force,
            channels,
            names: vec!["a1".into(), "a2".into(), "a3".into()],
            warmup: 0,
        }
    }

    /// A spring three times its declared stiffness (a record the declared
    /// spring cannot explain) runs out of the plausible range: it is held
    /// at its declared value, what it ran to is reported (the truth, on a
    /// noise-free record), and it is not called significant.
    #[test]
    fn a_spring_run_out_of_range_is_held_and_reported() {
        let data = record_of(&chain(6000.0), 100.0, 2000);
        let s = CalibrationSettings {
            substeps: 10,
            ..Default::default()
        };
        let cal = calibrate(&chain(2000.0), std::slice::from_ref(&data), &s).unwrap();
        let k12 = &cal.corrections[1];
        assert!(k12.held, "{:?}", cal.corrections);
        let ran = k12.ran_to.unwrap();
        assert!((ran / 6000.0 - 1.0).abs() < 0.01, "ran to {ran}");
        assert_eq!(k12.calibrated, 2000.0);
        assert!(!k12.significant && k12.std_error.is_infinite());
        // the same record with the plausible range opened: calibrated
        let open = CalibrationSettings {
            spring_factor: f64::INFINITY,
            ..s
        };
        let cal = calibrate(&chain(2000.0), &[data], &open).unwrap();
        let k = cal.corrections[1].calibrated;
        assert!(
            (k / 6000.0 - 1.0).abs() < 1e-3 && !cal.corrections[1].held,
            "{k}"
        );
        assert_eq!(cal.status, CalibrationStatus::Converged);
    }

    /// Nothing free (every freedom off): the declared model comes back
    /// with its output error, no correction and the status saying so
    /// (the standard errors of no parameter are none, not a failed SVD).
    #[test]
    fn nothing_free_gives_the_declared_model_and_its_error() {
        let data = record_of(&chain(6000.0), 100.0, 2000);
        let s = CalibrationSettings {
            substeps: 10,
            freedom: Freedom {
                springs: false,
                damping: false,
                masses: false,
            },
            ..Default::default()
        };
        let cal = calibrate(&chain(2000.0), &[data], &s).unwrap();
        assert_eq!(cal.status, CalibrationStatus::NothingFree);
        assert!(cal.corrections.is_empty(), "{:?}", cal.corrections);
        assert!(cal.error_before > 0.01, "{}", cal.error_before);
        assert_eq!(cal.error_before, cal.error_after);
    }
}
