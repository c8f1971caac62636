//! The trace step on simulated records, fed the true states: it must name
//! the effect that was simulated and nothing on a linear record.

use nalgebra::DMatrix;
use tacit::linear::SampledModel;
use tacit::model::{Contact, Cubic, Friction, Model, Spring};
use tacit::record::Quantity;
use tacit::simulate::{simulate_record, RecordSpec};
use tacit::trace::{trace, EffectKind, TraceInput, TraceSettings};

fn lanl() -> Model {
    let p = concat!(env!("CARGO_MANIFEST_DIR"), "/data/lanl8dof.toml");
    Model::from_file(std::path::Path::new(p)).unwrap()
}

fn run(truth: &Model, sensors: &[usize], noise: f64, seed: u64) -> tacit::trace::TraceResult {
    run_shifted(truth, sensors, noise, seed, (0.0, 0.0)).0
}

/// [`run`] with the states shifted by a rigid-body motion `d + w t` (what
/// acceleration data cannot fix).
fn run_shifted(
    truth: &Model,
    sensors: &[usize],
    noise: f64,
    seed: u64,
    (d, w): (f64, f64),
) -> (tacit::trace::TraceResult, f64) {
    let declared = lanl();
    let spec = RecordSpec {
        samples: 2048,
        sensors: sensors.to_vec(),
        noise,
        seed,
        settings: tacit::integrate::SimSettings {
            substeps: 20,
            ..Default::default()
        },
        ..Default::default()
    };
    let (rec, sim) = simulate_record(truth, &spec).unwrap();
    let n = 8;
    let sm = SampledModel::from_model(&declared, rec.fs, 20).unwrap();
    let chans: Vec<(Quantity, usize)> = rec
        .outputs
        .iter()
        .map(|c| (c.quantity, c.dof - 1))
        .collect();
    let (cy, dy) = sm.outputs(&chans).unwrap();
    let meas = DMatrix::from_fn(chans.len(), rec.len(), |c, k| rec.outputs[c].data[k]);
    let fext = tacit::signal::force_matrix(&rec, n);
    let mut states = DMatrix::zeros(2 * n, rec.len());
    states.rows_mut(0, n).copy_from(&sim.u);
    states.rows_mut(n, n).copy_from(&sim.v);
    for k in 0..rec.len() {
        let t = k as f64 / rec.fs;
        for i in 0..n {
            states[(i, k)] += d + w * t;
            states[(n + i, k)] += w;
        }
    }
    let input = TraceInput {
        model: &declared,
        sampled: &sm,
        cy: &cy,
        dy: &dy,
        measured: &meas,
        force_ext: &fext,
        states: &states,
        identified_force: Some(&sim.fint),
        segment: 51,
        baseline: None,
        exclude: &[],
        located: None,
    };
    let t = std::time::Instant::now();
    let res = trace(&input, &TraceSettings::default());
    eprintln!("trace: {:?}, {} sims", t.elapsed(), res.simulations);
    for e in res.ranking.iter().take(5) {
        eprintln!(
            "  {} gain {:.3} bic {:.1} {:?}",
            e.label, e.residual_explained, e.bic_change, e.parameters
        );
    }
    for e in &res.selected {
        eprintln!(
            "SELECTED {} {:?} se {:?}",
            e.label, e.parameters, e.std_errors
        );
    }
    eprintln!("stop: {}", res.stop_reason);
    (res, rec.fs)
}

#[test]
fn contact_is_named_with_its_gap() {
    for (dofs, sensors) in [
        ([5, 6], vec![1, 2, 3, 4, 5, 6, 7, 8]),
        ([6, 5], vec![1, 5, 6]),
    ] {
        let mut truth = lanl();
        truth.contacts = vec![Contact {
            dofs: dofs.to_vec(),
            gap: 0.381e-3,
            stiffness: 2e6,
        }];
        let res = run(&truth, &sensors, 0.01, 11);
        let e = &res.selected[0];
        assert_eq!(e.candidate.kind, EffectKind::Contact);
        assert_eq!(e.candidate.dofs, vec![dofs[0] - 1, dofs[1] - 1]);
        // the trace only starts the gap: the time-domain fit refines it
        let gap = e.parameters[0].1;
        assert!((gap / 0.381e-3 - 1.0).abs() < 0.3, "gap {gap}");
    }
}

