//! The bridge to the window method's types: a horizon answer on an
//! `identify::Problem` / `System` becomes a `ForceEstimate` the shared
//! writers accept (full order and SEREP-reduced).

mod horizon_common;
use horizon_common::*;
use tacit::horizon::convert::identify_problem;
use tacit::horizon::{NoiseLevel, WeightSelection};
use tacit::identify::{output, Problem, Reduce, System};
use tacit::integrate::SimSettings;
use tacit::record::Quantity;
use tacit::simulate::{simulate_record, RecordSpec};

#[test]
fn horizon_result_goes_through_the_shared_writers() {
    let mut model = lanl8dof("lanl8dof-contact");
    model.contacts[0].gap = 0.6e-3;
    model.contacts[0].stiffness = 2e5;
    let spec = RecordSpec {
        samples: 1024,
        sensors: vec![1, 5, 6],
        kinds: vec![Quantity::Accel],
        noise: 0.01,
        settings: SimSettings {
            substeps: 40,
            ..SimSettings::default()
        },
        ..RecordSpec::default()
    };
    let (rec, _) = simulate_record(&model, &spec).unwrap();
    let prob = Problem::new(&model.linear_part(), &rec, &[1, 5, 6]).unwrap();
    let mut s = settings();
    s.selection = WeightSelection::Discrepancy {
        noise: NoiseLevel::Known,
        tau: 1.0,
    };
    for reduce in [Reduce::None, Reduce::Serep] {
        let sys = System::new(&prob, reduce, 40).unwrap();
        let (res, est) = identify_problem(&prob, &sys, &[], &s).unwrap();
        assert_eq!(est.method, "horizon");
        assert_eq!(est.force.shape(), (8, 1024));
        assert!(est.force_std.is_some());
        // the coefficients are the internal force in the window convention
        assert!((est.force.row(4) - res.force.row(4)).amax() < 1e-12);
        let (before, after, _) = est.overall_errors();
        eprintln!(
            "{reduce:?}: error before {before:.3}, after {after:.4}; corr f5 {:.3}",
            corr(
                est.force.row(4).transpose().as_slice(),
                &rec.truth.as_ref().unwrap().fint[4]
            )
        );
        assert!(after < before);
        let dir = tempfile::tempdir().unwrap();
        let files = output::write_all(&est, dir.path(), false).unwrap();
        assert!(files.iter().all(|f| f.exists()), "{files:?}");
    }
}
