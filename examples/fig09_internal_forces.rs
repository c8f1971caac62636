//! Reproduces Fig. 9 of Hemez & Doebling §6.2 on a simulated lanl8dof
//! record with the 0.381 mm bumper: time histories of the identified internal forces at the 8 DOFs, with the true contact force.
//!
//! Writes `out/fig09_internal_forces/<run>_{first90,whole}.{png,svg}` for the runs: the
//! published scheme on the paper's first 90 samples and on the whole record
//! (where it diverges, docs/theory.md, fact R1), MHE (the default, SEREP on 1, 5,
//! 6) and MHE on the full-order model (forces localise at DOFs 5–6).
//! Run: `cargo run --release --example fig09_internal_forces`.

#[path = "identify_common/mod.rs"]
mod common;

use tacit::identify::output::force_figure;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let dir = common::out_dir("fig09_internal_forces");
    for (label, est) in common::runs() {
        let n = est.time.len();
        let mut ranges = vec![("first90", 0..common::PAPER_SAMPLES.min(n))];
        if n > common::PAPER_SAMPLES {
            ranges.push(("whole", 0..n));
        }
        for (what, range) in ranges {
            let est = &est;
            let fig = force_figure(est, range);
            for f in tacit::plot::save(&fig, &dir.join(format!("{label}_{what}")))? {
                println!("wrote {}", f.display());
            }
        }
    }
    Ok(())
}
