//! Checks of a record against the model it is used with, on top of the
//! model-free checks of [`super::checks`]: the response scale the linear
//! model predicts from the measured force (accelerations in g, force in
//! kN), and the rigid-body momentum balance of a free structure (an
//! accelerometer offset).
//!
//! [`check`] gives every finding; [`usable`] turns the errors among them
//! into one [`TacitError::Record`] and keeps the warnings. `tacit
//! diagnose`, `identify` and `modal`, `tacit campaign` and the Python
//! binding all run [`warnings`], so they report the same findings.

use super::checks::{self, Balance, CheckSettings, Finding, Kind, Severity};
use super::{Quantity, Record};
use crate::error::{Result, TacitError};
use crate::integrate::{Integrator, SimSettings};
use crate::model::Model;
use crate::signal::{force_matrix, rms_of};
use nalgebra::{DMatrix, DVector};

/// Every finding on `rec` used with `model`. `selected`: the output DOFs
/// the run uses (`None`: all).
pub fn check(
    rec: &Record,
    model: &Model,
    selected: Option<&[usize]>,
    s: &CheckSettings,
) -> Vec<Finding> {
    let mut found = checks::check_record(rec, selected, s);
    if rec.inputs.is_empty() {
        return found;
    }
    found.extend(scale_finding(rec, model, s));
    // a spike or a clipped run shifts a mean too: named already
    let shifted = found
        .iter()
        .any(|f| matches!(f.kind, Kind::Spike | Kind::Clipped));
    if !shifted {
        found.extend(
            balances(rec, model)
                .iter()
                .filter_map(|b| checks::momentum(b, s)),
        );
    }
    found
}

/// The warnings among `found`, or an error naming the record's file
/// (`<memory>` for a record built in memory) and every finding of
/// [`Severity::Error`].
pub fn usable(rec: &Record, found: Vec<Finding>) -> Result<Vec<Finding>> {
    let errors: Vec<&str> = found
        .iter()
        .filter(|f| f.severity == Severity::Error)
        .map(|f| f.message.as_str())
        .collect();
    if !errors.is_empty() {
        let file = match rec.source.as_os_str().is_empty() {
            true => std::path::Path::new("<memory>"),
            false => rec.source.as_path(),
        };
        return Err(TacitError::record(
            file,
            format!("cannot be used as it is: {}", errors.join("; ")),
        ));
    }
    Ok(found)
}

/// [`check`] with the default thresholds, then [`usable`].
pub fn warnings(rec: &Record, model: &Model, selected: Option<&[usize]>) -> Result<Vec<Finding>> {
    usable(rec, check(rec, model, selected, &CheckSettings::default()))
}

/// The warnings as a report carries them: `FILE: message`.
pub fn labelled(file: &str, found: &[Finding]) -> Vec<String> {
    found
        .iter()
        .map(|f| format!("{file}: {}", f.message))
        .collect()
}

/// The measured RMS of each acceleration (or velocity) channel against
/// the linear model's response to the record's force.
fn scale_finding(rec: &Record, model: &Model, s: &CheckSettings) -> Option<Finding> {
    let n = model.ndof();
    if rec.inputs.iter().chain(&rec.outputs).any(|c| c.dof > n) {
        return None;
    }
    let settings = SimSettings {
        substeps: 10,
        ..Default::default()
    };
    let integ = Integrator::new(&model.linear_part(), rec.fs, settings).ok()?;
    let zeros = vec![0.0; n];
    let sim = integ.run(force_matrix(rec, n).as_view(), &zeros, &zeros);
    if !sim.completed() {
        return None;
    }
    let kind = [Quantity::Accel, Quantity::Vel]
        .into_iter()
        .find(|q| rec.outputs.iter().any(|c| c.quantity == *q))?;
    let src = if kind == Quantity::Accel {
        &sim.a
    } else {
        &sim.v
    };
    let pairs: Vec<(String, f64, f64)> = rec
        .outputs
        .iter()
        .filter(|c| c.quantity == kind)
        .map(|c| {
            let row: Vec<f64> = src.row(c.dof - 1).iter().copied().collect();
            (c.name(), rms_of(&c.data), rms_of(&row))
        })
        .collect();
    checks::scale(&pairs, s)
}

