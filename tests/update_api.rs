//! The updating API: derivatives, the minimum-change term, bounds, errors,
//! failed simulations as status.

use approx::assert_relative_eq;
use tacit::integrate::SimSettings;
use tacit::model::Model;
use tacit::record::Quantity;
use tacit::update::{
    self, cost::Evaluator, optimize, parse_free, table4, FitSettings, Parameter, Problem, Target,
    Termination,
};

/// SDOF oscillator m = 1, k = 1e4 released from u0 = 1 mm, displacement
/// recorded: u(t) = u0 cos(ω t), ω = √(k/m).
fn sdof() -> (Model, Problem) {
    let model = Model::from_toml_str(
        "masses = [1.0]\n[[spring]]\ndofs = [1]\nstiffness = 1.0e4\n",
        "sdof",
    )
    .unwrap();
    let fs = 1000.0;
    let w = 100.0f64;
    let data: Vec<f64> = (0..100).map(|k| 1e-3 * (w * k as f64 / fs).cos()).collect();
    let rec = tacit::record::Record {
        t0: 0.0,
        fs,
        inputs: vec![],
        outputs: vec![tacit::record::Channel::new(Quantity::Disp, 1, data)],
        truth: None,
        source: Default::default(),
    };
    let params = vec![Parameter::relative(&model, Target::SpringStiffness(0)).unwrap()];
    let mut p = Problem::from_record(
        &model,
        &rec,
        &[Quantity::Disp],
        None,
        params,
        vec![1e-3],
        vec![0.0],
    )
    .unwrap();
    p.sim = SimSettings {
        substeps: 50,
        ..Default::default()
    };
    (model, p)
}

#[test]
fn finite_difference_jacobian_matches_the_analytic_derivative() {
    let (_, p) = sdof();
    let mut ev = Evaluator::new(&p);
    let x = [0.0];
    let r0 = ev.residual(&x).unwrap();
    let jac = optimize::jacobian(&mut ev, &x, &r0, &[-0.5], &[0.5], 1e-5).unwrap();
    // r = w (y − u), u = u0 cos(ω t), ω = √(k0 (1 + x)); ∂u/∂x = −u0 t sin(ω t) ω / 2
    let w = p.observations[0].weight;
    let omega = 100.0f64;
    for k in (1..100).step_by(7) {
        let t = k as f64 / 1000.0;
        let du = -1e-3 * t * (omega * t).sin() * omega / 2.0;
        assert_relative_eq!(
            jac[(k, 0)],
            -w * du,
            epsilon = 2e-3 * w * 1e-3,
            max_relative = 1e-2
        );
    }
    // and the data are matched at the nominal value
    assert!(r0.amax() < 1e-3);
}

#[test]
fn minimum_change_term_pulls_toward_the_nominal_values() {
    let case = table4::case(0.01, 2).unwrap();
    let col = table4::columns()[2];
    let mut last = f64::INFINITY;
    for alpha in [0.0, 1e-3, 1e-1, 10.0, 1e3] {
        let mut p = table4::problem(&case, &col).unwrap();
        p.metric = update::Metric::Gls;
        p.alpha = alpha;
        let r = update::fit(&p, &FitSettings::default()).unwrap();
        let norm = r.x.iter().map(|v| v * v).sum::<f64>().sqrt();
        assert!(norm < last, "alpha {alpha}: |x| {norm} not below {last}");
        last = norm;
    }
    assert!(last < 0.005, "alpha 1000 leaves |x| = {last}");
}

#[test]
fn bounds_hold() {
    let case = table4::case(0.0, 1).unwrap();
    let mut p = table4::problem(&case, &table4::columns()[2]).unwrap();
    // k3 may only go down to −10 %: the fit must stop there
    p.parameters[2] = p.parameters[2].clone().with_relative_bounds(-0.10, 0.5);
    for opt in [optimize::Optimizer::Lm, optimize::Optimizer::Simplex] {
        let r = update::fit(&p, &FitSettings::with(opt)).unwrap();
        let k3 = &r.parameters[2];
        assert!(
            k3.value >= k3.lower - 1e-9 * k3.lower,
            "{opt:?}: {}",
            k3.value
        );
        assert!(
            (k3.value - k3.lower) / k3.nominal < 1e-4,
            "{opt:?}: {:?}",
            k3
        );
        if opt == optimize::Optimizer::Lm {
            assert!(k3.at_bound, "{k3:?}");
        }
        for q in &r.parameters {
            assert!(q.value >= q.lower && q.value <= q.upper, "{opt:?}: {q:?}");
        }
    }
}

#[test]
fn bad_input_is_a_clear_error() {
    let case = table4::case(0.0, 1).unwrap();
    let m = &case.nominal;
    let e = parse_free("k9", m).unwrap_err().to_string();
    assert!(e.contains("'k9'") && e.contains("k1, k2, k3, k4"), "{e}");
    let e = parse_free("", m).unwrap_err().to_string();
    assert!(e.contains("empty"), "{e}");
    let e = parse_free("gap1", m).unwrap_err().to_string();
    assert!(e.contains("contacts"), "{e}");
    // negative stiffness as a bound or a nominal value
    let mut p = table4::problem(&case, &table4::columns()[2]).unwrap();
    p.parameters[1].lower = -1.0;
    let e = update::fit(&p, &FitSettings::default())
        .unwrap_err()
        .to_string();
    assert!(e.contains("parameter k2") && e.contains("> 0"), "{e}");
    let mut p = table4::problem(&case, &table4::columns()[2]).unwrap();
    p.parameters.clear();
    let e = update::fit(&p, &FitSettings::default())
        .unwrap_err()
        .to_string();
    assert!(e.contains("no free parameter"), "{e}");
    let mut p = table4::problem(&case, &table4::columns()[2]).unwrap();
    p.segments[0].u0.pop();
    let e = update::fit(&p, &FitSettings::default())
        .unwrap_err()
        .to_string();
    assert!(e.contains("segment 0"), "{e}");
    let mut p = table4::problem(&case, &table4::columns()[2]).unwrap();
    p.alpha = -1.0;
    assert!(update::fit(&p, &FitSettings::default())
        .unwrap_err()
        .to_string()
        .contains("alpha"));
}

#[test]
fn a_failed_simulation_is_a_status_not_a_number() {
    let case = table4::case(0.0, 1).unwrap();
    let mut p = table4::problem(&case, &table4::columns()[2]).unwrap();
    // a strongly softening cubic makes the response diverge at the start
    let cubic = &mut p.parameters[4];
    cubic.lower = -1e13;
    cubic.start = -1e13;
    let r = update::fit(&p, &FitSettings::default()).unwrap();
    assert!(
        matches!(r.termination, Termination::StartFailed { .. }),
        "{:?}",
        r.termination
    );
    assert!(r.cost_history.is_empty());
}
