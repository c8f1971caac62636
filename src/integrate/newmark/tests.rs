use super::*;
use crate::model::{Contact, Damping, Friction, Model, Spring};

fn sdof(m: f64, k: f64) -> Model {
    Model {
        name: "sdof".into(),
        description: String::new(),
        masses: vec![m],
        springs: vec![Spring {
            dofs: vec![1],
            stiffness: k,
            name: None,
        }],
        damping: Damping::None,
        ..Default::default()
    }
}

fn zero_force(n: usize, ns: usize) -> DMatrix<f64> {
    DMatrix::zeros(n, ns)
}

/// Free vibration error against u0 cos(ωt), for a given number of sub-steps.
fn sdof_error(substeps: usize) -> f64 {
    let (m, k) = (2.0, 800.0); // ω = 20 rad/s
    let model = sdof(m, k);
    let fs = 100.0;
    let settings = SimSettings {
        substeps,
        ..Default::default()
    };
    let integ = Integrator::new(&model, fs, settings).unwrap();
    let f = zero_force(1, 101);
    let sim = integ.run(f.as_view(), &[1e-3], &[0.0]);
    assert!(sim.completed());
    let w = (k / m).sqrt();
    (0..101)
        .map(|i| (sim.u[(0, i)] - 1e-3 * (w * i as f64 / fs).cos()).abs())
        .fold(0.0, f64::max)
}

#[test]
fn sdof_free_vibration_second_order() {
    let e1 = sdof_error(4);
    let e2 = sdof_error(8);
    let e3 = sdof_error(16);
    assert!(e3 < 1e-5 * 1e-3 * 100.0, "error {e3}");
    let p1 = (e1 / e2).log2();
    let p2 = (e2 / e3).log2();
    assert!(
        (p1 - 2.0).abs() < 0.1 && (p2 - 2.0).abs() < 0.1,
        "orders {p1} {p2}"
    );
}

fn lanl(contact: bool) -> Model {
    let p = if contact {
        "/data/lanl8dof-contact.toml"
    } else {
        "/data/lanl8dof.toml"
    };
    Model::from_file(std::path::Path::new(&format!(
        "{}{}",
        env!("CARGO_MANIFEST_DIR"),
        p
    )))
    .unwrap()
}

#[test]
fn undamped_linear_conserves_energy() {
    let mut model = lanl(false);
    model.damping = Damping::None;
    let integ = Integrator::new(&model, 512.0, SimSettings::default()).unwrap();
    let mut v0 = vec![0.0; 8];
    v0[0] = 0.1;
    v0[4] = -0.05;
    let sim = integ.run(zero_force(8, 2000).as_view(), &[0.0; 8], &v0);
    let mm = model.mass_matrix();
    let kk = model.stiffness_matrix();
    let energy = |k: usize| {
        let u = sim.u.column(k);
        let v = sim.v.column(k);
        0.5 * (v.transpose() * &mm * v)[0] + 0.5 * (u.transpose() * &kk * u)[0]
    };
    let e0 = energy(0);
    for k in [1, 500, 1999] {
        approx::assert_relative_eq!(energy(k), e0, max_relative = 1e-7);
    }
}

#[test]
fn contact_bounce_returns_incoming_speed() {
    // a free mass hitting a ground stop at gap 1 mm, undamped contact
    let model = Model {
        masses: vec![0.42],
        springs: vec![],
        contacts: vec![Contact {
            dofs: vec![1],
            gap: 1e-3,
            stiffness: 2e6,
        }],
        ..sdof(1.0, 1.0)
    };
    let integ = Integrator::new(
        &model,
        5120.0,
        SimSettings {
            substeps: 4,
            ..Default::default()
        },
    )
    .unwrap();
    let v_in = 0.2;
    let sim = integ.run(zero_force(1, 100).as_view(), &[0.0], &[v_in]);
    assert!(sim.completed());
    let last = sim.len() - 1;
    // the step that straddles first touch is not energy-exact: 0.1 % here
    approx::assert_relative_eq!(sim.v[(0, last)], -v_in, max_relative = 2e-3);
    // it did touch: maximum penetration close to v sqrt(m/k)
    let umax = sim.u.row(0).max();
    let pen = v_in * (0.42f64 / 2e6).sqrt();
    approx::assert_relative_eq!(umax - 1e-3, pen, max_relative = 0.02);
}

#[test]
fn friction_oscillator_sticks_where_theory_says() {
    // m x'' + k x + F sgn(x') = 0 from x0 at rest: each half cycle loses 2F/k,
    // motion stops at the first turning point with |x| <= F/k.
    let (m, k, f) = (1.0, 1000.0, 2.0);
    let mut model = sdof(m, k);
    model.frictions = vec![Friction {
        dof: 1,
        level: f,
        velocity: 1e-6,
    }];
    let x0 = 0.0105;
    let d = f / k;
    let mut amp = x0;
    let mut pos = x0;
    while amp > d {
        amp -= 2.0 * d;
        pos = if pos > 0.0 { -amp } else { amp };
    }
    let integ = Integrator::new(
        &model,
        1000.0,
        SimSettings {
            substeps: 20,
            ..Default::default()
        },
    )
    .unwrap();
    let sim = integ.run(zero_force(1, 1000).as_view(), &[x0], &[0.0]);
    assert!(sim.completed(), "{:?}", sim.status);
    let end = sim.u[(0, 999)];
    assert!(
        (end - pos).abs() < 0.02 * d,
        "stopped at {end}, theory {pos} (band ±{d})"
    );
    assert!(sim.v[(0, 999)].abs() < 1e-5);
}

