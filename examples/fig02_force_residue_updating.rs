//! Reproduces the paper's Fig. 2 (adjustments brought to the spring
//! stiffnesses when force-based modal residues, eq. 4, are minimised): bar
//! charts of the change of each spring, %, for the damaged testbed (spring 5
//! softer by 14 %), first five modes, all springs updated.
//!
//! Test data: exact modes (noise-free) and modes identified from simulated
//! tests with friction and noise, with the paper's sensing (DOFs 1, 4, 7,
//! shapes expanded by SEREP or dynamic expansion) and with all 8 DOFs; and
//! a test whose shaker suspension (2 kN/m to ground at DOF 1) is missing
//! from the model, the kind of local driving-point stiffness the paper
//! reports.
//!
//! Run: `cargo run --release --example fig02_force_residue_updating`.
//! Writes `out/fig02_force_residue_updating/fig02_{exact,identified,shaker}.{png,svg}`.

mod residue_common;

use tacit::correlate::Residue;

fn main() -> anyhow::Result<()> {
    residue_common::run(Residue::Force, "fig02_force_residue_updating", "Fig. 2")
}
