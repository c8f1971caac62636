//! Close the loop: find the residual, trace it to the missing effect, add
//! it, fit it, and report the error before and after.
//!
//! 1. **Before**: the declared model's errors ([`errors`]): multiple-shooting
//!    prediction over short segments from the reconstructed start states
//!    (`relative_error`) and open-loop simulation (`simulation_error`).
//! 2. **Identify**: the full-horizon smoother ([`crate::horizon`]) on the
//!    full-order linear model, an unknown force at every DOF: reconstructed
//!    states and internal force.
//! 3. **Trace** ([`crate::trace`]): rank the candidate effects by how much of
//!    the segment residual they remove (BIC, minimum gain).
//! 4. **Add and fit**: add the best effect as a model element and fit all
//!    added effects' parameters jointly by multiple-shooting simulation error
//!    ([`crate::update`], Levenberg–Marquardt, bounds, several starts for a
//!    contact), with sub-steps that resolve the stiffest element. The new
//!    residual (nonlinear model) goes back to step 3 while the next effect
//!    pays for itself.
//! 5. **After**: the errors again, on the record and on a validation record.

pub mod calibrated;
pub mod effects;
pub mod errors;
pub mod joint;
pub mod lifted;
pub mod locate;
pub mod report;
pub mod starts;

use crate::error::{Result, TacitError};
use crate::horizon::{self, problem::HorizonData, settings::HorizonSettings};
use crate::integrate::SimSettings;
use crate::linear::SampledModel;
use crate::model::Model;
use crate::record::{Quantity, Record};
use crate::trace::{self, EffectKind, RankedEffect, TraceInput, TraceSettings};
use crate::update::optimize::FitSettings;
use crate::update::problem::Observation;
use crate::update::shooting::{self, Segment};
use effects::AddedEffect;
pub use errors::{ChannelError, Comparison, ErrorSet};
use nalgebra::DMatrix;
use serde::Serialize;
use std::collections::BTreeMap;
use std::time::Instant;

/// Settings of the diagnosis. Every field has a default.
#[derive(Debug, Clone, Serialize)]
pub struct DiagnoseSettings {
    /// Segment length of the multiple-shooting error, s (default 0.1).
    pub segment_seconds: f64,
    /// Sub-steps per sample of the identification and the trace's linear
    /// model (default 10); the simulations of the scored and fitted models
    /// use at least this and at least [`MIN_SUBSTEPS`], more for a stiff
    /// element ([`auto_substeps`]).
    pub substeps: usize,
    /// Most effects added (default 3).
    pub max_effects: usize,
    /// Trace settings.
    pub trace: TraceSettings,
    /// Identification settings.
    pub horizon: HorizonSettings,
    /// Optimizer settings of the parameter fit.
    pub fit: FitSettings,
    /// Segments used by the fit (evenly spread over the record; default 20).
    pub fit_segments: usize,
    /// Target ω h of the stiffest element when choosing sub-steps (default 0.15).
    pub omega_h: f64,
    /// Largest number of sub-steps (default 80).
    pub max_substeps: usize,
    /// An added and fitted effect must remove at least this fraction of the
    /// squared multiple-shooting error, or it is withdrawn (default 0.05,
    /// the trace's threshold).
    pub min_improvement: f64,
    /// The same for a linear change along the located force direction that
    /// the screen did not propose, fitted after a nonlinear effect there
    /// (default 0.5: it must explain half of what remains).
    pub companion_improvement: f64,
    /// Multiple-shooting relative error at or below which the model is taken
    /// to explain the record up to noise and integration error, and no
    /// effect is sought (default 0.025: 2.5 × a 1 % noise level).
    pub noise_floor: f64,
    /// Where the states come from (default: the lifted smoother).
    pub states: StatesSource,
    /// Dominance ratio of the force-location search ([`locate`]; default
    /// 0.8; 0 disables it: an unknown force at every DOF).
    pub locate_ratio: f64,
    /// Most force directions the search selects (default 3).
    pub locate_max: usize,
    /// Gauss–Newton iterations refining each segment's start state for the
    /// model being scored ([`starts`]; default 3, a linear model takes one;
    /// 0 = reconstructed states).
    pub start_iterations: usize,
    /// Most alternations of start-state refinement and refit after an
    /// effect's fit (default 12; they stop once the cost falls by < 1 %).
    pub start_alternations: usize,
    /// Settings of the lifted smoother.
    #[serde(skip)]
    pub lifted: lifted::LiftedSettings,
}

/// Source of the states the trace and the segments use.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum StatesSource {
    /// Reconstructed by the sub-sample ("lifted") smoother
    /// ([`lifted::reconstruct`]): the unknown force piecewise constant on
    /// sub-intervals of each sample, so impacts between samples are seen.
    Lifted,
    /// Reconstructed by the full-horizon smoother ([`crate::horizon`]), the
    /// unknown force linear between samples.
    Reconstructed,
    /// The truth stored with a simulated record (for validation of the
    /// later steps only; an error on a record without truth).
    Truth,
}

impl Default for DiagnoseSettings {
    fn default() -> Self {
        DiagnoseSettings {
            segment_seconds: 0.1,
            substeps: 10,
            max_effects: 3,
            trace: TraceSettings::default(),
            horizon: HorizonSettings {
                selection: horizon::settings::WeightSelection::Gcv,
                ..HorizonSettings::default()
            },
            fit: FitSettings {
                max_iterations: 30,
                x_tol: 1e-5,
                f_tol: 1e-7,
                ..FitSettings::default()
            },
            fit_segments: 20,
            omega_h: 0.15,
            max_substeps: 80,
            min_improvement: 0.05,
            companion_improvement: 0.5,
            noise_floor: 0.025,
            states: StatesSource::Lifted,
            locate_ratio: 0.8,
            locate_max: 3,
            start_iterations: 3,
            start_alternations: 12,
            lifted: lifted::LiftedSettings::default(),
        }
    }
}

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
    w2 = w2.max(effects::stiffest_added(model, states));
    let need = (w2.sqrt() / (omega_h * fs)).ceil() as usize;
    need.clamp(base.max(1), max.max(base))
}

/// Integrator settings with [`auto_substeps`] for `model` (cubic springs
/// judged on the reconstructed `states`).
fn resolved(
    model: &Model,
    fs: f64,
    settings: &DiagnoseSettings,
    states: &DMatrix<f64>,
) -> SimSettings {
    // at least MIN_SUBSTEPS, for every model alike (the declared one and
    // each fitted one): at 10 the Newmark period error of the highest
    // modes was left for an effect to fit. A linear model (and a contact
    // model while its contacts are open) is stepped a whole sample at a
    // time, so they cost it nothing
    let base = settings.substeps.max(MIN_SUBSTEPS);
    SimSettings {
        substeps: auto_substeps(
            model,
            fs,
            base,
            settings.omega_h,
            settings.max_substeps,
            Some(states),
        ),
        ..Default::default()
    }
}

/// Fewest sub-steps of a model in [`resolved`].
pub const MIN_SUBSTEPS: usize = 40;

/// The reconstruction from the identification step.
#[derive(Debug, Clone)]
pub struct Reconstruction {
    /// States `[u; v]` (2n × N).
    pub states: DMatrix<f64>,
    /// Identified internal force (n × N), left-hand-side convention (the
    /// simulator's `f_int`: the force the model lacks is `−f_int`).
    pub force: DMatrix<f64>,
    /// Standard deviation of the force (n × N) when available.
    pub force_std: Option<DMatrix<f64>>,
    /// Tikhonov weight λ used.
    pub lambda: f64,
    /// Status and notes of the smoother.
    pub status: String,
    /// Seconds.
    pub elapsed_s: f64,
}

/// A record prepared for the loop: the channels, the comparison data and
/// the reconstruction.
#[derive(Debug, Clone)]
pub struct Prepared {
    /// `(quantity, dof0)` of every measured channel used.
    pub channels: Vec<(Quantity, usize)>,
    /// Data the errors are computed on.
    pub comparison: Comparison,
    /// Reconstructed states and force.
    pub recon: Reconstruction,
    /// The linear model's sampled map.
    pub sampled: SampledModel,
    /// Samples per segment.
    pub segment: usize,
    /// The force-location search (lifted states only).
    pub located: Option<locate::Located>,
}

/// Prepare a record: select the channels (all outputs at `sensors`, or all
/// outputs), reconstruct states and force with the linear part of `model`,
/// cut the segments.
pub fn prepare(
    model: &Model,
    rec: &Record,
    sensors: Option<&[usize]>,
    settings: &DiagnoseSettings,
) -> Result<Prepared> {
    prepare_located(model, rec, sensors, settings, None)
}

/// The channels, input and sampled linear part of a record, checked.
struct Setup<'a> {
    rec: &'a Record,
    outs: Vec<&'a crate::record::Channel>,
    segment: usize,
    channels: Vec<(Quantity, usize)>,
    force: DMatrix<f64>,
    measured: DMatrix<f64>,
    sampled: SampledModel,
}

