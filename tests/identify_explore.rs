use tacit::identify::*;
use tacit::model::Model;
use tacit::simulate::{simulate_record, RecordSpec};
use tacit::integrate::SimSettings;

fn ctx_model(ground: bool) -> Model {
    let mut t = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/data/lanl8dof-contact.toml")).unwrap();
    if ground { t.push_str("\n[[spring]]\nname = \"shaker\"\ndofs = [1]\nstiffness = 2000.0\n"); }
    Model::from_toml_str(&t, "ctx").unwrap()
}

fn show(tag: &str, est: &ForceEstimate) {
    let (b, af, rp) = est.overall_errors();
    let r = est.force_rms();
    let tc = est.truth.as_ref().unwrap();
    eprintln!("{tag}: radius {:.5?} before {b:.3} after {af:.4} replay {rp:.4} st {:?}\n    rms {:?}\n    corr {:?} tenths {:?}", est.diagnostics.spectral_radius, matches!(est.status, Status::Ok),
      r.iter().map(|v| format!("{v:.1}")).collect::<Vec<_>>(), tc.correlation.iter().map(|v| format!("{v:.2}")).collect::<Vec<_>>(),
      est.diagnostics.force_rms_by_tenth.iter().map(|v| format!("{v:.0}")).collect::<Vec<_>>());
}

#[test]
fn explore() {
    let ground = std::env::var("GROUND").is_ok();
    let model = ctx_model(ground);
    let spec = RecordSpec { samples: 4096, sensors: vec![1,2,3,4,5,6,7,8], settings: SimSettings { substeps: 40, ..Default::default() }, ..Default::default() };
    let (rec, _) = simulate_record(&model, &spec).unwrap();
    let lin = model.linear_part();
    let prob = Problem::new(&lin, &rec, &[1,5,6]).unwrap();
    let red = if std::env::var("FULL").is_ok() { Reduce::None } else { Reduce::Serep };
    for h in [24usize] {
        for (mu, eps) in [(1e-3, 1e-4), (1e-2, 1e-6), (1e-2, 1e-4), (1e-1, 1e-4), (1e-1, 1e-6), (1e-2, 1e-5)] {
            for a in [1e-3, 1e-2] {
                let s = IdentifySettings { reduce: red, horizon: h, prior_weight: mu, leak: eps, regularization: Regularization::Fixed(a), ..Default::default() };
                let t = std::time::Instant::now();
                let est = identify(&prob, &s).unwrap();
                show(&format!("MHE {red:?} h={h} mu={mu:e} eps={eps:e} a={a:e} ({:.2?})", t.elapsed()), &est);
            }
        }
    }
}
