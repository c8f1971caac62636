//! End-to-end: a cubic spring from one mass to ground on the free-free
//! LANL structure (data/lanl8dof.toml), not declared, 1 % noise, all eight
//! accelerations. Under accelerations the reconstruction leaves the
//! rigid-body displacement to its prior, so the law is screened on the
//! identified force with the rigid-body wander fitted beside it
//! (`tacit::diagnose::ground`). Each must be named at its DOF with `k3`
//! within 10 % and end with a validation error at most 1.5 × the noise
//! measured on the record (and at most a fifth of the error before, on
//! both records).

mod diagnose_common;

use diagnose_common::{assert_improved_by, lanl, run};
use tacit::diagnose::Diagnosis;
use tacit::model::Cubic;

fn cubic_to_ground(dof: usize, k3: f64, seed: u64) -> Diagnosis {
    let mut truth = lanl();
    truth.cubics = vec![Cubic {
        dofs: vec![dof],
        k3,
    }];
    let d = run(&truth, &[1, 2, 3, 4, 5, 6, 7, 8], seed);
    assert_eq!(d.effects.len(), 1, "{}", d.verdict);
    let e = &d.effects[0];
    assert_eq!((e.kind.name(), e.dofs.clone()), ("cubic", vec![dof]));
    let x = e.parameters["k3"];
    assert!((x / k3 - 1.0).abs() <= 0.1, "k3 {x} vs {k3}");
    let noise = d.noise.as_ref().expect("noise measured").level;
    let v = d.validation.as_ref().unwrap().after.relative_error.unwrap();
    assert!(v <= 1.5 * noise, "validation {v} against noise {noise}");
    assert_improved_by(&d, 5.0, 5.0);
    d
}

#[test]
fn cubic_from_mass_6_to_ground() {
    cubic_to_ground(6, 8e11, 61);
}

#[test]
fn cubic_from_mass_1_to_ground() {
    cubic_to_ground(1, 3e11, 62);
}
