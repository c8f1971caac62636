//! The scoring of an exact model with a grazing clearance seen by three
//! accelerometers: the multiple-shooting error of the true model, with
//! its segments' start states refined, must come within 1.5 × the
//! measured noise (docs/calibration.md, "A grazing contact under three
//! sensors").

use tacit::diagnose::{diagnose, DiagnoseSettings};
use tacit::integrate::SimSettings;
use tacit::model::{Clearance, Damping, Model};
use tacit::simulate::{simulate_record, RecordSpec};

/// The record: its noise seed and length.
const SEED: u64 = 779091;
const SAMPLES: usize = 2048;

fn lanl() -> Model {
    let p = concat!(env!("CARGO_MANIFEST_DIR"), "/data/lanl8dof.toml");
    Model::from_file(std::path::Path::new(p)).unwrap()
}

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

fn record(m: &Model, seed: u64, samples: usize) -> tacit::record::Record {
    let spec = RecordSpec {
        samples,
        sensors: vec![2, 3, 7],
        noise: 0.01,
        seed,
        settings: SimSettings {
            substeps: 40,
            ..Default::default()
        },
        ..Default::default()
    };
    simulate_record(m, &spec).unwrap().0
}

#[test]
fn truth_scores_near_the_noise_under_three_sensors() {
    let m = truth();
    let rec = record(&m, SEED, SAMPLES);
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
