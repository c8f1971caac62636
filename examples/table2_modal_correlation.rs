//! Reproduces the paper's Table 2 (test-analysis correlation before
//! updating: damaged testbed vs nominal model): identified frequency, model
//! frequency, frequency error and MAC, with a MAC-matrix figure.
//!
//! Test data: the damaged testbed (spring 5 softer by 14 %), (a) its exact
//! modes and (b) modes identified by tacit from a simulated test with
//! friction and noise (five 8-s records, random force at mass 1). MAC at
//! all 8 DOFs and at DOFs 1, 4, 7.
//!
//! Run: `cargo run --release --example table2_modal_correlation`.
//! Writes `out/table2_modal_correlation/mac_{exact,identified}_{all,147}.{png,svg}`.

use std::path::Path;
use tacit::correlate::{self, report, ModalTest};
use tacit::model::Model;

/// The paper's Table 2: identified Hz, FE Hz, error %, MAC %.
const PAPER: [report::PaperRow; 5] = [
    (22.3, 21.8, -2.3, 99.7),
    (43.9, 43.0, -2.0, 99.4),
    (64.8, 63.0, -2.8, 99.4),
    (85.9, 80.8, -6.0, 93.2),
    (99.7, 95.6, -4.1, 98.5),
];

fn main() -> anyhow::Result<()> {
    let out = Path::new("out/table2_modal_correlation");
    tacit::io::ensure_dir(out)?;
    let nominal = Model::from_file(Path::new("data/lanl8dof.toml"))?;
    let damaged = correlate::with_spring_change(&nominal, "k5", -0.14)?;
    let all: Vec<usize> = (1..=8).collect();
    let exact = correlate::model_test_modes(&damaged, &all, 5)?;
    let (ident, _) = correlate::identified_modes(
        &damaged,
        &ModalTest::like_the_paper(),
        "damaged, identified (friction + noise)",
        5,
    )?;
    let modes = tacit::modal::solve(&nominal.mass_matrix(), &nominal.stiffness_matrix())?;
    for (tag, data) in [("exact", &exact), ("identified", &ident)] {
        for (dtag, dofs) in [("all", all.clone()), ("147", vec![1, 4, 7])] {
            let t = data.restrict(&dofs)?;
            let corr = correlate::correlate(&t, &modes, &Default::default())?;
            println!(
                "\nTable 2 ({tag} damaged modes vs nominal model, DOFs {:?})",
                dofs
            );
            print!("{}", report::correlation_table(&corr, Some(&PAPER)));
            let fig = report::mac_figure(
                &format!("Table 2: {tag} damaged modes vs nominal model"),
                &corr,
                &data.name,
                &nominal.name,
            );
            tacit::plot::save(&fig, &out.join(format!("mac_{tag}_{dtag}")))?;
        }
    }
    println!(
        "\nThe paper's model is 2-6 % below its test in frequency (a stiffer real testbed);\n\
         here model and test differ only by the damage (and friction, noise): the\n\
         errors are the damage's signature, largest on modes 4 and 1 where spring 5 strains most."
    );
    Ok(())
}