fn setup<'a>(
    model: &Model,
    rec: &'a Record,
    sensors: Option<&[usize]>,
    settings: &DiagnoseSettings,
) -> Result<Setup<'a>> {
    let n = model.ndof();
    rec.validate(Some(n))?;
    if let Some(s) = sensors {
        for &d in s {
            if d < 1 || d > n {
                return Err(TacitError::Setting(format!(
                    "sensor DOF {d} is outside the model (1..={n})"
                )));
            }
            if !rec.outputs.iter().any(|c| c.dof == d) {
                return Err(TacitError::record(
                    rec.source.clone(),
                    format!("no output channel at sensor DOF {d}"),
                ));
            }
        }
    }
    let outs: Vec<_> = rec
        .outputs
        .iter()
        .filter(|c| sensors.is_none_or(|s| s.contains(&c.dof)))
        .collect();
    if outs.is_empty() {
        return Err(TacitError::record(
            rec.source.clone(),
            "no output channel to compare",
        ));
    }
    let segment = ((settings.segment_seconds * rec.fs).round() as usize).max(4);
    if rec.len() < 2 * segment {
        return Err(TacitError::record(
            rec.source.clone(),
            format!(
                "{} samples: at least two segments of {segment} samples are needed",
                rec.len()
            ),
        ));
    }
    let channels: Vec<(Quantity, usize)> = outs.iter().map(|c| (c.quantity, c.dof - 1)).collect();
    let force = crate::signal::force_matrix(rec, n);
    let measured = DMatrix::from_fn(outs.len(), rec.len(), |c, k| outs[c].data[k]);
    let sampled = SampledModel::from_model(&model.linear_part(), rec.fs, settings.substeps)?;
    Ok(Setup {
        rec,
        outs,
        segment,
        channels,
        force,
        measured,
        sampled,
    })
}

/// The force directions of a record (the greedy search of
/// [`locate::locate`]) when `settings` reconstruct with the lifted smoother
/// and search; None otherwise.
fn search(
    model: &Model,
    s: &Setup<'_>,
    settings: &DiagnoseSettings,
) -> Result<Option<locate::Located>> {
    if settings.states == StatesSource::Lifted
        && settings.locate_ratio > 0.0
        && settings.locate_max > 0
    {
        Ok(Some(locate::locate(
            model,
            &s.sampled,
            &s.force,
            &s.measured,
            &s.channels,
            &settings.lifted,
            settings.locate_ratio,
            settings.locate_max,
        )?))
    } else {
        Ok(None)
    }
}

/// [`prepare`] with the force directions already located (on another
/// record of the same structure: a validation record), or searched when
/// `located` is None.
pub fn prepare_located(
    model: &Model,
    rec: &Record,
    sensors: Option<&[usize]>,
    settings: &DiagnoseSettings,
    located_before: Option<&locate::Located>,
) -> Result<Prepared> {
    let st = setup(model, rec, sensors, settings)?;
    let t = Instant::now();
    let loc = match located_before {
        Some(l) => Some(l.clone()),
        None => search(model, &st, settings)?,
    };
    prepare_from(model, st, settings, loc, t)
}

/// [`prepare_located`] from the record's [`setup`], with the force
/// directions `loc` (the reconstruction timed from `t`).
fn prepare_from(
    model: &Model,
    st: Setup<'_>,
    settings: &DiagnoseSettings,
    loc: Option<locate::Located>,
    t: Instant,
) -> Result<Prepared> {
    let n = model.ndof();
    let mut located = None;
    let Setup {
        rec,
        outs,
        segment,
        channels,
        force,
        measured,
        sampled,
    } = st;
    let mut recon = if settings.states == StatesSource::Lifted {
        let e = match &loc {
            Some(l) if !l.directions.is_empty() => l.matrix(n),
            _ => DMatrix::identity(n, n),
        };
        let r = lifted::reconstruct_along(
            &sampled,
            &e,
            &force,
            &measured,
            &channels,
            &settings.lifted,
        )?;
        let status = format!(
            "lifted smoother, {} sub-intervals per sample; {}: {}",
            settings.lifted.resolution,
            loc.as_ref()
                .map_or("location search off".into(), |l| l.summary()),
            r.status
        );
        located = loc;
        Reconstruction {
            states: r.states,
            force: -r.force,
            force_std: None,
            lambda: settings.lifted.lambda,
            status,
            elapsed_s: t.elapsed().as_secs_f64(),
        }
    } else {
        reconstruct(&sampled, &force, &measured, &channels, &settings.horizon)?
    };
    if settings.states == StatesSource::Truth {
        let t = rec.truth.as_ref().ok_or_else(|| {
            TacitError::record(
                rec.source.clone(),
                "states from the truth: the record has no truth",
            )
        })?;
        for i in 0..n {
            for k in 0..rec.len() {
                recon.states[(i, k)] = t.u[i][k];
                recon.states[(n + i, k)] = t.v[i][k];
            }
        }
        recon.status = format!("{} (states replaced by the record's truth)", recon.status);
    }
    let state = |k: usize| -> Result<(Vec<f64>, Vec<f64>)> {
        let u = (0..n).map(|i| recon.states[(i, k)]).collect();
        let v = (0..n).map(|i| recon.states[(n + i, k)]).collect();
        Ok((u, v))
    };
    let segments = quiet_segments(rec.len(), segment, &recon.force, state)?;
    let (u0, v0) = state(0)?;
    let observations = outs
        .iter()
        .map(|c| Observation {
            quantity: c.quantity,
            dof: c.dof,
            weight: 1.0 / c.data.iter().map(|x| x * x).sum::<f64>().sqrt().max(1e-300),
            data: c.data.clone(),
        })
        .collect();
    Ok(Prepared {
        channels,
        comparison: Comparison {
            fs: rec.fs,
            force,
            observations,
            segments,
            whole: Segment {
                start: 0,
                len: rec.len(),
                u0,
                v0,
            },
            start_iterations: settings.start_iterations,
        },
        recon,
        sampled,
        segment,
        located,
    })
}

/// Consecutive segments of about `len` samples whose boundaries are moved
/// (by at most a quarter segment) to where the identified force has been
/// quiet for a few samples: a start state estimated just after an impact
/// carries the impulse's error (the impact happens between samples), one
/// estimated in free motion does not.
pub fn quiet_segments<F>(
    samples: usize,
    len: usize,
    force: &DMatrix<f64>,
    mut state: F,
) -> Result<Vec<Segment>>
where
    F: FnMut(usize) -> Result<(Vec<f64>, Vec<f64>)>,
{
    let nominal = shooting::uniform(samples, len, |_| Ok((vec![], vec![])))?;
    let level: Vec<f64> = (0..samples).map(|k| force.column(k).amax()).collect();
    let window = 4usize;
    let quiet = |k: usize| -> f64 {
        let a = k.saturating_sub(window);
        level[a..=k.min(samples - 1)]
            .iter()
            .copied()
            .fold(0.0, f64::max)
    };
    let mut starts = vec![0usize];
    for seg in nominal.iter().skip(1) {
        let b = seg.start;
        let r = len / 4;
        let lo = (b.saturating_sub(r)).max(starts.last().unwrap() + len / 2);
        let hi = (b + r).min(samples.saturating_sub(len / 2 + 1));
        let best = if lo <= hi {
            (lo..=hi)
                .min_by(|&x, &y| {
                    quiet(x)
                        .total_cmp(&quiet(y))
                        .then(x.abs_diff(b).cmp(&y.abs_diff(b)))
                })
                .unwrap_or(b)
        } else {
            b
        };
        starts.push(best);
    }
    starts.push(samples);
    let mut out = vec![];
    for w in starts.windows(2) {
        if w[1] > w[0] + 1 {
            let (u0, v0) = state(w[0])?;
            out.push(Segment {
                start: w[0],
                len: w[1] - w[0],
                u0,
                v0,
            });
        }
    }
    Ok(out)
}

/// Reconstruct states and the internal force with the full-horizon
/// smoother, an unknown force at every DOF.
pub fn reconstruct(
    sampled: &SampledModel,
    force: &DMatrix<f64>,
    measured: &DMatrix<f64>,
    channels: &[(Quantity, usize)],
    settings: &HorizonSettings,
) -> Result<Reconstruction> {
    let t = Instant::now();
    let n = sampled.n;
    let unknown = horizon::problem::unknown_at_dofs(n, &(0..n).collect::<Vec<_>>())?;
    let data = HorizonData {
        known_force: force,
        measured,
        channels,
        unknown: &unknown,
    };
    let res = horizon::identify(sampled, &data, settings)?;
    let mut status = format!(
        "full-horizon smoother, unknown force at every DOF: {:?}",
        res.status
    );
    if !res.notes.is_empty() {
        status = format!("{status}: {}", res.notes.join("; "));
    }
    Ok(Reconstruction {
        force: -&res.dof_force,
        force_std: res.force_std.clone(),
        states: res.states,
        lambda: res.weights.lambda,
        status,
        elapsed_s: t.elapsed().as_secs_f64(),
    })
}

