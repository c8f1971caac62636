//! How good are the reconstructed states for multiple shooting? On a simulated
//! bumper record: relative errors of u5 − u6 and v5 − v6, and the segment
//! error of the exact and the linear model from each source of start states.
//! `cargo run --release --example reconstruction_quality -- data/lanl8dof-bumper.h5`
use tacit::diagnose::{prepare, DiagnoseSettings, StatesSource};
use tacit::integrate::SimSettings;
use tacit::model::Model;
fn main() {
    let path = std::env::args().nth(1).unwrap();
    let rec = tacit::record::read(std::path::Path::new(&path)).unwrap();
    let lin = Model::from_file(std::path::Path::new("data/lanl8dof.toml")).unwrap();
    let exact = Model::from_file(std::path::Path::new("data/lanl8dof-contact.toml")).unwrap();
    let truth = rec.truth.clone().unwrap();
    for (name, src, res) in [
        ("lifted r8", StatesSource::Lifted, 8),
        ("lifted r16", StatesSource::Lifted, 16),
        ("horizon", StatesSource::Reconstructed, 0),
        ("truth", StatesSource::Truth, 0),
    ] {
        let mut s = DiagnoseSettings {
            states: src,
            ..Default::default()
        };
        if res > 0 {
            s.lifted.resolution = res;
        }
        let p = prepare(&lin, &rec, None, &s).unwrap();
        let st = &p.recon.states;
        let (mut num, mut den) = (0.0, 0.0);
        let (mut nv, mut dv) = (0.0, 0.0);
        for k in 0..rec.len() {
            let d = (st[(4, k)] - st[(5, k)]) - (truth.u[4][k] - truth.u[5][k]);
            num += d * d;
            den += (truth.u[4][k] - truth.u[5][k]).powi(2);
            let d = (st[(12, k)] - st[(13, k)]) - (truth.v[4][k] - truth.v[5][k]);
            nv += d * d;
            dv += (truth.v[4][k] - truth.v[5][k]).powi(2);
        }
        let sim = SimSettings {
            substeps: 40,
            ..Default::default()
        };
        let (e_exact, _) = p.comparison.errors(&exact, sim);
        let (e_lin, _) = p.comparison.errors(&lin, sim);
        println!("{name}: u5-u6 err {:.3}, v5-v6 err {:.3} | exact model seg err {:?} | linear {:?} | {:.2}s", (num / den).sqrt(), (nv / dv).sqrt(), e_exact.relative_error, e_lin.relative_error, p.recon.elapsed_s);
    }
}
