//! Reading records for a command: unit conversions reported, the sanity
//! checks of `tacit::record::checks` run (with the model's predicted
//! response scale), warnings printed, and an error where the record cannot
//! be used at all.

use anyhow::{bail, Result};
use tacit::integrate::{Integrator, SimSettings};
use tacit::model::Model;
use tacit::record::checks::{self, CheckSettings, Finding, Severity};
use tacit::record::{Quantity, Record};

/// Run every check of `rec` against `model`; print the warnings on
/// stderr; fail on a finding that makes the record unusable. `selected`:
/// the output DOFs the run uses (`None`: all). Returns the warnings, each
/// prefixed with the record's file name, for the report.
pub fn check(rec: &Record, model: &Model, selected: Option<&[usize]>) -> Result<Vec<String>> {
    let s = CheckSettings::default();
    let mut found = checks::check_record(rec, selected, &s);
    if !rec.inputs.is_empty() {
        if let Some(f) = scale_finding(rec, model, &s) {
            found.push(f);
        }
    }
    report(rec, &found)
}

/// Print the findings; an error for the first of `Severity::Error`.
fn report(rec: &Record, found: &[Finding]) -> Result<Vec<String>> {
    let file = rec.source.display().to_string();
    let errors: Vec<&Finding> = found
        .iter()
        .filter(|f| f.severity == Severity::Error)
        .collect();
    if !errors.is_empty() {
        let list: Vec<String> = errors.iter().map(|f| f.message.clone()).collect();
        bail!(
            "record {file}: cannot be used as it is: {}",
            list.join("; ")
        );
    }
    let mut out = vec![];
    for f in found {
        eprintln!("tacit: warning: {file}: {}", f.message);
        out.push(format!("{file}: {}", f.message));
    }
    Ok(out)
}

/// The measured RMS of each acceleration (or velocity) channel against
/// the linear model's response to the record's force.
fn scale_finding(rec: &Record, model: &Model, s: &CheckSettings) -> Option<Finding> {
    let n = model.ndof();
    if rec.inputs.iter().chain(&rec.outputs).any(|c| c.dof > n) {
        return None;
    }
    let lin = model.linear_part();
    let settings = SimSettings {
        substeps: 10,
        ..Default::default()
    };
    let integ = Integrator::new(&lin, rec.fs, settings).ok()?;
    let mut force = nalgebra::DMatrix::zeros(n, rec.len());
    for c in &rec.inputs {
        for (k, v) in c.data.iter().enumerate() {
            force[(c.dof - 1, k)] += v;
        }
    }
    let zeros = vec![0.0; n];
    let sim = integ.run(force.as_view(), &zeros, &zeros);
    if !sim.completed() {
        return None;
    }
    let kind = [Quantity::Accel, Quantity::Vel]
        .into_iter()
        .find(|q| rec.outputs.iter().any(|c| c.quantity == *q))?;
    let pairs: Vec<(String, f64, f64)> = rec
        .outputs
        .iter()
        .filter(|c| c.quantity == kind)
        .map(|c| {
            let src = if kind == Quantity::Accel {
                &sim.a
            } else {
                &sim.v
            };
            let row: Vec<f64> = src.row(c.dof - 1).iter().copied().collect();
            (c.name(), checks::rms(&c.data), checks::rms(&row))
        })
        .collect();
    checks::scale(&pairs, s)
}