/// One effect in the report.
#[derive(Debug, Clone, Serialize)]
pub struct EffectReport {
    /// `contact`, `friction`, `cubic`, `stiffness`, `ground_spring`, `damping`.
    pub kind: String,
    /// DOFs from 1 (contact `[i, j]`: on when `u_i − u_j` exceeds the gap).
    pub dofs: Vec<usize>,
    /// Label.
    pub label: String,
    /// Fitted parameters, SI (`gap` m, `stiffness` N/m, `level` N, `k3`
    /// N/m³, `delta` relative change).
    pub parameters: BTreeMap<String, f64>,
    /// Standard errors of the parameters (null when not determined).
    pub std_errors: BTreeMap<String, Option<f64>>,
    /// Parameters from the trace regression (the fit's start).
    pub traced: BTreeMap<String, f64>,
    /// Scores.
    pub score: Score,
}

/// How much an effect pays.
#[derive(Debug, Clone, Serialize)]
pub struct Score {
    /// Fraction of the remaining segment residual its regression removed.
    pub residual_explained: f64,
    /// BIC change of the regression (negative pays).
    pub bic_change: f64,
    /// Fraction of the identified force it explains.
    pub force_explained: Option<f64>,
    /// Multiple-shooting error before it was added.
    pub error_before: Option<f64>,
    /// Multiple-shooting error after it was added and fitted.
    pub error_after: Option<f64>,
}

/// One round of the loop.
#[derive(Debug, Clone, Serialize)]
pub struct Round {
    /// Effect proposed (None when none paid).
    pub proposed: Option<String>,
    /// Whether it was kept.
    pub kept: bool,
    /// Why the round ended as it did.
    pub note: String,
    /// Fit termination (if fitted).
    pub fit: Option<String>,
    /// Simulations spent by the fit.
    pub simulations: usize,
}

/// Errors on the validation record.
#[derive(Debug, Clone, Serialize)]
pub struct Validation {
    /// Declared model.
    pub before: ErrorSet,
    /// Fitted model.
    pub after: ErrorSet,
    /// Linear model driven by the force identified on the first record
    /// (non-parametric prediction), multiple-shooting error.
    pub nonparametric_relative_error: Option<f64>,
}

/// The result of [`diagnose`].
#[derive(Debug, Clone, Serialize)]
pub struct Diagnosis {
    /// "no missing effect found" or what was found.
    pub verdict: String,
    /// Declared model's errors.
    pub before: ErrorSet,
    /// Fitted model's errors.
    pub after: ErrorSet,
    /// On the validation record, when given.
    pub validation: Option<Validation>,
    /// Effects added, in order.
    pub effects: Vec<EffectReport>,
    /// Best candidates of the first trace round.
    pub ranking: Vec<RankedEffect>,
    /// The rounds of the loop.
    pub rounds: Vec<Round>,
    /// Sub-steps used before and after.
    pub substeps: (usize, usize),
    /// Nonlinear simulations run (fits and errors).
    pub simulations: usize,
    /// Linear segment simulations of the trace.
    pub trace_simulations: usize,
    /// Identification notes.
    pub identification: String,
    /// Timings, s.
    pub timings: BTreeMap<String, f64>,
    /// The calibration of the linear part and its corrections (None when
    /// the declared model was trusted).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub calibration: Option<calibrated::CalibrationReport>,
    /// The fitted model.
    #[serde(skip)]
    pub model: Model,
    /// The effects' parameter bookkeeping, in the order of `effects`.
    #[serde(skip)]
    pub added: Vec<AddedEffect>,
    /// Data of the first record (for figures).
    #[serde(skip)]
    pub prepared: Prepared,
    /// Segment predictions before and after (p × N).
    #[serde(skip)]
    pub predictions: (Option<DMatrix<f64>>, Option<DMatrix<f64>>),
}

/// Segment simulations spent by [`Comparison::shoot`]: the start-state
/// refinement's, or one per segment.
fn shot_simulations(starts: Option<&starts::StartFit>, cmp: &Comparison) -> usize {
    starts.map_or(cmp.segments.len(), |f| f.simulations)
}

/// Segment simulations spent by [`Comparison::errors`]: the multiple
/// shooting and the open-loop run.
fn error_simulations(set: &ErrorSet, cmp: &Comparison) -> usize {
    shot_simulations(set.starts.as_ref(), cmp) + 1
}

/// Pick up to `k` segments spread evenly over `all`.
fn spread(all: &[Segment], k: usize) -> Vec<Segment> {
    if all.len() <= k || k == 0 {
        return all.to_vec();
    }
    (0..k).map(|i| all[i * all.len() / k].clone()).collect()
}

