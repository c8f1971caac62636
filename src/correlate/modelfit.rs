//! A linear model from a test: the modes in the band identified from
//! records (H1, then LSCF poles and LSFD shapes, [`super::fit`]) and written
//! as a modal model ([`crate::model::modal`]) whose points are the measured
//! points.
//!
//! **Why LSCF.** The records of a ground vibration test are force-driven
//! with one shaker: the FRFs from the force to each accelerometer are
//! what the test measures well (a periodic excitation gives them without
//! leakage), and a common-denominator fit of those FRFs over model orders
//! with a stabilisation check separates the physical poles from the
//! noise poles on the test engineer's own terms (frequency, damping,
//! shape). A subspace identification would give a state-space model of
//! the same order directly, but its states carry no physical meaning and
//! its modes would still have to be read off, real-normalised and scaled;
//! the modal parameters are what the structure's model needs.
//!
//! **Mass normalisation.** The modal constants are real,
//! `A_or = φ_or φ_dr` with `d` the driving point (the force is applied at
//! a measured point), so `φ_dr = √A_dr` and `φ_or = A_or / φ_dr`. A mode
//! whose driving-point constant is not positive cannot be scaled: it is
//! left out and named in the diagnostics.
//!
//! **Residual modes.** The modes outside the band leave a residual in it:
//! a mass line from those below, a flexibility from those above. Each is
//! represented by one residual mode (below at half the band's low end,
//! above at twice its high end, damping 5 %) fitted with the modes; it is
//! kept where it matters: when it lowers the LSFD fit error by more than
//! 1 % of the error without it and its driving-point constant is
//! positive.

use super::fit::{self, FitSettings, Group};
use super::frf::{h1_records, Frf, FrfSettings};
use crate::error::{Result, TacitError};
use crate::model::modal::{ModalMode, ModalSection};
use crate::record::{Channel, Quantity, Record};
use nalgebra::DMatrix;
use serde::Serialize;

/// Damping ratio of the residual modes.
pub const RESIDUAL_DAMPING: f64 = 0.05;

/// Settings of [`identify_model`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ModelFitSettings {
    /// H1 estimate.
    pub frf: FrfSettings,
    /// Curve fit (its band is the model's band).
    pub fit: FitSettings,
    /// Try residual modes below and above the band.
    pub residuals: bool,
}

impl ModelFitSettings {
    /// Check the FRF and curve-fit settings against a sample rate.
    pub fn validate(&self, fs: f64) -> Result<()> {
        self.frf.validate()?;
        self.fit.validate(fs)
    }
}

/// What came out of [`identify_model`].
#[derive(Debug, Clone, Serialize)]
pub struct ModelFit {
    /// The modal model.
    pub section: ModalSection,
    /// The FRFs it was fitted to.
    #[serde(skip)]
    pub frf: Frf,
    /// Relative LSFD fit error per point over the band, with the modes
    /// and residual modes kept.
    pub fit_error: Vec<f64>,
    /// The same without residual modes.
    pub fit_error_without_residuals: Vec<f64>,
    /// Stable poles behind each identified mode (same order as the
    /// curve fit's modes).
    pub support: Vec<usize>,
    /// Modes left out and why, residual modes tried, the curve fit's notes.
    pub diagnostics: Vec<String>,
}

/// A channel's point label: its point, or `dof<k>` for a channel by DOF.
fn label(c: &Channel) -> String {
    c.point.clone().unwrap_or_else(|| format!("dof{}", c.dof))
}

/// The measured points of a record: (label, record DOF) of each
/// acceleration channel, and the index of the force's point among them.
fn points(rec: &Record) -> Result<(Vec<(String, usize)>, usize)> {
    let err = |m: String| TacitError::record(rec.source.clone(), m);
    let pts: Vec<(String, usize)> = rec
        .outputs
        .iter()
        .filter(|c| c.quantity == Quantity::Accel)
        .map(|c| (label(c), c.dof))
        .collect();
    if pts.is_empty() {
        return Err(err(
            "no acceleration channel: a modal model is identified from accelerations".into(),
        ));
    }
    let force = match rec.inputs.as_slice() {
        [f] => f,
        [] => return Err(err("no force channel".into())),
        _ => {
            return Err(err(format!(
                "{} force channels: the identification takes one shaker",
                rec.inputs.len()
            )))
        }
    };
    let dp = pts.iter().position(|p| p.0 == label(force)).ok_or_else(|| {
        err(format!(
            "force channel {} is not at a measured point (no accel channel there): the shapes cannot be mass-normalised through the driving point",
            force.name()
        ))
    })?;
    Ok((pts, dp))
}

/// The records with their channels numbered 1..=p by point (the FRF
/// estimate works on DOF numbers); every record must have the first
/// one's points.
fn renumbered(records: &[Record], pts: &[(String, usize)]) -> Result<Vec<Record>> {
    let mut out = Vec::with_capacity(records.len());
    for r in records {
        let mut r = r.clone();
        for c in r.inputs.iter_mut().chain(r.outputs.iter_mut()) {
            let l = label(c);
            let i = pts.iter().position(|p| p.0 == l).ok_or_else(|| {
                TacitError::record(
                    r.source.clone(),
                    format!("channel {}: not a point of the first record", c.name()),
                )
            })?;
            c.dof = i + 1;
            c.point = None;
        }
        out.push(r);
    }
    Ok(out)
}

