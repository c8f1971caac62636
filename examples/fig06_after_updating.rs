//! Draws the paper's Fig. 6 (§6.1): displacement time histories of the
//! 4-DOF cubic chain after updating (PCD, full order, displacement data,
//! Levenberg–Marquardt), "test" (solid) against the updated model (dashed),
//! at DOFs 1, 3 and 4. Writes `data/figures/fig06_after_updating.{png,svg}`.
//!
//! Run: `cargo run --release --example fig06_after_updating`

use std::path::Path;
use tacit::cases::table4;
use tacit::update::{self, FitSettings};

fn main() -> tacit::Result<()> {
    let case = table4::case(0.0, 11)?;
    let problem = table4::problem(&case, &table4::columns()[2])?;
    let result = update::fit(&problem, &FitSettings::default())?;
    let predicted = update::predict(&problem, &result.x)
        .map_err(|f| tacit::TacitError::Numerical(f.to_string()))?;
    let fig = update::figures::responses(
        &problem,
        &case.record.times(),
        &predicted,
        "Fig. 6: displacements after updating (test solid, model dashed)",
    );
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("data/figures");
    tacit::io::ensure_dir(&dir)?;
    for p in tacit::plot::save(&fig, &dir.join("fig06_after_updating"))? {
        println!("wrote {}", p.display());
    }
    println!("changes (%): {:?}", result.percent_changes());
    Ok(())
}
