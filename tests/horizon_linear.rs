//! Full-horizon identification on linear records made with the exact
//! sampled model: known forces come back, a record without a missing force
//! gives no force (docs/theory.md, fact R7), ±2σ bands cover at the nominal rate,
//! long records stay bounded, records that do not start at rest are
//! handled by estimating x0, and the weight rules and the QP behave.

mod horizon_common;
use horizon_common::*;
use nalgebra::{DMatrix, DVector};
use tacit::horizon::{
    identify, solve, unknown_at_dofs, ChannelNoise, CovarianceScale, HorizonStatus, InitialState,
    NoiseLevel, WeightSelection,
};

fn rms(x: &[f64]) -> f64 {
    (x.iter().map(|v| v * v).sum::<f64>() / x.len() as f64).sqrt()
}

/// Truth forces at DOFs 5, 6: band-limited random, 5 N RMS.
fn band_forces(len: usize) -> DMatrix<f64> {
    let a = tacit::signal::random_band(len, FS, (2.0, 60.0), 5.0, 21).unwrap();
    let b = tacit::signal::random_band(len, FS, (2.0, 60.0), 5.0, 22).unwrap();
    DMatrix::from_fn(2, len, |i, k| if i == 0 { a[k] } else { b[k] })
}

#[test]
fn known_forces_come_back_on_linear_data() {
    let sm = sampled();
    let len = 2000;
    let bu = unknown_at_dofs(8, &[4, 5]).unwrap();
    let w = band_forces(len);
    let (g, y, _) = linear_record(&sm, len, &bu, &w, &DVector::zeros(16), &[1e-3; 3], 3);
    let ch = channels();
    let d = data(&g, &y, &ch, &bu);
    let mut s = settings();
    s.noise = ChannelNoise::Std { std: vec![1e-3; 3] };
    s.initial = InitialState::Rest;
    let r = solve(&sm, &d, &s, 1e-2, 0.0, false).unwrap();
    assert_eq!(r.status, HorizonStatus::Solved);
    let e = (&r.force - &w).norm() / w.norm();
    eprintln!(
        "relative force error {e:.2e}, relative residual {:.2e}",
        r.diagnostics.relative_residual_total
    );
    assert!(e < 0.02, "relative force error {e}");
}

#[test]
fn no_false_force_on_a_linear_record() {
    // fact 7: a textbook AKF reported 2–18 N of force that is not there
    let sm = sampled();
    let len = 4096;
    let bu = unknown_at_dofs(8, &[0, 1, 2, 3, 4, 5, 6, 7]).unwrap();
    let w = DMatrix::zeros(8, len);
    let (g, y0, _) = linear_record(&sm, len, &bu, &w, &DVector::zeros(16), &[0.0; 3], 4);
    // 1 % noise of each channel's RMS
    let sd: Vec<f64> = (0..3)
        .map(|r| 0.01 * rms(y0.row(r).transpose().as_slice()))
        .collect();
    let (g, y, _) = {
        let (_, y, xs) = linear_record(&sm, len, &bu, &w, &DVector::zeros(16), &sd, 4);
        (g, y, xs)
    };
    let ch = channels();
    let d = data(&g, &y, &ch, &bu);
    // 8 unknowns per sample, 3 measurements: GCV interpolates the noise
    // (tr H → N p); the discrepancy principle with the known 1 % noise does not
    let mut s = settings();
    s.selection = WeightSelection::Discrepancy {
        noise: NoiseLevel::Known,
        tau: 1.0,
    };
    s.selection_decades = 4.0;
    s.selection_points_per_decade = 1;
    let r = identify(&sm, &d, &s).unwrap();
    let per_dof: Vec<f64> = (0..8)
        .map(|i| rms(r.force.row(i).transpose().as_slice()))
        .collect();
    let worst = per_dof.iter().cloned().fold(0.0, f64::max);

    eprintln!(
        "false force RMS per DOF (N): {per_dof:.3?}; λ = {:.3e}",
        r.weights.lambda
    );
    assert!(worst < 1.0, "false force {worst} N");
}

