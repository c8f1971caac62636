//! Reading records for a command: the checks of
//! `tacit::record::model_checks` run, warnings printed, and an error where
//! the record cannot be used at all.

use anyhow::Result;
use tacit::model::Model;
use tacit::record::model_checks;
use tacit::record::Record;

/// Run every check of `rec` against `model`; print the warnings on
/// stderr; fail on a finding that makes the record unusable. `selected`:
/// the output DOFs the run uses (`None`: all). Returns the warnings, each
/// prefixed with the record's file name, for the report.
pub fn check(rec: &Record, model: &Model, selected: Option<&[usize]>) -> Result<Vec<String>> {
    let found = model_checks::warnings(rec, model, selected)?;
    let out = model_checks::labelled(&rec.source.display().to_string(), &found);
    for w in &out {
        eprintln!("tacit: warning: {w}");
    }
    Ok(out)
}
