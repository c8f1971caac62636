//! Reading records for a command: unit conversions reported, the sanity
//! checks of `tacit::record::checks` run (with the model's predicted
//! response scale), warnings printed, and an error where the record cannot
//! be used at all.

use anyhow::{bail, Result};
use tacit::integrate::{Integrator, SimSettings};
use tacit::model::Model;
use tacit::record::checks::{self, CheckSettings, Finding, Severity};
use tacit::record::{Quantity, Record};
use tacit::signal::{force_matrix, rms_of};

/// Run every check of `rec` against `model`; print the warnings on
/// stderr; fail on a finding that makes the record unusable. `selected`:
/// the output DOFs the run uses (`None`: all). Returns the warnings, each
/// prefixed with the record's file name, for the report.
pub fn check(rec: &Record, model: &Model, selected: Option<&[usize]>) -> Result<Vec<String>> {
    let s = CheckSettings::default();
    let mut found = checks::check_record(rec, selected, &s);
    if !rec.inputs.is_empty() {
        found.extend(scale_finding(rec, model, &s));
        // a spike or a clipped run shifts a mean too: named already
        let shifted = found
            .iter()
            .any(|f| matches!(f.kind, checks::Kind::Spike | checks::Kind::Clipped));
        if !shifted {
            found.extend(
                balances(rec, model)
                    .iter()
                    .filter_map(|b| checks::momentum(b, &s)),
            );
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
    let force = force_matrix(rec, n);
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
            (c.name(), rms_of(&c.data), rms_of(&row))
        })
        .collect();
    checks::scale(&pairs, s)
}

/// The rigid-body momentum balances of a record: one per rigid-body mode
/// of a model with no element to ground and no damping of its rigid
/// motion, when every DOF the mode moves carries an accelerometer.
fn balances(rec: &Record, model: &Model) -> Vec<checks::Balance> {
    let grounded = model.springs.iter().any(|s| s.dofs.len() < 2)
        || model.contacts.iter().any(|c| c.dofs.len() < 2)
        || !model.frictions.is_empty()
        || model.cubics.iter().any(|c| c.dofs.len() < 2);
    let n = model.ndof();
    if grounded || rec.inputs.iter().chain(&rec.outputs).any(|c| c.dof > n) {
        return vec![];
    }
    let (m, k) = (model.mass_matrix(), model.stiffness_matrix());
    let (Ok(modes), Ok(c)) = (tacit::modal::solve(&m, &k), model.damping_matrix()) else {
        return vec![];
    };
    let mut out = vec![];
    for (r, _) in modes.rigid.iter().enumerate().filter(|(_, rigid)| **rigid) {
        // scaled to a largest entry of 1: a translation's coefficients are
        // the masses and the balance is in N
        let mut phi = modes.shapes.column(r).into_owned();
        let big = phi
            .iter()
            .copied()
            .fold(0.0f64, |a, x| if x.abs() > a.abs() { x } else { a });
        if big == 0.0 {
            continue;
        }
        phi /= big;
        let coef = m.transpose() * &phi;
        let scale = coef.amax();
        if (c.transpose() * &phi).amax() > 1e-9 * (c.amax() * phi.amax()).max(f64::MIN_POSITIVE) {
            continue;
        }
        let mut terms = vec![];
        let mut inertia = vec![0.0; rec.len()];
        for i in (0..n).filter(|&i| coef[i].abs() > 1e-9 * scale) {
            let Some(ch) = rec.output(Quantity::Accel, i + 1) else {
                return out;
            };
            terms.push((ch.name(), coef[i], mean(&ch.data)));
            for (s, a) in inertia.iter_mut().zip(&ch.data) {
                *s += coef[i] * a;
            }
        }
        let mut f = vec![0.0; rec.len()];
        for ch in &rec.inputs {
            for (fk, v) in f.iter_mut().zip(&ch.data) {
                *fk += phi[ch.dof - 1] * v;
            }
        }
        out.push(checks::Balance {
            terms,
            force_mean: mean(&f),
            force_rms: rms_of(&f),
            inertia_rms: rms_of(&inertia),
        });
    }
    out
}

fn mean(x: &[f64]) -> f64 {
    x.iter().sum::<f64>() / x.len().max(1) as f64
}
