mod horizon_common;
use horizon_common::*;
use nalgebra::DVector;
use tacit::horizon::batch::solve_dense;
use tacit::horizon::{solve, unknown_at_dofs, ChannelNoise, InitialState};

#[test]
fn debug() {
    let sm = sampled();
    let len = 400;
    let bu = unknown_at_dofs(8, &[4, 5]).unwrap();
    let a = tacit::signal::random_band(len, FS, (2.0, 60.0), 5.0, 21).unwrap();
    let w = nalgebra::DMatrix::from_fn(2, len, |i, k| if i == 0 { a[k] } else { -a[k] * 0.5 });
    let (g, y, _) = linear_record(&sm, len, &bu, &w, &DVector::zeros(16), &[1e-6; 3], 3);
    let ch = channels();
    let d = data(&g, &y, &ch, &bu);
    let mut s = settings();
    s.noise = ChannelNoise::Std { std: vec![1e-6; 3] };
    s.initial = InitialState::Rest;
    for lam in [1e-4, 1e-8] {
        let r = solve(&sm, &d, &s, lam, 0.0, false).unwrap();
        let b = solve_dense(&sm, &d, &s, lam, 0.0).unwrap();
        for t in 0..8 {
            let c = r.force.columns(t * 50, 50) - w.columns(t * 50, 50);
            let cb = b.force.columns(t * 50, 50) - w.columns(t * 50, 50);
            eprintln!(
                "λ {lam} seg {t}: err {:.3e} batch {:.3e} (norm {:.3e})",
                c.norm(),
                cb.norm(),
                w.columns(t * 50, 50).norm()
            );
        }
        eprintln!(
            "rel resid {:?} rss {:e} cost {:e} batch cost {:e}",
            r.diagnostics.relative_residual, r.diagnostics.rss, r.diagnostics.cost, b.cost
        );
        let gt = tacit::horizon::batch::relative_gradient(
            &sm,
            &d,
            &s,
            lam,
            0.0,
            &DVector::zeros(16),
            &w,
        )
        .unwrap();
        eprintln!("gradient at truth {gt:e}");
        let (cy, dy) = sm.outputs(&ch).unwrap();
        let ft = &g + &bu * &w;
        let xs = sm.simulate(&DVector::zeros(16), &ft);
        let yt = &cy * &xs + &dy * &ft;
        eprintln!("truth resid {:e} rel", (&yt - &y).norm() / y.norm());
        let fe = &g + &bu * &r.force;
        let xe = sm.simulate(&DVector::zeros(16), &fe);
        let ye = &cy * &xe + &dy * &fe;
        eprintln!(
            "est resid {:e} rel; est pred vs reported {:e}",
            (&ye - &y).norm() / y.norm(),
            (&ye - &r.predicted).norm() / y.norm()
        );
        eprintln!(
            "w[0..6] {:?}\nest {:?}",
            w.row(0).columns(0, 6),
            r.force.row(0).columns(0, 6)
        );
    }
}
