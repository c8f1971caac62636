//! Full-horizon identification speed (issue 4): lanl8dof, full order (8
//! DOFs), accelerations at DOFs 1, 5, 6, 8 unknown forces, fixed weights,
//! with covariance. Targets: 4096 samples under 5 ms, 1e6 samples under
//! 2 s, cost linear in the record length (figures at 1e4, 1e5, 1e6).
//! Run on one core: `taskset -c 0 cargo bench --bench horizon`. The
//! breakdown printed before each size is that of the first run ("forward"
//! includes writing the outputs, "covariance" the standard deviations).

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use nalgebra::DMatrix;
use std::hint::black_box;
use tacit::horizon::{solve, unknown_at_dofs, HorizonData, HorizonSettings};
use tacit::linear::SampledModel;
use tacit::model::Model;
use tacit::record::Quantity;

fn record(sm: &SampledModel, len: usize) -> (DMatrix<f64>, DMatrix<f64>) {
    let x = tacit::signal::random_band(len.min(65_536), 512.0, (5.0, 200.0), 20.0, 7).unwrap();
    let mut g = DMatrix::zeros(8, len);
    for k in 0..len {
        g[(0, k)] = x[k % x.len()];
    }
    let xs = sm.simulate(&nalgebra::DVector::zeros(16), &g);
    let (cy, dy) = sm.outputs(&channels()).unwrap();
    let mut y = &cy * &xs + &dy * &g;
    for (i, v) in y.iter_mut().enumerate() {
        *v += 0.05 * (((i * 7919) % 1000) as f64 / 500.0 - 1.0);
    }
    (g, y)
}

fn channels() -> Vec<(Quantity, usize)> {
    vec![
        (Quantity::Accel, 0),
        (Quantity::Accel, 4),
        (Quantity::Accel, 5),
    ]
}

fn bench(c: &mut Criterion) {
    let p = concat!(env!("CARGO_MANIFEST_DIR"), "/data/lanl8dof.toml");
    let model = Model::from_file(std::path::Path::new(p)).unwrap();
    let sm = SampledModel::from_model(&model, 512.0, 10).unwrap();
    let bu = unknown_at_dofs(8, &[0, 1, 2, 3, 4, 5, 6, 7]).unwrap();
    let ch = channels();
    let settings = HorizonSettings::default();
    let mut group = c.benchmark_group("horizon_8dof_3sensors_8forces");
    group.sample_size(10);
    for &len in &[4096usize, 10_000, 100_000, 1_000_000] {
        let (g, y) = record(&sm, len);
        let data = HorizonData {
            known_force: &g,
            measured: &y,
            channels: &ch,
            unknown: &bu,
        };
        let r = solve(&sm, &data, &settings, 1e-2, 0.0, true).unwrap();
        eprintln!(
            "N = {len}: status {:?}, Riccati transient {} samples (held at distance {:.1e}), covariance held from {:?}; setup {:.2} ms, backward {:.2} ms, forward {:.2} ms, covariance {:.2} ms, total {:.2} ms",
            r.status,
            r.diagnostics.riccati_transient,
            r.diagnostics.riccati_held_distance,
            r.diagnostics.covariance_held_from,
            1e3 * r.timings.setup,
            1e3 * r.timings.backward,
            1e3 * r.timings.forward,
            1e3 * r.timings.covariance,
            1e3 * r.timings.total
        );
        group.throughput(Throughput::Elements(len as u64));
        group.bench_with_input(BenchmarkId::from_parameter(len), &len, |b, _| {
            b.iter(|| black_box(solve(&sm, &data, &settings, 1e-2, 0.0, true).unwrap()))
        });
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
