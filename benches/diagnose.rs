//! The main job's speed (issue 7): the whole `diagnose` of the record
//! shipped in `data/` (lanl8dof with the 0.381 mm bumper 5→6, 4096
//! samples, all eight accelerometers) with its validation record —
//! identification, trace, fit, errors before and after on both records.
//!
//! The imperfect declared model (issue 16): the testbed as a test sees
//! it (data/lanl8dof-testbed.toml: springs within ±3 %, 2 % modal
//! damping, 0.2 N friction on every mass, the bumper; 4096 samples, 1 %
//! noise, 40 sub-steps, seeds 17, 34 and 5, the simulator's default
//! random force at DOF 1 and all eight accelerometers), diagnosed
//! against data/lanl8dof.toml with its linear part calibrated on a record
//! of the structure without the bumper (`--linear-record`).
//!
//! Before timing, each diagnosis is run once and its result, simulations
//! and stage timings are printed.
//!
//! Run: `cargo bench --bench diagnose`

use criterion::{criterion_group, criterion_main, Criterion};
use std::hint::black_box;
use std::path::Path;
use tacit::diagnose::calibrated::{diagnose_calibrated, CalibratedSettings};
use tacit::diagnose::{diagnose, DiagnoseSettings, Diagnosis};
use tacit::integrate::SimSettings;
use tacit::model::Model;
use tacit::record::Record;
use tacit::simulate::{simulate_record, RecordSpec};

fn bench(c: &mut Criterion) {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let model = Model::from_file(&root.join("data/lanl8dof.toml")).unwrap();
    let rec = tacit::record::read(&root.join("data/lanl8dof-bumper.h5")).unwrap();
    let val = tacit::record::read(&root.join("data/lanl8dof-bumper-validation.h5")).unwrap();
    let settings = DiagnoseSettings::default();
    let run = || diagnose(&model, &rec, Some(&val), None, &settings, &|_| {}).unwrap();
    print_result(&run());
    let mut g = c.benchmark_group("diagnose");
    g.sample_size(10);
    g.bench_function("lanl8dof_bumper_with_validation", |b| {
        b.iter(|| black_box(run()))
    });
    g.finish();
}

/// A record of `model` as the README's tour simulates it (random force at
/// DOF 1, all eight accelerometers).
fn testbed_record(model: &Model, seed: u64) -> Record {
    let spec = RecordSpec {
        samples: 4096,
        sensors: (1..=8).collect(),
        noise: 0.01,
        seed,
        settings: SimSettings {
            substeps: 40,
            ..Default::default()
        },
        ..Default::default()
    };
    simulate_record(model, &spec).unwrap().0
}

fn bench_calibrated(c: &mut Criterion) {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let read = |f: &str| Model::from_file(&root.join("data").join(f)).unwrap();
    let (declared, truth, linear) = (
        read("lanl8dof.toml"),
        read("lanl8dof-testbed.toml"),
        read("lanl8dof-testbed-linear.toml"),
    );
    let rec = testbed_record(&truth, 17);
    let val = testbed_record(&truth, 34);
    let low = vec![testbed_record(&linear, 5)];
    let (settings, cal) = (DiagnoseSettings::default(), CalibratedSettings::default());
    let run = || {
        diagnose_calibrated(
            &declared,
            &rec,
            Some(&val),
            &low,
            None,
            &settings,
            &cal,
            &|_| {},
        )
        .unwrap()
    };
    print_result(&run());
    let mut g = c.benchmark_group("diagnose_calibrated");
    g.sample_size(10);
    g.bench_function("testbed_with_linear_record_and_validation", |b| {
        b.iter(|| black_box(run()))
    });
    g.finish();
}

/// The verdict, errors, simulations and stage timings of `d`.
fn print_result(d: &Diagnosis) {
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
}

criterion_group!(benches, bench, bench_calibrated);
criterion_main!(benches);
