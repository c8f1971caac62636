//! Model updating speed (issue 6), each fit with the Jacobian from forward
//! sensitivities and from centered finite differences:
//!
//! - one Table 4 column end to end (`PCD, FM, D`: the full-order column;
//!   the reduced columns fall back to finite differences, so both settings
//!   run the same code there), noise-free, from the nominal model;
//! - the multiple-shooting contact fit of `examples/update_contact_shooting`:
//!   gap and stiffness of the 5→6 bumper of lanl8dof, 4096 samples, 1 %
//!   noise, accelerations at DOFs 1, 5, 6, 80 segments of 0.1 s from the
//!   true states, 40 sub-steps, started 30 % off (gap +30 %, stiffness
//!   −30 %).
//!
//! Before timing, each fit is run once and its result, iterations and
//! simulations are printed.
//!
//! Run: `taskset -c 0 cargo bench --bench update`

use criterion::{criterion_group, criterion_main, Criterion};
use std::hint::black_box;
use tacit::integrate::SimSettings;
use tacit::model::Model;
use tacit::record::Quantity;
use tacit::simulate::{simulate_record, RecordSpec};
use tacit::update::{
    self, shooting, table4, FitResult, FitSettings, JacobianMethod, Parameter, Problem, Target,
};

fn contact_problem() -> Problem {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("data/lanl8dof-contact.toml");
    let truth = Model::from_file(&path).unwrap();
    let spec = RecordSpec {
        samples: 4096,
        sensors: vec![1, 5, 6],
        kinds: vec![Quantity::Accel],
        noise: 0.01,
        seed: 7,
        settings: SimSettings {
            substeps: 40,
            ..Default::default()
        },
        ..Default::default()
    };
    let (rec, _) = simulate_record(&truth, &spec).unwrap();
    let params = vec![
        Parameter::relative(&truth, Target::ContactGap(0))
            .unwrap()
            .with_relative_start(0.3),
        Parameter::relative(&truth, Target::ContactStiffness(0))
            .unwrap()
            .with_relative_start(-0.3),
    ];
    let n = truth.ndof();
    let mut p = Problem::from_record(
        &truth,
        &rec,
        &[Quantity::Accel],
        None,
        params,
        vec![0.0; n],
        vec![0.0; n],
    )
    .unwrap();
    p.sim.substeps = 40;
    p.segments = shooting::from_truth(&rec, 51).unwrap();
    p
}

fn describe(label: &str, r: &FitResult) {
    let pct: Vec<String> = r
        .parameters
        .iter()
        .map(|q| format!("{} {:+.2} %", q.name, q.percent_change))
        .collect();
    eprintln!(
        "{label}: {}; {:?}; {} iterations, {} cost evaluations, {} simulations ({} with sensitivities), {} Jacobians in {:.2} s, {:.2} s in all",
        pct.join(", "),
        r.termination,
        r.iterations,
        r.evaluations,
        r.simulations,
        r.sensitivity_simulations,
        r.jacobians,
        r.jacobian_s,
        r.elapsed_s
    );
}

fn bench(c: &mut Criterion) {
    let methods = [
        ("sens", JacobianMethod::Sensitivity),
        ("fd", JacobianMethod::CentralDifference),
    ];
    let case = table4::case(0.0, 11).unwrap();
    let col = table4::columns()[2];
    let t4 = table4::problem(&case, &col).unwrap();
    let mut g = c.benchmark_group("table4");
    g.sample_size(20);
    for (name, jacobian) in methods {
        let s = FitSettings {
            jacobian,
            ..Default::default()
        };
        describe(
            &format!("Table 4 {} ({name})", col.label),
            &update::fit(&t4, &s).unwrap(),
        );
        g.bench_function(format!("pcd_fm_d_{name}"), |b| {
            b.iter(|| black_box(update::fit(black_box(&t4), &s).unwrap()))
        });
    }
    g.finish();
    let contact = contact_problem();
    let mut g = c.benchmark_group("contact_shooting");
    g.sample_size(10)
        .warm_up_time(std::time::Duration::from_millis(1))
        .measurement_time(std::time::Duration::from_secs(1));
    for (name, jacobian) in methods {
        let s = FitSettings {
            jacobian,
            ..Default::default()
        };
        describe(
            &format!("bumper gap and stiffness, 80 segments ({name})"),
            &update::fit(&contact, &s).unwrap(),
        );
        g.bench_function(format!("gap_stiffness_4096_{name}"), |b| {
            b.iter(|| black_box(update::fit(black_box(&contact), &s).unwrap()))
        });
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