#[test]
fn two_sigma_band_covers_at_the_nominal_rate() {
    let sm = sampled();
    let len = 3000;
    let sf = 2.0;
    let sn = 0.2;
    let bu = unknown_at_dofs(8, &[4, 5]).unwrap();
    let w = white(2, len, sf, 77);
    let mut x0 = DVector::zeros(16);
    x0[12] = 5e-3;
    let (g, y, _) = linear_record(&sm, len, &bu, &w, &x0, &[sn; 3], 78);
    let ch = channels();
    let d = data(&g, &y, &ch, &bu);
    let mut s = settings();
    s.noise = ChannelNoise::Std { std: vec![sn; 3] };
    s.covariance_scale = CovarianceScale::Model;
    s.initial = InitialState::Estimate {
        mean: vec![],
        std_disp: 1e-2,
        std_vel: 1e-1,
    };
    let r = solve(&sm, &d, &s, 1.0 / (sf * sf), 0.0, true).unwrap();
    let sd = r.force_std.as_ref().unwrap();
    let mut inside = 0;
    for k in 0..len {
        for i in 0..2 {
            if (r.force[(i, k)] - w[(i, k)]).abs() <= 2.0 * sd[(i, k)] {
                inside += 1;
            }
        }
    }
    let rate = inside as f64 / (2 * len) as f64;
    eprintln!(
        "±2σ coverage {rate:.4} (nominal 0.9545); std {:.3} N; variance factor {:.3}",
        sd[(0, len / 2)],
        r.diagnostics.variance_factor
    );
    assert!((0.935..=0.975).contains(&rate), "coverage {rate}");
    assert!((r.diagnostics.variance_factor - 1.0).abs() < 0.1);
}

#[test]
fn a_long_record_stays_bounded() {
    let sm = sampled();
    let len = 100_000;
    let bu = unknown_at_dofs(8, &[4, 5]).unwrap();
    let w = band_forces(len);
    let (g, y, _) = linear_record(&sm, len, &bu, &w, &DVector::zeros(16), &[0.1; 3], 9);
    let ch = channels();
    let d = data(&g, &y, &ch, &bu);
    let mut s = settings();
    s.noise = ChannelNoise::Std { std: vec![0.1; 3] };
    let r = solve(&sm, &d, &s, 1e-2, 0.0, true).unwrap();
    assert_eq!(r.status, HorizonStatus::Solved, "{:?}", r.notes);
    let tenth = len / 10;
    let err: Vec<f64> = (0..10)
        .map(|t| {
            let a = r.force.columns(t * tenth, tenth) - w.columns(t * tenth, tenth);
            a.norm() / w.columns(t * tenth, tenth).norm()
        })
        .collect();
    let sd = r.force_std.as_ref().unwrap();
    eprintln!(
        "relative force error by tenth {err:.3?}; transient {} samples; covariance held from {:?}; std {:.3} / {:.3} N; {:.3} s",
        r.diagnostics.riccati_transient,
        r.diagnostics.covariance_held_from,
        sd[(0, 10)],
        sd[(0, len / 2)],
        r.timings.total
    );
    let (lo, hi) = err
        .iter()
        .fold((f64::MAX, 0.0f64), |(a, b), &e| (a.min(e), b.max(e)));
    assert!(hi < 0.2 && hi < 1.5 * lo, "errors by tenth {err:?}");
    assert!(r.diagnostics.riccati_transient < 10_000);
    assert!(r.states.iter().all(|v| v.is_finite()));
    assert!(sd.iter().all(|v| v.is_finite() && *v > 0.0));
}

#[test]
fn a_record_not_at_rest_is_handled_by_estimating_x0() {
    let sm = sampled();
    let len = 1500;
    let bu = unknown_at_dofs(8, &[4, 5]).unwrap();
    let w = band_forces(len);
    let mut x0 = DVector::zeros(16);
    for i in 0..8 {
        x0[i] = 2e-4 * ((i as f64) * 0.7).sin();
        x0[8 + i] = 0.05 * ((i as f64) * 1.3).cos();
    }
    let (g, y, xs) = linear_record(&sm, len, &bu, &w, &x0, &[0.05; 3], 10);
    let ch = channels();
    let d = data(&g, &y, &ch, &bu);
    let mut s = settings();
    s.noise = ChannelNoise::Std { std: vec![0.05; 3] };
    let est = solve(&sm, &d, &s, 1e-2, 0.0, false).unwrap();
    s.initial = InitialState::Rest;
    let rest = solve(&sm, &d, &s, 1e-2, 0.0, false).unwrap();
    let head = 500;
    let e = |r: &tacit::horizon::HorizonResult| {
        (r.force.columns(0, head) - w.columns(0, head)).norm() / w.columns(0, head).norm()
    };
    // flexible part of x0 (the rigid-body position is not seen by accelerations)
    let flex_err =
        (est.states.column(10) - xs.column(10)).rows(8, 8).norm() / xs.column(10).rows(8, 8).norm();
    eprintln!(
        "first {head} samples: force error {:.3} with x0 estimated, {:.3} assuming rest; velocity error at sample 10: {flex_err:.2e}",
        e(&est),
        e(&rest)
    );
    assert!(e(&est) < 0.25);
    assert!(e(&rest) > 10.0 * e(&est));
}

