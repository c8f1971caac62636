//! MAC, pairing, frequency error and test-mode files.

use std::path::Path;
use tacit::correlate::{self, mac, TestMode, TestModes};
use tacit::model::Model;

fn nominal() -> Model {
    let p = concat!(env!("CARGO_MANIFEST_DIR"), "/data/lanl8dof.toml");
    Model::from_file(Path::new(p)).unwrap()
}

#[test]
fn mac_of_a_mode_with_itself_is_one_and_with_an_orthogonal_shape_zero() {
    let model = nominal();
    let modes = tacit::modal::solve(&model.mass_matrix(), &model.stiffness_matrix()).unwrap();
    for r in 1..8 {
        let phi: Vec<f64> = modes.shapes.column(r).iter().copied().collect();
        approx::assert_relative_eq!(mac(&phi, &phi).unwrap(), 1.0, epsilon = 1e-14);
        let neg: Vec<f64> = phi.iter().map(|v| -3.0 * v).collect();
        approx::assert_relative_eq!(mac(&phi, &neg).unwrap(), 1.0, epsilon = 1e-14);
        // M φ_r is orthogonal to every other mode (mass orthogonality)
        let mphi = model.mass_matrix() * modes.shapes.column(r);
        for s in 0..8 {
            if s != r {
                let other: Vec<f64> = modes.shapes.column(s).iter().copied().collect();
                let m: Vec<f64> = mphi.iter().copied().collect();
                assert!(mac(&m, &other).unwrap() < 1e-20);
            }
        }
    }
    assert_eq!(mac(&[1.0, 1.0], &[1.0, -1.0]).unwrap(), 0.0);
}

#[test]
fn wrong_lengths_and_unknown_dofs_are_errors() {
    let e = mac(&[1.0, 2.0, 3.0], &[1.0]).unwrap_err().to_string();
    assert!(e.contains("3 and 1"), "{e}");
    let bad = TestModes::new(
        "t",
        vec![1, 4, 7],
        vec![TestMode {
            frequency_hz: 20.0,
            damping: 0.01,
            shape: vec![1.0, 0.5],
        }],
        false,
        8,
    )
    .unwrap_err()
    .to_string();
    assert!(
        bad.contains("mode 1") && bad.contains("2 values for 3 DOFs"),
        "{bad}"
    );
    let bad = TestModes::new(
        "t",
        vec![1, 9],
        vec![TestMode {
            frequency_hz: 20.0,
            damping: 0.0,
            shape: vec![1.0, 0.5],
        }],
        false,
        8,
    )
    .unwrap_err()
    .to_string();
    assert!(bad.contains("DOF 9"), "{bad}");
    let text = "dofs = [\"dof1\", \"mass4\"]\n[[mode]]\nfrequency_hz = 22.0\nshape = [1.0, 0.2]\n";
    let e = TestModes::from_toml_str(text, "modes.toml", 8)
        .unwrap_err()
        .to_string();
    assert!(e.contains("modes.toml") && e.contains("mass4"), "{e}");
    let t = correlate::model_test_modes(&nominal(), &[1, 4, 7], 5).unwrap();
    let e = t.restrict(&[1, 5]).unwrap_err().to_string();
    assert!(e.contains("DOF 5 was not measured"), "{e}");
}

/// Table 2's structure: the damaged testbed's modes against the nominal
/// model. The damage lowers every frequency (positive error with the
/// paper's sign convention model − test), most for the modes that strain
/// spring 5; MACs stay above 98 %.
#[test]
fn damaged_vs_nominal_like_table2() {
    let model = nominal();
    let damaged = correlate::with_spring_change(&model, "k5", -0.14).unwrap();
    let t = correlate::model_test_modes(&damaged, &[1, 4, 7], 5).unwrap();
    let modes = tacit::modal::solve(&model.mass_matrix(), &model.stiffness_matrix()).unwrap();
    let c = correlate::correlate(&t, &modes, &Default::default()).unwrap();
    assert_eq!(c.pairs.len(), 5);
    for p in &c.pairs {
        assert_eq!(p.test_mode, p.model_mode);
        assert!(p.freq_error_pct > 0.0 && p.freq_error_pct < 2.5, "{p:?}");
        assert!(p.mac > 0.98, "{p:?}");
    }
    // mode 4 strains spring 5 most (paper: largest error, lowest MAC)
    let worst = c
        .pairs
        .iter()
        .max_by(|a, b| a.freq_error_pct.total_cmp(&b.freq_error_pct))
        .unwrap();
    assert_eq!(worst.test_mode, 4);
    assert!(correlate::with_spring_change(&model, "k9", -0.1).is_err());
}

#[test]
fn test_modes_file_round_trip() {
    let t = correlate::model_test_modes(&nominal(), &[1, 4, 7], 3).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("modes.toml");
    std::fs::write(&p, t.to_toml_string()).unwrap();
    let back = TestModes::from_file(&p, 8).unwrap();
    assert_eq!(back, t);
    let e = TestModes::from_file(&p, 6).unwrap_err().to_string();
    assert!(e.contains("7") && e.contains("1..=6"), "{e}");
}