#[test]
fn newton_failure_is_reported_with_time() {
    let model = lanl(true);
    let settings = SimSettings {
        substeps: 1,
        max_newton: 1,
        ..Default::default()
    };
    let integ = Integrator::new(&model, 512.0, settings).unwrap();
    let mut f = zero_force(8, 200);
    for k in 0..200 {
        f[(4, k)] = 400.0;
    }
    let sim = integ.run(f.as_view(), &[0.0; 8], &[0.0; 8]);
    match sim.status {
        SimStatus::NewtonFailed { time, sample, .. } => {
            assert!(time > 0.0 && sample < 199);
            assert_eq!(sim.len(), sample + 1);
        }
        other => panic!("expected a Newton failure, got {other:?}"),
    }
}

#[test]
fn matches_independent_reference_record() {
    // the independent reference record of the shared data set: a NumPy
    // Newmark code at 40 sub-steps, same model (docs/theory.md)
    let Some(path) = crate::record::shared_data("reference/lanl8dof-contact-ref.csv") else {
        return;
    };
    let rec = crate::record::csvio::read(&path).unwrap();
    let model = lanl(true);
    let integ = Integrator::new(
        &model,
        rec.fs,
        SimSettings {
            substeps: 40,
            ..Default::default()
        },
    )
    .unwrap();
    let f = crate::signal::force_matrix(&rec, 8);
    let n = 400;
    let sim = integ.run(f.columns(0, n), &[0.0; 8], &[0.0; 8]);
    assert!(sim.completed());
    for c in &rec.outputs {
        let d = c.dof - 1;
        let (mut num, mut den) = (0.0, 0.0);
        for k in 0..n {
            num += (sim.a[(d, k)] - c.data[k]).powi(2);
            den += c.data[k].powi(2);
        }
        let e = (num / den).sqrt();
        assert!(e < 1e-3, "{}: relative error {e}", c.name());
    }
}

#[test]
fn hht_damps_and_stays_second_order_for_small_alpha() {
    let model = sdof(2.0, 800.0);
    let s = |alpha| SimSettings {
        substeps: 8,
        hht_alpha: alpha,
        ..Default::default()
    };
    let a = Integrator::new(&model, 100.0, s(-0.1)).unwrap();
    let sim = a.run(zero_force(1, 101).as_view(), &[1e-3], &[0.0]);
    let w: f64 = 20.0;
    let err = (0..101)
        .map(|i| (sim.u[(0, i)] - 1e-3 * (w * i as f64 / 100.0).cos()).abs())
        .fold(0.0, f64::max);
    assert!(err < 2e-5, "HHT error {err}");
    assert!(Integrator::new(&model, 100.0, s(-0.5)).is_err());
}

#[test]
fn unrolled_and_generic_kernels_agree_bit_for_bit() {
    // the 8-DOF run uses kernels unrolled for n = 8; the generic ones must
    // give the same numbers (friction on every mass, the contact, HHT, and
    // the contact alone, whose Newton factor is reused while it is closed)
    let mut rough = lanl(true);
    rough.frictions = (1..=8)
        .map(|d| Friction {
            dof: d,
            level: 0.3,
            velocity: 1e-3,
        })
        .collect();
    let x = crate::signal::random_band(600, 512.0, (5.0, 200.0), 20.0, 7).unwrap();
    let mut f = zero_force(8, 600);
    f.row_mut(0).copy_from_slice(&x);
    for (model, alpha) in [(rough.clone(), 0.0), (rough, -0.1), (lanl(true), 0.0)] {
        let settings = SimSettings {
            hht_alpha: alpha,
            ..Default::default()
        };
        let integ = Integrator::new(&model, 512.0, settings).unwrap();
        let fast = integ.run(f.as_view(), &[0.0; 8], &[0.0; 8]);
        let generic = integ.run_n::<0>(f.as_view(), &[0.0; 8], &[0.0; 8], None);
        assert!(fast.completed() && fast.newton_iterations > fast.steps);
        assert_eq!(fast.status, generic.status);
        assert_eq!(fast.newton_iterations, generic.newton_iterations);
        assert_eq!(fast.u, generic.u);
        assert_eq!(fast.a, generic.a);
        assert_eq!(fast.fint, generic.fint);
        assert!(fast.fint.iter().any(|&x| x != 0.0));
    }
}