/// Run the loop.
pub fn diagnose(
    declared: &Model,
    rec: &Record,
    validation: Option<&Record>,
    sensors: Option<&[usize]>,
    settings: &DiagnoseSettings,
    progress: &dyn Fn(&str),
) -> Result<Diagnosis> {
    let t_all = Instant::now();
    let mut timings = BTreeMap::new();
    progress("identify");
    let t = Instant::now();
    let st = setup(declared, rec, sensors, settings)?;
    let found = search(declared, &st, settings)?;
    let t_locate = t.elapsed().as_secs_f64();
    // the validation record is identified with the force directions
    // located on the record (the same structure; no second search), both
    // smoothers at once (each one a sequential sweep)
    let (prep, vprep) = rayon::join(
        || prepare_from(declared, st, settings, found.clone(), Instant::now()),
        || {
            validation
                .map(|v| prepare_located(declared, v, sensors, settings, found.as_ref()))
                .transpose()
        },
    );
    let (prep, vprep) = (prep?, vprep?);
    timings.insert("locate".into(), t_locate);
    timings.insert("identify".into(), t_locate + prep.recon.elapsed_s);
    if let Some(v) = &vprep {
        timings.insert("identify_validation".into(), v.recon.elapsed_s);
    }
    let cmp = &prep.comparison;
    let sim0 = resolved(declared, rec.fs, settings, &prep.recon.states);
    let base_sub = sim0.substeps;
    progress("errors before");
    let t = Instant::now();
    let (before, pred_before) = cmp.errors(declared, sim0);
    timings.insert("errors_before".into(), t.elapsed().as_secs_f64());
    let mut sims = error_simulations(&before, cmp);
    let measured = cmp.measured();
    let (cy, dy) = prep.sampled.outputs(&prep.channels)?;
    let mut current = declared.clone();
    let mut current_err = before.relative_error;
    let mut current_sub = base_sub;
    // the current model's own reconstruction (a spring to ground;
    // [`rescore_prep`]) and its multiple shooting, once an effect is kept
    let mut current_shot: Option<(Option<Prepared>, std::result::Result<errors::Shot, String>)> =
        None;
    let own_prep = |m: &Model, r: &Record| {
        rescore_prep(declared, m, r, sensors, settings, prep.located.as_ref())
    };
    let mut current_segments: Option<(Vec<Segment>, SimSettings)> = None;
    let mut baseline = if declared.is_nonlinear() {
        pred_before.clone()
    } else {
        None
    };
    let mut added: Vec<(AddedEffect, RankedEffect, Score)> = vec![];
    let mut rounds = vec![];
    let mut ranking = vec![];
    let mut trace_sims = 0;
    let located = prep.located.as_ref().map(|l| l.matrix(declared.ndof()));
    let t_loop = Instant::now();
    for round in 0..settings.max_effects {
        if current_err.is_some_and(|e| e <= settings.noise_floor) {
            rounds.push(Round {
                proposed: None,
                kept: false,
                note: format!(
                    "the model explains the record up to noise and integration error (multiple-shooting error {:.2} % ≤ {:.2} %)",
                    100.0 * current_err.unwrap_or(f64::NAN),
                    100.0 * settings.noise_floor
                ),
                fit: None,
                simulations: 0,
            });
            break;
        }
        progress(&format!("trace, round {}", round + 1));
        let exclude: Vec<_> = added.iter().map(|a| a.0.candidate.clone()).collect();
        let input = TraceInput {
            model: declared,
            sampled: &prep.sampled,
            cy: &cy,
            dy: &dy,
            measured: &measured,
            force_ext: &cmp.force,
            states: &prep.recon.states,
            identified_force: Some(&prep.recon.force),
            segment: prep.segment,
            baseline: baseline.as_ref(),
            exclude: &exclude,
            located: located.as_ref(),
        };
        let ts = TraceSettings {
            max_effects: 1,
            ..settings.trace
        };
        let t = Instant::now();
        let tr = trace::trace(&input, &ts);
        *timings.entry("trace".into()).or_insert(0.0) += t.elapsed().as_secs_f64();
        trace_sims += tr.simulations;
        if round == 0 {
            ranking = tr.ranking.iter().take(10).cloned().collect();
        }
        // below the screen's threshold, a linear change along the located
        // direction is still fitted once, jointly with the effects found:
        // a nonlinear effect's fit absorbs a linear change at the same
        // place (a bumper's gap and penalty stiffness trade against a
        // softer spring beside it), so the screen, run after that fit,
        // cannot see it; the fit decides whether it pays
        let companion = || {
            let dirs = located.as_ref().filter(|d| d.ncols() > 0)?;
            if added.iter().all(|a| a.0.candidate.kind.linear_in_state()) {
                return None;
            }
            // (a damping change acts along no single direction)
            tr.ranking
                .iter()
                .find(|e| {
                    e.candidate.kind.linear_in_state() && trace::acts_along(&e.candidate, dirs)
                })
                .cloned()
        };
        let screened = !tr.selected.is_empty();
        // below the screen, after a first effect: the companion, then the
        // best remaining candidate that lowers the BIC (the screen's
        // regression on the linear model's states can underrate a second
        // effect), each screened by the gain the joint linearization at
        // the current fit predicts for it
        let mut pool: Vec<RankedEffect> = vec![];
        match tr.selected.first() {
            Some(s) => pool.push(s.clone()),
            None => {
                pool.extend(companion());
                if !added.is_empty() {
                    let next = tr.ranking.iter().find(|e| {
                        e.bic_change < 0.0 && !pool.iter().any(|p| p.candidate == e.candidate)
                    });
                    pool.extend(next.cloned());
                }
            }
        }
        if pool.is_empty() {
            rounds.push(Round {
                proposed: None,
                kept: false,
                note: tr.stop_reason.clone(),
                fit: None,
                simulations: 0,
            });
            break;
        }
        let mut chosen = None;
        let screen = companion_screen(current_err, settings);
        let mut screened_out = vec![];
        let mut screen_sims = 0;
        let mut predicted = None;
        for best in pool {
            predicted = None;
            let mut trial = current.clone();
            let eff = effects::add(&mut trial, &best);
            let mut all: Vec<AddedEffect> = added.iter().map(|a| a.0.clone()).collect();
            all.push(eff.clone());
            // (a spring to ground on a free-free model is judged on states
            // reconstructed with it, [`rescore_prep`]: linearized on the
            // declared model's reconstruction its gain is not seen, and
            // with modal damping its derivative at zero is infinite; the
            // fit decides)
            let own = grounded(&trial) && !grounded(&current) && !grounded(declared);
            if !screened && !own {
                if let Some((segs, sim)) = current_segments.as_ref() {
                    let t = Instant::now();
                    let (g, n, at) = companion_gain(&trial, &all, cmp, segs, *sim);
                    screen_sims += n;
                    predicted = at;
                    *timings.entry("fit".into()).or_insert(0.0) += t.elapsed().as_secs_f64();
                    if g.is_some_and(|g| g < screen) {
                        screened_out.push(format!(
                            "{} {:.1} %",
                            best.label,
                            100.0 * g.unwrap_or(f64::NAN)
                        ));
                        continue;
                    }
                }
            }
            chosen = Some((best, trial, eff, all));
            break;
        }
        sims += screen_sims;
        let Some((best, trial, eff, all)) = chosen else {
            rounds.push(Round {
                proposed: None,
                kept: false,
                note: format!(
                    "not fitted: at the current fit, with the segment start states free, the candidates below the screen are predicted to remove {} of the fit cost (screen {:.0} %; below the screen: {})",
                    screened_out.join(", "),
                    100.0 * screen,
                    tr.stop_reason
                ),
                fit: None,
                simulations: screen_sims,
            });
            break;
        };
        progress(&format!("fit {}", best.label));
        // a trial with a spring to ground is fitted from states
        // reconstructed with its own linear part (as it is scored), not
        // from the declared reconstruction corrected along the hidden
        // trajectories
        let fit_trial = |trial: &Model,
                         all: &[AddedEffect],
                         correction: Option<&DMatrix<f64>>,
                         predicted: Option<&[Vec<f64>]>| {
            match &own_prep(trial, rec) {
                Some(o) => fit_effects(
                    trial,
                    all,
                    &o.comparison,
                    &o.recon.states,
                    None,
                    predicted,
                    rec.fs,
                    settings,
                ),
                None => fit_effects(
                    trial,
                    all,
                    cmp,
                    &prep.recon.states,
                    correction,
                    predicted,
                    rec.fs,
                    settings,
                ),
            }
        };
        // a model's multiple shooting (from its own reconstruction when it
        // needs one), the simulations run and the error on the record
        let shoot = |m: &Model, sim: SimSettings| {
            let own = own_prep(m, rec);
            let own_cmp = own.as_ref().map_or(cmp, |p| &p.comparison);
            let pred = own_cmp.shoot(m, sim);
            let n = shot_simulations(pred.as_ref().ok().and_then(|p| p.2.as_ref()), own_cmp);
            let err = pred.as_ref().ok().map(|y| cmp.total_error(&y.0));
            (own, pred, n, err)
        };
        // the effect's fit of the states along the hidden trajectories
        let correction = (!best.hidden.is_empty()).then(|| {
            let mut d = DMatrix::zeros(prep.recon.states.nrows(), prep.recon.states.ncols());
            for (c, e) in best.hidden.iter().zip(&tr.hidden) {
                d += e * *c;
            }
            d
        });
        let t = Instant::now();
        let EffectFit {
            model: mut fitted,
            mut note,
            simulations: fit_sims,
            fitted: mut fit_segs,
            stages,
        } = fit_trial(&trial, &all, correction.as_ref(), predicted.as_deref())?;
        sims += fit_sims;
        *timings.entry("fit".into()).or_insert(0.0) += t.elapsed().as_secs_f64();
        for (name, secs) in stages {
            *timings.entry(name.into()).or_insert(0.0) += secs;
        }
        let mut sim = resolved(&fitted, rec.fs, settings, &prep.recon.states);
        let (mut own, mut pred, n, mut new_err) = shoot(&fitted, sim);
        sims += n;
        let (mut best, mut eff) = (best, eff);
        // a large stiffness change left far from the noise: the cubic
        // spring on the same pair is fitted too, from the k3 whose
        // equivalent linearization is that change (the screen's regression
        // on states the sensors fix poorly can prefer the linear change)
        if let Some(alt) = cubic_alternative(&best, &eff, &fitted, &tr.ranking, &prep.recon.states)
            .filter(|_| {
                screened && new_err.is_some_and(|e| e > ALTERNATIVE_FLOOR * settings.noise_floor)
            })
        {
            progress(&format!("fit {} (alternative)", alt.label));
            let mut trial2 = current.clone();
            let eff2 = effects::add(&mut trial2, &alt);
            let mut all2: Vec<AddedEffect> = added.iter().map(|a| a.0.clone()).collect();
            all2.push(eff2.clone());
            let t = Instant::now();
            let f2 = fit_trial(&trial2, &all2, None, None)?;
            *timings.entry("fit".into()).or_insert(0.0) += t.elapsed().as_secs_f64();
            sims += f2.simulations;
            let sim2 = resolved(&f2.model, rec.fs, settings, &prep.recon.states);
            let (own2, pred2, n2, err2) = shoot(&f2.model, sim2);
            sims += n2;
            let taken = err2.is_some_and(|e2| new_err.is_none_or(|e| e2 < e));
            let line = format!(
                "{} fitted too, from {}: {}{}",
                alt.label,
                alt.parameters
                    .iter()
                    .map(|p| format!("{} {:.3e}", p.0, p.1))
                    .collect::<Vec<_>>()
                    .join(", "),
                err2.map_or("failed".into(), |e| format!("{:.2} %", 100.0 * e)),
                if taken { ", taken" } else { "" }
            );
            if taken {
                note = format!(
                    "{}; {line} instead of {} at {:.2} %",
                    f2.note,
                    best.label,
                    100.0 * new_err.unwrap_or(f64::NAN)
                );
                fitted = f2.model;
                fit_segs = f2.fitted;
                sim = sim2;
                own = own2;
                pred = pred2;
                new_err = err2;
                best = alt;
                eff = eff2;
            } else {
                note = format!("{note}; {line}");
            }
        }
        let sub = sim.substeps;
        // a change the screen did not propose must explain more
        let need = if screened {
            settings.min_improvement
        } else {
            settings.companion_improvement
        };
        // a candidate below the screen may only have let the effects found
        // be refitted: with it switched off in the fitted model (the
        // others as fitted), it must itself remove the same share of the
        // squared error
        let mut without_err = None;
        let mut off_shot = None;
        if !screened {
            let off = effects::remove(&fitted, &eff);
            let (off_prep, p0, n, w) = shoot(&off, sim);
            sims += n;
            without_err = w;
            off_shot = Some((off, off_prep, p0));
        }
        let negligible = match (without_err, new_err) {
            (Some(w), Some(b)) => b * b >= w * w * (1.0 - need),
            _ => false,
        };
        let pays = !negligible
            && match (current_err, new_err) {
                (Some(a), Some(b)) => b * b < a * a * (1.0 - need),
                (None, Some(_)) => true,
                _ => false,
            };
        let why = if screened {
            String::new()
        } else {
            let pre = if screened_out.is_empty() {
                String::new()
            } else {
                format!(
                    "; predicted below {:.0} %: {}",
                    100.0 * screen,
                    screened_out.join(", ")
                )
            };
            format!(
                " (below the screen: {}{pre}; fitted because the joint linearization predicts it removes at least {:.0} % of the fit cost)",
                tr.stop_reason,
                100.0 * screen
            )
        };
        rounds.push(Round {
            proposed: Some(best.label.clone()),
            kept: pays,
            note: if pays {
                format!(
                    "kept: multiple-shooting error {:.4} → {:.4}{why}",
                    current_err.unwrap_or(f64::NAN),
                    new_err.unwrap_or(f64::NAN)
                )
            } else if negligible {
                format!(
                    "withdrawn: switched off in the fitted model, the error is {:.4} against {:.4} with it: it does not itself remove {:.0} % of the squared error{why}",
                    without_err.unwrap_or(f64::NAN),
                    new_err.unwrap_or(f64::NAN),
                    100.0 * need
                )
            } else {
                format!(
                    "withdrawn: the fitted effect does not remove {:.0} % of the squared multiple-shooting error ({:.4} → {:.4}){why}",
                    100.0 * need,
                    current_err.unwrap_or(f64::NAN),
                    new_err.unwrap_or(f64::NAN)
                )
            },
            fit: Some(note),
            simulations: fit_sims,
        });
        if !pays {
            // the effects found, as refitted beside the withdrawn
            // candidate, are kept when they lower the error by the
            // screen's share on their own (the joint refit left the
            // earlier fit's local minimum)
            let better = match (negligible, without_err, current_err) {
                (true, Some(w), Some(a)) => w * w < a * a * (1.0 - settings.min_improvement),
                _ => false,
            };
            if let (true, Some((off, off_prep, shot))) = (better, off_shot) {
                if let Some(r) = rounds.last_mut() {
                    r.note = format!(
                        "{}; the effects found, as refitted beside it, are kept: multiple-shooting error {:.4} → {:.4}",
                        r.note,
                        current_err.unwrap_or(f64::NAN),
                        without_err.unwrap_or(f64::NAN)
                    );
                }
                current_segments = fit_segs;
                current = off;
                current_sub = sub;
                current_shot = Some((off_prep, shot));
            }
            break;
        }
        let score = Score {
            residual_explained: best.residual_explained,
            bic_change: best.bic_change,
            force_explained: best.force_explained,
            error_before: current_err,
            error_after: new_err,
        };
        added.push((eff, best, score));
        current_segments = fit_segs;
        current = fitted;
        current_err = new_err;
        current_sub = sub;
        baseline = pred.as_ref().ok().map(|p| p.0.clone());
        current_shot = Some((own, pred));
    }
    timings.insert("trace_and_fit".into(), t_loop.elapsed().as_secs_f64());
    progress("errors after");
    let sim1 = SimSettings {
        substeps: current_sub,
        ..Default::default()
    };
    let t = Instant::now();
    // the last kept round shot the final model at these settings already;
    // with no effect kept, the final model is the declared one, scored
    // before
    let (after, pred_after) = match current_shot.take() {
        Some((own, shot)) => {
            let own_cmp = own.as_ref().map_or(cmp, |p| &p.comparison);
            let (after, pred) = own_cmp.errors_of(&current, sim1, shot);
            sims += 1; // the open-loop run
            (after, pred)
        }
        None => (before.clone(), pred_before.clone()),
    };
    let effects = report_effects(
        &current,
        &added,
        cmp,
        sim1,
        current_segments.as_ref(),
        settings,
        &mut sims,
    );
    timings.insert("errors_after".into(), t.elapsed().as_secs_f64());
    let t = Instant::now();
    let validation = match vprep.as_ref() {
        Some(v) => {
            progress("validation");
            let own = validation.and_then(|r| own_prep(&current, r));
            Some(validate(
                declared,
                &current,
                v,
                own.as_ref(),
                &prep,
                (sim0, sim1),
                &mut sims,
            )?)
        }
        None => None,
    };
    if validation.is_some() {
        timings.insert("validation".into(), t.elapsed().as_secs_f64());
    }
    let verdict = verdict(&effects);
    timings.insert("total".into(), t_all.elapsed().as_secs_f64());
    Ok(Diagnosis {
        verdict,
        before,
        after,
        validation,
        effects,
        ranking,
        rounds,
        substeps: (base_sub, current_sub),
        simulations: sims,
        trace_simulations: trace_sims,
        identification: format!(
            "full-order model, λ = {:.3e}: {}",
            prep.recon.lambda, prep.recon.status
        ),
        timings,
        calibration: None,
        model: current,
        added: added.iter().map(|a| a.0.clone()).collect(),
        prepared: prep,
        predictions: (pred_before, pred_after),
    })
}

