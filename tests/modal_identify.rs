//! Modes identified by tacit (H1 + LSCF/LSFD) from simulated records of
//! the LANL 8-DOF testbed, against the model's own modes.

use std::path::Path;
use tacit::correlate::{self, FitSettings, FitStatus, FrfSettings, ModalTest};
use tacit::model::Model;

fn nominal() -> Model {
    let p = concat!(env!("CARGO_MANIFEST_DIR"), "/data/lanl8dof.toml");
    Model::from_file(Path::new(p)).unwrap()
}

/// One linear record: random force at DOF 1, 16 s at 512 Hz, accelerations
/// at all 8 DOFs, no noise. Every flexible mode within 0.5 % in frequency
/// and with a MAC above 0.99; shapes mass-normalized through the driving
/// point.
#[test]
fn linear_record_gives_the_model_modes() {
    let model = nominal();
    let test = ModalTest {
        records: 1,
        samples: 8192,
        ..ModalTest::linear()
    };
    let recs = test.simulate(&model).unwrap();
    let sensors: Vec<usize> = (1..=8).collect();
    let id = correlate::identify_records(
        &recs,
        None,
        &sensors,
        &FrfSettings::default(),
        &FitSettings::default(),
    )
    .unwrap();
    assert_eq!(id.fit.status, FitStatus::Identified);
    assert!(id.fit.mass_normalized);
    let t = id.fit.test_modes("linear", 8).unwrap();
    assert_eq!(t.modes.len(), 7, "{:?}", t.modes);
    let modes = tacit::modal::solve(&model.mass_matrix(), &model.stiffness_matrix()).unwrap();
    let corr = correlate::correlate(&t, &modes, &Default::default()).unwrap();
    assert_eq!(corr.pairs.len(), 7);
    for p in &corr.pairs {
        assert_eq!(p.test_mode, p.model_mode);
        assert!(p.freq_error_pct.abs() < 0.5, "{p:?}");
        assert!(p.mac > 0.99, "{p:?}");
    }
    // mass normalization: the first flexible mode's driving-point entry
    let (phi, _) = correlate::mac::flexible_at(&modes, &[1]).unwrap();
    let rel = (t.modes[0].shape[0].abs() - phi[(0, 0)].abs()).abs() / phi[(0, 0)].abs();
    assert!(
        rel < 0.05,
        "driving point {} vs {}",
        t.modes[0].shape[0],
        phi[(0, 0)]
    );
    // damping: the model has 1 % on every mode
    for m in &t.modes {
        assert!((m.damping - 0.01).abs() < 0.005, "{m:?}");
    }
}

/// The paper's sensing (accelerometers at 1, 4, 7 only, shaker at 1).
#[test]
fn sensors_1_4_7() {
    let model = nominal();
    let test = ModalTest {
        records: 1,
        samples: 8192,
        sensors: vec![1, 4, 7],
        ..ModalTest::linear()
    };
    let recs = test.simulate(&model).unwrap();
    let id = correlate::identify_records(
        &recs,
        Some(1),
        &[1, 4, 7],
        &FrfSettings::default(),
        &FitSettings::default(),
    )
    .unwrap();
    let t = id.fit.test_modes("147", 8).unwrap().first(5);
    let modes = tacit::modal::solve(&model.mass_matrix(), &model.stiffness_matrix()).unwrap();
    let corr = correlate::correlate(&t, &modes, &Default::default()).unwrap();
    assert_eq!(corr.pairs.len(), 5);
    for p in &corr.pairs {
        assert!(p.freq_error_pct.abs() < 0.5 && p.mac > 0.99, "{p:?}");
    }
}

/// Friction (0.3 N at every mass) and 1 % noise, five 8-s records as in
/// the LANL test plan: the modes are still found (within 0.5 %, MAC > 0.99)
/// and the friction shows as extra damping, most on the first mode.
#[test]
fn friction_and_noise_like_the_paper() {
    let model = nominal();
    let (t, id) =
        correlate::identified_modes(&model, &ModalTest::like_the_paper(), "f", 5).unwrap();
    assert_eq!(id.frf.averages, 15);
    let modes = tacit::modal::solve(&model.mass_matrix(), &model.stiffness_matrix()).unwrap();
    let corr = correlate::correlate(&t, &modes, &Default::default()).unwrap();
    assert_eq!(corr.pairs.len(), 5);
    for p in &corr.pairs {
        assert!(p.freq_error_pct.abs() < 0.5 && p.mac > 0.99, "{p:?}");
    }
    assert!(t.modes[0].damping > 0.015, "{:?}", t.modes[0]);
    assert!(t.modes[0].damping > t.modes[4].damping);
}

/// Bad records and settings give errors that name the channel or rule.
#[test]
fn bad_input_is_reported() {
    let model = nominal();
    let test = ModalTest {
        records: 1,
        samples: 4096,
        sensors: vec![1, 4],
        ..ModalTest::linear()
    };
    let recs = test.simulate(&model).unwrap();
    let e = correlate::identify_records(
        &recs,
        Some(1),
        &[1, 5],
        &FrfSettings::default(),
        &FitSettings::default(),
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("accel_5"), "{e}");
    let e = correlate::identify_records(
        &recs,
        Some(2),
        &[1],
        &FrfSettings::default(),
        &FitSettings::default(),
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("force channel at DOF 2"), "{e}");
    let fit = FitSettings {
        band_hz: (5.0, 300.0),
        ..Default::default()
    };
    let e = correlate::identify_records(&recs, Some(1), &[1], &FrfSettings::default(), &fit)
        .unwrap_err()
        .to_string();
    assert!(e.contains("fs/2"), "{e}");
    let frf = FrfSettings {
        segment: 8192,
        ..Default::default()
    };
    let e = correlate::identify_records(&recs, Some(1), &[1], &frf, &FitSettings::default())
        .unwrap_err()
        .to_string();
    assert!(e.contains("shorter than one FRF segment"), "{e}");
}
