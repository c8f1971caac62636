//! Table 4 of Hemez & Doebling (§6.1) as tests: each optimizer on the
//! paper's problem, every column on noise-free data, determinism.

use tacit::cases::table4;
use tacit::update::{self, FitSettings, Optimizer, Termination};

/// k3 within 0.5 points of −15 % and the cubic within 0.5 of +25 %.
fn assert_recovers(label: &str, pct: &[f64]) {
    assert!((pct[2] + 15.0).abs() < 0.5, "{label}: k3 {pct:?}");
    assert!((pct[4] - 25.0).abs() < 0.5, "{label}: cubic {pct:?}");
    for i in [0, 1, 3] {
        assert!(pct[i].abs() < 0.5, "{label}: k{} {pct:?}", i + 1);
    }
}

#[test]
fn every_column_recovers_the_truth_on_noise_free_data() {
    let case = table4::case(0.0, 11).unwrap();
    for col in table4::columns() {
        let p = table4::problem(&case, &col).unwrap();
        let r = update::fit(&p, &FitSettings::default()).unwrap();
        assert!(
            r.termination.converged(),
            "{}: {:?}",
            col.label,
            r.termination
        );
        let id = r.identifiability.as_ref().unwrap();
        assert!(id.all_determined, "{}: {}", col.label, id.verdict);
        assert_recovers(col.label, &r.percent_changes());
        let before = r.errors_before.as_ref().unwrap().overall;
        let after = r.errors_after.as_ref().unwrap().overall;
        assert!(
            before > 0.1 && after < 0.03,
            "{}: {before} -> {after}",
            col.label
        );
        // the reduced columns say how much the reduction leaves out
        assert_eq!(r.reduction_error.is_some(), col.reduction.is_some());
    }
}

#[test]
fn each_optimizer_solves_the_full_order_column() {
    let case = table4::case(0.0, 11).unwrap();
    let col = table4::columns()[2];
    for opt in [
        Optimizer::Lm,
        Optimizer::Gn,
        Optimizer::Bfgs,
        Optimizer::Simplex,
    ] {
        let p = table4::problem(&case, &col).unwrap();
        let r = update::fit(&p, &FitSettings::with(opt)).unwrap();
        assert!(
            matches!(r.termination, Termination::Converged { .. }),
            "{opt:?}: {:?}",
            r.termination
        );
        assert_recovers(&format!("{opt:?}"), &r.percent_changes());
        assert!(r.iterations > 0 && r.simulations > r.evaluations.min(1));
        // the cost history decreases
        let h = &r.cost_history;
        assert!(h.windows(2).all(|w| w[1] <= w[0]), "{opt:?}: {h:?}");
    }
}

#[test]
fn one_percent_noise_stays_within_its_predicted_scatter() {
    let case = table4::case(0.01, 3).unwrap();
    let col = table4::columns()[1];
    let p = table4::problem(&case, &col).unwrap();
    let r = update::fit(&p, &FitSettings::default()).unwrap();
    let id = r.identifiability.unwrap();
    for (i, truth) in table4::TRUE_CHANGE.iter().enumerate() {
        let err = r.parameters[i].percent_change - 100.0 * truth;
        let sd = 100.0 * id.parameters[i].std_scaled;
        assert!(
            err.abs() < 4.0 * sd + 0.3,
            "{}: error {err} std {sd}",
            r.parameters[i].name
        );
    }
}

#[test]
fn same_problem_same_result() {
    let case = table4::case(0.01, 5).unwrap();
    let p = table4::problem(&case, &table4::columns()[0]).unwrap();
    let a = update::fit(&p, &FitSettings::default()).unwrap();
    let b = update::fit(&p, &FitSettings::default()).unwrap();
    assert_eq!(a.x, b.x);
    assert_eq!(a.cost_history, b.cost_history);
    assert_eq!(a.simulations, b.simulations);
}
