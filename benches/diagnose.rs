//! The main job's speed (issue 7): the whole `diagnose` of the record
//! shipped in `data/` (lanl8dof with the 0.381 mm bumper 5→6, 4096
//! samples, all eight accelerometers) with its validation record —
//! identification, trace, fit, errors before and after on both records.
//!
//! Before timing, the diagnosis is run once and its result, simulations and
//! stage timings are printed.
//!
//! Run: `cargo bench --bench diagnose`

use criterion::{criterion_group, criterion_main, Criterion};
use std::hint::black_box;
use std::path::Path;
use tacit::diagnose::{diagnose, DiagnoseSettings};
use tacit::model::Model;

fn bench(c: &mut Criterion) {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let model = Model::from_file(&root.join("data/lanl8dof.toml")).unwrap();
    let rec = tacit::record::read(&root.join("data/lanl8dof-bumper.h5")).unwrap();
    let val = tacit::record::read(&root.join("data/lanl8dof-bumper-validation.h5")).unwrap();
    let settings = DiagnoseSettings::default();
    let run = || diagnose(&model, &rec, Some(&val), None, &settings, &|_| {}).unwrap();
    let d = run();
    let stages: Vec<String> = d
        .timings
        .iter()
        .map(|(k, v)| format!("{k} {v:.2} s"))
        .collect();
    eprintln!(
        "{}: relative error {:.4} -> {:.4}, validation {:.4} -> {:.4}; {} segment simulations + {} linear; {}",
        d.verdict,
        d.before.relative_error.unwrap_or(f64::NAN),
        d.after.relative_error.unwrap_or(f64::NAN),
        d.validation
            .as_ref()
            .and_then(|v| v.before.relative_error)
            .unwrap_or(f64::NAN),
        d.validation
            .as_ref()
            .and_then(|v| v.after.relative_error)
            .unwrap_or(f64::NAN),
        d.simulations,
        d.trace_simulations,
        stages.join(", ")
    );
    let mut g = c.benchmark_group("diagnose");
    g.sample_size(10);
    g.bench_function("lanl8dof_bumper_with_validation", |b| {
        b.iter(|| black_box(run()))
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
