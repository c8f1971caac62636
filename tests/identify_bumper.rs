//! The default method (MHE) on the simulated lanl8dof bumper record, the QP
//! solver against least squares, and constraints.

use tacit::identify::{
    identify, Constraints, IdentifySettings, Method, Problem, Reduce, Regularization, Solver,
    Status,
};
use tacit::integrate::SimSettings;
use tacit::model::Model;
use tacit::record::Record;
use tacit::simulate::{simulate_record, RecordSpec};

fn bumper_record(samples: usize) -> (Model, Record) {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/data/lanl8dof-contact.toml");
    let model = Model::from_file(path.as_ref()).unwrap();
    let spec = RecordSpec {
        samples,
        sensors: vec![1, 5, 6],
        // resolved contact (docs/theory.md, fact R5): 40 sub-steps for the "test"
        settings: SimSettings {
            substeps: 40,
            ..Default::default()
        },
        ..Default::default()
    };
    let (rec, _) = simulate_record(&model, &spec).unwrap();
    (model.linear_part(), rec)
}

/// Largest force RMS of the last three tenths over that of the first three.
fn growth(tenths: &[f64]) -> f64 {
    let first = tenths[..3].iter().cloned().fold(0.0, f64::max);
    let last = tenths[7..].iter().cloned().fold(0.0, f64::max);
    last / first
}

#[test]
fn mhe_default_holds_over_the_whole_bumper_record() {
    let (lin, rec) = bumper_record(4096);
    let prob = Problem::new(&lin, &rec, &[1, 5, 6]).unwrap();
    let est = identify(&prob, &IdentifySettings::default()).unwrap();
    assert_eq!(est.status, Status::Ok, "{:?}", est.warnings);
    let r = est.diagnostics.spectral_radius.unwrap();
    assert!(r < 1.0, "radius {r}");
    for c in &est.channels {
        assert!(
            c.error_before > 0.5,
            "{}: before {}",
            c.name,
            c.error_before
        );
        assert!(c.error_after < 0.05, "{}: after {}", c.name, c.error_after);
    }
    let g = growth(&est.diagnostics.force_rms_by_tenth);
    assert!(
        g < 3.0,
        "force grows: {:?}",
        est.diagnostics.force_rms_by_tenth
    );
    // the published scheme on the same record diverges (docs/theory.md, fact R1)
    let paper = identify(&prob, &IdentifySettings::paper(1.0)).unwrap();
    assert!(
        matches!(paper.status, Status::Diverged { .. }),
        "{:?}",
        paper.status
    );
}

#[test]
fn qp_without_constraints_agrees_with_least_squares() {
    let (lin, rec) = bumper_record(160);
    let prob = Problem::new(&lin, &rec, &[1, 5, 6]).unwrap();
    for (method, reduce) in [(Method::Paper, Reduce::Serep), (Method::Mhe, Reduce::None)] {
        let ls = IdentifySettings {
            method,
            reduce,
            horizon: 9,
            regularization: Regularization::Fixed(1e-2),
            ..Default::default()
        };
        let qp = IdentifySettings {
            solver: Solver::Qp,
            ..ls.clone()
        };
        let a = identify(&prob, &ls).unwrap();
        let b = identify(&prob, &qp).unwrap();
        let scale = a.force.amax();
        let diff = (&a.force - &b.force).amax();
        assert!(
            diff <= 1e-8 * scale,
            "{method:?}: |QP − LS| = {diff:e}, scale {scale:e}"
        );
        assert!(!matches!(b.status, Status::Failed { .. }), "{:?}", b.status);
    }
}

#[test]
fn qp_constraints_hold() {
    let (lin, rec) = bumper_record(120);
    let prob = Problem::new(&lin, &rec, &[1, 5, 6]).unwrap();
    let s = IdentifySettings {
        method: Method::Paper,
        reduce: Reduce::None,
        solver: Solver::Qp,
        regularization: Regularization::Fixed(1e-2),
        constraints: Constraints {
            pairs: vec![(5, 6)],
            push_apart: true,
            active: Some(vec![5, 6]),
            equilibrium: true,
            upper: vec![(5, 500.0)],
            ..Default::default()
        },
        ..Default::default()
    };
    let est = identify(&prob, &s).unwrap();
    assert!(
        !matches!(est.status, Status::Failed { .. }),
        "{:?}",
        est.status
    );
    for k in 0..prob.len() {
        let f = est.force.column(k);
        assert!((f[4] + f[5]).abs() < 1e-6, "pair at {k}: {f}");
        assert!(
            f[4] >= -1e-6 && f[4] <= 500.0 + 1e-6,
            "sign/bound at {k}: {f}"
        );
        for i in [0, 1, 2, 3, 6, 7] {
            assert!(f[i].abs() < 1e-6, "inactive DOF {} at {k}: {f}", i + 1);
        }
    }
}

/// 40960 samples (80 s): run with `cargo test --release --test identify_bumper -- --ignored`.
#[test]
#[ignore]
fn mhe_nothing_grows_over_40960_samples() {
    let (lin, rec) = bumper_record(40960);
    let prob = Problem::new(&lin, &rec, &[1, 5, 6]).unwrap();
    let est = identify(&prob, &IdentifySettings::default()).unwrap();
    let (b, a, r) = est.overall_errors();
    eprintln!(
        "40960 samples: status {:?}, radius {:?}, errors before {b:.3} after {a:.4} replay {r:.3}, force RMS by tenth {:?}, state/no-force by tenth {:?}, {:.3} s",
        est.status,
        est.diagnostics.spectral_radius,
        est.diagnostics.force_rms_by_tenth,
        est.diagnostics.state_ratio_by_tenth,
        est.timings.total
    );
    assert_eq!(est.status, Status::Ok, "{:?}", est.warnings);
    assert!(a < 0.05);
    assert!(growth(&est.diagnostics.force_rms_by_tenth) < 3.0);
    assert!(growth(&est.diagnostics.state_ratio_by_tenth) < 3.0);
}