#[test]
#[ignore = "not met: against the linear baseline the contact's sub-sample residual masks the softer spring; the diagnosis loop re-traces against the fitted contact model instead"]
fn bumper_with_softer_spring_gives_both() {
    let mut truth = lanl();
    truth.contacts = vec![Contact {
        dofs: vec![5, 6],
        gap: 0.203e-3,
        stiffness: 2e6,
    }];
    truth.springs[4].stiffness *= 0.86;
    let res = run(&truth, &[1, 2, 3, 4, 5, 6, 7, 8], 0.01, 12);
    let kinds: Vec<EffectKind> = res.selected.iter().map(|e| e.candidate.kind).collect();
    assert!(kinds.contains(&EffectKind::Contact), "{kinds:?}");
    assert!(kinds.contains(&EffectKind::Stiffness), "{kinds:?}");
}

#[test]
fn linear_record_gives_nothing() {
    let res = run(&lanl(), &[1, 5, 6], 0.01, 3);
    assert!(
        res.selected.is_empty(),
        "{:?}",
        res.selected.first().map(|e| &e.label)
    );
}

#[test]
fn other_effects_are_named() {
    let mut fr = lanl();
    fr.frictions = (1..=8)
        .map(|d| Friction {
            dof: d,
            level: 0.5,
            velocity: 1e-3,
        })
        .collect();
    let res = run(&fr, &[1, 2, 3, 4, 5, 6, 7, 8], 0.01, 5);
    assert_eq!(res.selected[0].candidate.kind, EffectKind::Friction);

    let mut cu = lanl();
    cu.cubics = vec![Cubic {
        dofs: vec![3, 4],
        k3: 2e12,
    }];
    let res = run(&cu, &[1, 2, 3, 4, 5, 6, 7, 8], 0.01, 6);
    assert_eq!(res.selected[0].candidate.kind, EffectKind::Cubic);
    assert_eq!(res.selected[0].candidate.dofs, vec![2, 3]);

    let mut gs = lanl();
    gs.springs.push(Spring {
        dofs: vec![1],
        stiffness: 2000.0,
        name: None,
    });
    let res = run(&gs, &[1, 5, 6], 0.01, 7);
    assert_eq!(res.selected[0].candidate.kind, EffectKind::GroundSpring);
    assert_eq!(res.selected[0].candidate.dofs, vec![0]);
}

#[test]
fn a_spring_to_ground_is_found_under_an_unknown_rigid_body_shift() {
    // the reconstruction cannot place the rigid-body position: the trace
    // fits it with the spring along the hidden trajectories
    for (dof, sensors, shift) in [
        (1, vec![1, 2, 3, 4, 5, 6, 7, 8], (2e-4, -1e-3)),
        (4, vec![1, 5, 6], (-3e-4, 5e-4)),
        (8, vec![1, 5, 6], (0.0, 0.0)),
    ] {
        let mut gs = lanl();
        gs.springs.push(Spring {
            dofs: vec![dof],
            stiffness: 2000.0,
            name: None,
        });
        let (res, fs) = run_shifted(&gs, &sensors, 0.01, 17, shift);
        let e = &res.selected[0];
        assert_eq!(e.candidate.kind, EffectKind::GroundSpring, "{}", e.label);
        assert_eq!(e.candidate.dofs, vec![dof - 1]);
        let k = e.parameters[0].1;
        assert!((k / 2000.0 - 1.0).abs() < 0.1, "DOF {dof}: k {k}");
        // the fitted correction undoes the shift at the spring's DOF
        let mut corr = DMatrix::zeros(16, res.hidden[0].ncols());
        for (c, h) in e.hidden.iter().zip(&res.hidden) {
            corr += h * *c;
        }
        let last = corr.ncols() - 1;
        let scale = shift.0.abs() + shift.1.abs() * last as f64 / fs;
        for k in [0, last / 2, last] {
            let want = -(shift.0 + shift.1 * k as f64 / fs);
            let got = corr[(dof - 1, k)];
            assert!(
                (got - want).abs() <= 0.1 * scale + 2e-5,
                "DOF {dof}, sample {k}: correction {got:.3e}, shift {want:.3e}"
            );
        }
    }
}
