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
//! The same job without the linear record (`-- diagnose_held`): the
//! linear part calibrated on the record diagnosed itself.
//!
//! Before timing, each diagnosis is run once and its result, simulations
//! and stage timings are printed.
//!
//! Run: `cargo bench --bench diagnose` (a name after `--` runs only the
//! groups it matches, e.g. `-- diagnose_calibrated`). With
//! `TACIT_BENCH_ONCE=1` each diagnosis is run once, its stages printed with
//! the process's CPU time and the wall time spent in each, and nothing is
//! timed. `TACIT_BENCH_SETTINGS=FILE` reads the diagnosis settings of the
//! calibrated group from FILE (the `--settings` file of `tacit diagnose`)
//! to weigh a setting's cost against its results.

use criterion::{criterion_group, criterion_main, Criterion};
use std::hint::black_box;
use std::path::Path;
use tacit::diagnose::calibrated::{diagnose_calibrated, CalibratedSettings};
use tacit::diagnose::{diagnose, DiagnoseSettings, Diagnosis};
use tacit::integrate::SimSettings;
use tacit::model::Model;
use tacit::record::Record;
use tacit::simulate::{simulate_record, RecordSpec};

/// The first argument that is not an option: criterion's filter.
fn filter() -> Option<String> {
    std::env::args().skip(1).find(|a| !a.starts_with('-'))
}

/// Whether the group `name` runs under the command line's filter.
fn wanted(name: &str) -> bool {
    filter().is_none_or(|f| name.contains(&f) || f.contains(name))
}

/// Run once with the stages printed, nothing timed (`TACIT_BENCH_ONCE`).
fn once() -> bool {
    std::env::var_os("TACIT_BENCH_ONCE").is_some()
}

/// The process's user + system CPU time, s (Linux: /proc/self/stat, in
/// clock ticks of 1/100 s); 0 elsewhere.
fn cpu_seconds() -> f64 {
    let Ok(stat) = std::fs::read_to_string("/proc/self/stat") else {
        return 0.0;
    };
    // the fields after the command name (in parentheses)
    let rest = stat.rsplit(')').next().unwrap_or("");
    let f: Vec<&str> = rest.split_whitespace().collect();
    let tick = |i: usize| f.get(i).and_then(|v| v.parse::<f64>().ok()).unwrap_or(0.0);
    (tick(11) + tick(12)) / 100.0
}

/// A progress callback printing each stage with the CPU and wall time
/// since the previous one.
fn stage_printer() -> impl Fn(&str) {
    let last = std::cell::Cell::new((cpu_seconds(), std::time::Instant::now()));
    let start = last.get();
    move |stage: &str| {
        let (c0, w0) = last.get();
        let (c, w) = (cpu_seconds(), std::time::Instant::now());
        eprintln!(
            "  [{:7.2} s cpu, {:7.2} s wall] +{:6.2} s cpu {:6.2} s wall before: {stage}",
            c - start.0,
            (w - start.1).as_secs_f64(),
            c - c0,
            (w - w0).as_secs_f64()
        );
        last.set((c, w));
    }
}

fn bench(c: &mut Criterion) {
    if !wanted("diagnose/lanl8dof_bumper_with_validation") {
        return;
    }
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
    calibrated_group(
        c,
        "diagnose_calibrated",
        "testbed_with_linear_record_and_validation",
        true,
    );
}

/// The same job without the linear record: the linear part calibrated on
/// the record diagnosed itself.
fn bench_held(c: &mut Criterion) {
    calibrated_group(c, "diagnose_held", "testbed_with_validation", false);
}

/// The testbed's calibrated diagnosis as group `group`, function `name`,
/// with the low-level record or without.
fn calibrated_group(c: &mut Criterion, group: &str, name: &str, with_linear: bool) {
    if !wanted(&format!("{group}/{name}")) {
        return;
    }
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let read = |f: &str| Model::from_file(&root.join("data").join(f)).unwrap();
    let (declared, truth, linear) = (
        read("lanl8dof.toml"),
        read("lanl8dof-testbed.toml"),
        read("lanl8dof-testbed-linear.toml"),
    );
    let rec = testbed_record(&truth, 17);
    let val = testbed_record(&truth, 34);
    let low = if with_linear {
        vec![testbed_record(&linear, 5)]
    } else {
        vec![]
    };
    let (settings, cal) = (bench_settings(), CalibratedSettings::default());
    let run_with = |progress: &dyn Fn(&str)| {
        diagnose_calibrated(
            &declared,
            &rec,
            Some(&val),
            &low,
            None,
            &settings,
            &cal,
            progress,
        )
        .unwrap()
    };
    if once() {
        let printer = stage_printer();
        let d = run_with(&printer);
        printer("end");
        print_result(&d);
        print_calibration(&d);
        return;
    }
    let run = || run_with(&|_| {});
    print_result(&run());
    let mut g = c.benchmark_group(group);
    g.sample_size(10);
    g.bench_function(name, |b| b.iter(|| black_box(run())));
    g.finish();
}

/// The diagnosis settings: from the file named by `TACIT_BENCH_SETTINGS`
/// (the `--settings` file of `tacit diagnose`), else the defaults.
fn bench_settings() -> DiagnoseSettings {
    match std::env::var_os("TACIT_BENCH_SETTINGS") {
        Some(p) => DiagnoseSettings::from_file(Path::new(&p))
            .unwrap_or_else(|e| panic!("TACIT_BENCH_SETTINGS={}: {e}", p.to_string_lossy())),
        None => DiagnoseSettings::default(),
    }
}

/// The verdict, errors, simulations and stage timings of `d`.
fn print_result(d: &Diagnosis) {
    let stages: Vec<String> = d
        .timings
        .iter()
        .map(|(k, v)| format!("{k} {v:.2} s"))
        .collect();
    eprintln!(
        "{}: relative error {:.6} -> {:.6}, validation {:.6} -> {:.6}; {} segment simulations + {} linear; {}",
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

/// The calibrated diagnosis's choice and refinement, in words, and the
/// start-state refinement of the errors after.
fn print_calibration(d: &Diagnosis) {
    if let Some(c) = &d.calibration {
        eprintln!("choice: {}\nrefinement: {}", c.choice, c.refinement);
    }
    if let Some(f) = &d.after.starts {
        eprintln!(
            "starts after: {} iterations, {} simulations, {} continued, {} grown, {} rescued, {} split, {} stuck, {} stalled",
            f.iterations,
            f.simulations,
            f.continued,
            f.grown,
            f.rescued,
            f.split,
            f.stuck.len(),
            f.stalled
        );
    }
    for e in &d.effects {
        eprintln!("effect {}: {:?}", e.label, e.parameters);
    }
}

criterion_group!(benches, bench, bench_calibrated, bench_held);
criterion_main!(benches);