/// The rigid-body momentum balances of a record: one per rigid-body mode
/// of a model with no element to ground and no damping of its rigid
/// motion, when every DOF the mode moves carries an accelerometer.
fn balances(rec: &Record, model: &Model) -> Vec<Balance> {
    let n = model.ndof();
    if model.has_ground_element() || rec.inputs.iter().chain(&rec.outputs).any(|c| c.dof > n) {
        return vec![];
    }
    let (m, k) = (model.mass_matrix(), model.stiffness_matrix());
    let (Ok(modes), Ok(c)) = (crate::modal::solve(&m, &k), model.damping_matrix()) else {
        return vec![];
    };
    let mut out = vec![];
    for (r, _) in modes.rigid.iter().enumerate().filter(|(_, rigid)| **rigid) {
        // scaled to a largest entry of 1: a translation's coefficients are
        // the masses and the balance is in N
        let phi = modes.shapes.column(r).into_owned();
        let big = phi
            .iter()
            .copied()
            .fold(0.0f64, |a, x| if x.abs() > a.abs() { x } else { a });
        if big == 0.0 || damps(&c, &(&phi / big)) {
            continue;
        }
        match balance(rec, &m, &(phi / big)) {
            Some(b) => out.push(b),
            None => return out,
        }
    }
    out
}

/// True when the damping matrix `c` resists the rigid motion `phi`.
fn damps(c: &DMatrix<f64>, phi: &DVector<f64>) -> bool {
    (c.transpose() * phi).amax() > 1e-9 * (c.amax() * phi.amax()).max(f64::MIN_POSITIVE)
}

/// The balance over the rigid-body mode `phi` (largest entry 1); `None`
/// when a DOF the mode moves has no accelerometer.
fn balance(rec: &Record, m: &DMatrix<f64>, phi: &DVector<f64>) -> Option<Balance> {
    let coef = m.transpose() * phi;
    let scale = coef.amax();
    let mut terms = vec![];
    let mut inertia = vec![0.0; rec.len()];
    for i in (0..m.nrows()).filter(|&i| coef[i].abs() > 1e-9 * scale) {
        let ch = rec.output(Quantity::Accel, i + 1)?;
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
    Some(Balance {
        terms,
        force_mean: mean(&f),
        force_rms: rms_of(&f),
        inertia_rms: rms_of(&inertia),
    })
}

fn mean(x: &[f64]) -> f64 {
    x.iter().sum::<f64>() / x.len().max(1) as f64
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    fn data(name: &str) -> std::path::PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("data")
            .join(name)
    }

    fn bumper() -> (Record, Model) {
        let rec = crate::record::read(&data("lanl8dof-bumper.h5")).unwrap();
        let model = Model::from_file(&data("lanl8dof.toml")).unwrap();
        (rec, model)
    }

    fn kinds(found: &[Finding]) -> Vec<Kind> {
        found.iter().map(|f| f.kind).collect()
    }

    #[test]
    fn the_shipped_record_has_no_finding() {
        let (rec, model) = bumper();
        assert_eq!(warnings(&rec, &model, None).unwrap(), vec![]);
    }

    #[test]
    fn accelerations_in_g_are_a_scale_warning_near_one_over_g() {
        let (mut rec, model) = bumper();
        for c in &mut rec.outputs {
            c.data
                .iter_mut()
                .for_each(|x| *x /= crate::record::units::G0);
        }
        let found = warnings(&rec, &model, None).unwrap();
        assert_eq!(kinds(&found), vec![Kind::Scale], "{found:?}");
        // the clean record's ratio is about 1.13 (docs/reliability.md)
        let r: f64 = found[0].message.split(" are ").nth(1).unwrap()[..5]
            .parse()
            .unwrap();
        assert!((r - 1.13 / 9.80665).abs() < 0.01, "{r}");
    }

    #[test]
    fn an_offset_is_named_through_the_momentum_balance() {
        let (mut rec, model) = bumper();
        let c = rec.outputs.iter_mut().find(|c| c.dof == 6).unwrap();
        c.data.iter_mut().for_each(|x| *x += 5.0);
        let found = warnings(&rec, &model, None).unwrap();
        let b = found.iter().find(|f| f.kind == Kind::Momentum).unwrap();
        assert_eq!(b.channel.as_deref(), Some("accel_6"), "{b:?}");
    }

    #[test]
    fn a_model_with_any_element_to_ground_has_no_momentum_balance() {
        let (rec, mut model) = bumper();
        assert_eq!(balances(&rec, &model).len(), 1);
        model.quadratics.push(crate::model::Quadratic {
            dofs: vec![8],
            k2: 1e6,
        });
        assert!(balances(&rec, &model).is_empty());
    }

    #[test]
    fn an_error_finding_names_the_file() {
        let (mut rec, model) = bumper();
        rec.outputs[0].data.fill(0.0);
        let e = warnings(&rec, &model, None).unwrap_err().to_string();
        assert!(e.starts_with("record "), "{e}");
        assert!(
            e.contains("lanl8dof-bumper.h5: cannot be used as it is: channel accel_1 is dead"),
            "{e}"
        );
    }
}
