//! Window identification speed (issue 3): one 4096-sample record, 8 force
//! unknowns per window, windows of 3 samples, 10 sub-steps. Targets: least
//! squares under 2 ms per record, QP under 100 ms (a NumPy version of the
//! same scheme takes 0.2–0.35 s). The window operators are built once per
//! setting (reported separately as `setup`), the bench times the run over
//! the record.

use criterion::{criterion_group, criterion_main, Criterion};
use std::hint::black_box;
use tacit::identify::run::{run, LsSolver};
use tacit::identify::{
    build_plan, identify, qp::QpSolver, Constraints, IdentifySettings, Problem, Reduce, System,
};
use tacit::integrate::SimSettings;
use tacit::model::Model;
use tacit::simulate::{simulate_record, RecordSpec};

fn problem() -> Problem {
    let p = concat!(env!("CARGO_MANIFEST_DIR"), "/data/lanl8dof-contact.toml");
    let model = Model::from_file(std::path::Path::new(p)).unwrap();
    let spec = RecordSpec {
        samples: 4096,
        sensors: vec![1, 5, 6],
        settings: SimSettings {
            substeps: 40,
            ..Default::default()
        },
        ..Default::default()
    };
    let (rec, _) = simulate_record(&model, &spec).unwrap();
    Problem::new(&model.linear_part(), &rec, &[1, 5, 6]).unwrap()
}

fn bench(c: &mut Criterion) {
    let prob = problem();
    // the paper's setting: SEREP on 1, 5, 6, 8 unknowns per window of 3
    let paper = IdentifySettings::paper(1e2);
    let sys = System::new(&prob, Reduce::Serep, 10).unwrap();
    let plan = build_plan(&sys, prob.len(), &paper, 1e2);
    eprintln!("paper: {} windows", plan.windows.len());
    c.bench_function("paper_ls_4096", |b| {
        b.iter(|| black_box(run(&sys, &prob, &plan, &mut LsSolver, &mut |_, _| {})))
    });
    c.bench_function("paper_qp_4096", |b| {
        b.iter(|| {
            let mut s = QpSolver::new(Constraints::default(), 8, plan.ops.len());
            black_box(run(&sys, &prob, &plan, &mut s, &mut |_, _| {}))
        })
    });
    let full = System::new(&prob, Reduce::None, 10).unwrap();
    let fplan = build_plan(&full, prob.len(), &paper, 1e2);
    c.bench_function("paper_full_order_ls_4096", |b| {
        b.iter(|| black_box(run(&full, &prob, &fplan, &mut LsSolver, &mut |_, _| {})))
    });
    c.bench_function("paper_full_order_qp_4096", |b| {
        b.iter(|| {
            let mut s = QpSolver::new(Constraints::default(), 8, fplan.ops.len());
            black_box(run(&full, &prob, &fplan, &mut s, &mut |_, _| {}))
        })
    });
    let contact = Constraints {
        pairs: vec![(5, 6)],
        push_apart: true,
        ..Default::default()
    };
    c.bench_function("paper_full_order_qp_pair_pushapart_4096", |b| {
        b.iter(|| {
            let mut s = QpSolver::new(contact.clone(), 8, fplan.ops.len());
            black_box(run(&full, &prob, &fplan, &mut s, &mut |_, _| {}))
        })
    });
    // the default: MHE, horizon 24, SEREP
    let mhe = IdentifySettings::default();
    let mplan = build_plan(&sys, prob.len(), &mhe, 1e-3);
    c.bench_function("mhe_ls_4096", |b| {
        b.iter(|| black_box(run(&sys, &prob, &mplan, &mut LsSolver, &mut |_, _| {})))
    });
    let mut g = c.benchmark_group("end_to_end");
    g.sample_size(10);
    g.bench_function("identify_paper_ls_4096_with_setup", |b| {
        b.iter(|| black_box(identify(&prob, &paper).unwrap()))
    });
    g.bench_function("identify_mhe_ls_4096_with_setup", |b| {
        b.iter(|| black_box(identify(&prob, &mhe).unwrap()))
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
