//! Shared setup of the fig08–fig10 examples: the simulated lanl8dof record
//! with the 0.381 mm bumper and the identifications shown beside the
//! paper's Figs 8–10.

use tacit::identify::{identify, ForceEstimate, IdentifySettings, Problem, Reduce};
use tacit::integrate::SimSettings;
use tacit::model::Model;
use tacit::simulate::{simulate_record, RecordSpec};

/// The paper processes the first 90 measurements (30 windows of 3) after
/// the start sample.
pub const PAPER_SAMPLES: usize = 91;

/// Four identifications: (label, estimate).
pub fn runs() -> Vec<(&'static str, ForceEstimate)> {
    let p = concat!(env!("CARGO_MANIFEST_DIR"), "/data/lanl8dof-contact.toml");
    let model = Model::from_file(std::path::Path::new(p)).expect("model");
    // "test": 4096 samples at 512 Hz, 20 N random at DOF 1, contact resolved
    // with 40 sub-steps (docs/theory.md, fact R5), accelerations at 1, 5, 6
    let spec = RecordSpec {
        samples: 4096,
        sensors: vec![1, 5, 6],
        settings: SimSettings {
            substeps: 40,
            ..Default::default()
        },
        ..Default::default()
    };
    let (rec, _) = simulate_record(&model, &spec).expect("simulation");
    let mut first = rec.clone();
    for c in first.inputs.iter_mut().chain(first.outputs.iter_mut()) {
        c.data.truncate(PAPER_SAMPLES);
    }
    if let Some(t) = first.truth.as_mut() {
        for m in [&mut t.u, &mut t.v, &mut t.a, &mut t.fint] {
            for r in m.iter_mut() {
                r.truncate(PAPER_SAMPLES);
            }
        }
    }
    let lin = model.linear_part();
    let paper = IdentifySettings::paper(1.0);
    let mhe = IdentifySettings::default();
    let full = IdentifySettings {
        reduce: Reduce::None,
        regularization: tacit::identify::Regularization::Fixed(0.1),
        ..Default::default()
    };
    let mut out = Vec::new();
    for (label, r, s) in [
        ("paper_first90", &first, &paper),
        ("paper_whole", &rec, &paper),
        ("mhe_whole", &rec, &mhe),
        ("mhe_full_order_whole", &rec, &full),
    ] {
        let prob = Problem::new(&lin, r, &[1, 5, 6]).expect("problem");
        let est = identify(&prob, s).expect("identify");
        let (b, a, rp) = est.overall_errors();
        println!(
            "{label:>22}: status {:?}, radius {:?}, error before {:.1} %, after {:.2} %, replay {:.1} %",
            est.status,
            est.diagnostics.spectral_radius,
            100.0 * b,
            100.0 * a,
            100.0 * rp
        );
        out.push((label, est));
    }
    out
}

/// `out/<example>/`, created.
pub fn out_dir(example: &str) -> std::path::PathBuf {
    let d = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("out")
        .join(example);
    std::fs::create_dir_all(&d).expect("output directory");
    d
}
