//! Reproduces Fig. 10 of Hemez & Doebling §6.2 on a simulated lanl8dof
//! record with the 0.381 mm bumper: the accelerations at DOFs 1, 5, 6 after
//! identification (linear model + identified internal force) against the
//! measured ones.
//!
//! Writes `out/fig10_after_identification/<run>_{first90,whole}.{png,svg}` for the runs: the
//! published scheme on the paper's first 90 samples and on the whole record
//! (where it diverges, docs/theory.md, fact R1), MHE (the default, SEREP on 1, 5,
//! 6) and MHE on the full-order model (forces localise at DOFs 5–6).
//! Run: `cargo run --release --example fig10_after_identification`.

#[path = "identify_common/mod.rs"]
mod common;

use tacit::identify::output::channel_figure;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let dir = common::out_dir("fig10_after_identification");
    for (label, est) in common::runs() {
        let n = est.time.len();
        let mut ranges = vec![("first90", 0..common::PAPER_SAMPLES.min(n))];
        if n > common::PAPER_SAMPLES {
            ranges.push(("whole", 0..n));
        }
        for (what, range) in ranges {
            let est = &est;
            let fig = channel_figure(est, true, range);
            for f in tacit::plot::save(&fig, &dir.join(format!("{label}_{what}")))? {
                println!("wrote {}", f.display());
            }
        }
    }
    Ok(())
}