/// "no missing effect found" or "found ..." with the effects' labels.
pub fn verdict(effects: &[EffectReport]) -> String {
    if effects.is_empty() {
        "no missing effect found".to_string()
    } else {
        format!(
            "found {}",
            effects
                .iter()
                .map(|e| e.label.clone())
                .collect::<Vec<_>>()
                .join(", ")
        )
    }
}

/// True when `model` has a spring from a DOF to ground.
fn grounded(model: &Model) -> bool {
    model.springs.iter().any(|s| s.dofs.len() == 1)
}

/// The record prepared again for scoring `model` when it has a spring to
/// ground and the declared model has none: the states are then
/// reconstructed with `model`'s linear part (the directions located
/// before), in which the absolute position the declared free-free model
/// left to its prior drives a force and is seen. From the declared model's
/// reconstruction the exact model of a contact with a ground spring scored
/// 73 %; from its own, 3.7 %. None otherwise (or when it fails: then the
/// declared model's reconstruction is used).
fn rescore_prep(
    declared: &Model,
    model: &Model,
    rec: &Record,
    sensors: Option<&[usize]>,
    settings: &DiagnoseSettings,
    located: Option<&locate::Located>,
) -> Option<Prepared> {
    if grounded(declared) || !grounded(model) {
        return None;
    }
    prepare_located(model, rec, sensors, settings, located).ok()
}

/// Gap and stiffness starts of a contact (of a clearance: `ci` indexes
/// `model.clearances` and the gaps are taken on `|δ|`) from a scan of the
/// multiple-shooting error with the nonlinear model (CONTEXT fact 6: the
/// cost is rough in the gap): gaps at upper quantiles of the reconstructed
/// relative displacement, stiffnesses at multiples of the stiffest spring
/// the pair touches. Returns the two best (gap, stiffness) pairs and the
/// evaluations spent.
fn scan_contact(
    trial: &Model,
    ci: usize,
    cand: &crate::trace::Candidate,
    states: &DMatrix<f64>,
    cmp: &Comparison,
    segments: &[Segment],
    settings: &DiagnoseSettings,
) -> (Vec<(f64, f64)>, usize) {
    const KEEP: usize = 2;
    let fs = cmp.fs;
    // a clearance: its gap on |δ|, its own entry
    let two_sided = cand.kind == EffectKind::Clearance;
    let dofs = if two_sided {
        &trial.clearances[ci].dofs
    } else {
        &trial.contacts[ci].dofs
    };
    let mut d: Vec<f64> = (0..states.ncols())
        .map(|k| cand.delta(states, k))
        .map(|x| if two_sided { x.abs() } else { x })
        .collect();
    d.sort_by(f64::total_cmp);
    let q = |f: f64| d[((d.len() - 1) as f64 * f) as usize].max(0.0);
    let kspring = trial
        .springs
        .iter()
        .filter(|s| s.dofs.contains(&dofs[0]) || dofs.get(1).is_some_and(|j| s.dofs.contains(j)))
        .map(|s| s.stiffness)
        .fold(0.0, f64::max)
        .max(1.0);
    let mut scored = vec![];
    let mut evals = 0;
    for &kc in &[10.0 * kspring, 40.0 * kspring] {
        for f in [0.8, 0.88, 0.93, 0.96, 0.98, 0.99, 0.995] {
            let g = q(f);
            let mut m = trial.clone();
            if two_sided {
                m.clearances[ci].gap = g;
                m.clearances[ci].stiffness = kc;
            } else {
                m.contacts[ci].gap = g;
                m.contacts[ci].stiffness = kc;
            }
            let sim = resolved(&m, fs, settings, states);
            evals += 1;
            if let Ok(y) = cmp.predict(&m, segments, sim) {
                scored.push((cmp.total_error(&y), g, kc));
            }
        }
    }
    scored.sort_by(|a, b| a.0.total_cmp(&b.0));
    // distinct pairs only (upper quantiles of a sparse impact history can
    // coincide)
    let mut best: Vec<(f64, f64)> = vec![];
    for (_, g, kc) in scored {
        if best.len() < KEEP && !best.contains(&(g, kc)) {
            best.push((g, kc));
        }
    }
    (best, evals)
}

/// A candidate below the screen (a companion linear change, or the best
/// remaining one) predicted to remove less than this fraction of the fit
/// cost is not fitted...
const COMPANION_SCREEN: f64 = 0.2;

/// ...unless the multiple-shooting error is still above this multiple of
/// the noise floor ([`DiagnoseSettings::noise_floor`]): a model that far
/// from the record is worth a fit for a smaller predicted gain (a contact
/// fitted alone absorbs a softer spring beside it, and the linearization
/// at that fit underrates the spring: 18.9 % predicted at an error of
/// 25 %, which the fit of both brings to 1.2 %).
const FAR_FROM_NOISE: f64 = 4.0;

/// The screen far from the noise floor.
const COMPANION_SCREEN_FAR: f64 = 0.05;