/// Identify a modal model from force-driven records with accelerations
/// (one force, at a measured point). Errors name the record and channel.
pub fn identify_model(records: &[Record], settings: &ModelFitSettings) -> Result<ModelFit> {
    let first = records
        .first()
        .ok_or_else(|| TacitError::Setting("the identification needs a record".into()))?;
    settings.validate(first.fs)?;
    let (pts, dp) = points(first)?;
    let recs = renumbered(records, &pts)?;
    let sensors: Vec<usize> = (1..=pts.len()).collect();
    let frf = h1_records(
        &recs,
        Some(dp + 1),
        &sensors,
        Quantity::Accel,
        &settings.frf,
    )?;
    let curve = fit::identify(&frf, &settings.fit)?;
    let mut diagnostics = curve.diagnostics.clone();
    if curve.modes.is_empty() {
        return Err(TacitError::Numerical(format!(
            "the curve fit identified no mode in {:?} Hz ({})",
            settings.fit.band_hz,
            diagnostics.join("; ")
        )));
    }
    let lines = fit::band_lines(&frf, settings.fit.band_hz);
    let mut modes: Vec<Group> = curve
        .modes
        .iter()
        .map(|m| (m.frequency_hz, m.damping, 0))
        .collect();
    // modes that cannot be mass-normalised are left out, then all refitted
    let (groups, consts, err, err0) = loop {
        let (c0, e0) = fit::lsfd(&frf, &lines, &modes, false)?;
        let (groups, consts, err) = if settings.residuals {
            let base = (c0, e0.clone());
            residual_modes(&frf, &lines, &modes, dp, settings, base, &mut diagnostics)?
        } else {
            (modes.clone(), c0, e0.clone())
        };
        let bad: Vec<usize> = (0..modes.len())
            .filter(|&r| !(consts[(dp, r)] > 0.0))
            .collect();
        if bad.is_empty() {
            break (groups, consts, err, e0);
        }
        for &r in &bad {
            diagnostics.push(format!(
                "mode at {:.3} Hz left out: its driving-point constant {:.3e} is not positive",
                modes[r].0,
                consts[(dp, r)]
            ));
        }
        modes = modes
            .iter()
            .enumerate()
            .filter(|(r, _)| !bad.contains(r))
            .map(|(_, g)| *g)
            .collect();
        if modes.is_empty() {
            return Err(TacitError::Numerical(format!(
                "no identified mode has a positive driving-point constant ({})",
                diagnostics.join("; ")
            )));
        }
    };
    let section = section(&pts, dp, &groups, modes.len(), &consts)?;
    Ok(ModelFit {
        section,
        frf,
        fit_error: err,
        fit_error_without_residuals: err0,
        support: curve.support.clone(),
        diagnostics,
    })
}

/// Sum of the per-point fit errors.
fn total(e: &[f64]) -> f64 {
    e.iter().sum()
}

/// Try a residual mode below and above the band; keep each that lowers
/// the fit error by more than 1 % and scales through the driving point.
fn residual_modes(
    frf: &Frf,
    lines: &[usize],
    modes: &[Group],
    dp: usize,
    settings: &ModelFitSettings,
    base: (DMatrix<f64>, Vec<f64>),
    diagnostics: &mut Vec<String>,
) -> Result<(Vec<Group>, DMatrix<f64>, Vec<f64>)> {
    let (lo, hi) = settings.fit.band_hz;
    let mut groups = modes.to_vec();
    let (mut consts, mut err) = base;
    for (what, f) in [("below", 0.5 * lo), ("above", 2.0 * hi)] {
        let mut trial = groups.clone();
        trial.push((f, RESIDUAL_DAMPING, 0));
        let (c, e) = fit::lsfd(frf, lines, &trial, false)?;
        let a = c[(dp, trial.len() - 1)];
        let gain = 1.0 - total(&e) / total(&err);
        let kept = a > 0.0 && gain > 0.01;
        diagnostics.push(format!(
            "residual mode {what} the band ({f:.2} Hz): fit error {:.4} -> {:.4}, driving-point constant {a:.3e}: {}",
            total(&err),
            total(&e),
            if kept { "kept" } else { "not kept" }
        ));
        if kept {
            groups = trial;
            consts = c;
            err = e;
        }
    }
    Ok((groups, consts, err))
}

/// The modal section: shapes mass-normalised through the driving point;
/// groups after the first `n_modes` are residual modes.
fn section(
    pts: &[(String, usize)],
    dp: usize,
    groups: &[Group],
    n_modes: usize,
    consts: &DMatrix<f64>,
) -> Result<ModalSection> {
    let mut modes = Vec::with_capacity(groups.len());
    for (r, &(f, z, _)) in groups.iter().enumerate() {
        let a = consts[(dp, r)];
        if !(a > 0.0) {
            return Err(TacitError::Numerical(format!(
                "mode at {f:.3} Hz: driving-point constant {a:.3e} is not positive after the refit"
            )));
        }
        let phi = a.sqrt();
        modes.push(ModalMode {
            frequency_hz: f,
            damping: z,
            shape: (0..consts.nrows()).map(|o| consts[(o, r)] / phi).collect(),
            residual: r >= n_modes,
        });
    }
    let all_dofs = pts.iter().all(|p| p.1 > 0);
    Ok(ModalSection {
        points: pts.iter().map(|p| p.0.clone()).collect(),
        dofs: if all_dofs {
            pts.iter().map(|p| p.1).collect()
        } else {
            vec![]
        },
        driving_point: Some(pts[dp].0.clone()),
        modes,
    })
}
