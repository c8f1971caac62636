//! The joint estimate of one effect's parameters over several records of
//! the same structure (the campaign's joint fit, `tacit::campaign::joint`).

use crate::err;
use crate::model::Model;
use crate::record::Record;
use pyo3::prelude::*;
use std::path::PathBuf;
use tacit::campaign::joint;
use tacit::diagnose::DiagnoseSettings;

/// One set of parameters of the effect `effect` (`kind` at `dofs`, from
/// 1) fitted to every record at once. `records[i]` was diagnosed against
/// `model` and gave the fitted model `fitted[i]` with `substeps[i]`
/// Newmark sub-steps per sample; `names[i]` names it in the result.
/// `sensors`: DOFs from 1 (None: every response channel); `settings`: the
/// diagnosis settings file the records were diagnosed with. Returns the
/// result as JSON (shared values in SI units with noise-only standard
/// deviations, each record's error with its own and with the shared
/// parameters) and the model carrying the shared parameters.
#[pyfunction]
#[pyo3(signature = (model, records, fitted, names, effect, kind, dofs, substeps,
    sensors = None, settings = None))]
#[allow(clippy::too_many_arguments)]
pub fn group_estimates(
    py: Python<'_>,
    model: &Model,
    records: Vec<PyRef<'_, Record>>,
    fitted: Vec<PyRef<'_, Model>>,
    names: Vec<String>,
    effect: String,
    kind: String,
    dofs: Vec<usize>,
    substeps: Vec<usize>,
    sensors: Option<Vec<usize>>,
    settings: Option<PathBuf>,
) -> PyResult<(String, Model)> {
    let n = records.len();
    if fitted.len() != n || names.len() != n || substeps.len() != n {
        return Err(err(format!(
            "group_estimates: {n} records, {} fitted models, {} names, {} sub-step counts: give one of each per record",
            fitted.len(),
            names.len(),
            substeps.len()
        )));
    }
    let settings = match settings {
        Some(p) => DiagnoseSettings::from_file(&p).map_err(err)?,
        None => DiagnoseSettings::default(),
    };
    settings.validate().map_err(err)?;
    let recs: Vec<tacit::record::Record> = records.iter().map(|r| r.inner.clone()).collect();
    let diagnosed: Vec<joint::Diagnosed<'_>> = recs
        .iter()
        .zip(&fitted)
        .zip(names.iter().zip(&substeps))
        .map(|((rec, f), (name, &s))| joint::Diagnosed {
            name: name.clone(),
            record: rec,
            sensors: sensors.as_deref(),
            fitted: f.inner.clone(),
            substeps: s,
        })
        .collect();
    let m = model.reduced("group_estimates")?;
    let fit = py
        .detach(|| joint::fit_diagnosed(m, (&effect, &kind, &dofs), &diagnosed, &settings))
        .map_err(err)?;
    let json = serde_json::to_string(&fit).map_err(err)?;
    Ok((json, Model::dense(fit.model, None)))
}
