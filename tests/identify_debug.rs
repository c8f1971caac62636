use nalgebra::DMatrix;
use tacit::identify::*;
use tacit::integrate::{Integrator, SimSettings};
use tacit::model::Model;
use tacit::record::{Channel, Quantity, Record, Truth};
#[test]
fn dbg() {
    let model = Model::from_file(concat!(env!("CARGO_MANIFEST_DIR"), "/data/lanl8dof.toml").as_ref()).unwrap();
    let ns = 600; let n = 8;
    let ext = tacit::signal::random_band(ns, 512.0, (5.0, 200.0), 20.0, 11).unwrap();
    let mut fint = DMatrix::zeros(8, ns);
    for k in 200..208 { fint[(4, k)] = 30.0 * (std::f64::consts::PI * (k - 200) as f64 / 7.0).sin(); }
    let mut f = -fint.clone(); for k in 0..ns { f[(0,k)] += ext[k]; }
    let sim = Integrator::new(&model, 512.0, SimSettings::default()).unwrap().run(f.as_view(), &vec![0.0; n], &vec![0.0; n]);
    let rows = |m: &DMatrix<f64>| -> Vec<Vec<f64>> { (0..n).map(|i| m.row(i).iter().copied().collect()).collect() };
    let rec = Record { t0: 0.0, fs: 512.0, inputs: vec![Channel::new(Quantity::Force, 1, ext.clone())],
        outputs: (1..=8).map(|d| Channel::new(Quantity::Accel, d, sim.a.row(d-1).iter().copied().collect())).collect(),
        truth: Some(Truth { u: rows(&sim.u), v: rows(&sim.v), a: rows(&sim.a), fint: rows(&fint), model_toml: String::new() }), source: Default::default() };
    let all: Vec<usize> = (1..=8).collect();
    let prob = Problem::new(&model, &rec, &all).unwrap();
    for (mu, eps, a, h) in [(1.0, 1e-8, 1e-8, 24), (10.0, 1e-8, 1e-8, 24), (100.0, 1e-8, 1e-8, 24), (10.0, 1e-8, 1e-10, 24)] {
        let s = IdentifySettings { reduce: Reduce::None, regularization: Regularization::Fixed(a), prior_weight: mu, leak: eps, horizon: h, ..Default::default() };
        let est = identify(&prob, &s).unwrap();
        let got: Vec<f64> = est.force.row(4).iter().copied().collect();
        let tru: Vec<f64> = fint.row(4).iter().copied().collect();
        let err: Vec<String> = (196..212).map(|k| format!("{:.2}/{:.2}", got[k], tru[k])).collect();
        let _ = err; eprintln!("mu {mu} eps {eps} a {a} h {h}: rel {:.4} after {:?} radius {:?}", tacit::metrics::relative_error(&got, &tru), est.overall_errors(), est.diagnostics.spectral_radius);
    }
}
