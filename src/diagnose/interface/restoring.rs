//! The interface's restoring force against the relative motion it acts
//! on: the force of the Jenkins (Iwan) elements on the interface
//! coordinate in the model's open-loop simulation of a record, against the
//! coordinate's displacement and against the relative displacement of the
//! measured pair next to the interface.

use super::{simulate, INTERFACE};
use crate::error::{Result, TacitError};
use crate::model::Model;
use crate::plot::{Figure, Panel, Series};
use crate::record::Record;
use serde::Serialize;

/// The restoring force of the interface in one simulation (the last
/// `samples` samples of the record).
#[derive(Debug, Clone, Serialize)]
pub struct Restoring {
    /// The record simulated.
    pub record: String,
    /// The pair whose relative displacement is the second abscissa.
    pub pair: [String; 2],
    /// Displacement of the interface coordinate, m.
    pub displacement: Vec<f64>,
    /// Relative displacement of the pair (first minus second), m.
    pub relative: Vec<f64>,
    /// Force of the elements on the coordinate (the sliders' and the
    /// elastic softening's), N.
    pub force: Vec<f64>,
    /// The slip force (the largest), N.
    pub slip_force: f64,
    /// Where the interface moves with the structure: the correlation of
    /// the interface coordinate's velocity with the relative velocity of
    /// every pair of measured points (`a–b`) and with every point's
    /// velocity (`a–ground`) over the samples kept, largest magnitude
    /// first.
    pub follows: Vec<(String, f64)>,
}

/// Simulate `model` (with the [`INTERFACE`] point, its Jenkins elements
/// and any saturating spring on it) from rest under the record's force and return the elements'
/// force over the last `samples` samples, with the interface displacement
/// and the pair's relative displacement (`pair`: DOFs from 1). The slip of
/// each element is replayed on the simulated displacement at the sample
/// rate (the integrator commits it at every sub-step).
pub fn restoring(
    model: &Model,
    rec: &Record,
    pair: [usize; 2],
    substeps: usize,
    samples: usize,
) -> Result<Restoring> {
    let dof = model
        .points
        .iter()
        .position(|p| p == INTERFACE)
        .ok_or_else(|| {
            TacitError::Numerical(format!("the model {} has no {INTERFACE} point", model.name))
        })?;
    let run = simulate(model, rec, substeps)?;
    let n = rec.len();
    let k0 = n.saturating_sub(samples);
    let els: Vec<_> = model
        .jenkins
        .iter()
        .filter(|j| j.dofs == [dof + 1])
        .collect();
    let soft: Vec<_> = model
        .saturating
        .iter()
        .filter(|e| e.dofs == [dof + 1])
        .collect();
    let mut slips = vec![0.0; els.len()];
    let (mut displacement, mut relative, mut force) = (vec![], vec![], vec![]);
    let (a, b) = (pair[0] - 1, pair[1] - 1);
    for k in 0..n {
        let d = run.u[(dof, k)];
        let mut f = 0.0;
        for (e, z) in els.iter().zip(slips.iter_mut()) {
            let (fe, _) = crate::model::elements::jenkins_law(e.stiffness, e.slip_force, d, *z);
            *z = d - fe / e.stiffness;
            f += fe;
        }
        for e in &soft {
            f += crate::model::elements::saturation(e.stiffness, e.force, d).0;
        }
        if k >= k0 {
            displacement.push(d);
            relative.push(run.u[(a, k)] - run.u[(b, k)]);
            force.push(f);
        }
    }
    let follows = follows(model, &run.v, dof, k0);
    Ok(Restoring {
        follows,
        record: rec.source.display().to_string(),
        pair: [model.dof_name(pair[0]), model.dof_name(pair[1])],
        displacement,
        relative,
        force,
        slip_force: els.iter().map(|e| e.slip_force).fold(0.0, f64::max),
    })
}

/// The correlation of the velocity of DOF `dof` with the relative
/// velocities of the other points (every pair, every point to ground) from
/// sample `k0` on, largest magnitude first.
fn follows(model: &Model, v: &nalgebra::DMatrix<f64>, dof: usize, k0: usize) -> Vec<(String, f64)> {
    let n = v.ncols();
    let vi: Vec<f64> = (k0..n).map(|k| v[(dof, k)]).collect();
    let pts: Vec<usize> = (0..model.points.len()).filter(|&p| p != dof).collect();
    let mut out = vec![];
    for (x, &a) in pts.iter().enumerate() {
        for &b in &pts[x + 1..] {
            let r: Vec<f64> = (k0..n).map(|k| v[(a, k)] - v[(b, k)]).collect();
            out.push((
                format!("{}–{}", model.points[a], model.points[b]),
                correlation(&vi, &r),
            ));
        }
        let r: Vec<f64> = (k0..n).map(|k| v[(a, k)]).collect();
        out.push((format!("{}–ground", model.points[a]), correlation(&vi, &r)));
    }
    out.sort_by(|x, y| y.1.abs().total_cmp(&x.1.abs()));
    out
}

/// The correlation coefficient of two series (0 when either is constant).
fn correlation(a: &[f64], b: &[f64]) -> f64 {
    let m = |x: &[f64]| x.iter().sum::<f64>() / x.len().max(1) as f64;
    let (ma, mb) = (m(a), m(b));
    let (mut ab, mut aa, mut bb) = (0.0, 0.0, 0.0);
    for (x, y) in a.iter().zip(b) {
        ab += (x - ma) * (y - mb);
        aa += (x - ma).powi(2);
        bb += (y - mb).powi(2);
    }
    if aa > 0.0 && bb > 0.0 {
        ab / (aa * bb).sqrt()
    } else {
        0.0
    }
}

/// Two panels: the force against the interface displacement and against
/// the pair's relative displacement (µm).
pub fn restoring_figure(r: &Restoring, title: &str) -> Figure {
    let um = |x: &[f64]| x.iter().map(|v| v * 1e6).collect::<Vec<f64>>();
    let name = std::path::Path::new(&r.record)
        .file_name()
        .map_or(r.record.clone(), |f| f.to_string_lossy().into_owned());
    let p1 = Panel::xy(
        format!("{INTERFACE} to ground ({name})"),
        format!("{INTERFACE} displacement [µm]"),
        "interface force [N]",
        vec![Series::line(
            "model (open loop)",
            um(&r.displacement),
            r.force.clone(),
        )],
    );
    let p2 = Panel::xy(
        format!("against the relative motion {}–{}", r.pair[0], r.pair[1]),
        format!("{} − {} displacement [µm]", r.pair[0], r.pair[1]),
        "interface force [N]",
        vec![Series::points(
            "model (open loop)",
            um(&r.relative),
            r.force.clone(),
        )],
    );
    Figure::new(title, vec![p1, p2], 2)
}
