//! Set-up shared by the end-to-end diagnosis tests (`diagnose_effects`,
//! `diagnose_added_effects`): records simulated from lanl8dof with an
//! effect the model file does not declare (2048 samples, 1 % noise, 40
//! sub-steps), diagnosed with the declared linear model and validated on a
//! second record. Each test crate uses part of it.
#![allow(dead_code)]

use rand::Rng;
use tacit::diagnose::{diagnose, DiagnoseSettings, Diagnosis};
use tacit::integrate::SimSettings;
use tacit::model::{Damping, Model};
use tacit::record::Record;
use tacit::simulate::{simulate_record, RecordSpec};

/// The declared model, `data/lanl8dof.toml`.
pub fn lanl() -> Model {
    let p = concat!(env!("CARGO_MANIFEST_DIR"), "/data/lanl8dof.toml");
    Model::from_file(std::path::Path::new(p)).unwrap()
}

/// lanl8dof as a test sees it: springs within ±3 % of nominal (seeded
/// with `seed`) and 2 % modal damping.
pub fn imperfect(seed: u64) -> Model {
    imperfect_with(seed, 0.03, 0.02)
}

/// lanl8dof with springs within ±`spread` of nominal (seeded with `seed`)
/// and modal damping `ratio` on every mode.
pub fn imperfect_with(seed: u64, spread: f64, ratio: f64) -> Model {
    let mut m = lanl();
    let mut g = tacit::signal::rng(seed);
    for s in &mut m.springs {
        s.stiffness *= 1.0 + spread * (2.0 * g.random::<f64>() - 1.0);
    }
    m.damping = Damping::Modal {
        ratio: Some(ratio),
        ratios: vec![],
    };
    m
}

/// The validation error after the diagnosis is at most 1.5 × the noise
/// measured on the record.
pub fn assert_validation_at_noise(d: &Diagnosis) {
    let noise = d.noise.as_ref().expect("noise measured").level;
    let v = d.validation.as_ref().unwrap().after.relative_error.unwrap();
    assert!(v <= 1.5 * noise, "validation {v} against noise {noise}");
}

/// A record of `truth` as these tests simulate it: `samples` samples,
/// every output at `sensors`, 1 % noise (seed `seed`), 40 sub-steps.
pub fn record(truth: &Model, sensors: &[usize], samples: usize, seed: u64) -> Record {
    record_at(truth, sensors, samples, seed, 40)
}

/// [`record`] integrated at `substeps` sub-steps per sample.
pub fn record_at(
    truth: &Model,
    sensors: &[usize],
    samples: usize,
    seed: u64,
    substeps: usize,
) -> Record {
    let spec = RecordSpec {
        samples,
        sensors: sensors.to_vec(),
        noise: 0.01,
        seed,
        settings: SimSettings {
            substeps,
            ..Default::default()
        },
        ..Default::default()
    };
    simulate_record(truth, &spec).unwrap().0
}

/// A record of `truth` at `sensors` as `examples/imperfect_matrix.rs`
/// simulates it: 4096 samples, 1 % noise (seed `seed`), 400 sub-steps per
/// sample (standing for the continuous structure).
pub fn matrix_record(truth: &Model, sensors: &[usize], seed: u64) -> Record {
    record_at(truth, sensors, 4096, seed, 400)
}

/// The calibrated diagnosis of `rec` against lanl8dof without a linear
/// record (default settings), validated on `val`; its calibration notes
/// printed.
pub fn calibrated_without_linear_record(rec: &Record, val: &Record) -> Diagnosis {
    use tacit::diagnose::calibrated::{diagnose_calibrated, CalibratedSettings};
    let d = diagnose_calibrated(
        &lanl(),
        rec,
        Some(val),
        &[],
        None,
        &DiagnoseSettings::default(),
        &CalibratedSettings::default(),
        &|_| {},
    )
    .unwrap();
    let cal = d.calibration.as_ref().expect("calibrated");
    eprintln!("{}\n{}", cal.refinement, cal.choice);
    d
}

/// The record (seed `seed`) and the validation record (seed `seed + 1000`)
/// of `truth` at `sensors`, 2048 samples each.
pub fn records(truth: &Model, sensors: &[usize], seed: u64) -> (Record, Record) {
    (
        record(truth, sensors, 2048, seed),
        record(truth, sensors, 2048, seed + 1000),
    )
}

/// The records of `truth` diagnosed with the declared model (default
/// settings); the verdict, errors and effects printed.
pub fn run(truth: &Model, sensors: &[usize], seed: u64) -> Diagnosis {
    let (rec, val) = records(truth, sensors, seed);
    let mut settings = DiagnoseSettings::default();
    settings.noise.measure = std::env::var("NOMEASURE").is_err();
    let d = diagnose(&lanl(), &rec, Some(&val), None, &settings, &|_| {}).unwrap();
    eprintln!(
        "{} | before {:?} after {:?} | validation {:?} → {:?}",
        d.verdict,
        d.before.relative_error,
        d.after.relative_error,
        d.validation.as_ref().map(|v| v.before.relative_error),
        d.validation.as_ref().map(|v| v.after.relative_error)
    );
    if let Some(n) = &d.noise {
        eprintln!(
            "  noise measured {:.3} % (assumed {:.3} %)",
            100.0 * n.level,
            100.0 * n.assumed
        );
    }
    for e in &d.effects {
        eprintln!("  {} {:?}", e.label, e.parameters);
    }
    d
}

/// The multiple-shooting error falls by at least `on_record` on the record
/// and `on_validation` on the validation record.
pub fn assert_improved_by(d: &Diagnosis, on_record: f64, on_validation: f64) {
    let (b, a) = (
        d.before.relative_error.unwrap(),
        d.after.relative_error.unwrap(),
    );
    assert!(a <= b / on_record, "relative_error {b} → {a}");
    let v = d.validation.as_ref().unwrap();
    let (b, a) = (
        v.before.relative_error.unwrap(),
        v.after.relative_error.unwrap(),
    );
    assert!(
        a <= b / on_validation,
        "validation relative_error {b} → {a}"
    );
}
