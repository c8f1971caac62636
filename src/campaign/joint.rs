//! One set of effect parameters fitted to several records of the same
//! structure (the same bumper seen at several force levels).
//!
//! Each record brings its multiple-shooting data ([`Comparison`]: input,
//! measured channels, segments with start states reconstructed from the
//! record). The records are laid end to end into one updating problem
//! ([`crate::update::Problem`]): forces and channels concatenated, each
//! record's segments shifted by its offset, so that a segment never crosses
//! from one record into the next and each is simulated from its own start
//! state exactly as in the record's own fit. The shared parameters (a
//! contact's gap and stiffness, a friction level, a cubic coefficient) are
//! then fitted by [`crate::update::fit`] (Levenberg–Marquardt with forward
//! sensitivities, bounds), starting from the median of the per-record
//! values. The segments' start states are first refined for the current
//! parameters on every record ([`Comparison::shoot`], as the diagnosis
//! does), then held while the parameters are fitted; two such passes.
//! Each channel is weighted by `1/‖y‖₂` over all records together,
//! so a record at a higher level weighs more, as its data do.
//!
//! The result compares, record by record, the multiple-shooting error of
//! the record's own fitted model with that of the model carrying the
//! shared parameters, both computed as the reports compute it
//! ([`Comparison::errors`]: start states refined for each model).

use crate::diagnose::comparison::Comparison;
use crate::error::{Result, TacitError};
use crate::integrate::SimSettings;
use crate::model::Model;
use crate::update::param::{Parameter, Target};
use crate::update::problem::{Metric, Observation, Problem};
use crate::update::shooting::Segment;
use crate::update::{self, FitSettings};
use nalgebra::DMatrix;
use serde::Serialize;

/// One record of the joint fit.
#[derive(Debug, Clone)]
pub struct JointRecord {
    /// Record name.
    pub name: String,
    /// Its multiple-shooting data.
    pub comparison: Comparison,
    /// Its own fitted model (for the comparison of errors).
    pub own: Model,
}

/// A shared parameter.
#[derive(Debug, Clone, Serialize)]
pub struct SharedParameter {
    /// `gap`, `stiffness`, …
    pub name: String,
    /// SI unit.
    pub unit: String,
    /// Fitted value, SI.
    pub value: f64,
    /// Standard deviation from the noise level (when the fit's Jacobian
    /// was computed).
    pub std: Option<f64>,
    /// The per-record values it replaces.
    pub per_record: Vec<f64>,
    /// True when the value ended on a bound.
    pub at_bound: bool,
}

/// One record's errors with its own and the shared parameters.
#[derive(Debug, Clone, Serialize)]
pub struct RecordErrors {
    /// Record name.
    pub name: String,
    /// Multiple-shooting relative error of its own fitted model.
    pub own: Option<f64>,
    /// The same with the shared parameters.
    pub joint: Option<f64>,
}

/// The joint fit.
#[derive(Debug, Clone, Serialize)]
pub struct JointFit {
    /// The effect whose parameters are shared (`contact 5→6`).
    pub effect: String,
    /// The shared parameters.
    pub parameters: Vec<SharedParameter>,
    /// Per record.
    pub records: Vec<RecordErrors>,
    /// How the search ended, in words.
    pub termination: String,
    /// Iterations of the search.
    pub iterations: usize,
    /// Wall time, s.
    pub elapsed_s: f64,
    /// The model with the shared parameters (the start model's linear
    /// part).
    #[serde(skip)]
    pub model: Model,
}

/// The parameters (name, target) of the element an effect of `kind` at
/// `dofs` (from 1) added to `model`.
pub fn targets(model: &Model, kind: &str, dofs: &[usize]) -> Result<Vec<(String, Target)>> {
    let missing = || {
        TacitError::Setting(format!(
            "joint fit: the model has no {kind} element at DOFs {dofs:?}"
        ))
    };
    let pair = |d: &Vec<usize>| d.as_slice() == dofs;
    Ok(match kind {
        "contact" => {
            let i = model.contacts.iter().position(|c| pair(&c.dofs)).ok_or_else(missing)?;
            vec![("gap".into(), Target::ContactGap(i)), ("stiffness".into(), Target::ContactStiffness(i))]
        }
        "clearance" => {
            let i = model.clearances.iter().position(|c| pair(&c.dofs)).ok_or_else(missing)?;
            vec![("gap".into(), Target::ClearanceGap(i)), ("stiffness".into(), Target::ClearanceStiffness(i))]
        }
        "cubic" => {
            let i = model.cubics.iter().position(|c| pair(&c.dofs)).ok_or_else(missing)?;
            vec![("k3".into(), Target::CubicK3(i))]
        }
        "friction" if dofs.len() == 1 => {
            let i = model.frictions.iter().position(|f| f.dof == dofs[0]).ok_or_else(missing)?;
            vec![("level".into(), Target::FrictionLevel(i))]
        }
        other => {
            return Err(TacitError::Setting(format!(
                "joint fit: a {other} effect at DOFs {dofs:?} is not supported (contact, clearance, cubic, friction at one DOF)"
            )))
        }
    })
}

