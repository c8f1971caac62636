//! Draws the paper's Fig. 5 (§6.1): displacement time histories of the
//! 4-DOF cubic chain before updating, "test" (solid) against the nominal
//! model (dashed), at DOFs 1, 3 and 4. Writes
//! `data/figures/fig05_before_updating.{png,svg}`.
//!
//! Run: `cargo run --release --example fig05_before_updating`

use std::path::Path;
use tacit::cases::table4;
use tacit::update;

fn main() -> tacit::Result<()> {
    let case = table4::case(0.0, 11)?;
    let problem = table4::problem(&case, &table4::columns()[2])?;
    let predicted = update::predict(&problem, &problem.x_start())
        .map_err(|f| tacit::TacitError::Numerical(f.to_string()))?;
    let fig = update::figures::responses(
        &problem,
        &case.record.times(),
        &predicted,
        "Fig. 5: displacements before updating (test solid, model dashed)",
    );
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("data/figures");
    tacit::io::ensure_dir(&dir)?;
    for p in tacit::plot::save(&fig, &dir.join("fig05_before_updating"))? {
        println!("wrote {}", p.display());
    }
    Ok(())
}
