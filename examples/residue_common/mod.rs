//! Shared by the Fig. 2 and Fig. 3 examples: modal updating of the
//! damaged testbed's springs from exact, identified and shaker-suspended
//! test modes, with DOFs 1, 4, 7 and all 8, as tables and bar charts.

use std::path::Path;
use tacit::correlate::{self, report, Expansion, ModalTest, Residue, UpdateResult, UpdateSettings};
use tacit::model::Model;

/// Shared by the Fig. 2 and Fig. 3 examples (same code, other residue).
pub fn run(residue: Residue, name: &str, fig: &str) -> anyhow::Result<()> {
    let out = Path::new("out").join(name);
    tacit::io::ensure_dir(&out)?;
    let nominal = Model::from_file(Path::new("data/lanl8dof.toml"))?;
    let damaged = correlate::with_spring_change(&nominal, "k5", -0.14)?;
    let all: Vec<usize> = (1..=8).collect();
    let exact = correlate::model_test_modes(&damaged, &all, 5)?;
    let (ident, _) = correlate::identified_modes(
        &damaged,
        &ModalTest::like_the_paper(),
        "identified (friction + noise)",
        5,
    )?;
    let shaker_test = ModalTest {
        shaker_stiffness: 2000.0,
        ..ModalTest::like_the_paper()
    };
    let (shaker, _) = correlate::identified_modes(
        &damaged,
        &shaker_test,
        "identified (friction + noise + shaker suspension)",
        5,
    )?;
    for (tag, data) in [
        ("exact", &exact),
        ("identified", &ident),
        ("shaker", &shaker),
    ] {
        let mut results: Vec<(String, UpdateResult)> = Vec::new();
        for (dname, dofs) in [("1,4,7", vec![1, 4, 7]), ("all 8", all.clone())] {
            let t = data.restrict(&dofs)?;
            let exps: Vec<(&str, Expansion)> = if dofs.len() == 8 {
                vec![("", Expansion::Serep)]
            } else {
                vec![("SEREP", Expansion::Serep), ("dynamic", Expansion::Dynamic)]
            };
            for (ename, exp) in exps {
                let s = UpdateSettings::new(residue).with_expansion(exp);
                let r = correlate::update_stiffness(&nominal, &t, &s)?;
                let label = if ename.is_empty() {
                    format!("DOFs {dname}")
                } else {
                    format!("DOFs {dname}, {ename}")
                };
                results.push((label, r));
            }
        }
        println!("\n{fig} ({residue:?} residues), test modes: {}", data.name);
        let refs: Vec<(&str, &UpdateResult)> =
            results.iter().map(|(n, r)| (n.as_str(), r)).collect();
        print!("{}", report::adjustment_table(&refs));
        let bars: Vec<(String, &UpdateResult)> =
            results.iter().map(|(n, r)| (n.clone(), r)).collect();
        let f = report::adjustment_figure(
            &format!("{fig}: {residue:?}-residue updating, {}", data.name),
            &bars,
        );
        let stem = out.join(format!("{}_{tag}", &name[..5]));
        tacit::plot::save(&f, &stem)?;
    }
    println!("\ntruth: k5 -14 %, every other spring 0 %");
    Ok(())
}