/// The companion screen at multiple-shooting error `err`.
fn companion_screen(err: Option<f64>, settings: &DiagnoseSettings) -> f64 {
    if err.is_some_and(|e| e > FAR_FROM_NOISE * settings.noise_floor) {
        COMPANION_SCREEN_FAR
    } else {
        COMPANION_SCREEN
    }
}

/// The fraction of the fit cost a candidate below the screen (the last
/// effect of `all` on `trial`, taken at no change: a spring at its declared
/// stiffness, a nonlinear element at zero strength with its traced gap) is
/// predicted to remove at the current fit
/// ([`joint::predicted_gain`] on the fit segments `segs`, with the fit's
/// sub-steps), and the simulations spent; None when it cannot be
/// computed.
fn companion_gain(
    trial: &Model,
    all: &[AddedEffect],
    cmp: &Comparison,
    segs: &[Segment],
    sim: SimSettings,
) -> (Option<f64>, usize, Option<Vec<Vec<f64>>>) {
    let mut params = vec![];
    let mut extra = 0;
    for e in all {
        match effects::parameters(trial, e) {
            Ok(p) => {
                extra = p.len();
                params.extend(p);
            }
            Err(_) => return (None, 0, None),
        }
    }
    let Some(last) = all.last() else {
        return (None, 0, None);
    };
    let mut problem = cmp.problem(trial, segs.to_vec(), sim);
    problem.parameters = params;
    // linearized where the candidate is no change at all (the traced
    // value is only the screen's estimate)
    let mut x = problem.x_start();
    let zero = match last.candidate.kind {
        EffectKind::GroundSpring => 0.0,
        _ => last.nominal,
    };
    for (xi, p) in x.iter_mut().zip(&problem.parameters).rev().take(extra) {
        // a contact is switched off by its stiffness; its gap stays where
        // the trace put it
        if !matches!(
            p.target,
            crate::update::Target::ContactGap(_) | crate::update::Target::ClearanceGap(_)
        ) {
            *xi = p.to_x(zero);
        }
    }
    match joint::predicted_gain(&problem, &x, extra) {
        Some((g, dx, n)) => {
            // the Gauss–Newton step's parameter values: a start for the
            // fit (the trace's value of a companion comes from a
            // regression on states the effects found already absorb it in)
            let (lo, hi) = problem.x_bounds();
            let at = GN_STRIDES
                .iter()
                .map(|f| {
                    problem
                        .parameters
                        .iter()
                        .enumerate()
                        .map(|(i, p)| p.from_x((x[i] + f * dx[i]).clamp(lo[i], hi[i])))
                        .collect()
                })
                .collect();
            (Some(g), n, Some(at))
        }
        None => (None, 0, None),
    }
}

/// Iterations each start of a multistart fit gets before the best goes on.
const RACE_ITERATIONS: usize = 6;

/// A traced value of zero cannot be scaled relatively (a contact traced
/// to switch on at zero gap, or with zero stiffness; a friction level or
/// a spring of zero): such a value starts the fit at a small positive one
/// instead — a gap of 5 % of the largest reconstructed relative
/// displacement, 10× the stiffest spring at the pair, 0.1 % of the largest
/// applied force, 0.1 % of the stiffest spring.
fn floor_start(model: &mut Model, e: &AddedEffect, states: &DMatrix<f64>, force: &DMatrix<f64>) {
    use crate::update::Target;
    let stiffest = |m: &Model, dofs: &[usize]| {
        m.springs
            .iter()
            .filter(|s| dofs.iter().any(|d| s.dofs.contains(&(d + 1))))
            .map(|s| s.stiffness)
            .fold(0.0, f64::max)
            .max(1.0)
    };
    for &t in &e.targets {
        let v = t.get(model).unwrap_or(0.0);
        if v != 0.0 && v.is_finite() {
            continue;
        }
        let dofs = &e.candidate.dofs;
        let floor = match t {
            Target::ContactGap(_) => {
                let dmax = (0..states.ncols())
                    .map(|k| e.candidate.delta(states, k))
                    .fold(0.0, f64::max);
                (0.05 * dmax).max(1e-9)
            }
            Target::ContactStiffness(_) => 10.0 * stiffest(model, dofs),
            Target::FrictionLevel(_) => (1e-3 * force.amax()).max(1e-9),
            Target::SpringStiffness(_) => 1e-3 * stiffest(model, dofs),
            _ => continue,
        };
        t.set(model, floor);
    }
}

