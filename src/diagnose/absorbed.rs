//! A spring the calibration on the record moved far, beside a localized
//! effect the diagnosis then named: the calibration is suspected of having
//! absorbed that effect's equivalent linearization into the spring (a
//! contact stiffens the spring across its gap), and the diagnosis is run
//! again from a calibration with that spring held at its declared
//! stiffness ([`super::calibrated`] keeps the lower multiple-shooting error
//! on the record).
//!
//! The plausible range of the calibration
//! ([`crate::calibrate::CalibrationSettings::spring_factor`]) holds a
//! spring run out of it; within it, a spring's correction is suspect when
//! it is at least [`SUSPECT_CHANGE`] of its declared stiffness, at least
//! [`SUSPECT_RATIO`] times the median correction of the other springs (the
//! correction is localized, not the spread of a declared model a few per
//! cent off) and the spring shares a DOF with a nonlinear effect named by
//! a diagnosis (a stiffness or damping change is a linear correction, not
//! such an effect).

use crate::calibrate::{Calibration, Correction, LinearParam};
use crate::model::Model;
use crate::trace::{Candidate, EffectKind};

/// Relative correction of a spring (calibrated, or run to before it was
/// held) from which it may have absorbed a localized effect.
pub const SUSPECT_CHANGE: f64 = 0.2;

/// How many times the median correction of the other springs a suspect
/// spring's correction is at least.
pub const SUSPECT_RATIO: f64 = 4.0;

/// The spring (index into `model.springs`) the calibration is suspected of
/// having absorbed an effect into: the largest spring correction among
/// `corrections`, when it is at least [`SUSPECT_CHANGE`] and
/// [`SUSPECT_RATIO`] times the median of the others and the spring shares
/// a DOF with one of the nonlinear effects `named`; None otherwise.
pub fn suspect_spring(
    corrections: &[Correction],
    model: &Model,
    named: &[&Candidate],
) -> Option<usize> {
    let springs: Vec<(usize, f64)> = corrections
        .iter()
        .filter_map(|c| match c.parameter {
            LinearParam::Spring(i) => Some((i, moved(c))),
            _ => None,
        })
        .collect();
    let &(spring, largest) = springs.iter().max_by(|a, b| a.1.total_cmp(&b.1))?;
    let others = median(
        springs
            .iter()
            .filter(|(i, _)| *i != spring)
            .map(|(_, c)| *c)
            .collect(),
    )
    .unwrap_or(0.0);
    if largest < SUSPECT_CHANGE || largest < SUSPECT_RATIO * others {
        return None;
    }
    let (a, b) = model.springs.get(spring)?.ends();
    let beside = named
        .iter()
        .filter(|e| !matches!(e.kind, EffectKind::Stiffness | EffectKind::Damping))
        .any(|e| e.dofs.iter().any(|&k| k == a || Some(k) == b));
    beside.then_some(spring)
}

/// The size of a spring's correction: |value / declared − 1| of the value
/// the calibration gave it, or ran it to before holding it.
fn moved(c: &Correction) -> f64 {
    (c.ran_to.unwrap_or(c.calibrated) / c.declared - 1.0).abs()
}

/// `recalibrated` (with `spring` frozen, so not among its corrections) with
/// the spring's correction of `first` (the calibration that moved it)
/// added back: held at its declared stiffness, with the value it ran to.
pub fn with_held(mut recalibrated: Calibration, first: &Calibration, spring: usize) -> Calibration {
    let listed = |c: &&Correction| c.parameter == LinearParam::Spring(spring);
    if recalibrated.corrections.iter().any(|c| listed(&c)) {
        return recalibrated;
    }
    if let Some(c) = first.corrections.iter().find(listed) {
        recalibrated.corrections.push(Correction {
            calibrated: c.declared,
            change: 0.0,
            std_error: f64::INFINITY,
            significant: false,
            identifiable: false,
            held: true,
            ran_to: Some(c.ran_to.unwrap_or(c.calibrated)),
            ..c.clone()
        });
    }
    recalibrated
}

/// Median of `v` (None when empty).
fn median(mut v: Vec<f64>) -> Option<f64> {
    if v.is_empty() {
        return None;
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    Some(if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lanl() -> Model {
        let p = concat!(env!("CARGO_MANIFEST_DIR"), "/data/lanl8dof.toml");
        Model::from_file(std::path::Path::new(p)).unwrap()
    }

    /// Spring corrections (relative) of lanl8dof's seven springs; `held`:
    /// the one run out of range to `ran_to` (relative).
    fn corrections(changes: [f64; 7], held: Option<(usize, f64)>) -> Vec<Correction> {
        let m = lanl();
        changes
            .iter()
            .enumerate()
            .map(|(i, c)| {
                let declared = m.springs[i].stiffness;
                let h = held.filter(|(j, _)| *j == i);
                Correction {
                    name: format!("k{}", i + 1),
                    parameter: LinearParam::Spring(i),
                    unit: "N/m".into(),
                    declared,
                    calibrated: declared * (1.0 + c),
                    change: *c,
                    std_error: 1.0,
                    significant: true,
                    identifiable: true,
                    held: h.is_some(),
                    ran_to: h.map(|(_, r)| declared * (1.0 + r)),
                }
            })
            .collect()
    }

    #[test]
    fn a_large_localized_spring_correction_beside_an_effect_is_suspect() {
        let m = lanl();
        // the contact 3→2 (0-based DOFs 2, 1) beside spring k2 (DOFs 2–3)
        let contact = Candidate::new(EffectKind::Contact, vec![2, 1]);
        let c = corrections([0.03, 0.43, -0.01, 0.01, 0.0, 0.03, -0.02], None);
        assert_eq!(suspect_spring(&c, &m, &[&contact]), Some(1));
        // the same correction with the effect elsewhere: not suspect
        let far = Candidate::new(EffectKind::Contact, vec![6, 5]);
        assert_eq!(suspect_spring(&c, &m, &[&far]), None);
        // a stiffness change is a linear correction, not an effect
        let stiff = Candidate::new(EffectKind::Stiffness, vec![1, 2]);
        assert_eq!(suspect_spring(&c, &m, &[&stiff]), None);
        // corrections spread over every spring: not localized
        let spread = corrections([0.15, 0.3, -0.2, 0.12, 0.2, 0.1, -0.15], None);
        assert_eq!(suspect_spring(&spread, &m, &[&contact]), None);
        // a small one: not suspect
        let small = corrections([0.01, 0.08, 0.0, 0.0, 0.0, 0.01, 0.0], None);
        assert_eq!(suspect_spring(&small, &m, &[&contact]), None);
    }

    #[test]
    fn a_held_spring_is_suspect_by_the_value_it_ran_to() {
        let m = lanl();
        let cubic = Candidate::new(EffectKind::Cubic, vec![0, 1]);
        let c = corrections([0.0; 7], Some((0, 4.19)));
        assert_eq!(suspect_spring(&c, &m, &[&cubic]), Some(0));
    }
}
