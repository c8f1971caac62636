//! Model updating speed (issue 6), each fit with the Jacobian from forward
//! sensitivities and from centered finite differences:
//!
//! - one Table 4 column end to end (`PCD, FM, D`: the full-order column;
//!   the reduced columns fall back to finite differences, so both settings
//!   run the same code there), noise-free, from the nominal model;
//! - the multiple-shooting contact fit of [`tacit::cases::contact_case`] (gap
//!   and stiffness of the 5→6 bumper of lanl8dof, 4096 samples, 1 % noise,
//!   accelerations at DOFs 1, 5, 6, 80 segments of 0.1 s from the true
//!   states, 40 sub-steps), started 30 % off (gap +30 %, stiffness −30 %).
//!
//! Before timing, each fit is run once and its result, iterations and
//! simulations are printed.
//!
//! Run: `taskset -c 0 cargo bench --bench update`

use criterion::{criterion_group, criterion_main, Criterion};
use std::hint::black_box;
use tacit::cases::{contact_case, table4};
use tacit::update::{self, FitResult, FitSettings, JacobianMethod};

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
    let contact = contact_case::case([0.3, -0.3]).unwrap().shooting;
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
