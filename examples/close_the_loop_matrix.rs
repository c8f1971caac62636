//! The close-the-loop checks of the issue, as a table: records simulated
//! from lanl8dof with an undeclared effect (1 % noise, 4096 samples), with
//! sensors at all eight masses and at 1, 5, 6; each diagnosed with the
//! declared linear model and validated on a second record.
//!
//! `cargo run --release --example close_the_loop_matrix [-- --quick] [--only TEXT]`
//!
//! With `TACIT_MATRIX_JSON=DIR` set, each diagnosis is also written whole
//! to `DIR/case-K.json` (K counts the rows), for comparing runs.

mod matrix_common;

use matrix_common::{effects_cell, lanl, sensors_cell};
use tacit::diagnose::{diagnose, DiagnoseSettings};
use tacit::integrate::SimSettings;
use tacit::model::{Contact, Cubic, Friction, Model, Spring};
use tacit::simulate::{simulate_record, RecordSpec};

fn cases() -> Vec<(&'static str, Model, String)> {
    let mut out = vec![];
    for (gap, name) in [
        (0.381e-3, "bumper 5→6, 0.381 mm"),
        (0.203e-3, "bumper 5→6, 0.203 mm"),
    ] {
        let mut m = lanl();
        m.contacts = vec![Contact {
            dofs: vec![5, 6],
            gap,
            stiffness: 2e6,
        }];
        out.push((
            name,
            m,
            format!("contact [5, 6] gap {gap:.3e} stiffness 2e6"),
        ));
    }
    let mut m = lanl();
    m.contacts = vec![Contact {
        dofs: vec![3, 2],
        gap: 0.3e-3,
        stiffness: 2e6,
    }];
    out.push((
        "bumper 3→2, 0.3 mm",
        m,
        "contact [3, 2] gap 3e-4 stiffness 2e6".into(),
    ));
    let mut m = lanl();
    m.frictions = (1..=8)
        .map(|d| Friction {
            dof: d,
            level: 0.5,
            velocity: 1e-3,
        })
        .collect();
    out.push((
        "friction 0.5 N on every mass",
        m,
        "friction level 0.5".into(),
    ));
    let mut m = lanl();
    m.cubics = vec![Cubic {
        dofs: vec![3, 4],
        k3: 2e12,
    }];
    out.push(("cubic spring 3–4", m, "cubic [3, 4] k3 2e12".into()));
    let mut m = lanl();
    m.springs.push(Spring {
        dofs: vec![1],
        stiffness: 2000.0,
        name: None,
    });
    out.push((
        "spring to ground at 1",
        m,
        "ground_spring [1] stiffness 2000".into(),
    ));
    let mut m = lanl();
    m.contacts = vec![Contact {
        dofs: vec![5, 6],
        gap: 0.381e-3,
        stiffness: 2e6,
    }];
    m.springs[4].stiffness *= 0.86;
    out.push((
        "bumper + spring 5 −14 %",
        m,
        "contact [5, 6] + stiffness k5 delta −0.14".into(),
    ));
    out.push(("linear (no effect)", lanl(), "none".into()));
    out
}

fn main() {
    let quick = std::env::args().any(|a| a == "--quick");
    let samples = if quick { 2048 } else { 4096 };
    // `--only TEXT`: the records whose name contains TEXT
    let args: Vec<String> = std::env::args().collect();
    let only = args
        .iter()
        .position(|a| a == "--only")
        .and_then(|i| args.get(i + 1).cloned());
    println!("| record | sensors | truth | found | parameters | relative_error before → after | validation before → after | time |");
    println!("|---|---|---|---|---|---|---|---|");
    let dump = std::env::var_os("TACIT_MATRIX_JSON").map(std::path::PathBuf::from);
    let mut row = 0;
    for (name, truth, truth_text) in cases() {
        if only.as_ref().is_some_and(|o| !name.contains(o.as_str())) {
            continue;
        }
        for sensors in [vec![1, 2, 3, 4, 5, 6, 7, 8], vec![1, 5, 6]] {
            let spec = |seed| RecordSpec {
                samples,
                sensors: sensors.clone(),
                noise: 0.01,
                seed,
                settings: SimSettings {
                    substeps: 40,
                    ..Default::default()
                },
                ..Default::default()
            };
            let rec = simulate_record(&truth, &spec(101)).unwrap().0;
            let val = simulate_record(&truth, &spec(202)).unwrap().0;
            let t = std::time::Instant::now();
            let d = match diagnose(
                &lanl(),
                &rec,
                Some(&val),
                None,
                &DiagnoseSettings::default(),
                &|_| {},
            ) {
                Ok(d) => d,
                Err(e) => {
                    println!("| {name} | {sensors:?} | {truth_text} | error: {e} | | | | |");
                    continue;
                }
            };
            row += 1;
            if let Some(dir) = &dump {
                std::fs::create_dir_all(dir).unwrap();
                let json = serde_json::to_string_pretty(&d).unwrap();
                std::fs::write(dir.join(format!("case-{row}.json")), json).unwrap();
            }
            let pct = |x: Option<f64>| x.map_or("failed".into(), |v| format!("{:.1} %", 100.0 * v));
            let v = d.validation.as_ref().unwrap();
            println!(
                "| {name} | {} | {truth_text} | {} | {} | {} → {} | {} → {} | {:.1} s |",
                sensors_cell(&sensors),
                d.verdict,
                effects_cell(&d.effects),
                pct(d.before.relative_error),
                pct(d.after.relative_error),
                pct(v.before.relative_error),
                pct(v.after.relative_error),
                t.elapsed().as_secs_f64()
            );
        }
    }
}