#[test]
fn weight_rules_choose_near_the_true_prior() {
    let sm = sampled();
    let len = 1500;
    let (sf, sn) = (2.0, 0.2);
    let bu = unknown_at_dofs(8, &[4, 5]).unwrap();
    let w = white(2, len, sf, 31);
    let (g, y, _) = linear_record(&sm, len, &bu, &w, &DVector::zeros(16), &[sn; 3], 32);
    let ch = channels();
    let d = data(&g, &y, &ch, &bu);
    let truth = 1.0 / (sf * sf);
    for sel in [
        WeightSelection::Gcv,
        WeightSelection::Discrepancy {
            noise: NoiseLevel::Known,
            tau: 1.0,
        },
        WeightSelection::Discrepancy {
            noise: NoiseLevel::Estimated,
            tau: 1.0,
        },
        WeightSelection::LCurve,
    ] {
        let mut s = settings();
        s.noise = ChannelNoise::Std { std: vec![sn; 3] };
        s.initial = InitialState::Rest;
        s.lambda = 1.0;
        s.selection = sel.clone();
        s.selection_decades = 3.0;
        let r = identify(&sm, &d, &s).unwrap();
        let ratio = r.weights.lambda / truth;
        eprintln!(
            "{sel:?}: λ = {:.3e} ({ratio:.2} × truth), criterion {:.3e}, {} candidates",
            r.weights.lambda,
            r.weights.criterion,
            r.weights.candidates.len()
        );
        assert!(r.weights.lambda.is_finite() && !r.weights.candidates.is_empty());
        match sel {
            WeightSelection::Gcv => assert!((0.2..5.0).contains(&ratio), "GCV chose {ratio}"),
            // the discrepancy principle over-smooths (target N p, not N p − tr H)
            WeightSelection::Discrepancy { .. } => {
                assert!((0.2..50.0).contains(&ratio), "{sel:?} chose {ratio}")
            }
            _ => {}
        }
    }
}

#[test]
fn qp_without_active_constraints_equals_the_sweep_and_respects_constraints() {
    let sm = sampled();
    let len = 300;
    let bu = unknown_at_dofs(8, &[4, 5]).unwrap();
    // a pair force: +f at 5, −f at 6, f ≥ 0
    let a = tacit::signal::random_band(len, FS, (2.0, 60.0), 5.0, 41).unwrap();
    let w = DMatrix::from_fn(2, len, |i, k| {
        let f = a[k].max(0.0);
        if i == 0 {
            f
        } else {
            -f
        }
    });
    let (g, y, _) = linear_record(&sm, len, &bu, &w, &DVector::zeros(16), &[0.1; 3], 42);
    let ch = channels();
    let d = data(&g, &y, &ch, &bu);
    let mut s = settings();
    s.noise = ChannelNoise::Std { std: vec![0.1; 3] };
    s.initial = InitialState::Rest;
    s.covariance = false;
    let free = solve(&sm, &d, &s, 1e-2, 0.0, false).unwrap();
    s.constraints.bounds = vec![(0, -1e6, 1e6)];
    let qp = identify(&sm, &d, &s).unwrap();
    let e = rel(&qp.force, &free.force);
    eprintln!(
        "QP with inactive bounds vs sweep: {e:.2e}; {} iterations",
        qp.diagnostics.qp_iterations
    );
    assert_eq!(qp.status, HorizonStatus::Solved, "{:?}", qp.notes);
    assert!(e < 1e-6);
    s.constraints.bounds = vec![(0, 0.0, f64::INFINITY)];
    s.constraints.pairs = vec![(4, 5)];
    let qp = identify(&sm, &d, &s).unwrap();
    assert_eq!(qp.status, HorizonStatus::Solved);
    let pair = (qp.force.row(0) + qp.force.row(1)).amax();
    let neg = qp.force.row(0).min();
    let err = (&qp.force - &w).norm() / w.norm();
    let err_free = (&free.force - &w).norm() / w.norm();
    eprintln!(
        "pair violation {pair:.1e}, min f5 {neg:.1e}, error {err:.3} (unconstrained {err_free:.3})"
    );
    assert!(pair < 1e-6 && neg > -1e-6);
    assert!(err < err_free);
}
