//! The scoring of an exact model with a grazing clearance seen by three
//! accelerometers: the multiple-shooting error of the true model, with
//! its segments' start states refined, must come within 1.5 × the
//! measured noise (docs/calibration.md, "A grazing contact under three
//! sensors").

mod diagnose_common;

use diagnose_common::{lanl, record};
use tacit::diagnose::{diagnose, DiagnoseSettings};
use tacit::model::{Clearance, Damping, Model};

/// The record: its noise seed and length.
const SEED: u64 = 779091;
const SAMPLES: usize = 2048;

/// lanl8dof with 2.5 % modal damping and a clearance 2–3 of ±0.15 mm,
/// 1e6 N/m: the relative motion of masses 2 and 3 grazes the gap.
fn truth() -> Model {
    let mut m = lanl();
    m.damping = Damping::Modal {
        ratio: Some(0.025),
        ratios: vec![],
    };
    m.clearances.push(Clearance {
        dofs: vec![2, 3],
        gap: 0.15e-3,
        stiffness: 1e6,
    });
    m
}

#[test]
fn truth_scores_near_the_noise_under_three_sensors() {
    let m = truth();
    let rec = record(&m, &[2, 3, 7], SAMPLES, SEED);
    let d = diagnose(&m, &rec, None, None, &DiagnoseSettings::default(), &|_| {}).unwrap();
    let noise = d.noise.as_ref().unwrap().level;
    let e = d.before.relative_error.unwrap();
    eprintln!(
        "truth {:.2} % against the measured noise {:.2} %; starts {:?}",
        100.0 * e,
        100.0 * noise,
        d.before.starts
    );
    assert!(
        e < 1.5 * noise,
        "the true model scores {:.2} % against the measured noise {:.2} %",
        100.0 * e,
        100.0 * noise
    );
}