/// The records laid end to end into one updating problem (module docs).
pub fn concatenate(
    model: &Model,
    records: &[JointRecord],
    parameters: Vec<Parameter>,
    sim: SimSettings,
) -> Result<Problem> {
    let first = &records
        .first()
        .ok_or_else(|| TacitError::Setting("joint fit: no record".into()))?
        .comparison;
    let key = |c: &Comparison| -> Vec<(crate::record::Quantity, usize)> {
        c.observations.iter().map(|o| (o.quantity, o.dof)).collect()
    };
    for r in records {
        let c = &r.comparison;
        if c.fs != first.fs || key(c) != key(first) || c.force.nrows() != first.force.nrows() {
            return Err(TacitError::Setting(format!(
                "joint fit: record {} has other channels or another sample rate than {} ({} Hz, {:?})",
                r.name, records[0].name, first.fs, key(first)
            )));
        }
    }
    let total: usize = records.iter().map(|r| r.comparison.force.ncols()).sum();
    let mut force = DMatrix::zeros(first.force.nrows(), total);
    let mut observations: Vec<Observation> = first
        .observations
        .iter()
        .map(|o| Observation {
            data: Vec::with_capacity(total),
            ..o.clone()
        })
        .collect();
    let mut segments = vec![];
    let mut offset = 0;
    for r in records {
        let c = &r.comparison;
        let len = c.force.ncols();
        force.columns_mut(offset, len).copy_from(&c.force);
        for (o, src) in observations.iter_mut().zip(&c.observations) {
            o.data.extend_from_slice(&src.data);
        }
        segments.extend(c.segments.iter().map(|s| Segment {
            start: s.start + offset,
            ..s.clone()
        }));
        offset += len;
    }
    for o in &mut observations {
        o.weight = 1.0 / o.data.iter().map(|x| x * x).sum::<f64>().sqrt().max(1e-300);
    }
    Ok(Problem {
        model: model.clone(),
        fs: first.fs,
        force,
        observations,
        parameters,
        segments,
        reduction: None,
        metric: Metric::Gls,
        alpha: 0.0,
        sim,
    })
}

/// Fit the parameters of the effect `label` (`kind` at `dofs`) of
/// `start` to every record at once, from the median of `per_record`
/// (one value list per parameter, in the order of [`targets`]).
pub fn fit(
    start: &Model,
    label: &str,
    kind: &str,
    dofs: &[usize],
    per_record: &[Vec<f64>],
    records: &[JointRecord],
    sim: SimSettings,
) -> Result<JointFit> {
    let t0 = std::time::Instant::now();
    let tg = targets(start, kind, dofs)?;
    let mut model = start.clone();
    for ((_, t), vals) in tg.iter().zip(per_record) {
        if let Some(m) = median(vals) {
            t.set(&mut model, m);
        }
    }
    // start states refined for the current parameters, then the
    // parameters fitted with those start states held: twice
    let mut work = records.to_vec();
    let mut res = None;
    let mut iterations = 0;
    for _ in 0..PASSES {
        for r in &mut work {
            if let Ok((_, segs, _)) = r.comparison.shoot(&model, sim) {
                r.comparison.segments = segs;
            }
        }
        let problem = concatenate(&model, &work, bounded(&model, &tg)?, sim)?;
        let fitted = update::fit(&problem, &FitSettings::default())?;
        update::usable(&problem, &fitted, &format!("joint fit of {label}"))?;
        iterations += fitted.iterations;
        model = fitted.model.clone();
        res = Some(fitted);
    }
    let res = res.expect("at least one pass");
    let ident = res.identifiability.as_ref();
    let parameters = tg
        .iter()
        .zip(&res.parameters)
        .zip(per_record)
        .map(|(((name, _), p), vals)| SharedParameter {
            unit: super::summary::unit(name).into(),
            name: name.clone(),
            value: p.value,
            std: ident
                .and_then(|i| i.parameters.iter().find(|q| q.name == p.name))
                .map(|q| q.std_value),
            per_record: vals.clone(),
            at_bound: p.at_bound,
        })
        .collect();
    let records = records
        .iter()
        .map(|r| {
            let joint = r.comparison.errors(&res.model, sim).0.relative_error;
            match joint {
                Some(e) if e.is_finite() => Ok(RecordErrors {
                    name: r.name.clone(),
                    own: r.comparison.errors(&r.own, sim).0.relative_error,
                    joint,
                }),
                _ => Err(TacitError::Numerical(format!(
                    "joint fit of {label}: the model with the shared parameters cannot be simulated on record {} ({}): no shared model is given",
                    r.name,
                    joint.map_or("its simulation failed".into(), |e| format!("its error is {e}"))
                ))),
            }
        })
        .collect::<Result<Vec<_>>>()?;
    Ok(JointFit {
        effect: label.into(),
        parameters,
        records,
        termination: res.termination.words(),
        iterations,
        elapsed_s: t0.elapsed().as_secs_f64(),
        model: res.model,
    })
}

