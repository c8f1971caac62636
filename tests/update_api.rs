//! The updating API: derivatives, the minimum-change term, bounds, errors,
//! failed simulations as status.

use approx::assert_relative_eq;
use tacit::cases::table4;
use tacit::integrate::SimSettings;
use tacit::model::Model;
use tacit::record::Quantity;
use tacit::update::{
    self, cost::Evaluator, optimize, parse_free, FitSettings, Parameter, Problem, Target,
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

/// A small multiple-shooting problem: lanl8dof with its bumper (5→6), 0.3 N
/// friction at DOF 3 and modal damping, 600 samples in segments of 51 from
/// the true states, accelerations at 1, 5, 6 and displacements at 5, 6;
/// free gap, contact stiffness, friction level and spring k5.
fn shooting_problem() -> Problem {
    use tacit::model::Friction;
    use tacit::simulate::{simulate_record, RecordSpec};
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("data/lanl8dof-contact.toml");
    let mut truth = Model::from_file(&path).unwrap();
    truth.frictions = vec![Friction {
        dof: 3,
        level: 0.3,
        velocity: 1e-2,
    }];
    let spec = RecordSpec {
        samples: 600,
        sensors: vec![1, 5, 6],
        kinds: vec![Quantity::Accel, Quantity::Disp],
        ..Default::default()
    };
    let (rec, _) = simulate_record(&truth, &spec).unwrap();
    let params = vec![
        Parameter::relative(&truth, Target::ContactGap(0)).unwrap(),
        Parameter::relative(&truth, Target::ContactStiffness(0)).unwrap(),
        Parameter::relative(&truth, Target::FrictionLevel(0)).unwrap(),
        Parameter::relative(&truth, Target::SpringStiffness(4)).unwrap(),
    ];
    let n = truth.ndof();
    let mut p = Problem::from_record(
        &truth,
        &rec,
        &[Quantity::Accel, Quantity::Disp],
        Some(&[1, 5, 6]),
        params,
        vec![0.0; n],
        vec![0.0; n],
    )
    .unwrap();
    p.segments = update::shooting::from_truth(&rec, 51).unwrap();
    // Newton converged to rounding, so that the differences measure the
    // scheme and not the Newton tolerance
    p.sim.newton_tol = 1e-13;
    p
}

#[test]
fn sensitivity_jacobian_matches_finite_differences_on_a_shooting_problem() {
    let mut p = shooting_problem();
    assert_eq!(p.segments.len(), 12);
    // away from the truth, so that the residual is not zero
    let x = [0.12, -0.2, 0.3, 0.04];
    let (lo, hi) = ([-0.9; 4], [0.9; 4]);
    // reference: centered differences of the residual, Richardson-
    // extrapolated ((4 D(h/2) − D(h))/3), with a step per parameter: for the
    // gap and spring the largest that keeps the contact's open/closed
    // pattern in every segment (larger steps differ by 1–50 %), for the
    // friction level and contact stiffness, whose effect is small, the
    // smallest above the simulations' rounding noise
    let steps = [1e-4, 1e-3, 3e-3, 3e-5];
    for (metric, alpha, tol) in [
        (update::Metric::Gls, 0.0, 1e-6),
        (update::Metric::Gls, 0.5, 1e-6),
        (update::Metric::pcd(), 0.0, 3e-6),
    ] {
        p.metric = metric;
        p.alpha = alpha;
        let mut ev = Evaluator::new(&p);
        let r0 = ev.residual(&x).unwrap();
        let sims = ev.simulations;
        let js = ev.sensitivity_jacobian(&x, 1e-5).unwrap();
        // one simulation with sensitivities per segment for all parameters
        assert_eq!(ev.simulations - sims, 12);
        assert_eq!(ev.sensitivity_simulations, 12);
        let sims = ev.simulations;
        let mut fd = |h: f64| optimize::jacobian(&mut ev, &x, &r0, &lo, &hi, h).unwrap();
        for (j, &h) in steps.iter().enumerate() {
            let jf = (fd(h / 2.0) * 4.0 - fd(h)) / 3.0;
            assert_eq!(js.shape(), jf.shape());
            let (s, f) = (js.column(j), jf.column(j));
            let e = (s - f).norm() / f.norm();
            eprintln!(
                "{metric:?} alpha {alpha}: parameter {}: |J| {:.3e}, relative difference {e:.1e}",
                p.parameters[j].name,
                f.norm()
            );
            assert!(e < tol, "{metric:?}, parameter {j}: {e:e}");
        }
        assert_eq!(ev.simulations - sims, 4 * 2 * 2 * 4 * 12);
    }
}

#[test]
fn reduced_problems_fall_back_to_finite_differences_and_say_so() {
    let case = table4::case(0.0, 1).unwrap();
    let mut s = FitSettings {
        max_iterations: 1,
        ..Default::default()
    };
    let r = update::fit(&table4::problem(&case, &table4::columns()[0]).unwrap(), &s).unwrap();
    assert_eq!(r.jacobian, update::JacobianMethod::CentralDifference);
    assert!(r.jacobian_note.as_deref().unwrap().contains("reduced"));
    assert_eq!(r.sensitivity_simulations, 0);
    let r = update::fit(&table4::problem(&case, &table4::columns()[2]).unwrap(), &s).unwrap();
    assert_eq!(r.jacobian, update::JacobianMethod::Sensitivity);
    assert!(r.jacobian_note.is_none());
    // the optimizer's Jacobian and the identifiability report's: one
    // sensitivity simulation each (one segment)
    assert_eq!((r.jacobians, r.sensitivity_simulations), (2, 2));
    assert_eq!(r.sensitivity_fallbacks, 0);
    s.jacobian = update::JacobianMethod::CentralDifference;
    let r = update::fit(&table4::problem(&case, &table4::columns()[2]).unwrap(), &s).unwrap();
    assert_eq!(r.jacobian, update::JacobianMethod::CentralDifference);
    assert_eq!(r.sensitivity_simulations, 0);
}

#[test]
fn contact_jacobian_follows_the_computed_trajectory_at_the_default_newton_tolerance() {
    // the bumper fit of cases::contact_case (80 segments of 0.1 s, 40
    // sub-steps, default Newton tolerance 1e-10) on a grid of points around
    // the truth. Newton once accepted iterates within the tolerance across
    // the contact's switch from the side of its matrix; the computed
    // trajectory then jumped where a perturbation moved the penetration out
    // of the tolerance band, and the gap's differences disagreed with the
    // derivatives by 2-3 % (enough to stall Levenberg-Marquardt). Newton
    // now steps on to the point's own side: no such sub-step remains, and
    // the derivatives follow the differences everywhere on the grid.
    use tacit::integrate::{Integrator, Seeds};
    let p = tacit::cases::contact_case::case([0.0, 0.0])
        .unwrap()
        .shooting;
    // sub-steps across the switch, over all segments, at x
    let across_at = |x: &[f64]| -> usize {
        let model = p.model_at(x);
        let integ = Integrator::new(&model, p.fs, p.sim).unwrap();
        let seeds = Seeds::params(
            8,
            update::sensitivity::param_seeds(&model, &p.parameters).unwrap(),
        );
        p.segments
            .iter()
            .map(|s| {
                let f = p.force.columns(s.start, s.len);
                integ
                    .run_sensitivities(f, &s.u0, &s.v0, &seeds)
                    .unwrap()
                    .1
                    .newton_side_steps
            })
            .sum()
    };
    let grid = (0..9).map(|k| {
        [
            0.006 * (k % 3) as f64 + 0.013,
            0.006 * (k / 3) as f64 + 0.004,
        ]
    });
    let mut ev = Evaluator::new(&p);
    for x in grid.chain([[0.018958583497239268, 0.009842814501277523]]) {
        assert_eq!(across_at(&x), 0, "at {x:?}");
        let r0 = ev.residual(&x).unwrap();
        let js = ev.sensitivity_jacobian(&x, 1e-5).unwrap();
        // differences small enough (3.8e-10 m on the gap at 1e-6) to keep
        // every sub-step's contact pattern at most points; where a step
        // crosses a switch (a grazing contact) the differences at 1e-6 and
        // 1e-7 disagree by tens of percent, and the smaller step is right
        // (below 1e-8 rounding takes over)
        let (mut best, mut jbest) = (f64::INFINITY, None);
        for step in [1e-6, 1e-7] {
            let jf = optimize::jacobian(&mut ev, &x, &r0, &[-0.9; 2], &[0.9; 2], step).unwrap();
            let e = (0..2)
                .map(|j| (js.column(j) - jf.column(j)).norm() / jf.column(j).norm())
                .fold(0.0, f64::max);
            eprintln!("{x:?}, step {step:e}: relative difference {e:.1e}");
            if e < best {
                (best, jbest) = (e, Some(jf));
            }
        }
        assert!(best < 1e-3, "{x:?}: {best:e}");
        // the gradient of the cost, which the fit follows, agrees too
        let jf = jbest.unwrap();
        let (gs, gf) = (js.transpose() * &r0, jf.transpose() * &r0);
        assert!((gs[0] - gf[0]).abs() < 1e-2 * gf[0].abs(), "{gs} {gf}");
    }
}

/// The sensitivity Jacobian at the point just evaluated, replayed from the
/// tapes of that evaluation (`Evaluator::keep_tapes`), is the simulated
/// one bit for bit and runs no simulation; at another point it simulates.
#[test]
fn sensitivity_jacobian_from_the_evaluation_tapes_is_the_simulated_one() {
    let mut p = shooting_problem();
    // element parameters only (gap, contact stiffness, friction level)
    p.parameters.truncate(3);
    let x = [0.12, -0.2, 0.3];
    for metric in [update::Metric::Gls, update::Metric::pcd()] {
        p.metric = metric;
        let mut plain = Evaluator::new(&p);
        let r = plain.residual(&x).unwrap();
        let j = plain.sensitivity_jacobian(&x, 1e-5).unwrap();
        let mut taped = Evaluator::new(&p);
        taped.keep_tapes = true;
        assert_eq!(taped.residual(&x).unwrap(), r);
        let sims = taped.simulations;
        assert_eq!(taped.sensitivity_jacobian(&x, 1e-5).unwrap(), j);
        assert_eq!(
            taped.simulations, sims,
            "{metric:?}: replayed, not simulated"
        );
        // at a point not evaluated last: simulated, one run per segment
        let y = [0.1, -0.2, 0.3];
        let jy = plain.sensitivity_jacobian(&y, 1e-5).unwrap();
        assert_eq!(taped.sensitivity_jacobian(&y, 1e-5).unwrap(), jy);
        assert_eq!(taped.simulations, sims + p.segments.len());
    }
}

/// The start race ends where the fits of `fit_multistart` end, start by
/// start, in fewer simulations (no reports).
#[test]
fn race_ends_where_fit_multistart_ends() {
    let p = shooting_problem();
    let settings = FitSettings {
        max_iterations: 3,
        ..Default::default()
    };
    let starts = vec![vec![0.1, -0.1, 0.2, 0.02], vec![-0.05, 0.1, -0.2, 0.0]];
    let (_, full) = update::fit_multistart(&p, &settings, &starts).unwrap();
    let raced = update::race(&p, &settings, &starts).unwrap();
    assert_eq!(raced.len(), 2);
    for (r, f) in raced.iter().zip(&full) {
        assert_eq!(r.x, f.x);
        assert_eq!(r.cost_history, f.cost_history);
        assert_eq!(r.iterations, f.iterations);
        assert_eq!(
            format!("{:?}", r.termination),
            format!("{:?}", f.termination)
        );
        assert!(
            r.simulations < f.simulations,
            "{} vs {}",
            r.simulations,
            f.simulations
        );
    }
    // a start of the wrong length is an error naming it
    let e = update::race(&p, &settings, &[vec![0.0; 3]]).unwrap_err();
    assert!(e.to_string().contains("start 0 has 3 values"), "{e}");
}