/// The fit of the added effects.
struct EffectFit {
    /// The model with the fitted values.
    model: Model,
    /// How the fit ended.
    note: String,
    /// Segment simulations spent.
    simulations: usize,
    /// The fit segments with their fitted start states, and the
    /// simulation settings of the fit (None when no start was carried on).
    fitted: Option<(Vec<Segment>, SimSettings)>,
    /// Seconds spent in the contact scan, the race and the polish.
    stages: [(&'static str, f64); 3],
}

/// Fit the parameters of all added effects jointly.
#[allow(clippy::too_many_arguments)]
fn fit_effects(
    trial: &Model,
    all: &[AddedEffect],
    cmp: &Comparison,
    states: &DMatrix<f64>,
    correction: Option<&DMatrix<f64>>,
    predicted: Option<&[Vec<f64>]>,
    fs: f64,
    settings: &DiagnoseSettings,
) -> Result<EffectFit> {
    let mut floored = trial.clone();
    for e in all {
        floor_start(&mut floored, e, states, &cmp.force);
    }
    let trial = &floored;
    let mut params = vec![];
    for e in all {
        params.extend(effects::parameters(trial, e)?);
    }
    let mut segments = spread(&cmp.segments, settings.fit_segments);
    let corrected;
    let states = match correction {
        Some(d) => {
            let n = trial.ndof();
            for s in &mut segments {
                for i in 0..n {
                    s.u0[i] += d[(i, s.start)];
                    s.v0[i] += d[(n + i, s.start)];
                }
            }
            corrected = states + d;
            &corrected
        }
        None => states,
    };
    let mut problem = cmp.problem(trial, segments.clone(), SimSettings::default());
    problem.parameters = params;
    let np = problem.parameters.len();
    let mut starts = vec![vec![0.0; np]];
    // the joint linearization's step at the current fit, when the effect
    // came in on its predicted gain ([`companion_gain`])
    for at in predicted.unwrap_or_default() {
        push_start(&mut starts, &problem.parameters, at);
    }
    let mut sims = 0;
    let mut stages = [("fit_scan", 0.0), ("fit_race", 0.0), ("fit_polish", 0.0)];
    let mut stiffest = trial.clone();
    // a cubic spring: the segment error has local minima in k3 (the
    // traced value comes from linear-model states), so two more starts
    // bracket it
    if let Some(last) = all.last() {
        if last.candidate.kind == EffectKind::Cubic {
            let p = &problem.parameters[np - 1];
            let k3 = trial.cubics[trial.cubics.len() - 1].k3;
            for f in [0.6, 1.6] {
                let mut s = vec![0.0; np];
                s[np - 1] = p.to_x((k3 * f).clamp(p.lower, p.upper));
                starts.push(s);
            }
            let c = stiffest.cubics.len() - 1;
            stiffest.cubics[c].k3 = k3 * 1.6;
        }
    }
    // a clearance: starts from the same scan, on |δ|
    if let Some(last) = all
        .last()
        .filter(|l| l.candidate.kind == EffectKind::Clearance)
    {
        let ci = trial.clearances.len() - 1;
        let t = Instant::now();
        let (best, evals) =
            scan_contact(trial, ci, &last.candidate, states, cmp, &segments, settings);
        sims += evals * segments.len();
        stages[0].1 += t.elapsed().as_secs_f64();
        let (pg, pk) = (&problem.parameters[np - 2], &problem.parameters[np - 1]);
        for (g, kc) in best {
            let mut s = vec![0.0; np];
            s[np - 2] = pg.to_x(g.clamp(pg.lower, pg.upper));
            s[np - 1] = pk.to_x(kc.clamp(pk.lower, pk.upper));
            if !starts.contains(&s) {
                starts.push(s);
                let c = &mut stiffest.clearances[ci];
                c.stiffness = c.stiffness.max(kc);
            }
        }
    }
    // a contact: starts from a scan of gap and stiffness (CONTEXT fact 6)
    if let Some(last) = all.last() {
        if last.candidate.kind == EffectKind::Contact {
            let ci = trial.contacts.len() - 1;
            // the gap may lie anywhere below the largest reconstructed
            // relative displacement (beyond it the contact never closes),
            // not only within 3× the traced value: a traced gap from a
            // few sensors can be a third of the truth
            let dmax = (0..states.ncols())
                .map(|k| last.candidate.delta(states, k))
                .fold(0.0, f64::max);
            let pg = &mut problem.parameters[np - 2];
            pg.upper = pg.upper.max(1.2 * dmax);
            let t = Instant::now();
            let (best, evals) =
                scan_contact(trial, ci, &last.candidate, states, cmp, &segments, settings);
            sims += evals * segments.len();
            stages[0].1 += t.elapsed().as_secs_f64();
            let (pg, pk) = (&problem.parameters[np - 2], &problem.parameters[np - 1]);
            for (g, kc) in best {
                let mut s = vec![0.0; np];
                s[np - 2] = pg.to_x(g.clamp(pg.lower, pg.upper));
                s[np - 1] = pk.to_x(kc.clamp(pk.lower, pk.upper));
                if starts.contains(&s) {
                    continue;
                }
                starts.push(s);
                if kc > stiffest.contacts[ci].stiffness {
                    stiffest.contacts[ci].stiffness = kc;
                }
            }
        }
    }
    // a change linear in the state beside a contact found before: the
    // contact's gap and stiffness scanned again with the change at the
    // farthest predicted value, or at its start (the contact fitted alone
    // took up part of it)
    let start_values: Vec<f64> = problem.parameters.iter().map(|p| p.start).collect();
    let far = predicted.and_then(|p| p.last()).unwrap_or(&start_values);
    if let Some(last) = all.last() {
        let contact = all[..all.len() - 1]
            .iter()
            .rev()
            .find(|e| e.candidate.kind == EffectKind::Contact);
        let slot = |t: crate::update::Target| problem.parameters.iter().position(|p| p.target == t);
        if let (true, Some(c), true) = (
            last.candidate.kind.linear_in_state(),
            contact,
            far.len() == np,
        ) {
            let ci = c.targets.iter().find_map(|t| match t {
                crate::update::Target::ContactGap(i) => Some(*i),
                _ => None,
            });
            if let Some(ci) = ci {
                let (ig, ik) = (
                    slot(crate::update::Target::ContactGap(ci)),
                    slot(crate::update::Target::ContactStiffness(ci)),
                );
                if let (Some(ig), Some(ik)) = (ig, ik) {
                    let mut at = trial.clone();
                    for (p, &v) in problem.parameters.iter().zip(far) {
                        p.target.set(&mut at, v);
                    }
                    let t = Instant::now();
                    let (best, evals) =
                        scan_contact(&at, ci, &c.candidate, states, cmp, &segments, settings);
                    sims += evals * segments.len();
                    stages[0].1 += t.elapsed().as_secs_f64();
                    for (g, kc) in best {
                        let mut v = far.to_vec();
                        v[ig] = g;
                        v[ik] = kc;
                        push_start(&mut starts, &problem.parameters, &v);
                        if kc > stiffest.contacts[ci].stiffness {
                            stiffest.contacts[ci].stiffness = kc;
                        }
                    }
                }
            }
        }
    }
    problem.sim = resolved(&stiffest, fs, settings, states);
    let sub = problem.sim.substeps;
    // the starts race: a few iterations each from the reconstructed start
    // states; the joint fit below carries the best one on
    let race = FitSettings {
        max_iterations: settings.fit.max_iterations.min(RACE_ITERATIONS),
        ..settings.fit
    };
    let t = Instant::now();
    let (_, results) = crate::update::fit_multistart(&problem, &race, &starts)?;
    sims += results.iter().map(|r| r.simulations).sum::<usize>();
    stages[1].1 += t.elapsed().as_secs_f64();
    let t = Instant::now();
    // the race's starts, best first
    let mut order: Vec<usize> = (0..results.len())
        .filter(|&i| results[i].cost().is_finite())
        .collect();
    order.sort_by(|&a, &b| results[a].cost().total_cmp(&results[b].cost()));
    let floor = noise_cost(cmp, &problem.segments, settings.fit.noise_level);
    let mut kept: Option<Polished> = None;
    for (tries, &i) in order.iter().enumerate() {
        // a second start only when the first ends far above the noise
        if tries >= POLISH_STARTS
            || kept
                .as_ref()
                .is_some_and(|k| k.cost <= NOISE_MARGIN * floor)
        {
            break;
        }
        let r = &results[i];
        let beat = kept.as_ref().map(|k| k.cost);
        let mut p = polish(cmp, &problem, &r.x, r.cost(), settings, beat);
        sims += p.simulations;
        p.note = format!(
            "start {} of {} carried on after a {}-iteration race ({:?}; {} sub-steps){}",
            i + 1,
            starts.len(),
            r.iterations,
            r.termination,
            sub,
            p.note
        );
        if kept.as_ref().is_none_or(|k| p.cost < k.cost) {
            kept = Some(p);
        }
    }
    // (no start with a finite cost: none was carried on)
    let Some(k) = kept else {
        return Ok(EffectFit {
            model: trial.clone(),
            note: "every start failed; traced values kept".into(),
            simulations: sims,
            fitted: None,
            stages,
        });
    };
    stages[2].1 += t.elapsed().as_secs_f64();
    Ok(EffectFit {
        model: k.model,
        note: k.note,
        simulations: sims,
        fitted: Some((k.segments, problem.sim)),
        stages,
    })
}

/// Add the start at parameter `values` (clamped to the bounds, scaled)
/// unless it is there already, has the wrong length or is not finite.
fn push_start(starts: &mut Vec<Vec<f64>>, params: &[crate::update::Parameter], values: &[f64]) {
    if values.len() != params.len() {
        return;
    }
    let s: Vec<f64> = params
        .iter()
        .zip(values)
        .map(|(p, &v)| p.to_x(v.clamp(p.lower, p.upper)))
        .collect();
    if s.iter().all(|v| v.is_finite()) && !starts.contains(&s) {
        starts.push(s);
    }
}

/// Multiples of the joint linearization's parameter step that start the
/// fit of an effect taken in on its predicted gain: a companion of an
/// effect found before trades against it (a softer spring beside a
/// bumper whose stiffness took up part of it), and the step from the
/// current fit, linearized, falls short along that valley.
const GN_STRIDES: [f64; 3] = [1.0, 2.0, 3.0];

/// A screened effect leaving the error above this multiple of the noise
/// floor may be replaced by the cubic spring at its place, a cubic spring
/// by the clearance ([`cubic_alternative`]).
const ALTERNATIVE_FLOOR: f64 = 4.0;

/// The cubic spring on the pair of a stiffness change of more than 50 %,
/// with the k3 whose equivalent linearization `3 k3 ⟨δ²⟩` (δ the
/// reconstructed relative displacement) is the fitted change; None for any
/// other effect or when the trace did not rank that cubic.
fn cubic_alternative(
    best: &RankedEffect,
    eff: &AddedEffect,
    fitted: &Model,
    ranking: &[RankedEffect],
    states: &DMatrix<f64>,
) -> Option<RankedEffect> {
    if best.candidate.kind == EffectKind::Cubic {
        return effects::clearance_alternative(best, ranking);
    }
    if best.candidate.kind != EffectKind::Stiffness || best.candidate.dofs.len() != 2 {
        return None;
    }
    let delta = effects::values(fitted, eff)
        .into_iter()
        .find(|v| v.0 == "delta")?
        .1;
    if !(delta.abs() > 0.5) {
        return None;
    }
    let mut alt = ranking
        .iter()
        .find(|e| {
            e.candidate.kind == EffectKind::Cubic && {
                let (mut a, mut b) = (e.candidate.dofs.clone(), best.candidate.dofs.clone());
                a.sort_unstable();
                b.sort_unstable();
                a == b
            }
        })?
        .clone();
    let ns = states.ncols().max(1);
    let msq = (0..states.ncols())
        .map(|k| best.candidate.delta(states, k).powi(2))
        .sum::<f64>()
        / ns as f64;
    let k3 = delta * eff.nominal / (3.0 * msq.max(f64::MIN_POSITIVE));
    if !(k3.is_finite() && k3 > 0.0) {
        return None;
    }
    for p in alt.parameters.iter_mut().filter(|p| p.0 == "k3") {
        p.1 = k3;
    }
    Some(alt)
}

/// Race starts carried on by [`polish`] at most.
const POLISH_STARTS: usize = 2;

/// A polished fit ending below this multiple of the noise cost is not
/// tried from another start.
const NOISE_MARGIN: f64 = 10.0;

/// The cost white noise of `level` times each channel's RMS would leave
/// on `segments` ([`Observation::noise_std`] per residual row).
fn noise_cost(cmp: &Comparison, segments: &[Segment], level: f64) -> f64 {
    let covered: usize = segments.iter().map(|s| s.len).sum();
    let per_sample: f64 = cmp
        .observations
        .iter()
        .map(|o| o.noise_std(level).powi(2))
        .sum();
    per_sample * covered as f64
}

/// A race result carried on.
struct Polished {
    model: Model,
    cost: f64,
    segments: Vec<Segment>,
    note: String,
    simulations: usize,
}

/// Carry a race result on (scaled parameters `x0` at cost `cost0`, on
/// `base`'s segments): the start states the race used were
/// reconstructed with the linear model, so refine them for the fitted
/// model (continuity starts and Gauss–Newton, [`starts::refine`]), then fit
/// the parameters and the start states together ([`joint::fit`]); segments
/// left far above the others are run in from the segment before
/// ([`starts::run_in`]); again while that lowers the cost by 1 % or a
/// run-in took, and while the cost is below twice `beat` (the cost of a
/// start already carried on).
fn polish(
    cmp: &Comparison,
    base: &crate::update::Problem,
    x0: &[f64],
    cost0: f64,
    settings: &DiagnoseSettings,
    beat: Option<f64>,
) -> Polished {
    let mut problem = base.clone();
    let mut model = problem.model_at(x0);
    let mut x = x0.to_vec();
    let mut cost = cost0;
    let mut sims = 0;
    let mut rounds = 0;
    let mut tried = vec![false; problem.segments.len()];
    let mut run_ins = 0;
    while cmp.start_iterations > 0 && rounds < settings.start_alternations {
        rounds += 1;
        let (segs, _, sf) = starts::refine(
            cmp,
            &model,
            problem.sim,
            &problem.segments,
            cmp.start_iterations,
        );
        sims += sf.simulations;
        problem.segments = segs;
        let Some(j) = joint::fit(&problem, &x, &settings.fit) else {
            break;
        };
        sims += j.simulations;
        model = problem.model_at(&j.x);
        x = j.x;
        problem.segments = j.segments;
        let gain = 1.0 - j.cost.1 / cost;
        // what the joint fit itself gained: once it finds nothing to add
        // to the refined start states, another refinement from its end
        // does not either (measured on the main job: 1e-4 of the cost)
        let joint_gain = 1.0 - j.cost.1 / j.cost.0;
        cost = j.cost.1;
        // a segment far above the others is likely started in a wrong
        // basin: run it in from the segment before it
        let picks = starts::outliers(&j.segment_costs, &tried)
            .into_iter()
            .filter_map(|i| {
                tried[i] = true;
                let start = problem.segments[i].start;
                let k = cmp.segments.iter().position(|s| s.start == start)?;
                let before = cmp.segments.get(k.checked_sub(1)?)?.clone();
                Some((i, before, j.segment_costs[i]))
            })
            .collect::<Vec<_>>();
        let (changed, n) = starts::run_in(
            cmp,
            &model,
            problem.sim,
            &mut problem.segments,
            &picks,
            cmp.start_iterations,
        );
        sims += n;
        run_ins += changed.len();
        if (!(gain > 0.01) || !(joint_gain > joint::STALL_GAIN)) && changed.is_empty() {
            break;
        }
        // a second start that stays well above the first is given up
        if beat.is_some_and(|b| cost > 2.0 * b) {
            break;
        }
    }
    let mut note = String::new();
    if run_ins > 0 {
        note = format!("{note}; {run_ins} segments run in from the one before");
    }
    if rounds > 0 {
        note = format!(
            "{note}; {rounds} rounds of start-state refinement and joint fit of parameters and start states (cost {cost:.4e})"
        );
    }
    Polished {
        model,
        cost,
        segments: problem.segments,
        note,
        simulations: sims,
    }
}

/// Effect reports with fitted values and standard errors: from the joint
/// Jacobian of the fit's multiple-shooting residual in the parameters and
/// start states when the fit's segments are given (the states as nuisance
/// parameters), else from the parameter Jacobian with the reconstructed
/// start states.
fn report_effects(
    model: &Model,
    added: &[(AddedEffect, RankedEffect, Score)],
    cmp: &Comparison,
    sim: SimSettings,
    fitted: Option<&(Vec<Segment>, SimSettings)>,
    settings: &DiagnoseSettings,
    sims: &mut usize,
) -> Vec<EffectReport> {
    let mut ses: BTreeMap<(usize, usize), f64> = BTreeMap::new();
    if !added.is_empty() {
        let mut params = vec![];
        let mut owner = vec![];
        for (ei, (e, _, _)) in added.iter().enumerate() {
            if let Ok(ps) = effects::parameters(model, e) {
                for (pi, p) in ps.into_iter().enumerate() {
                    params.push(p);
                    owner.push((ei, pi));
                }
            }
        }
        // with the fit's segments and start states: the start states are
        // nuisance parameters of the same fit ([`joint::std_errors`])
        let joint = fitted.and_then(|(segs, fsim)| {
            let mut problem = cmp.problem(model, segs.clone(), *fsim);
            problem.parameters = params.clone();
            *sims += segs.len();
            let x = vec![0.0; problem.parameters.len()];
            joint::std_errors(&problem, &x, settings.fit.noise_level)
        });
        match joint {
            Some(sd) => {
                for (k, v) in sd.into_iter().enumerate() {
                    if let Some(&o) = owner.get(k) {
                        ses.insert(o, v);
                    }
                }
            }
            None => {
                let segs = spread(&cmp.segments, settings.fit_segments);
                let mut problem = cmp.problem(model, segs, sim);
                problem.parameters = params;
                let fs_ = FitSettings {
                    max_iterations: 1,
                    ..settings.fit
                };
                if let Ok(r) = crate::update::fit(&problem, &fs_) {
                    *sims += r.simulations;
                    if let Some(id) = &r.identifiability {
                        for (k, pid) in id.parameters.iter().enumerate() {
                            if let Some(&o) = owner.get(k) {
                                ses.insert(o, pid.std_value);
                            }
                        }
                    }
                }
            }
        }
    }
    added
        .iter()
        .enumerate()
        .map(|(ei, (e, r, score))| {
            let vals = effects::values(model, e);
            let mut std_errors = BTreeMap::new();
            for (pi, (name, _)) in vals.iter().enumerate() {
                let se = ses.get(&(ei, pi)).copied().filter(|x| x.is_finite());
                let se = match e.candidate.kind {
                    EffectKind::Stiffness if e.nominal != 0.0 => se.map(|s| s / e.nominal),
                    _ => se,
                };
                std_errors.insert(name.clone(), se);
            }
            EffectReport {
                kind: e.candidate.kind.name().to_string(),
                dofs: e.candidate.dofs.iter().map(|d| d + 1).collect(),
                label: e.label.clone(),
                parameters: vals.into_iter().collect(),
                std_errors,
                traced: r.parameters.iter().cloned().collect(),
                score: score.clone(),
            }
        })
        .collect()
}

/// Errors on a validation record, and the non-parametric prediction.
fn validate(
    declared: &Model,
    fitted: &Model,
    prep: &Prepared,
    own: Option<&Prepared>,
    first: &Prepared,
    sims: (SimSettings, SimSettings),
    count: &mut usize,
) -> Result<Validation> {
    let cmp = &prep.comparison;
    let (before, _) = cmp.errors(declared, sims.0);
    // the fitted model from its own reconstruction when it needs one
    let cmp_after = own.map_or(cmp, |p| &p.comparison);
    let (after, _) = cmp_after.errors(fitted, sims.1);
    *count += error_simulations(&before, cmp) + error_simulations(&after, cmp_after);
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
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::trace::Candidate;

    fn ranked(c: Candidate, parameters: Vec<(&str, f64)>) -> RankedEffect {
        RankedEffect {
            label: c.label(),
            candidate: c,
            parameters: parameters.into_iter().map(|(n, v)| (n.into(), v)).collect(),
            std_errors: vec![],
            residual_explained: 0.3,
            force_explained: None,
            bic_change: -100.0,
            hidden: vec![],
        }
    }

    /// The cubic alternative of a large stiffness change: `k3` from the
    /// equivalent linearization `3 k3 ⟨δ²⟩ = Δk`; none for a small change.
    #[test]
    fn a_large_stiffness_change_offers_the_cubic_with_its_equivalent_k3() {
        let p = concat!(env!("CARGO_MANIFEST_DIR"), "/data/lanl8dof.toml");
        let model = Model::from_file(std::path::Path::new(p)).unwrap();
        let k0 = model.springs[6].stiffness;
        let mut stiff = Candidate::new(EffectKind::Stiffness, vec![6, 7]);
        stiff.spring = Some(6);
        stiff.nominal = k0;
        let cubic = ranked(
            Candidate::new(EffectKind::Cubic, vec![7, 6]),
            vec![("k3", 1.0)],
        );
        // relative displacement u7 − u8 alternating ±2e-4 m: ⟨δ²⟩ = 4e-8
        let states = DMatrix::from_fn(16, 100, |i, k| match i {
            6 => {
                if k % 2 == 0 {
                    2e-4
                } else {
                    -2e-4
                }
            }
            _ => 0.0,
        });
        for (delta, expect) in [(2.0, true), (0.3, false), (-0.8, false)] {
            let best = ranked(stiff.clone(), vec![("delta", delta)]);
            let mut fitted = model.clone();
            let eff = effects::add(&mut fitted, &best);
            let got =
                cubic_alternative(&best, &eff, &fitted, std::slice::from_ref(&cubic), &states);
            assert_eq!(got.is_some(), expect, "delta {delta}");
            if let Some(alt) = got {
                assert_eq!(alt.candidate.kind, EffectKind::Cubic);
                let k3 = alt.parameters.iter().find(|p| p.0 == "k3").unwrap().1;
                let want = delta * k0 / (3.0 * 4e-8);
                assert!((k3 / want - 1.0).abs() < 1e-9, "{k3} vs {want}");
            }
        }
        // not for another kind
        let contact = ranked(
            Candidate::new(EffectKind::Contact, vec![6, 7]),
            vec![("gap", 1e-4), ("stiffness", 1e6)],
        );
        let mut fitted = model.clone();
        let eff = effects::add(&mut fitted, &contact);
        assert!(cubic_alternative(&contact, &eff, &fitted, &[cubic], &states).is_none());
    }
}