/// One diagnosed record for [`fit_diagnosed`].
#[derive(Debug, Clone)]
pub struct Diagnosed<'a> {
    /// Record name (in the result and the messages).
    pub name: String,
    /// The record.
    pub record: &'a crate::record::Record,
    /// Its sensors (DOFs from 1; None: every response channel).
    pub sensors: Option<&'a [usize]>,
    /// The model its own diagnosis fitted (the declared model and the
    /// effects found).
    pub fitted: Model,
    /// Integration sub-steps per sample of that fit.
    pub substeps: usize,
}

/// The joint fit of the effect `label` (`kind` at `dofs`, from 1) over
/// records that were each diagnosed against `model` with `settings`:
/// each record's multiple-shooting data prepared as the diagnosis
/// prepares them, the per-record values read from its fitted model, the
/// shared values started from their median on the first record's fitted
/// model (its linear part), simulated with the largest sub-step count of
/// the records. At least two records.
pub fn fit_diagnosed(
    model: &Model,
    (label, kind, dofs): (&str, &str, &[usize]),
    records: &[Diagnosed<'_>],
    settings: &crate::diagnose::DiagnoseSettings,
) -> Result<JointFit> {
    if records.len() < 2 {
        return Err(TacitError::Setting(format!(
            "joint fit of {label}: {} record(s) carry it; at least two are needed",
            records.len()
        )));
    }
    let mut jr = vec![];
    let mut per_record: Vec<Vec<f64>> = vec![];
    for d in records {
        let named =
            |e: TacitError| TacitError::Setting(format!("joint fit: record {}: {e}", d.name));
        let tg = targets(&d.fitted, kind, dofs).map_err(named)?;
        per_record.resize(tg.len(), vec![]);
        for ((_, t), vals) in tg.iter().zip(&mut per_record) {
            vals.push(t.get(&d.fitted)?);
        }
        let mut rec = d.record.clone();
        model.resolve_channels(&mut rec).map_err(named)?;
        let prep =
            crate::diagnose::prepare::prepare_located(model, &rec, d.sensors, settings, None)
                .map_err(named)?;
        jr.push(JointRecord {
            name: d.name.clone(),
            comparison: prep.comparison,
            own: d.fitted.clone(),
        });
    }
    let sim = SimSettings {
        substeps: records.iter().map(|d| d.substeps).max().unwrap_or(10),
        ..Default::default()
    };
    fit(&jr[0].own, label, kind, dofs, &per_record, &jr, sim)
}

/// Passes of start-state refinement and parameter fit.
const PASSES: usize = 2;

/// The free parameters at `model`'s values with physical bounds.
fn bounded(model: &Model, tg: &[(String, Target)]) -> Result<Vec<Parameter>> {
    tg.iter()
        .map(|(_, t)| {
            let p = Parameter::relative(model, *t)?;
            Ok(match t {
                Target::ContactGap(_) | Target::ClearanceGap(_) => {
                    p.with_relative_bounds(-0.8, 2.0)
                }
                _ => p.with_relative_bounds(-0.95, 10.0),
            })
        })
        .collect()
}

/// The median of finite values (None when there is none).
fn median(v: &[f64]) -> Option<f64> {
    let mut s: Vec<f64> = v.iter().copied().filter(|x| x.is_finite()).collect();
    if s.is_empty() {
        return None;
    }
    s.sort_by(f64::total_cmp);
    let n = s.len();
    Some(if n % 2 == 1 {
        s[n / 2]
    } else {
        0.5 * (s[n / 2 - 1] + s[n / 2])
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn median_of_odd_even_and_non_finite() {
        assert_eq!(median(&[3.0, 1.0, 2.0]), Some(2.0));
        assert_eq!(median(&[4.0, 1.0, 3.0, 2.0]), Some(2.5));
        assert_eq!(median(&[f64::NAN, 5.0]), Some(5.0));
        assert_eq!(median(&[]), None);
    }

    #[test]
    fn targets_name_the_element_and_refuse_other_kinds() {
        let p = concat!(env!("CARGO_MANIFEST_DIR"), "/data/lanl8dof-contact.toml");
        let m = Model::from_file(std::path::Path::new(p)).unwrap();
        let t = targets(&m, "contact", &[5, 6]).unwrap();
        assert_eq!(t[0], ("gap".to_string(), Target::ContactGap(0)));
        assert_eq!(t[1], ("stiffness".to_string(), Target::ContactStiffness(0)));
        assert!(targets(&m, "contact", &[6, 5]).is_err());
        let e = targets(&m, "damping", &[]).unwrap_err().to_string();
        assert!(e.contains("not supported"), "{e}");
    }
}
