//! Development check: reconstruction quality against the truth.
use tacit::diagnose::{prepare, DiagnoseSettings};
use tacit::model::Model;
fn main() {
    let rec = tacit::record::read(std::path::Path::new(&std::env::args().nth(1).unwrap())).unwrap();
    let model = Model::from_file(std::path::Path::new("data/lanl8dof.toml")).unwrap();
    let truth = rec.truth.clone().unwrap();
    for lam in [1e-2, 1.0, 1e2, 1e4] {
        let mut s = DiagnoseSettings::default();
        s.horizon.lambda = lam;
        let p = prepare(&model, &rec, None, &s).unwrap();
        let st = &p.recon.states;
        let n = 8;
        let mut e = vec![];
        for (name, rows, off) in [("u", &truth.u, 0), ("v", &truth.v, n)] {
            let (mut num, mut den) = (0.0, 0.0);
            for i in 0..n {
                for k in 0..rec.len() {
                    let d = if i == 4 {
                        (st[(off + 4, k)] - st[(off + 5, k)]) - (rows[4][k] - rows[5][k])
                    } else {
                        st[(off + i, k)] - rows[i][k]
                    };
                    num += d * d;
                    den += rows[i][k] * rows[i][k];
                }
            }
            e.push(format!("{name}: {:.3}", (num / den).sqrt()));
        }
        let (mut num, mut den) = (0.0, 0.0);
        for k in 0..rec.len() {
            let d = (st[(4, k)] - st[(5, k)]) - (truth.u[4][k] - truth.u[5][k]);
            num += d * d;
            den += (truth.u[4][k] - truth.u[5][k]).powi(2);
        }
        let y = tacit::trace::regress::segment_response(
            &p.sampled,
            &p.sampled.outputs(&p.channels).unwrap().0,
            &p.sampled.outputs(&p.channels).unwrap().1,
            Some(st),
            &p.comparison.force,
            p.segment,
        );
        let err = p.comparison.total_error(&y);
        println!(
            "lambda {lam}: {} | u5-u6 rel err {:.3} | lin seg err {:.3} | {}",
            e.join(" "),
            (num / den).sqrt(),
            err,
            p.recon.status
        );
    }
}
