//! Simulator speed: lanl8dof with the bumper and 0.3 N friction on every
//! mass, 4096 samples × 10 sub-steps (issue target: under 20 ms; a
//! pure-NumPy Newmark takes about 3.4 s). Also the same run with forward
//! sensitivities: 16 state seeds (every initial displacement and velocity)
//! and 2 parameter seeds (the bumper's gap and stiffness); and a 128-sample
//! segment at 40 sub-steps with 16 state seeds and 10 parameter seeds.

use criterion::{criterion_group, criterion_main, Criterion};
use std::hint::black_box;
use tacit::integrate::{ElementSeed, Integrator, ParamSeed, Seeds, SimSettings};
use tacit::model::elements::ElementParam;
use tacit::model::{Friction, Model};

fn testbed() -> Model {
    let p = concat!(env!("CARGO_MANIFEST_DIR"), "/data/lanl8dof-contact.toml");
    let mut m = Model::from_file(std::path::Path::new(p)).unwrap();
    m.frictions = (1..=8)
        .map(|d| Friction {
            dof: d,
            level: 0.3,
            velocity: 1e-3,
        })
        .collect();
    m
}

fn bench(c: &mut Criterion) {
    let model = testbed();
    let fs = 512.0;
    let n = 4096;
    let x = tacit::signal::random_band(n, fs, (5.0, 200.0), 20.0, 7).unwrap();
    let mut f = nalgebra::DMatrix::zeros(8, n);
    for (k, v) in x.iter().enumerate() {
        f[(0, k)] = *v;
    }
    let integ = Integrator::new(&model, fs, SimSettings::default()).unwrap();
    let sim = integ.run(f.as_view(), &[0.0; 8], &[0.0; 8]);
    assert!(sim.completed());
    eprintln!(
        "contact+friction: {} sub-steps, {} Newton iterations",
        sim.steps, sim.newton_iterations
    );
    c.bench_function("lanl8dof_contact_friction_4096x10", |b| {
        b.iter(|| black_box(integ.run(black_box(f.as_view()), &[0.0; 8], &[0.0; 8])))
    });
    let state = Seeds::initial_state(8);
    let params = Seeds::params(
        8,
        [ElementParam::Gap, ElementParam::Stiffness]
            .map(|param| ParamSeed {
                elements: vec![ElementSeed {
                    element: 0,
                    param,
                    scale: 1.0,
                }],
                ..Default::default()
            })
            .to_vec(),
    );
    for (name, seeds) in [("16_state", &state), ("2_param", &params)] {
        let (_, sens) = integ
            .run_sensitivities(f.as_view(), &[0.0; 8], &[0.0; 8], seeds)
            .unwrap();
        eprintln!(
            "sensitivities {name}: {} tangent factorizations",
            sens.factorizations
        );
        c.bench_function(
            &format!("lanl8dof_contact_friction_4096x10_sens_{name}"),
            |b| {
                b.iter(|| {
                    black_box(integ.run_sensitivities(
                        black_box(f.as_view()),
                        &[0.0; 8],
                        &[0.0; 8],
                        seeds,
                    ))
                })
            },
        );
    }
    // the testbed as the calibrated diagnosis refines it: 40 sub-steps, 16
    // state seeds and a parameter per element (gap, stiffness, 8 levels),
    // one 128-sample segment
    let sub40 = SimSettings {
        substeps: 40,
        ..Default::default()
    };
    let integ40 = Integrator::new(&model, fs, sub40).unwrap();
    let mut many = Seeds::initial_state(8);
    many.params = params.params.clone();
    for e in 1..integ40.elements().len() {
        many.params.push(ParamSeed {
            elements: vec![ElementSeed {
                element: e,
                param: ElementParam::Level,
                scale: 1.0,
            }],
            ..Default::default()
        });
    }
    let seg = f.columns(0, 128);
    c.bench_function("lanl8dof_contact_friction_128x40_sens_26_seeds", |b| {
        b.iter(|| black_box(integ40.run_sensitivities(black_box(seg), &[0.0; 8], &[0.0; 8], &many)))
    });
    let linear = model.linear_part();
    let integ_l = Integrator::new(&linear, fs, SimSettings::default()).unwrap();
    c.bench_function("lanl8dof_linear_4096x10", |b| {
        b.iter(|| black_box(integ_l.run(black_box(f.as_view()), &[0.0; 8], &[0.0; 8])))
    });
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(20);
    targets = bench
}
criterion_main!(benches);