#[test]
fn whole_samples_without_contact_agree_with_sub_stepping() {
    // lanl8dof with the bumper 5→6 and a ground stop at DOF 1, under a
    // shaker force that closes both now and then: samples taken in one
    // product (SampleMap) against every sample sub-stepped
    let mut model = lanl(true);
    model.contacts.push(Contact {
        dofs: vec![1],
        gap: 4e-4,
        stiffness: 5e5,
    });
    let ns = 1000;
    let x = crate::signal::random_band(ns, 512.0, (5.0, 200.0), 30.0, 3).unwrap();
    let mut f = zero_force(8, ns);
    f.row_mut(0).copy_from_slice(&x);
    for (substeps, with_contacts) in [(10, true), (23, true), (10, false)] {
        let mut m = model.clone();
        if !with_contacts {
            m.contacts.clear();
        }
        let settings = SimSettings {
            substeps,
            ..Default::default()
        };
        let mut integ = Integrator::new(&m, 512.0, settings).unwrap();
        let batched = integ.run(f.as_view(), &[0.0; 8], &[0.0; 8]);
        assert!(integ.sample_map().is_some());
        integ.batch_linear = false;
        integ.sample_map = std::sync::OnceLock::new();
        let stepped = integ.run(f.as_view(), &[0.0; 8], &[0.0; 8]);
        assert!(integ.sample_map().is_none());
        assert!(batched.completed() && stepped.completed());
        assert_eq!(batched.steps, stepped.steps);
        // both contacts close and open again
        if with_contacts {
            for d in [0, 4] {
                let closed = (0..ns).filter(|&k| stepped.fint[(d, k)] != 0.0).count();
                assert!(closed > 0 && closed < ns / 2, "DOF {}: {closed}", d + 1);
            }
        }
        for (a, b) in [
            (&batched.u, &stepped.u),
            (&batched.v, &stepped.v),
            (&batched.a, &stepped.a),
            (&batched.fint, &stepped.fint),
        ] {
            // rounding differences grow tenfold per 100 samples through
            // the impacts (2e-5 after 1000): compared over 300
            let e = (a.columns(0, 300) - b.columns(0, 300)).amax() / b.amax().max(1e-300);
            assert!(e < 1e-7, "{substeps} sub-steps: {e:e}");
        }
        // (the same bits would mean the map was not used)
        assert!(batched.u != stepped.u);
    }
}

#[test]
fn integrators_sharing_a_linear_part_share_its_operators_not_their_gaps() {
    // the bumper 5→6 with a wide gap, then the same linear part with a
    // narrow gap and another stiffness: the second integrator may take
    // the first one's sample map and derivative powers from the cache,
    // but it must close its contact at its own gap
    let ns = 600;
    let x = crate::signal::random_band(ns, 512.0, (5.0, 200.0), 30.0, 5).unwrap();
    let mut f = zero_force(8, ns);
    f.row_mut(0).copy_from_slice(&x);
    let settings = SimSettings {
        substeps: 17,
        ..Default::default()
    };
    let mut wide = lanl(true);
    wide.contacts[0].gap = 5e-3;
    let first = Integrator::new(&wide, 512.0, settings).unwrap();
    let open = first.run(f.as_view(), &[0.0; 8], &[0.0; 8]);
    assert!(open.completed() && open.fint.iter().all(|&v| v == 0.0));
    assert!(first.sample_map().is_some() && first.linear_powers().is_some());
    let mut narrow = lanl(true);
    narrow.contacts[0].gap = 1e-4;
    narrow.contacts[0].stiffness = 3e6;
    let integ = Integrator::new(&narrow, 512.0, settings).unwrap();
    assert_eq!(integ.linear_key(), first.linear_key());
    let cached = integ.run(f.as_view(), &[0.0; 8], &[0.0; 8]);
    let mut plain = Integrator::new(&narrow, 512.0, settings).unwrap();
    plain.batch_linear = false;
    let stepped = plain.run(f.as_view(), &[0.0; 8], &[0.0; 8]);
    assert!(cached.completed() && stepped.completed());
    let closed = (0..ns).filter(|&k| stepped.fint[(4, k)] != 0.0).count();
    assert!(closed > 10, "the narrow contact closes: {closed} samples");
    // (rounding differences grow through the impacts: 1.5e-6 after 300
    // samples; the first integrator's gap would leave this contact open)
    let e = (cached.u.columns(0, 300) - stepped.u.columns(0, 300)).amax() / stepped.u.amax();
    assert!(e < 1e-4, "{e:e}");
    // the derivative powers too: the same sensitivities as the plain
    // recursion
    let seeds = crate::integrate::Seeds::initial_state(8);
    let (_, d1) = integ
        .run_sensitivities(f.columns(0, 200), &[0.0; 8], &[0.0; 8], &seeds)
        .unwrap();
    let (_, d2) = plain
        .run_sensitivities(f.columns(0, 200), &[0.0; 8], &[0.0; 8], &seeds)
        .unwrap();
    for q in 0..16 {
        let e = (&d1.du[q] - &d2.du[q]).amax() / d2.du[q].amax().max(1e-300);
        assert!(e < 1e-7, "seed {q}: {e:e}");
    }
}
