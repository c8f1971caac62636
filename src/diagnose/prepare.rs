//! Prepare a record for the loop: check it, choose the channels, locate
//! the missing force's directions ([`super::locate`]), reconstruct the
//! states and force ([`super::lifted`] along the located directions, or
//! [`crate::horizon`] with a force at every DOF), and cut the segments of
//! the multiple-shooting error.

use super::errors::Comparison;
use super::noise::{self, NoiseEstimate, NoiseInput, NoiseStatus};
use super::{lifted, locate, DiagnoseSettings, StatesSource};
use crate::error::{Result, TacitError};
use crate::horizon::{self, problem::HorizonData, settings::HorizonSettings};
use crate::linear::SampledModel;
use crate::model::Model;
use crate::record::{Quantity, Record};
use crate::update::problem::Observation;
use crate::update::shooting::{self, Segment};
use nalgebra::DMatrix;
use std::collections::BTreeMap;
use std::time::Instant;

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
    let segment = ((settings.segments.seconds * rec.fs).round() as usize).max(4);
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
    let sampled = SampledModel::from_model(&model.linear_part(), rec.fs, settings.substeps.base)?;
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
        && settings.locate.ratio > 0.0
        && settings.locate.max > 0
    {
        Ok(Some(locate::locate(
            model,
            &s.sampled,
            &s.force,
            &s.measured,
            &s.channels,
            &settings.lifted_settings(),
            &settings.locate,
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
    let Setup {
        rec,
        outs,
        segment,
        channels,
        force,
        measured,
        sampled,
    } = st;
    let (mut recon, located) = if settings.states == StatesSource::Lifted {
        let r = reconstruct_lifted(
            &sampled,
            &force,
            &measured,
            &channels,
            settings,
            loc.as_ref(),
        )?;
        let recon = Reconstruction {
            elapsed_s: t.elapsed().as_secs_f64(),
            ..r
        };
        (recon, loc)
    } else {
        let r = reconstruct(&sampled, &force, &measured, &channels, &settings.horizon)?;
        (r, None)
    };
    if settings.states == StatesSource::Truth {
        truth_states(rec, &mut recon)?;
    }
    let state = |k: usize| -> Result<(Vec<f64>, Vec<f64>)> {
        let u = (0..n).map(|i| recon.states[(i, k)]).collect();
        let v = (0..n).map(|i| recon.states[(n + i, k)]).collect();
        Ok((u, v))
    };
    let window = settings.segments.quiet_window;
    let segments = quiet_segments(rec.len(), segment, window, &recon.force, state)?;
    let (u0, v0) = state(0)?;
    let observations = outs
        .iter()
        .map(|c| Observation {
            quantity: c.quantity,
            dof: c.dof,
            weight: 1.0 / c.data.iter().map(|x| x * x).sum::<f64>().sqrt().max(1e-300),
            data: c.data.clone(),
            point: c.point.clone(),
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
            unscored: settings.unscored.min(rec.len().saturating_sub(1)),
            starts: settings.starts,
        },
        recon,
        sampled,
        segment,
        located,
    })
}

/// The lifted smoother's reconstruction along the located directions,
/// its force prior's weight floored by the residual
/// ([`lifted::reconstruct_floored`]); an unknown force at every DOF, at
/// the settings' weight, when none were located or the search was off.
fn reconstruct_lifted(
    sampled: &SampledModel,
    force: &DMatrix<f64>,
    measured: &DMatrix<f64>,
    channels: &[(Quantity, usize)],
    settings: &DiagnoseSettings,
    loc: Option<&locate::Located>,
) -> Result<Reconstruction> {
    let n = sampled.n;
    let lifted = settings.lifted_settings();
    let e = loc
        .filter(|l| !l.directions.is_empty())
        .map(|l| l.matrix(n));
    let r = lifted::reconstruct_located(sampled, e.as_ref(), force, measured, channels, &lifted)?;
    let status = format!(
        "lifted smoother, {} sub-intervals per sample; {}: {}",
        lifted.resolution,
        loc.map_or("location search off".into(), |l| l.summary()),
        r.status
    );
    Ok(Reconstruction {
        states: r.states,
        force: -r.force,
        force_std: None,
        lambda: r.lambda,
        status,
        elapsed_s: 0.0,
    })
}

/// Replace the reconstructed states by the truth stored with a simulated
/// record.
fn truth_states(rec: &Record, recon: &mut Reconstruction) -> Result<()> {
    let t = rec.truth.as_ref().ok_or_else(|| {
        TacitError::record(
            rec.source.clone(),
            "states from the truth: the record has no truth",
        )
    })?;
    let n = recon.states.nrows() / 2;
    for i in 0..n {
        for k in 0..rec.len() {
            recon.states[(i, k)] = t.u[i][k];
            recon.states[(n + i, k)] = t.v[i][k];
        }
    }
    recon.status = format!("{} (states replaced by the record's truth)", recon.status);
    Ok(())
}

/// Consecutive segments of about `len` samples whose boundaries are moved
/// (by at most a quarter segment) to where the identified force has been
/// quiet for a few samples: a start state estimated just after an impact
/// carries the impulse's error (the impact happens between samples), one
/// estimated in free motion does not.
pub fn quiet_segments<F>(
    samples: usize,
    len: usize,
    window: usize,
    force: &DMatrix<f64>,
    mut state: F,
) -> Result<Vec<Segment>>
where
    F: FnMut(usize) -> Result<(Vec<f64>, Vec<f64>)>,
{
    let nominal = shooting::uniform(samples, len, |_| Ok((vec![], vec![])))?;
    let level: Vec<f64> = (0..samples).map(|k| force.column(k).amax()).collect();
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

/// The record and the validation record prepared for the loop, with the
/// noise measured on the record and the settings the loop runs at.
pub(super) struct Both {
    /// The record.
    pub prep: Prepared,
    /// The validation record.
    pub vprep: Option<Prepared>,
    /// The noise measured on the record (None when not measured).
    pub noise: Option<NoiseEstimate>,
    /// `settings` with the noise level the loop runs at
    /// ([`NoiseEstimate::used`]).
    pub settings: DiagnoseSettings,
}

/// The record and the validation record prepared, the validation record
/// with the force directions located on the record (the same structure;
/// no second search), both smoothers at once (each one a sequential
/// sweep). The noise is measured on the record after the search (which
/// runs again at the measured level when that is far from the assumed
/// one) and every later step uses the measured level. Inserts the stage
/// times into `timings`.
pub(super) fn both(
    declared: &Model,
    rec: &Record,
    validation: Option<&Record>,
    sensors: Option<&[usize]>,
    settings: &DiagnoseSettings,
    timings: &mut BTreeMap<String, f64>,
) -> Result<Both> {
    let t = Instant::now();
    let st = setup(declared, rec, sensors, settings)?;
    let mut found = search(declared, &st, settings)?;
    let t_locate = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let mut eff = settings.clone();
    let mut noise = None;
    if settings.noise.measure {
        let mut n = measure_noise(&st, found.as_ref(), settings)?;
        let measured = n.level.clamp(MIN_LEVEL, MAX_LEVEL);
        // far from the assumed level: the search and the measurement
        // again at the measured level (the smoother weighs the data by it),
        // and every later step at the measured level; a coloured residual
        // above the assumed level holds model error, which the trace must
        // still see, so it does not raise the level
        let raises_coloured = measured > settings.noise.level && n.status != NoiseStatus::White;
        if far(
            measured,
            settings.noise.level,
            settings.noise.relocate_factor,
        ) && !raises_coloured
        {
            eff.noise.level = measured;
            found = search(declared, &st, &eff)?;
            n = measure_noise(&st, found.as_ref(), &eff)?;
            n.assumed = settings.noise.level;
            eff.noise.level = n.level.clamp(MIN_LEVEL, MAX_LEVEL);
        }
        n.used = eff.noise.level;
        timings.insert("noise".into(), t.elapsed().as_secs_f64());
        noise = Some(n);
    }
    // the integration error kept below the record's noise
    let level = noise.as_ref().map_or(eff.noise.level, |n| n.level);
    eff.substeps = eff.substeps.at_noise(level.clamp(MIN_LEVEL, MAX_LEVEL));
    let (prep, vprep) = rayon::join(
        || prepare_from(declared, st, &eff, found.clone(), Instant::now()),
        || {
            validation
                .map(|v| prepare_located(declared, v, sensors, &eff, found.as_ref()))
                .transpose()
        },
    );
    let (prep, vprep) = (prep?, vprep?);
    timings.insert("locate".into(), t_locate);
    timings.insert("identify".into(), t_locate + prep.recon.elapsed_s);
    if let Some(v) = &vprep {
        timings.insert("identify_validation".into(), v.recon.elapsed_s);
    }
    Ok(Both {
        prep,
        vprep,
        noise,
        settings: eff,
    })
}

/// True when `a` and `b` differ by more than `factor` (> 1) either way.
fn far(a: f64, b: f64, factor: f64) -> bool {
    (a / b).ln().abs() > factor.ln()
}

/// The measured level is used within these bounds (a level outside them
/// is reported as measured; the thresholds stay meaningful).
const MIN_LEVEL: f64 = 1e-5;
const MAX_LEVEL: f64 = 0.5;

/// The noise of the record's channels ([`noise::measure`]) along the
/// located directions (a force at every DOF when none were located).
fn measure_noise(
    st: &Setup<'_>,
    found: Option<&locate::Located>,
    settings: &DiagnoseSettings,
) -> Result<NoiseEstimate> {
    let n = st.sampled.n;
    let directions = match found {
        Some(l) if !l.directions.is_empty() => l.matrix(n),
        _ => DMatrix::identity(n, n),
    };
    let names: Vec<String> = st.outs.iter().map(|c| c.name()).collect();
    let input = NoiseInput {
        sampled: &st.sampled,
        directions: &directions,
        known_force: &st.force,
        measured: &st.measured,
        channels: &st.channels,
        names: &names,
        fs: st.rec.fs,
    };
    noise::measure(&input, &settings.lifted_settings(), settings.noise.bands)
}

/// The record prepared again for scoring `model` when it has a spring to
/// ground and the declared model has none: the states are then
/// reconstructed with `model`'s linear part (the directions located
/// before), in which the absolute position the declared free-free model
/// left to its prior drives a force and is seen. From the declared model's
/// reconstruction the exact model of a contact with a ground spring scored
/// 73 %; from its own, 3.7 %. None otherwise.
///
/// A model with a law against ground in the absolute displacement (a
/// cubic, quadratic or contact to ground; [`super::ground`]) and no spring
/// to ground, on a free-free declared model: the declared reconstruction
/// (`base` when given, else made) corrected along the rigid-body
/// displacement by the wander fitted with its laws
/// ([`super::ground::corrected`]).
pub(super) fn rescore_prep(
    declared: &Model,
    model: &Model,
    rec: &Record,
    sensors: Option<&[usize]>,
    settings: &DiagnoseSettings,
    located: Option<&locate::Located>,
    base: Option<&Prepared>,
) -> Result<Option<Prepared>> {
    if declared.has_ground_spring() {
        return Ok(None);
    }
    if model.has_ground_spring() {
        return prepare_located(model, rec, sensors, settings, located).map(Some);
    }
    if super::ground::ground_laws(model).is_empty() {
        return Ok(None);
    }
    let made;
    let prep = match base {
        Some(p) => p,
        None => {
            made = prepare_located(model, rec, sensors, settings, located)?;
            &made
        }
    };
    Ok(super::ground::corrected(model, prep))
}
